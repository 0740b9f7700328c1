//! Why a PnP problem has no answer: the error of every PnP step (input checks, initial pose,
//! refinement), in its own file so those steps need nothing else of the solver.

use crate::CameraError;

/// Why a PnP problem has no answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PnpError {
    /// Fewer than four correspondences.
    #[error("PnP needs at least 4 points, got {0}")]
    TooFewPoints(usize),
    /// The model and image point lists (or covariances) differ in length.
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        /// Which list.
        what: &'static str,
        /// The number of model points.
        expected: usize,
        /// Its length.
        got: usize,
    },
    /// A coordinate or covariance entry is NaN or infinite.
    #[error("non-finite value in {0}")]
    NonFinite(&'static str),
    /// The model points are coincident or collinear: the pose is not determined.
    #[error("the model points are {0}: the pose is not determined")]
    DegenerateModel(&'static str),
    /// The image points are coincident or collinear.
    #[error("the image points are {0}: the pose is not determined")]
    DegenerateImage(&'static str),
    /// A keypoint covariance is not symmetric positive definite.
    #[error("covariance of point {0} is not positive definite")]
    BadCovariance(usize),
    /// A pixel could not be turned into a ray.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// The solver found no pose with every point in front of the camera.
    #[error("no pose found: {0}")]
    NoSolution(&'static str),
}
