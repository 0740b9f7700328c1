//! Rejecting impossible scenarios before a run, each problem with its key path and reason. This
//! is the one home of the checks of the cell's numbers (gripper, feeder, noise, steps) and of
//! its geometry (reach, camera view, footprints): `cell check` reports what it finds here, and
//! the simulated cell refuses to build on the same findings.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use perception::part::{Catalog, TriMesh};
use robots::ur_arm::UrArm;

use crate::config::{AssemblyStep, CellSpec, Destination, NoiseSpec};

/// How far above a point the reachability check puts the TCP, metres.
const APPROACH: f64 = 0.03;

/// Fewest pixels the largest side of the smallest feeder part must span in the camera image:
/// below this its keypoints crowd within a few pixels of each other, and a pixel of keypoint
/// error becomes a large fraction of the part (PnP is ill-conditioned). The seed's camera sees
/// the 9 mm main shell over about 64 pixels.
pub const MIN_PART_PIXELS: f64 = 24.0;

/// Largest angle between a step's insertion direction and straight down (base frame), and
/// between the up direction of the stable pose a part is grasped in and straight up at its
/// target, radians: the planner picks every part from above with a vertical tool and inserts
/// along the tool, so a step must insert downward with the part the way up it was picked.
pub const MAX_INSERTION_TILT: f64 = 1.0 * std::f64::consts::PI / 180.0;

/// A found problem: (key path, message).
pub type Finding = (String, String);

/// Every reason the scenario cannot run on `arm` (the scenario's `cell.robot`), as (key path,
/// message); empty when it is feasible: [`check_values`] and [`check_geometry`].
pub fn check_feasible(
    cell: &CellSpec,
    arm: &UrArm,
    steps: &[AssemblyStep],
    noise: &NoiseSpec,
    catalog: &Catalog,
) -> Vec<Finding> {
    let mut out = check_values(cell, steps, noise);
    out.extend(check_geometry(cell, arm, steps, catalog));
    out
}

fn positive(out: &mut Vec<Finding>, key: String, v: f64) {
    if !(v.is_finite() && v > 0.0) {
        out.push((key, format!("must be a positive number, got {v}")));
    }
}

fn non_negative(out: &mut Vec<Finding>, key: String, v: f64) {
    if !(v.is_finite() && v >= 0.0) {
        out.push((key, format!("must be zero or positive, got {v}")));
    }
}

/// The cell's numbers, without the catalog: gripper sizes and friction, feeder size and shake
/// time, noise values, and each step's tolerances, clearance, lead-in, insertion axis, target
/// and destination order.
pub fn check_values(cell: &CellSpec, steps: &[AssemblyStep], noise: &NoiseSpec) -> Vec<Finding> {
    let mut out = Vec::new();
    let g = &cell.gripper;
    for (k, v) in [
        ("stroke", g.stroke),
        ("finger_width", g.finger_width),
        ("finger_thickness", g.finger_thickness),
        ("finger_length", g.finger_length),
        ("tcp_offset", g.tcp_offset),
    ] {
        positive(&mut out, format!("cell.gripper.{k}"), v);
    }
    non_negative(&mut out, "cell.gripper.friction".into(), g.friction);
    if let Some(m) = g.opening_margin {
        non_negative(&mut out, "cell.gripper.opening_margin".into(), m);
    }
    if let Some(o) = g.width_output
        && o > 1
    {
        out.push((
            "cell.gripper.width_output".into(),
            format!("a UR controller has standard analog outputs 0 and 1, got {o}"),
        ));
    }
    let f = &cell.feeder;
    for i in 0..2 {
        positive(&mut out, format!("cell.feeder.size[{i}]"), f.size[i]);
    }
    non_negative(&mut out, "cell.feeder.shake_time".into(), f.shake_time);
    for (k, v) in [
        ("robot_repeatability", noise.robot_repeatability),
        ("calibration_translation", noise.calibration_translation),
        ("calibration_rotation", noise.calibration_rotation),
        ("grasp_offset", noise.grasp_offset),
        ("grasp_rotation", noise.grasp_rotation),
    ] {
        non_negative(&mut out, format!("noise.{k}"), v);
    }
    let mut placed: Vec<&str> = Vec::new();
    for (i, s) in steps.iter().enumerate() {
        let t = &s.tolerances;
        for (k, v) in [("lateral", t.lateral), ("depth", t.depth), ("tilt", t.tilt)] {
            positive(&mut out, format!("assembly[{i}].tolerances.{k}"), v);
        }
        positive(&mut out, format!("assembly[{i}].clearance"), s.clearance);
        non_negative(&mut out, format!("assembly[{i}].lead_in"), s.lead_in);
        let axis = Vector3::from(s.insertion_axis);
        if !(axis.iter().all(|v| v.is_finite()) && axis.norm() > 1e-9) {
            out.push((
                format!("assembly[{i}].insertion_axis"),
                "must be a non-zero vector".into(),
            ));
        }
        if !s.target.is_finite() {
            out.push((
                format!("assembly[{i}].target"),
                "pose has a non-finite number".into(),
            ));
        }
        if let Some(base_T_target) = nominal_targets(cell, steps)[i]
            && axis.iter().all(|v| v.is_finite())
            && axis.norm() > 1e-9
        {
            let base_axis = base_T_target.rotation * s.target.isometry().rotation.inverse() * axis;
            let off = base_axis.angle(&-Vector3::z());
            if off > MAX_INSERTION_TILT {
                out.push((
                    format!("assembly[{i}].insertion_axis"),
                    format!(
                        "points {:.1}° from straight down in the robot's base frame ({:?} there); \
                         the cell picks parts from above and inserts along its vertical tool, so \
                         a step must insert downward (within {:.0}°)",
                        off.to_degrees(),
                        [base_axis.x, base_axis.y, base_axis.z].map(|v| (v * 1e4).round() / 1e4),
                        MAX_INSERTION_TILT.to_degrees()
                    ),
                ));
            }
        }
        if let Destination::Part(p) = &s.into
            && !placed.contains(&p.as_str())
        {
            out.push((
                format!("assembly[{i}].into"),
                format!("\"{p}\" is not placed by an earlier step, so nothing can go into it"),
            ));
        }
        placed.push(s.part.as_str());
    }
    out
}

/// The cell's geometry against the catalog: the parts named exist and their meshes load, each
/// grasp's part width against the gripper stroke, the fixture and the feeder corners inside the
/// limits' workspace box and reachable top-down by the UR5e with this gripper, the feeder region
/// clear of the fixture's footprint, and the camera seeing the feeder region and the fixture
/// with the smallest feeder part at least [`MIN_PART_PIXELS`] across.
pub fn check_geometry(
    cell: &CellSpec,
    arm: &UrArm,
    steps: &[AssemblyStep],
    catalog: &Catalog,
) -> Vec<Finding> {
    let mut out: Vec<Finding> = Vec::new();
    let g = &cell.gripper;
    let f = &cell.feeder;
    let known = catalog
        .parts
        .iter()
        .map(|p| p.name.as_str())
        .collect::<Vec<_>>()
        .join(", ");
    // Widths across the jaws of every part the gripper must pick.
    let mut picked: Vec<(String, String)> = f
        .parts
        .keys()
        .map(|n| (n.clone(), format!("cell.feeder.parts.{n}")))
        .collect();
    for (i, s) in steps.iter().enumerate() {
        picked.push((s.part.clone(), format!("assembly[{i}].part")));
    }
    let mut smallest_part = f64::INFINITY;
    let mut seen: Vec<String> = Vec::new();
    for (name, key) in &picked {
        let Some(spec) = catalog.part(name) else {
            out.push((
                key.clone(),
                format!("no part \"{name}\" in the catalog (it has: {known})"),
            ));
            continue;
        };
        if seen.contains(name) {
            continue;
        }
        seen.push(name.clone());
        let mesh = match catalog.load_mesh(spec) {
            Ok(m) => m,
            Err(e) => {
                out.push((key.clone(), format!("cannot load its mesh: {e}")));
                continue;
            }
        };
        if f.parts.contains_key(name) {
            smallest_part = smallest_part.min(mesh.extents().max());
        }
        for grasp in &spec.grasps {
            let axis = Vector3::from(grasp.closing_axis);
            if axis.norm() == 0.0 {
                continue;
            }
            let width = super::gripper::width_across(&mesh.vertices, &axis);
            if width > g.stroke {
                out.push((
                    key.clone(),
                    format!(
                        "part \"{name}\" is {:.2} mm wide across its grasp ({}) but the gripper \
                         opens only {:.2} mm",
                        width * 1e3,
                        grasp.stable_pose,
                        g.stroke * 1e3
                    ),
                ));
            } else if let Some(m) = g.opening_margin
                && m >= 0.0
                && width + 2.0 * m > g.stroke
            {
                out.push((
                    "cell.gripper.opening_margin".into(),
                    format!(
                        "part \"{name}\" is {:.2} mm wide across its grasp ({}): with {:.2} mm \
                         of room each side the fingers would open {:.2} mm, more than the {:.2} \
                         mm stroke",
                        width * 1e3,
                        grasp.stable_pose,
                        m * 1e3,
                        (width + 2.0 * m) * 1e3,
                        g.stroke * 1e3
                    ),
                ));
            }
        }
    }

    // Reach: the fixture and the feeder corners, top-down, their approach points (where the TCP
    // goes, `APPROACH` above them) inside the workspace box. The points themselves lie on the
    // table, which a measured calibration tilts by tens of µrad: a box whose floor is the table
    // must not refuse a corner a few µm below it.
    let base_T_table = cell.base_T_table.isometry();
    let above = |p: &Point3<f64>| p.coords + Vector3::z() * APPROACH;
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
    if !cell.limits.workspace.contains(&above(&fixture_origin)) {
        out.push((
            "cell.fixture.table_T_fixture".into(),
            format!(
                "fixture at {:?} m (base) is outside the limits' workspace box",
                fixture_origin.coords.as_slice()
            ),
        ));
    } else if !reachable(&fixture_origin) {
        out.push((
            "cell.fixture.table_T_fixture".into(),
            format!(
                "fixture at {:?} m (base) is out of the {}'s reach top-down",
                fixture_origin.coords.as_slice(),
                arm.name
            ),
        ));
    }
    let in_reach = |p: &Point3<f64>| {
        if !cell.limits.workspace.contains(&above(p)) {
            Err("is outside the limits' workspace box".to_string())
        } else if !reachable(p) {
            Err(format!("is out of the {}'s reach top-down", arm.name))
        } else {
            Ok(())
        }
    };
    out.extend(check_targets(cell, steps, catalog, &in_reach));
    let feeder_corners = feeder_corners(cell);
    for corner in &feeder_corners {
        let corner = base_T_table * corner;
        if !cell.limits.workspace.contains(&above(&corner)) || !reachable(&corner) {
            out.push((
                "cell.feeder".into(),
                format!(
                    "feeder corner at {:?} m (base) is outside the workspace or out of reach",
                    corner.coords.as_slice()
                ),
            ));
            break;
        }
    }
    // Feeder against the fixture's footprint on the table.
    let fixture_mesh = match catalog.part(&cell.fixture.part) {
        None => {
            out.push((
                "cell.fixture.part".into(),
                format!(
                    "no part \"{}\" in the catalog (it has: {known})",
                    cell.fixture.part
                ),
            ));
            None
        }
        Some(spec) => match catalog.load_mesh(spec) {
            Ok(m) => Some(m),
            Err(e) => {
                out.push((
                    "cell.fixture.part".into(),
                    format!("cannot load the fixture's mesh: {e}"),
                ));
                None
            }
        },
    };
    if let Some(mesh) = &fixture_mesh {
        let [cx, cy] = f.center;
        let (hx, hy) = (f.size[0] / 2.0, f.size[1] / 2.0);
        let t = cell.fixture.table_T_fixture.isometry();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &mesh.vertices {
            let q = t * p;
            lo = [lo[0].min(q.x), lo[1].min(q.y)];
            hi = [hi[0].max(q.x), hi[1].max(q.y)];
        }
        let overlap = lo[0] < cx + hx && hi[0] > cx - hx && lo[1] < cy + hy && hi[1] > cy - hy;
        if overlap {
            out.push((
                "cell.feeder".into(),
                format!(
                    "the feeder region overlaps the fixture {:?} (footprint x {:.3}..{:.3}, y \
                     {:.3}..{:.3} m on the table)",
                    cell.fixture.part, lo[0], hi[0], lo[1], hi[1]
                ),
            ));
        }
    }
    out.extend(check_camera_view(
        cell,
        &feeder_corners,
        fixture_mesh.as_ref(),
        smallest_part,
    ));
    out
}

/// Each step's nominal seated pose in the base frame, with every earlier part seated exactly at
/// its own target; `None` for a step whose destination is no earlier step's part.
#[allow(non_snake_case)]
pub fn nominal_targets(cell: &CellSpec, steps: &[AssemblyStep]) -> Vec<Option<Isometry3<f64>>> {
    let base_T_fixture = cell.base_T_table.isometry() * cell.fixture.table_T_fixture.isometry();
    let mut out: Vec<Option<Isometry3<f64>>> = Vec::with_capacity(steps.len());
    for (i, s) in steps.iter().enumerate() {
        let dest = match &s.into {
            Destination::Fixture => Some(base_T_fixture),
            Destination::Part(name) => steps[..i]
                .iter()
                .rposition(|e| &e.part == name)
                .and_then(|j| out[j]),
        };
        out.push(dest.map(|d| d * s.target.isometry()));
    }
    out
}

/// Each step's target within the workspace and reach top-down, and its part grasped the way
/// up the target holds it.
fn check_targets(
    cell: &CellSpec,
    steps: &[AssemblyStep],
    catalog: &Catalog,
    in_reach: &dyn Fn(&Point3<f64>) -> Result<(), String>,
) -> Vec<Finding> {
    let mut out = Vec::new();
    for (i, (s, target)) in steps.iter().zip(nominal_targets(cell, steps)).enumerate() {
        let Some(base_T_target) = target else {
            continue;
        };
        let origin = base_T_target * Point3::origin();
        if let Err(why) = in_reach(&origin) {
            out.push((
                format!("assembly[{i}].target"),
                format!(
                    "the target of \"{}\" at {:?} m (base) {why}",
                    s.part,
                    origin
                        .coords
                        .iter()
                        .map(|v| (v * 1e4).round() / 1e4)
                        .collect::<Vec<_>>()
                ),
            ));
            continue;
        }
        let Some(spec) = catalog.part(&s.part) else {
            continue;
        };
        let ups: Vec<(String, f64)> = spec
            .grasps
            .iter()
            .filter_map(|g| spec.stable_pose(&g.stable_pose))
            .map(|pose| {
                let up = Vector3::from(pose.up_in_part);
                let angle = if up.norm() > 0.0 {
                    (base_T_target.rotation * up.normalize()).angle(&Vector3::z())
                } else {
                    std::f64::consts::PI
                };
                (pose.name.clone(), angle)
            })
            .collect();
        if !ups.is_empty() && ups.iter().all(|(_, a)| *a > MAX_INSERTION_TILT) {
            let list = ups
                .iter()
                .map(|(n, a)| format!("\"{n}\" {:.1}°", a.to_degrees()))
                .collect::<Vec<_>>()
                .join(", ");
            out.push((
                format!("assembly[{i}].target"),
                format!(
                    "turns \"{}\" so that none of the stable poses it is grasped in stays up \
                     (their up directions lie {list} from vertical there); the gripper picks \
                     from above and cannot turn a part over, so the target must keep a grasped \
                     pose up (within {:.0}°)",
                    s.part,
                    MAX_INSERTION_TILT.to_degrees()
                ),
            ));
        }
    }
    out
}

/// The feeder region's corners in the table frame.
fn feeder_corners(cell: &CellSpec) -> [Point3<f64>; 4] {
    let [cx, cy] = cell.feeder.center;
    let (hx, hy) = (cell.feeder.size[0] / 2.0, cell.feeder.size[1] / 2.0);
    [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .map(|(sx, sy)| Point3::new(cx + sx * hx, cy + sy * hy, 0.0))
}

/// The camera sees every feeder corner and the fixture's bounding box inside its image, and the
/// smallest feeder part (`smallest_part` metres across) spans at least [`MIN_PART_PIXELS`].
fn check_camera_view(
    cell: &CellSpec,
    feeder_corners: &[Point3<f64>; 4],
    fixture: Option<&TriMesh>,
    smallest_part: f64,
) -> Vec<Finding> {
    let key = "cell.camera.base_T_camera".to_string();
    let camera = &cell.camera.intrinsics;
    if !cell.camera.base_T_camera.is_finite() || camera.validate().is_err() {
        return Vec::new(); // reported where the camera's numbers are checked
    }
    let camera_T_table =
        cell.camera.base_T_camera.isometry().inverse() * cell.base_T_table.isometry();
    let fix = "point base_T_camera's optical axis (its z) at the table, or move the feeder or \
               fixture into the view";
    let sees = |what: &str, points: &[Point3<f64>]| -> Result<(), String> {
        for p in points {
            let q = camera_T_table * p;
            if q.z <= 0.0 {
                return Err(format!(
                    "the camera cannot see the {what}: it lies behind the camera ({:.3} m along \
                     its optical axis); {fix}",
                    q.z
                ));
            }
            match camera.project(&q) {
                Ok(px) if camera.contains(px) => {}
                Ok(px) => {
                    return Err(format!(
                        "the camera cannot see all of the {what}: a corner projects to pixel \
                         ({:.0}, {:.0}), outside the {} × {} image; {fix}",
                        px.x, px.y, camera.width, camera.height
                    ));
                }
                Err(e) => return Err(format!("the camera cannot see the {what}: {e}; {fix}")),
            }
        }
        Ok(())
    };
    if let Err(m) = sees("feeder region", feeder_corners) {
        return vec![(key, m)];
    }
    if let Some(mesh) = fixture {
        let t = cell.fixture.table_T_fixture.isometry();
        let (lo, hi) = mesh.aabb();
        let box_corners: Vec<Point3<f64>> = (0..8)
            .map(|i| {
                t * Point3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
            })
            .collect();
        if let Err(m) = sees("fixture", &box_corners) {
            return vec![(key, m)];
        }
    }
    if smallest_part.is_finite() {
        // Pixels per metre at the farthest feeder corner.
        let far = feeder_corners
            .iter()
            .map(|p| (camera_T_table * p).z)
            .fold(0.0, f64::max);
        let pixels = smallest_part * camera.fx.min(camera.fy) / far;
        if pixels < MIN_PART_PIXELS {
            return vec![(
                key,
                format!(
                    "the smallest feeder part ({:.1} mm) spans only {pixels:.1} pixels at {far:.2} \
                     m from the camera; perception needs at least {MIN_PART_PIXELS} (move the \
                     camera closer or use a longer lens)",
                    smallest_part * 1e3
                ),
            )];
        }
    }
    Vec::new()
}
