//! `cell run SCENARIO [--robot ROBOT]`: run a scenario's episodes, resumably, and report. The
//! robot is the in-process simulated cell (`sim`, default), the simulated cell behind a virtual
//! UR controller driven over loopback RTDE (`virtual-ur`), or a real controller
//! (`ur://HOST[:PORT]`, after the production pre-flight).

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::str::FromStr;

use anyhow::Context;
use cell::episode::EpisodeRecord;
use cell::orchestrator::{
    EpisodeOutput, OrchestratorError, PartPerception, ProductionCellIo, ProductionError,
    ProductionOptions, SimSetup, preflight, run_episode, run_sim_episode_blocking,
};
use cell::report::{ReportFiles, write_report};
use cell::run::{
    LoadedScenario, ResultsStore, RunOptions, RunOutcome, Shard, Summary, results_dir, run_episodes,
};
use cell::scenario::{PerceptionMode, Scenario};

/// Arguments of `cell run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario file (validated first: an invalid scenario never starts a run).
    pub scenario: PathBuf,
    /// Episodes to run (default: the scenario's `episodes`); a larger number extends an
    /// earlier run.
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Run only shard I of N (episodes i with i % N == I), for an external scheduler; combine
    /// the shards with `cell merge`.
    #[arg(long, default_value = "0/1")]
    pub shard: Shard,
    /// Results root: episodes go to OUT/<scenario>/<shard>/episodes.jsonl, and a rerun
    /// continues with the episodes not yet there.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub jobs: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// The robot: `sim` (the in-process simulated cell), `virtual-ur` (the simulated cell behind
    /// a virtual UR controller on 127.0.0.1, driven by the production RTDE client; episodes run
    /// one after another in real time) or `ur://HOST[:PORT]` (a real controller, RTDE port 30004
    /// by default; needs --allow-motion and --camera, and an image-reading perception mode).
    #[arg(long, default_value = "sim")]
    pub robot: RobotTarget,
    /// Production opt-in: allow a real arm to move (only with --robot ur://HOST).
    #[arg(long)]
    pub allow_motion: bool,
    /// Production camera source: an image file or a folder of images (only with
    /// --robot ur://HOST).
    #[arg(long)]
    pub camera: Option<PathBuf>,
}

/// Which robot a run drives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RobotTarget {
    /// The in-process simulated cell.
    Sim,
    /// The simulated cell behind an in-process virtual UR controller on loopback, driven over
    /// RTDE by the production client.
    VirtualUr,
    /// A real UR controller.
    Ur {
        /// Host name or address.
        host: String,
        /// RTDE port.
        port: u16,
    },
}

impl FromStr for RobotTarget {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        const EXPECTED: &str = "expected sim, virtual-ur or ur://HOST[:PORT]";
        match s {
            "sim" => return Ok(Self::Sim),
            "virtual-ur" => return Ok(Self::VirtualUr),
            _ => {}
        }
        let Some(rest) = s.strip_prefix("ur://") else {
            return Err(format!("unknown robot {s:?}: {EXPECTED}"));
        };
        let bad = |why: &str| format!("robot {s:?}: {why} ({EXPECTED}, e.g. ur://192.168.0.10)");
        let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
            let (addr, after) = v6.split_once(']').ok_or_else(|| bad("unclosed '['"))?;
            addr.parse::<std::net::Ipv6Addr>()
                .map_err(|_| bad("not an IPv6 address in brackets"))?;
            let port = match after {
                "" => None,
                p => Some(p.strip_prefix(':').ok_or_else(|| bad("junk after ']'"))?),
            };
            (addr, port)
        } else {
            match rest.split_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (rest, None),
            }
        };
        if host.is_empty() {
            return Err(bad("no host"));
        }
        let host_ok = host.contains(':')
            || host
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '-');
        if !host_ok || host.starts_with(['.', '-']) {
            return Err(bad("the host may hold only letters, digits, '.' and '-'"));
        }
        let port = match port {
            None => robots::rtde::RTDE_PORT,
            Some(p) => match p.parse::<u16>() {
                Ok(p) if p > 0 => p,
                _ => return Err(bad("the port must be a number from 1 to 65535")),
            },
        };
        Ok(Self::Ur {
            host: host.to_string(),
            port,
        })
    }
}

impl fmt::Display for RobotTarget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Sim => f.write_str("sim"),
            Self::VirtualUr => f.write_str("virtual-ur"),
            Self::Ur { host, port } if host.contains(':') => write!(f, "ur://[{host}]:{port}"),
            Self::Ur { host, port } => write!(f, "ur://{host}:{port}"),
        }
    }
}

/// What can stop one simulated episode from producing a record.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError {
    /// The simulated cell or perception could not be set up.
    #[error(transparent)]
    Setup(#[from] OrchestratorError),
    /// The episode over loopback RTDE could not run.
    #[error(transparent)]
    OverRtde(#[from] cell::orchestrator::OverRtdeError),
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
            (Driver::VirtualUr, Some(rt)) => {
                rt.block_on(cell::orchestrator::sim_episode_over_rtde(&setup, e))?
            }
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
        let mut config = UrRobotConfig::new(self.host.clone());
        config.rtde_port = self.port;
        config.limits = setup.scenario.spec.cell.limits.clone();
        config.kinematics = setup.knowledge.kinematics.clone();
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

/// The headline of a summary, one line.
pub fn headline(s: &Summary) -> String {
    format!(
        "{}: {} of {} episodes assembled, {:.1} % (95 % Wilson {:.1}–{:.1} %)",
        s.scenario,
        s.successes,
        s.episodes,
        100.0 * s.success_rate,
        100.0 * s.success_ci95.lo,
        100.0 * s.success_ci95.hi
    )
}

/// Validates the scenario, runs (or resumes) it, prints the headline and where the report is.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let loaded = LoadedScenario::load(&args.scenario)?;
    let episodes = args.episodes.unwrap_or(loaded.scenario.spec.episodes);
    let driver = match &args.robot {
        RobotTarget::Ur { .. } => production(
            &loaded.scenario,
            &args.robot,
            args.allow_motion,
            args.camera.as_deref(),
        )?,
        other => {
            anyhow::ensure!(
                !args.allow_motion && args.camera.is_none(),
                "--allow-motion and --camera are for a real controller (--robot ur://HOST), \
                 not --robot {other}"
            );
            match other {
                RobotTarget::VirtualUr => Driver::VirtualUr,
                _ => Driver::Sim,
            }
        }
    };
    let done = execute_on(
        &loaded,
        &args.out,
        args.shard,
        episodes,
        args.jobs,
        !args.quiet,
        &driver,
    )?;
    println!("{}", headline(&done.summary));
    for t in &done.summary.steps {
        println!(
            "  step {} {:<12} seated {}/{} ({:.1} %)",
            t.index,
            t.part,
            t.seated,
            t.reached,
            100.0 * t.rate
        );
    }
    for e in done.summary.error_budget.iter().take(5) {
        println!(
            "  failures blamed on {:<26} {:>4} ({:.0} %)",
            e.source,
            e.failures,
            100.0 * e.share
        );
    }
    println!(
        "ran {} episodes in {:.1} s ({} resumed); results {}, report {}",
        done.outcome.ran,
        done.outcome.wall_s,
        done.outcome.resumed,
        done.dir.join(cell::run::RESULTS_FILE).display(),
        done.report.html.display()
    );
    Ok(ExitCode::SUCCESS)
}
