//! `cell virtual-ur`: a simulated UR controller (RTDE, dashboard, script port) on loopback,
//! backed by a kinematic UR5e or, with `--scenario`, by a scenario's simulated cell.
//!
//! ur_rtde's control script runs natively: every call either has the effect it has on a UR, or
//! fails loudly (the program stops with a runtime error; ur_rtde returns False or raises). The
//! conformance suite `scripts/ur_rtde/conformance.py` lists the methods that are not simulated.
//! As on a UR, a `speedJ`/`speedL` keeps going when its client dies without `stopScript`
//! unless the client armed the RTDE watchdog (`setWatchdog(f)` with `kickWatchdog()` in its
//! loop, or `rtde_set_watchdog` in a URCap program): after 1/f s without an update of
//! `input_int_register_0` the program stops and the arm decelerates to rest.

use std::f64::consts::FRAC_PI_2;
use std::net::IpAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::Context;
use cell::harness::SimSetup;
use cell::scenario::Scenario;
use robots::virtual_ur::arm::ArmModel;
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use sim::cell::arm::SimArm;

/// Arguments of `cell virtual-ur`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Address to listen on; loopback unless you mean to expose it.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: IpAddr,
    /// RTDE port (0 picks a free one).
    #[arg(long, default_value_t = 30004)]
    pub rtde_port: u16,
    /// Dashboard server port (0 picks a free one).
    #[arg(long, default_value_t = 29999)]
    pub dashboard_port: u16,
    /// Script port accepting URScript programs (0 picks a free one).
    #[arg(long, default_value_t = 30003)]
    pub script_port: u16,
    /// Initial joint angles in radians, six comma-separated values (default: the UR5e's
    /// upright pose; a scenario's cell starts at its home).
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        conflicts_with = "scenario"
    )]
    pub initial_q: Option<Vec<f64>>,
    /// Serve this scenario's simulated cell (feeder, gripper on tool output 0, insertions,
    /// table protective stops) instead of a bare kinematic arm, so ur_rtde programs can drive it.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// With --scenario: which episode's world (feeder draw, error sources) to serve.
    #[arg(long, default_value_t = 0, requires = "scenario")]
    pub episode: u32,
    /// Seconds after a protective stop before `unlock protective stop` succeeds (5 on a real UR).
    #[arg(long, default_value_t = 5.0)]
    pub unlock_delay_s: f64,
    /// Stop after this many seconds (default: run until Ctrl-C).
    #[arg(long)]
    pub duration_s: Option<f64>,
}

/// Runs the virtual controller until Ctrl-C (or `--duration-s`).
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let cell = match &args.scenario {
        Some(path) => {
            let scenario = Scenario::load(path).map_err(|e| anyhow::anyhow!("{e}"))?;
            let name = scenario.spec.name.clone();
            let setup = SimSetup::new(scenario)?;
            Some((name, setup.cell(args.episode)?))
        }
        None => None,
    };
    let initial_q: [f64; 6] = match (&args.initial_q, &cell) {
        (Some(q), _) => q
            .as_slice()
            .try_into()
            .context("--initial-q needs exactly six joint angles")?,
        (_, Some((_, c))) => c.lock().unwrap_or_else(|p| p.into_inner()).joints_now(),
        (None, None) => [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0],
    };
    anyhow::ensure!(
        initial_q.iter().all(|q| q.is_finite()),
        "--initial-q must be finite numbers"
    );
    anyhow::ensure!(
        args.unlock_delay_s.is_finite() && args.unlock_delay_s >= 0.0,
        "--unlock-delay-s must be a non-negative number of seconds"
    );
    let config = VirtualUrConfig {
        host: args.host,
        rtde_port: args.rtde_port,
        dashboard_port: args.dashboard_port,
        script_port: args.script_port,
        initial_q,
        unlock_delay: Duration::from_secs_f64(args.unlock_delay_s),
        ..VirtualUrConfig::default()
    };
    let runtime = tokio::runtime::Runtime::new().context("start the async runtime")?;
    runtime.block_on(async move {
        let (vur, backing) = match cell {
            Some((name, cell)) => {
                let arm: Box<dyn ArmModel> = Box::new(SimArm::new(cell));
                let what = format!("the simulated cell of {name}, episode {}", args.episode);
                (VirtualUr::start_with_arm(config, arm).await, what)
            }
            None => (
                VirtualUr::start(config).await,
                "a kinematic UR5e".to_string(),
            ),
        };
        let vur = vur.context("bind the controller ports (another controller running?)")?;
        println!(
            "virtual UR5e running ({backing}): RTDE {}, dashboard {}, script {} (Ctrl-C to stop)",
            vur.rtde_addr(),
            vur.dashboard_addr(),
            vur.script_addr()
        );
        match args.duration_s {
            Some(s) if s.is_finite() && s >= 0.0 => {
                tokio::time::sleep(Duration::from_secs_f64(s)).await;
            }
            Some(s) => anyhow::bail!("--duration-s {s} is not a non-negative number"),
            None => tokio::signal::ctrl_c().await.context("wait for Ctrl-C")?,
        }
        println!(
            "stopped after {} control cycles ({} overruns)",
            vur.loop_stats.cycles.load(Ordering::Relaxed),
            vur.loop_stats.overruns.load(Ordering::Relaxed)
        );
        Ok(ExitCode::SUCCESS)
    })
}
