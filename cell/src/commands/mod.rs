//! One module per subcommand: argument parsing and human output only; the work lives in the
//! library crates.

pub mod ablate;
pub mod board;
pub mod board_study;
pub mod calibrate;
pub mod check;
pub mod dataset;
pub mod eval;
pub mod merge;
pub mod parts;
pub mod regress;
pub mod replay;
pub mod run;
pub mod scorers;
pub mod virtual_ur;

/// An error and its causes as one text, each cause appended once: a cause whose text the
/// message already holds (an error that prints its source itself) is not repeated.
pub fn error_text(e: &anyhow::Error) -> String {
    let mut text = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !text.contains(&c) {
            text.push_str(": ");
            text.push_str(&c);
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::error_text;

    #[derive(Debug, thiserror::Error)]
    #[error("outer: {source}")]
    struct Repeats {
        source: std::io::Error,
    }

    #[test]
    fn a_cause_already_in_the_message_is_not_repeated() {
        let e = anyhow::Error::new(Repeats {
            source: std::io::Error::other("disk full"),
        });
        assert_eq!(error_text(&e), "outer: disk full");
        let e = anyhow::Error::new(std::io::Error::other("disk full")).context("writing x");
        assert_eq!(error_text(&e), "writing x: disk full");
    }
}
