//! Forward and analytic inverse kinematics of Universal Robots arms (parameters from the robot
//! description: [`crate::ur_arm::UrArm`]).
//!
//! Frames follow the controller's conventions: `base` is the controller base frame (ROS's
//! `base_link` is rotated 180° about z from it), `flange` is the tool flange (UR's tool0), and
//! `tcp` sits at a configurable `flange_T_tcp`. Joint angles are radians, lengths metres.
//!
//! The inverse kinematics is the closed form for arms whose joints 2–4 are parallel and whose
//! wrist axes meet pairwise: q1 from the wrist centre, q5 from q1, q6 from q1 and q5, then the
//! planar 3R problem for q2..q4. It returns every solution (up to 8) and flags the wrist, elbow
//! and shoulder singularities on each one instead of producing NaN.

mod angles;
mod dh;
mod ik;
mod jacobian;
mod joint_limits;
mod pose;
mod singularity;
mod ur;

pub use angles::{Joints, joint_distance, normalize_angle};
pub use dh::{DhRow, UrDh};
pub use ik::{IkError, IkSolution, IkSolutions, MAX_IK_SOLUTIONS};
pub use jacobian::{jacobian, manipulability};
pub use joint_limits::JointLimits;
pub use pose::{from_ur_pose, to_ur_pose};
pub use singularity::{Singularities, SingularityPolicy, SingularityThresholds};
pub use ur::UrKinematics;
