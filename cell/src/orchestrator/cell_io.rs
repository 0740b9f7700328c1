//! The cell as the engine sees it: the arm ([`Robot`]) and the side channels besides it
//! ([`CellIo`]: camera, feeder, grasp and insertion checks, clock), reached through one
//! [`Workcell`]. Production implements [`CellIo`] with its camera source and sensors
//! (`ProductionCellIo`); the simulation harness (`crate::harness`) with the simulated cell.

use robots::robot::Robot;

use crate::episode::{PerceptionVerdict, PoseError, StepOutcome};
use perception::{DetectedPart, Frame};

/// Why a cell side channel failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CellIoError {
    /// The camera delivered no frame.
    #[error("camera: {0}")]
    Camera(String),
    /// The feeder could not shake.
    #[error("feeder: {0}")]
    Feeder(String),
}

/// What the cell says about an insertion after release.
#[derive(Debug, Clone, PartialEq)]
pub struct InsertionCheck {
    /// Seated, jammed or missed.
    pub outcome: StepOutcome,
    /// Why it was not seated.
    pub cause: Option<String>,
    /// Error sources blamed, by scenario parameter name.
    pub sources: Vec<String>,
    /// True pose error (simulation only).
    pub pose_error: Option<PoseError>,
    /// How far above fully seated the part stopped, metres: what the cell measures (arm height
    /// at the force threshold), and the slip of the part up the fingers when it was pushed.
    pub stop_height: Option<f64>,
}

/// A detection checked against the simulated world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerceptionAudit {
    /// Right, wrong part, wrong stable pose, or nothing there.
    pub verdict: PerceptionVerdict,
    /// Error of the estimate in the table plane against the part there (x, y mm; yaw °).
    pub table_error: Option<[f64; 3]>,
}

/// The camera, feeder and sensors of a cell.
pub trait CellIo: Send {
    /// Takes a camera frame.
    fn capture(&mut self) -> Result<Frame, CellIoError>;
    /// Takes a camera frame for a seat check: pixels that cover the fixture. A production
    /// camera delivers its full sensor, so this is [`CellIo::capture`]; the simulated cell
    /// renders the fixture window instead of the feeder's.
    fn capture_fixture(&mut self) -> Result<Frame, CellIoError> {
        self.capture()
    }
    /// Where the part placed by step `step` truly is, base frame (simulation only; for the
    /// seat check's measured error).
    fn placed_truth(&self, _step: usize) -> Option<nalgebra::Isometry3<f64>> {
        None
    }
    /// Starts a feeder shake so parts come to rest anew; the feeder runs on its own and the next
    /// [`CellIo::capture`] waits until the parts are at rest.
    fn shake_feeder(&mut self) -> Result<(), CellIoError>;
    /// Starts a feeder shake as [`CellIo::shake_feeder`], dated `t` on the cell's clock: an
    /// instant during the arm's last motion, from [`CellIo::last_motion_trace`]. A cell that
    /// ran that motion to its end before the engine regained control (the in-process
    /// simulation) starts the shake at that instant, as an engine watching the motion would
    /// have; any other cell starts it now.
    fn shake_feeder_at(&mut self, _t: f64) -> Result<(), CellIoError> {
        self.shake_feeder()
    }
    /// The arm's joints along its last motion, (cell clock, joints) at most `step` seconds
    /// apart from its start to its end, where the cell ran that motion to its end before the
    /// engine regained control (the in-process simulation: the planned trajectory as the cell
    /// timed it); `None` for a cell whose arm reports its joints as it moves (read them from
    /// the robot).
    fn last_motion_trace(&self, _step: f64) -> Option<Vec<(f64, robots::kinematics::Joints)>> {
        None
    }
    /// Whether a part is between the closed fingers; `None` when the cell has no grasp sensor
    /// (the grasp is then assumed to hold and the insertion check decides).
    fn part_in_gripper(&mut self) -> Option<bool>;
    /// The result of the insertion just released, if there was one.
    fn insertion_check(&mut self) -> Option<InsertionCheck>;
    /// Whether the part still in the fingers is seated, checked before the fingers open (by
    /// height and force in production); `None` when the cell cannot tell before release (the
    /// part is then released and [`CellIo::insertion_check`] decides, with no retry).
    fn seating_check(&mut self) -> Option<InsertionCheck> {
        None
    }
    /// Seconds on the cell's clock since the episode started (simulated time in simulation).
    fn clock(&self) -> f64;
    /// Lets the cell's clock run on to `t` while the engine waits for work off the arm's path
    /// (perception); the simulated cell advances its clock, a real cell's time passes anyway.
    fn wait_until(&mut self, _t: f64) {}
    /// Whether the feeder's parts are at rest now (no shake still settling); `None` when the
    /// cell cannot tell.
    fn feeder_at_rest(&self) -> Option<bool> {
        None
    }
    /// What the simulator knows of a detection (simulation only; for the error budget).
    fn audit(&self, _detection: &DetectedPart) -> Option<PerceptionAudit> {
        None
    }
    /// How many parts named `part` the camera sees that no detection matches (simulation only).
    fn missed(&self, _part: &str, _detections: &[DetectedPart]) -> Option<usize> {
        None
    }
}

/// One cell as the engine drives it: its arm and its side channels, lent one at a time.
///
/// The simulated cell is both at once (one object: the arm moves the world the camera sees);
/// a production cell is a robot client beside its camera and sensors ([`SplitCell`]).
pub trait Workcell: Send {
    /// The arm.
    fn robot(&mut self) -> &mut dyn Robot;
    /// The camera, feeder and sensors.
    fn io(&mut self) -> &mut dyn CellIo;
}

/// A cell whose arm and side channels are separate objects (a robot client and the cell's
/// camera and sensors).
pub struct SplitCell<'a> {
    /// The arm.
    pub robot: &'a mut dyn Robot,
    /// The camera, feeder and sensors.
    pub io: &'a mut dyn CellIo,
}

impl Workcell for SplitCell<'_> {
    fn robot(&mut self) -> &mut dyn Robot {
        self.robot
    }

    fn io(&mut self) -> &mut dyn CellIo {
        self.io
    }
}
