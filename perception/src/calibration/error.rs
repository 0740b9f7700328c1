//! Why a board or a calibration was refused.

use std::path::PathBuf;

/// A board description that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum BoardError {
    /// The board file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The board file is malformed or describes an impossible board.
    #[error("{}:{line}:{column}: {message}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A description that cannot be printed or detected.
    #[error("board `{key}`: {message}")]
    Invalid {
        /// The offending key.
        key: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A family the reference library does not define.
    #[error(
        "unknown tag family `{0}` (known: tag36h11, tag25h9, tag16h5, tagStandard41h12, tagStandard52h13)"
    )]
    UnknownFamily(String),
}

impl BoardError {
    /// The board file's key an error is about, if any.
    pub fn key(&self) -> Option<&'static str> {
        match self {
            Self::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }
}

/// Why a calibration could not be made, or was refused. Each names the cause and what to do.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// No tag of the board was found in the image.
    #[error(
        "no tag of the board ({family}, ids {first}–{last}) in view: is the board in the camera's field and lit?"
    )]
    NoBoard {
        /// The board's family.
        family: String,
        /// Its first id.
        first: u32,
        /// Its last id.
        last: u32,
    },
    /// Too few tags were decoded for a trustworthy pose.
    #[error(
        "only {found} of the board's {total} tags decoded ({need} needed): the board is partly hidden, out of view or badly lit"
    )]
    TooFewTags {
        /// Tags decoded.
        found: usize,
        /// Tags needed.
        need: usize,
        /// Tags on the board.
        total: usize,
    },
    /// A decoded tag id is not on the board: another board, or the wrong board file.
    #[error(
        "tag id {ids:?} decoded in the image is not on the board (ids {first}–{last}): a second board in view, or the wrong board file"
    )]
    ForeignTag {
        /// The ids not on the board.
        ids: Vec<u32>,
        /// The board's first id.
        first: u32,
        /// Its last id.
        last: u32,
    },
    /// The board is seen too obliquely for the pose to be trusted.
    #[error(
        "the board is seen {angle_deg:.1}° off the optical axis (at most {max_deg:.0}°): put the board flatter to the camera"
    )]
    TooOblique {
        /// Angle between the board's normal and the line of sight, degrees.
        angle_deg: f64,
        /// The allowed maximum.
        max_deg: f64,
    },
    /// The image's size is not the calibrated camera's sensor.
    #[error(
        "the image is {got_w} × {got_h} px but the camera's calibration is for {want_w} × {want_h} px: wrong camera, binning or ROI"
    )]
    Resolution {
        /// Image columns.
        got_w: u32,
        /// Image rows.
        got_h: u32,
        /// Calibrated columns.
        want_w: u32,
        /// Calibrated rows.
        want_h: u32,
    },
    /// Touch points that no rigid transform fits: a point touched in the wrong place.
    #[error(
        "touch point {worst} ({name}) is {residual_mm:.3} mm from where the others put it (at most {bound_mm:.3} mm): touch it again"
    )]
    TouchPointsDontFit {
        /// Index of the worst point (from 1).
        worst: usize,
        /// Its mark on the board.
        name: String,
        /// Its residual, mm.
        residual_mm: f64,
        /// The bound, mm.
        bound_mm: f64,
    },
    /// Too few touch points.
    #[error("{got} touch points; a rigid fit needs at least {need} marks, not all on one line")]
    TooFewTouchPoints {
        /// Points given.
        got: usize,
        /// Points needed.
        need: usize,
    },
    /// A hand-eye pose set that does not determine the transform.
    #[error("the hand-eye poses are degenerate: {missing}; add poses that rotate about it")]
    DegenerateHandEye {
        /// The rotation axes the set lacks.
        missing: String,
    },
    /// The pose solve failed.
    #[error("board pose: {0}")]
    Pnp(#[from] crate::pnp::PnpError),
    /// The reference detector could not be set up or run on the image.
    #[error("tag detector: {0}: check the board's family and the image")]
    Detector(String),
    /// The board's white print clips at full scale around the tag borders: the edges, and so
    /// the pose, would be biased.
    #[error(
        "{percent:.1} % of the pixels around the tag borders are saturated (at most {max_percent:.1} %): lower the exposure or the light"
    )]
    Overexposed {
        /// Share of saturated pixels around the borders, percent.
        percent: f64,
        /// The allowed share, percent.
        max_percent: f64,
    },
    /// A touch point with a NaN or infinite coordinate: a bad robot reading or board mark.
    #[error("touch point {index} ({name}) has a non-finite coordinate: read the robot's TCP again")]
    NonFiniteTouchPoint {
        /// Its index (from 1).
        index: usize,
        /// Its mark on the board.
        name: String,
    },
    /// A hand-eye view that cannot be used: a non-finite reading or a covariance that is not
    /// positive definite.
    #[error("hand-eye view {index}: {what}: measure that pose again")]
    BadHandEyeView {
        /// Its index (from 1).
        index: usize,
        /// What is wrong.
        what: String,
    },
}
