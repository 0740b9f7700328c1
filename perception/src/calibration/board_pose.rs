//! The board's pose in the camera from one image: PnP over every tag corner, with covariance.
