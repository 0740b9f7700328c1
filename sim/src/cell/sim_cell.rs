//! `SimCell`: one episode of the simulated cell, driven through `robots::Robot` and a small
//! sim-only API (see the module documentation of `sim::cell`).

use std::sync::Arc;

use nalgebra::{Isometry3, Point2, Point3, Translation3, Vector2, Vector3};
use robots::kinematics::Joints;
use robots::kinematics::from_ur_pose;
use robots::limits::Limits;
use robots::robot::Waypoint;
use robots::robot::{
    ContactOutcome, JointMotion, LinearMotion, Robot, RobotError, RobotFuture, RobotMode,
    RobotStatus, SafetyStatus, Wrench,
};
use robots::virtual_ur::arm::{ArmError, KinematicArm};
use robots::virtual_ur::force::{FtNoise, TABLE_STIFFNESS};
use robots::virtual_ur::path::{CONTROLLER_PERIOD, PathMove, execute_path, waypoint_moves};
use serde::{Deserialize, Serialize};

use super::error::CellError;
use super::feeder::{self, FeederPart};
use super::gripper::{self, Grasp, GraspCandidate, GraspFailure};
use super::insertion::felt::{FeltKey, FeltStop, FeltStops};
use super::insertion::{
    InsertionCase, InsertionCause, InsertionResult, Mating, PoseError, ReceiverPart, Scorer,
    Verdict,
};
use super::model::CellModel;
use super::motion::{Profile, move_j_profile, move_l_profile, move_l_time};
use super::noise::{EpisodeStreams, ErrorBudget, ErrorSource, gauss3, true_camera_pose};
use super::wrench::{GRIP_SLIP_FORCE, HELD_CONTACT_STIFFNESS};
use crate::config::{Destination, Placement};
use crate::render::IncrementalRenderer;

/// Least axial load (N) of a contact engine's push at its stop for its lateral force and
/// moment to be scaled to the cell's press (under it, the press is along the axis only).
const MIN_ENGINE_PUSH: f64 = 0.1;
/// Samples along a motion's path checked for reachability and table clearance.
const PATH_SAMPLES: usize = 12;
/// Samples along a guarded move's path searched for the first contact (then refined by
/// bisection).
const GUARD_SAMPLES: usize = 400;
/// Even steps of a guarded move at which its wrench trace samples the contact model.
const GUARD_TRACE_SAMPLES: usize = 64;
/// Further even steps of the trace from first touch to the stop (the press).
const GUARD_TRACE_PRESS_SAMPLES: usize = 16;

/// The arm's last motion as the cell ran it, kept to replay its joints over the clock
/// ([`SimCell::last_motion_trace`]).
#[derive(Debug, Clone)]
enum LastMotion {
    /// A synchronised joint move from `from` to `to`, started at `start` on the clock.
    Joint {
        from: Joints,
        to: Joints,
        start: f64,
        profile: Profile,
    },
    /// A straight TCP line from `from` (at joints `from_q`) to `to`, started at `start`.
    Linear {
        from_q: Joints,
        from: Isometry3<f64>,
        to: Isometry3<f64>,
        start: f64,
        profile: Profile,
    },
    /// A blended path, its joints every controller period (clock time, joints), from its start.
    Sampled(Vec<(f64, Joints)>),
}

/// A move a controller is about to run, for [`SimCell::check_controller_move`].
#[derive(Debug, Clone, Copy)]
pub(crate) enum ControllerMove {
    /// To these joints, joint-interpolated.
    Joints(Joints),
    /// To this TCP pose in the base frame, in a straight line.
    Linear(Isometry3<f64>),
}
/// How far laterally from a target a held part may come down and still count as inserting
/// (beyond it, it comes down beside the receiver), metres.
const INSERTION_REACH: f64 = 0.01;
/// Highest a released part may be above its receiver and still fall into its target (straight
/// down, scored like an insertion from where it was released), metres.
const DROP_HEIGHT: f64 = 0.02;

/// A part the camera sees in the feeder, from the TRUE camera pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct CameraPart {
    /// Instance id.
    pub instance: u32,
    /// Catalog name.
    pub part: String,
    /// True pose of the part in the true camera frame.
    pub camera_T_part: Isometry3<f64>,
    /// Where its origin projects in the image, pixels.
    pub pixel: Point2<f64>,
}

/// The part in the gripper.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct HeldPart {
    /// Instance id.
    pub instance: u32,
    /// Catalog name.
    pub part: String,
    /// True pose of the part in the TCP frame.
    pub tcp_T_part: Isometry3<f64>,
}

/// A part placed by an insertion (whatever its verdict).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct PlacedPart {
    /// Instance id.
    pub instance: u32,
    /// Catalog name.
    pub part: String,
    /// Assembly step index.
    pub step: usize,
    /// True pose in the base frame.
    pub base_T_part: Isometry3<f64>,
    /// Its insertion's verdict.
    pub verdict: Verdict,
}

/// The outcome of the last release: an insertion's verdict, cause, true pose errors and the
/// attribution of its start error to the named error sources.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReleaseReport {
    /// Assembly step index (`None` when released away from every target).
    pub step: Option<usize>,
    /// Instance released.
    pub instance: u32,
    /// Its name.
    pub part: String,
    /// Seated, jammed or missed.
    pub verdict: Verdict,
    /// Why.
    pub cause: InsertionCause,
    /// The scorer's full result (absent when released away from every target).
    pub insertion: Option<InsertionResult>,
    /// The start lateral error split by error source.
    pub budget: Option<ErrorBudget>,
}

/// What a grasp carried in from its error sources, in the TCP frame at the grasp.
#[derive(Debug, Clone, PartialEq)]
struct GraspErrors {
    repeatability: Vector3<f64>,
    calibration: Vector3<f64>,
    residual: Vector3<f64>,
}

#[derive(Debug, Clone)]
struct Held {
    part: HeldPart,
    errors: GraspErrors,
    /// Set once a motion pushed the part into a target: (step, result, true final base pose).
    inserted: Option<(usize, InsertionResult, Isometry3<f64>, ErrorBudget)>,
}

/// One episode of the simulated cell.
#[derive(Debug, Clone)]
pub struct SimCell {
    model: Arc<CellModel>,
    seed: u64,
    episode: u64,
    streams: EpisodeStreams,
    base_T_camera: Isometry3<f64>,
    q: Joints,
    /// Repeatability offset of the true TCP from the commanded one (base frame).
    tcp_error: Vector3<f64>,
    gripper_open: bool,
    /// How far apart the fingers are now, metres.
    opening: f64,
    /// Clock time at which fingers that move while the arm does are where they were sent.
    fingers_ready_at: f64,
    feeder: Vec<FeederPart>,
    held: Option<Held>,
    placed: Vec<PlacedPart>,
    next_instance: u32,
    clock: f64,
    safety: SafetyStatus,
    last_grasp: Option<Result<Grasp, GraspFailure>>,
    last_release: Option<ReleaseReport>,
    shakes: u32,
    /// Gripper opens and closes so far (each takes `cell.gripper.actuation_time`).
    gripper_actuations: u32,
    /// Metres the fingers travelled so far this episode.
    gripper_travel: f64,
    /// Clock time at which the parts of the last shake are at rest again.
    feeder_rest_at: f64,
    /// The arm's last joint move, straight line or blended path, to replay its joints.
    last_motion: Option<LastMotion>,
    /// Whether captures are rendered images (learned perception) or the true scene.
    renders_captures: bool,
    /// The feeder window's last render, reused where the feeder did not change.
    feeder_renderer: IncrementalRenderer,
    /// Why the insertion scorer could not score the last insertion, if it failed.
    scorer_failure: Option<String>,
    /// The wrist sensor's reading error (UR5e precision, its own seeded stream).
    ft: FtNoise,
    /// The contact engine's pushes already simulated for the held part's misalignments.
    felt: FeltStops,
}

#[allow(non_snake_case)]
impl SimCell {
    /// Episode `episode` of a run seeded with `seed`: the same triple gives the same world and
    /// outcomes, and any episode can be replayed alone.
    pub fn new(model: Arc<CellModel>, seed: u64, episode: u64) -> Result<Self, CellError> {
        let mut streams = EpisodeStreams::new(seed, episode);
        let base_T_camera = true_camera_pose(
            &model.geometry.base_T_camera_nominal,
            &model.noise,
            model.spec.calibration.as_ref(),
            &mut streams.calibration,
        );
        let stroke = model.spec.gripper.stroke;
        let mut cell = Self {
            q: model.home,
            model,
            seed,
            episode,
            streams,
            base_T_camera,
            tcp_error: Vector3::zeros(),
            gripper_open: true,
            opening: stroke,
            fingers_ready_at: 0.0,
            feeder: Vec::new(),
            held: None,
            placed: Vec::new(),
            next_instance: 1,
            clock: 0.0,
            safety: SafetyStatus::Normal,
            last_grasp: None,
            last_release: None,
            shakes: 0,
            gripper_actuations: 0,
            gripper_travel: 0.0,
            feeder_rest_at: 0.0,
            last_motion: None,
            renders_captures: false,
            feeder_renderer: IncrementalRenderer::new(),
            scorer_failure: None,
            ft: FtNoise::ur5e(
                seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ episode.wrapping_add(0x5EED_F0CE),
            ),
            felt: FeltStops::default(),
        };
        cell.refill()?;
        Ok(cell)
    }

    /// The shared model (specs, shapes, kinematics, nominal targets, grasp poses).
    pub fn model(&self) -> &Arc<CellModel> {
        &self.model
    }

    /// (seed, episode) of this episode.
    pub fn episode(&self) -> (u64, u64) {
        (self.seed, self.episode)
    }

    /// Simulated time since the episode started, seconds (motions, gripper actuation).
    pub fn clock(&self) -> f64 {
        self.clock
    }

    /// The calibrated (nominal) camera pose the orchestrator knows.
    pub fn base_T_camera_nominal(&self) -> Isometry3<f64> {
        self.model.geometry.base_T_camera_nominal
    }

    /// Why the insertion scorer failed on an insertion of this episode, if it did: the part was
    /// then left unscored, and no verdict about it means anything.
    pub fn scorer_failure(&self) -> Option<&str> {
        self.scorer_failure.as_deref()
    }

    /// Makes captures rendered images (for learned perception) instead of the true scene.
    pub fn render_captures(mut self, on: bool) -> Self {
        self.renders_captures = on;
        self
    }

    /// Whether captures are rendered images.
    pub fn renders_captures(&self) -> bool {
        self.renders_captures
    }

    /// The feeder window as the camera sees it now: rendered from the true camera and part
    /// poses through the sensor (its noise from the episode's camera stream).
    pub fn render_feeder(&mut self) -> Result<super::FeederImage, CellError> {
        super::capture::render_feeder(
            &self.model,
            &self.feeder,
            &self.base_T_camera,
            &mut self.feeder_renderer,
            &mut self.streams.camera,
        )
    }

    /// The true camera pose (diagnostics only: a real cell does not know it).
    pub fn base_T_camera_true(&self) -> Isometry3<f64> {
        self.base_T_camera
    }

    /// What the camera sees: every feeder part whose origin projects into the image, with its
    /// true pose in the TRUE camera frame.
    pub fn camera_view(&self) -> Vec<CameraPart> {
        let cam = &self.model.spec.camera.intrinsics;
        let camera_T_base = self.base_T_camera.inverse();
        self.feeder
            .iter()
            .filter_map(|p| {
                let camera_T_part =
                    camera_T_base * self.model.geometry.base_T_table * p.table_T_part;
                let pixel = cam
                    .project(&Point3::from(camera_T_part.translation.vector))
                    .ok()?;
                cam.contains(pixel).then(|| CameraPart {
                    instance: p.instance,
                    part: p.part.clone(),
                    camera_T_part,
                    pixel,
                })
            })
            .collect()
    }

    /// True poses of the parts in the feeder, table frame (diagnostics and perception-free runs).
    pub fn feeder_parts(&self) -> &[FeederPart] {
        &self.feeder
    }

    /// The part in the gripper and its true pose in the TCP frame.
    pub fn held(&self) -> Option<&HeldPart> {
        self.held.as_ref().map(|h| &h.part)
    }

    /// The outcome of the last `close_gripper`: the grasp, or why it failed.
    pub fn last_grasp(&self) -> Option<&Result<Grasp, GraspFailure>> {
        self.last_grasp.as_ref()
    }

    /// The outcome of the last release with a part in the gripper.
    pub fn last_release(&self) -> Option<&ReleaseReport> {
        self.last_release.as_ref()
    }

    /// Parts placed by insertions so far.
    pub fn placed(&self) -> &[PlacedPart] {
        &self.placed
    }

    /// The insertion verdict of the part still in the gripper, before release: `Some` once the
    /// last motion pushed the held part into its target (what a production cell measures by
    /// height and force before it opens the fingers). The part stays in the fingers where the
    /// insertion left it (it may have slipped); the next motion takes it back out.
    pub fn held_insertion(&self) -> Option<ReleaseReport> {
        let h = self.held.as_ref()?;
        let (step, result, _, budget) = h.inserted.as_ref()?;
        Some(ReleaseReport {
            step: Some(*step),
            instance: h.part.instance,
            part: h.part.part.clone(),
            verdict: result.verdict,
            cause: result.cause,
            insertion: Some(result.clone()),
            budget: Some(budget.clone()),
        })
    }

    /// Shakes done so far this episode.
    pub fn shakes(&self) -> u32 {
        self.shakes
    }

    /// Gripper actuations (opens and closes, each timed by the fingers' travel,
    /// [`crate::config::GripperSpec::travel_time`]) so far this episode.
    pub fn gripper_actuations(&self) -> u32 {
        self.gripper_actuations
    }

    /// Metres the fingers travelled so far this episode (opening and closing).
    pub fn gripper_travel(&self) -> f64 {
        self.gripper_travel
    }

    /// The true base-frame pose where step `step`'s part goes, as the world now is: on the
    /// fixture, or relative to the true pose of the part placed by the earlier step.
    pub fn target(&self, step: usize) -> Option<Isometry3<f64>> {
        let s = self.model.steps.get(step)?;
        Some(self.destination(&s.into)? * s.target.isometry())
    }

    /// The true pose of the TCP (the commanded pose off by the robot's repeatability).
    pub fn true_tcp(&self) -> Isometry3<f64> {
        Translation3::from(self.tcp_error) * self.model.kinematics.forward_tcp(&self.q)
    }

    /// Clock time at which the parts of the last shake are at rest.
    pub fn feeder_rest_at(&self) -> f64 {
        self.feeder_rest_at
    }

    /// Lets the clock run on to `t` (work off the arm's path, such as perception, that the arm
    /// waits for); never back.
    pub fn wait_until(&mut self, t: f64) {
        self.clock = self.clock.max(t);
    }

    /// Waits (on the clock) until the parts of the last shake are at rest: a camera frame of the
    /// feeder or a grasp in it is only meaningful then.
    pub fn wait_for_feeder(&mut self) {
        self.clock = self.clock.max(self.feeder_rest_at);
    }

    /// Clears a protective stop (like the dashboard's `unlock protective stop`).
    pub fn unlock_protective_stop(&mut self) {
        self.safety = SafetyStatus::Normal;
    }

    /// Shakes the feeder: every part in it is re-placed (re-sampled or re-dropped). The feeder
    /// runs on its own: the shake and the parts settling take the feeder's `shake_time`, during
    /// which the arm may go on working elsewhere; the camera and the fingers wait for the parts
    /// to rest ([`Self::wait_for_feeder`]).
    pub fn shake(&mut self) -> Result<(), CellError> {
        self.shake_from(self.clock)
    }

    /// Shakes the feeder as [`Self::shake`] does, the shake having started at `t` on the clock:
    /// an instant during the arm's last motion, which the cell ran to its end before the caller
    /// could act (the orchestrator starts a shake mid-transit, at the first instant the arm is
    /// clear of the feeder, [`Self::last_motion_trace`]). `t` is taken no later than now and no
    /// earlier than that motion's start; the parts settle `shake_time` after it.
    pub fn shake_from(&mut self, t: f64) -> Result<(), CellError> {
        let earliest = self.last_motion_start().unwrap_or(self.clock);
        let t = if t.is_finite() {
            t.clamp(earliest.min(self.clock), self.clock)
        } else {
            self.clock
        };
        let wanted: Vec<(String, u32)> = self
            .feeder
            .iter()
            .map(|p| (p.part.clone(), p.instance))
            .collect();
        self.feeder = self.place(&wanted, &[])?;
        self.feeder_rest_at = self.feeder_rest_at.max(t) + self.model.spec.feeder.shake_time;
        self.shakes += 1;
        Ok(())
    }

    /// Refills the feeder up to the scenario's count of each part (new instance ids).
    pub fn refill(&mut self) -> Result<(), CellError> {
        let mut wanted = Vec::new();
        for (name, &count) in &self.model.spec.feeder.parts {
            let have = self.feeder.iter().filter(|p| &p.part == name).count() as u32;
            for _ in have..count {
                wanted.push((name.clone(), self.next_instance));
                self.next_instance += 1;
            }
        }
        if wanted.is_empty() {
            return Ok(());
        }
        let keep = self.feeder.clone();
        let added = match self.model.spec.feeder.placement {
            Placement::Sampled => self.place(&wanted, &keep)?,
            // A drop re-settles everything in the feeder together.
            Placement::Dropped => {
                let mut all: Vec<(String, u32)> =
                    keep.iter().map(|p| (p.part.clone(), p.instance)).collect();
                all.extend(wanted);
                self.feeder.clear();
                self.place(&all, &[])?
            }
        };
        self.feeder.extend(added);
        Ok(())
    }

    fn place(
        &mut self,
        wanted: &[(String, u32)],
        keep: &[FeederPart],
    ) -> Result<Vec<FeederPart>, CellError> {
        let spec = &self.model.spec.feeder;
        match spec.placement {
            Placement::Sampled => feeder::sample(
                spec,
                &self.model.geometry,
                wanted,
                keep,
                &mut self.streams.feeder,
            ),
            Placement::Dropped => feeder::drop(
                spec,
                &self.model.part_models,
                wanted,
                &mut self.streams.feeder,
            ),
        }
    }

    fn destination(&self, into: &Destination) -> Option<Isometry3<f64>> {
        match into {
            Destination::Fixture => Some(self.model.geometry.base_T_fixture),
            Destination::Part(name) => self
                .placed
                .iter()
                .rev()
                .find(|p| &p.part == name)
                .map(|p| p.base_T_part),
        }
    }

    fn check_motion_allowed(&self) -> Result<(), RobotError> {
        match self.safety.motion_error() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Lowest point (table frame z) of the fingertips and the held part at a TCP pose.
    fn lowest_z(&self, base_T_tcp: &Isometry3<f64>) -> f64 {
        let table_T_base = self.model.geometry.base_T_table.inverse();
        let tip = (table_T_base * base_T_tcp).translation.z;
        let part = self.held.as_ref().and_then(|h| {
            let g = self.model.geometry.parts.get(&h.part.part)?;
            let t = table_T_base * base_T_tcp * h.part.tcp_T_part;
            Some(
                g.mesh
                    .vertices
                    .iter()
                    .map(|p| (t * p).z)
                    .fold(f64::INFINITY, f64::min),
            )
        });
        part.map_or(tip, |p| p.min(tip))
    }

    /// Protective stop when a pose on the path puts the fingertips or the held part into the
    /// table, unless the held part is coming down into its target.
    fn check_clearance(&mut self, poses: &[Isometry3<f64>]) -> Result<(), RobotError> {
        for pose in poses {
            if self.lowest_z(pose) < 0.0 && self.insertion_at(pose, 0.0).is_none() {
                self.safety = SafetyStatus::ProtectiveStop;
                return Err(RobotError::ProtectiveStop);
            }
        }
        Ok(())
    }

    /// The step and insertion frame when the held part at TCP pose `base_T_tcp` is coming down
    /// into its target: below the receiver's top and within reach of the target laterally.
    fn insertion_at(
        &self,
        base_T_tcp: &Isometry3<f64>,
        above: f64,
    ) -> Option<(usize, Isometry3<f64>, Mating)> {
        let held = self.held.as_ref()?;
        let step = self.pending_step(&held.part.part)?;
        let s = &self.model.steps[step];
        let base_T_dest = self.destination(&s.into)?;
        let base_T_ins = self.model.insertion_frame(step, &base_T_dest)?;
        let mating = self.mating(step, &base_T_dest)?;
        let ins_T_part = base_T_ins.inverse() * base_T_tcp * held.part.tcp_T_part;
        let e = mating.pose_error(&ins_T_part);
        (e.height < mating.engagement + above && e.lateral.norm() < INSERTION_REACH)
            .then_some((step, base_T_ins, mating))
    }

    fn pending_step(&self, part: &str) -> Option<usize> {
        self.model.steps.iter().enumerate().position(|(i, s)| {
            s.part == part
                && !self
                    .placed
                    .iter()
                    .any(|p| p.step == i && p.verdict == Verdict::Seated)
        })
    }

    /// The pieces a contact engine pushes together for `step`: the inserted part's geometry and
    /// its receivers where the step's destination stands now (the fixture when it is not placed).
    #[allow(non_snake_case)]
    fn insertion_pieces(
        &self,
        step: usize,
    ) -> Option<(&super::geometry::PartGeometry, Vec<ReceiverPart<'_>>)> {
        let s = &self.model.steps[step];
        let base_T_dest = self
            .destination(&s.into)
            .unwrap_or(self.model.geometry.base_T_fixture);
        Some((
            self.model.geometry.parts.get(&s.part)?,
            self.receivers(step, &base_T_dest)?,
        ))
    }

    fn receivers(
        &self,
        step: usize,
        base_T_dest: &Isometry3<f64>,
    ) -> Option<Vec<ReceiverPart<'_>>> {
        let s = &self.model.steps[step];
        let geo = &self.model.geometry;
        let dest_T_base = base_T_dest.inverse();
        let mut out = Vec::new();
        match &s.into {
            Destination::Fixture => out.push(ReceiverPart {
                geometry: geo.parts.get(&geo.fixture_part)?,
                destination_T_part: Isometry3::identity(),
            }),
            Destination::Part(name) => {
                out.push(ReceiverPart {
                    geometry: geo.parts.get(name)?,
                    destination_T_part: Isometry3::identity(),
                });
                out.push(ReceiverPart {
                    geometry: geo.parts.get(&geo.fixture_part)?,
                    destination_T_part: dest_T_base * geo.base_T_fixture,
                });
                for p in &self.placed {
                    if &p.part != name {
                        out.push(ReceiverPart {
                            geometry: geo.parts.get(&p.part)?,
                            destination_T_part: dest_T_base * p.base_T_part,
                        });
                    }
                }
            }
        }
        Some(out)
    }

    fn mating(&self, step: usize, base_T_dest: &Isometry3<f64>) -> Option<Mating> {
        let s = &self.model.steps[step];
        let held = self.model.geometry.parts.get(&s.part)?;
        let receivers = self.receivers(step, base_T_dest)?;
        Some(Mating::new(s, held, &receivers[..1]))
    }

    /// After a motion: if the held part came down into its target, score the insertion.
    fn settle_insertion(&mut self, above: f64) {
        self.settle_insertion_at(self.true_tcp(), above, false);
    }

    /// Scores the insertion of the held part with the true TCP at `tcp`, if it came down into
    /// its target there. `felt`: the part was pressed in by a guarded move, so a contact
    /// engine's push that stopped it ([`Self::felt_stop`]) is its score (the same call), and the
    /// part then rests where that push left it.
    fn settle_insertion_at(&mut self, tcp: Isometry3<f64>, above: f64, felt: bool) {
        let Some((step, base_T_ins, mating)) = self.insertion_at(&tcp, above) else {
            return;
        };
        let Some(held) = self.held.as_ref() else {
            return;
        };
        let ins_T_part = base_T_ins.inverse() * tcp * held.part.tcp_T_part;
        let Some((geom, receivers)) = self.insertion_pieces(step) else {
            return;
        };
        let case = InsertionCase {
            mating: &mating,
            held: geom,
            receivers: &receivers,
            ins_T_part,
        };
        let key = FeltKey {
            instance: held.part.instance,
            step,
            placed: self.placed.len(),
            ins_T_part,
        };
        let pushed = if felt {
            self.felt.get(&key).filter(|f| f.scored.is_some())
        } else {
            None
        };
        // Every part was checked against the scorer when the model was built; an engine that
        // still fails leaves the part unscored and says why (`scorer_failure`).
        let scored = match pushed.as_ref().and_then(|f| f.scored.clone()) {
            // The engines start every push from the same clear height: only the start's
            // recorded height differs.
            Some(mut s) => {
                s.result = InsertionResult::ended_at(
                    &mating,
                    mating.pose_error(&ins_T_part),
                    s.result.ins_T_part,
                );
                s
            }
            None => match self.model.insertion.score(&case) {
                Ok(scored) => scored,
                Err(e) => {
                    self.scorer_failure = Some(format!("step {step}: {e}"));
                    return;
                }
            },
        };
        self.clock += scored.simulated_time;
        let result = scored.result;
        if let Some(f) = pushed {
            // The part now rests where the push left it: the same stop for its new pose.
            self.felt.insert(
                FeltKey {
                    ins_T_part: result.ins_T_part,
                    ..key
                },
                f,
            );
        }
        let budget = self.budget(&base_T_ins, &tcp, result.start.lateral);
        let base_T_part = base_T_ins * result.ins_T_part;
        if let Some(h) = self.held.as_mut() {
            h.part.tcp_T_part = tcp.inverse() * base_T_part;
            h.inserted = Some((step, result, base_T_part, budget));
        }
    }

    /// The held part's true pose error against its target where it is now, and that lateral
    /// error split into the error sources (as an insertion's budget), while it is over its
    /// target: within reach laterally, and at most `above` over the receiver's top (a part
    /// stopped on the rim never came down into its target, and no insertion scored it).
    #[allow(non_snake_case)]
    pub fn held_budget(&self, above: f64) -> Option<(PoseError, ErrorBudget)> {
        let tcp = self.true_tcp();
        let (_, base_T_ins, mating) = self.insertion_at(&tcp, above)?;
        let held = self.held.as_ref()?;
        let e = mating.pose_error(&(base_T_ins.inverse() * tcp * held.part.tcp_T_part));
        let budget = self.budget(&base_T_ins, &tcp, e.lateral);
        Some((e, budget))
    }

    /// Splits the start lateral error `lateral` (insertion frame) into the named sources.
    fn budget(
        &self,
        base_T_ins: &Isometry3<f64>,
        base_T_tcp: &Isometry3<f64>,
        lateral: Vector2<f64>,
    ) -> ErrorBudget {
        let ins_R_base = base_T_ins.rotation.inverse();
        let to_ins = |v_tcp: &Vector3<f64>| {
            let v = ins_R_base * (base_T_tcp.rotation * v_tcp);
            Vector2::new(v.x, v.y)
        };
        let now = ins_R_base * self.tcp_error;
        let mut named = vec![(ErrorSource::RobotRepeatability, Vector2::new(now.x, now.y))];
        if let Some(h) = &self.held {
            named[0].1 += to_ins(&h.errors.repeatability);
            named.push((
                ErrorSource::CameraCalibration,
                to_ins(&h.errors.calibration),
            ));
            named.push((ErrorSource::GraspResidual, to_ins(&h.errors.residual)));
        }
        ErrorBudget::new(named, lateral)
    }

    /// Runs a joint move now (the `Robot::move_j` body). The cell's limits are not checked here:
    /// wrap the cell in [`robots::limited::Limited`] ([`CellModel::limited`]) to drive it.
    pub fn move_j_sync(&mut self, target: Joints, motion: JointMotion) -> Result<(), RobotError> {
        self.check_motion_allowed()?;
        let poses = self.joint_path(&target);
        self.begin_motion();
        self.check_clearance(&poses)?;
        let profile = move_j_profile(&self.q, &target, &motion, &self.model.spec.limits);
        self.last_motion = Some(LastMotion::Joint {
            from: self.q,
            to: target,
            start: self.clock,
            profile,
        });
        self.clock += profile.duration();
        self.q = target;
        self.end_motion();
        Ok(())
    }

    /// Runs a straight-line TCP move now (the `Robot::move_l` body); limits as for
    /// [`Self::move_j_sync`].
    pub fn move_l_sync(
        &mut self,
        base_T_tcp: Isometry3<f64>,
        motion: LinearMotion,
    ) -> Result<(), RobotError> {
        self.check_motion_allowed()?;
        let start = self.model.kinematics.forward_tcp(&self.q);
        let (poses, q) = self.linear_path(&base_T_tcp)?;
        self.begin_motion();
        self.check_clearance(&poses)?;
        let profile = move_l_profile(&start, &base_T_tcp, &motion, &self.model.spec.limits);
        self.last_motion = Some(LastMotion::Linear {
            from_q: self.q,
            from: start,
            to: base_T_tcp,
            start: self.clock,
            profile,
        });
        self.clock += profile.duration();
        self.q = q;
        self.end_motion();
        Ok(())
    }

    /// Runs a blended path now (the `Robot::move_path` body): the clearance of every segment
    /// checked as a move's (a blend cuts a corner by at most its radius), then the motion, its
    /// time and its final joints from the virtual UR's arm model ([`execute_path`] on
    /// [`Self::controller_arm`] at the controller's period), the model the controller runs the
    /// same path with over RTDE.
    pub fn move_path_sync(&mut self, path: &[Waypoint]) -> Result<(), RobotError> {
        self.check_motion_allowed()?;
        let moves = waypoint_moves(path);
        self.check_controller_path(&moves)?;
        let mut arm = self.controller_arm();
        let start = self.clock;
        let mut trace = vec![(start, self.q)];
        let run = execute_path(&mut arm, &moves, CONTROLLER_PERIOD, |c| {
            trace.push((start + c.t, c.state.q));
            Ok::<_, ArmError>(())
        })
        .map_err(|e| {
            // Refused before anything moved, as `Limited`'s check refuses it.
            RobotError::LimitViolation(robots::limits::LimitViolation::PathRefused {
                detail: e.to_string(),
            })
        })?;
        self.last_motion = Some(LastMotion::Sampled(trace));
        // A blend URScript would skip (`run.warnings`) is skipped here too: the arm stops at
        // that via-point, as the controller's does.
        self.clock += run.duration;
        self.q = run.q;
        self.end_motion();
        Ok(())
    }

    /// When the arm's last joint move, straight line or blended path started, on the clock.
    fn last_motion_start(&self) -> Option<f64> {
        match self.last_motion.as_ref()? {
            LastMotion::Joint { start, .. } | LastMotion::Linear { start, .. } => Some(*start),
            LastMotion::Sampled(trace) => trace.first().map(|(t, _)| *t),
        }
    }

    /// The arm's joints along its last joint move, straight line or blended path, as the cell
    /// ran it: (clock time, joints) from its start to its end, both included, every `step`
    /// seconds (a blended path every controller period, 2 ms, whatever `step`); empty before
    /// any motion. The commanded joints, as the arm reports them (the repeatability error is
    /// the TCP's, not the joints').
    pub fn last_motion_trace(&self, step: f64) -> Vec<(f64, Joints)> {
        let step = if step.is_finite() && step > 0.0 {
            step
        } else {
            CONTROLLER_PERIOD
        };
        let times = |start: f64, profile: Profile| {
            let total = profile.duration();
            let n = (total / step).ceil().max(1.0) as usize;
            (0..=n).map(move |k| {
                let t = (k as f64 * step).min(total);
                (start + t, profile.fraction(t))
            })
        };
        match self.last_motion.as_ref() {
            None => Vec::new(),
            Some(LastMotion::Sampled(trace)) => trace.clone(),
            Some(LastMotion::Joint {
                from,
                to,
                start,
                profile,
            }) => times(*start, *profile)
                .map(|(t, s)| (t, std::array::from_fn(|i| from[i] + s * (to[i] - from[i]))))
                .collect(),
            Some(LastMotion::Linear {
                from_q,
                from,
                to,
                start,
                profile,
            }) => {
                let mut q = *from_q;
                times(*start, *profile)
                    .map(|(t, s)| {
                        let pose = from.lerp_slerp(to, s);
                        if let Ok(sol) = self.model.kinematics.inverse_nearest(&pose, &q) {
                            q = sol.joints;
                        }
                        (t, q)
                    })
                    .collect()
            }
        }
    }

    /// The virtual UR's kinematic arm model for this cell, at its joints: the cell's kinematics
    /// (with its gripper TCP) and its speed and acceleration limits as the arm's.
    pub fn controller_arm(&self) -> KinematicArm {
        let limits = &self.model.spec.limits;
        let mut arm = KinematicArm::new(self.model.kinematics.clone(), self.q);
        arm.max_joint_speed = limits.max_joint_speed;
        arm.max_joint_accel = limits.max_joint_acceleration;
        arm.max_tool_speed = limits.max_tcp_speed;
        arm.max_tool_accel = limits.max_tcp_acceleration;
        arm
    }

    /// For a blended path about to start (in process or in the virtual UR's arm model): each
    /// segment, from the previous via-point, checked for table clearance as a single move is;
    /// protective stop on the first that is not clear.
    pub(crate) fn check_controller_path(&mut self, moves: &[PathMove]) -> Result<(), RobotError> {
        let kinematics = &self.model.kinematics;
        let mut q = self.q;
        let mut poses = Vec::with_capacity(moves.len() * PATH_SAMPLES);
        for m in moves {
            match *m {
                PathMove::Joint { q: target, .. } => {
                    poses.extend((1..=PATH_SAMPLES).map(|k| {
                        let s = k as f64 / PATH_SAMPLES as f64;
                        let qs: Joints = std::array::from_fn(|i| q[i] + s * (target[i] - q[i]));
                        kinematics.forward_tcp(&qs)
                    }));
                    q = target;
                }
                PathMove::Linear { pose, .. } => {
                    let start = kinematics.forward_tcp(&q);
                    let end = from_ur_pose(&pose);
                    for k in 1..=PATH_SAMPLES {
                        let p = start.lerp_slerp(&end, k as f64 / PATH_SAMPLES as f64);
                        q = kinematics.inverse_nearest(&p, &q)?.joints;
                        poses.push(p);
                    }
                }
            }
        }
        self.begin_motion();
        self.check_clearance(&poses)
    }

    /// The TCP poses a joint move from the current joints to `target` is checked at.
    fn joint_path(&self, target: &Joints) -> Vec<Isometry3<f64>> {
        (1..=PATH_SAMPLES)
            .map(|k| {
                let s = k as f64 / PATH_SAMPLES as f64;
                let q: Joints = std::array::from_fn(|i| self.q[i] + s * (target[i] - self.q[i]));
                self.model.kinematics.forward_tcp(&q)
            })
            .collect()
    }

    /// The TCP poses a straight-line move to `base_T_tcp` is checked at, and the joints it ends
    /// at (following the current IK branch).
    #[allow(non_snake_case)]
    fn linear_path(
        &self,
        base_T_tcp: &Isometry3<f64>,
    ) -> Result<(Vec<Isometry3<f64>>, Joints), RobotError> {
        let start = self.model.kinematics.forward_tcp(&self.q);
        let mut q = self.q;
        let mut poses = Vec::with_capacity(PATH_SAMPLES);
        for k in 1..=PATH_SAMPLES {
            let pose = start.lerp_slerp(base_T_tcp, k as f64 / PATH_SAMPLES as f64);
            q = self.model.kinematics.inverse_nearest(&pose, &q)?.joints;
            poses.push(pose);
        }
        Ok((poses, q))
    }

    /// For a controller about to start a move (the virtual UR's arm model): protective stop,
    /// as the in-process move would, when its path puts the fingertips or the held part into
    /// the table. `Ok` for a path that is clear.
    #[allow(non_snake_case)]
    pub(crate) fn check_controller_move(
        &mut self,
        target: ControllerMove,
    ) -> Result<(), RobotError> {
        let poses = match target {
            ControllerMove::Joints(q) => self.joint_path(&q),
            ControllerMove::Linear(base_T_tcp) => self.linear_path(&base_T_tcp)?.0,
        };
        self.begin_motion();
        self.check_clearance(&poses)
    }

    fn begin_motion(&mut self) {
        // A part pushed into a target and still held comes back out with the gripper.
        if let Some(h) = self.held.as_mut() {
            h.inserted = None;
        }
    }

    fn end_motion(&mut self) {
        // A motion ends with the fingers where they were sent during it.
        self.clock = self.clock.max(self.fingers_ready_at);
        self.tcp_error = gauss3(
            &mut self.streams.robot,
            self.model.noise.robot_repeatability,
        );
        if !self.gripper_open {
            self.settle_insertion(0.0);
        }
    }

    /// One gripper open or close on the clock: the fingers travel from the present opening to
    /// `to` ([`crate::config::GripperSpec::travel_time`]).
    fn actuate_gripper(&mut self, to: f64) {
        self.move_fingers(to, true);
    }

    /// The fingers travel to `to` after any earlier travel ends; the clock waits for them when
    /// `wait`, else the next motion or gripper command does.
    fn move_fingers(&mut self, to: f64, wait: bool) {
        let start = self.clock.max(self.fingers_ready_at);
        let end = start + self.model.spec.gripper.travel_time(to - self.opening);
        if wait {
            self.clock = end;
        } else {
            self.fingers_ready_at = end;
        }
        self.gripper_travel += (to - self.opening).abs();
        self.opening = to;
        self.gripper_actuations += 1;
    }

    /// Where fingers sent to `width` go: within the stroke (the full stroke for a width that
    /// is not a number).
    fn finger_target(&self, width: f64) -> f64 {
        let stroke = self.model.spec.gripper.stroke;
        if width.is_finite() {
            width.clamp(0.0, stroke)
        } else {
            stroke
        }
    }

    /// How far apart the fingers are now, metres.
    pub fn finger_opening(&self) -> f64 {
        self.opening
    }

    /// Whether the gripper is open (its last command opened it).
    pub fn gripper_is_open(&self) -> bool {
        self.gripper_open
    }

    /// Opens the gripper the full stroke now; see [`Self::open_gripper_to_sync`].
    pub fn open_gripper_sync(&mut self) {
        self.open_gripper_to_sync(self.model.spec.gripper.stroke);
    }

    /// Sends empty fingers to `width` apart while the arm goes on: the clock does not wait here,
    /// the next motion ends no earlier than the fingers arrive, and the next gripper command
    /// waits for them. With a part between the fingers this is [`Self::open_gripper_to_sync`]
    /// (a release waits).
    pub fn send_fingers_to(&mut self, width: f64) {
        if self.held.is_some() || !self.gripper_open {
            self.open_gripper_to_sync(width);
            return;
        }
        self.move_fingers(self.finger_target(width), false);
    }

    /// Moves the fingers to `width` apart now (the `Robot::open_gripper_to` body; at most the
    /// stroke, and with a part between them no closer than they hold it); a held part is
    /// released where it is and the release is reported.
    pub fn open_gripper_to_sync(&mut self, width: f64) {
        let mut to = self.finger_target(width);
        if self.held.is_some() {
            to = to.max(self.opening);
        }
        self.actuate_gripper(to);
        self.gripper_open = true;
        // Released above its target: it falls in, scored from where it was let go.
        if self.held.as_ref().is_some_and(|h| h.inserted.is_none()) {
            self.settle_insertion(DROP_HEIGHT);
        }
        let Some(held) = self.held.take() else { return };
        let report = match held.inserted {
            Some((step, result, base_T_part, budget)) => {
                self.placed.push(PlacedPart {
                    instance: held.part.instance,
                    part: held.part.part.clone(),
                    step,
                    base_T_part,
                    verdict: result.verdict,
                });
                ReleaseReport {
                    step: Some(step),
                    instance: held.part.instance,
                    part: held.part.part,
                    verdict: result.verdict,
                    cause: result.cause,
                    insertion: Some(result),
                    budget: Some(budget),
                }
            }
            None => ReleaseReport {
                step: None,
                instance: held.part.instance,
                part: held.part.part,
                verdict: Verdict::Missed,
                cause: InsertionCause::ReleasedAwayFromTarget,
                insertion: None,
                budget: None,
            },
        };
        self.last_release = Some(report);
    }

    /// Closes the gripper now (the `Robot::close_gripper` body); see [`Self::last_grasp`].
    pub fn close_gripper_sync(&mut self) {
        self.wait_for_feeder();
        self.clock = self.clock.max(self.fingers_ready_at);
        if !self.gripper_open {
            self.actuate_gripper(self.opening);
            return;
        }
        self.gripper_open = false;
        let tcp = self.true_tcp();
        let geo = &self.model.geometry;
        let candidates: Vec<GraspCandidate<'_>> = self
            .feeder
            .iter()
            .filter_map(|p| {
                Some(GraspCandidate {
                    instance: p.instance,
                    geometry: geo.parts.get(&p.part)?,
                    base_T_part: geo.base_T_table * p.table_T_part,
                })
            })
            .collect();
        let result = gripper::close_from(
            &self.model.spec.gripper,
            self.opening,
            &self.model.noise,
            &tcp,
            &candidates,
            &mut self.streams.grasp,
        );
        if let Ok(g) = &result
            && let Some(i) = self.feeder.iter().position(|p| p.instance == g.instance)
        {
            let p = self.feeder.remove(i);
            let base_T_part = geo.base_T_table * p.table_T_part;
            // Where the orchestrator would have believed the part was with perfect perception
            // through the calibrated camera, and what that did across the jaws.
            let seen = self.model.geometry.base_T_camera_nominal
                * self.base_T_camera.inverse()
                * Point3::from(base_T_part.translation.vector);
            let e_cal = seen.coords - base_T_part.translation.vector;
            let tcp_R_base = tcp.rotation.inverse();
            let across = |v: Vector3<f64>| {
                let t = tcp_R_base * v;
                Vector3::new(t.x, 0.0, 0.0)
            };
            let bottom = geo.parts.get(&p.part).map_or(0.0, |pg| pg.aabb.0.z);
            let lead = g.tcp_T_part.rotation * Vector3::new(0.0, 0.0, bottom);
            let errors = GraspErrors {
                repeatability: -across(self.tcp_error),
                calibration: -across(e_cal),
                residual: g.residual_offset + g.residual_rotation.cross(&lead),
            };
            self.held = Some(Held {
                part: HeldPart {
                    instance: p.instance,
                    part: p.part,
                    tcp_T_part: g.tcp_T_part,
                },
                errors,
                inserted: None,
            });
        }
        // The fingers stop on the part, or close fully on nothing.
        let closed_to = result.as_ref().map_or(0.0, |g| g.width);
        self.actuate_gripper(closed_to.min(self.opening));
        self.last_grasp = Some(result);
    }

    /// The true external wrench on the tool (base frame, at the TCP: force N, moment N·m) with
    /// the arm commanded at `base_T_tcp`: a held part coming down into its target meets what
    /// stops it ([`Self::felt_stop`]: the seat, the rim, or a jam, where the scenario's scorer
    /// stops it) and presses on it with [`HELD_CONTACT_STIFFNESS`] up to [`GRIP_SLIP_FORCE`]
    /// along the insertion frame's z (with a contact engine, the engine's load at its stop,
    /// lateral force and moment included, scaled to that press); fingertips or a held part
    /// below the table press on it with the table's stiffness. Zero otherwise (the fixture's
    /// and placed parts' other faces are not modelled).
    #[allow(non_snake_case)]
    pub fn contact_wrench_at(&self, base_T_tcp: &Isometry3<f64>) -> Wrench {
        let tcp = Translation3::from(self.tcp_error) * base_T_tcp;
        if let Some(h) = self.held.as_ref()
            && !self.gripper_open
            && let Some((step, base_T_ins, mating)) = self.insertion_at(&tcp, 0.0)
        {
            let ins_T_part = base_T_ins.inverse() * tcp * h.part.tcp_T_part;
            let felt = self.felt_stop(step, &mating, &ins_T_part);
            let depth = felt.height - mating.pose_error(&ins_T_part).height;
            if depth <= 0.0 {
                return [0.0; 6];
            }
            let press = (HELD_CONTACT_STIFFNESS * depth).min(GRIP_SLIP_FORCE);
            let (f, m) = match felt.wrench.filter(|w| w.force.z > MIN_ENGINE_PUSH) {
                // The engine's load at its stop, its share of lateral force and moment kept.
                Some(w) => {
                    let scale = press / w.force.z;
                    let force = w.force * scale;
                    let centre = ins_T_part * mating.lead_point;
                    let at = base_T_ins.inverse() * Point3::from(tcp.translation.vector);
                    let moment = w.moment * scale + (centre - at).cross(&force);
                    (base_T_ins.rotation * force, base_T_ins.rotation * moment)
                }
                None => (base_T_ins.rotation * Vector3::z() * press, Vector3::zeros()),
            };
            return [f.x, f.y, f.z, m.x, m.y, m.z];
        }
        let below = -self.lowest_z(&tcp);
        if below > 0.0 {
            let f = self.model.geometry.base_T_table.rotation
                * Vector3::z()
                * (TABLE_STIFFNESS * below);
            return [f.x, f.y, f.z, 0.0, 0.0, 0.0];
        }
        [0.0; 6]
    }

    /// Where the held part at `ins_T_part` (insertion frame of step `step`) stops when pressed
    /// into its target, and what the wrist feels there, from the scenario's scorer: the
    /// analytic capture model's end height; or a contact engine's push for this misalignment
    /// (simulated once, then remembered: the same call scores the insertion when the guarded
    /// move ends). An engine that fails falls back to the analytic stop (and the insertion's
    /// scoring says why).
    #[allow(non_snake_case)]
    pub fn felt_stop(
        &self,
        step: usize,
        mating: &Mating,
        ins_T_part: &Isometry3<f64>,
    ) -> Arc<FeltStop> {
        let analytic = || {
            Arc::new(FeltStop {
                height: super::insertion::analytic::score(mating, ins_T_part)
                    .end
                    .height,
                wrench: None,
                scored: None,
            })
        };
        let Some(held) = self.held.as_ref() else {
            return analytic();
        };
        if self.model.scorer == Scorer::Analytic {
            return analytic();
        }
        let key = FeltKey {
            instance: held.part.instance,
            step,
            placed: self.placed.len(),
            ins_T_part: *ins_T_part,
        };
        if let Some(f) = self.felt.get(&key) {
            return f;
        }
        let Some((geom, receivers)) = self.insertion_pieces(step) else {
            return analytic();
        };
        let case = InsertionCase {
            mating,
            held: geom,
            receivers: &receivers,
            ins_T_part: *ins_T_part,
        };
        let Ok((scored, wrench)) = self.model.insertion.score_with_wrench(&case) else {
            return analytic();
        };
        let felt = Arc::new(FeltStop {
            height: scored.result.end.height,
            wrench: wrench.last().copied(),
            scored: Some(scored),
        });
        self.felt.insert(key, felt.clone());
        felt
    }

    /// Makes ready the contact model for a move to `base_T_tcp` (a controller's `movel` target):
    /// a contact engine's push for the held part's misalignment there is simulated now, before
    /// the arm moves, rather than by the controller's first sensor reading in contact.
    #[allow(non_snake_case)]
    pub fn prepare_contact(&self, base_T_tcp: &Isometry3<f64>) {
        let _ = self.contact_wrench_at(base_T_tcp);
    }

    /// One reading of the wrist sensor now (`actual_TCP_force`: the external wrench, base frame,
    /// at the TCP, payload compensated, with the UR5e's bias and noise).
    pub fn read_wrench(&mut self) -> Wrench {
        let truth = self.contact_wrench_at(&self.tcp_pose_now());
        let e = self.ft.sample();
        std::array::from_fn(|i| truth[i] + e[i])
    }

    /// Runs a guarded straight-line move now (the `Robot::move_until_contact` body; limits as
    /// for [`Self::move_j_sync`]): the arm stops where the true contact force against the motion
    /// ([`Self::contact_wrench_at`]) first exceeds `force_limit`, or at the target. A held part
    /// that met its target is scored where the contact began (the press is elastic: the part
    /// does not slip up the fingers), and the arm's repeatability is not redrawn (it stopped on
    /// force, not on a position).
    #[allow(non_snake_case)]
    pub fn move_until_contact_sync(
        &mut self,
        base_T_tcp: Isometry3<f64>,
        motion: LinearMotion,
        force_limit: f64,
    ) -> Result<ContactOutcome, RobotError> {
        self.check_motion_allowed()?;
        let start = self.model.kinematics.forward_tcp(&self.q);
        let direction = base_T_tcp.translation.vector - start.translation.vector;
        let dir = direction
            .try_normalize(1e-12)
            .unwrap_or_else(Vector3::zeros);
        let pose_at = |s: f64| start.lerp_slerp(&base_T_tcp, s);
        // Path checks and the part's insertion state refer to the start of the move.
        self.begin_motion();
        let against = |cell: &Self, s: f64| {
            let w = cell.contact_wrench_at(&pose_at(s));
            -(w[0] * dir.x + w[1] * dir.y + w[2] * dir.z)
        };
        let first = (1..=GUARD_SAMPLES)
            .map(|k| k as f64 / GUARD_SAMPLES as f64)
            .find(|&s| against(self, s) > force_limit);
        let (stop_s, contact) = match first {
            None => (1.0, false),
            Some(hi) => {
                let (mut lo, mut hi) = (hi - 1.0 / GUARD_SAMPLES as f64, hi);
                for _ in 0..40 {
                    let mid = 0.5 * (lo + hi);
                    if against(self, mid) > force_limit {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                (hi, true)
            }
        };
        // Where the contact began: the last pose with no force against the motion.
        let touch_s = if contact {
            let (mut lo, mut hi) = (0.0, stop_s);
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if against(self, mid) > 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            lo
        } else {
            stop_s
        };
        let stop = pose_at(stop_s);
        let (_, q) = self.linear_path(&stop)?;
        let trace = self.guard_trace(&start, &pose_at, stop_s, touch_s, &motion);
        let reading = {
            let truth = self.contact_wrench_at(&stop);
            let e = self.ft.sample();
            std::array::from_fn(|i| truth[i] + e[i])
        };
        self.clock += move_l_time(&start, &stop, &motion, &self.model.spec.limits);
        self.q = q;
        self.clock = self.clock.max(self.fingers_ready_at);
        if !self.gripper_open {
            let touch = Translation3::from(self.tcp_error) * pose_at(touch_s);
            self.settle_insertion_at(touch, 0.0, true);
        }
        Ok(ContactOutcome {
            stopped_at: self.tcp_pose_now(),
            wrench: reading,
            contact,
            trace,
        })
    }

    /// The contact model's true wrench ([`Self::contact_wrench_at`], without the sensor's
    /// noise, whose stream it leaves alone) sampled along a guarded move up to its stop
    /// (`stop_s` of the way): [`GUARD_TRACE_SAMPLES`] even steps, and
    /// [`GUARD_TRACE_PRESS_SAMPLES`] from first touch (`touch_s`) to the stop, timed by the
    /// commanded speed profile from rest.
    fn guard_trace(
        &self,
        start: &Isometry3<f64>,
        pose_at: &dyn Fn(f64) -> Isometry3<f64>,
        stop_s: f64,
        touch_s: f64,
        motion: &LinearMotion,
    ) -> Vec<robots::robot::ContactSample> {
        let limits = &self.model.spec.limits;
        let v = motion.speed.min(limits.max_tcp_speed).max(1e-9);
        let a = motion
            .acceleration
            .min(limits.max_tcp_acceleration)
            .max(1e-9);
        let ramp = v * v / (2.0 * a);
        let mut at: Vec<f64> = (0..=GUARD_TRACE_SAMPLES)
            .map(|k| stop_s * k as f64 / GUARD_TRACE_SAMPLES as f64)
            .collect();
        // The press from first touch to the stop, resolved on its own.
        at.extend(
            (0..GUARD_TRACE_PRESS_SAMPLES).map(|k| {
                touch_s + (stop_s - touch_s) * k as f64 / GUARD_TRACE_PRESS_SAMPLES as f64
            }),
        );
        at.sort_by(f64::total_cmp);
        at.dedup();
        at.into_iter()
            .map(|s| {
                let pose = pose_at(s);
                let x = (pose.translation.vector - start.translation.vector).norm();
                let t = if x < ramp {
                    (2.0 * x / a).sqrt()
                } else {
                    v / (2.0 * a) + x / v
                };
                robots::robot::ContactSample {
                    t,
                    tcp: pose.translation.vector.into(),
                    wrench: self.contact_wrench_at(&pose),
                }
            })
            .collect()
    }

    /// Mode, safety and program state.
    pub fn status_now(&self) -> RobotStatus {
        RobotStatus {
            mode: RobotMode::Running,
            safety: self.safety,
            program_running: true,
        }
    }

    /// Current joints.
    pub fn joints_now(&self) -> Joints {
        self.q
    }

    /// Current measured TCP pose (the commanded one; repeatability is invisible to encoders).
    pub fn tcp_pose_now(&self) -> Isometry3<f64> {
        self.model.kinematics.forward_tcp(&self.q)
    }

    /// Whether the tool presses on something with the arm commanded at `base_T_tcp`
    /// ([`Self::contact_wrench_at`] is not zero).
    #[allow(non_snake_case)]
    pub fn pressing_at(&self, base_T_tcp: &Isometry3<f64>) -> bool {
        self.contact_wrench_at(base_T_tcp).iter().any(|v| *v != 0.0)
    }

    /// Moves the arm to joints `q` where a stop while pressing on something brought it to rest
    /// (a guarded move stopped on force by the virtual controller), `elapsed` seconds after the
    /// motion began: as [`Self::move_until_contact_sync`] ends, the repeatability is not redrawn
    /// and a held part is scored where the contact began (the press, along the contact force,
    /// is elastic and does not slip the part up the fingers).
    pub(crate) fn set_joints_after_guarded_stop(&mut self, q: Joints, elapsed: f64) {
        self.begin_motion();
        self.q = q;
        self.clock += elapsed;
        self.clock = self.clock.max(self.fingers_ready_at);
        if !self.gripper_open {
            let stop = self.tcp_pose_now();
            let w = self.contact_wrench_at(&stop);
            let f = Vector3::new(w[0], w[1], w[2]);
            let touch = match f.try_normalize(1e-12) {
                Some(dir) => Translation3::from(dir * (f.norm() / HELD_CONTACT_STIFFNESS)) * stop,
                None => stop,
            };
            self.settle_insertion_at(Translation3::from(self.tcp_error) * touch, 0.0, true);
        }
    }

    /// Moves the arm to joints `q` at once without timing or checks (used by the virtual
    /// controller's arm model, which times the motion itself).
    /// The controller's motion that is ending, as its arm model stepped it: (seconds since it
    /// started, joints) every control period, kept as the last motion
    /// ([`Self::last_motion_trace`]) from the clock now, where it started. Call before
    /// [`Self::set_joints_after_motion`] moves the clock on.
    pub(crate) fn record_controller_motion(&mut self, steps: Vec<(f64, Joints)>) {
        let start = self.clock;
        self.last_motion = Some(LastMotion::Sampled(
            steps.into_iter().map(|(t, q)| (start + t, q)).collect(),
        ));
    }

    pub(crate) fn set_joints_after_motion(&mut self, q: Joints, elapsed: f64) {
        self.begin_motion();
        self.q = q;
        self.clock += elapsed;
        self.end_motion();
    }

    /// Sets the gripper from the controller's tool output.
    pub(crate) fn set_gripper(&mut self, closed: bool) {
        if closed {
            self.close_gripper_sync()
        } else {
            self.open_gripper_sync()
        }
    }
}

impl Robot for SimCell {
    fn limits(&self) -> &Limits {
        &self.model.spec.limits
    }

    fn joints(&mut self) -> RobotFuture<'_, Joints> {
        let q = self.q;
        Box::pin(async move { Ok(q) })
    }

    fn tcp_pose(&mut self) -> RobotFuture<'_, Isometry3<f64>> {
        let pose = self.tcp_pose_now();
        Box::pin(async move { Ok(pose) })
    }

    fn move_j(&mut self, target: Joints, motion: JointMotion) -> RobotFuture<'_, ()> {
        Box::pin(async move { self.move_j_sync(target, motion) })
    }

    fn move_l(&mut self, base_T_tcp: Isometry3<f64>, motion: LinearMotion) -> RobotFuture<'_, ()> {
        Box::pin(async move { self.move_l_sync(base_T_tcp, motion) })
    }

    fn move_path(&mut self, path: Vec<Waypoint>) -> RobotFuture<'_, ()> {
        Box::pin(async move { self.move_path_sync(&path) })
    }

    fn open_gripper(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            self.open_gripper_sync();
            Ok(())
        })
    }

    fn open_gripper_to(&mut self, width: f64) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            if !(width.is_finite() && width >= 0.0) {
                return Err(RobotError::Rejected {
                    detail: format!("finger opening {width} m is not a width"),
                });
            }
            self.send_fingers_to(width);
            Ok(())
        })
    }

    fn close_gripper(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            self.close_gripper_sync();
            Ok(())
        })
    }

    fn stop(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(async move { Ok(()) })
    }

    fn status(&mut self) -> RobotFuture<'_, RobotStatus> {
        let s = self.status_now();
        Box::pin(async move { Ok(s) })
    }

    #[allow(non_snake_case)]
    fn move_until_contact(
        &mut self,
        base_T_tcp: Isometry3<f64>,
        motion: LinearMotion,
        force_limit: f64,
    ) -> RobotFuture<'_, ContactOutcome> {
        Box::pin(async move { self.move_until_contact_sync(base_T_tcp, motion, force_limit) })
    }

    fn wrench(&mut self) -> RobotFuture<'_, Wrench> {
        let w = self.read_wrench();
        Box::pin(async move { Ok(w) })
    }
}
