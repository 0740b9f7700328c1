//! `Observed<R, O>`: a [`Robot`] that passes every command on to `R` unchanged and shows each
//! command that acts on the arm or the gripper to an [`Observer`]: before it is passed on, and
//! after it completed without error. Test and calibration rigs use it to count motions or to
//! record what the arm did after each one, without writing out the whole trait again; a
//! decorator that changes what reaches the robot (such as [`crate::limited::Limited`]) is a
//! `Robot` of its own instead.
//!
//! Queries (`limits`, `joints`, `tcp_pose`, `status`, `wrench`) are passed on without a hook.
//! A plain closure `FnMut(&Command<'_>)` is an observer that sees each command before it is
//! passed on.

use nalgebra::Isometry3;

use crate::kinematics::Joints;
use crate::limits::Limits;
use crate::motion::{JointMotion, LinearMotion};
use crate::robot::{ContactOutcome, Robot, RobotError, RobotFuture, RobotStatus, Waypoint, Wrench};

/// A command an [`Observed`] robot passes on, as its [`Observer`] sees it: the arguments of
/// the [`Robot`] method of the same name.
#[derive(Clone, Copy, Debug, PartialEq)]
#[allow(non_snake_case)]
pub enum Command<'a> {
    /// [`Robot::move_j`].
    MoveJ {
        /// Target joint angles, rad.
        target: Joints,
        /// Speed and acceleration.
        motion: JointMotion,
    },
    /// [`Robot::move_l`].
    MoveL {
        /// Target `base_T_tcp`.
        base_T_tcp: Isometry3<f64>,
        /// Speed and acceleration.
        motion: LinearMotion,
    },
    /// [`Robot::move_path`].
    MovePath {
        /// The via-points.
        path: &'a [Waypoint],
    },
    /// [`Robot::move_until_contact`].
    MoveUntilContact {
        /// Target `base_T_tcp`.
        base_T_tcp: Isometry3<f64>,
        /// Speed and acceleration.
        motion: LinearMotion,
        /// Force against the motion that stops it, N.
        force_limit: f64,
    },
    /// [`Robot::open_gripper`].
    OpenGripper,
    /// [`Robot::open_gripper_to`].
    OpenGripperTo {
        /// Finger opening, metres.
        width: f64,
    },
    /// [`Robot::close_gripper`].
    CloseGripper,
    /// [`Robot::stop`].
    Stop,
}

impl Command<'_> {
    /// The [`Robot`] method's name: `move_j`, `move_l`, `move_path`, `move_until_contact`,
    /// `open_gripper`, `open_gripper_to`, `close_gripper` or `stop`.
    pub fn name(&self) -> &'static str {
        match self {
            Command::MoveJ { .. } => "move_j",
            Command::MoveL { .. } => "move_l",
            Command::MovePath { .. } => "move_path",
            Command::MoveUntilContact { .. } => "move_until_contact",
            Command::OpenGripper => "open_gripper",
            Command::OpenGripperTo { .. } => "open_gripper_to",
            Command::CloseGripper => "close_gripper",
            Command::Stop => "stop",
        }
    }

    /// True for a command that moves the arm (a joint, linear, blended or guarded move).
    pub fn moves_arm(&self) -> bool {
        matches!(
            self,
            Command::MoveJ { .. }
                | Command::MoveL { .. }
                | Command::MovePath { .. }
                | Command::MoveUntilContact { .. }
        )
    }

    /// True for a command that moves the fingers (opening or closing the gripper).
    pub fn moves_fingers(&self) -> bool {
        matches!(
            self,
            Command::OpenGripper | Command::OpenGripperTo { .. } | Command::CloseGripper
        )
    }
}

/// What an [`Observed`] robot shows its commands to. Both hooks do nothing unless implemented.
pub trait Observer<R: ?Sized>: Send {
    /// Called with the robot as it is before `command` is passed on to it (whether or not the
    /// command then succeeds).
    fn before(&mut self, robot: &R, command: &Command<'_>) {
        let _ = (robot, command);
    }

    /// Called after `command` completed without error, with the robot to query (`contact` is
    /// the guarded move's outcome for [`Command::MoveUntilContact`], `None` otherwise). An
    /// error here is the command's error.
    fn after<'a>(
        &'a mut self,
        robot: &'a mut R,
        command: &'a Command<'a>,
        contact: Option<&'a ContactOutcome>,
    ) -> RobotFuture<'a, ()> {
        let _ = (robot, command, contact);
        Box::pin(std::future::ready(Ok(())))
    }
}

/// A closure sees each command before it is passed on.
impl<R: ?Sized, F: FnMut(&Command<'_>) + Send> Observer<R> for F {
    fn before(&mut self, _robot: &R, command: &Command<'_>) {
        self(command)
    }
}

/// A robot whose commands an [`Observer`] sees; everything is passed on to `R` unchanged.
pub struct Observed<R, O> {
    robot: R,
    observer: O,
}

impl<R: Robot, O: Observer<R>> Observed<R, O> {
    /// `robot`, its commands shown to `observer`.
    pub fn new(robot: R, observer: O) -> Self {
        Observed { robot, observer }
    }

    /// The robot commands are passed on to.
    pub fn inner(&self) -> &R {
        &self.robot
    }

    /// The robot commands are passed on to, mutably (what is sent through it is not observed).
    pub fn inner_mut(&mut self) -> &mut R {
        &mut self.robot
    }

    /// The observer.
    pub fn observer(&self) -> &O {
        &self.observer
    }

    /// The observer, mutably.
    pub fn observer_mut(&mut self) -> &mut O {
        &mut self.observer
    }

    /// The robot and the observer.
    pub fn into_parts(self) -> (R, O) {
        (self.robot, self.observer)
    }
}

impl<R: Robot, O: Observer<R>> Observed<R, O> {
    /// Shows `command` to the observer, passes it on, and shows the observer its success.
    async fn pass_on(&mut self, command: Command<'_>) -> Result<(), RobotError> {
        self.observer.before(&self.robot, &command);
        send(&mut self.robot, &command).await?;
        self.observer.after(&mut self.robot, &command, None).await
    }
}

/// Sends `command` to `robot` (a guarded move's outcome is dropped).
fn send<'r, R: Robot>(robot: &'r mut R, command: &Command<'_>) -> RobotFuture<'r, ()> {
    match *command {
        Command::MoveJ { target, motion } => robot.move_j(target, motion),
        Command::MoveL { base_T_tcp, motion } => robot.move_l(base_T_tcp, motion),
        Command::MovePath { path } => robot.move_path(path.to_vec()),
        Command::MoveUntilContact {
            base_T_tcp,
            motion,
            force_limit,
        } => Box::pin(async move {
            robot
                .move_until_contact(base_T_tcp, motion, force_limit)
                .await
                .map(drop)
        }),
        Command::OpenGripper => robot.open_gripper(),
        Command::OpenGripperTo { width } => robot.open_gripper_to(width),
        Command::CloseGripper => robot.close_gripper(),
        Command::Stop => robot.stop(),
    }
}

impl<R: Robot, O: Observer<R>> Robot for Observed<R, O> {
    fn limits(&self) -> &Limits {
        self.robot.limits()
    }

    fn joints(&mut self) -> RobotFuture<'_, Joints> {
        self.robot.joints()
    }

    fn tcp_pose(&mut self) -> RobotFuture<'_, Isometry3<f64>> {
        self.robot.tcp_pose()
    }

    fn move_j(&mut self, target: Joints, motion: JointMotion) -> RobotFuture<'_, ()> {
        Box::pin(self.pass_on(Command::MoveJ { target, motion }))
    }

    #[allow(non_snake_case)]
    fn move_l(&mut self, base_T_tcp: Isometry3<f64>, motion: LinearMotion) -> RobotFuture<'_, ()> {
        Box::pin(self.pass_on(Command::MoveL { base_T_tcp, motion }))
    }

    /// The robot takes a copy of the path; the observer sees the via-points before and after.
    fn move_path(&mut self, path: Vec<Waypoint>) -> RobotFuture<'_, ()> {
        Box::pin(async move { self.pass_on(Command::MovePath { path: &path }).await })
    }

    fn open_gripper(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(self.pass_on(Command::OpenGripper))
    }

    fn open_gripper_to(&mut self, width: f64) -> RobotFuture<'_, ()> {
        Box::pin(self.pass_on(Command::OpenGripperTo { width }))
    }

    fn close_gripper(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(self.pass_on(Command::CloseGripper))
    }

    fn stop(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(self.pass_on(Command::Stop))
    }

    fn status(&mut self) -> RobotFuture<'_, RobotStatus> {
        self.robot.status()
    }

    #[allow(non_snake_case)]
    fn move_until_contact(
        &mut self,
        base_T_tcp: Isometry3<f64>,
        motion: LinearMotion,
        force_limit: f64,
    ) -> RobotFuture<'_, ContactOutcome> {
        Box::pin(async move {
            let command = Command::MoveUntilContact {
                base_T_tcp,
                motion,
                force_limit,
            };
            self.observer.before(&self.robot, &command);
            let outcome = self
                .robot
                .move_until_contact(base_T_tcp, motion, force_limit)
                .await?;
            self.observer
                .after(&mut self.robot, &command, Some(&outcome))
                .await?;
            Ok(outcome)
        })
    }

    fn wrench(&mut self) -> RobotFuture<'_, Wrench> {
        self.robot.wrench()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::UrKinematics;
    use crate::limited::Limited;
    use crate::ur_robot::{UrRobot, UrRobotConfig};
    use crate::virtual_ur::{VirtualUr, VirtualUrConfig};
    use nalgebra::Translation3;
    use std::f64::consts::FRAC_PI_2;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    const JOINT: JointMotion = JointMotion {
        speed: 2.0,
        acceleration: 4.0,
    };
    const LINEAR: LinearMotion = LinearMotion {
        speed: 0.25,
        acceleration: 1.2,
    };

    /// Notes each hook's command, and after each arm motion where the robot reads the TCP.
    #[derive(Default)]
    struct Log {
        lines: Vec<String>,
        reached: Vec<Isometry3<f64>>,
    }

    impl<R: Robot> Observer<R> for Log {
        fn before(&mut self, _robot: &R, command: &Command<'_>) {
            self.lines.push(format!("before {}", command.name()));
        }

        fn after<'a>(
            &'a mut self,
            robot: &'a mut R,
            command: &'a Command<'a>,
            contact: Option<&'a ContactOutcome>,
        ) -> RobotFuture<'a, ()> {
            Box::pin(async move {
                self.lines
                    .push(format!("after {} {}", command.name(), contact.is_some()));
                if command.moves_arm() {
                    self.reached.push(robot.tcp_pose().await?);
                }
                Ok(())
            })
        }
    }

    async fn connect(vur: &VirtualUr) -> Limited<UrRobot> {
        UrRobot::connect(UrRobotConfig {
            rtde_port: vur.rtde_addr().port(),
            dashboard_port: vur.dashboard_addr().port(),
            script_port: vur.script_addr().port(),
            command_timeout: Duration::from_secs(10),
            ..UrRobotConfig::new("127.0.0.1", UrKinematics::ur5e())
        })
        .await
        .unwrap()
    }

    // Against the virtual UR on free loopback ports: every command reaches the robot unchanged,
    // the observer sees each before it is passed on and after it succeeded (with the robot to
    // query), not after a refused one, and a closure counts commands.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn commands_pass_through_and_the_observer_sees_each_before_and_after() {
        let vur = VirtualUr::start(VirtualUrConfig::ephemeral())
            .await
            .unwrap();
        let mut robot = Observed::new(connect(&vur).await, Log::default());
        let kin = UrKinematics::ur5e();
        let q = [0.2, -1.4, 1.5, -1.7, -FRAC_PI_2, 0.3];
        robot.move_j(q, JOINT).await.unwrap();
        let start = kin.forward_tcp(&q);
        let target = Translation3::new(0.03, -0.04, -0.05) * start;
        robot.move_l(target, LINEAR).await.unwrap();
        let path = vec![
            Waypoint::joints(q, JOINT, 0.0),
            Waypoint::linear(target, LINEAR, 0.0),
        ];
        robot.move_path(path).await.unwrap();
        robot.close_gripper().await.unwrap();
        assert_eq!(vur.controller.snapshot().io.tool_do, 1);
        robot.open_gripper().await.unwrap();
        assert_eq!(vur.controller.snapshot().io.tool_do, 0);
        robot.stop().await.unwrap();
        // Refused by the limits below: seen before, never after.
        let below_table = Translation3::new(0.0, 0.0, -0.6) * target;
        assert!(matches!(
            robot.move_l(below_table, LINEAR).await,
            Err(RobotError::LimitViolation(_))
        ));
        let log = robot.observer();
        let expected: Vec<String> = [
            "before move_j",
            "after move_j false",
            "before move_l",
            "after move_l false",
            "before move_path",
            "after move_path false",
            "before close_gripper",
            "after close_gripper false",
            "before open_gripper",
            "after open_gripper false",
            "before stop",
            "after stop false",
            "before move_l",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(log.lines, expected);
        // The arm was where each motion put it when the observer read it.
        let ends = [start, target, target];
        assert_eq!(log.reached.len(), ends.len());
        for (reached, end) in log.reached.iter().zip(&ends) {
            let d = (reached.translation.vector - end.translation.vector).norm();
            assert!(d < 1e-6, "{d} m from the motion's end");
        }
        // Queries pass straight on, unobserved.
        let q_now = robot.joints().await.unwrap();
        assert!(kin.forward_tcp(&q_now).translation.vector.z > 0.0);
        assert!(robot.status().await.unwrap().ready());
        assert_eq!(robot.observer().lines.len(), expected.len());

        // A closure counts the arm's motions as they are passed on, refused or not.
        let (inner, _) = robot.into_parts();
        let moves = Arc::new(AtomicUsize::new(0));
        let counted = moves.clone();
        let mut robot = Observed::new(inner, move |c: &Command<'_>| {
            if c.moves_arm() {
                counted.fetch_add(1, Ordering::SeqCst);
            }
        });
        robot.move_j(q, JOINT).await.unwrap();
        robot.close_gripper().await.unwrap();
        assert!(robot.move_l(below_table, LINEAR).await.is_err());
        assert_eq!(moves.load(Ordering::SeqCst), 2);
    }
}
