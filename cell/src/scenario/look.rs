//! Look files (`cell dataset --environment FILE`): the opt-in room, area lights and backlit
//! feeder plate of `sim::dataset::LookOptions`; and randomisation family files (`cell dataset
//! --families FILE`, `sim::dataset::Families`); both read with file:line:column errors.

use std::path::Path;

use perception::part::line_column;
use sim::dataset::{Families, LookOptions};

use super::{KeyPath, Locator, Problem, ScenarioError};

/// The name that stands for the built-in look (every option at its default) instead of a file.
pub const DEFAULT_LOOK: &str = "room";

/// Reads a look: [`DEFAULT_LOOK`] (unless a file of that name exists) gives the defaults,
/// anything else is a TOML file whose syntax, type and range errors name its line and column.
pub fn load_look(arg: &Path) -> Result<LookOptions, ScenarioError> {
    if arg.as_os_str() == DEFAULT_LOOK && !arg.is_file() {
        return Ok(LookOptions::default());
    }
    read_checked(arg, "look", parse_look)
}

/// Parses and checks look text read from `path`.
pub fn parse_look(text: &str, path: &Path) -> Result<LookOptions, ScenarioError> {
    parse_checked(text, path, |l: &LookOptions| {
        l.validate().map_err(|e| (e.key, e.message))
    })
}

/// Reads a randomisation families file (TOML, every key optional; a family is on when its
/// `enabled` is true), its syntax, type and range errors at their line and column.
pub fn load_families(path: &Path) -> Result<Families, ScenarioError> {
    read_checked(path, "families", parse_families)
}

/// Parses and checks randomisation family text read from `path`.
pub fn parse_families(text: &str, path: &Path) -> Result<Families, ScenarioError> {
    parse_checked(text, path, |f: &Families| {
        f.validate().map_err(|e| (e.key, e.message))
    })
}

/// Reads the `what` file at `path` and parses it with `parse`; an unreadable file is an error
/// at its first line.
fn read_checked<T>(
    path: &Path,
    what: &str,
    parse: fn(&str, &Path) -> Result<T, ScenarioError>,
) -> Result<T, ScenarioError> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        ScenarioError(vec![Problem {
            file: path.into(),
            line: 1,
            column: 1,
            key: None,
            message: format!("cannot read the {what} file: {e}"),
        }])
    })?;
    parse(&text, path)
}

/// Deserialises `text` and checks it with `validate` (which names the offending key path and
/// what is wrong); either error points at its line and column in `path`.
fn parse_checked<T: serde::de::DeserializeOwned>(
    text: &str,
    path: &Path,
    validate: impl Fn(&T) -> Result<(), (String, String)>,
) -> Result<T, ScenarioError> {
    let value: T = toml::from_str(text).map_err(|e| ScenarioError::from_toml(&e, text, path))?;
    validate(&value).map_err(|(key, message)| {
        let (line, column) = Locator::new(text)
            .offset(&KeyPath::parse(&key))
            .map(|o| line_column(text, o))
            .unwrap_or((1, 1));
        ScenarioError(vec![Problem {
            file: path.into(),
            line,
            column,
            key: Some(key),
            message,
        }])
    })?;
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_file_is_the_default_look() {
        let look = parse_look("", Path::new("look.toml")).unwrap();
        assert_eq!(look, LookOptions::default());
        let look = load_look(Path::new(DEFAULT_LOOK)).unwrap();
        assert_eq!(look, LookOptions::default());
    }

    #[test]
    fn keys_are_read() {
        let text = "[room]\npanels = { lo = 2, hi = 2 }\nmount = false\n\n[backlight]\n\
                    probability = 1.0\n";
        let look = parse_look(text, Path::new("l.toml")).unwrap();
        assert_eq!(look.room.panels.lo, 2.0);
        assert!(!look.room.mount);
        assert_eq!(look.backlight.probability, 1.0);
    }

    #[test]
    fn a_bad_range_is_refused_at_its_line_and_column() {
        let text = "[room]\nmount = true\npanels = { lo = 3, hi = 1 }\n";
        let e = parse_look(text, Path::new("l.toml"))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e, "l.toml:3:10: room.panels: inverted: lo = 3 > hi = 1",
            "{e}"
        );
        let text = "[backlight]\n\nprobability = 1.5\n";
        let e = parse_look(text, Path::new("l.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("l.toml:3:15: backlight.probability: "), "{e}");
    }

    #[test]
    fn an_unknown_key_or_wrong_type_is_refused_at_its_line_and_column() {
        let e = parse_look("[room]\npanles = 3\n", Path::new("l.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("l.toml:2:1: unknown field `panles`"), "{e}");
        let e = parse_look("[area_lights]\nsamples = \"two\"\n", Path::new("l.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("l.toml:2:11: "), "{e}");
    }

    #[test]
    fn families_are_read_from_files() {
        let text = "[plating]\nenabled = true\nroughness = { lo = 0.05, hi = 0.3 }\n";
        let f = parse_families(text, Path::new("f.toml")).unwrap();
        assert_eq!(f.enabled(), ["plating"]);
        assert_eq!(f.plating.roughness.hi, 0.3);
        let e = load_families(Path::new("no/such/families.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("no/such/families.toml:1:1: cannot read"),
            "{e}"
        );
    }

    #[test]
    fn a_bad_family_range_or_key_is_refused_at_its_line_and_column() {
        let text = "[sensor]\nenabled = true\ngain = { lo = 2, hi = 1 }\n";
        let e = parse_families(text, Path::new("f.toml"))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e, "f.toml:3:8: sensor.gain: inverted: lo = 2 > hi = 1",
            "{e}"
        );
        let e = parse_families("[distractors]\ncuont = 3\n", Path::new("f.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("f.toml:2:1: unknown field `cuont`"), "{e}");
    }
}
