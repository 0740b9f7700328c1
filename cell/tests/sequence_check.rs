//! `cell check` on assembly sequences: a step naming a part or destination that does not exist,
//! a target outside the workspace or beyond the arm's reach, an insertion direction the top-down
//! gripper cannot follow and a target that turns the part over are each refused at the step's
//! line and column, with the reason; the NIST peg scenario itself is valid.

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;

use cell::scenario::Scenario;
use support::line_of;

fn scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

fn pegs_text() -> String {
    std::fs::read_to_string(scenarios().join("nist_pegs_nominal.toml")).unwrap()
}

/// Writes a variant beside the scenarios (so relative paths still resolve), loads it, removes
/// it, and returns the problem reported at `key`, with the variant's text.
fn problem_at(name: &str, text: &str, key: &str) -> (cell::scenario::Problem, String) {
    let path = scenarios().join(format!(".test_seq_{name}_{}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    let result = Scenario::load(&path);
    std::fs::remove_file(&path).ok();
    let err = match result {
        Ok(_) => panic!("{name}: the variant was accepted"),
        Err(e) => e,
    };
    let p = err
        .0
        .iter()
        .find(|p| p.key.as_deref() == Some(key))
        .unwrap_or_else(|| panic!("{name}: nothing at {key}: {err}"))
        .clone();
    (p, text.to_string())
}

/// The text with the `n`-th (0-based) occurrence of `from` replaced by `to`.
fn replace_nth(text: &str, from: &str, to: &str, n: usize) -> String {
    let at = text.match_indices(from).nth(n).expect("occurrence").0;
    format!("{}{to}{}", &text[..at], &text[at + from.len()..])
}

#[test]
fn the_nist_peg_scenario_is_valid() {
    let s = Scenario::load(&scenarios().join("nist_pegs_nominal.toml")).unwrap_or_else(|e| {
        panic!("{e}");
    });
    assert_eq!(s.spec.assembly.len(), 6);
    let out = Command::new(env!("CARGO_BIN_EXE_cell"))
        .args(["check", "../scenarios/nist_pegs_nominal.toml"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_step_naming_an_unknown_part_or_destination_is_refused_at_its_line() {
    let text = pegs_text().replacen("part = \"round_12\"", "part = \"round_13\"", 1);
    let (p, text) = problem_at("part", &text, "assembly[4].part");
    assert!(
        p.message.contains("no part \"round_13\" in the catalog"),
        "{p:?}"
    );
    assert!(
        p.message.contains("round_12"),
        "the known parts are listed: {p:?}"
    );
    assert_eq!(p.line, line_of(&text, "part = \"round_13\""));
    assert_eq!(p.column, "part = ".len() + 1);

    // Into a part no earlier step placed (here one that does not exist at all).
    let text = replace_nth(
        &pegs_text(),
        "into = \"fixture\"",
        "into = { part = \"lid\" }",
        2,
    );
    let (p, text) = problem_at("into", &text, "assembly[2].into");
    assert!(
        p.message
            .contains("\"lid\" is not placed by an earlier step"),
        "{p:?}"
    );
    assert_eq!(p.line, line_of(&text, "{ part = \"lid\" }"));

    // A fixture (the frame every first step goes into) that is not in the catalog.
    let text = pegs_text().replace("part = \"nist_plate\"", "part = \"nist_board\"");
    let (p, _) = problem_at("fixture", &text, "cell.fixture.part");
    assert!(p.message.contains("no part \"nist_board\""), "{p:?}");
}

#[test]
fn a_target_outside_the_workspace_or_out_of_reach_is_refused_at_its_line() {
    // The 16 mm round peg's hole 0.4 m off in x: outside the workspace box.
    let text = pegs_text().replace(
        "translation = [0.036, 0.018, 0.006]",
        "translation = [0.4, 0.018, 0.006]",
    );
    let (p, text) = problem_at("workspace", &text, "assembly[5].target");
    assert!(
        p.message.contains("outside the limits' workspace box"),
        "{p:?}"
    );
    assert!(p.message.contains("round_16"), "{p:?}");
    assert_eq!(p.line, line_of(&text, "[0.4, 0.018, 0.006]"));
    assert_eq!(p.column, "target = ".len() + 1);

    // In a widened box but 1.2 m from the base: beyond the UR5e's reach top-down.
    let text = pegs_text()
        .replace(
            "workspace = { min = [-0.3, -0.7, 0.0], max = [0.3, -0.2, 0.5] }",
            "workspace = { min = [-2.0, -2.0, 0.0], max = [2.0, 2.0, 1.0] }",
        )
        .replace(
            "translation = [-0.036, -0.018, 0.006]",
            "translation = [1.2, -0.018, 0.006]",
        );
    let (p, text) = problem_at("reach", &text, "assembly[0].target");
    assert!(
        p.message.contains("out of the ur5e's reach top-down"),
        "{p:?}"
    );
    assert_eq!(p.line, line_of(&text, "[1.2, -0.018, 0.006]"));
}

#[test]
fn an_insertion_direction_the_top_down_gripper_cannot_follow_is_refused() {
    // Sideways, along +x.
    let text = replace_nth(
        &pegs_text(),
        "insertion_axis = [0.0, 0.0, -1.0]",
        "insertion_axis = [1.0, 0.0, 0.0]",
        4,
    );
    let (p, text) = problem_at("sideways", &text, "assembly[4].insertion_axis");
    assert!(p.message.contains("90.0° from straight down"), "{p:?}");
    assert!(
        p.message.contains("inserts along its vertical tool"),
        "{p:?}"
    );
    assert_eq!(p.line, line_of(&text, "insertion_axis = [1.0, 0.0, 0.0]"));
    assert_eq!(p.column, "insertion_axis = ".len() + 1);

    // Upward, out of the plate.
    let text = replace_nth(
        &pegs_text(),
        "insertion_axis = [0.0, 0.0, -1.0]",
        "insertion_axis = [0.0, 0.0, 1.0]",
        0,
    );
    let (p, _) = problem_at("upward", &text, "assembly[0].insertion_axis");
    assert!(p.message.contains("180.0° from straight down"), "{p:?}");

    // Two degrees off: beyond the 1° the cell allows.
    let text = replace_nth(
        &pegs_text(),
        "insertion_axis = [0.0, 0.0, -1.0]",
        "insertion_axis = [0.0349, 0.0, -0.9994]",
        1,
    );
    let (p, _) = problem_at("tilted", &text, "assembly[1].insertion_axis");
    assert!(p.message.contains("2.0° from straight down"), "{p:?}");
}

#[test]
fn a_target_that_turns_the_part_over_is_refused() {
    // The square 8 mm peg seated upside down: picked standing on its bottom end, it would have to
    // be turned over in the fingers.
    let text = pegs_text().replace(
        "translation = [-0.036, -0.018, 0.006], rotation = [0.0, 0.0, 0.0]",
        "translation = [-0.036, -0.018, 0.006], rotation = [3.141592653589793, 0.0, 0.0]",
    );
    let (p, text) = problem_at("over", &text, "assembly[0].target");
    assert!(p.message.contains("turns \"square_8\""), "{p:?}");
    assert!(p.message.contains("\"+z\" 180.0°"), "{p:?}");
    assert_eq!(
        p.line,
        line_of(&text, "[-0.036, -0.018, 0.006], rotation = [3.14")
    );
}

#[test]
fn the_binary_prints_the_file_line_and_reason_of_a_bad_step() {
    let text = replace_nth(
        &pegs_text(),
        "insertion_axis = [0.0, 0.0, -1.0]",
        "insertion_axis = [0.0, 1.0, 0.0]",
        5,
    );
    let path = scenarios().join(format!(".test_seq_binary_{}.toml", std::process::id()));
    std::fs::write(&path, &text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_cell"))
        .arg("check")
        .arg(&path)
        .output()
        .unwrap();
    std::fs::remove_file(&path).ok();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let want = format!(
        "{}:{}:",
        path.display(),
        line_of(&text, "insertion_axis = [0.0, 1.0, 0.0]")
    );
    assert!(
        stderr.contains(&want) && stderr.contains("from straight down"),
        "{stderr}"
    );
}
