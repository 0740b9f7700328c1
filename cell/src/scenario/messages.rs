//! TOML parse and type errors in words a cell integrator reads: the expected type named in words
//! (not `u32`), and a duplicate key named.

/// A TOML error `message` from the parser, rewritten for people; `span` is where it points in
/// `text`.
pub fn toml_message(message: &str, text: &str, span: Option<std::ops::Range<usize>>) -> String {
    let message = message.trim();
    if message == "duplicate key" {
        let key = span
            .and_then(|s| text.get(s))
            .map(|k| k.trim().trim_matches('"').to_string())
            .filter(|k| !k.is_empty());
        return match key {
            Some(k) => {
                format!("duplicate key `{k}`: it is already set in this table; keep one of the two")
            }
            None => "duplicate key: it is already set in this table; keep one of the two".into(),
        };
    }
    match message.rsplit_once(", expected ") {
        Some((head, expected)) => format!("{head}, expected {}", expected_in_words(expected)),
        None => message.to_string(),
    }
}

/// serde's name of an expected type, in words.
fn expected_in_words(expected: &str) -> String {
    let whole = |max: u64| format!("a whole number from 0 to {max}");
    match expected {
        "u8" => whole(u8::MAX.into()),
        "u16" => whole(u16::MAX.into()),
        "u32" => whole(u32::MAX.into()),
        "u64" | "usize" => whole(u64::MAX),
        "i8" | "i16" | "i32" | "i64" | "isize" => "a whole number".into(),
        "f32" | "f64" => "a number (e.g. 0.5 or 1e-3)".into(),
        "a boolean" | "bool" => "true or false".into(),
        "a string" | "a borrowed string" => "a string in quotes".into(),
        "a sequence" => "an array [a, b, ...]".into(),
        "a map" => "a table".into(),
        other => match other.strip_prefix("struct ") {
            Some(_) => "a table".into(),
            None => match other.strip_prefix("an array of length ") {
                Some(n) => format!("an array of {n} numbers [a, b, ...]"),
                None => other.to_string(),
            },
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn types_are_named_in_words() {
        assert_eq!(
            toml_message("invalid type: string \"x\", expected u32", "", None),
            "invalid type: string \"x\", expected a whole number from 0 to 4294967295"
        );
        assert_eq!(
            toml_message("invalid type: integer `3`, expected f64", "", None),
            "invalid type: integer `3`, expected a number (e.g. 0.5 or 1e-3)"
        );
        assert_eq!(
            toml_message("invalid length 2, expected an array of length 3", "", None),
            "invalid length 2, expected an array of 3 numbers [a, b, ...]"
        );
        assert_eq!(toml_message("something else", "", None), "something else");
    }

    #[test]
    fn a_duplicate_key_is_named() {
        let text = "a = 1\na = 2\n";
        assert_eq!(
            toml_message("duplicate key", text, Some(6..7)),
            "duplicate key `a`: it is already set in this table; keep one of the two"
        );
    }
}
