//! The docs are checked like code (docs/maintainers/docs.md):
//! - every relative link and image in the Markdown pages resolves, anchors included;
//! - the mdBook summary lists every page under docs/, and nothing else;
//! - every shell block (```` ```sh ````) of the README and the guides runs, in order, page by page,
//!   with `cell` this build's binary and every size capped to a small input ([`SMALL`]);
//!   a block that cannot run here (a real arm, PyTorch) is tagged ```` ```sh no-run ```` and
//!   says why on its first line.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::Instant;

use pulldown_cmark::{CodeBlockKind, Event, Parser, Tag, TagEnd};

mod support;

use support::root as repo;

/// Every Markdown page of the docs: README, docs/**, and the READMEs beside data and training.
fn pages() -> Vec<PathBuf> {
    let root = repo();
    let mut out = vec![
        root.join("README.md"),
        root.join("scenarios/README.md"),
        root.join("training/README.md"),
    ];
    out.extend(markdown_under(&root.join("docs")));
    out
}

fn markdown_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("read docs folder") {
            let path = entry.expect("docs entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// 1-based line of byte offset `at` in `text`.
fn line_of(text: &str, at: usize) -> usize {
    text[..at].matches('\n').count() + 1
}

/// The anchors GitHub gives a page's headings: lower case, punctuation dropped, spaces to
/// hyphens, and `-1`, `-2` … on repeats.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut heading: Option<String> = None;
    for event in Parser::new(text) {
        match event {
            Event::Start(Tag::Heading { .. }) => heading = Some(String::new()),
            Event::Text(t) | Event::Code(t) => {
                if let Some(h) = heading.as_mut() {
                    h.push_str(&t);
                }
            }
            Event::End(TagEnd::Heading(_)) => {
                let h = heading.take().unwrap_or_default();
                let slug: String = h
                    .to_lowercase()
                    .chars()
                    .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
                    .map(|c| if c == ' ' { '-' } else { c })
                    .collect();
                let n = seen.entry(slug.clone()).or_insert(0);
                out.insert(if *n == 0 {
                    slug.clone()
                } else {
                    format!("{slug}-{n}")
                });
                *n += 1;
            }
            _ => {}
        }
    }
    out
}

/// Relative links and images of a page: (line, destination).
fn links(text: &str) -> Vec<(usize, String)> {
    Parser::new(text)
        .into_offset_iter()
        .filter_map(|(event, range)| match event {
            Event::Start(Tag::Link { dest_url, .. } | Tag::Image { dest_url, .. }) => {
                Some((line_of(text, range.start), dest_url.to_string()))
            }
            _ => None,
        })
        .filter(|(_, d)| !d.contains("://") && !d.starts_with("mailto:"))
        .collect()
}

#[test]
fn every_link_and_anchor_resolves() {
    let mut broken = Vec::new();
    // Each target's anchors, parsed once however many links point into it.
    let mut anchors_of: BTreeMap<PathBuf, BTreeSet<String>> = BTreeMap::new();
    for page in pages() {
        let text = read(&page);
        for (line, dest) in links(&text) {
            let (path, anchor) = dest.split_once('#').unwrap_or((&dest, ""));
            let target = if path.is_empty() {
                page.clone()
            } else {
                page.parent().expect("a page has a folder").join(path)
            };
            let at = format!("{}:{line}: {dest}", page.display());
            if !target.exists() {
                broken.push(format!("{at}: no such file"));
            } else if !anchor.is_empty() {
                if target.extension().is_some_and(|e| e == "md") {
                    let known = anchors_of
                        .entry(target.clone())
                        .or_insert_with(|| anchors(&read(&target)));
                    if !known.contains(anchor) {
                        broken.push(format!("{at}: no heading with that anchor"));
                    }
                } else {
                    broken.push(format!("{at}: an anchor into a file that is not Markdown"));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_book_summary_lists_every_page() {
    let docs = repo().join("docs");
    let summary = docs.join("SUMMARY.md");
    let listed: BTreeSet<PathBuf> = links(&read(&summary))
        .into_iter()
        .map(|(_, d)| docs.join(d))
        .collect();
    let pages: BTreeSet<PathBuf> = markdown_under(&docs)
        .into_iter()
        .filter(|p| *p != summary)
        .collect();
    let missing: Vec<_> = pages.difference(&listed).collect();
    let stray: Vec<_> = listed.difference(&pages).collect();
    assert!(
        missing.is_empty() && stray.is_empty(),
        "docs/SUMMARY.md must list every page under docs/: not listed {missing:?}; listed but absent {stray:?}"
    );
}

/// A fenced shell block of a page.
#[derive(Debug)]
struct ShellBlock {
    line: usize,
    run: bool,
    text: String,
}

fn shell_blocks(text: &str) -> Vec<ShellBlock> {
    let mut out = Vec::new();
    let mut current: Option<ShellBlock> = None;
    for (event, range) in Parser::new(text).into_offset_iter() {
        match event {
            Event::Start(Tag::CodeBlock(CodeBlockKind::Fenced(info))) => {
                let words: Vec<&str> = info.split([' ', ',']).filter(|w| !w.is_empty()).collect();
                if words.first() == Some(&"sh") {
                    current = Some(ShellBlock {
                        line: line_of(text, range.start),
                        run: !words.contains(&"no-run"),
                        text: String::new(),
                    });
                }
            }
            Event::Text(t) => {
                if let Some(b) = current.as_mut() {
                    b.text.push_str(&t);
                }
            }
            Event::End(TagEnd::CodeBlock) => out.extend(current.take()),
            _ => {}
        }
    }
    out
}

/// Small inputs: the largest value each size option of a subcommand may take in CI, and the
/// value it gets when the command does not give one (its default being larger).
const SMALL: &[(&str, &str, u64)] = &[
    ("run", "--episodes", 2),
    ("regress", "--episodes", 2),
    ("dataset", "--train-crops", 2),
    ("dataset", "--test-crops", 2),
    ("dataset", "--train-overviews", 1),
    ("dataset", "--test-overviews", 1),
    ("dataset", "--train-feeder", 2),
    ("dataset", "--test-feeder", 2),
    ("eval", "--limit", 2),
    ("prepare", "--drops", 200),
    ("ablate", "--trials", 5),
    ("virtual-ur", "--duration-s", 60),
];

/// Options whose default is zero: capped when given, not added when absent.
const ZERO_BY_DEFAULT: &[&str] = &["--train-feeder", "--test-feeder"];

/// `cell ARGS` with every size capped by [`SMALL`].
fn small(args: &[String]) -> Vec<String> {
    let sub = args
        .iter()
        .find(|a| !a.starts_with('-') && *a != "parts")
        .cloned()
        .unwrap_or_default();
    let mut out = args.to_vec();
    for (_, option, cap) in SMALL.iter().filter(|(s, _, _)| *s == sub) {
        let cap = if sub == "run" && out.iter().any(|a| a == "virtual-ur") {
            1
        } else {
            *cap
        };
        match out.iter().position(|a| a == option) {
            Some(i) if i + 1 < out.len() => {
                let given: u64 = out[i + 1].parse().unwrap_or(cap);
                out[i + 1] = given.min(cap).to_string();
            }
            _ if !ZERO_BY_DEFAULT.contains(option) => {
                out.push((*option).to_string());
                out.push(cap.to_string());
            }
            _ => {}
        }
    }
    out
}

/// Drops a trailing `# comment` outside quotes.
fn strip_comment(line: &str) -> &str {
    let (mut single, mut double) = (false, false);
    let mut previous = ' ';
    for (i, c) in line.char_indices() {
        match c {
            '\'' if !double => single = !single,
            '"' if !single => double = !double,
            '#' if !single && !double && previous.is_whitespace() => return line[..i].trim_end(),
            _ => {}
        }
        previous = c;
    }
    line
}

/// The block as the script CI runs: continuation lines joined, comments dropped, `cell`
/// commands (and `cargo run --release -p cell --`) capped to small inputs, and the two commands
/// CI is itself (`cargo test --workspace`, `cargo build --release -p cell`) left out.
fn ci_script(block: &str) -> Vec<String> {
    let joined = block.replace("\\\n", " ");
    let mut out = Vec::new();
    for raw in joined.lines() {
        let line = strip_comment(raw.trim());
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if line == "cargo test --workspace" || line == "cargo build --release -p cell" {
            continue;
        }
        let line = line
            .strip_prefix("cargo run --release -p cell -- ")
            .map(|rest| format!("cell {rest}"))
            .unwrap_or_else(|| line.to_string());
        let (command, background) = match line.strip_suffix('&') {
            Some(c) => (c.trim_end().to_string(), " &"),
            None => (line, ""),
        };
        if command.starts_with("cell ") {
            let words = shlex::split(&command)
                .unwrap_or_else(|| panic!("cannot split the command {command:?}"));
            let capped = small(&words[1..]);
            let quoted = shlex::try_join(capped.iter().map(String::as_str))
                .expect("arguments quote for the shell");
            out.push(format!("cell {quoted}{background}"));
        } else {
            out.push(format!("{command}{background}"));
        }
    }
    out
}

/// A working folder like a checkout: its own copy of `scenarios/` (commands write into it),
/// and `scripts/` and `target/` (for the provisioned venvs) of this one.
fn workspace() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temporary folder");
    copy_tree(&repo().join("scenarios"), &dir.path().join("scenarios"));
    for shared in ["deploy", "scripts", "target", "training"] {
        std::os::unix::fs::symlink(repo().join(shared), dir.path().join(shared))
            .expect("link into the checkout");
    }
    let bin = dir.path().join(".bin");
    std::fs::create_dir(&bin).expect("bin folder");
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_cell"), bin.join("cell")).expect("link cell");
    dir
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("create folder");
    for entry in std::fs::read_dir(from).expect("read folder") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("file type").is_dir() {
            copy_tree(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy file");
        }
    }
}

/// The ports `cell virtual-ur` and ur_rtde use are fixed: one page at a time.
static ONE_PAGE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Runs every runnable shell block of `page` (relative to the repository) in order in one fresh
/// working folder; returns how many commands ran.
fn run_page(page: &str) -> usize {
    let _turn = ONE_PAGE_AT_A_TIME
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    let path = repo().join(page);
    let text = read(&path);
    let work = workspace();
    let path_var = format!(
        "{}:{}",
        work.path().join(".bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut commands = 0;
    for block in shell_blocks(&text) {
        let at = format!("{page}:{}", block.line);
        if !block.run {
            assert!(
                block.text.starts_with("# not run in CI:"),
                "{at}: a no-run block must say why on its first line (`# not run in CI: …`)"
            );
            continue;
        }
        let script = ci_script(&block.text);
        commands += script.len();
        let started = Instant::now();
        eprintln!("{at}:\n  {}", script.join("\n  "));
        let out = Command::new("timeout")
            .arg("900")
            .arg("bash")
            .arg("-c")
            .arg(format!(
                "set -euo pipefail\ntrap 'kill $(jobs -p) 2>/dev/null || true' EXIT\n{}",
                script.join("\n")
            ))
            .current_dir(work.path())
            .env("PATH", &path_var)
            .output()
            .expect("run bash");
        eprintln!("  ({:.1} s)", started.elapsed().as_secs_f64());
        assert!(
            out.status.success(),
            "{at}: the block failed ({}):\n{}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            out.status,
            script.join("\n"),
            tail(&out.stdout),
            tail(&out.stderr)
        );
    }
    commands
}

fn tail(bytes: &[u8]) -> String {
    let text = String::from_utf8_lossy(bytes);
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(40)..].join("\n")
}

/// Every guide is run by one of the tests below.
#[test]
fn every_guide_has_its_commands_test() {
    let tested = [
        "simulate.md",
        "production.md",
        "commission.md",
        "perception.md",
        "add-part.md",
        "assembly-sequence.md",
        "regress.md",
        "scale.md",
        "seat-verification.md",
    ];
    for guide in markdown_under(&repo().join("docs/guides")) {
        let name = guide.file_name().expect("a file").to_string_lossy();
        assert!(
            tested.contains(&name.as_ref()),
            "docs/guides/{name} has no test running its commands in cell/tests/docs.rs"
        );
    }
}

#[test]
fn readme_commands_run() {
    assert!(run_page("README.md") >= 6);
}

#[test]
fn simulate_guide_commands_run() {
    assert!(run_page("docs/guides/simulate.md") > 0);
}

#[test]
fn production_guide_commands_run() {
    assert!(run_page("docs/guides/production.md") > 0);
}

#[test]
fn commission_guide_commands_run() {
    assert!(run_page("docs/guides/commission.md") > 0);
}

#[test]
fn perception_guide_commands_run() {
    assert!(run_page("docs/guides/perception.md") > 0);
}

#[test]
fn add_part_guide_commands_run() {
    assert!(run_page("docs/guides/add-part.md") > 0);
}

#[test]
fn assembly_sequence_guide_commands_run() {
    assert!(run_page("docs/guides/assembly-sequence.md") > 0);
}

#[test]
fn regress_guide_commands_run() {
    assert!(run_page("docs/guides/regress.md") > 0);
}

#[test]
fn scale_guide_commands_run() {
    assert!(run_page("docs/guides/scale.md") > 0);
}

#[test]
fn seat_verification_guide_commands_run() {
    assert!(run_page("docs/guides/seat-verification.md") > 0);
}

#[test]
fn small_inputs_cap_sizes_and_keep_everything_else() {
    let words = |s: &str| -> Vec<String> { s.split(' ').map(String::from).collect() };
    assert_eq!(
        small(&words("run scenarios/a.toml --episodes 1000 --out x")),
        words("run scenarios/a.toml --episodes 2 --out x")
    );
    assert_eq!(
        small(&words("run scenarios/a.toml")),
        words("run scenarios/a.toml --episodes 2")
    );
    assert_eq!(
        small(&words("run a.toml --robot virtual-ur --episodes 5")),
        words("run a.toml --robot virtual-ur --episodes 1")
    );
    assert_eq!(
        small(&words("parts prepare c.toml")),
        words("parts prepare c.toml --drops 200")
    );
    let dataset = small(&words("dataset --out d --test-feeder 100"));
    assert!(dataset.windows(2).any(|w| w == ["--test-feeder", "2"]));
    assert!(!dataset.iter().any(|a| a == "--train-feeder"));
    assert_eq!(
        small(&words("replay r --episode 3")),
        words("replay r --episode 3")
    );
    assert_eq!(
        ci_script(
            "cargo run --release -p cell -- run s.toml  # main job\ncargo test --workspace\n"
        ),
        vec!["cell run s.toml --episodes 2".to_string()]
    );
    assert_eq!(
        ci_script("cell virtual-ur --duration-s 120 &\nsleep 2"),
        vec![
            "cell virtual-ur --duration-s 60 &".to_string(),
            "sleep 2".to_string()
        ]
    );
    assert_eq!(
        ci_script("cell dataset --out d \\\n  --test-feeder 9 --train-crops 0 --test-crops 0 --train-overviews 0 --test-overviews 0"),
        vec!["cell dataset --out d --test-feeder 2 --train-crops 0 --test-crops 0 --train-overviews 0 --test-overviews 0".to_string()]
    );
}
