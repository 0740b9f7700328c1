//! Semantic checks of a parsed scenario: files exist, numbers are in range, names resolve, and
//! the cell is physically possible. Each problem carries the key path it concerns.

use std::path::Path;

use perception::learned::LearnedModels;
use perception::part::{Catalog, PartRole};
use robots::ur_arm::UrArm;
use sim::cell::feasible::{check_geometry, check_values};

use super::{
    KeyPath, MAX_INSERTION_ATTEMPTS, PLANNER_CLEARANCE_HEIGHT, PLANNER_SLOW_DISTANCE,
    PerceptionMode, ScenarioSpec,
};

type Issues = Vec<(KeyPath, String)>;

fn root() -> KeyPath {
    KeyPath::default()
}

fn non_negative(issues: &mut Issues, path: KeyPath, value: f64, what: &str) {
    if !(value.is_finite() && value >= 0.0) {
        issues.push((
            path,
            format!("{what} must be zero or positive, got {value}"),
        ));
    }
}

/// Checks `[force_insertion]`: a contact force the sensor can tell from its noise and the arm
/// allows, a positive speed within the cell's TCP speed, positive stiffness and distances, a
/// bounded search.
fn force_insertion(spec: &ScenarioSpec, f: &super::ForceInsertionSpec, issues: &mut Issues) {
    use robots::virtual_ur::force::UR5E_FORCE_PRECISION;
    let key = |k: &str| root().key("force_insertion").key(k);
    let max_force = spec.cell.limits.max_contact_force;
    if !(f.contact_force.is_finite()
        && f.contact_force > UR5E_FORCE_PRECISION
        && f.contact_force <= max_force)
    {
        issues.push((
            key("contact_force"),
            format!(
                "contact_force must be above the wrist sensor's precision ({UR5E_FORCE_PRECISION} N) \
                 and at most cell.limits.max_contact_force ({max_force} N), got {}",
                f.contact_force
            ),
        ));
    }
    let max_speed = spec.cell.limits.max_tcp_speed;
    if !(f.contact_speed.is_finite() && f.contact_speed > 0.0 && f.contact_speed <= max_speed) {
        issues.push((
            key("contact_speed"),
            format!(
                "contact_speed must be positive and at most cell.limits.max_tcp_speed \
                 ({max_speed} m/s), got {}",
                f.contact_speed
            ),
        ));
    }
    for (name, value) in [
        ("contact_stiffness", f.contact_stiffness),
        ("overtravel", f.overtravel),
        ("seat_band", f.seat_band),
    ] {
        if !(value.is_finite() && value > 0.0) {
            issues.push((key(name), format!("{name} must be positive, got {value}")));
        }
    }
    if f.search_points > super::MAX_SEARCH_POINTS {
        issues.push((
            key("search_points"),
            format!(
                "search_points must be at most {}, got {}",
                super::MAX_SEARCH_POINTS,
                f.search_points
            ),
        ));
    }
}

/// Checks `[seat_check]`: tolerances finite and positive, a support share in (0, 1].
fn seat_check(c: &super::SeatCheckSpec, issues: &mut Issues) {
    let key = |k: &str| root().key("seat_check").key(k);
    for (name, value) in [("lateral", c.lateral), ("yaw", Some(c.yaw))] {
        if let Some(v) = value
            && !(v.is_finite() && v > 0.0)
        {
            issues.push((key(name), format!("{name} must be positive, got {v}")));
        }
    }
    let s = c.min_support;
    if !(s.is_finite() && s > 0.0 && s <= 1.0) {
        issues.push((
            key("min_support"),
            format!("min_support must be a share above 0 and at most 1, got {s}"),
        ));
    }
}

/// Checks `[motion] blend_radius`: finite, not negative, and at most half of the shortest
/// segment it blends. With the planner's clearance height `c` and slow distance `s`, a blended
/// lift rises `c + r` and a blended descent comes down `c + r - s` (the corners are raised by
/// the radius `r`), so `r ≤ (c + r - s) / 2`, that is `r ≤ c - s`.
fn blend_radius(r: f64, issues: &mut Issues) {
    let key = root().key("motion").key("blend_radius");
    if !r.is_finite() {
        issues.push((
            key,
            format!("blend_radius must be a finite number, got {r}"),
        ));
        return;
    }
    if r < 0.0 {
        issues.push((
            key,
            format!("blend_radius must be zero or positive, got {r}"),
        ));
        return;
    }
    let (clearance, slow) = (PLANNER_CLEARANCE_HEIGHT, PLANNER_SLOW_DISTANCE);
    let max = clearance - slow;
    if r > max {
        issues.push((
            key,
            format!(
                "blend_radius {r} m is larger than half the shortest segment it would blend: the \
                 planner's lift and descent ({} m clearance, {} m slow distance, raised by the \
                 radius) allow at most {max} m",
                clearance, slow
            ),
        ));
    }
}

/// Checks `[motion] perception_time`: a finite number of seconds, zero or more.
fn perception_time(t: f64, issues: &mut Issues) {
    if !t.is_finite() || t < 0.0 {
        issues.push((
            root().key("motion").key("perception_time"),
            format!("perception_time must be a finite number of seconds, zero or more, got {t}"),
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
    if let Some(problem) = spec.cell.gripper.actuation_time_problem() {
        issues.push((cell.key("gripper").key("actuation_time"), problem));
    }
    if let Err(e) = spec.cell.load_board(dir) {
        issues.push((cell.key("board"), format!("cannot use the board: {e}")));
    }
    // The cell's numbers have one home, the simulator's feasibility check.
    for (key, message) in check_values(&spec.cell, &spec.assembly, &spec.noise) {
        issues.push((KeyPath::parse(&key), message));
    }
    let attempts = spec.policy.max_insertion_attempts;
    if !(1..=MAX_INSERTION_ATTEMPTS).contains(&attempts) {
        issues.push((
            root().key("policy").key("max_insertion_attempts"),
            format!(
                "max_insertion_attempts must be between 1 and {MAX_INSERTION_ATTEMPTS}, got {attempts}"
            ),
        ));
    }
    if let Some(f) = &spec.force_insertion {
        force_insertion(spec, f, &mut issues);
    }
    if let Some(c) = &spec.seat_check {
        seat_check(c, &mut issues);
    }
    blend_radius(spec.motion.blend_radius, &mut issues);
    perception_time(spec.motion.perception_time, &mut issues);
    let bar = spec.policy.min_pick_confidence;
    if !(0.0..=1.0).contains(&bar) {
        issues.push((
            root().key("policy").key("min_pick_confidence"),
            format!("min_pick_confidence must be between 0 and 1, got {bar}"),
        ));
    }
    let pp = root().key("perception");
    let learned_models = match (&spec.perception.mode, &spec.perception.models) {
        (PerceptionMode::Learned, None) => {
            issues.push((
                pp.key("mode"),
                "mode \"learned\" needs `models`, the folder of its ONNX models (e.g. \
                 models = \"models/usbc\")"
                    .into(),
            ));
            None
        }
        (PerceptionMode::Learned, Some(models)) => match LearnedModels::in_dir(&dir.join(models)) {
            Ok(m) => Some(m),
            Err(e) => {
                issues.push((pp.key("models"), format!("cannot use the models: {e}")));
                None
            }
        },
        (PerceptionMode::KeypointNoise, _) => None,
    };
    non_negative(
        &mut issues,
        pp.key("keypoint_noise_px"),
        spec.perception.keypoint_noise_px,
        "keypoint_noise_px",
    );
    let gate = spec.perception.max_rms_px;
    if !(gate.is_finite() && gate > 0.0) {
        issues.push((
            pp.key("max_rms_px"),
            format!("max_rms_px must be positive, got {gate}"),
        ));
    }
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
    if let (Some(catalog), Some(models)) = (&catalog, &learned_models)
        && let Err(e) = models.check_catalog(catalog)
    {
        issues.push((
            pp.key("models"),
            format!("the models do not fit the catalog: {e}"),
        ));
    }
    if let Some(catalog) = &catalog {
        // What the simulated cell refuses as impossible on the scenario's arm (parts and meshes,
        // reach, workspace, feeder over the fixture, camera view, parts wider than the stroke),
        // then what the scenario needs of the catalog, each where no problem is reported at the
        // same key yet.
        let mut found: Issues = match &arm {
            Some(arm) => check_geometry(&spec.cell, arm, &spec.assembly, catalog)
                .into_iter()
                .map(|(key, message)| (KeyPath::parse(&key), message))
                .collect(),
            None => Vec::new(),
        };
        check_against_catalog(spec, catalog, &mut found);
        for (path, message) in found {
            if !issues.iter().any(|(p, _)| *p == path) {
                issues.push((path, message));
            }
        }
    }
    (catalog, arm, issues)
}

fn check_against_catalog(spec: &ScenarioSpec, catalog: &Catalog, issues: &mut Issues) {
    // Names missing from the catalog are reported by the geometry check.
    let cell = root().key("cell");
    for name in spec.cell.feeder.parts.keys() {
        if let Some(p) = catalog.part(name)
            && p.role == PartRole::Fixture
        {
            issues.push((
                cell.key("feeder").key("parts").key(name),
                format!("\"{name}\" is a fixture, not a part that can lie in a feeder"),
            ));
        }
    }
    for (i, step) in spec.assembly.iter().enumerate() {
        let sp = root().key("assembly").index(i);
        if let Some(part) = catalog.part(&step.part) {
            if !part.is_prepared() {
                issues.push((
                    sp.key("part"),
                    format!(
                        "part \"{}\" has no keypoints or stable poses yet: run `cell parts \
                         prepare {}`",
                        step.part,
                        catalog.file.display()
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
        if spec.cell.feeder.parts.get(&step.part).copied().unwrap_or(0) == 0 {
            issues.push((
                sp.key("part"),
                format!(
                    "no \"{}\" in the feeder: add it to cell.feeder.parts",
                    step.part
                ),
            ));
        }
    }
    if spec.assembly.is_empty() {
        issues.push((root(), "the scenario has no [[assembly]] step".into()));
    }
}
