//! The seat check by camera (`[seat_check]`): after a seated verdict, the release and the
//! retreat, a capture of the fixture, taken with the arm out of the camera's view of it, shows
//! where the placed part stands. Its outline is aligned on the image's edges with perception's
//! contour alignment ([`perception::contour`]), started at the step's target pose (the fixture
//! pose composed with the assembly targets) and held on the plane across the insertion axis
//! through that pose (planar refinement: x, y and the turn about the axis are fitted; height
//! and tilt stay the target's).
//!
//! A part seated in a nest shares most of its outline with what was there before it: the
//! pocket's rim lies a clearance away from a shell's walls, the receiving shell's walls a
//! clearance inside a cover's skirts. Those edges are in the image whether the part is there or
//! not, so the support that decides whether the part was seen counts only the part's own
//! outline samples: those farther than [`SHARED_EDGE_PX`] from every crease or silhouette edge
//! of the fixture and the parts placed before it (at their targets). A part whose own edges
//! are not found (absent, hidden, or far from its target) is "not visible", never passed.

use nalgebra::{Isometry3, Point2, Point3, Vector2, Vector3};
use perception::contour::PartOutline;
use perception::contour::{
    ContourAligner, ContourConfig, ContourView, FinalEdge, GreyPatch, Owner,
};
use perception::part::{Catalog, StablePose, TriMesh};
use perception::{Camera, Frame, FrameContent};
use robots::kinematics::Joints;

use super::geometry::CellKnowledge;
use super::view::{arm_in_feeder_view, arm_in_view_of};
use crate::episode::{SeatCheckRecord, SeatCheckVerdict};
use crate::scenario::SeatCheckSpec;

/// Error-budget name of a step whose seat check did not pass.
pub const SEAT_CHECK_FAILED: &str = "seat_check";

/// Outline samples of the checked part closer than this to an edge of what was there before it
/// are not its own: they would find that edge with the part absent, pixels.
pub const SHARED_EDGE_PX: f64 = 1.5;

/// Fewest own outline samples a check needs; with fewer the part is "not visible".
pub const MIN_OWN_SAMPLES: usize = 12;

/// Margin around the fixture's footprint that the camera must see clear, metres.
const FIXTURE_MARGIN: f64 = 0.004;

/// Pixels around the part's projected target box that the outline search may reach.
const PATCH_MARGIN_PX: f64 = 24.0;

/// Two triangles meeting at more than this angle make a visible crease, radians (20°).
const CREASE: f64 = 0.35;

/// The tolerances one step's seat is checked against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeatTolerance {
    /// Largest measured lateral offset, metres.
    pub lateral: f64,
    /// Largest measured turn about the insertion axis, radians.
    pub yaw: f64,
    /// Least share of the part's own outline samples that must find an edge.
    pub min_support: f64,
}

impl SeatTolerance {
    /// The tolerances of step `step` under `spec`: its values, the lateral one by default the
    /// step's own `tolerances.lateral` plus the check's allowance
    /// ([`crate::scenario::SEAT_CHECK_ALLOWANCE`]).
    pub fn of(spec: &SeatCheckSpec, k: &CellKnowledge, step: usize) -> Self {
        let t = &k.steps[step].tolerances;
        Self {
            lateral: spec
                .lateral
                .unwrap_or(t.lateral + crate::scenario::SEAT_CHECK_ALLOWANCE),
            yaw: spec.yaw,
            min_support: spec.min_support,
        }
    }
}

/// Where the check measured the placed part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeatMeasurement {
    /// Offset from the target across the insertion axis (insertion frame x, y), metres.
    pub offset: Vector2<f64>,
    /// Turn about the insertion axis, radians.
    pub yaw: f64,
    /// Share of the part's own outline samples that found an edge within a pixel.
    pub support: f64,
    /// How many of its outline samples were its own.
    pub samples: usize,
}

/// Why no measurement: the part's own edges were not found, with what was found.
#[derive(Debug, Clone, PartialEq)]
pub struct NotSeen {
    /// Why, in words.
    pub why: String,
    /// How many of its outline samples at the target were its own.
    pub samples: usize,
    /// Whether the part's geometry alone hides it: at its target its outline has fewer than
    /// [`MIN_OWN_SAMPLES`] samples off the edges of what was there before it, so no image
    /// could show it (a part inside a receiver's cavity); otherwise it had edges of its own to
    /// show and the image did not show them.
    pub by_geometry: bool,
}

/// The fixture's footprint on the table with the margin: centre and half sizes (table frame),
/// metres.
#[allow(non_snake_case)]
fn fixture_rect(k: &CellKnowledge) -> ([f64; 2], [f64; 2]) {
    let table_T_fixture = k.geometry.base_T_table.inverse() * k.geometry.base_T_fixture;
    let (lo, hi) = k
        .part(&k.geometry.fixture_part)
        .map(|g| g.aabb)
        .unwrap_or((Point3::origin(), Point3::origin()));
    let mut min = Vector2::repeat(f64::INFINITY);
    let mut max = Vector2::repeat(f64::NEG_INFINITY);
    for i in 0..8 {
        let c = Point3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let p = (table_T_fixture * c).coords.xy();
        min = min.inf(&p);
        max = max.sup(&p);
    }
    let centre = (min + max) / 2.0;
    let half = (max - min) / 2.0 + Vector2::repeat(FIXTURE_MARGIN);
    ([centre.x, centre.y], [half.x, half.y])
}

/// The first part of the arm (or the held part) found in the camera's view of the fixture at
/// joints `q`, by name; `None` when the view is clear. The same check as the feeder's
/// ([`super::view::arm_in_feeder_view`]): capsules around the links from the joints and the
/// planning kinematics, against the pyramid from the calibrated camera to the fixture's
/// footprint with a margin.
pub fn arm_in_fixture_view(
    k: &CellKnowledge,
    q: &Joints,
    held: Option<f64>,
) -> Option<&'static str> {
    arm_in_view_of(k, q, held, fixture_rect(k))
}

/// Sideways steps tried from the retreat, metres.
const ASIDE_STEPS: [f64; 8] = [0.03, 0.045, 0.06, 0.08, 0.1, 0.12, 0.15, 0.2];

/// Directions tried at each step, turned from the one towards the feeder, degrees.
const ASIDE_TURNS: [f64; 8] = [0.0, 45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0];

/// A TCP pose at the height of `base_T_tcp` (the retreat above the fixture), moved sideways by
/// the shortest of [`ASIDE_STEPS`] (towards the feeder's centre first, then turned from it by
/// [`ASIDE_TURNS`]) within the workspace limits whose inverse kinematics (nearest `q`) puts the
/// arm out of the camera's view of the fixture and of the feeder (the next step's capture is
/// taken there), with those joints; `None` when none does.
#[allow(non_snake_case)]
pub fn pose_out_of_view(
    k: &CellKnowledge,
    base_T_tcp: &Isometry3<f64>,
    q: &Joints,
) -> Option<(Isometry3<f64>, Joints)> {
    let f = k.spec.feeder.center;
    let feeder = k.geometry.base_T_table * Point3::new(f[0], f[1], 0.0);
    let d = (feeder.coords - base_T_tcp.translation.vector).xy();
    let towards = d.try_normalize(1e-9)?;
    ASIDE_STEPS.iter().find_map(|step| {
        ASIDE_TURNS.iter().find_map(|turn| {
            let dir = nalgebra::Rotation2::new(turn.to_radians()) * towards;
            let pose = nalgebra::Translation3::new(dir.x * step, dir.y * step, 0.0) * base_T_tcp;
            if !k.spec.limits.workspace.contains(&pose.translation.vector) {
                return None;
            }
            let s = k.kinematics.inverse_nearest(&pose, q).ok()?;
            (arm_in_fixture_view(k, &s.joints, None).is_none()
                && arm_in_feeder_view(k, &s.joints, None).is_none())
            .then_some((pose, s.joints))
        })
    })
}

/// A boolean mask over a box of sensor pixels.
struct Mask {
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    on: Vec<bool>,
}

impl Mask {
    fn new(b: [i64; 4]) -> Self {
        let (width, height) = (b[2].max(0) as usize, b[3].max(0) as usize);
        Self {
            x0: b[0],
            y0: b[1],
            width,
            height,
            on: vec![false; width * height],
        }
    }

    fn get(&self, x: i64, y: i64) -> bool {
        let (u, v) = (x - self.x0, y - self.y0);
        u >= 0
            && v >= 0
            && (u as usize) < self.width
            && (v as usize) < self.height
            && self.on[v as usize * self.width + u as usize]
    }

    fn at(&self, p: Point2<f64>) -> bool {
        self.get(p.x.round() as i64, p.y.round() as i64)
    }

    /// Marks every pixel whose centre is within `r` of `p`.
    fn disc(&mut self, p: Point2<f64>, r: f64) {
        let n = r.ceil() as i64;
        let (cx, cy) = (p.x.round() as i64, p.y.round() as i64);
        for y in cy - n..=cy + n {
            for x in cx - n..=cx + n {
                let (u, v) = (x - self.x0, y - self.y0);
                if u < 0 || v < 0 || u as usize >= self.width || v as usize >= self.height {
                    continue;
                }
                if (x as f64 - p.x).hypot(y as f64 - p.y) <= r {
                    self.on[v as usize * self.width + u as usize] = true;
                }
            }
        }
    }
}

/// Marks on `mask` every pixel within `r` of an edge of `mesh` at `camera_T_part` that can show
/// in an image: a silhouette edge (one side facing the camera, the other away) or a crease
/// (two faces meeting at more than [`CREASE`], one facing the camera). Occlusion is ignored: an
/// edge hidden behind something is marked too, which only withholds samples from the support.
#[allow(non_snake_case)]
fn mark_edges(
    mask: &mut Mask,
    mesh: &TriMesh,
    camera: &Camera,
    camera_T_part: &Isometry3<f64>,
    r: f64,
) {
    let normals: Vec<Vector3<f64>> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            (b - a).cross(&(c - a))
        })
        .collect();
    let front: Vec<bool> = mesh
        .triangles
        .iter()
        .zip(&normals)
        .map(|(t, n)| {
            let p = camera_T_part * mesh.vertices[t[0] as usize];
            (camera_T_part.rotation * n).dot(&p.coords) < 0.0
        })
        .collect();
    let mut by_edge: std::collections::HashMap<[u32; 2], Vec<usize>> =
        std::collections::HashMap::new();
    for (ti, t) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (i, j) = (t[k], t[(k + 1) % 3]);
            by_edge.entry([i.min(j), i.max(j)]).or_default().push(ti);
        }
    }
    for ([a, b], tris) in by_edge {
        let shows = match tris.as_slice() {
            [t] => front[*t],
            [t, u] => {
                (front[*t] != front[*u])
                    || ((front[*t] || front[*u]) && normals[*t].angle(&normals[*u]) > CREASE)
            }
            many => many.iter().any(|t| front[*t]),
        };
        if !shows {
            continue;
        }
        let project = |v: u32| {
            camera
                .project(&(camera_T_part * mesh.vertices[v as usize]))
                .ok()
        };
        let (Some(pa), Some(pb)) = (project(a), project(b)) else {
            continue;
        };
        let n = ((pb - pa).norm() / 0.5).ceil().max(1.0) as usize;
        for s in 0..=n {
            mask.disc(pa + (pb - pa) * (s as f64 / n as f64), r);
        }
    }
}

/// Measures the part of step `step` in `frame`: its outline aligned from the step's target pose
/// on the frame's pixels, with the support counted over its own outline samples only.
#[allow(non_snake_case)]
pub fn measure_seat(
    k: &CellKnowledge,
    catalog: &Catalog,
    step: usize,
    frame: &Frame,
) -> Result<SeatMeasurement, NotSeen> {
    let unseen = |why: String| NotSeen {
        why,
        samples: 0,
        by_geometry: false,
    };
    let s = k
        .steps
        .get(step)
        .ok_or_else(|| unseen(format!("no step {step}")))?;
    let part = k
        .part(&s.part)
        .ok_or_else(|| unseen(format!("no shape of part {}", s.part)))?;
    let spec = catalog
        .part(&s.part)
        .ok_or_else(|| unseen(format!("part {} is not in the catalog", s.part)))?;
    let outline = PartOutline::new(&part.mesh)
        .with_final_edge(FinalEdge::for_material(spec.material))
        .with_hole_weight(spec.hole_weight.get());
    let camera = &frame.camera;
    let base_T_ins = k.base_T_insertions[step];
    let ins_T_target = base_T_ins.inverse() * k.base_T_targets[step];
    let camera_T_ins = frame.base_T_camera.inverse() * base_T_ins;
    let r = ins_T_target.rotation;
    let up = r.inverse() * Vector3::z();
    // The part held on the plane across the insertion axis at its target height, turned as
    // its target: a "stable pose" of the insertion frame.
    let seated = StablePose {
        name: "seated".into(),
        probability: 1.0,
        up_in_part: [up.x, up.y, up.z],
        rotation: r.scaled_axis().into(),
        rest_height: ins_T_target.translation.z,
    };
    let start = (ins_T_target.translation.x, ins_T_target.translation.y, 0.0);
    let camera_T_target = camera_T_ins * seated.table_T_part(start.0, start.1, start.2);
    // The sensor box the part covers at its target, with room for the search.
    let pixels: Vec<Point2<f64>> = part
        .mesh
        .vertices
        .iter()
        .filter_map(|v| camera.project(&(camera_T_target * v)).ok())
        .collect();
    if pixels.len() != part.mesh.vertices.len() {
        return Err(unseen("the target is behind the camera".into()));
    }
    let (mut lo, mut hi) = (
        Point2::new(f64::INFINITY, f64::INFINITY),
        Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for p in &pixels {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let b = [
        (lo.x - PATCH_MARGIN_PX).floor() as i64,
        (lo.y - PATCH_MARGIN_PX).floor() as i64,
        (hi.x - lo.x + 2.0 * PATCH_MARGIN_PX).ceil() as i64,
        (hi.y - lo.y + 2.0 * PATCH_MARGIN_PX).ceil() as i64,
    ];
    // The edges of what was there before the part: the fixture and the earlier steps' parts.
    let mut shared = Mask::new(b);
    let camera_T_base = frame.base_T_camera.inverse();
    if let Some(f) = k.part(&k.geometry.fixture_part) {
        let pose = camera_T_base * k.geometry.base_T_fixture;
        mark_edges(&mut shared, &f.mesh, camera, &pose, SHARED_EDGE_PX);
    }
    for (j, earlier) in k.steps[..step].iter().enumerate() {
        if let Some(g) = k.part(&earlier.part) {
            let pose = camera_T_base * k.base_T_targets[j];
            mark_edges(&mut shared, &g.mesh, camera, &pose, SHARED_EDGE_PX);
        }
    }
    let own = |pose: &Isometry3<f64>| {
        outline
            .pixels(camera, pose, ContourConfig::default().spacing_px)
            .into_iter()
            .filter(|p| !shared.at(*p))
            .count()
    };
    let samples = own(&camera_T_target);
    if samples < MIN_OWN_SAMPLES {
        return Err(NotSeen {
            why: format!(
                "its outline at the target has {samples} samples of its own (at least \
                 {MIN_OWN_SAMPLES} needed): the rest lie on edges of what was there before it"
            ),
            samples,
            by_geometry: true,
        });
    }
    let FrameContent::Image(image) = &frame.content else {
        return Err(unseen("the frame holds no pixels".into()));
    };
    let (ox, oy) = (i64::from(image.origin[0]), i64::from(image.origin[1]));
    if b[0] < ox
        || b[1] < oy
        || b[0] + b[2] > ox + i64::from(image.width())
        || b[1] + b[3] > oy + i64::from(image.height())
    {
        return Err(unseen(format!(
            "the captured pixels ({} × {} at sensor ({ox}, {oy})) do not cover the part's target \
             ({} × {} at ({}, {}))",
            image.width(),
            image.height(),
            b[2],
            b[3],
            b[0],
            b[1]
        )));
    }
    let patch = GreyPatch::cut(&image.pixels, image.origin, b).with_owners(|y, x, row| {
        for (i, v) in row.iter_mut().enumerate() {
            if shared.get(x + i as i64, y) {
                *v = Owner::Other;
            }
        }
    });
    let view = ContourView {
        outline: &outline,
        stable: &seated,
        camera,
        patch: &patch,
    };
    // Coarse to fine as the aligner's own rounds, each on the part's own samples only
    // (`screen` skips the hidden ones): the shared edges lie a clearance off the part's
    // outline, or its height's parallax off it, and would pull the fit towards them.
    let mut fit = None;
    let mut from = start;
    for reach in ContourConfig::default().search_px {
        let config = ContourConfig {
            search_px: [reach; 3],
            ..ContourConfig::default()
        };
        let Some(f) = ContourAligner::new(camera_T_ins, config).screen(view, from) else {
            fit = None;
            break;
        };
        from = (f.x, f.y, f.yaw);
        fit = Some(f);
    }
    let Some(fit) = fit else {
        return Err(NotSeen {
            why: "too few of its own outline samples found an image edge".into(),
            samples,
            by_geometry: false,
        });
    };
    let samples = own(&(camera_T_ins * seated.table_T_part(fit.x, fit.y, fit.yaw)));
    Ok(SeatMeasurement {
        offset: Vector2::new(fit.x - start.0, fit.y - start.1),
        yaw: fit.yaw,
        support: fit.support,
        samples,
    })
}

/// Whether the part of step `step` is hidden by construction, seen by the calibrated camera:
/// its outline at its target has fewer than [`MIN_OWN_SAMPLES`] samples off the edges of what
/// was there before it, so no capture could show it (decided before any capture is taken).
pub fn hidden_by_construction(
    k: &CellKnowledge,
    catalog: &Catalog,
    step: usize,
) -> Option<NotSeen> {
    let frame = Frame {
        camera: k.spec.camera.intrinsics,
        base_T_camera: k.geometry.base_T_camera_nominal,
        content: FrameContent::Simulated(Vec::new()),
    };
    measure_seat(k, catalog, step, &frame)
        .err()
        .filter(|n| n.by_geometry)
}

/// The verdict on a measurement against `tol`, with the reason a check that did not pass
/// gives (`None` for a pass).
pub fn judge(
    m: &Result<SeatMeasurement, NotSeen>,
    tol: &SeatTolerance,
) -> (SeatCheckVerdict, Option<String>) {
    match m {
        Err(n) => (
            SeatCheckVerdict::NotVisible,
            Some(format!("the placed part is not visible: {}", n.why)),
        ),
        Ok(m) if m.support < tol.min_support => (
            SeatCheckVerdict::NotVisible,
            Some(format!(
                "the placed part is not visible: {:.0} % of its {} own outline samples found an \
                 edge (at least {:.0} % needed)",
                100.0 * m.support,
                m.samples,
                100.0 * tol.min_support
            )),
        ),
        Ok(m) => {
            let lateral = m.offset.norm();
            let mut beyond = Vec::new();
            if lateral > tol.lateral {
                beyond.push(format!(
                    "lateral offset {:.3} mm ({:+.3}, {:+.3}) beyond the {:.3} mm tolerance",
                    lateral * 1e3,
                    m.offset.x * 1e3,
                    m.offset.y * 1e3,
                    tol.lateral * 1e3
                ));
            }
            if m.yaw.abs() > tol.yaw {
                beyond.push(format!(
                    "turned {:+.2} mrad about the insertion axis, beyond the {:.2} mrad tolerance",
                    m.yaw * 1e3,
                    tol.yaw * 1e3
                ));
            }
            if beyond.is_empty() {
                (SeatCheckVerdict::Passed, None)
            } else {
                (
                    SeatCheckVerdict::Failed,
                    Some(format!(
                        "the seat check measured the placed part {} ({:.0} % of {} own outline \
                         samples found)",
                        beyond.join(" and "),
                        100.0 * m.support,
                        m.samples
                    )),
                )
            }
        }
    }
}

/// The record of a check: its verdict on `m` against `tol`, and the part's true offset where
/// the simulator knows it.
pub fn record(
    m: &Result<SeatMeasurement, NotSeen>,
    tol: &SeatTolerance,
    true_offset: Option<Vector2<f64>>,
) -> SeatCheckRecord {
    let (verdict, _) = judge(m, tol);
    let (offset_mm, yaw_mrad, support, samples) = match m {
        Ok(m) => (
            Some([m.offset.x * 1e3, m.offset.y * 1e3]),
            Some(m.yaw * 1e3),
            Some(m.support),
            m.samples,
        ),
        Err(n) => (None, None, None, n.samples),
    };
    SeatCheckRecord {
        verdict,
        offset_mm,
        yaw_mrad,
        support,
        samples: samples as u32,
        tolerance: [tol.lateral * 1e3, tol.yaw * 1e3],
        true_offset_mm: true_offset.map(|o| [o.x * 1e3, o.y * 1e3]),
    }
}

/// The true offset across the insertion axis of a part at `base_T_part` placed by step `step`
/// (insertion frame x, y), metres: what the measurement is compared with in simulation.
#[allow(non_snake_case)]
pub fn true_offset(k: &CellKnowledge, step: usize, base_T_part: &Isometry3<f64>) -> Vector2<f64> {
    let ins = k.base_T_insertions[step];
    let t = ins.inverse() * base_T_part;
    let target = ins.inverse() * k.base_T_targets[step];
    (t.translation.vector - target.translation.vector).xy()
}
