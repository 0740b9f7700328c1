//! Production camera sources: where a production run's images come from, one image per capture.
//!
//! One trait ([`CameraSource`]) with one implementation per file:
//! - [`folder::FolderCamera`] (`folder:/path`, or a plain folder path): a folder that a vendor's
//!   grab tool (Basler pylon Viewer, a GenICam grabber, ...) writes into; a capture waits for a
//!   new, fully written image file.
//! - [`command::CommandCamera`] (`cmd:'grab --out {path}'`): runs a command per capture that
//!   writes the image to a fresh path.
//! - [`files::FilesCamera`] (`files:/dir`, or a plain image file path): replays recorded images in
//!   name order.
//! - `aravis::AravisCamera` (`aravis:` or `aravis:DEVICE`, cargo feature `aravis`): a GenICam
//!   camera through libaravis.
//!
//! Every source decodes and checks its image the same way ([`decode_file`], [`check_image`]):
//! PNG or TIFF, 8- or 16-bit, mono or colour, exactly the scenario camera's full sensor size.
//! Any failure is a [`CameraError`] naming the file, folder, command or camera; the orchestrator
//! then aborts the step before any motion, so nothing ever moves on an old or wrong picture.

pub mod command;
pub mod files;
pub mod folder;
mod spec;

#[cfg(feature = "aravis")]
pub mod aravis;

#[cfg(feature = "aravis")]
pub use aravis::AravisCamera;
pub use command::CommandCamera;
pub use files::FilesCamera;
pub use folder::FolderCamera;
pub use spec::{CameraSpec, open};

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use image::DynamicImage;
use perception::FrameImage;

/// How far a file's modification time may lie before the capture request and still count as
/// new: Linux stamps files with a coarse clock that lags the wall clock by up to a few ms.
pub const MTIME_SLACK: Duration = Duration::from_millis(50);

/// How often file-based sources look at the disk while they wait.
pub const POLL: Duration = Duration::from_millis(10);

/// The default capture timeout of a production run (`--capture-timeout`).
pub const DEFAULT_CAPTURE_TIMEOUT: Duration = Duration::from_secs(5);

/// Image file extensions the file-based sources pick up.
pub const IMAGE_EXTENSIONS: [&str; 3] = ["png", "tif", "tiff"];

/// One image delivered by a camera source.
#[derive(Debug, Clone, PartialEq)]
pub struct Capture {
    /// The pixels (the full sensor).
    pub image: FrameImage,
    /// The file the image was read from, if it came from one.
    pub path: Option<PathBuf>,
    /// When the image was taken (the file's modification time, or the grab's end).
    pub taken: SystemTime,
}

impl Capture {
    /// The frame perception reads: these pixels, seen by the scenario's calibrated `camera`.
    pub fn into_frame(self, camera: &sim::config::CameraSpec) -> perception::Frame {
        perception::Frame {
            camera: camera.intrinsics,
            base_T_camera: camera.base_T_camera.isometry(),
            content: perception::FrameContent::Image(self.image),
        }
    }
}

/// The size the images must have: the scenario camera's full sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sensor {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

impl Sensor {
    /// The full sensor of a calibrated camera.
    pub fn of(camera: &perception::Camera) -> Self {
        Self {
            width: camera.width,
            height: camera.height,
        }
    }
}

/// Why a camera source delivered no image; every variant names the source it is about.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// No image came within the capture deadline.
    #[error("{source_name}: no new image within {:.3} s", waited.as_secs_f64())]
    Timeout {
        /// The folder, command or camera.
        source_name: String,
        /// How long the capture waited.
        waited: Duration,
    },
    /// The only image that came was taken before the capture was asked for.
    #[error(
        "{}: stale image, written {:.3} s before the capture request (never used: the arm \
         must not move on an old picture)",
        path.display(),
        age.as_secs_f64()
    )]
    Stale {
        /// The image file.
        path: PathBuf,
        /// How long before the request it was written.
        age: Duration,
    },
    /// The image is not the size of the scenario camera's sensor.
    #[error(
        "{what}: the image is {got_width} × {got_height} pixels, but the scenario camera's sensor \
         is {expected_width} × {expected_height} (full-sensor images only)"
    )]
    WrongSize {
        /// The file or camera.
        what: String,
        /// Expected columns (the scenario's camera width).
        expected_width: u32,
        /// Expected rows (the scenario's camera height).
        expected_height: u32,
        /// Columns delivered.
        got_width: u32,
        /// Rows delivered.
        got_height: u32,
    },
    /// The file could not be read or decoded.
    #[error("{}: cannot read the image: {message}", path.display())]
    Unreadable {
        /// The image file.
        path: PathBuf,
        /// The reader's or decoder's message.
        message: String,
    },
    /// The image decodes, but its bit depth or colour type is not one the pipeline reads.
    #[error(
        "{what}: unsupported image format {format} (supported: 8- or 16-bit mono or RGB, PNG or \
         TIFF)"
    )]
    UnsupportedFormat {
        /// The file or camera.
        what: String,
        /// The format found.
        format: String,
    },
    /// The capture command exited with an error.
    #[error("command `{command}` failed ({status}){}", stderr_tail(stderr))]
    CommandFailed {
        /// The command as run.
        command: String,
        /// Its exit status, or what went wrong running it.
        status: String,
        /// The end of its standard error.
        stderr: String,
    },
    /// The capture command did not finish within the deadline and was killed.
    #[error(
        "command `{command}` did not finish within {:.3} s and was killed{}",
        waited.as_secs_f64(),
        stderr_tail(stderr)
    )]
    CommandHung {
        /// The command as run.
        command: String,
        /// How long it was given.
        waited: Duration,
        /// The end of its standard error.
        stderr: String,
    },
    /// The camera (or its folder) went away during the run.
    #[error("{source_name}: the camera is gone: {reason}")]
    Vanished {
        /// The folder or camera.
        source_name: String,
        /// What was seen.
        reason: String,
    },
    /// The folder or file does not exist.
    #[error("camera source {}: does not exist", path.display())]
    Missing {
        /// The path.
        path: PathBuf,
    },
    /// A replay source delivered every recorded image.
    #[error("{source_name}: every recorded image was used ({count} images)")]
    Exhausted {
        /// The replay source.
        source_name: String,
        /// How many images it held.
        count: usize,
    },
    /// The `--camera` specification or the source's set-up is invalid.
    #[error("camera source {spec:?}: {reason}")]
    Invalid {
        /// The specification as given.
        spec: String,
        /// What is wrong.
        reason: String,
    },
}

/// ": stderr: …" with the last lines of a command's standard error, or nothing when empty.
fn stderr_tail(stderr: &str) -> String {
    let s = stderr.trim();
    if s.is_empty() {
        String::new()
    } else {
        format!("; stderr: {s}")
    }
}

/// A camera that delivers one full-sensor image per capture.
pub trait CameraSource: Send {
    /// Waits up to `deadline` for one image taken after this call began.
    fn capture(&mut self, deadline: Duration) -> Result<Capture, CameraError>;
    /// The source in words, for logs and errors (`folder /data/grabs`).
    fn describe(&self) -> String;
}

/// Whether `path` has one of the [`IMAGE_EXTENSIONS`] (any case).
pub fn is_image_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Reads and decodes the image file at `path` (format from its content: PNG, TIFF) and checks
/// it with [`check_image`].
pub fn decode_file(path: &Path, sensor: Sensor) -> Result<DynamicImage, CameraError> {
    let unreadable = |message: String| CameraError::Unreadable {
        path: path.into(),
        message,
    };
    let reader = image::ImageReader::open(path)
        .map_err(|e| unreadable(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| unreadable(e.to_string()))?;
    if reader.format().is_none() {
        return Err(unreadable("not a PNG or TIFF file".into()));
    }
    let pixels = reader.decode().map_err(|e| match e {
        image::ImageError::Unsupported(u) => CameraError::UnsupportedFormat {
            what: path.display().to_string(),
            format: u.to_string(),
        },
        other => unreadable(other.to_string()),
    })?;
    check_image(pixels, sensor, &path.display().to_string())
}

/// Checks an image's format and size: 8- or 16-bit mono or colour (an alpha channel is
/// dropped), exactly `sensor`'s width × height; `what` names it in errors.
pub fn check_image(
    pixels: DynamicImage,
    sensor: Sensor,
    what: &str,
) -> Result<DynamicImage, CameraError> {
    let pixels = match pixels {
        p @ (DynamicImage::ImageLuma8(_)
        | DynamicImage::ImageLuma16(_)
        | DynamicImage::ImageRgb8(_)
        | DynamicImage::ImageRgb16(_)) => p,
        p @ DynamicImage::ImageLumaA8(_) => DynamicImage::ImageLuma8(p.to_luma8()),
        p @ DynamicImage::ImageLumaA16(_) => DynamicImage::ImageLuma16(p.to_luma16()),
        p @ DynamicImage::ImageRgba8(_) => DynamicImage::ImageRgb8(p.to_rgb8()),
        p @ DynamicImage::ImageRgba16(_) => DynamicImage::ImageRgb16(p.to_rgb16()),
        other => {
            return Err(CameraError::UnsupportedFormat {
                what: what.into(),
                format: format!("{:?}", other.color()),
            });
        }
    };
    if (pixels.width(), pixels.height()) != (sensor.width, sensor.height) {
        return Err(CameraError::WrongSize {
            what: what.into(),
            expected_width: sensor.width,
            expected_height: sensor.height,
            got_width: pixels.width(),
            got_height: pixels.height(),
        });
    }
    Ok(pixels)
}

/// A file's size and modification time, to tell when it stops changing.
pub(crate) fn file_stamp(path: &Path) -> Option<(u64, SystemTime)> {
    let m = std::fs::metadata(path).ok()?;
    Some((m.len(), m.modified().ok()?))
}

/// How long before `request` the time `t` lies (zero when it is not before).
pub(crate) fn age_before(t: SystemTime, request: SystemTime) -> Duration {
    request.duration_since(t).unwrap_or_default()
}
