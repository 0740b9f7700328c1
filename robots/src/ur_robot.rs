//! `UrRobot`: the [`Robot`] trait over RTDE + dashboard + our URScript program (`cell.script`).
//!
//! [`UrRobot::connect`] returns the robot wrapped in [`Limited`], which checks every target
//! against the configured [`Limits`] (workspace box, speeds, accelerations, joint range) before
//! anything is sent. Each command gets a fresh id, is written
//! to the program's registers in one RTDE package, and is awaited with a timeout; a protective
//! stop, an emergency stop or the program stopping aborts the wait with a typed error. While a
//! safety stop is active no command is sent at all. A gripper command is done only after the
//! program has slept the configured actuation time ([`UrRobotConfig::gripper_actuation_s`]).

use crate::dashboard::{DashboardClient, DashboardError};
use crate::kinematics::{Joints, UrKinematics, from_ur_pose, to_ur_pose};
use crate::limited::Limited;
use crate::limits::Limits;
use crate::program::{self, layout as L};
use crate::robot::{
    ContactOutcome, ContactSample, JointMotion, LinearMotion, Robot, RobotError, RobotFuture,
    RobotMode, RobotStatus, SafetyStatus, Wrench,
};
use crate::robot::{Waypoint, WaypointTarget};
use crate::rtde::client::{Backoff, ClientConfig, ClientError, LinkStatus, RtdeClient};
use crate::rtde::state::{
    OutputState, RuntimeState, SAFETY_BIT_EMERGENCY_STOPPED, SAFETY_BIT_PROTECTIVE_STOPPED,
};
use crate::rtde::types::Value;
use nalgebra::Isometry3;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

/// Which digital output drives the gripper.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GripperOutput {
    /// Tool digital output 0 or 1.
    Tool(u8),
    /// Standard digital output 0–7.
    Standard(u8),
}

/// A gripper whose opening follows a standard analog output (a position input across its
/// stroke, 0–10 V or 4–20 mA), besides the digital output that closes it on a part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GripperWidthOutput {
    /// Standard analog output 0 or 1.
    pub output: u8,
    /// Opening at the top of the output's range, metres: the full stroke.
    pub stroke: f64,
}

/// Configuration of a [`UrRobot`].
#[derive(Debug, Clone)]
pub struct UrRobotConfig {
    /// Controller host, e.g. `127.0.0.1`.
    pub host: String,
    /// RTDE port (30004).
    pub rtde_port: u16,
    /// Dashboard port (29999).
    pub dashboard_port: u16,
    /// Script port (30003).
    pub script_port: u16,
    /// Limits every target is checked against (by the [`Limited`] wrapper `connect` returns).
    pub limits: Limits,
    /// Kinematics used for the joint-move path check and reachability.
    pub kinematics: UrKinematics,
    /// Longest wait for one command.
    pub command_timeout: Duration,
    /// Longest wait for the program to run after upload.
    pub program_start_timeout: Duration,
    /// Period of the heartbeat the program's watchdog listens to (well under 0.5 s).
    pub heartbeat_period: Duration,
    /// RTDE stall timeout.
    pub stall_timeout: Duration,
    /// Longest wait, before a new command or reading, for a link that is re-establishing itself
    /// (after a stall or a dropped connection) to stream again; a link still down then is a
    /// lost connection. No command is sent meanwhile, and the program's watchdog has stopped the
    /// arm if the heartbeat was missed for longer than it allows.
    pub reconnect_grace: Duration,
    /// Gripper output.
    pub gripper: GripperOutput,
    /// Output level that closes the gripper.
    pub gripper_close_level: bool,
    /// Seconds the gripper needs to open or close: the program sleeps this long after setting
    /// the output before it reports the gripper command done, so the arm does not move away
    /// from a part the fingers still close on. Finite, 0 to [`MAX_GRIPPER_ACTUATION_S`].
    pub gripper_actuation_s: f64,
    /// The analog output that sets the fingers' opening; `None`: opening the gripper opens the
    /// full stroke whatever the width asked.
    pub gripper_width: Option<GripperWidthOutput>,
}

/// Longest gripper actuation time a [`UrRobotConfig`] accepts (s): the program reads no command
/// (a stop included) while it waits.
pub const MAX_GRIPPER_ACTUATION_S: f64 = L::MAX_DO_WAIT_S;

/// Why a [`UrRobotConfig`] is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UrConfigError {
    /// The gripper actuation time is not a number, negative or too long.
    #[error(
        "gripper actuation time {0} s is not a finite time from 0 to {MAX_GRIPPER_ACTUATION_S} s"
    )]
    GripperActuation(f64),
    /// The gripper's width output is not a standard analog output or its stroke not a width.
    #[error(
        "gripper width output {output} with a {stroke} m stroke: the output must be standard \
         analog output 0 or 1 and the stroke a positive width"
    )]
    GripperWidth {
        /// The output asked for.
        output: u8,
        /// The stroke given.
        stroke: f64,
    },
}

impl UrRobotConfig {
    /// Defaults for the arm with `kinematics` (from its description, with the TCP set in the
    /// controller) at `host` on the standard ports.
    pub fn new(host: impl Into<String>, kinematics: UrKinematics) -> UrRobotConfig {
        UrRobotConfig {
            host: host.into(),
            rtde_port: crate::rtde::RTDE_PORT,
            dashboard_port: crate::dashboard::DASHBOARD_PORT,
            script_port: 30003,
            limits: Limits::default(),
            kinematics,
            command_timeout: Duration::from_secs(30),
            program_start_timeout: Duration::from_secs(5),
            heartbeat_period: Duration::from_millis(50),
            stall_timeout: Duration::from_millis(200),
            reconnect_grace: Duration::from_secs(1),
            gripper: GripperOutput::Tool(0),
            gripper_close_level: true,
            gripper_actuation_s: 0.25,
            gripper_width: None,
        }
    }

    /// Checks the values [`UrRobot::connect`] relies on (the limits are checked there too).
    pub fn validate(&self) -> Result<(), UrConfigError> {
        if !(0.0..=MAX_GRIPPER_ACTUATION_S).contains(&self.gripper_actuation_s) {
            return Err(UrConfigError::GripperActuation(self.gripper_actuation_s));
        }
        if let Some(GripperWidthOutput { output, stroke }) = self.gripper_width
            && (output > 1 || !(stroke.is_finite() && stroke > 0.0))
        {
            return Err(UrConfigError::GripperWidth { output, stroke });
        }
        Ok(())
    }
}

/// Output variables `UrRobot` reads.
fn output_names() -> Vec<String> {
    let mut names: Vec<String> = [
        "timestamp",
        "actual_q",
        "actual_TCP_pose",
        "actual_TCP_force",
        "robot_mode",
        "safety_mode",
        "safety_status_bits",
        "runtime_state",
    ]
    .iter()
    .map(|s| (*s).to_owned())
    .collect();
    names.extend(L::output_registers());
    names
}

/// One command of the program protocol.
#[derive(Debug, Clone, Copy, Default)]
struct Command {
    kind: i32,
    target: [f64; 6],
    speed: f64,
    accel: f64,
    pin: i32,
    level: bool,
    /// Seconds the program sleeps after a set-output command.
    wait: f64,
}

/// A UR arm driven through our program.
pub struct UrRobot {
    config: UrRobotConfig,
    rtde: Arc<RtdeClient>,
    dashboard: Option<DashboardClient>,
    next_id: i32,
    heartbeat: tokio::task::JoinHandle<()>,
    /// The width output's last set-point as a ratio of the stroke, once the program confirmed it.
    gripper_ratio: Option<f64>,
}

impl UrRobot {
    /// Whether the controller's arm has a wrist force/torque sensor, from its software version:
    /// an e-Series (5 and later) has one at the flange; a CB3 (3.x) only estimates the TCP force
    /// from its joint currents, too coarse to tell a seat from a jam. `Err` says why not.
    pub fn force_sensor(&self) -> Result<(), String> {
        let v = self.rtde.controller_version();
        if v.major >= 5 {
            return Ok(());
        }
        Err(format!(
            "the controller runs software {}.{}.{}, a CB-series arm without the e-Series' flange \
             force/torque sensor (its actual_TCP_force is estimated from joint currents)",
            v.major, v.minor, v.bugfix
        ))
    }
}

impl Drop for UrRobot {
    fn drop(&mut self) {
        self.heartbeat.abort();
        // The heartbeat task's clone of the client may outlive this robot for a moment; the
        // link must not see the controller close meanwhile and warn of a failed link.
        self.rtde.close();
    }
}

fn link_error(e: ClientError) -> RobotError {
    RobotError::ConnectionLost {
        detail: e.to_string(),
    }
}

fn dashboard_error(e: DashboardError) -> RobotError {
    match e {
        DashboardError::Refused { command, reply } => RobotError::Rejected {
            detail: format!("dashboard {command:?}: {reply}"),
        },
        other => RobotError::ConnectionLost {
            detail: other.to_string(),
        },
    }
}

fn register(state: &OutputState, reg: usize) -> i32 {
    state
        .i64(&format!("output_int_register_{reg}"))
        .unwrap_or(0) as i32
}

/// The typed error for a state in which the arm must not (or cannot) move, if any.
fn blocking_error(state: &OutputState) -> Option<RobotError> {
    let bits = state.i64("safety_status_bits").unwrap_or(0) as u32;
    let safety = state.safety_mode();
    if bits & SAFETY_BIT_EMERGENCY_STOPPED != 0 {
        return Some(RobotError::EmergencyStop {
            safety: safety.unwrap_or(SafetyStatus::RobotEmergencyStop),
        });
    }
    if bits & SAFETY_BIT_PROTECTIVE_STOPPED != 0 {
        return Some(RobotError::ProtectiveStop);
    }
    if let Some(err) = safety.and_then(SafetyStatus::motion_error) {
        return Some(err);
    }
    let mode = state.robot_mode().unwrap_or(RobotMode::Disconnected);
    let running = state.runtime_state() == Some(RuntimeState::Playing);
    if mode != RobotMode::Running || !running {
        return Some(RobotError::NotReady {
            mode,
            program_running: running,
        });
    }
    None
}

/// Uploads a URScript program to the script port.
pub async fn upload_script(address: &str, script: &str, timeout: Duration) -> std::io::Result<()> {
    let io = async {
        let mut stream = TcpStream::connect(address).await?;
        stream.write_all(script.as_bytes()).await?;
        stream.shutdown().await
    };
    tokio::time::timeout(timeout, io)
        .await
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::TimedOut, "script upload"))?
}

impl UrRobot {
    /// Connects RTDE and the dashboard, uploads our program and waits until it runs. The robot
    /// comes wrapped in [`Limited`] with the configured limits and kinematics (the only way to
    /// get one), so no target reaches the controller unchecked.
    pub async fn connect(config: UrRobotConfig) -> Result<Limited<UrRobot>, RobotError> {
        let limits = config.limits.clone();
        let kinematics = config.kinematics.clone();
        // Checked before anything connects.
        limits.validate().map_err(|e| RobotError::Rejected {
            detail: e.to_string(),
        })?;
        config.validate().map_err(|e| RobotError::Rejected {
            detail: e.to_string(),
        })?;
        let outputs = output_names();
        let mut rtde_config =
            ClientConfig::new(format!("{}:{}", config.host, config.rtde_port), &[]);
        rtde_config.outputs = outputs;
        rtde_config.inputs = vec![
            L::command_recipe(),
            L::heartbeat_recipe(),
            L::force_limit_recipe(),
            L::blend_recipe(),
        ];
        rtde_config.stall_timeout = config.stall_timeout;
        rtde_config.backoff = Backoff::default();
        let rtde = Arc::new(RtdeClient::connect(rtde_config).await.map_err(link_error)?);
        let dashboard = DashboardClient::connect(
            &format!("{}:{}", config.host, config.dashboard_port),
            Duration::from_secs(2),
        )
        .await
        .map_err(dashboard_error)?;
        let heartbeat = {
            let rtde = rtde.clone();
            let period = config.heartbeat_period;
            tokio::spawn(async move {
                let mut beat = 0i32;
                let mut tick = tokio::time::interval(period);
                loop {
                    tick.tick().await;
                    beat = beat.wrapping_add(1);
                    // While the link is down the beat is simply missed; the watchdog decides.
                    let _ = rtde.send_inputs(1, &[Value::Int32(beat)]).await;
                }
            })
        };
        let mut robot = UrRobot {
            config,
            rtde,
            dashboard: Some(dashboard),
            next_id: 0,
            heartbeat,
            gripper_ratio: None,
        };
        robot.start_program().await?;
        Limited::new(robot, limits, kinematics).map_err(|e| RobotError::Rejected {
            detail: e.to_string(),
        })
    }

    /// The newest state, or a connection error when the link is down or no state has arrived.
    fn state(&self) -> Result<Arc<OutputState>, RobotError> {
        match self.rtde.status() {
            LinkStatus::Streaming => {}
            other => {
                return Err(RobotError::ConnectionLost {
                    detail: format!("RTDE link {other:?}"),
                });
            }
        }
        self.rtde.latest().ok_or(RobotError::ConnectionLost {
            detail: "no RTDE state received yet".into(),
        })
    }

    /// [`Self::state`] once the link streams: a link that is stalled or reconnecting gets
    /// [`UrRobotConfig::reconnect_grace`] to come back, and the state is then a package of the
    /// new connection, not the last one from before the silence.
    async fn live_state(&self) -> Result<Arc<OutputState>, RobotError> {
        let recovering =
            |s: &LinkStatus| matches!(s, LinkStatus::Stalled | LinkStatus::Reconnecting(_));
        if !recovering(&self.rtde.status()) {
            return self.state();
        }
        let grace = self.config.reconnect_grace;
        let deadline = Instant::now() + grace;
        let mut status = self.rtde.subscribe_status();
        let back = tokio::time::timeout(grace, async {
            while recovering(&status.borrow_and_update()) {
                if status.changed().await.is_err() {
                    return false;
                }
            }
            true
        })
        .await;
        if back != Ok(true) {
            return self.state();
        }
        let left = deadline.saturating_duration_since(Instant::now());
        match self.rtde.next_state(left).await {
            Ok(state) => self.state().map(|_| state),
            Err(_) => self.state(),
        }
    }

    async fn wait_state(
        &self,
        deadline: Instant,
        operation: &str,
    ) -> Result<Arc<OutputState>, RobotError> {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(RobotError::Timeout {
                operation: operation.into(),
                after: self.config.command_timeout,
            });
        }
        match self.rtde.next_state(left).await {
            Ok(s) => Ok(s),
            Err(ClientError::Timeout(_)) => {
                self.state()?;
                Err(RobotError::Timeout {
                    operation: operation.into(),
                    after: left,
                })
            }
            Err(e) => Err(link_error(e)),
        }
    }

    /// Uploads `cell.script` and waits until it runs and its beat advances.
    pub async fn start_program(&mut self) -> Result<(), RobotError> {
        let address = format!("{}:{}", self.config.host, self.config.script_port);
        upload_script(&address, program::CELL_SCRIPT, Duration::from_secs(2))
            .await
            .map_err(|e| RobotError::ConnectionLost {
                detail: format!("script port: {e}"),
            })?;
        let deadline = Instant::now() + self.config.program_start_timeout;
        let mut first_beat = None;
        loop {
            let state = match self.wait_state(deadline, "program start").await {
                Ok(s) => s,
                Err(RobotError::Timeout { .. }) => {
                    let state = self.state()?;
                    return Err(blocking_error(&state).unwrap_or(RobotError::Rejected {
                        detail: "program did not start".into(),
                    }));
                }
                Err(e) => return Err(e),
            };
            if state.runtime_state() != Some(RuntimeState::Playing) {
                continue;
            }
            let beat = register(&state, L::PROGRAM_BEAT_REG);
            match first_beat {
                None => first_beat = Some(beat),
                Some(b) if b != beat => {
                    self.next_id = self.next_id.max(register(&state, L::ACCEPTED_ID_REG));
                    return Ok(());
                }
                Some(_) => {}
            }
        }
    }

    /// Unlocks a protective stop through the dashboard and resumes the program.
    pub async fn unlock_protective_stop(&mut self) -> Result<(), RobotError> {
        let dashboard = self.dashboard.as_mut().ok_or(RobotError::ConnectionLost {
            detail: "no dashboard connection".into(),
        })?;
        dashboard
            .unlock_protective_stop()
            .await
            .map_err(dashboard_error)?;
        dashboard
            .close_safety_popup()
            .await
            .map_err(dashboard_error)?;
        let state = self
            .wait_state(Instant::now() + Duration::from_secs(1), "unlock")
            .await?;
        if state.runtime_state() == Some(RuntimeState::Paused) {
            let dashboard = self.dashboard.as_mut().ok_or(RobotError::ConnectionLost {
                detail: "no dashboard connection".into(),
            })?;
            dashboard.play().await.map_err(dashboard_error)?;
        }
        let deadline = Instant::now() + self.config.program_start_timeout;
        loop {
            let state = self
                .wait_state(deadline, "resume after protective stop")
                .await?;
            if blocking_error(&state).is_none() {
                return Ok(());
            }
        }
    }

    /// The dashboard connection, for power on, brake release and the like.
    pub fn dashboard(&mut self) -> Option<&mut DashboardClient> {
        self.dashboard.as_mut()
    }

    /// The RTDE client (newest state, link status).
    pub fn rtde(&self) -> &RtdeClient {
        &self.rtde
    }

    /// Sends one command and waits until the program reports it done.
    async fn run_command(&mut self, cmd: Command, operation: &str) -> Result<(), RobotError> {
        self.run_command_state(cmd, operation, &mut |_| {})
            .await
            .map(|_| ())
    }

    /// Sends one command and waits until the program reports it done; returns the state that
    /// reported it. `observe` sees every state received while the command runs, that one
    /// included.
    async fn run_command_state(
        &mut self,
        cmd: Command,
        operation: &str,
        observe: &mut (dyn FnMut(&OutputState) + Send),
    ) -> Result<Arc<OutputState>, RobotError> {
        let Command {
            kind,
            target,
            speed,
            accel,
            pin,
            level,
            wait,
        } = cmd;
        let state = self.live_state().await?;
        if let Some(e) = blocking_error(&state) {
            return Err(e);
        }
        self.next_id = self
            .next_id
            .max(register(&state, L::ACCEPTED_ID_REG))
            .wrapping_add(1)
            .max(1);
        let id = self.next_id;
        let mut values = vec![
            Value::Int32(kind),
            Value::Int32(pin),
            Value::Int32(i32::from(level)),
        ];
        values.extend(target.iter().map(|v| Value::Double(*v)));
        values.extend([
            Value::Double(speed),
            Value::Double(accel),
            Value::Double(wait),
            Value::Int32(id),
        ]);
        self.rtde
            .send_inputs(0, &values)
            .await
            .map_err(link_error)?;
        let deadline = Instant::now() + self.config.command_timeout;
        loop {
            let state = self.wait_state(deadline, operation).await?;
            if let Some(e) = blocking_error(&state) {
                return Err(e);
            }
            observe(&state);
            if register(&state, L::DONE_ID_REG) != id {
                continue;
            }
            let status = register(&state, L::STATUS_REG);
            if status != L::STATUS_FAILED {
                return Ok(state);
            }
            let detail = match register(&state, L::ERROR_REG) {
                L::ERROR_WATCHDOG => "program watchdog stopped the arm (heartbeat lost)",
                L::ERROR_UNKNOWN_COMMAND => "program did not understand the command",
                L::ERROR_STOPPED => "interrupted by a stop",
                L::ERROR_MOTION => "controller could not execute the motion",
                L::ERROR_INVALID_WAIT => "program refused the output wait",
                L::ERROR_INVALID_FORCE => "program refused the contact force limit",
                L::ERROR_INVALID_PATH => "program refused the path (order, length or radius)",
                L::ERROR_INVALID_OUTPUT => "program refused the analog output or its value",
                _ => "program reported an unknown error",
            };
            return Err(RobotError::Rejected {
                detail: format!("{operation}: {detail}"),
            });
        }
    }

    /// Sets the gripper's opening set-point to `width` (at most the stroke) on its analog
    /// output; the program waits the fingers' travel from the last set-point in proportion to
    /// the full stroke's actuation time (the whole time when it is not known).
    async fn set_gripper_width(
        &mut self,
        out: GripperWidthOutput,
        width: f64,
    ) -> Result<(), RobotError> {
        if !(width.is_finite() && width >= 0.0) {
            return Err(RobotError::Rejected {
                detail: format!("finger opening {width} m is not a width"),
            });
        }
        let ratio = (width / out.stroke).min(1.0);
        let travel = self.gripper_ratio.map_or(1.0, |r| (ratio - r).abs());
        let mut target = [0.0; 6];
        target[0] = ratio;
        let cmd = Command {
            kind: L::KIND_SET_STANDARD_AO,
            target,
            pin: i32::from(out.output),
            wait: self.config.gripper_actuation_s * travel,
            ..Command::default()
        };
        // Unknown until the program confirms: a failed command leaves the full wait next time.
        self.gripper_ratio = None;
        self.run_command(cmd, "gripper width").await?;
        self.gripper_ratio = Some(ratio);
        Ok(())
    }

    fn set_gripper(&mut self, close: bool) -> RobotFuture<'_, ()> {
        let level = close == self.config.gripper_close_level;
        let (kind, pin) = match self.config.gripper {
            GripperOutput::Tool(pin) => (L::KIND_SET_TOOL_DO, pin),
            GripperOutput::Standard(pin) => (L::KIND_SET_STANDARD_DO, pin),
        };
        Box::pin(async move {
            let cmd = Command {
                kind,
                pin: i32::from(pin),
                level,
                wait: self.config.gripper_actuation_s,
                ..Command::default()
            };
            self.run_command(cmd, "gripper").await
        })
    }
}

impl Robot for UrRobot {
    fn limits(&self) -> &Limits {
        &self.config.limits
    }

    fn joints(&mut self) -> RobotFuture<'_, Joints> {
        Box::pin(async move {
            self.live_state()
                .await?
                .vector6d("actual_q")
                .ok_or(RobotError::ConnectionLost {
                    detail: "actual_q missing".into(),
                })
        })
    }

    fn tcp_pose(&mut self) -> RobotFuture<'_, Isometry3<f64>> {
        Box::pin(async move {
            self.live_state()
                .await?
                .vector6d("actual_TCP_pose")
                .map(|p| from_ur_pose(&p))
                .ok_or(RobotError::ConnectionLost {
                    detail: "actual_TCP_pose missing".into(),
                })
        })
    }

    fn move_j(&mut self, target: Joints, motion: JointMotion) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            let cmd = Command {
                kind: L::KIND_MOVEJ,
                target,
                speed: motion.speed,
                accel: motion.acceleration,
                ..Command::default()
            };
            self.run_command(cmd, "move_j").await
        })
    }

    #[allow(non_snake_case)]
    fn move_l(&mut self, base_T_tcp: Isometry3<f64>, motion: LinearMotion) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            let from = self.joints().await?;
            self.config.kinematics.inverse_nearest(&base_T_tcp, &from)?;
            let cmd = Command {
                kind: L::KIND_MOVEL,
                target: to_ur_pose(&base_T_tcp),
                speed: motion.speed,
                accel: motion.acceleration,
                ..Command::default()
            };
            self.run_command(cmd, "move_l").await
        })
    }

    /// Sent through our program: each via-point as a `KIND_PATH_ADD_*` command (its blend radius
    /// in its register first), then `KIND_PATH_RUN`, which the program runs as one blended
    /// `movej`/`movel ..., r=` sequence and reports done at rest, as a single move.
    fn move_path(&mut self, path: Vec<Waypoint>) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            if path.is_empty() || path.len() > L::MAX_PATH_POINTS {
                return Err(RobotError::Rejected {
                    detail: format!(
                        "move_path: {} via-points (our program takes 1 to {})",
                        path.len(),
                        L::MAX_PATH_POINTS
                    ),
                });
            }
            let mut near = self.joints().await?;
            for (index, w) in path.iter().enumerate() {
                let (kind, target) = match w.target {
                    WaypointTarget::Joints(q) => {
                        near = q;
                        (L::KIND_PATH_ADD_MOVEJ, q)
                    }
                    WaypointTarget::Linear(pose) => {
                        near = self.config.kinematics.inverse_nearest(&pose, &near)?.joints;
                        (L::KIND_PATH_ADD_MOVEL, to_ur_pose(&pose))
                    }
                };
                self.rtde
                    .send_inputs(3, &[Value::Double(w.blend)])
                    .await
                    .map_err(link_error)?;
                let cmd = Command {
                    kind,
                    target,
                    speed: w.speed,
                    accel: w.acceleration,
                    pin: index as i32,
                    ..Command::default()
                };
                self.run_command(cmd, "move_path").await?;
            }
            let cmd = Command {
                kind: L::KIND_PATH_RUN,
                ..Command::default()
            };
            self.run_command(cmd, "move_path").await
        })
    }

    fn open_gripper(&mut self) -> RobotFuture<'_, ()> {
        match self.config.gripper_width {
            Some(out) => self.open_gripper_to(out.stroke),
            None => self.set_gripper(false),
        }
    }

    /// With a width output ([`UrRobotConfig::gripper_width`]) the set-point goes first, then the
    /// digital output opens the gripper (already open fingers move to the new set-point); without
    /// one the gripper opens the full stroke whatever the width.
    fn open_gripper_to(&mut self, width: f64) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            if let Some(out) = self.config.gripper_width {
                self.set_gripper_width(out, width).await?;
            }
            self.set_gripper(false).await
        })
    }

    fn close_gripper(&mut self) -> RobotFuture<'_, ()> {
        self.set_gripper(true)
    }

    fn stop(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            let state = self.live_state().await?;
            if blocking_error(&state).is_some() {
                // A safety stop already halted the arm, or no program moves it.
                return Ok(());
            }
            let cmd = Command {
                kind: L::KIND_STOP,
                ..Command::default()
            };
            self.run_command(cmd, "stop").await
        })
    }

    /// Sent as our program's guarded move: the force limit in its register first, then the
    /// command; the program stops the arm where `get_tcp_force` exceeds the limit against the
    /// motion and reports whether it did.
    #[allow(non_snake_case)]
    fn move_until_contact(
        &mut self,
        base_T_tcp: Isometry3<f64>,
        motion: LinearMotion,
        force_limit: f64,
    ) -> RobotFuture<'_, ContactOutcome> {
        Box::pin(async move {
            let from = self.joints().await?;
            self.config.kinematics.inverse_nearest(&base_T_tcp, &from)?;
            self.rtde
                .send_inputs(2, &[Value::Double(force_limit)])
                .await
                .map_err(link_error)?;
            let cmd = Command {
                kind: L::KIND_MOVE_UNTIL_CONTACT,
                target: to_ur_pose(&base_T_tcp),
                speed: motion.speed,
                accel: motion.acceleration,
                ..Command::default()
            };
            // The wrist's readings along the move, as the controller streamed them.
            let mut trace = Vec::new();
            let mut t0 = None;
            let state = self
                .run_command_state(cmd, "move_until_contact", &mut |s: &OutputState| {
                    if let (Some(t), Some(p), Some(w)) = (
                        s.f64("timestamp"),
                        s.vector6d("actual_TCP_pose"),
                        s.vector6d("actual_TCP_force"),
                    ) {
                        let t0 = *t0.get_or_insert(t);
                        trace.push(ContactSample {
                            t: t - t0,
                            tcp: [p[0], p[1], p[2]],
                            wrench: w,
                        });
                    }
                })
                .await?;
            let missing = |what: &str| RobotError::ConnectionLost {
                detail: format!("{what} missing"),
            };
            Ok(ContactOutcome {
                stopped_at: state
                    .vector6d("actual_TCP_pose")
                    .map(|p| from_ur_pose(&p))
                    .ok_or_else(|| missing("actual_TCP_pose"))?,
                wrench: state
                    .vector6d("actual_TCP_force")
                    .ok_or_else(|| missing("actual_TCP_force"))?,
                contact: register(&state, L::CONTACT_REG) == 1,
                trace,
            })
        })
    }

    fn wrench(&mut self) -> RobotFuture<'_, Wrench> {
        Box::pin(async move {
            self.live_state().await?.vector6d("actual_TCP_force").ok_or(
                RobotError::ConnectionLost {
                    detail: "actual_TCP_force missing".into(),
                },
            )
        })
    }

    fn status(&mut self) -> RobotFuture<'_, RobotStatus> {
        Box::pin(async move {
            let state = self.live_state().await?;
            // A code this crate does not know reads as the most conservative state.
            let mode = state.robot_mode().unwrap_or(RobotMode::Disconnected);
            let safety = state.safety_mode().unwrap_or(SafetyStatus::Fault);
            Ok(RobotStatus {
                mode,
                safety,
                program_running: state.runtime_state() == Some(RuntimeState::Playing),
            })
        })
    }
}
