//! Finding the board in an image: tag detection by the reference AprilTag library and sub-pixel corners.
