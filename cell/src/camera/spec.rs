//! Which camera a `--camera` specification names (`folder:`, `files:`, `cmd:`, `aravis:` or a
//! plain path), and opening it: the one place that knows every source.

use std::path::PathBuf;
use std::str::FromStr;

#[cfg(feature = "aravis")]
use super::aravis::AravisCamera;
use super::command::CommandCamera;
use super::files::FilesCamera;
use super::folder::FolderCamera;
use super::{CameraError, CameraSource, Sensor};

/// A `--camera` specification, parsed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CameraSpec {
    /// `folder:/path` or a plain folder path: wait for new image files there.
    Folder(PathBuf),
    /// `files:/path` or a plain image file path: replay recorded images in name order.
    Files(PathBuf),
    /// `cmd:COMMAND`: run the command once per capture; `{path}` is the image it must write.
    Command(String),
    /// `aravis:` or `aravis:DEVICE`: a GenICam camera through libaravis (the first one found
    /// when no device is named).
    Aravis(Option<String>),
}

impl FromStr for CameraSpec {
    type Err = CameraError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let invalid = |reason: &str| CameraError::Invalid {
            spec: s.into(),
            reason: reason.into(),
        };
        let nonempty = |rest: &str, what: &str| {
            if rest.trim().is_empty() {
                Err(invalid(&format!("{what} is empty")))
            } else {
                Ok(rest.to_string())
            }
        };
        if let Some(rest) = s.strip_prefix("folder:") {
            Ok(Self::Folder(nonempty(rest, "the folder")?.into()))
        } else if let Some(rest) = s.strip_prefix("files:") {
            Ok(Self::Files(nonempty(rest, "the replay path")?.into()))
        } else if let Some(rest) = s.strip_prefix("cmd:") {
            Ok(Self::Command(nonempty(rest, "the command")?))
        } else if let Some(rest) = s.strip_prefix("aravis:") {
            Ok(Self::Aravis((!rest.is_empty()).then(|| rest.to_string())))
        } else if s.trim().is_empty() {
            Err(invalid(
                "empty; use folder:/path, files:/path, cmd:'grab --out {path}' or aravis:[DEVICE]",
            ))
        } else {
            // A plain path: an image file is replayed; anything else is a watched folder (which
            // must exist when the source opens).
            let p = PathBuf::from(s);
            Ok(if p.is_file() {
                Self::Files(p)
            } else {
                Self::Folder(p)
            })
        }
    }
}

impl std::fmt::Display for CameraSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Folder(p) => write!(f, "folder:{}", p.display()),
            Self::Files(p) => write!(f, "files:{}", p.display()),
            Self::Command(c) => write!(f, "cmd:{c}"),
            Self::Aravis(d) => write!(f, "aravis:{}", d.as_deref().unwrap_or("")),
        }
    }
}

/// Opens the source `spec` names for images of `sensor`'s size, checking what can be checked
/// before a run starts (the folder exists, the command's program is found, the camera answers).
pub fn open(spec: &CameraSpec, sensor: Sensor) -> Result<Box<dyn CameraSource>, CameraError> {
    Ok(match spec {
        CameraSpec::Folder(p) => Box::new(FolderCamera::open(p, sensor)?),
        CameraSpec::Files(p) => Box::new(FilesCamera::open(p, sensor)?),
        CameraSpec::Command(c) => Box::new(CommandCamera::open(c, sensor)?),
        #[cfg(feature = "aravis")]
        CameraSpec::Aravis(d) => Box::new(AravisCamera::open(d.as_deref(), sensor)?),
        #[cfg(not(feature = "aravis"))]
        CameraSpec::Aravis(_) => {
            return Err(CameraError::Invalid {
                spec: spec.to_string(),
                reason: "this build has no GenICam support; rebuild with `cargo build -p cell \
                         --features aravis` (needs libaravis-dev >= 0.8.25)"
                    .into(),
            });
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_every_form() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a.png");
        std::fs::write(&file, b"x").unwrap();
        assert_eq!(
            "folder:/data/grabs".parse::<CameraSpec>().unwrap(),
            CameraSpec::Folder("/data/grabs".into())
        );
        assert_eq!(
            "files:/data/rec".parse::<CameraSpec>().unwrap(),
            CameraSpec::Files("/data/rec".into())
        );
        assert_eq!(
            "cmd:grab --out {path}".parse::<CameraSpec>().unwrap(),
            CameraSpec::Command("grab --out {path}".into())
        );
        assert_eq!(
            "aravis:".parse::<CameraSpec>().unwrap(),
            CameraSpec::Aravis(None)
        );
        assert_eq!(
            "aravis:Fake_1".parse::<CameraSpec>().unwrap(),
            CameraSpec::Aravis(Some("Fake_1".into()))
        );
        assert_eq!(
            dir.path().to_str().unwrap().parse::<CameraSpec>().unwrap(),
            CameraSpec::Folder(dir.path().into())
        );
        assert_eq!(
            file.to_str().unwrap().parse::<CameraSpec>().unwrap(),
            CameraSpec::Files(file.clone())
        );
        for bad in ["", "cmd:", "folder: ", "files:"] {
            let e = bad.parse::<CameraSpec>().unwrap_err();
            assert!(matches!(e, CameraError::Invalid { .. }), "{bad}: {e}");
        }
        let spec = CameraSpec::Command("grab {path}".into());
        assert_eq!(spec.to_string().parse::<CameraSpec>().unwrap(), spec);
    }

    #[cfg(not(feature = "aravis"))]
    #[test]
    fn aravis_needs_the_feature() {
        let e = open(
            &CameraSpec::Aravis(None),
            Sensor {
                width: 4,
                height: 4,
            },
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("--features aravis"), "{e}");
    }
}
