//! UR arm descriptions (URDF) and kinematics, RTDE, the Robot trait and the virtual UR controller.
pub mod dashboard;
pub mod description;
pub mod kinematics;
pub mod limited;
pub mod limits;
pub mod motion;
pub mod observed;
pub mod program;
pub mod robot;
pub mod rtde;
pub mod ur_arm;
pub mod ur_robot;
pub mod virtual_ur;
