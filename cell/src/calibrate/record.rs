//! Writing a calibration into its scenario file: `[cell] base_T_table`, `[cell.camera]
//! base_T_camera` and `[cell.calibration]` set with `toml_edit`, every other byte kept, the old
//! poses kept in a comment above the new ones, and the file replaced atomically only once the
//! new text loads as a scenario.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use nalgebra::{Isometry3, Matrix6};
use sim::config::{CalibrationMethod, CovarianceError, PoseCovariance};
use toml_edit::{Array, DocumentMut, InlineTable, Item, Table, Value};

use crate::scenario::{Scenario, ScenarioError};

/// What `cell calibrate` measured, ready to be written into a scenario.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct CalibrationRecord {
    /// The camera (OpenCV frame) in the robot base.
    pub base_T_camera: Isometry3<f64>,
    /// The table frame (the board's top face, z up) in the robot base.
    pub base_T_table: Isometry3<f64>,
    /// Covariance of `base_T_camera` (convention of [`PoseCovariance`]).
    pub camera_covariance: Matrix6<f64>,
    /// Covariance of `base_T_table` (convention of [`PoseCovariance`]).
    pub table_covariance: Matrix6<f64>,
    /// How the board was located in the base.
    pub method: CalibrationMethod,
    /// Reprojection RMS of the board's tag corners, pixels.
    pub rms_px: f64,
    /// Tags the board pose used.
    pub tags: u32,
    /// The board file (as the caller names it; written relative to the scenario when it lies
    /// in or under the scenario's folder); `None` for the seed's built-in board.
    pub board: Option<PathBuf>,
    /// When it was measured.
    pub date: SystemTime,
}

/// Why a calibration was not written; the scenario file is then unchanged.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The scenario file could not be read.
    #[error("cannot read the scenario {path}: {source}")]
    Read {
        /// The scenario file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The scenario file is not TOML.
    #[error(
        "{path}:{line}:{column}: not TOML, so the calibration cannot be written into it: {message}"
    )]
    NotToml {
        /// The scenario file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// The parser's message.
        message: String,
    },
    /// A table or key the calibration replaces is missing or of another kind.
    #[error(
        "{path}: `{key}` is missing or not a table; a scenario has `[cell]` with `base_T_table` and \
         `[cell.camera]` with `base_T_camera` (run `cell check` on it)"
    )]
    Layout {
        /// The scenario file.
        path: PathBuf,
        /// The key path.
        key: &'static str,
    },
    /// A measured covariance is unusable (so the measurement is wrong; nothing is written).
    #[error("the measured {which} covariance cannot be recorded: {source}")]
    Covariance {
        /// `camera` or `table`.
        which: &'static str,
        /// Why.
        source: CovarianceError,
    },
    /// A measured pose or figure is not finite.
    #[error("the measured {what} is not finite; nothing was written")]
    NonFinite {
        /// Which value.
        what: &'static str,
    },
    /// The scenario with the calibration written in would not load.
    #[error("the calibrated scenario would not load, so {path} was left as it was:\n{source}")]
    Invalid {
        /// The scenario file.
        path: PathBuf,
        /// The problems the new text has.
        source: ScenarioError,
    },
    /// The new file could not be written.
    #[error("cannot write {path} (the old file is intact): {source}")]
    Write {
        /// The scenario file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Writes `record` into the scenario file at `path`: the old file stays whole until the new
/// text, which must load as a scenario, replaces it atomically. Returns the scenario as loaded
/// from the new text.
pub fn write_calibration(path: &Path, record: &CalibrationRecord) -> Result<Scenario, RecordError> {
    let text = std::fs::read_to_string(path).map_err(|source| RecordError::Read {
        path: path.into(),
        source,
    })?;
    let new = calibrated_text(&text, path, record)?;
    let scenario = Scenario::parse(&new, path).map_err(|source| RecordError::Invalid {
        path: path.into(),
        source,
    })?;
    sim::fsutil::write_atomic(path, new.as_bytes()).map_err(|source| RecordError::Write {
        path: path.into(),
        source,
    })?;
    Ok(scenario)
}

/// The scenario text `text` (read from `path`, which relative board paths are made against)
/// with `record` written in; every line outside the replaced values and the calibration table is
/// kept byte for byte.
pub fn calibrated_text(
    text: &str,
    path: &Path,
    record: &CalibrationRecord,
) -> Result<String, RecordError> {
    let camera_covariance = covariance(&record.camera_covariance, "camera")?;
    let table_covariance = covariance(&record.table_covariance, "table")?;
    for (what, ok) in [
        ("base_T_camera", finite_pose(&record.base_T_camera)),
        ("base_T_table", finite_pose(&record.base_T_table)),
        (
            "reprojection RMS",
            record.rms_px.is_finite() && record.rms_px >= 0.0,
        ),
    ] {
        if !ok {
            return Err(RecordError::NonFinite { what });
        }
    }
    let mut doc: DocumentMut = text.parse().map_err(|e: toml_edit::TomlError| {
        let (line, column) = e
            .span()
            .map(|s| perception::part::line_column(text, s.start))
            .unwrap_or((1, 1));
        RecordError::NotToml {
            path: path.into(),
            line,
            column,
            message: e.message().trim().to_string(),
        }
    })?;
    let date = humantime::format_rfc3339_seconds(record.date).to_string();
    let layout = |key| RecordError::Layout {
        path: path.into(),
        key,
    };
    let cell = doc
        .get_mut("cell")
        .and_then(Item::as_table_mut)
        .ok_or_else(|| layout("cell"))?;
    replace_pose(cell, "base_T_table", &record.base_T_table, &date)
        .ok_or_else(|| layout("cell.base_T_table"))?;
    let camera = cell
        .get_mut("camera")
        .and_then(Item::as_table_mut)
        .ok_or_else(|| layout("cell.camera"))?;
    replace_pose(camera, "base_T_camera", &record.base_T_camera, &date)
        .ok_or_else(|| layout("cell.camera.base_T_camera"))?;

    let mut table = Table::new();
    table.insert("method", toml_edit::value(method_name(record.method)));
    table.insert("date", toml_edit::value(date.as_str()));
    table.insert("camera_covariance", matrix_item(&camera_covariance));
    table.insert("table_covariance", matrix_item(&table_covariance));
    table.insert("reprojection_rms_px", toml_edit::value(record.rms_px));
    table.insert("tags", toml_edit::value(i64::from(record.tags)));
    if let Some(board) = &record.board {
        let board = board_path(board, path);
        table.insert(
            "board",
            toml_edit::value(board.to_string_lossy().into_owned()),
        );
    }
    let before = match cell.get("calibration").and_then(Item::as_table) {
        Some(old) => {
            // Keep the table where it was and its leading comments, with its values replaced.
            table.set_position(old.position());
            old.decor().clone()
        }
        None => {
            let mut d = toml_edit::Decor::default();
            d.set_prefix(
                "\n# What `cell calibrate` measured: the covariances of base_T_camera and \
                 base_T_table\n# ([δt (m); δω (rad)], true pose = (exp(δω)·R, t + δt) in the \
                 base frame). The\n# simulated cell draws its camera calibration error from \
                 camera_covariance.\n",
            );
            d
        }
    };
    *table.decor_mut() = before;
    cell.insert("calibration", Item::Table(table));
    Ok(doc.to_string())
}

/// Replaces the pose `key` of `table` (an inline table or a standard one) with `pose`, the old
/// value kept in a comment above it. `None` when there is no such pose.
fn replace_pose(table: &mut Table, key: &str, pose: &Isometry3<f64>, date: &str) -> Option<()> {
    let item = table.get_mut(key)?;
    let old = match item {
        Item::Value(v @ Value::InlineTable(_)) => v.to_string(),
        Item::Table(t) => t.clone().into_inline_table().to_string(),
        _ => return None,
    };
    let note = format!(
        "# before cell calibrate on {date}: {key} = {}\n",
        old.trim()
    );
    let new = pose_table(pose);
    match item {
        Item::Value(v) => {
            let decor = v.decor().clone();
            let mut n = Value::InlineTable(new);
            *n.decor_mut() = decor;
            *v = n;
            let mut k = table.key_mut(key)?;
            let prefix = k
                .leaf_decor()
                .prefix()
                .and_then(|p| p.as_str())
                .unwrap_or("")
                .to_string();
            k.leaf_decor_mut().set_prefix(format!("{prefix}{note}"));
        }
        Item::Table(t) => {
            for (name, v) in new.iter() {
                t.insert(name, toml_edit::value(v.clone()));
            }
            let prefix = t
                .decor()
                .prefix()
                .and_then(|p| p.as_str())
                .unwrap_or("")
                .to_string();
            t.decor_mut().set_prefix(format!("{prefix}{note}"));
        }
        _ => return None,
    }
    Some(())
}

/// `{ translation = [x, y, z], rotation = [rx, ry, rz] }`, the scenario's pose form (rotation
/// vector, radians), with numbers written to round-trip exactly.
fn pose_table(pose: &Isometry3<f64>) -> InlineTable {
    let t = pose.translation.vector;
    let r = pose.rotation.scaled_axis();
    let mut table = InlineTable::new();
    table.insert("translation", Value::Array(numbers(&[t.x, t.y, t.z])));
    table.insert("rotation", Value::Array(numbers(&[r.x, r.y, r.z])));
    table.fmt();
    table
}

/// An array of these numbers, written shortest-exact (`{}`, which always reads back the same
/// f64).
fn numbers(values: &[f64]) -> Array {
    let mut a: Array = values.iter().map(|v| Value::from(*v)).collect();
    a.fmt();
    a
}

/// A covariance as 6 rows of 6, one row a line, numbers in shortest-exact exponent form (zeros
/// as `0.0`).
fn matrix_item(c: &PoseCovariance) -> Item {
    let m = c.matrix();
    let mut rows = Array::new();
    for r in 0..6 {
        let mut row = Array::new();
        for col in 0..6 {
            let v = m[(r, col)];
            let text = if v == 0.0 {
                "0.0".to_string()
            } else {
                format!("{v:e}")
            };
            let mut v: Value = text.parse().expect("Rust's exponent form is a TOML float");
            v.decor_mut().set_prefix(if col == 0 { "" } else { " " });
            row.push_formatted(v);
        }
        let mut row = Value::Array(row);
        row.decor_mut().set_prefix("\n    ");
        rows.push_formatted(row);
    }
    rows.set_trailing_comma(true);
    rows.set_trailing("\n");
    toml_edit::value(rows)
}

fn covariance(m: &Matrix6<f64>, which: &'static str) -> Result<PoseCovariance, RecordError> {
    PoseCovariance::new(*m).map_err(|source| RecordError::Covariance { which, source })
}

fn finite_pose(p: &Isometry3<f64>) -> bool {
    p.translation.vector.iter().all(|v| v.is_finite())
        && p.rotation.coords.iter().all(|v| v.is_finite())
}

fn method_name(m: CalibrationMethod) -> &'static str {
    match m {
        CalibrationMethod::Touch => "touch",
        CalibrationMethod::HandEye => "hand-eye",
    }
}

/// `board` as the scenario at `scenario` should name it: relative to the scenario's folder when
/// it lies in or under it (as written, or once links are resolved), else absolute.
fn board_path(board: &Path, scenario: &Path) -> PathBuf {
    let dir = scenario.parent().unwrap_or(Path::new("."));
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let (b, d) = (absolute(board), absolute(dir));
    if let Ok(rel) = b.strip_prefix(&d) {
        return rel.to_path_buf();
    }
    match (board.canonicalize(), dir.canonicalize()) {
        (Ok(b), Ok(d)) => b.strip_prefix(&d).map(Path::to_path_buf).unwrap_or(b),
        _ => b,
    }
}

#[cfg(test)]
#[allow(non_snake_case)]
mod tests {
    use std::time::Duration;

    use nalgebra::{Translation3, UnitQuaternion, Vector3, Vector6};

    use super::*;

    /// A temporary folder holding a copy of the nominal scenario (`scenario.toml`) beside links to
    /// the files it names, so it loads; the repository's scenarios are never written.
    fn copied_scenario() -> (tempfile::TempDir, PathBuf) {
        let scenarios = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let dir = tempfile::tempdir().unwrap();
        for sub in ["robots", "parts", "boards"] {
            std::os::unix::fs::symlink(scenarios.join(sub), dir.path().join(sub)).unwrap();
        }
        let path = dir.path().join("scenario.toml");
        std::fs::copy(scenarios.join("usbc_nominal.toml"), &path).unwrap();
        (dir, path)
    }

    fn covariance(sigmas: [f64; 6], coupling: f64) -> Matrix6<f64> {
        let s = Matrix6::from_diagonal(&Vector6::from(sigmas));
        let mut corr = Matrix6::identity();
        corr[(1, 3)] = coupling;
        corr[(3, 1)] = coupling;
        s * corr * s
    }

    fn record(board: PathBuf) -> CalibrationRecord {
        let board = Some(board);
        CalibrationRecord {
            base_T_camera: Isometry3::from_parts(
                Translation3::new(0.000_123_456_789, -0.450_987_654_321, 1.512_345_678_9),
                UnitQuaternion::from_scaled_axis(Vector3::new(3.1, 0.001_234, -0.000_567)),
            ),
            base_T_table: Isometry3::from_parts(
                Translation3::new(0.000_21, -0.449_87, 0.000_033),
                UnitQuaternion::from_scaled_axis(Vector3::new(0.000_1, -0.000_2, 0.003)),
            ),
            camera_covariance: covariance([9e-6, 8e-6, 3e-5, 1.4e-5, 1.5e-5, 6e-6], -0.8),
            table_covariance: covariance([1.1e-5, 1.2e-5, 9e-6, 4e-5, 4e-5, 7e-5], 0.3),
            method: CalibrationMethod::Touch,
            rms_px: 0.047,
            tags: 16,
            board,
            date: SystemTime::UNIX_EPOCH + Duration::from_secs(1_795_838_400),
        }
    }

    #[test]
    fn the_written_scenario_loads_with_the_measured_poses_and_keeps_every_other_line() {
        let (dir, path) = copied_scenario();
        let before = std::fs::read_to_string(&path).unwrap();
        let r = record(dir.path().join("boards/seed.toml"));
        let scenario = write_calibration(&path, &r).unwrap_or_else(|e| panic!("{e}"));
        let after = std::fs::read_to_string(&path).unwrap();

        // The poses round-trip through the file.
        let reloaded = Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(reloaded.spec, scenario.spec);
        let cell = &reloaded.spec.cell;
        for (written, read) in [
            (r.base_T_camera, cell.camera.base_T_camera.isometry()),
            (r.base_T_table, cell.base_T_table.isometry()),
        ] {
            let dt = (written.translation.vector - read.translation.vector).amax();
            let dr = written.rotation.angle_to(&read.rotation);
            assert!(
                dt < 1e-12 && dr < 1e-12,
                "moved {dt:e} m, turned {dr:e} rad"
            );
        }
        let c = cell.calibration.as_ref().expect("[cell.calibration]");
        assert_eq!(c.method, CalibrationMethod::Touch);
        assert_eq!(c.date, "2026-11-28T04:00:00Z");
        assert_eq!((c.tags, c.reprojection_rms_px), (16, 0.047));
        assert_eq!(c.board.as_deref(), Some(Path::new("boards/seed.toml")));
        // The covariances read back exactly (as the symmetric matrices they were rounded to).
        let symmetric = |m: Matrix6<f64>| (m + m.transpose()) / 2.0;
        assert_eq!(
            *c.camera_covariance.matrix(),
            symmetric(r.camera_covariance)
        );
        assert_eq!(*c.table_covariance.matrix(), symmetric(r.table_covariance));

        // Outside the two pose lines, the comments above them and the new table, every line of
        // the old file is there byte for byte and in order.
        let old_table =
            "base_T_table = { translation = [0.0, -0.45, 0.0], rotation = [0.0, 0.0, 0.0] }";
        let old_camera = "base_T_camera = { translation = [0.0, -0.45, 1.51], rotation = [3.141592653589793, 0.0, 0.0] }";
        let kept: Vec<&str> = before
            .lines()
            .filter(|l| *l != old_table && *l != old_camera)
            .collect();
        let calibration_lines = after
            .lines()
            .skip_while(|l| *l != "[cell.calibration]")
            .take_while(|l| !l.is_empty() && *l != "[parts]")
            .count();
        let mut rest: Vec<&str> = Vec::new();
        let mut in_calibration = false;
        for l in after.lines() {
            in_calibration = match l {
                "[cell.calibration]" => true,
                _ if l.starts_with('[') => false,
                _ => in_calibration,
            };
            let new_pose = l.starts_with("base_T_table = ") || l.starts_with("base_T_camera = ");
            if !in_calibration && !new_pose && !l.starts_with("# before cell calibrate on") {
                rest.push(l);
            }
        }
        // What is left of the new file is the old file plus the calibration table's leading
        // comment (four lines) before its header.
        let comment: Vec<&str> = rest.iter().copied().filter(|l| !kept.contains(l)).collect();
        assert_eq!(comment.len(), 3, "{comment:?}");
        assert!(comment.iter().all(|l| l.starts_with("# ")), "{comment:?}");
        let without: Vec<&str> = rest.into_iter().filter(|l| kept.contains(l)).collect();
        assert_eq!(without, kept);
        assert!(
            calibration_lines > 8,
            "the table is written, covariances over lines"
        );

        // The old values are in a comment just above the new ones.
        for (old, key) in [(old_table, "base_T_table"), (old_camera, "base_T_camera")] {
            let lines: Vec<&str> = after.lines().collect();
            let at = lines
                .iter()
                .position(|l| l.starts_with(&format!("{key} = ")))
                .unwrap();
            assert_eq!(
                lines[at - 1],
                format!("# before cell calibrate on 2026-11-28T04:00:00Z: {old}")
            );
        }
    }

    #[test]
    fn a_second_calibration_replaces_the_table_and_keeps_both_old_values() {
        let (dir, path) = copied_scenario();
        let first = record(dir.path().join("boards/seed.toml"));
        write_calibration(&path, &first).unwrap();
        let mut second = first.clone();
        second.base_T_table.translation.x += 1e-4;
        second.method = CalibrationMethod::HandEye;
        second.date += Duration::from_secs(86_400);
        let s = write_calibration(&path, &second).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.matches("[cell.calibration]").count(), 1);
        assert_eq!(text.matches("# before cell calibrate on").count(), 4);
        assert!(text.contains("# before cell calibrate on 2026-11-29T04:00:00Z: base_T_table = { translation = [0.00021, "));
        let c = s.spec.cell.calibration.unwrap();
        assert_eq!(
            (c.method, c.date.as_str()),
            (CalibrationMethod::HandEye, "2026-11-29T04:00:00Z")
        );
    }

    #[test]
    fn a_refused_calibration_leaves_the_scenario_untouched() {
        let (dir, path) = copied_scenario();
        let before = std::fs::read(&path).unwrap();
        let board = dir.path().join("boards/seed.toml");

        let mut not_pd = record(board.clone());
        not_pd.camera_covariance[(5, 5)] = -1e-12;
        let e = write_calibration(&path, &not_pd).unwrap_err().to_string();
        assert!(
            e.contains("camera covariance") && e.contains("positive definite"),
            "{e}"
        );

        let mut nan = record(board.clone());
        nan.base_T_table.translation.y = f64::NAN;
        let e = write_calibration(&path, &nan).unwrap_err().to_string();
        assert!(e.contains("base_T_table is not finite"), "{e}");

        // A new text that does not load (here: the scenario names a board file that is gone)
        // is refused by the scenario's own checks, naming the problem.
        let text = std::fs::read_to_string(&path).unwrap().replacen(
            "robot = \"robots/ur5e.urdf\"\n",
            "robot = \"robots/ur5e.urdf\"\nboard = \"boards/gone.toml\"\n",
            1,
        );
        std::fs::write(&path, &text).unwrap();
        let e = write_calibration(&path, &record(board))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("would not load") && e.contains("gone.toml"),
            "{e}"
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), text);

        std::fs::write(&path, &before).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), before);
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .filter(|n| n.ends_with(".tmp"))
            .collect();
        assert!(names.is_empty(), "no temporary left behind: {names:?}");
    }

    #[test]
    fn a_recorded_covariance_spoiled_by_hand_is_refused_at_its_line_and_column() {
        let (dir, path) = copied_scenario();
        write_calibration(&path, &record(dir.path().join("boards/seed.toml"))).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        // Make the camera covariance's first variance negative: no longer positive definite.
        let at = text.find("camera_covariance = [\n    [8.1e-11").unwrap();
        let spoiled = text.replacen("[8.1e-11", "[-8.1e-11", 1);
        let e = Scenario::parse(&spoiled, &path).unwrap_err();
        let p = &e.0[0];
        let line = text[..at].matches('\n').count() + 1;
        assert_eq!((p.line, p.column), (line, 21), "{e}");
        assert!(p.message.contains("not positive definite"), "{e}");
    }
}
