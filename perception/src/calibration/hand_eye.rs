//! Hand-eye calibration: the camera in the robot base from board views at several arm poses (AX = XB).
