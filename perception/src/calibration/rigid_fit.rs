//! Touch points: the board in the robot base from TCP readings at marked board points.
