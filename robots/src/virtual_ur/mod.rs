//! A virtual UR controller: RTDE (30004), dashboard (29999) and script port (30003) on loopback,
//! backed by a simulated arm stepped at 500 Hz. It recognises our program and SDU ur_rtde's
//! control script when uploaded and executes their register protocols natively.
//!
//! Fault injection for tests: drop connections, protective stop, e-stop, delay, skip or
//! withhold packages, refuse programs.

pub mod arm;
pub mod controller;
pub mod dynamics;
pub mod force;
pub mod path;
pub mod path_move;
pub mod programs;
pub mod registers;
pub mod script_port;
pub mod ur_rtde_program;

use crate::kinematics::Joints;
use crate::rtde::ControllerVersion;
use crate::rtde::server::{self, ServerFaults};
use arm::{ArmModel, KinematicArm};
use controller::VirtualController;
use std::f64::consts::FRAC_PI_2;
use std::io;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tokio::net::TcpListener;

/// Where and how the virtual controller runs.
#[derive(Debug, Clone)]
pub struct VirtualUrConfig {
    /// Address to listen on (loopback by default).
    pub host: IpAddr,
    /// RTDE port (0: any free port).
    pub rtde_port: u16,
    /// Dashboard port (0: any free port).
    pub dashboard_port: u16,
    /// Script port (0: any free port).
    pub script_port: u16,
    /// Joints at start.
    pub initial_q: Joints,
    /// Reported controller version.
    pub version: ControllerVersion,
    /// Control period.
    pub period: Duration,
    /// Time after a protective stop before it can be unlocked.
    pub unlock_delay: Duration,
    /// What the tool touches when the arm model does not simulate contacts itself: the table
    /// plane under the base by default.
    pub contact: force::ContactEnvironment,
    /// Seed of the wrist force/torque sensor's bias and noise.
    pub sensor_seed: u64,
}

impl Default for VirtualUrConfig {
    fn default() -> Self {
        VirtualUrConfig {
            host: IpAddr::V4(Ipv4Addr::LOCALHOST),
            rtde_port: crate::rtde::RTDE_PORT,
            dashboard_port: crate::dashboard::DASHBOARD_PORT,
            script_port: 30003,
            initial_q: [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0],
            version: ControllerVersion {
                major: 5,
                minor: 23,
                bugfix: 0,
                build: 0,
            },
            period: Duration::from_millis(2),
            unlock_delay: Duration::from_secs(5),
            contact: force::ContactEnvironment::Plane(force::ContactPlane::table()),
            sensor_seed: controller::DEFAULT_SENSOR_SEED,
        }
    }
}

impl VirtualUrConfig {
    /// Loopback with free ports for all three services (for tests).
    pub fn ephemeral() -> VirtualUrConfig {
        VirtualUrConfig {
            rtde_port: 0,
            dashboard_port: 0,
            script_port: 0,
            ..VirtualUrConfig::default()
        }
    }
}

/// Timing statistics of the control loop.
#[derive(Debug, Default)]
pub struct LoopStats {
    /// Cycles run.
    pub cycles: AtomicU64,
    /// Cycles that started more than one period late.
    pub overruns: AtomicU64,
}

/// A running virtual controller; dropping it stops every service.
pub struct VirtualUr {
    /// The controller (state, faults, dashboard logic).
    pub controller: Arc<VirtualController>,
    /// RTDE stream faults.
    pub faults: Arc<ServerFaults>,
    /// Control loop timing.
    pub loop_stats: Arc<LoopStats>,
    rtde_addr: SocketAddr,
    dashboard_addr: SocketAddr,
    script_addr: SocketAddr,
    tasks: Vec<tokio::task::JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    sim: Option<std::thread::JoinHandle<()>>,
}

impl VirtualUr {
    /// Starts a virtual UR5e (kinematic arm).
    pub async fn start(config: VirtualUrConfig) -> io::Result<VirtualUr> {
        let arm = KinematicArm::ur5e(config.initial_q);
        VirtualUr::start_with_arm(config, Box::new(arm)).await
    }

    /// Starts the controller around any arm model.
    pub async fn start_with_arm(
        config: VirtualUrConfig,
        arm: Box<dyn ArmModel>,
    ) -> io::Result<VirtualUr> {
        let rtde = TcpListener::bind((config.host, config.rtde_port)).await?;
        let dashboard = TcpListener::bind((config.host, config.dashboard_port)).await?;
        let script = TcpListener::bind((config.host, config.script_port)).await?;
        let (rtde_addr, dashboard_addr, script_addr) = (
            rtde.local_addr()?,
            dashboard.local_addr()?,
            script.local_addr()?,
        );
        let controller = Arc::new(VirtualController::new(
            arm,
            config.version,
            config.period,
            config.unlock_delay,
        ));
        controller.set_sensor_noise(force::FtNoise::ur5e(config.sensor_seed));
        controller.set_contact_environment(config.contact);
        let faults = Arc::new(ServerFaults::default());
        let stop = Arc::new(AtomicBool::new(false));
        let loop_stats = Arc::new(LoopStats::default());
        let sim = {
            let (controller, stop, stats) = (controller.clone(), stop.clone(), loop_stats.clone());
            std::thread::Builder::new()
                .name("virtual-ur-control".into())
                .spawn(move || control_loop(&controller, &stop, &stats))?
        };
        let mut tasks = Vec::new();
        {
            let (c, f) = (controller.clone(), faults.clone());
            tasks.push(tokio::spawn(async move {
                if let Err(e) = server::serve(rtde, c, f).await {
                    tracing::error!(error = %e, "RTDE server stopped");
                }
            }));
        }
        {
            let c = controller.clone();
            let handler = Arc::new(move |line: &str| c.dashboard(line));
            tasks.push(tokio::spawn(async move {
                if let Err(e) = crate::dashboard::serve(dashboard, handler).await {
                    tracing::error!(error = %e, "dashboard server stopped");
                }
            }));
        }
        {
            let c = controller.clone();
            tasks.push(tokio::spawn(async move {
                if let Err(e) = script_port::serve(script, c).await {
                    tracing::error!(error = %e, "script server stopped");
                }
            }));
        }
        tracing::info!(%rtde_addr, %dashboard_addr, %script_addr, "virtual UR controller running");
        Ok(VirtualUr {
            controller,
            faults,
            loop_stats,
            rtde_addr,
            dashboard_addr,
            script_addr,
            tasks,
            stop,
            sim: Some(sim),
        })
    }

    /// RTDE address.
    pub fn rtde_addr(&self) -> SocketAddr {
        self.rtde_addr
    }

    /// Dashboard address.
    pub fn dashboard_addr(&self) -> SocketAddr {
        self.dashboard_addr
    }

    /// Script port address.
    pub fn script_addr(&self) -> SocketAddr {
        self.script_addr
    }

    /// Fault: close every RTDE connection.
    pub fn drop_rtde_connections(&self) {
        self.faults.drop_connections();
    }

    /// Fault: protective stop.
    pub fn protective_stop(&self) {
        self.controller.protective_stop();
    }

    /// Fault: emergency stop.
    pub fn emergency_stop(&self) {
        self.controller.emergency_stop();
    }

    /// Fault: refuse uploaded programs (or accept them again).
    pub fn refuse_programs(&self, refuse: bool) {
        self.controller.refuse_programs(refuse);
    }
}

impl Drop for VirtualUr {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in &self.tasks {
            t.abort();
        }
        if let Some(sim) = self.sim.take() {
            let _ = sim.join();
        }
    }
}

/// Runs the control loop on a dedicated thread with absolute deadlines, so controller time
/// tracks wall-clock time: a cycle that starts late is counted as an overrun and the missed
/// cycles are stepped at once (clients then see skipped packages, as from a loaded controller);
/// beyond [`MAX_CATCH_UP`] missed cycles the schedule is re-based instead.
fn control_loop(controller: &VirtualController, stop: &AtomicBool, stats: &LoopStats) {
    let period = controller.period;
    let mut next = Instant::now() + period;
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if next > now {
            // Plain sleep: ~0.1 ms late at worst on Linux, far inside the 4 ms lateness budget,
            // and no core burnt spinning (tests run many controllers on two cores).
            std::thread::sleep(next - now);
        } else if now - next > period {
            stats.overruns.fetch_add(1, Ordering::Relaxed);
            let missed = ((now - next).as_secs_f64() / period.as_secs_f64()) as u32;
            if missed > MAX_CATCH_UP {
                next = now;
            } else {
                for _ in 0..missed {
                    controller.tick();
                    stats.cycles.fetch_add(1, Ordering::Relaxed);
                    next += period;
                }
            }
        }
        controller.tick();
        stats.cycles.fetch_add(1, Ordering::Relaxed);
        next += period;
    }
}

/// Most missed cycles the control loop steps to catch up (0.5 s at 500 Hz).
pub const MAX_CATCH_UP: u32 = 250;
