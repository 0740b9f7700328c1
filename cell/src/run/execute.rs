//! Executing a run on a robot: the results store, one episode after another (in parallel in
//! simulation), the event files, then the summary and report; and the checked set-up for a real
//! controller. Only the simulated drivers build the simulation harness; a production run builds
//! the engine's [`Setup`] alone.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::{
    LoadedScenario, ResultsStore, RobotTarget, RunError, RunOptions, RunOutcome, Shard, StoreError,
    Summary, results_dir, run_episodes,
};
use crate::calibrate::preflight::CameraCheck;
use crate::camera::CameraSpec;
use crate::episode::EpisodeRecord;
use crate::harness::{
    HarnessError, OverRtdeError, SimSetup, run_sim_episode_blocking, sim_episode_over_rtde,
};
use crate::learned;
use crate::orchestrator::{
    EpisodeOutput, KnowledgeError, ProductionCellIo, ProductionError, ProductionOptions, Setup,
    SplitCell, force_sensor_preflight, preflight, run_episode,
};
use crate::report::{ReportError, ReportFiles, write_report};
use crate::scenario::{PerceptionMode, Scenario};
use perception::learned::LearnedPerception;
use perception::{PartPerception, PerceptionError};

/// What can stop one episode from producing a record.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError {
    /// The simulated cell or perception could not be set up.
    #[error(transparent)]
    Setup(#[from] HarnessError),
    /// The episode over loopback RTDE could not run.
    #[error(transparent)]
    OverRtde(#[from] OverRtdeError),
    /// The real controller could not be reached or did not start our program.
    #[error("{robot}: {source}")]
    Robot {
        /// The controller.
        robot: String,
        /// The failure.
        source: robots::robot::RobotError,
    },
    /// The connected controller failed a pre-flight check; nothing moved.
    #[error("{robot}: refused before anything moves: {source}")]
    Preflight {
        /// The controller.
        robot: String,
        /// The check that failed.
        source: ProductionError,
    },
    /// The episode's event log could not be written.
    #[error("writing {}: {source}", path.display())]
    Events {
        /// The event file.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
}

/// Why a run stopped before its summary and report were written.
#[derive(Debug, thiserror::Error)]
pub enum ExecuteError {
    /// The results file refused the run.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The simulated cell could not be built.
    #[error(transparent)]
    Harness(#[from] HarnessError),
    /// The planning model could not be built.
    #[error(transparent)]
    Knowledge(#[from] KnowledgeError),
    /// The events folder could not be created.
    #[error("creating {}: {source}", path.display())]
    Events {
        /// The folder.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// The async runtime for a controller could not start.
    #[error("starting the async runtime: {0}")]
    Runtime(std::io::Error),
    /// An episode could not run or be stored.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The report could not be written.
    #[error(transparent)]
    Report(#[from] ReportError),
}

/// Why a real-controller run is refused before anything connects.
#[derive(Debug, thiserror::Error)]
pub enum ProductionRefusal {
    /// The target is not a real controller.
    #[error("{0} is not a real controller")]
    NotAController(RobotTarget),
    /// A check failed.
    #[error("refusing to run on {robot}: {why}")]
    Refused {
        /// The controller.
        robot: RobotTarget,
        /// What is missing or wrong.
        why: String,
    },
}

/// A finished (or resumed-to-completion) run of one shard.
pub struct Executed {
    /// The shard's results folder.
    pub dir: PathBuf,
    /// What this invocation ran.
    pub outcome: RunOutcome,
    /// Their summary.
    pub summary: Summary,
    /// The report written.
    pub report: ReportFiles,
}

/// How a run's episodes are executed.
pub enum Driver {
    /// The in-process simulated cell, episodes in parallel.
    Sim,
    /// The simulated cell behind a virtual UR controller over loopback RTDE, one at a time.
    VirtualUr,
    /// A real controller that passed the pre-flight, one episode at a time.
    Production(Box<Production>),
}

impl Driver {
    /// The robot as `--robot` names it, recorded in the results header so that results of
    /// different robots never mix in one file.
    pub fn robot(&self) -> String {
        match self {
            Driver::Sim => RobotTarget::Sim.to_string(),
            Driver::VirtualUr => RobotTarget::VirtualUr.to_string(),
            Driver::Production(p) => p.robot.to_string(),
        }
    }
}

/// A checked production set-up (see [`production`]).
pub struct Production {
    robot: RobotTarget,
    host: String,
    port: u16,
    /// The camera source and the perception, lent to one episode at a time.
    side: std::sync::Mutex<Option<(ProductionCellIo, Box<dyn PartPerception>)>>,
}

/// Runs `episodes` of a loaded scenario's `shard` in simulation under `root`, resuming what is
/// there, then writes the summary and report beside the results.
pub fn execute(
    loaded: &LoadedScenario,
    root: &Path,
    shard: Shard,
    episodes: u32,
    jobs: usize,
    progress: bool,
) -> Result<Executed, ExecuteError> {
    execute_on(loaded, root, shard, episodes, jobs, progress, &Driver::Sim)
}

/// What a driver runs episodes with: the simulation harness, or (for a real controller) the
/// engine's set-up alone; controllers get an async runtime.
enum Runner<'d> {
    Sim(SimSetup),
    VirtualUr(SimSetup, tokio::runtime::Runtime),
    Production(&'d Production, Setup, tokio::runtime::Runtime),
}

/// The scenario as a controller runs it: without a width output (`cell.gripper.width_output`)
/// our program drives the gripper by one digital output, which opens the full stroke, so
/// selection and planning must leave the fingers room for the full stroke
/// (`cell.gripper.opening_margin` is set aside, with a warning). `[motion] overlap` is set aside
/// too, with a warning: a controller run perceives while the arm stands still (the engine awaits
/// each command), so there is nothing to overlap yet.
fn as_a_controller_runs_it(scenario: &Scenario) -> Scenario {
    let mut s = scenario.clone();
    let gripper = &mut s.spec.cell.gripper;
    if gripper.width_output.is_none() && gripper.opening_margin.take().is_some() {
        tracing::warn!(
            "cell.gripper.opening_margin set aside: the controller's gripper output opens the \
             full stroke (set cell.gripper.width_output for a gripper with a position input)"
        );
    }
    if std::mem::take(&mut s.spec.motion.overlap) {
        tracing::warn!(
            "[motion] overlap set aside: a controller run does not yet capture and perceive \
             while the arm moves"
        );
    }
    s
}

impl<'d> Runner<'d> {
    fn new(driver: &'d Driver, scenario: &Scenario) -> Result<Self, ExecuteError> {
        let runtime = || {
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .map_err(ExecuteError::Runtime)
        };
        Ok(match driver {
            Driver::Sim => Runner::Sim(SimSetup::new(scenario.clone())?),
            Driver::VirtualUr => Runner::VirtualUr(
                SimSetup::new(as_a_controller_runs_it(scenario))?,
                runtime()?,
            ),
            // A real controller gets no simulated cell: only the engine's planning model.
            Driver::Production(p) => Runner::Production(
                p,
                Setup::new(as_a_controller_runs_it(scenario))?,
                runtime()?,
            ),
        })
    }

    fn episode(&self, e: u32) -> Result<EpisodeOutput, EpisodeError> {
        Ok(match self {
            Runner::Sim(sim) => run_sim_episode_blocking(sim, e)?,
            Runner::VirtualUr(sim, rt) => rt.block_on(sim_episode_over_rtde(sim, e))?,
            Runner::Production(p, setup, rt) => rt.block_on(p.episode(setup, e))?,
        })
    }
}

/// [`execute`] on any [`Driver`]: the same results store, event files, summary and report.
pub fn execute_on(
    loaded: &LoadedScenario,
    root: &Path,
    shard: Shard,
    episodes: u32,
    jobs: usize,
    progress: bool,
    driver: &Driver,
) -> Result<Executed, ExecuteError> {
    let name = &loaded.scenario.spec.name;
    let dir = results_dir(root, name, shard);
    let header = loaded.header(shard).with_robot(driver.robot());
    let (mut store, opened) = ResultsStore::open(&dir, header)?;
    if opened.truncated_bytes > 0 {
        eprintln!(
            "{}: cut off a torn last line ({} bytes) from an interrupted run",
            store.path().display(),
            opened.truncated_bytes
        );
    }
    if !opened.created {
        eprintln!(
            "{}: resuming, {} episodes already stored",
            store.path().display(),
            opened.present
        );
    }
    let runner = Runner::new(driver, &loaded.scenario)?;
    let events = dir.join("events");
    std::fs::create_dir_all(&events).map_err(|source| ExecuteError::Events {
        path: events.clone(),
        source,
    })?;
    let options = RunOptions {
        episodes,
        // Episodes on a controller run one at a time: it drives one arm, in real time.
        jobs: match runner {
            Runner::Sim(_) => jobs,
            Runner::VirtualUr(..) | Runner::Production(..) => 1,
        },
        progress,
    };
    let outcome = run_episodes(&loaded.scenario, &mut store, &options, |_, e| {
        let out = runner.episode(e)?;
        let path = events.join(format!("episode-{e:06}.jsonl"));
        let mut bytes = Vec::new();
        out.events
            .write_jsonl(&mut bytes)
            .and_then(|()| sim::fsutil::write_atomic(&path, &bytes))
            .map_err(|source| EpisodeError::Events { path, source })?;
        Ok::<_, EpisodeError>(out.record)
    })?;
    let records: BTreeMap<u32, EpisodeRecord> = store
        .records()
        .range(..episodes)
        .map(|(k, v)| (*k, v.clone()))
        .collect();
    let summary = Summary::new(store.header(), records.values());
    let report = write_report(&dir, &summary, &records)?;
    Ok(Executed {
        dir,
        outcome,
        summary,
        report,
    })
}

impl Production {
    /// Runs one episode on the real controller: connects, runs, disconnects.
    async fn episode(&self, setup: &Setup, e: u32) -> Result<EpisodeOutput, EpisodeError> {
        use robots::ur_robot::{UrRobot, UrRobotConfig};
        let robot_err = |source| EpisodeError::Robot {
            robot: self.robot.to_string(),
            source,
        };
        let cell = &setup.scenario.spec.cell;
        let mut config = UrRobotConfig::new(self.host.clone(), setup.knowledge.kinematics.clone());
        config.rtde_port = self.port;
        config.limits = cell.limits.clone();
        cell.gripper.configure_ur(&mut config);
        let mut robot = UrRobot::connect(config).await.map_err(robot_err)?;
        force_sensor_preflight(&setup.scenario, robot.inner().force_sensor()).map_err(
            |source| EpisodeError::Preflight {
                robot: self.robot.to_string(),
                source,
            },
        )?;
        let (mut io, mut perception) = self
            .side
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .ok_or_else(|| {
            robot_err(robots::robot::RobotError::Rejected {
                detail: "the camera source serves one episode at a time".into(),
            })
        })?;
        let mut workcell = SplitCell {
            robot: &mut robot,
            io: &mut io,
        };
        let out = run_episode(setup.context(e), &mut workcell, perception.as_mut()).await;
        *self.side.lock().unwrap_or_else(|p| p.into_inner()) = Some((io, perception));
        Ok(out)
    }
}

/// Checks everything a real-controller run needs, before anything connects: the explicit
/// opt-in, the scenario's limits, the camera source (opened; each capture waits up to
/// `capture_timeout`), and a perception mode that reads camera images and is available.
pub fn production(
    scenario: &Scenario,
    robot: &RobotTarget,
    allow_motion: bool,
    camera: Option<&CameraSpec>,
    capture_timeout: Duration,
) -> Result<Driver, ProductionRefusal> {
    let RobotTarget::Ur { host, port } = robot else {
        return Err(ProductionRefusal::NotAController(robot.clone()));
    };
    let refuse = |why: String| ProductionRefusal::Refused {
        robot: robot.clone(),
        why,
    };
    let camera = match camera {
        Some(c) => c.clone(),
        None if allow_motion => {
            return Err(refuse(
                "a production run needs --camera SPEC (the camera source: folder:/path, \
                 cmd:'grab --out {path}', files:/path or aravis:[DEVICE])"
                    .into(),
            ));
        }
        // Refused below for the missing opt-in, before any camera is looked at.
        None => CameraSpec::Folder(PathBuf::new()),
    };
    let options = ProductionOptions {
        allow_motion,
        camera,
        capture_timeout,
    };
    let camera = preflight(scenario, &options).map_err(|e| {
        refuse(match e {
            ProductionError::NotAllowed => {
                "it moves a real arm: pass --allow-motion to allow motion".into()
            }
            ProductionError::Perception(PerceptionMode::KeypointNoise) => {
                "keypoint-noise perception needs the simulated scene and cannot read camera \
                 images; use --robot sim or --robot virtual-ur, or a scenario with \
                 [perception] mode = \"learned\""
                    .into()
            }
            other => other.to_string(),
        })
    })?;
    let perception = image_perception(scenario).map_err(|e| refuse(e.to_string()))?;
    Ok(Driver::Production(Box::new(Production {
        robot: robot.clone(),
        host: host.clone(),
        port: *port,
        side: std::sync::Mutex::new(Some((
            camera_checked(
                ProductionCellIo::new(scenario.clone(), camera, capture_timeout),
                scenario,
            ),
            perception,
        ))),
    })))
}

/// The production side channels with the camera check of the run's first capture, against the
/// scenario's board and calibrated poses.
fn camera_checked(io: ProductionCellIo, scenario: &Scenario) -> ProductionCellIo {
    let cell = &scenario.spec.cell;
    match cell.board_layout() {
        Some(board) => io.with_camera_check(CameraCheck::new(
            board,
            cell.camera.intrinsics,
            &cell.camera.base_T_camera.isometry(),
            &cell.base_T_table.isometry(),
            crate::calibrate::preflight::DEFAULT_TOLERANCE,
        )),
        None => io,
    }
}

/// The perception that reads camera images for `scenario`'s mode: the learned pipeline with both
/// cores, searching the window of the full-sensor image that shows the feeder.
#[allow(non_snake_case)]
fn image_perception(scenario: &Scenario) -> Result<Box<dyn PartPerception>, PerceptionError> {
    let pipeline = learned::pipeline(scenario, &learned::models(scenario)?, 2)?;
    let base_T_table = scenario.spec.cell.base_T_table.isometry();
    Ok(Box::new(
        LearnedPerception::new(pipeline, base_T_table).with_roi(learned::feeder_roi(scenario)?),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{FilesCamera, Sensor};
    use perception::{Frame, Perceived, PerceptionError};

    /// Stands in for the learned perception, which has no trained models yet; the guarded run
    /// never gets as far as perceiving.
    struct NoModels;

    impl PartPerception for NoModels {
        fn perceive(&mut self, _frame: &Frame) -> Result<Perceived, PerceptionError> {
            Err(PerceptionError::Settings("no trained models".into()))
        }
    }

    /// A production run builds no simulated cell: with a cell the simulator cannot model (its
    /// feeder 5 m out of reach) the run still reaches the controller, and fails only because
    /// nothing listens there.
    #[test]
    fn a_production_run_builds_no_simulated_cell() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
        let mut loaded = LoadedScenario::load(&path).unwrap();
        loaded.scenario.spec.cell.feeder.center = [5.0, 5.0];
        assert!(
            SimSetup::new(loaded.scenario.clone()).is_err(),
            "the simulator must refuse this cell for the test to mean anything"
        );
        // A loopback port with nothing listening.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .unwrap()
            .port();
        let images = tempfile::tempdir().unwrap();
        std::fs::write(images.path().join("frame.png"), b"not decoded").unwrap();
        let robot = RobotTarget::Ur {
            host: "127.0.0.1".into(),
            port,
        };
        let driver = Driver::Production(Box::new(Production {
            robot: robot.clone(),
            host: "127.0.0.1".into(),
            port,
            side: std::sync::Mutex::new(Some((
                ProductionCellIo::new(
                    loaded.scenario.clone(),
                    Box::new(
                        FilesCamera::open(
                            images.path(),
                            Sensor::of(&loaded.scenario.spec.cell.camera.intrinsics),
                        )
                        .unwrap(),
                    ),
                    Duration::from_millis(100),
                ),
                Box::new(NoModels),
            ))),
        }));
        let out = tempfile::tempdir().unwrap();
        let err = execute_on(&loaded, out.path(), Shard::ALL, 1, 1, false, &driver)
            .err()
            .expect("nothing listens on the controller's port");
        match &err {
            ExecuteError::Run(RunError::Episode { episode: 0, source }) => {
                let text = source.to_string();
                assert!(text.starts_with(&robot.to_string()), "{text}");
            }
            other => panic!("expected the controller connection to fail, got: {other}"),
        }
    }
}
