//! `cell virtual-ur`: a simulated UR controller (RTDE, dashboard, script port) on loopback.

use anyhow::Context;
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use std::net::IpAddr;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

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
    /// Initial joint angles in radians, six comma-separated values.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true,
          default_values_t = [0.0, -std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2,
                              -std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2, 0.0])]
    pub initial_q: Vec<f64>,
    /// Seconds after a protective stop before `unlock protective stop` succeeds (5 on a real UR).
    #[arg(long, default_value_t = 5.0)]
    pub unlock_delay_s: f64,
    /// Stop after this many seconds (default: run until Ctrl-C).
    #[arg(long)]
    pub duration_s: Option<f64>,
}

/// Runs the virtual controller until Ctrl-C (or `--duration-s`).
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let initial_q: [f64; 6] = args
        .initial_q
        .as_slice()
        .try_into()
        .context("--initial-q needs exactly six joint angles")?;
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
        let vur = VirtualUr::start(config)
            .await
            .context("bind the controller ports (another controller running?)")?;
        println!(
            "virtual UR5e running: RTDE {}, dashboard {}, script {} (Ctrl-C to stop)",
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
