//! Rejecting impossible scenarios before a run, each problem with its key path and reason.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use perception::part::{Catalog, TriMesh};
use robots::ur_arm::UrArm;

use crate::config::{AssemblyStep, CellSpec, Destination, NoiseSpec};

/// How far above a point the reachability check puts the TCP, metres.
const APPROACH: f64 = 0.03;

/// Every reason the scenario cannot run, as (key path, message); empty when it is feasible.
///
/// Checks: tolerances, clearances and lead-ins; the insertion axis; parts and destinations in the
/// catalog and placed by an earlier step; each grasp's part width against the gripper stroke;
/// gripper and feeder sizes; noise values; the fixture and the feeder corners inside the limits'
/// workspace box and reachable top-down by the arm (`arm`, the scenario's `cell.robot`) with this
/// gripper; the feeder region
/// overlapping the fixture's footprint.
pub fn check_feasible(
    cell: &CellSpec,
    arm: &UrArm,
    steps: &[AssemblyStep],
    noise: &NoiseSpec,
    catalog: &Catalog,
) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = Vec::new();
    let mut bad = |k: String, m: String| out.push((k, m));
    let positive = |v: f64| v.is_finite() && v > 0.0;

    let g = &cell.gripper;
    for (k, v) in [
        ("stroke", g.stroke),
        ("finger_width", g.finger_width),
        ("finger_thickness", g.finger_thickness),
        ("finger_length", g.finger_length),
        ("tcp_offset", g.tcp_offset),
    ] {
        if !positive(v) {
            bad(
                format!("cell.gripper.{k}"),
                format!("must be positive, got {v}"),
            );
        }
    }
    if !(g.friction.is_finite() && g.friction >= 0.0) {
        bad(
            "cell.gripper.friction".into(),
            format!("must be ≥ 0, got {}", g.friction),
        );
    }
    let f = &cell.feeder;
    if !(positive(f.size[0]) && positive(f.size[1])) {
        bad(
            "cell.feeder.size".into(),
            format!("must be positive, got {:?}", f.size),
        );
    }
    for (k, v) in [
        ("robot_repeatability", noise.robot_repeatability),
        ("calibration_translation", noise.calibration_translation),
        ("calibration_rotation", noise.calibration_rotation),
        ("grasp_offset", noise.grasp_offset),
        ("grasp_rotation", noise.grasp_rotation),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            bad(format!("noise.{k}"), format!("must be ≥ 0, got {v}"));
        }
    }

    let mesh_of = |name: &str| -> Option<TriMesh> {
        let spec = catalog.part(name)?;
        catalog.load_mesh(spec).ok()
    };
    // Widths across the jaws of every part the gripper must pick.
    let mut picked: Vec<(String, String)> = f
        .parts
        .keys()
        .map(|n| (n.clone(), format!("cell.feeder.parts.{n}")))
        .collect();
    for (i, s) in steps.iter().enumerate() {
        picked.push((s.part.clone(), format!("assembly[{i}].part")));
    }
    picked.sort();
    picked.dedup_by(|a, b| a.0 == b.0);
    for (name, key) in &picked {
        let Some(spec) = catalog.part(name) else {
            bad(key.clone(), format!("part {name:?} is not in the catalog"));
            continue;
        };
        let Some(mesh) = mesh_of(name) else {
            bad(
                key.clone(),
                format!("part {name:?}: its mesh cannot be loaded"),
            );
            continue;
        };
        for grasp in &spec.grasps {
            let axis = Vector3::from(grasp.closing_axis);
            if axis.norm() == 0.0 {
                continue;
            }
            let axis = axis.normalize();
            let (lo, hi) = mesh
                .vertices
                .iter()
                .map(|p| p.coords.dot(&axis))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), d| {
                    (l.min(d), h.max(d))
                });
            if hi - lo > g.stroke {
                bad(
                    key.clone(),
                    format!(
                        "part {name:?} is {:.2} mm wide across its grasp ({}) but the gripper opens only {:.2} mm",
                        (hi - lo) * 1e3,
                        grasp.stable_pose,
                        g.stroke * 1e3
                    ),
                );
            }
        }
    }

    let mut placed: Vec<&str> = Vec::new();
    for (i, s) in steps.iter().enumerate() {
        let t = &s.tolerances;
        for (k, v) in [("lateral", t.lateral), ("depth", t.depth), ("tilt", t.tilt)] {
            if !positive(v) {
                bad(
                    format!("assembly[{i}].tolerances.{k}"),
                    format!("must be positive, got {v}"),
                );
            }
        }
        if !positive(s.clearance) {
            bad(
                format!("assembly[{i}].clearance"),
                format!("must be positive, got {}", s.clearance),
            );
        }
        if !(s.lead_in.is_finite() && s.lead_in >= 0.0) {
            bad(
                format!("assembly[{i}].lead_in"),
                format!("must be ≥ 0, got {}", s.lead_in),
            );
        }
        let axis = Vector3::from(s.insertion_axis);
        if !(axis.iter().all(|v| v.is_finite()) && axis.norm() > 1e-9) {
            bad(
                format!("assembly[{i}].insertion_axis"),
                "must be a non-zero vector".into(),
            );
        }
        if !s.target.is_finite() {
            bad(format!("assembly[{i}].target"), "must be finite".into());
        }
        if let Destination::Part(p) = &s.into
            && !placed.contains(&p.as_str())
        {
            bad(
                format!("assembly[{i}].into"),
                format!("part {p:?} is not placed by an earlier step"),
            );
        }
        placed.push(s.part.as_str());
    }

    // Reach: the fixture and the feeder corners, top-down, inside the workspace box.
    let base_T_table = cell.base_T_table.isometry();
    let kin =
        (arm.kinematics.clone()).with_tcp(Isometry3::translation(0.0, 0.0, g.tcp_offset.max(0.0)));
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let reachable = |p: &Point3<f64>| {
        let tcp = Isometry3::from_parts(Translation3::new(p.x, p.y, p.z + APPROACH), down);
        kin.inverse_all(&tcp, 0.0)
            .map(|s| s.iter().next().is_some())
            .unwrap_or(false)
    };
    let fixture_origin = base_T_table * cell.fixture.table_T_fixture.isometry() * Point3::origin();
    if !cell.limits.workspace.contains(&fixture_origin.coords) {
        bad(
            "cell.fixture.table_T_fixture".into(),
            format!(
                "fixture at {:?} m (base) is outside the limits' workspace box",
                fixture_origin.coords.as_slice()
            ),
        );
    } else if !reachable(&fixture_origin) {
        bad(
            "cell.fixture.table_T_fixture".into(),
            format!(
                "fixture at {:?} m (base) is out of the {}'s reach top-down",
                fixture_origin.coords.as_slice(),
                arm.name
            ),
        );
    }
    let [cx, cy] = f.center;
    let (hx, hy) = (f.size[0] / 2.0, f.size[1] / 2.0);
    for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        let corner = base_T_table * Point3::new(cx + sx * hx, cy + sy * hy, 0.0);
        if !cell.limits.workspace.contains(&corner.coords) || !reachable(&corner) {
            bad(
                "cell.feeder".into(),
                format!(
                    "feeder corner at {:?} m (base) is outside the workspace or out of reach",
                    corner.coords.as_slice()
                ),
            );
            break;
        }
    }
    // Feeder against the fixture's footprint on the table.
    if let Some(mesh) = mesh_of(&cell.fixture.part) {
        let t = cell.fixture.table_T_fixture.isometry();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &mesh.vertices {
            let q = t * p;
            lo = [lo[0].min(q.x), lo[1].min(q.y)];
            hi = [hi[0].max(q.x), hi[1].max(q.y)];
        }
        let overlap = lo[0] < cx + hx && hi[0] > cx - hx && lo[1] < cy + hy && hi[1] > cy - hy;
        if overlap {
            bad(
                "cell.feeder".into(),
                format!(
                    "the feeder region overlaps the fixture {:?} (footprint x {:.3}..{:.3}, y {:.3}..{:.3} m on the table)",
                    cell.fixture.part, lo[0], hi[0], lo[1], hi[1]
                ),
            );
        }
    } else {
        bad(
            "cell.fixture.part".into(),
            format!(
                "fixture part {:?} is not in the catalog or its mesh cannot be loaded",
                cell.fixture.part
            ),
        );
    }
    out
}
