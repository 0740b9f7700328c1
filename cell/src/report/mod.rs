//! Reports of a results set: `summary.json` (the [`Summary`](crate::run::Summary)) and a single
//! self-contained `report.html` with inline SVG plots.

pub mod html;
pub mod plots;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::episode::EpisodeRecord;
use crate::run::Summary;

pub use html::render_html;
pub use plots::PlotError;

/// Name of the JSON summary in a results folder.
pub const SUMMARY_FILE: &str = "summary.json";
/// Name of the HTML report in a results folder.
pub const REPORT_FILE: &str = "report.html";

/// Why a report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// A plot could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// The files a report wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReportFiles {
    /// `summary.json`.
    pub summary: PathBuf,
    /// `report.html`.
    pub html: PathBuf,
}

/// Writes `summary.json` and `report.html` for `records` into `dir`, atomically.
pub fn write_report(
    dir: &Path,
    summary: &Summary,
    records: &BTreeMap<u32, EpisodeRecord>,
) -> Result<ReportFiles, ReportError> {
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.join(name);
        sim::fsutil::write_atomic(&path, bytes)
            .map_err(|source| ReportError::Io {
                path: path.clone(),
                source,
            })
            .map(|()| path)
    };
    let mut json = serde_json::to_string_pretty(summary).expect("a summary serialises");
    json.push('\n');
    let summary_path = write(SUMMARY_FILE, json.as_bytes())?;
    let html = render_html(summary, records)?;
    let html_path = write(REPORT_FILE, html.as_bytes())?;
    Ok(ReportFiles {
        summary: summary_path,
        html: html_path,
    })
}
