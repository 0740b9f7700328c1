//! Semantic checks of a parsed scenario: files exist, numbers are in range, names resolve, and
//! the cell is physically possible. Each problem carries the key path it concerns.

use std::path::Path;

use nalgebra::Vector3;
use perception::part::{Catalog, PartRole};
use robots::ur_arm::UrArm;
use sim::cell::check_feasible;

use super::{Destination, KeyPath, MAX_INSERTION_ATTEMPTS, ScenarioSpec};

type Issues = Vec<(KeyPath, String)>;

fn root() -> KeyPath {
    KeyPath::default()
}

fn positive(issues: &mut Issues, path: KeyPath, value: f64, what: &str) {
    if !(value.is_finite() && value > 0.0) {
        issues.push((
            path,
            format!("{what} must be a positive number, got {value}"),
        ));
    }
}

fn non_negative(issues: &mut Issues, path: KeyPath, value: f64, what: &str) {
    if !(value.is_finite() && value >= 0.0) {
        issues.push((
            path,
            format!("{what} must be zero or positive, got {value}"),
        ));
    }
}

/// The arm the scenario's `cell.robot` describes (a UR arm's URDF, relative to `dir`), and its
/// joint speed limits against the scenario's; `None` (with the problem recorded) when unusable.
fn load_arm(spec: &ScenarioSpec, dir: &Path, issues: &mut Issues) -> Option<UrArm> {
    let key = root().key("cell").key("robot");
    let path = dir.join(&spec.cell.robot);
    if !path.is_file() {
        issues.push((
            key,
            format!("robot description {} does not exist", path.display()),
        ));
        return None;
    }
    let arm = match UrArm::from_file(&path) {
        Ok(arm) => arm,
        Err(e) => {
            issues.push((key, format!("cannot use the robot description: {e}")));
            return None;
        }
    };
    let slowest = arm.slowest_joint_speed();
    if spec.cell.limits.max_joint_speed > slowest {
        issues.push((
            root().key("cell").key("limits").key("max_joint_speed"),
            format!(
                "{} rad/s is more than the {}'s slowest joint allows ({slowest:.4} rad/s, from {})",
                spec.cell.limits.max_joint_speed,
                arm.name,
                path.display()
            ),
        ));
    }
    Some(arm)
}

/// Checks a parsed scenario whose relative paths start at `dir`; returns the catalog and the arm
/// when they load.
pub fn validate(spec: &ScenarioSpec, dir: &Path) -> (Option<Catalog>, Option<UrArm>, Issues) {
    let mut issues = Issues::new();
    if spec.episodes == 0 {
        issues.push((root().key("episodes"), "episodes must be at least 1".into()));
    }
    let cell = root().key("cell");
    let arm = load_arm(spec, dir, &mut issues);
    for (name, pose) in [("base_T_table", &spec.cell.base_T_table)] {
        if !pose.is_finite() {
            issues.push((cell.key(name), "pose has a non-finite number".into()));
        }
    }
    let camera = cell.key("camera");
    if let Err(e) = spec.cell.camera.intrinsics.validate() {
        issues.push((camera.key("intrinsics"), format!("invalid camera: {e}")));
    }
    if !spec.cell.camera.base_T_camera.is_finite() {
        issues.push((
            camera.key("base_T_camera"),
            "pose has a non-finite number".into(),
        ));
    }
    if let Err(e) = spec.cell.limits.validate() {
        issues.push((
            cell.key("limits").key(e.field),
            format!("invalid limits: {}", e.reason),
        ));
    }
    let g = &spec.cell.gripper;
    let gp = cell.key("gripper");
    positive(&mut issues, gp.key("stroke"), g.stroke, "stroke");
    positive(
        &mut issues,
        gp.key("finger_width"),
        g.finger_width,
        "finger_width",
    );
    positive(
        &mut issues,
        gp.key("finger_thickness"),
        g.finger_thickness,
        "finger_thickness",
    );
    positive(
        &mut issues,
        gp.key("finger_length"),
        g.finger_length,
        "finger_length",
    );
    non_negative(&mut issues, gp.key("friction"), g.friction, "friction");
    if let Some(problem) = g.actuation_time_problem() {
        issues.push((gp.key("actuation_time"), problem));
    }
    let fp = cell.key("feeder");
    for i in 0..2 {
        positive(
            &mut issues,
            fp.key("size").index(i),
            spec.cell.feeder.size[i],
            "feeder size",
        );
    }
    let np = root().key("noise");
    let n = &spec.noise;
    for (key, v) in [
        ("robot_repeatability", n.robot_repeatability),
        ("calibration_translation", n.calibration_translation),
        ("calibration_rotation", n.calibration_rotation),
        ("grasp_offset", n.grasp_offset),
        ("grasp_rotation", n.grasp_rotation),
    ] {
        non_negative(&mut issues, np.key(key), v, key);
    }
    let fp2 = cell.key("feeder");
    non_negative(
        &mut issues,
        fp2.key("shake_time"),
        spec.cell.feeder.shake_time,
        "shake_time",
    );
    let attempts = spec.policy.max_insertion_attempts;
    if !(1..=MAX_INSERTION_ATTEMPTS).contains(&attempts) {
        issues.push((
            root().key("policy").key("max_insertion_attempts"),
            format!(
                "max_insertion_attempts must be between 1 and {MAX_INSERTION_ATTEMPTS}, got {attempts}"
            ),
        ));
    }
    let pp = root().key("perception");
    non_negative(
        &mut issues,
        pp.key("keypoint_noise_px"),
        spec.perception.keypoint_noise_px,
        "keypoint_noise_px",
    );
    let f = spec.perception.outlier_fraction;
    if !(0.0..=1.0).contains(&f) {
        issues.push((
            pp.key("outlier_fraction"),
            format!("outlier_fraction must be in [0, 1], got {f}"),
        ));
    }
    // The catalog, then everything that names its parts.
    let catalog_path = dir.join(&spec.parts.catalog);
    let catalog = match Catalog::load(&catalog_path) {
        Ok(c) => Some(c),
        Err(e) => {
            issues.push((
                root().key("parts").key("catalog"),
                format!("cannot use the catalog: {e}"),
            ));
            None
        }
    };
    if let Some(catalog) = &catalog {
        check_against_catalog(spec, catalog, &mut issues);
    }
    if let (Some(catalog), Some(arm)) = (&catalog, &arm) {
        // What the simulated cell refuses as impossible (reach, workspace, feeder over the
        // fixture, parts wider than the stroke), where not already reported at the same key.
        let c = &spec.cell;
        for (key, message) in check_feasible(c, arm, &spec.assembly, &spec.noise, catalog) {
            let path = KeyPath::parse(&key);
            if !issues.iter().any(|(p, _)| *p == path) {
                issues.push((path, message));
            }
        }
    }
    (catalog, arm, issues)
}

fn check_against_catalog(spec: &ScenarioSpec, catalog: &Catalog, issues: &mut Issues) {
    let names: Vec<&str> = catalog.parts.iter().map(|p| p.name.as_str()).collect();
    let known = names.join(", ");
    let cell = root().key("cell");
    for name in spec.cell.feeder.parts.keys() {
        match catalog.part(name) {
            None => issues.push((
                cell.key("feeder").key("parts").key(name),
                format!("no part \"{name}\" in the catalog (it has: {known})"),
            )),
            Some(p) if p.role == PartRole::Fixture => issues.push((
                cell.key("feeder").key("parts").key(name),
                format!("\"{name}\" is a fixture, not a part that can lie in a feeder"),
            )),
            Some(_) => {}
        }
    }
    if catalog.part(&spec.cell.fixture.part).is_none() {
        issues.push((
            cell.key("fixture").key("part"),
            format!(
                "no part \"{}\" in the catalog (it has: {known})",
                spec.cell.fixture.part
            ),
        ));
    }
    let mut placed: Vec<&str> = Vec::new();
    for (i, step) in spec.assembly.iter().enumerate() {
        let sp = root().key("assembly").index(i);
        match catalog.part(&step.part) {
            None => issues.push((
                sp.key("part"),
                format!("no part \"{}\" in the catalog (it has: {known})", step.part),
            )),
            Some(part) => {
                if !part.is_prepared() {
                    issues.push((
                        sp.key("part"),
                        format!(
                            "part \"{}\" has no keypoints or stable poses yet: run `cell parts \
                             prepare {}`",
                            step.part,
                            catalog.dir.join("usbc.toml").display()
                        ),
                    ));
                } else if !part
                    .grasps
                    .iter()
                    .any(|g| part.stable_pose(&g.stable_pose).is_some())
                {
                    issues.push((
                        sp.key("part"),
                        format!(
                            "part \"{}\" has no grasp for any of its stable poses",
                            step.part
                        ),
                    ));
                }
            }
        }
        if let Destination::Part(target) = &step.into
            && !placed.contains(&target.as_str())
        {
            issues.push((
                sp.key("into"),
                format!("\"{target}\" is not placed by an earlier step, so nothing can go into it"),
            ));
        }
        if !step.target.is_finite() {
            issues.push((sp.key("target"), "pose has a non-finite number".into()));
        }
        let axis = Vector3::from(step.insertion_axis);
        if !(axis.norm() > 1e-9 && axis.iter().all(|v| v.is_finite())) {
            issues.push((
                sp.key("insertion_axis"),
                "insertion_axis must be a non-zero vector".into(),
            ));
        }
        positive(issues, sp.key("clearance"), step.clearance, "clearance");
        non_negative(issues, sp.key("lead_in"), step.lead_in, "lead_in");
        let tp = sp.key("tolerances");
        positive(
            issues,
            tp.key("lateral"),
            step.tolerances.lateral,
            "tolerance lateral",
        );
        positive(
            issues,
            tp.key("depth"),
            step.tolerances.depth,
            "tolerance depth",
        );
        positive(
            issues,
            tp.key("tilt"),
            step.tolerances.tilt,
            "tolerance tilt",
        );
        if spec.cell.feeder.parts.get(&step.part).copied().unwrap_or(0) == 0 {
            issues.push((
                sp.key("part"),
                format!(
                    "no \"{}\" in the feeder: add it to cell.feeder.parts",
                    step.part
                ),
            ));
        }
        placed.push(step.part.as_str());
    }
    if spec.assembly.is_empty() {
        issues.push((root(), "the scenario has no [[assembly]] step".into()));
    }
}
