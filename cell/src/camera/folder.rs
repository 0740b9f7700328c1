//! A watched folder (`--camera folder:/path`): what Basler pylon's or any vendor's grab tool
//! writes into. A capture waits for an image file created or modified after the capture request
//! and fully written (its size and time unchanged across two polls, or renamed into place from a
//! temporary name that is not an image name); older files are never used.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use perception::FrameImage;

use super::{
    CameraError, CameraSource, Capture, MTIME_SLACK, POLL, Sensor, age_before, decode_file,
    file_stamp, is_image_file,
};

/// A folder a grab tool writes images into.
#[derive(Debug)]
pub struct FolderCamera {
    dir: PathBuf,
    sensor: Sensor,
}

/// Size and modification time of a file.
type Stamp = (u64, SystemTime);

impl FolderCamera {
    /// Watches `dir` for images of `sensor`'s size; fails when it is not an existing folder.
    pub fn open(dir: &Path, sensor: Sensor) -> Result<Self, CameraError> {
        match std::fs::metadata(dir) {
            Ok(m) if m.is_dir() => Ok(Self {
                dir: dir.into(),
                sensor,
            }),
            Ok(_) => Err(CameraError::Invalid {
                spec: format!("folder:{}", dir.display()),
                reason: "not a folder (use files:PATH to replay one image file)".into(),
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                Err(CameraError::Missing { path: dir.into() })
            }
            Err(e) => Err(CameraError::Unreadable {
                path: dir.into(),
                message: e.to_string(),
            }),
        }
    }

    /// The image files in the folder with their stamps; `Err` when the folder is gone.
    fn scan(&self) -> Result<HashMap<PathBuf, Stamp>, CameraError> {
        let entries = std::fs::read_dir(&self.dir).map_err(|e| CameraError::Vanished {
            source_name: self.describe(),
            reason: e.to_string(),
        })?;
        Ok(entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| is_image_file(p) && !hidden(p))
            .filter_map(|p| {
                let m = std::fs::metadata(&p).ok()?;
                m.is_file().then_some(())?;
                Some((p, (m.len(), m.modified().ok()?)))
            })
            .collect())
    }
}

/// Whether a file name starts with a dot (a grab tool's temporary file).
fn hidden(p: &Path) -> bool {
    p.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.starts_with('.'))
}

impl CameraSource for FolderCamera {
    fn capture(&mut self, deadline: Duration) -> Result<Capture, CameraError> {
        let start = Instant::now();
        let request = SystemTime::now();
        // Everything there now is older than the request and is never used.
        let before = self.scan()?;
        // Candidates seen last poll, with their stamp then: one unchanged across two polls is
        // fully written.
        let mut seen: HashMap<PathBuf, Stamp> = HashMap::new();
        let mut failed: HashMap<PathBuf, (Stamp, CameraError)> = HashMap::new();
        let mut stale: Option<CameraError> = None;
        loop {
            let now = self.scan()?;
            let mut ready: Vec<(PathBuf, Stamp)> = Vec::new();
            for (path, stamp) in &now {
                if before.get(path) == Some(stamp) {
                    continue;
                }
                let age = age_before(stamp.1, request);
                if age > MTIME_SLACK {
                    // A file moved in with an old time (mv, cp -p): an old picture.
                    stale = Some(CameraError::Stale {
                        path: path.clone(),
                        age,
                    });
                    continue;
                }
                if stamp.0 > 0
                    && seen.get(path) == Some(stamp)
                    && failed.get(path).is_none_or(|(s, _)| s != stamp)
                {
                    ready.push((path.clone(), *stamp));
                }
            }
            // The newest complete image is the most current picture.
            ready.sort_by(|a, b| b.1.1.cmp(&a.1.1).then_with(|| b.0.cmp(&a.0)));
            for (path, stamp) in ready {
                match decode_file(&path, self.sensor) {
                    Ok(pixels) => {
                        // It must not have changed while it was decoded.
                        if file_stamp(&path) == Some(stamp) {
                            return Ok(Capture {
                                image: FrameImage::full(pixels),
                                path: Some(path),
                                taken: stamp.1,
                            });
                        }
                    }
                    // A wrong size or format will not get better: report it at once.
                    Err(
                        e @ (CameraError::WrongSize { .. } | CameraError::UnsupportedFormat { .. }),
                    ) => return Err(e),
                    // A writer may have paused mid-file: try again if it changes.
                    Err(e) => {
                        failed.insert(path, (stamp, e));
                    }
                }
            }
            seen = now;
            let elapsed = start.elapsed();
            if elapsed >= deadline {
                return Err(failed
                    .into_values()
                    .map(|(_, e)| e)
                    .next()
                    .or(stale)
                    .unwrap_or(CameraError::Timeout {
                        source_name: self.describe(),
                        waited: deadline,
                    }));
            }
            std::thread::sleep(POLL.min(deadline - elapsed));
        }
    }

    fn describe(&self) -> String {
        format!("camera folder {}", self.dir.display())
    }
}
