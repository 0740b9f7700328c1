//! No import circles among source files: within each crate of the workspace, no file uses items
//! of another file that (directly or through other files) uses items of the first.
//!
//! For every workspace member the checker walks the module tree from the crate roots (the
//! library root, `src/main.rs`, `src/bin/*.rs`) along `mod x;` declarations, so only files the
//! compiler builds are read (never `tests/`, `benches/` or `examples/`). In each file it reads:
//! - `use` declarations, including nested and multi-line trees (`use a::{b, c::{d, e as f}};`),
//!   also inside function bodies;
//! - qualified paths in code (`crate::a::B`, `super::B`, `self::a::B`, `a::B` where `a` is a
//!   child module or a module the file imported).
//!
//! Each path is resolved to the file that defines its item: the deepest module file
//! (`a/b.rs` or `a/b/mod.rs`, or an inline `mod` of a file) the path names; when that file only
//! imports the item (a `pub use` re-export, or a private `use` a child reaches through
//! `super::`), the import is followed to the file it comes from. Not dependencies: module
//! declarations, a path naming only a module (`use super::insertion;`), re-exports
//! (`pub use`, `pub(crate) use`) unless the file itself also uses the name, references to other
//! crates, and test code (anything under `#[cfg(test)]`, and inline `mod tests { .. }`).
//!
//! What it does not see (kept simple on purpose; it is a lexer plus a few rules, not rustc):
//! paths produced inside `macro_rules!` bodies (`$crate::..`) or by proc macros; `#[path]`
//! attributes and `include!`; `cfg` other than exactly `#[cfg(test)]` (feature-gated code is
//! read as if the feature were on, `cfg(any(test, ..))` as if it were not test code); names
//! reaching a file through a private glob import (`use super::*` outside tests) count as a use of
//! the glob's module file only when that file defines items itself, and a glob re-export is
//! followed only to find a name another file asks for; paths in doc comments and strings are
//! ignored (intra-doc links are not dependencies). A bare name used without a path is seen
//! through its `use`, which is enough: a file cannot name another file's item without one.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// Lexing

/// Blanks out comments, string and character literals (keeping newlines, so lines still count),
/// leaving only code.
fn strip_comments_and_literals(src: &str) -> String {
    let c: Vec<char> = src.chars().collect();
    let mut out = c.clone();
    let blank = |out: &mut Vec<char>, from: usize, to: usize| {
        for ch in out.iter_mut().take(to.min(c.len())).skip(from) {
            if *ch != '\n' {
                *ch = ' ';
            }
        }
    };
    let ident_char = |ch: char| ch.is_alphanumeric() || ch == '_';
    let mut i = 0;
    while i < c.len() {
        let at_token_start = i == 0 || !ident_char(c[i - 1]);
        if c[i] == '/' && c.get(i + 1) == Some(&'/') {
            let end = (i..c.len()).find(|&k| c[k] == '\n').unwrap_or(c.len());
            blank(&mut out, i, end);
            i = end;
        } else if c[i] == '/' && c.get(i + 1) == Some(&'*') {
            let (mut depth, mut k) = (0usize, i);
            while k < c.len() {
                if c[k] == '/' && c.get(k + 1) == Some(&'*') {
                    depth += 1;
                    k += 2;
                } else if c[k] == '*' && c.get(k + 1) == Some(&'/') {
                    depth -= 1;
                    k += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    k += 1;
                }
            }
            blank(&mut out, i, k);
            i = k;
        } else if at_token_start && (c[i] == 'r' || (c[i] == 'b' && c.get(i + 1) == Some(&'r'))) {
            // A raw string r"..", r#".."#, br#".."#, or just an identifier starting with r/b.
            let start = i;
            let mut k = if c[i] == 'b' { i + 2 } else { i + 1 };
            let mut hashes = 0;
            while c.get(k) == Some(&'#') {
                hashes += 1;
                k += 1;
            }
            if c.get(k) == Some(&'"') {
                k += 1;
                loop {
                    if k >= c.len() {
                        break;
                    }
                    if c[k] == '"' && (1..=hashes).all(|h| c.get(k + h) == Some(&'#')) {
                        k += 1 + hashes;
                        break;
                    }
                    k += 1;
                }
                blank(&mut out, start, k);
                i = k;
            } else {
                i += 1;
                while i < c.len() && ident_char(c[i]) {
                    i += 1;
                }
            }
        } else if c[i] == '"' {
            let mut k = i + 1;
            while k < c.len() && c[k] != '"' {
                k += if c[k] == '\\' { 2 } else { 1 };
            }
            blank(&mut out, i, k + 1);
            i = k + 1;
        } else if c[i] == '\'' {
            // A char literal ('x', '\n', '\u{..}') or a lifetime ('a), which stays.
            if c.get(i + 1) == Some(&'\\') {
                let mut k = i + 3;
                while k < c.len() && c[k] != '\'' {
                    k += 1;
                }
                blank(&mut out, i, k + 1);
                i = k + 1;
            } else if c.get(i + 2) == Some(&'\'') {
                blank(&mut out, i, i + 3);
                i += 3;
            } else {
                i += 1;
            }
        } else if ident_char(c[i]) {
            while i < c.len() && ident_char(c[i]) {
                i += 1;
            }
        } else {
            i += 1;
        }
    }
    out.into_iter().collect()
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Tok {
    Ident(String),
    /// `::`
    PathSep,
    Punct(char),
}

#[derive(Clone, Debug)]
struct Token {
    tok: Tok,
    line: usize,
}

/// Splits code (already stripped of comments and literals) into identifiers, `::` and single
/// punctuation; numbers and lifetimes are dropped.
fn tokenize(code: &str) -> Vec<Token> {
    let c: Vec<char> = code.chars().collect();
    let mut toks = Vec::new();
    let (mut i, mut line) = (0, 1);
    let ident_char = |ch: char| ch.is_alphanumeric() || ch == '_';
    while i < c.len() {
        let ch = c[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch.is_ascii_digit() {
            while i < c.len()
                && (ident_char(c[i])
                    || (c[i] == '.' && c.get(i + 1).is_some_and(char::is_ascii_digit)))
            {
                i += 1;
            }
        } else if ch == '\'' {
            i += 1;
            while i < c.len() && ident_char(c[i]) {
                i += 1;
            }
        } else if ident_char(ch) {
            let start = i;
            while i < c.len() && ident_char(c[i]) {
                i += 1;
            }
            let mut word: String = c[start..i].iter().collect();
            // A raw identifier r#name is the identifier name.
            if word == "r" && c.get(i) == Some(&'#') && c.get(i + 1).is_some_and(|&n| ident_char(n))
            {
                let s = i + 1;
                i = s;
                while i < c.len() && ident_char(c[i]) {
                    i += 1;
                }
                word = c[s..i].iter().collect();
            }
            toks.push(Token {
                tok: Tok::Ident(word),
                line,
            });
        } else if ch == ':' && c.get(i + 1) == Some(&':') {
            toks.push(Token {
                tok: Tok::PathSep,
                line,
            });
            i += 2;
        } else {
            toks.push(Token {
                tok: Tok::Punct(ch),
                line,
            });
            i += 1;
        }
    }
    toks
}

fn is_ident(t: Option<&Token>, word: &str) -> bool {
    matches!(t, Some(Token { tok: Tok::Ident(w), .. }) if w == word)
}

fn is_punct(t: Option<&Token>, ch: char) -> bool {
    matches!(t, Some(Token { tok: Tok::Punct(p), .. }) if *p == ch)
}

fn ident_of(t: Option<&Token>) -> Option<&str> {
    match t {
        Some(Token {
            tok: Tok::Ident(w), ..
        }) => Some(w),
        _ => None,
    }
}

/// Index just past the group opened at `open` (a `(`, `[` or `{`), counting all three kinds.
fn skip_group(toks: &[Token], open: usize) -> usize {
    let mut depth = 0i32;
    let mut k = open;
    while k < toks.len() {
        match toks[k].tok {
            Tok::Punct('(' | '[' | '{') => depth += 1,
            Tok::Punct(')' | ']' | '}') => {
                depth -= 1;
                if depth == 0 {
                    return k + 1;
                }
            }
            _ => {}
        }
        k += 1;
    }
    toks.len()
}

/// Index just past the item starting at `start`: its `;` or its first `{ .. }` block.
fn skip_item(toks: &[Token], start: usize) -> usize {
    let mut k = start;
    // Further attributes of the same item.
    while is_punct(toks.get(k), '#') && is_punct(toks.get(k + 1), '[') {
        k = skip_group(toks, k + 1);
    }
    while k < toks.len() {
        match toks[k].tok {
            Tok::Punct(';') => return k + 1,
            Tok::Punct('{') => return skip_group(toks, k),
            Tok::Punct('(' | '[') => k = skip_group(toks, k),
            _ => k += 1,
        }
    }
    toks.len()
}

/// Marks test code: items under `#[cfg(test)]` and inline `mod tests { .. }` blocks.
fn test_mask(toks: &[Token]) -> Vec<bool> {
    let mut mask = vec![false; toks.len()];
    let mut i = 0;
    while i < toks.len() {
        let cfg_test = is_punct(toks.get(i), '#')
            && is_punct(toks.get(i + 1), '[')
            && is_ident(toks.get(i + 2), "cfg")
            && is_punct(toks.get(i + 3), '(')
            && is_ident(toks.get(i + 4), "test")
            && is_punct(toks.get(i + 5), ')')
            && is_punct(toks.get(i + 6), ']');
        let mod_tests = is_ident(toks.get(i), "mod")
            && is_ident(toks.get(i + 1), "tests")
            && is_punct(toks.get(i + 2), '{');
        let end = if cfg_test {
            skip_item(toks, i + 7)
        } else if mod_tests {
            skip_group(toks, i + 2)
        } else {
            i += 1;
            continue;
        };
        mask[i..end].iter_mut().for_each(|m| *m = true);
        i = end;
    }
    mask
}

// ---------------------------------------------------------------------------------------------
// One file

/// One leaf of a `use` tree: `use a::{b, c as d}` gives `a::b` (name `b`) and `a::c` (name `d`).
#[derive(Clone, Debug, PartialEq)]
struct UseLeaf {
    /// The module the declaration is in, relative to the file's own module (inline `mod`s).
    scope: Vec<String>,
    path: Vec<String>,
    /// The name it brings into scope; `None` for a glob.
    name: Option<String>,
    public: bool,
    line: usize,
}

/// A qualified path in code, `a::b::C`, without generic arguments.
#[derive(Clone, Debug, PartialEq)]
struct PathRef {
    scope: Vec<String>,
    path: Vec<String>,
    line: usize,
}

/// What one file declares and refers to.
#[derive(Debug, Default)]
struct Parsed {
    uses: Vec<UseLeaf>,
    paths: Vec<PathRef>,
    /// Items the file defines, by module (relative scope), name.
    defines: BTreeSet<(Vec<String>, String)>,
    /// Out-of-line modules `mod x;` (relative scope, name).
    mods: Vec<(Vec<String>, String)>,
    /// Inline modules `mod x { .. }` (relative path).
    inline_mods: Vec<Vec<String>>,
    /// Every identifier outside `use` declarations (to see whether a re-exported name is used).
    code_idents: BTreeSet<String>,
}

fn parse_use_tree(
    toks: &[Token],
    i: &mut usize,
    prefix: Vec<String>,
    out: &mut Vec<(Vec<String>, Option<String>, usize)>,
) {
    let mut path = prefix;
    loop {
        match toks.get(*i).map(|t| &t.tok) {
            Some(Tok::PathSep) => *i += 1,
            Some(Tok::Punct('*')) => {
                *i += 1;
                out.push((path, None, toks[*i - 1].line));
                return;
            }
            Some(Tok::Punct('{')) => {
                *i += 1;
                loop {
                    match toks.get(*i).map(|t| &t.tok) {
                        None => return,
                        Some(Tok::Punct('}')) => {
                            *i += 1;
                            return;
                        }
                        Some(Tok::Punct(',')) => *i += 1,
                        _ => {
                            let before = *i;
                            parse_use_tree(toks, i, path.clone(), out);
                            if *i == before {
                                *i += 1;
                            }
                        }
                    }
                }
            }
            Some(Tok::Ident(w)) => {
                path.push(w.clone());
                let line = toks[*i].line;
                *i += 1;
                if matches!(toks.get(*i).map(|t| &t.tok), Some(Tok::PathSep)) {
                    continue;
                }
                let mut name = path.last().cloned();
                if is_ident(toks.get(*i), "as") {
                    name = ident_of(toks.get(*i + 1)).map(str::to_string);
                    *i += 2;
                }
                if path.last().map(String::as_str) == Some("self") {
                    path.pop();
                    if name.as_deref() == Some("self") {
                        name = path.last().cloned();
                    }
                }
                out.push((path, name, line));
                return;
            }
            _ => return,
        }
    }
}

const ITEM_KEYWORDS: [&str; 8] = [
    "fn", "struct", "enum", "trait", "type", "const", "static", "union",
];

/// Keywords after which an identifier is being defined, not used.
const DEFINERS: [&str; 10] = [
    "fn", "struct", "enum", "trait", "type", "const", "static", "union", "mod", "let",
];

fn parse_file(src: &str) -> Parsed {
    let toks = tokenize(&strip_comments_and_literals(src));
    let mask = test_mask(&toks);
    let mut parsed = Parsed::default();
    // Inline modules open: (name, brace depth inside it).
    let mut inline: Vec<(String, i32)> = Vec::new();
    let mut depth = 0i32;
    let mut i = 0;
    let scope_of =
        |inline: &Vec<(String, i32)>| inline.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    while i < toks.len() {
        if mask[i] {
            i += 1;
            continue;
        }
        let module_depth = inline.last().map_or(0, |(_, d)| *d);
        match &toks[i].tok {
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => {
                if inline.last().is_some_and(|(_, d)| *d == depth) {
                    inline.pop();
                }
                depth -= 1;
            }
            Tok::Ident(w) if w == "use" => {
                // Visibility: `pub use` or `pub(..) use`.
                let public = is_ident(i.checked_sub(1).and_then(|k| toks.get(k)), "pub")
                    || (is_punct(i.checked_sub(1).and_then(|k| toks.get(k)), ')')
                        && (0..i.saturating_sub(1))
                            .rev()
                            .find(|&k| is_punct(toks.get(k), '('))
                            .is_some_and(|k| {
                                is_ident(k.checked_sub(1).and_then(|p| toks.get(p)), "pub")
                            }));
                let mut k = i + 1;
                let mut leaves = Vec::new();
                parse_use_tree(&toks, &mut k, Vec::new(), &mut leaves);
                while k < toks.len() && !is_punct(toks.get(k), ';') {
                    k += 1;
                }
                let scope = scope_of(&inline);
                for (path, name, line) in leaves {
                    parsed.uses.push(UseLeaf {
                        scope: scope.clone(),
                        path,
                        name,
                        public,
                        line,
                    });
                }
                i = k + 1;
                continue;
            }
            Tok::Ident(w) if w == "mod" => {
                if let Some(name) = ident_of(toks.get(i + 1)) {
                    let mut path = scope_of(&inline);
                    if is_punct(toks.get(i + 2), ';') {
                        parsed.mods.push((path, name.to_string()));
                    } else if is_punct(toks.get(i + 2), '{') {
                        path.push(name.to_string());
                        parsed.inline_mods.push(path);
                        inline.push((name.to_string(), depth + 1));
                    }
                    i += 2;
                    continue;
                }
            }
            Tok::Ident(w)
                if depth == module_depth
                    && (ITEM_KEYWORDS.contains(&w.as_str()) || w == "macro_rules") =>
            {
                let name_at = if w == "macro_rules" { i + 2 } else { i + 1 };
                if let Some(name) =
                    ident_of(toks.get(name_at)).filter(|n| !ITEM_KEYWORDS.contains(n))
                {
                    parsed.defines.insert((scope_of(&inline), name.to_string()));
                }
            }
            Tok::Ident(w) => {
                // A name in use: not a field or method (`.x`), a definition (`fn x`) or a field
                // or binding with its type (`x: T`).
                let prev = i.checked_sub(1).and_then(|k| toks.get(k));
                let defined = ident_of(prev).is_some_and(|p| DEFINERS.contains(&p));
                if !is_punct(prev, '.') && !defined && !is_punct(toks.get(i + 1), ':') {
                    parsed.code_idents.insert(w.clone());
                }
                let path_start = matches!(toks.get(i + 1).map(|t| &t.tok), Some(Tok::PathSep))
                    && ident_of(toks.get(i + 2)).is_some()
                    && !matches!(
                        i.checked_sub(1).and_then(|k| toks.get(k)).map(|t| &t.tok),
                        Some(Tok::PathSep | Tok::Punct('$'))
                    );
                if path_start {
                    let line = toks[i].line;
                    let mut path = vec![w.clone()];
                    let mut k = i + 1;
                    while matches!(toks.get(k).map(|t| &t.tok), Some(Tok::PathSep)) {
                        match ident_of(toks.get(k + 1)) {
                            Some(seg) => {
                                path.push(seg.to_string());
                                k += 2;
                            }
                            None => break,
                        }
                    }
                    parsed.paths.push(PathRef {
                        scope: scope_of(&inline),
                        path,
                        line,
                    });
                    i = k;
                    continue;
                }
            }
            _ => {}
        }
        i += 1;
    }
    parsed
}

// ---------------------------------------------------------------------------------------------
// One crate

/// A source file of a crate target.
#[derive(Debug)]
struct File {
    /// Path relative to the workspace root, for messages.
    rel: String,
    /// Its module path in its target (`[]` for the root).
    module: Vec<String>,
    target: usize,
    parsed: Parsed,
}

/// A dependency edge's first example, for the message.
#[derive(Debug, Clone)]
struct Example {
    line: usize,
    text: String,
}

#[derive(Debug, Default)]
struct Graph {
    files: Vec<File>,
    /// (target, module path) → file defining that module (inline modules map to their file).
    modules: BTreeMap<(usize, Vec<String>), usize>,
    /// from → to → first example.
    edges: BTreeMap<usize, BTreeMap<usize, Example>>,
}

/// Reads a crate's targets from their root files along `mod x;` declarations. `read` returns a
/// file's text, `None` when it does not exist.
fn load_crate(roots: &[(PathBuf, String)], read: &dyn Fn(&Path) -> Option<String>) -> Graph {
    let mut g = Graph::default();
    for (target, (root, rel_root)) in roots.iter().enumerate() {
        let mut queue = vec![(root.clone(), rel_root.clone(), Vec::<String>::new())];
        while let Some((path, rel, module)) = queue.pop() {
            let Some(src) = read(&path) else { continue };
            let parsed = parse_file(&src);
            let idx = g.files.len();
            // Children of a.rs live in a/, children of mod.rs/lib.rs/main.rs beside it.
            let stem = path
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or_default()
                .to_string();
            let is_dir_owner = module.is_empty() || stem == "mod";
            let dir = |p: &Path| -> PathBuf {
                let parent = p.parent().map(Path::to_path_buf).unwrap_or_default();
                if is_dir_owner {
                    parent
                } else {
                    parent.join(&stem)
                }
            };
            let (child_dir, rel_child_dir) = (dir(&path), dir(Path::new(&rel)));
            for (scope, name) in &parsed.mods {
                let mut d = child_dir.clone();
                let mut rd = rel_child_dir.clone();
                for s in scope {
                    d.push(s);
                    rd.push(s);
                }
                let mut child_module = module.clone();
                child_module.extend(scope.iter().cloned());
                child_module.push(name.clone());
                let flat = d.join(format!("{name}.rs"));
                let (file, rel_file) = if read(&flat).is_some() {
                    (flat, rd.join(format!("{name}.rs")))
                } else {
                    (d.join(name).join("mod.rs"), rd.join(name).join("mod.rs"))
                };
                queue.push((file, rel_file.to_string_lossy().into_owned(), child_module));
            }
            for inline in &parsed.inline_mods {
                let mut m = module.clone();
                m.extend(inline.iter().cloned());
                g.modules.insert((target, m), idx);
            }
            g.modules.insert((target, module.clone()), idx);
            g.files.push(File {
                rel,
                module,
                target,
                parsed,
            });
        }
    }
    g.build_edges();
    g
}

impl Graph {
    /// Absolute module path of a path written in `file` inside `scope`, or `None` when it does
    /// not start in this crate. `aliases` are the file's imported modules.
    fn absolute(
        &self,
        file: usize,
        scope: &[String],
        path: &[String],
        aliases: &BTreeMap<String, Vec<String>>,
    ) -> Option<Vec<String>> {
        let f = &self.files[file];
        let mut here: Vec<String> = f.module.iter().chain(scope).cloned().collect();
        let first = path.first()?;
        match first.as_str() {
            "crate" => Some(path[1..].to_vec()),
            "self" => {
                here.extend(path[1..].iter().cloned());
                Some(here)
            }
            "super" => {
                let mut rest = path;
                while rest.first().map(String::as_str) == Some("super") {
                    here.pop()?;
                    rest = &rest[1..];
                }
                here.extend(rest.iter().cloned());
                Some(here)
            }
            _ => {
                let mut child = here.clone();
                child.push(first.clone());
                if self.modules.contains_key(&(f.target, child)) {
                    here.extend(path.iter().cloned());
                    Some(here)
                } else if let Some(module) = aliases.get(first) {
                    let mut abs = module.clone();
                    abs.extend(path[1..].iter().cloned());
                    Some(abs)
                } else {
                    None
                }
            }
        }
    }

    /// The module file `abs` lands on (its deepest module prefix) and the length of that prefix;
    /// `None` when it names a module itself or nothing of this crate.
    fn landing(&self, target: usize, abs: &[String]) -> Option<(usize, usize)> {
        let (n, file) = (0..=abs.len()).rev().find_map(|n| {
            self.modules
                .get(&(target, abs[..n].to_vec()))
                .map(|&f| (n, f))
        })?;
        (n < abs.len()).then_some((n, file))
    }

    /// The file whose item `abs` names: the module file it lands on, or, when that file only
    /// imports the name, the file the import comes from.
    fn locate(&self, target: usize, abs: &[String]) -> Option<usize> {
        let (_, file) = self.landing(target, abs)?;
        Some(self.defining(target, abs, 0).unwrap_or(file))
    }

    /// The file that defines the item `abs` names, following imports; `None` if none is found.
    fn defining(&self, target: usize, abs: &[String], hops: usize) -> Option<usize> {
        let (prefix_len, file) = self.landing(target, abs)?;
        let name = &abs[prefix_len];
        let f = &self.files[file];
        let scope: Vec<String> = abs[f.module.len()..prefix_len].to_vec();
        if f.parsed.defines.contains(&(scope.clone(), name.clone())) {
            return Some(file);
        }
        if hops > 16 {
            return None;
        }
        let aliases = self.aliases(file);
        // Imported by name (a re-export, or a private import a child reaches through super::).
        let named = f
            .parsed
            .uses
            .iter()
            .filter(|u| u.scope == scope && u.name.as_ref() == Some(name));
        // Or through a glob: the first glob whose module has the name.
        let globs = f
            .parsed
            .uses
            .iter()
            .filter(|u| u.scope == scope && u.name.is_none());
        named.chain(globs).find_map(|u| {
            let mut to = self.absolute(file, &u.scope, &u.path, &aliases)?;
            let rest = if u.name.is_some() {
                prefix_len + 1
            } else {
                prefix_len
            };
            to.extend(abs[rest..].iter().cloned());
            self.defining(target, &to, hops + 1)
        })
    }

    /// Modules a file imports by name (`use super::insertion;`), name → absolute module path.
    fn aliases(&self, file: usize) -> BTreeMap<String, Vec<String>> {
        let f = &self.files[file];
        let mut aliases = BTreeMap::new();
        for _ in 0..2 {
            for u in &f.parsed.uses {
                let (Some(name), Some(abs)) =
                    (&u.name, self.absolute(file, &u.scope, &u.path, &aliases))
                else {
                    continue;
                };
                if self.modules.contains_key(&(f.target, abs.clone())) {
                    aliases.insert(name.clone(), abs);
                }
            }
        }
        aliases
    }

    fn add_edge(&mut self, from: usize, to: usize, line: usize, text: String) {
        if from == to {
            return;
        }
        let e = self
            .edges
            .entry(from)
            .or_default()
            .entry(to)
            .or_insert(Example {
                line,
                text: text.clone(),
            });
        if line < e.line {
            *e = Example { line, text };
        }
    }

    fn build_edges(&mut self) {
        let mut found = Vec::new();
        for file in 0..self.files.len() {
            let f = &self.files[file];
            let aliases = self.aliases(file);
            for u in &f.parsed.uses {
                let text = format!(
                    "use {}{}",
                    u.path.join("::"),
                    if u.name.is_none() { "::*" } else { "" }
                );
                // A re-export is no dependency, unless the file uses the name itself.
                if u.public
                    && u.name
                        .as_ref()
                        .is_none_or(|n| !f.parsed.code_idents.contains(n))
                {
                    continue;
                }
                let Some(abs) = self.absolute(file, &u.scope, &u.path, &aliases) else {
                    continue;
                };
                let to = if u.name.is_some() {
                    self.locate(f.target, &abs)
                } else {
                    // A glob: its module's file, when that file defines items itself.
                    self.modules
                        .get(&(f.target, abs))
                        .copied()
                        .filter(|&m| !self.files[m].parsed.defines.is_empty())
                };
                if let Some(to) = to {
                    found.push((file, to, u.line, text));
                }
            }
            for p in &f.parsed.paths {
                let Some(abs) = self.absolute(file, &p.scope, &p.path, &aliases) else {
                    continue;
                };
                if let Some(to) = self.locate(f.target, &abs) {
                    found.push((file, to, p.line, p.path.join("::")));
                }
            }
        }
        for (from, to, line, text) in found {
            self.add_edge(from, to, line, text);
        }
    }

    /// Strongly connected components of more than one file (Tarjan), each sorted by path.
    fn cycles(&self) -> Vec<Vec<usize>> {
        struct Tarjan<'a> {
            g: &'a Graph,
            index: Vec<Option<usize>>,
            low: Vec<usize>,
            on_stack: Vec<bool>,
            stack: Vec<usize>,
            next: usize,
            out: Vec<Vec<usize>>,
        }
        impl Tarjan<'_> {
            fn visit(&mut self, v: usize) {
                self.index[v] = Some(self.next);
                self.low[v] = self.next;
                self.next += 1;
                self.stack.push(v);
                self.on_stack[v] = true;
                let succ: Vec<usize> = self
                    .g
                    .edges
                    .get(&v)
                    .map(|m| m.keys().copied().collect())
                    .unwrap_or_default();
                for w in succ {
                    match self.index[w] {
                        None => {
                            self.visit(w);
                            self.low[v] = self.low[v].min(self.low[w]);
                        }
                        Some(iw) if self.on_stack[w] => self.low[v] = self.low[v].min(iw),
                        Some(_) => {}
                    }
                }
                if Some(self.low[v]) == self.index[v] {
                    let mut scc = Vec::new();
                    while let Some(w) = self.stack.pop() {
                        self.on_stack[w] = false;
                        scc.push(w);
                        if w == v {
                            break;
                        }
                    }
                    if scc.len() > 1 {
                        scc.sort_by(|a, b| self.g.files[*a].rel.cmp(&self.g.files[*b].rel));
                        self.out.push(scc);
                    }
                }
            }
        }
        let n = self.files.len();
        let mut t = Tarjan {
            g: self,
            index: vec![None; n],
            low: vec![0; n],
            on_stack: vec![false; n],
            stack: Vec::new(),
            next: 0,
            out: Vec::new(),
        };
        for v in 0..n {
            if t.index[v].is_none() {
                t.visit(v);
            }
        }
        let mut out = t.out;
        out.sort_by(|a, b| self.files[a[0]].rel.cmp(&self.files[b[0]].rel));
        out
    }

    /// A cycle, its files and the edges inside it with one example each.
    fn describe(&self, scc: &[usize]) -> String {
        let mut s = String::new();
        for &f in scc {
            s += &format!("    {}\n", self.files[f].rel);
        }
        s += "  edges (file:line -> file, an example):\n";
        for &from in scc {
            for (to, ex) in self.edges.get(&from).into_iter().flatten() {
                if scc.contains(to) {
                    s += &format!(
                        "    {}:{} -> {}   `{}`\n",
                        self.files[from].rel, ex.line, self.files[*to].rel, ex.text
                    );
                }
            }
        }
        s
    }
}

// ---------------------------------------------------------------------------------------------
// The workspace

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lives in the workspace")
        .to_path_buf()
}

/// `members = [..]` of the workspace manifest.
fn members(root: &Path) -> Vec<String> {
    let manifest = fs::read_to_string(root.join("Cargo.toml")).expect("workspace Cargo.toml");
    let start = manifest.find("members").expect("a members list");
    let list = &manifest[start..];
    let list = &list[..list.find(']').expect("the members list ends")];
    list.split('"')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// A member's root files: its library (`[lib] path`, or `src/lib.rs`), `src/main.rs`, `src/bin/*.rs`.
fn crate_roots(root: &Path, member: &str) -> Vec<(PathBuf, String)> {
    let dir = root.join(member);
    let manifest = fs::read_to_string(dir.join("Cargo.toml")).unwrap_or_default();
    let mut lib = "src/lib.rs".to_string();
    let mut section = "";
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            section = line;
        } else if section == "[lib]" && line.starts_with("path") {
            lib = line.split('"').nth(1).unwrap_or(&lib).to_string();
        }
    }
    let mut rels = vec![lib, "src/main.rs".to_string()];
    if let Ok(bins) = fs::read_dir(dir.join("src/bin")) {
        let mut bins: Vec<String> = bins
            .flatten()
            .filter_map(|e| {
                e.file_name()
                    .to_str()
                    .filter(|n| n.ends_with(".rs"))
                    .map(|n| format!("src/bin/{n}"))
            })
            .collect();
        bins.sort();
        rels.extend(bins);
    }
    rels.into_iter()
        .filter(|r| dir.join(r).is_file())
        .map(|r| (dir.join(&r), format!("{member}/{r}")))
        .collect()
}

#[test]
fn no_import_cycles_among_files() {
    let root = workspace_root();
    let members = members(&root);
    for expected in [
        "perception",
        "robots",
        "sim",
        "cell",
        "tests",
        "mujoco-provision",
    ] {
        assert!(
            members.iter().any(|m| m == expected),
            "workspace member {expected} not found in {members:?}"
        );
    }
    let read = |p: &Path| fs::read_to_string(p).ok();
    let mut report = Vec::new();
    let (mut files, mut edges) = (0, 0);
    for member in &members {
        let roots = crate_roots(&root, member);
        assert!(!roots.is_empty(), "{member}: no crate root found");
        let g = load_crate(&roots, &read);
        files += g.files.len();
        edges += g.edges.values().map(BTreeMap::len).sum::<usize>();
        for scc in g.cycles() {
            report.push(format!(
                "{member}: {} files in a circle\n{}",
                scc.len(),
                g.describe(&scc)
            ));
        }
    }
    println!(
        "import graph: {files} files, {edges} file-to-file dependencies, {} circles",
        report.len()
    );
    assert!(
        report.is_empty(),
        "{} import circle(s) among files; move the shared items to their own file or to the \
         lower-level file so the dependencies point one way:\n\n{}",
        report.len(),
        report.join("\n")
    );
}

// ---------------------------------------------------------------------------------------------
// The checker's own checks

fn crate_of(files: &[(&str, &str)]) -> Graph {
    let map: BTreeMap<PathBuf, String> = files
        .iter()
        .map(|(p, s)| (PathBuf::from(p), s.to_string()))
        .collect();
    load_crate(
        &[(PathBuf::from("src/lib.rs"), "src/lib.rs".to_string())],
        &|p: &Path| map.get(p).cloned(),
    )
}

fn names(g: &Graph, scc: &[usize]) -> Vec<String> {
    scc.iter().map(|&f| g.files[f].rel.clone()).collect()
}

#[test]
fn use_trees_multi_line_nested_aliases_and_globs() {
    let p = parse_file(
        "pub use a::{\n    b,\n    c::{d, e as f, self},\n};\nuse g::*; // use h::i;\nfn x() { let s = \"use j::k;\"; }\n",
    );
    let got: Vec<(String, Option<String>, bool, usize)> = p
        .uses
        .iter()
        .map(|u| (u.path.join("::"), u.name.clone(), u.public, u.line))
        .collect();
    assert_eq!(
        got,
        vec![
            ("a::b".into(), Some("b".into()), true, 2),
            ("a::c::d".into(), Some("d".into()), true, 3),
            ("a::c::e".into(), Some("f".into()), true, 3),
            ("a::c".into(), Some("c".into()), true, 3),
            ("g".into(), None, false, 5),
        ]
    );
}

#[test]
fn test_code_comments_and_literals_are_not_read() {
    let p = parse_file(
        "/* crate::a::B */ fn f() -> char { '\"' }\n#[cfg(test)]\nuse crate::x::Y;\n#[cfg(test)]\nmod tests {\n    use crate::z::W;\n}\nfn g<'a>(s: &'a str) { crate::q::R::new(r#\"crate::no\"#); }\n",
    );
    assert!(p.uses.is_empty(), "{:?}", p.uses);
    assert_eq!(
        p.paths
            .iter()
            .map(|p| p.path.join("::"))
            .collect::<Vec<_>>(),
        vec!["crate::q::R::new"]
    );
    assert!(
        p.defines.contains(&(vec![], "f".to_string()))
            && p.defines.contains(&(vec![], "g".to_string()))
    );
}

#[test]
fn finds_a_circle_through_paths_and_follows_re_exports() {
    let g = crate_of(&[
        ("src/lib.rs", "mod a;\nmod b;\nmod c;\n"),
        // b re-exports c's item: a's use of it is a use of c, not of b.
        ("src/a.rs", "use crate::b::Thing;\npub struct A;\n"),
        ("src/b.rs", "pub use crate::c::Thing;\n"),
        (
            "src/c.rs",
            "pub struct Thing;\nfn f() -> crate::a::A { crate::a::A }\n",
        ),
    ]);
    let cycles: Vec<Vec<String>> = g.cycles().iter().map(|s| names(&g, s)).collect();
    assert_eq!(
        cycles,
        vec![vec!["src/a.rs".to_string(), "src/c.rs".to_string()]]
    );
    let text = g.describe(&g.cycles()[0]);
    assert!(
        text.contains("src/a.rs:1 -> src/c.rs   `use crate::b::Thing`"),
        "{text}"
    );
    assert!(
        text.contains("src/c.rs:2 -> src/a.rs   `crate::a::A`"),
        "{text}"
    );
}

#[test]
fn module_imports_declarations_and_one_way_uses_are_no_circle() {
    let g = crate_of(&[
        ("src/lib.rs", "pub mod m;\npub use m::Leaf;\n"),
        (
            "src/m/mod.rs",
            "mod leaf;\nmod user;\npub use leaf::Leaf;\n",
        ),
        ("src/m/leaf.rs", "pub struct Leaf;\n"),
        (
            "src/m/user.rs",
            "use super::leaf;\nuse super::Leaf as L;\nfn f() -> leaf::Leaf { L }\n#[cfg(test)]\nmod tests { use crate::m::user; }\n",
        ),
    ]);
    assert!(g.cycles().is_empty());
    let user = g
        .files
        .iter()
        .position(|f| f.rel == "src/m/user.rs")
        .unwrap();
    let leaf = g
        .files
        .iter()
        .position(|f| f.rel == "src/m/leaf.rs")
        .unwrap();
    assert_eq!(
        g.edges[&user].keys().copied().collect::<Vec<_>>(),
        vec![leaf]
    );
    assert_eq!(g.edges.values().map(BTreeMap::len).sum::<usize>(), 1);
}

#[test]
fn a_parent_that_uses_what_it_re_exports_depends_on_it() {
    // The camera pattern: children use the parent's error, the parent calls a child.
    let g = crate_of(&[
        ("src/lib.rs", "pub mod cam;\n"),
        (
            "src/cam/mod.rs",
            "mod folder;\npub use folder::Folder;\npub struct CamError;\npub fn open() -> Folder { Folder }\n",
        ),
        (
            "src/cam/folder.rs",
            "use super::CamError;\npub struct Folder;\n",
        ),
    ]);
    let cycles: Vec<Vec<String>> = g.cycles().iter().map(|s| names(&g, s)).collect();
    assert_eq!(
        cycles,
        vec![vec![
            "src/cam/folder.rs".to_string(),
            "src/cam/mod.rs".to_string()
        ]]
    );
}
