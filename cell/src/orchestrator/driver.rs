//! The episode driver: the state machine that runs every assembly step on a robot and a cell.

use std::collections::BTreeSet;
use std::time::Duration;

use nalgebra::Isometry3;
use perception::part::Catalog;
use robots::kinematics::Joints;
use robots::robot::{Robot, RobotError};
use sim::cell::geometry::PartGeometry;

use super::cell_io::CellIo;
use super::events::EventLog;
use super::geometry::CellKnowledge;
use super::perception::{DetectedPart, Frame, PartPerception};
use super::planning::{Motion, Plan, Planner, PlanningConfig, Speeds, grasped_offset};
use super::selection::{Rejection, Selection, SelectionConfig, select};
use super::state::{State, Timeouts};
use crate::episode::{EpisodeRecord, PoseError, RECORD_VERSION, StepOutcome, StepRecord};

/// Error-budget name of a step given up because the feeder held none of its part.
pub const FEEDER_EXHAUSTED: &str = "feeder.parts";
/// Error-budget name of a step given up because the camera detected no part at all (pointed
/// away from the feeder, or nothing in view).
pub const CAMERA_SAW_NOTHING: &str = "camera.view";
/// Error-budget name of a step given up after `max_shakes` shakes left no usable instance.
pub const FEEDER_SHAKE_BOUND: &str = "feeder.max_shakes";

/// Policies and tuning of an episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeSettings {
    /// Bounds of every state.
    pub timeouts: Timeouts,
    /// Instance selection.
    pub selection: SelectionConfig,
    /// Motion planning.
    pub planning: PlanningConfig,
    /// Pick attempts per step (a failed grasp re-perceives and retries).
    pub max_grasp_attempts: u32,
    /// Home joints; the robot's joints at the start when `None`.
    pub home: Option<Joints>,
}

impl Default for EpisodeSettings {
    fn default() -> Self {
        Self {
            timeouts: Timeouts::default(),
            selection: SelectionConfig::default(),
            planning: PlanningConfig::default(),
            max_grasp_attempts: 3,
            home: None,
        }
    }
}

/// Why the state machine stopped the episode early.
enum Stop {
    /// A robot command failed.
    Robot(State, RobotError),
    /// A state overran its bound.
    Timeout(State, Duration),
}

impl Stop {
    fn text(&self) -> String {
        match self {
            Stop::Robot(s, e) => format!("{s:?}: {e}"),
            Stop::Timeout(s, d) => format!("{s:?} timed out after {d:?}"),
        }
    }
}

/// Everything the state machine carries.
pub(super) struct Driver<'a> {
    pub scenario_name: String,
    pub seed: u64,
    pub episode: u32,
    pub catalog: &'a Catalog,
    pub knowledge: &'a CellKnowledge,
    pub robot: &'a mut dyn Robot,
    pub io: &'a mut dyn CellIo,
    pub perception: &'a mut dyn PartPerception,
    pub settings: &'a EpisodeSettings,
    pub max_shakes: u32,
    pub max_insertion_attempts: u32,
    pub log: EventLog,
    // Episode state.
    home: Joints,
    /// Clock when homing ended: the assembly cycle starts there.
    cycle_start: f64,
    step: usize,
    records: Vec<StepRecord>,
    placed: Vec<(String, Isometry3<f64>)>,
    abort: Option<String>,
    // Step state.
    step_start: f64,
    attempts: u32,
    shakes: u32,
    /// Shakes started for the next step while this one inserts.
    shakes_ahead: u32,
    /// Insertion attempts this step (first try and retries).
    insertions: u32,
    /// Search offset of the next insertion in the insertion frame.
    correction: Isometry3<f64>,
    /// Measured slip of the held part up the fingers so far, metres.
    slip: f64,
    /// Release and retreat of the insertion in progress, run once it is judged.
    pending: Vec<(&'static str, Motion)>,
    /// Why the last insertion attempt was retried.
    retry_reason: Option<String>,
    frame: Option<Frame>,
    detections: Vec<DetectedPart>,
    excluded: BTreeSet<usize>,
    selection: Option<Selection>,
    plan: Option<Plan>,
    perception_error: Option<[f64; 3]>,
    last_reason: String,
}

impl<'a> Driver<'a> {
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        scenario_name: String,
        seed: u64,
        episode: u32,
        catalog: &'a Catalog,
        knowledge: &'a CellKnowledge,
        robot: &'a mut dyn Robot,
        io: &'a mut dyn CellIo,
        perception: &'a mut dyn PartPerception,
        settings: &'a EpisodeSettings,
        max_shakes: u32,
        max_insertion_attempts: u32,
    ) -> Self {
        Self {
            scenario_name,
            seed,
            episode,
            catalog,
            knowledge,
            robot,
            io,
            perception,
            settings,
            max_shakes,
            max_insertion_attempts: max_insertion_attempts.max(1),
            log: EventLog::new(episode),
            home: [0.0; 6],
            cycle_start: 0.0,
            step: 0,
            records: Vec::new(),
            placed: Vec::new(),
            abort: None,
            step_start: 0.0,
            attempts: 0,
            shakes: 0,
            shakes_ahead: 0,
            insertions: 0,
            correction: Isometry3::identity(),
            slip: 0.0,
            pending: Vec::new(),
            retry_reason: None,
            frame: None,
            detections: Vec::new(),
            excluded: BTreeSet::new(),
            selection: None,
            plan: None,
            perception_error: None,
            last_reason: String::new(),
        }
    }

    fn step_part(&self) -> String {
        self.knowledge
            .steps
            .get(self.step)
            .map(|s| s.part.clone())
            .unwrap_or_default()
    }

    fn begin_step(&mut self) {
        self.step_start = self.io.clock();
        self.attempts = 0;
        // A shake started for this step while the last one inserted counts against its bound.
        self.shakes = std::mem::take(&mut self.shakes_ahead);
        self.insertions = 0;
        self.correction = Isometry3::identity();
        self.slip = 0.0;
        self.pending.clear();
        self.retry_reason = None;
        self.excluded.clear();
        self.selection = None;
        self.plan = None;
        self.perception_error = None;
    }

    /// Closes the current step with an outcome; returns the next state.
    fn finish_step(
        &mut self,
        outcome: StepOutcome,
        cause: Option<String>,
        sources: Vec<String>,
        pose_error: Option<PoseError>,
    ) -> State {
        self.records.push(StepRecord {
            part: self.step_part(),
            outcome,
            attempts: self.attempts,
            insertion_attempts: self.insertions,
            shakes: self.shakes,
            cause,
            sources,
            pose_error,
            perception_error: self.perception_error,
            sim_time_s: self.io.clock() - self.step_start,
        });
        if outcome == StepOutcome::Seated && self.step + 1 < self.knowledge.steps.len() {
            self.step += 1;
            self.begin_step();
            State::Capture
        } else {
            State::Done
        }
    }

    fn placed_shapes(&self) -> Vec<(&'a PartGeometry, Isometry3<f64>)> {
        let k: &'a CellKnowledge = self.knowledge;
        let mut out: Vec<(&'a PartGeometry, Isometry3<f64>)> = Vec::new();
        if let Some(f) = k.part(&k.geometry.fixture_part) {
            out.push((f, k.geometry.base_T_fixture));
        }
        for (name, pose) in &self.placed {
            if let Some(g) = k.part(name) {
                out.push((g, *pose));
            }
        }
        out
    }

    /// With this step's part out of the feeder: when the frame that found it shows no usable
    /// instance for the next step, start a shake now, so the feeder settles while the arm
    /// inserts (the next step's capture waits for the parts to rest). Counts against the next
    /// step's shake bound.
    fn shake_ahead(&mut self, picked: &Selection, here: &Joints) {
        let next = self.step + 1;
        if next >= self.knowledge.steps.len() || self.shakes_ahead >= self.max_shakes {
            return;
        }
        let rest: Vec<DetectedPart> = self
            .detections
            .iter()
            .filter(|d| d.index != picked.detection.index)
            .cloned()
            .collect();
        let ahead = select(
            self.knowledge,
            self.catalog,
            next,
            &rest,
            here,
            &self.settings.selection,
        );
        if ahead.chosen.is_none() && self.io.shake_feeder().is_ok() {
            self.shakes_ahead += 1;
        }
    }

    /// A jammed or missed insertion with the part still in the fingers: lift it clear along the
    /// insertion axis (the retreat pose, fingers closed), then correct the next attempt: the
    /// measured stop height is how far the part slipped up the fingers, so the held part's
    /// estimate moves up by it (the next insertion goes that much deeper); and a search offset (lateral for a miss, yaw for a jam, since a
    /// real cell measures neither error directly) is tried, a different one each attempt.
    async fn retry_insertion(
        &mut self,
        state: State,
        check: super::cell_io::InsertionCheck,
    ) -> Result<State, Stop> {
        let pending = std::mem::take(&mut self.pending);
        let lift: Vec<(&'static str, Motion)> = pending
            .into_iter()
            .filter(|(_, m)| *m != Motion::Open)
            .map(|(_, m)| ("lift clear", m))
            .collect();
        self.execute(state, &lift).await?;
        // The part pushed back comes out a little higher in the fingers than it went in.
        let slip_cap = self.settings.planning.clearance_height / 2.0;
        self.slip = (self.slip + check.stop_height.unwrap_or(0.0)).clamp(0.0, slip_cap);
        let k = self.insertions as usize; // retries so far, ≥ 1
        let search = self.settings.planning.search;
        let step = &self.knowledge.steps[self.step];
        let lateral = step
            .lead_in
            .max(step.clearance / 2.0)
            .max(search.min_lateral);
        let (offset, yaw) = match check.outcome {
            StepOutcome::Missed => {
                const PATTERN: [(f64, f64); 4] = [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)];
                let (x, y) = PATTERN[(k - 1) % PATTERN.len()];
                let ring = ((k - 1) / PATTERN.len() + 1) as f64;
                (nalgebra::Vector2::new(x, y) * lateral * ring, 0.0)
            }
            _ => {
                let ring = (k.div_ceil(2)) as f64;
                let sign = if k % 2 == 1 { 1.0 } else { -1.0 };
                (nalgebra::Vector2::zeros(), sign * ring * search.yaw_step)
            }
        };
        self.correction = Isometry3::from_parts(
            nalgebra::Translation3::new(offset.x, offset.y, 0.0),
            nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), yaw),
        );
        let what = match check.outcome {
            StepOutcome::Missed => "missed",
            _ => "jammed",
        };
        self.retry_reason = Some(format!(
            "insertion {} {what} ({}); retry {} of {}",
            self.insertions,
            check.cause.as_deref().unwrap_or("not seated"),
            self.insertions,
            self.max_insertion_attempts - 1
        ));
        self.last_reason = self.retry_reason.clone().unwrap_or_default();
        Ok(State::PlanInsert)
    }

    fn planner(&self) -> Planner<'a> {
        Planner {
            knowledge: self.knowledge,
            config: self.settings.planning,
            speeds: Speeds::within(self.robot.limits(), self.settings.planning.slow_speed),
        }
    }

    async fn execute(
        &mut self,
        state: State,
        motions: &[(&'static str, Motion)],
    ) -> Result<(), Stop> {
        for (name, m) in motions {
            let r = match m {
                Motion::MoveJ(q, s) => self.robot.move_j(*q, *s).await,
                Motion::MoveL(p, s) => self.robot.move_l(*p, *s).await,
                Motion::Open => self.robot.open_gripper().await,
                Motion::Close => self.robot.close_gripper().await,
            };
            tracing::debug!(
                episode = self.episode,
                waypoint = name,
                clock = self.io.clock(),
                "motion done"
            );
            if let Err(e) = r {
                tracing::warn!(
                    episode = self.episode,
                    waypoint = name,
                    "motion failed: {e}"
                );
                return Err(Stop::Robot(state, e));
            }
        }
        Ok(())
    }

    /// Runs one state; returns the next.
    async fn run_state(&mut self, state: State) -> Result<State, Stop> {
        match state {
            State::Home => {
                let r = async {
                    self.robot.open_gripper().await?;
                    let q = self.robot.joints().await?;
                    self.home = self
                        .settings
                        .home
                        .unwrap_or_else(|| self.knowledge.safe_home(&q));
                    if robots::kinematics::joint_distance(&self.home, &q) > 1e-9 {
                        let speeds = Speeds::within(self.robot.limits(), 0.01);
                        self.robot.move_j(self.home, speeds.joint).await?;
                    }
                    Ok::<_, RobotError>(())
                }
                .await;
                r.map_err(|e| Stop::Robot(state, e))?;
                self.cycle_start = self.io.clock();
                self.begin_step();
                Ok(State::Capture)
            }
            State::Capture => match self.io.capture() {
                Ok(f) => {
                    self.frame = Some(f);
                    self.excluded.clear();
                    Ok(State::Perceive)
                }
                Err(e) => {
                    self.last_reason = e.to_string();
                    Ok(self.finish_step(StepOutcome::Aborted, Some(e.to_string()), vec![], None))
                }
            },
            State::Perceive => {
                let frame = self.frame.take();
                let r = match &frame {
                    Some(f) => self.perception.perceive(f),
                    None => Ok(Vec::new()),
                };
                match r {
                    Ok(d) => {
                        self.detections = d;
                        Ok(State::Select)
                    }
                    Err(e) => Ok(self.finish_step(
                        StepOutcome::Aborted,
                        Some(format!("perception failed: {e}")),
                        vec!["perception".into()],
                        None,
                    )),
                }
            }
            State::Select => {
                let candidates: Vec<DetectedPart> = self
                    .detections
                    .iter()
                    .filter(|d| !self.excluded.contains(&d.index))
                    .cloned()
                    .collect();
                // Grasp yaw and travel are judged from where the arm is now.
                let here = self
                    .robot
                    .joints()
                    .await
                    .map_err(|e| Stop::Robot(state, e))?;
                let mut result = select(
                    self.knowledge,
                    self.catalog,
                    self.step,
                    &candidates,
                    &here,
                    &self.settings.selection,
                );
                // Excluded detections still count as neighbours for finger clearance.
                if candidates.len() != self.detections.len()
                    && let Some(c) = &result.chosen
                {
                    let k = self.knowledge;
                    let blocked = self.detections.iter().any(|n| {
                        n.index != c.detection.index
                            && self.excluded.contains(&n.index)
                            && k.part(&n.part).is_some_and(|g| {
                                k.finger_distance(&c.base_T_grasp, g.hull.as_ref(), &n.base_T_part)
                                    < self.settings.selection.finger_margin
                            })
                    });
                    if blocked {
                        self.excluded.insert(c.detection.index);
                        result.chosen = None;
                        return Ok(State::Select);
                    }
                }
                match result.chosen {
                    Some(sel) => {
                        self.perception_error = sel
                            .detection
                            .truth_instance
                            .and_then(|i| self.io.true_table_T_part(i))
                            .map(|truth| table_error(&truth, &sel.detection.table_T_part));
                        self.selection = Some(sel);
                        Ok(State::PlanPick)
                    }
                    None => {
                        self.last_reason = result.summary();
                        if self.shakes < self.max_shakes {
                            Ok(State::Shake)
                        } else {
                            let part = self.step_part();
                            let cause = format!(
                                "no usable {part} after {} shakes ({})",
                                self.shakes, self.last_reason
                            );
                            // Named causes for the error budget: an exhausted feeder, or parts
                            // there that the shake bound gave no chance to come to rest usably.
                            let any = result
                                .rejected
                                .iter()
                                .any(|(_, r)| !matches!(r, Rejection::OtherPart));
                            let source = if any {
                                FEEDER_SHAKE_BOUND
                            } else if result.rejected.is_empty() {
                                CAMERA_SAW_NOTHING
                            } else {
                                FEEDER_EXHAUSTED
                            };
                            Ok(self.finish_step(
                                StepOutcome::Aborted,
                                Some(cause),
                                vec![source.into()],
                                None,
                            ))
                        }
                    }
                }
            }
            State::Shake => match self.io.shake_feeder() {
                Ok(()) => {
                    self.shakes += 1;
                    Ok(State::Capture)
                }
                Err(e) => {
                    Ok(self.finish_step(StepOutcome::Aborted, Some(e.to_string()), vec![], None))
                }
            },
            State::PlanPick => {
                let Some(sel) = self.selection.clone() else {
                    return Ok(State::Select);
                };
                let start = self
                    .robot
                    .joints()
                    .await
                    .map_err(|e| Stop::Robot(state, e))?;
                let placed = self.placed_shapes();
                let k: &'a CellKnowledge = self.knowledge;
                let feeder: Vec<(&'a PartGeometry, Isometry3<f64>)> = self
                    .detections
                    .iter()
                    .filter_map(|d| Some((k.part(&d.part)?, d.base_T_part)))
                    .collect();
                match self.planner().pick(&sel, &start, &placed, &feeder) {
                    Ok(plan) => {
                        self.plan = Some(plan);
                        Ok(State::Pick)
                    }
                    Err(e) => {
                        self.last_reason = format!("pick plan: {e}");
                        self.excluded.insert(sel.detection.index);
                        Ok(State::Select)
                    }
                }
            }
            State::Pick => {
                let Some(plan) = self.plan.take() else {
                    return Ok(State::PlanPick);
                };
                self.attempts += 1;
                // A new part in the fingers: nothing learnt from an earlier one applies.
                self.correction = Isometry3::identity();
                self.slip = 0.0;
                self.execute(state, &plan.motions).await?;
                Ok(State::VerifyGrasp)
            }
            State::VerifyGrasp => {
                if self.io.part_in_gripper().unwrap_or(true) {
                    Ok(State::PlanInsert)
                } else if self.attempts < self.settings.max_grasp_attempts {
                    self.last_reason = "grasp failed: nothing between the fingers".into();
                    Ok(State::Retract)
                } else {
                    let cause = format!("grasp failed {} times", self.attempts);
                    Ok(self.finish_step(StepOutcome::Aborted, Some(cause), vec![], None))
                }
            }
            State::Retract => {
                let r = async {
                    self.robot.open_gripper().await?;
                    let tcp = self.robot.tcp_pose().await?;
                    let up = nalgebra::Translation3::new(
                        0.0,
                        0.0,
                        self.settings.planning.clearance_height,
                    ) * tcp;
                    let speeds = Speeds::within(self.robot.limits(), 0.01);
                    self.robot.move_l(up, speeds.fast).await
                }
                .await;
                r.map_err(|e| Stop::Robot(state, e))?;
                Ok(State::Capture)
            }
            State::PlanInsert => {
                let Some(sel) = self.selection.clone() else {
                    return Ok(State::Done);
                };
                let Some(g) = self.knowledge.part(&sel.detection.part) else {
                    return Ok(State::Done);
                };
                // The part slipped up the fingers (TCP −z) by what earlier attempts measured.
                let tcp_T_part = nalgebra::Translation3::new(0.0, 0.0, -self.slip)
                    * grasped_offset(&sel.tcp_T_part);
                let correction = self.correction;
                let start = self
                    .robot
                    .joints()
                    .await
                    .map_err(|e| Stop::Robot(state, e))?;
                let placed = self.placed_shapes();
                match self.planner().insert(
                    self.step,
                    (g, &tcp_T_part),
                    &correction,
                    &start,
                    &placed,
                ) {
                    Ok(plan) => {
                        self.plan = Some(plan);
                        if self.insertions == 0 {
                            self.shake_ahead(&sel, &start);
                        }
                        Ok(State::Insert)
                    }
                    Err(e) => {
                        let cause = format!("insertion plan: {e}");
                        // Put the part down where it came from rather than carry it around
                        // (let go 1 mm above the grasp: the grasp may have shifted it down).
                        let back = async {
                            self.robot
                                .move_l(
                                    nalgebra::Translation3::new(0.0, 0.0, 0.001) * sel.base_T_grasp,
                                    Speeds::within(self.robot.limits(), 0.01).slow,
                                )
                                .await?;
                            self.robot.open_gripper().await
                        }
                        .await;
                        back.map_err(|e| Stop::Robot(state, e))?;
                        Ok(self.finish_step(StepOutcome::Aborted, Some(cause), vec![], None))
                    }
                }
            }
            State::Insert => {
                let Some(plan) = self.plan.take() else {
                    return Ok(State::PlanInsert);
                };
                let split = plan
                    .motions
                    .iter()
                    .position(|(_, m)| *m == Motion::Open)
                    .unwrap_or(plan.motions.len());
                self.insertions += 1;
                self.pending = plan.motions[split..].to_vec();
                self.execute(state, &plan.motions[..split]).await?;
                Ok(State::Verify)
            }
            State::Verify => {
                // Judge the insertion before the fingers open, when the cell can.
                if let Some(c) = self.io.seating_check()
                    && c.outcome != StepOutcome::Seated
                    && self.insertions < self.max_insertion_attempts
                {
                    return self.retry_insertion(state, c).await;
                }
                let pending = std::mem::take(&mut self.pending);
                self.execute(state, &pending).await?;
                let check = self.io.insertion_check();
                let part = self.step_part();
                match check {
                    Some(c) => {
                        if c.outcome == StepOutcome::Seated {
                            self.placed
                                .push((part, self.knowledge.base_T_targets[self.step]));
                        }
                        let cause = c.cause.map(|t| match self.insertions {
                            0 | 1 => t,
                            n => format!("{t} (after {n} insertion attempts)"),
                        });
                        Ok(self.finish_step(c.outcome, cause, c.sources, c.pose_error))
                    }
                    None => Ok(self.finish_step(
                        StepOutcome::Missed,
                        Some("the cell reported no insertion".into()),
                        vec![],
                        None,
                    )),
                }
            }
            State::Done | State::SafeStop => Ok(state),
        }
    }

    /// Runs the state machine to its end and returns the episode record.
    pub(super) async fn run(mut self) -> (EpisodeRecord, EventLog) {
        let mut state = State::Home;
        self.log.push(None, state, state, self.io.clock(), "start");
        while !state.is_terminal() {
            let bound = self.settings.timeouts.of(state);
            let next = match tokio::time::timeout(bound, self.run_state(state)).await {
                Ok(r) => r,
                Err(_) => Err(Stop::Timeout(state, bound)),
            };
            let (next, detail) = match next {
                Ok(n) => {
                    let d = match n {
                        State::Shake | State::Retract => self.last_reason.clone(),
                        State::PlanInsert if state == State::Verify => self.last_reason.clone(),
                        _ => String::new(),
                    };
                    (n, d)
                }
                Err(stop) => {
                    let text = stop.text();
                    tracing::warn!(episode = self.episode, "safe stop: {text}");
                    // Stop the arm, bounded; errors here change nothing (it may be gone).
                    let _ = tokio::time::timeout(Duration::from_secs(2), self.robot.stop()).await;
                    if self.records.len() <= self.step && self.step < self.knowledge.steps.len() {
                        self.records.push(StepRecord {
                            part: self.step_part(),
                            outcome: StepOutcome::Aborted,
                            attempts: self.attempts,
                            insertion_attempts: self.insertions,
                            shakes: self.shakes,
                            cause: Some(text.clone()),
                            sources: vec![],
                            pose_error: None,
                            perception_error: self.perception_error,
                            sim_time_s: self.io.clock() - self.step_start,
                        });
                    }
                    self.abort = Some(text.clone());
                    (State::SafeStop, text)
                }
            };
            let step = (self.step < self.knowledge.steps.len()).then_some(self.step);
            self.log.push(step, state, next, self.io.clock(), detail);
            state = next;
        }
        let success = self.records.len() == self.knowledge.steps.len()
            && self
                .records
                .iter()
                .all(|r| r.outcome == StepOutcome::Seated);
        let record = EpisodeRecord {
            version: RECORD_VERSION,
            scenario: self.scenario_name.clone(),
            seed: self.seed,
            episode: self.episode,
            success,
            steps: std::mem::take(&mut self.records),
            cycle_time_s: self.io.clock() - self.cycle_start,
            wall_time_s: self.log.wall_time_s(),
            abort: self.abort.take(),
        };
        (record, self.log)
    }
}

/// Perception error in the table plane: [x mm, y mm, yaw degrees] of the estimate.
#[allow(non_snake_case)]
fn table_error(truth: &Isometry3<f64>, estimate: &Isometry3<f64>) -> [f64; 3] {
    let d = estimate.translation.vector - truth.translation.vector;
    let r = estimate.rotation * truth.rotation.inverse();
    let yaw = r.scaled_axis().z;
    [d.x * 1e3, d.y * 1e3, yaw.to_degrees()]
}
