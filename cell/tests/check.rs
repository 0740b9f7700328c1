//! `cell check`: the nominal scenario passes; bad scenarios fail with file:line:column and the
//! offending key, through the library and through the real binary.

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;

use cell::scenario::Scenario;
use support::line_of;

fn scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

fn nominal_text() -> String {
    std::fs::read_to_string(scenarios().join("usbc_nominal.toml")).unwrap()
}

/// Writes a variant of the nominal scenario beside it (so relative paths still resolve).
fn variant(name: &str, text: &str) -> PathBuf {
    let path = scenarios().join(format!(".test_{name}_{}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn the_nominal_scenario_is_valid() {
    let s = Scenario::load(&scenarios().join("usbc_nominal.toml")).unwrap();
    assert_eq!(s.spec.assembly.len(), 3);
    assert!(
        s.catalog
            .parts
            .iter()
            .filter(|p| p.role != perception::part::PartRole::Fixture)
            .all(|p| p.is_prepared())
    );
}

#[test]
fn an_unknown_key_is_located() {
    let text = nominal_text().replace(
        "placement = \"sampled\"",
        "placement = \"sampled\"\nmax_shaeks = 4",
    );
    let path = variant("unknown", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let p = &err.0[0];
    assert_eq!(p.line, line_of(&text, "max_shaeks"), "{err}");
    assert_eq!(p.column, 1, "{err}");
    assert!(p.message.contains("max_shaeks"), "{err}");
}

#[test]
fn a_negative_clearance_names_the_step_and_line() {
    let text = nominal_text().replacen("clearance = 0.00009", "clearance = -0.00009", 1);
    let path = variant("clearance", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let p = &err.0[0];
    assert_eq!(p.key.as_deref(), Some("assembly[1].clearance"), "{err}");
    assert_eq!(p.line, line_of(&text, "clearance = -0.00009"), "{err}");
    assert_eq!(p.column, "clearance = ".len() + 1, "{err}");
    assert!(p.message.contains("positive"), "{err}");
}

#[test]
fn a_missing_catalog_or_robot_file_is_named() {
    let text = nominal_text()
        .replace(
            "catalog = \"parts/usbc.toml\"",
            "catalog = \"parts/nope.toml\"",
        )
        .replace(
            "robot = \"robots/ur5e.urdf\"",
            "robot = \"robots/ur3.urdf\"",
        );
    let path = variant("missing", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let all = err.to_string();
    assert!(
        all.contains("nope.toml") && all.contains("parts.catalog"),
        "{all}"
    );
    assert!(
        all.contains("ur3.urdf") && all.contains("cell.robot"),
        "{all}"
    );
    let robot = err
        .0
        .iter()
        .find(|p| p.key.as_deref() == Some("cell.robot"))
        .unwrap();
    assert_eq!(robot.line, line_of(&text, "ur3.urdf"));
}

#[test]
fn a_part_wider_than_the_stroke_and_a_zero_tolerance_are_rejected() {
    let text = nominal_text()
        .replace("stroke = 0.014", "stroke = 0.008")
        .replacen(
            "tolerances = { lateral = 0.0001",
            "tolerances = { lateral = 0.0",
            1,
        );
    let path = variant("stroke", &text);
    let err = Scenario::load(&path).unwrap_err().to_string();
    std::fs::remove_file(&path).ok();
    assert!(err.contains("gripper opens only 8.00 mm"), "{err}");
    assert!(err.contains("assembly[0].tolerances.lateral"), "{err}");
}

#[test]
fn the_binary_exits_non_zero_and_prints_the_location() {
    let text = nominal_text().replace("episodes = 200", "episodes = 0");
    let path = variant("binary", &text);
    let out = Command::new(env!("CARGO_BIN_EXE_cell"))
        .arg("check")
        .arg(&path)
        .output()
        .unwrap();
    std::fs::remove_file(&path).ok();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let want = format!("{}:{}:", path.display(), line_of(&text, "episodes = 0"));
    assert!(
        stderr.contains(&want) && stderr.contains("episodes"),
        "{stderr}"
    );
    let ok = Command::new(env!("CARGO_BIN_EXE_cell"))
        .args(["check", "../scenarios/usbc_nominal.toml"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
}

#[test]
fn a_fixture_out_of_reach_and_a_feeder_over_the_fixture_are_rejected_with_their_lines() {
    // Inside a widened workspace box but 1.2 m from the base: beyond the UR5e's reach.
    let text = nominal_text()
        .replace(
            "workspace = { min = [-0.3, -0.7, 0.0], max = [0.3, -0.2, 0.5] }",
            "workspace = { min = [-2.0, -2.0, 0.0], max = [2.0, 2.0, 1.0] }",
        )
        .replace(
            "table_T_fixture = { translation = [0.05, -0.05, 0.003]",
            "table_T_fixture = { translation = [1.2, -0.05, 0.003]",
        );
    let path = variant("reach", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let p = err
        .0
        .iter()
        .find(|p| p.key.as_deref() == Some("cell.fixture.table_T_fixture"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(p.message.contains("out of the ur5e's reach"), "{err}");
    assert_eq!(p.line, line_of(&text, "table_T_fixture ="));

    // The feeder region centred on the fixture nest.
    let text = nominal_text().replace("center = [0.0, 0.05]", "center = [0.05, -0.05]");
    let path = variant("overlap", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let p = err
        .0
        .iter()
        .find(|p| p.message.contains("overlaps the fixture"))
        .unwrap_or_else(|| panic!("{err}"));
    assert_eq!(p.key.as_deref(), Some("cell.feeder"));
    assert_eq!(p.line, line_of(&text, "[cell.feeder]"));
}

#[test]
fn a_negative_gripper_actuation_time_is_rejected_at_its_line() {
    // Absent: the default 0.25 s.
    let s = Scenario::load(&scenarios().join("usbc_nominal.toml")).unwrap();
    assert_eq!(s.spec.cell.gripper.actuation_time, 0.25);
    let with = |value: &str| {
        nominal_text().replace(
            "friction = 0.3\n",
            &format!("friction = 0.3\nactuation_time = {value}\n"),
        )
    };
    let text = with("0.5");
    let path = variant("actuation_ok", &text);
    let ok = Scenario::load(&path);
    std::fs::remove_file(&path).ok();
    assert_eq!(ok.unwrap().spec.cell.gripper.actuation_time, 0.5);

    let text = with("-0.25");
    let path = variant("actuation", &text);
    let err = Scenario::load(&path).unwrap_err();
    let out = Command::new(env!("CARGO_BIN_EXE_cell"))
        .arg("check")
        .arg(&path)
        .output()
        .unwrap();
    std::fs::remove_file(&path).ok();
    let p = err
        .0
        .iter()
        .find(|p| p.key.as_deref() == Some("cell.gripper.actuation_time"))
        .unwrap_or_else(|| panic!("{err}"));
    assert_eq!(err.0.len(), 1, "{err}");
    assert_eq!(p.line, line_of(&text, "actuation_time = -0.25"), "{err}");
    assert_eq!(p.column, "actuation_time = ".len() + 1, "{err}");
    assert!(p.message.contains("-0.25"), "{err}");
    // The binary prints the same location and fails.
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let want = format!(
        "{}:{}:{}:",
        path.display(),
        p.line,
        "actuation_time = ".len() + 1
    );
    assert!(
        stderr.contains(&want) && stderr.contains("actuation_time"),
        "{stderr}"
    );
}

/// A gripper width output the controller does not have is refused where it stands; 0 and 1
/// are accepted.
#[test]
fn a_gripper_width_output_the_controller_lacks_is_located() {
    let with = |value: &str| {
        nominal_text().replace(
            "friction = 0.3\n",
            &format!("friction = 0.3\nwidth_output = {value}\n"),
        )
    };
    for good in [0, 1] {
        let path = variant("width_output_ok", &with(&good.to_string()));
        let ok = Scenario::load(&path);
        std::fs::remove_file(&path).ok();
        assert_eq!(ok.unwrap().spec.cell.gripper.width_output, Some(good));
    }
    let text = with("2");
    let path = variant("width_output", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let p = err
        .0
        .iter()
        .find(|p| p.key.as_deref() == Some("cell.gripper.width_output"))
        .unwrap_or_else(|| panic!("{err}"));
    assert_eq!(err.0.len(), 1, "{err}");
    assert_eq!(p.line, line_of(&text, "width_output = 2"), "{err}");
    assert_eq!(p.column, "width_output = ".len() + 1, "{err}");
    assert!(p.message.contains("analog outputs 0 and 1"), "{err}");
}

/// The cell's contact force limit: above the arm's protective stop it is refused where it
/// stands; below a force-guided insertion's `contact_force` it refuses that, naming both.
#[test]
fn a_contact_force_beyond_the_cells_limit_is_located() {
    let with_limit = |max: &str| {
        nominal_text().replacen(
            "max_joint_acceleration = 6.0",
            &format!("max_joint_acceleration = 6.0\nmax_contact_force = {max}"),
            1,
        ) + "\n[force_insertion]\ncontact_force = 12.0\n"
    };
    let text = with_limit("200.0");
    let path = variant("force_limit", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let p = &err.0[0];
    assert_eq!(
        p.key.as_deref(),
        Some("cell.limits.max_contact_force"),
        "{err}"
    );
    assert_eq!(p.line, line_of(&text, "max_contact_force = 200.0"), "{err}");
    assert!(p.message.contains("protective stop"), "{err}");

    let text = with_limit("10.0");
    let path = variant("force_over", &text);
    let err = Scenario::load(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    let p = &err.0[0];
    assert_eq!(
        p.key.as_deref(),
        Some("force_insertion.contact_force"),
        "{err}"
    );
    assert_eq!(p.line, line_of(&text, "contact_force = 12.0"), "{err}");
    assert!(p.message.contains("max_contact_force (10 N)"), "{err}");

    let path = variant("force_ok", &with_limit("20.0"));
    let loaded = Scenario::load(&path);
    std::fs::remove_file(&path).ok();
    assert_eq!(loaded.unwrap().spec.cell.limits.max_contact_force, 20.0);
}
