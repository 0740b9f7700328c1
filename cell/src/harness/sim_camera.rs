//! The simulated cell as a production camera: each capture renders the feeder window, writes it
//! into a full-sensor TIFF file (black outside the window) as a grab tool would, and reads it
//! back through the same decoding and checks as every file-based camera source. A virtual-UR
//! run then sees its images exactly as production does: files on disk, full-sensor size.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime};

use image::{DynamicImage, GenericImage, ImageFormat};
use perception::{FrameContent, FrameImage};
use sim::cell::SimCell;

use crate::camera::{CameraError, CameraSource, Capture, Sensor, decode_file};
use crate::orchestrator::CellIo;

/// A camera source whose images the simulated cell renders into files.
pub struct SimulatedCamera {
    cell: Arc<Mutex<SimCell>>,
    sensor: Sensor,
    dir: tempfile::TempDir,
    captures: u64,
}

impl SimulatedCamera {
    /// A camera for the shared `cell`, writing its images into a fresh temporary folder.
    pub fn new(cell: Arc<Mutex<SimCell>>) -> Result<Self, CameraError> {
        let sensor = {
            let c = cell.lock().unwrap_or_else(|p| p.into_inner());
            Sensor::of(&c.model().spec.camera.intrinsics)
        };
        let dir = tempfile::Builder::new()
            .prefix("cell-sim-camera-")
            .tempdir()
            .map_err(|e| CameraError::Invalid {
                spec: "simulated camera".into(),
                reason: format!("cannot make its image folder: {e}"),
            })?;
        Ok(Self {
            cell,
            sensor,
            dir,
            captures: 0,
        })
    }

    /// The full-sensor image file of the next capture.
    fn next_path(&mut self) -> PathBuf {
        self.captures += 1;
        self.dir
            .path()
            .join(format!("capture-{:06}.tif", self.captures))
    }
}

impl CameraSource for SimulatedCamera {
    fn capture(&mut self, _deadline: Duration) -> Result<Capture, CameraError> {
        let requested = SystemTime::now();
        let fail = |reason: String| CameraError::Invalid {
            spec: "simulated camera".into(),
            reason,
        };
        let frame = self
            .cell
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .capture()
            .map_err(|e| fail(e.to_string()))?;
        let FrameContent::Image(window) = frame.content else {
            return Err(fail(
                "the scenario's perception reads no pixels (keypoint-noise mode)".into(),
            ));
        };
        let mut full =
            DynamicImage::new(self.sensor.width, self.sensor.height, window.pixels.color());
        full.copy_from(&window.pixels, window.origin[0], window.origin[1])
            .map_err(|e| fail(format!("the rendered window does not fit the sensor: {e}")))?;
        let path = self.next_path();
        let mut bytes = std::io::Cursor::new(Vec::new());
        full.write_to(&mut bytes, ImageFormat::Tiff)
            .map_err(|e| fail(format!("cannot encode the TIFF: {e}")))?;
        sim::fsutil::write_atomic(&path, bytes.get_ref()).map_err(|e| CameraError::Unreadable {
            path: path.clone(),
            message: format!("cannot write: {e}"),
        })?;
        let pixels = decode_file(&path, self.sensor);
        // Each image is read once; the folder goes with the camera.
        let _ = std::fs::remove_file(&path);
        Ok(Capture {
            image: FrameImage {
                pixels: pixels?,
                origin: [0, 0],
            },
            path: Some(path),
            taken: requested,
        })
    }

    fn describe(&self) -> String {
        format!("simulated camera {}", self.dir.path().display())
    }
}
