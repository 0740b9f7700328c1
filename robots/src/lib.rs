//! UR5e description and kinematics, RTDE, the Robot trait and the virtual UR controller.
pub mod kinematics;
pub mod rtde;
