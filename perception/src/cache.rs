//! The user cache that provisioned native pieces (ONNX Runtime, the STEP kernel) and their
//! results live in, and the Python that provisions them: one place, so every provisioned piece
//! honours the same environment variables.

use std::path::PathBuf;

/// Where the cache and the provisioning Python are, from environment variables looked up by
/// `var` (empty values count as unset).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CacheLocation {
    /// `$CELL_CACHE_DIR`, else `$XDG_CACHE_HOME/cell`, else `$HOME/.cache/cell`, else a folder
    /// under the system's temporary directory.
    pub dir: PathBuf,
    /// The Python whose pip downloads wheels: `$CELL_PYTHON`, else `python3`.
    pub python: PathBuf,
}

impl CacheLocation {
    /// The location for the variables `var` returns.
    pub fn from_vars(var: &impl Fn(&str) -> Option<PathBuf>) -> Self {
        let set = |k: &str| var(k).filter(|v| !v.as_os_str().is_empty());
        Self {
            dir: set("CELL_CACHE_DIR")
                .or_else(|| set("XDG_CACHE_HOME").map(|d| d.join("cell")))
                .or_else(|| set("HOME").map(|d| d.join(".cache/cell")))
                .unwrap_or_else(|| std::env::temp_dir().join("cell-cache")),
            python: set("CELL_PYTHON").unwrap_or_else(|| "python3".into()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn location(vars: &[(&str, &str)]) -> CacheLocation {
        CacheLocation::from_vars(&|k: &str| {
            vars.iter()
                .find(|(name, _)| *name == k)
                .map(|(_, v)| PathBuf::from(v))
        })
    }

    #[test]
    fn the_cache_follows_the_variables_in_order_and_skips_empty_ones() {
        assert_eq!(
            location(&[("HOME", "/h")]).dir,
            PathBuf::from("/h/.cache/cell")
        );
        assert_eq!(
            location(&[("HOME", "/h"), ("XDG_CACHE_HOME", "/x")]).dir,
            PathBuf::from("/x/cell")
        );
        assert_eq!(
            location(&[("CELL_CACHE_DIR", "/c"), ("XDG_CACHE_HOME", "/x")]).dir,
            PathBuf::from("/c")
        );
        assert_eq!(
            location(&[("CELL_CACHE_DIR", ""), ("HOME", "/h")]).dir,
            PathBuf::from("/h/.cache/cell")
        );
        assert_eq!(location(&[]).python, PathBuf::from("python3"));
        assert_eq!(
            location(&[("CELL_PYTHON", "/py")]).python,
            PathBuf::from("/py")
        );
    }
}
