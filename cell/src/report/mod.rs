//! Reports of a results set: `summary.json` (the [`crate::run::Summary`]), a small
//! `report.html`, its plots as SVG files in `plots/`, linking each failed episode's event log
//! (`events/`) and pictures (`pictures/`) where they exist.

pub mod capture_picture;
pub mod escape;
pub mod force;
pub mod html;
pub mod pictures;
pub mod plots;
pub mod seat;
pub mod timeline;
pub mod wrench;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::episode::EpisodeRecord;
use crate::run::Summary;

pub use html::{EpisodeLinks, Opening, Page, render_html};
pub use plots::PlotError;

/// Name of the JSON summary in a results folder.
pub const SUMMARY_FILE: &str = "summary.json";
/// Name of the HTML report in a results folder.
pub const REPORT_FILE: &str = "report.html";
/// Folder of an episode's event logs in a results folder.
pub const EVENTS_DIR: &str = "events";
/// Folder of the failure pictures in a results folder.
pub const PICTURES_DIR: &str = "pictures";

/// The event log file name of an episode.
pub fn events_file(episode: u32) -> String {
    format!("episode-{episode:06}.jsonl")
}

/// What exists for each of `episodes` under `dir` (or, for a merged report, in the shard
/// folders beside it), and the opening picture, as links relative to `dir`.
pub fn find_links(dir: &Path, episodes: impl IntoIterator<Item = u32>) -> EpisodeLinks {
    let mut places: Vec<(PathBuf, String)> = vec![(dir.to_path_buf(), String::new())];
    if let Some(parent) = dir.parent()
        && let Ok(entries) = std::fs::read_dir(parent)
    {
        let mut shards: Vec<(PathBuf, String)> = entries
            .filter_map(Result::ok)
            .map(|e| (e.path(), e.file_name().to_string_lossy().into_owned()))
            .filter(|(p, n)| n.starts_with("shard-") && p.is_dir() && p != dir)
            .map(|(p, n)| (p, format!("../{n}/")))
            .collect();
        shards.sort();
        places.extend(shards);
    }
    let pictures: Vec<(String, String)> = places
        .iter()
        .flat_map(|(p, prefix)| {
            std::fs::read_dir(p.join(PICTURES_DIR))
                .into_iter()
                .flatten()
                .filter_map(Result::ok)
                .map(move |e| {
                    let n = e.file_name().to_string_lossy().into_owned();
                    (n.clone(), format!("{prefix}{PICTURES_DIR}/{n}"))
                })
        })
        .collect();
    // The opening picture: the first place (this folder, then the shards) that has one.
    let opening = places.iter().find_map(|(p, prefix)| {
        [
            (capture_picture::FIRST_CAPTURE_FILE, Opening::Capture),
            (capture_picture::FIRST_FEEDER_FILE, Opening::Feeder),
        ]
        .into_iter()
        .find(|(name, _)| p.join(PICTURES_DIR).join(name).is_file())
        .map(|(name, kind)| (format!("{prefix}{PICTURES_DIR}/{name}"), kind))
    });
    let mut links = EpisodeLinks {
        opening,
        ..EpisodeLinks::default()
    };
    for e in episodes {
        let name = events_file(e);
        if let Some((_, prefix)) = places
            .iter()
            .find(|(p, _)| p.join(EVENTS_DIR).join(&name).is_file())
        {
            links
                .events
                .insert(e, format!("{prefix}{EVENTS_DIR}/{name}"));
        }
        let stem = format!("episode-{e:06}-");
        let mut mine: Vec<String> = pictures
            .iter()
            .filter(|(n, _)| n.starts_with(&stem) && n.ends_with(".png"))
            .map(|(_, l)| l.clone())
            .collect();
        mine.sort();
        if !mine.is_empty() {
            links.pictures.insert(e, mine);
        }
    }
    links
}

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
    let failed = records.values().filter(|r| !r.success).map(|r| r.episode);
    let links = find_links(dir, failed);
    let page = render_html(summary, records, &links)?;
    let plots = dir.join(html::PLOTS_DIR);
    std::fs::create_dir_all(&plots).map_err(|source| ReportError::Io {
        path: plots.clone(),
        source,
    })?;
    for (name, bytes) in &page.files {
        write(name, bytes)?;
    }
    let html_path = write(REPORT_FILE, page.html.as_bytes())?;
    Ok(ReportFiles {
        summary: summary_path,
        html: html_path,
    })
}
