//! The results file of one run shard: `episodes.jsonl`, a header line and then one JSON line per
//! finished episode, appended as a whole line and synced before the next episode is counted.
//!
//! Opening checks the file before anything is written: a file that is not a results file, that
//! belongs to another scenario file, seed, record version or shard, or that has an unparsable or
//! inconsistent line anywhere but at the very end is refused and left untouched. An unterminated
//! last line is what a crash mid-append leaves behind; it is cut off (that episode reruns, and
//! episodes are deterministic, so nothing is lost).

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use super::header::ResultsHeader;
use crate::episode::EpisodeRecord;

/// Name of the results file inside a shard folder.
pub const RESULTS_FILE: &str = "episodes.jsonl";

/// Why a results file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A file system operation failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// The first line is not a results header.
    #[error(
        "{}: not a cell results file ({reason}); refusing to touch it — move it away or choose another output folder",
        path.display()
    )]
    NotResults {
        /// The file.
        path: PathBuf,
        /// What the first line lacks.
        reason: String,
    },
    /// The header belongs to another scenario file, seed, record version or shard.
    #[error(
        "{}: results of a different run ({field} is {found}, this run has {expected}); refusing to mix or overwrite them — move the folder away or choose another output folder",
        path.display()
    )]
    Foreign {
        /// The file.
        path: PathBuf,
        /// The header field that differs.
        field: &'static str,
        /// This run's value.
        expected: String,
        /// The file's value.
        found: String,
    },
    /// A line other than an unterminated last one is unparsable or inconsistent.
    #[error(
        "{}:{line}: corrupt results file: {reason}; refusing to touch it (only an unterminated last line is repaired)",
        path.display()
    )]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the line.
        reason: String,
    },
    /// Another process holds the file.
    #[error("{}: another process is writing these results", path.display())]
    Locked {
        /// The file.
        path: PathBuf,
    },
    /// A record handed to [`ResultsStore::append`] does not belong in this file.
    #[error("{}: refusing to append episode {episode}: {reason}", path.display())]
    Rejected {
        /// The file.
        path: PathBuf,
        /// The episode index of the record.
        episode: u32,
        /// Why.
        reason: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    move |source| StoreError::Io {
        path: path.into(),
        source,
    }
}

/// The validated contents of a results file.
#[derive(Debug, Clone)]
pub struct Results {
    /// The header line.
    pub header: ResultsHeader,
    /// Episodes by index.
    pub records: BTreeMap<u32, EpisodeRecord>,
    /// Bytes of an unterminated last line (0 when the file ends cleanly).
    pub torn_bytes: usize,
    /// Length of the file up to the end of the last complete line.
    pub valid_len: u64,
}

/// Checks a record against a header and the records already present.
fn check_record(
    header: &ResultsHeader,
    records: &BTreeMap<u32, EpisodeRecord>,
    r: &EpisodeRecord,
) -> Result<(), String> {
    if r.version != header.record_version {
        return Err(format!(
            "episode {} has record version {}, the header says {}",
            r.episode, r.version, header.record_version
        ));
    }
    if r.scenario != header.scenario || r.seed != header.seed {
        return Err(format!(
            "episode {} belongs to scenario {:?} seed {}, the header says {:?} seed {}",
            r.episode, r.scenario, r.seed, header.scenario, header.seed
        ));
    }
    if !header.shard.contains(r.episode) {
        return Err(format!(
            "episode {} is not in shard {}",
            r.episode, header.shard
        ));
    }
    if records.contains_key(&r.episode) {
        return Err(format!("episode {} appears twice", r.episode));
    }
    Ok(())
}

/// Parses and validates the bytes of a results file read from `path`.
pub fn parse_results(path: &Path, bytes: &[u8]) -> Result<Results, StoreError> {
    let not_results = |reason: String| StoreError::NotResults {
        path: path.into(),
        reason,
    };
    let Some(header_end) = bytes.iter().position(|b| *b == b'\n') else {
        return Err(not_results(if bytes.is_empty() {
            "the file is empty".into()
        } else {
            "no complete header line".into()
        }));
    };
    let header: ResultsHeader = serde_json::from_slice(&bytes[..header_end])
        .map_err(|e| not_results(format!("line 1 is not a results header: {e}")))?;
    if header.format != super::header::RESULTS_FORMAT {
        return Err(not_results(format!("format is {:?}", header.format)));
    }
    let mut records = BTreeMap::new();
    let mut start = header_end + 1;
    let mut line = 1;
    while start < bytes.len() {
        line += 1;
        let Some(len) = bytes[start..].iter().position(|b| *b == b'\n') else {
            // An unterminated last line: a torn append.
            return Ok(Results {
                header,
                records,
                torn_bytes: bytes.len() - start,
                valid_len: start as u64,
            });
        };
        let text = &bytes[start..start + len];
        let corrupt = |reason: String| StoreError::Corrupt {
            path: path.into(),
            line,
            reason,
        };
        let record: EpisodeRecord = serde_json::from_slice(text)
            .map_err(|e| corrupt(format!("not an episode record: {e}")))?;
        check_record(&header, &records, &record).map_err(corrupt)?;
        records.insert(record.episode, record);
        start += len + 1;
    }
    Ok(Results {
        header,
        records,
        torn_bytes: 0,
        valid_len: bytes.len() as u64,
    })
}

/// Reads and validates a results file without changing it (an unterminated last line is
/// reported in [`Results::torn_bytes`] and ignored).
pub fn read_results(path: &Path) -> Result<Results, StoreError> {
    let bytes = std::fs::read(path).map_err(io(path))?;
    parse_results(path, &bytes)
}

/// How opening a store went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OpenReport {
    /// The file was created.
    pub created: bool,
    /// Episodes already present.
    pub present: usize,
    /// Bytes of a torn last line that were cut off.
    pub truncated_bytes: usize,
}

/// An open, locked results file that episodes are appended to.
#[derive(Debug)]
pub struct ResultsStore {
    path: PathBuf,
    file: File,
    header: ResultsHeader,
    records: BTreeMap<u32, EpisodeRecord>,
    len: u64,
}

impl ResultsStore {
    /// Opens (or creates) `dir/episodes.jsonl` for a run with `header`: refuses foreign or
    /// corrupt files, cuts off a torn last line, and locks the file against other writers.
    pub fn open(dir: &Path, header: ResultsHeader) -> Result<(Self, OpenReport), StoreError> {
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let path = dir.join(RESULTS_FILE);
        let mut created = false;
        if !path.exists() {
            let mut line = serde_json::to_string(&header).expect("a header serialises");
            line.push('\n');
            sim::fsutil::write_atomic(&path, line.as_bytes()).map_err(io(&path))?;
            created = true;
        }
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .open(&path)
            .map_err(io(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(StoreError::Locked { path });
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(StoreError::Io { path, source: e }),
        }
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io(&path))?;
        let results = parse_results(&path, &bytes)?;
        if let Some((field, expected, found)) = results.header.mismatch(&header) {
            return Err(StoreError::Foreign {
                path,
                field,
                expected,
                found,
            });
        }
        if results.torn_bytes > 0 {
            tracing::warn!(
                "{}: cutting off a torn last line ({} bytes) left by an interrupted run",
                path.display(),
                results.torn_bytes
            );
            file.set_len(results.valid_len).map_err(io(&path))?;
            file.sync_all().map_err(io(&path))?;
        }
        let report = OpenReport {
            created,
            present: results.records.len(),
            truncated_bytes: results.torn_bytes,
        };
        let store = Self {
            path,
            file,
            header: results.header,
            records: results.records,
            len: results.valid_len,
        };
        Ok((store, report))
    }

    /// The results file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The header line.
    pub fn header(&self) -> &ResultsHeader {
        &self.header
    }

    /// Whether episode `episode` is stored.
    pub fn contains(&self, episode: u32) -> bool {
        self.records.contains_key(&episode)
    }

    /// Stored episodes by index.
    pub fn records(&self) -> &BTreeMap<u32, EpisodeRecord> {
        &self.records
    }

    /// Appends one episode as one synced line; on a failed write the file is cut back to its
    /// last complete line.
    pub fn append(&mut self, record: EpisodeRecord) -> Result<(), StoreError> {
        check_record(&self.header, &self.records, &record).map_err(|reason| {
            StoreError::Rejected {
                path: self.path.clone(),
                episode: record.episode,
                reason,
            }
        })?;
        let mut line = serde_json::to_vec(&record).expect("an episode record serialises");
        line.push(b'\n');
        let written = self
            .file
            .write_all(&line)
            .and_then(|()| self.file.sync_data());
        if let Err(e) = written {
            let _ = self.file.set_len(self.len);
            return Err(StoreError::Io {
                path: self.path.clone(),
                source: e,
            });
        }
        self.len += line.len() as u64;
        // Keep what a reader of the file will get (serde_json's default float parsing may differ
        // from the value written in the last bit), so a resumed run equals an uninterrupted one.
        let stored = serde_json::from_slice(&line).unwrap_or(record);
        self.records.insert(stored.episode, stored);
        Ok(())
    }
}
