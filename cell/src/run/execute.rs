//! Executing a run on a robot: the results store, one episode after another (in parallel in
//! simulation), the event files, then the summary and report; and the checked set-up for a real
//! controller.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;

use super::{
    LoadedScenario, ResultsStore, RobotTarget, RunOptions, RunOutcome, Shard, Summary, results_dir,
    run_episodes,
};
use crate::episode::EpisodeRecord;
use crate::orchestrator::{
    EpisodeOutput, OrchestratorError, OverRtdeError, PartPerception, ProductionCellIo,
    ProductionError, ProductionOptions, SimSetup, preflight, run_episode, run_sim_episode_blocking,
    sim_episode_over_rtde,
};
use crate::report::{ReportFiles, write_report};
use crate::scenario::{PerceptionMode, Scenario};

/// What can stop one simulated episode from producing a record.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError {
    /// The simulated cell or perception could not be set up.
    #[error(transparent)]
    Setup(#[from] OrchestratorError),
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
    /// The episode's event log could not be written.
    #[error("writing {}: {source}", path.display())]
    Events {
        /// The event file.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
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
) -> anyhow::Result<Executed> {
    execute_on(loaded, root, shard, episodes, jobs, progress, &Driver::Sim)
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
) -> anyhow::Result<Executed> {
    let name = &loaded.scenario.spec.name;
    let dir = results_dir(root, name, shard);
    let (mut store, opened) = ResultsStore::open(&dir, loaded.header(shard))?;
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
    let setup = SimSetup::new(loaded.scenario.clone())?;
    let events = dir.join("events");
    std::fs::create_dir_all(&events)?;
    // Episodes on a controller run one at a time: it drives one arm, in real time.
    let jobs = match driver {
        Driver::Sim => jobs,
        Driver::VirtualUr | Driver::Production(_) => 1,
    };
    let options = RunOptions {
        episodes,
        jobs,
        progress,
    };
    let runtime = match driver {
        Driver::Sim => None,
        Driver::VirtualUr | Driver::Production(_) => Some(
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .context("start the async runtime")?,
        ),
    };
    let outcome = run_episodes(&setup.scenario, &mut store, &options, |_, e| {
        let out = match (driver, &runtime) {
            (Driver::VirtualUr, Some(rt)) => rt.block_on(sim_episode_over_rtde(&setup, e))?,
            (Driver::Production(p), Some(rt)) => rt.block_on(p.episode(&setup, e))?,
            _ => run_sim_episode_blocking(&setup, e)?,
        };
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
    async fn episode(&self, setup: &SimSetup, e: u32) -> Result<EpisodeOutput, EpisodeError> {
        use robots::ur_robot::{UrRobot, UrRobotConfig};
        let robot_err = |source| EpisodeError::Robot {
            robot: self.robot.to_string(),
            source,
        };
        let mut config = UrRobotConfig::new(self.host.clone(), setup.knowledge.kinematics.clone());
        config.rtde_port = self.port;
        config.limits = setup.scenario.spec.cell.limits.clone();
        config.gripper_actuation_s = setup.scenario.spec.cell.gripper.actuation_time;
        let mut robot = UrRobot::connect(config).await.map_err(robot_err)?;
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
        let out = run_episode(
            &setup.scenario,
            &setup.knowledge,
            e,
            &mut robot,
            &mut io,
            perception.as_mut(),
            &setup.settings,
        )
        .await;
        *self.side.lock().unwrap_or_else(|p| p.into_inner()) = Some((io, perception));
        Ok(out)
    }
}

/// Checks everything a real-controller run needs, before anything connects: the explicit
/// opt-in, the scenario's limits, the camera source, and a perception mode that reads camera
/// images and is available.
pub fn production(
    scenario: &Scenario,
    robot: &RobotTarget,
    allow_motion: bool,
    camera: Option<&Path>,
) -> anyhow::Result<Driver> {
    let RobotTarget::Ur { host, port } = robot else {
        anyhow::bail!("{robot} is not a real controller");
    };
    let refuse = |why: String| anyhow::anyhow!("refusing to run on {robot}: {why}");
    if allow_motion && camera.is_none() {
        return Err(refuse(
            "a production run needs --camera IMAGE_OR_FOLDER (the camera source)".into(),
        ));
    }
    let options = ProductionOptions {
        allow_motion,
        camera: camera.map(Path::to_path_buf).unwrap_or_default(),
    };
    let images = preflight(scenario, &options).map_err(|e| {
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
            ProductionCellIo::new(scenario.clone(), images),
            perception,
        ))),
    })))
}

/// The perception that reads camera images for `scenario`'s mode.
fn image_perception(scenario: &Scenario) -> Result<Box<dyn PartPerception>, OrchestratorError> {
    // No learned models are trained yet: the learned mode is refused here, before connecting.
    Err(OrchestratorError::ModeUnavailable(
        scenario.spec.perception.mode,
    ))
}
