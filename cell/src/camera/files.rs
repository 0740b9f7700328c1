//! Replay of recorded images (`--camera files:/dir`, or a plain image file path): one image per
//! capture in name order, each checked for format and size like a live image. Recorded images
//! are old by nature, so there is no staleness check; the source ends when every image was
//! used (it never wraps around and shows an image twice).

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use perception::FrameImage;

use super::{CameraError, CameraSource, Capture, Sensor, decode_file, is_image_file};

/// Recorded images, delivered in name order.
#[derive(Debug)]
pub struct FilesCamera {
    root: PathBuf,
    files: Vec<PathBuf>,
    next: usize,
    sensor: Sensor,
}

impl FilesCamera {
    /// Lists the images at `path` (one image file, or every image in a folder); fails when
    /// there are none.
    pub fn open(path: &Path, sensor: Sensor) -> Result<Self, CameraError> {
        let invalid = |reason: String| CameraError::Invalid {
            spec: format!("files:{}", path.display()),
            reason,
        };
        let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => CameraError::Missing { path: path.into() },
            _ => CameraError::Unreadable {
                path: path.into(),
                message: e.to_string(),
            },
        })?;
        let mut files = if meta.is_dir() {
            std::fs::read_dir(path)
                .map_err(|e| CameraError::Unreadable {
                    path: path.into(),
                    message: e.to_string(),
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && is_image_file(p))
                .collect::<Vec<_>>()
        } else if is_image_file(path) {
            vec![path.to_path_buf()]
        } else {
            return Err(invalid(format!(
                "not an image file (expected one of {:?})",
                super::IMAGE_EXTENSIONS
            )));
        };
        files.sort();
        if files.is_empty() {
            return Err(invalid("no image files".into()));
        }
        Ok(Self {
            root: path.into(),
            files,
            next: 0,
            sensor,
        })
    }

    /// The images, in the order they are delivered.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }
}

impl CameraSource for FilesCamera {
    fn capture(&mut self, _deadline: Duration) -> Result<Capture, CameraError> {
        let path = self
            .files
            .get(self.next)
            .cloned()
            .ok_or_else(|| CameraError::Exhausted {
                source_name: self.describe(),
                count: self.files.len(),
            })?;
        self.next += 1;
        let pixels = decode_file(&path, self.sensor)?;
        let taken = std::fs::metadata(&path)
            .and_then(|m| m.modified())
            .unwrap_or_else(|_| SystemTime::now());
        Ok(Capture {
            image: FrameImage::full(pixels),
            path: Some(path),
            taken,
        })
    }

    fn describe(&self) -> String {
        format!("recorded images {}", self.root.display())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recorded_images_are_listed_in_order_and_empty_sources_refused() {
        let sensor = Sensor {
            width: 2,
            height: 1,
        };
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            FilesCamera::open(dir.path(), sensor),
            Err(CameraError::Invalid { .. })
        ));
        for name in ["b.png", "a.TIF", "notes.txt"] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        let s = FilesCamera::open(dir.path(), sensor).unwrap();
        let names: Vec<_> = s
            .files()
            .iter()
            .map(|p| p.file_name().unwrap().to_str().unwrap().to_string())
            .collect();
        assert_eq!(names, ["a.TIF", "b.png"]);
        assert!(matches!(
            FilesCamera::open(&dir.path().join("missing"), sensor),
            Err(CameraError::Missing { .. })
        ));
        assert!(matches!(
            FilesCamera::open(&dir.path().join("notes.txt"), sensor),
            Err(CameraError::Invalid { .. })
        ));
    }
}
