//! Finding where a key path (`assembly[1].clearance`) is written in a TOML file, so semantic
//! errors can name file:line:column like syntax errors do.

use std::fmt;

/// One step of a key path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Seg {
    /// A table key.
    Key(String),
    /// An array index (arrays of tables or inline arrays).
    Index(usize),
}

/// A path from the document root to a value.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct KeyPath(pub Vec<Seg>);

impl KeyPath {
    /// The path extended by a key.
    pub fn key(&self, k: &str) -> Self {
        let mut p = self.clone();
        p.0.push(Seg::Key(k.to_string()));
        p
    }

    /// The path extended by an index.
    pub fn index(&self, i: usize) -> Self {
        let mut p = self.clone();
        p.0.push(Seg::Index(i));
        p
    }

    /// Reads a path written as `assembly[1].tolerances.lateral` (the form [`fmt::Display`]
    /// writes); a segment that is not a valid index is kept as a key.
    pub fn parse(text: &str) -> Self {
        let mut path = Self::default();
        for part in text.split('.').filter(|p| !p.is_empty()) {
            let (key, mut rest) = part.split_once('[').map_or((part, ""), |(k, r)| (k, r));
            if !key.is_empty() {
                path.0.push(Seg::Key(key.to_string()));
            }
            while let Some((index, tail)) = rest.split_once(']') {
                match index.parse() {
                    Ok(i) => path.0.push(Seg::Index(i)),
                    Err(_) => path.0.push(Seg::Key(index.to_string())),
                }
                rest = tail.strip_prefix('[').unwrap_or(tail);
            }
        }
        path
    }
}

impl fmt::Display for KeyPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, s) in self.0.iter().enumerate() {
            match s {
                Seg::Key(k) if i == 0 => write!(f, "{k}")?,
                Seg::Key(k) => write!(f, ".{k}")?,
                Seg::Index(n) => write!(f, "[{n}]")?,
            }
        }
        Ok(())
    }
}

/// Parses `text` once and answers byte spans of key paths.
pub struct Locator {
    doc: Option<toml_edit::Document<String>>,
}

impl Locator {
    /// A locator over a TOML text (an unparsable text locates nothing).
    pub fn new(text: &str) -> Self {
        Self {
            doc: toml_edit::Document::parse(text.to_string()).ok(),
        }
    }

    /// Byte offset where the value at `path` starts, or the deepest existing ancestor's.
    pub fn offset(&self, path: &KeyPath) -> Option<usize> {
        let doc = self.doc.as_ref()?;
        let mut item: &toml_edit::Item = doc.as_item();
        let mut best = None;
        for seg in &path.0 {
            let next = match (seg, item) {
                (Seg::Key(k), toml_edit::Item::Table(t)) => t.get(k),
                (Seg::Key(k), toml_edit::Item::Value(toml_edit::Value::InlineTable(t))) => {
                    t.get(k).map(|_| &item[k.as_str()])
                }
                (Seg::Index(i), toml_edit::Item::ArrayOfTables(a)) => a.get(*i).map(|_| &item[*i]),
                (Seg::Index(i), toml_edit::Item::Value(toml_edit::Value::Array(a))) => {
                    a.get(*i).map(|_| &item[*i])
                }
                _ => None,
            };
            match next {
                Some(n) => {
                    item = n;
                    if let Some(span) = span_of(item) {
                        best = Some(span);
                    }
                }
                None => break,
            }
        }
        best
    }
}

fn span_of(item: &toml_edit::Item) -> Option<usize> {
    match item {
        toml_edit::Item::Value(v) => v.span().map(|s| s.start),
        toml_edit::Item::Table(t) => t.span().map(|s| s.start),
        toml_edit::Item::ArrayOfTables(a) => a.span().map(|s| s.start),
        toml_edit::Item::None => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_nested_values() {
        let text = "a = 1\n[[step]]\nx = 2\n[[step]]\nx = 3\ny = { z = [4, 5] }\n";
        let l = Locator::new(text);
        let path = KeyPath::default().key("step").index(1).key("x");
        assert_eq!(&text[l.offset(&path).unwrap()..][..1], "3");
        let deep = KeyPath::default()
            .key("step")
            .index(1)
            .key("y")
            .key("z")
            .index(1);
        assert_eq!(&text[l.offset(&deep).unwrap()..][..1], "5");
        assert_eq!(path.to_string(), "step[1].x");
    }

    #[test]
    fn parses_what_it_displays() {
        for text in [
            "assembly[1].tolerances.lateral",
            "cell.feeder",
            "y.z[1]",
            "a[2][3].b",
        ] {
            assert_eq!(KeyPath::parse(text).to_string(), text);
        }
        assert_eq!(
            KeyPath::parse("step[1].x"),
            KeyPath::default().key("step").index(1).key("x")
        );
        assert_eq!(KeyPath::parse(""), KeyPath::default());
    }
}
