//! `cell merge`: combine the results of shards (run anywhere, by any scheduler) into one results
//! set, refusing shards of another scenario file, seed or record version, and overlapping shards.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::Shard;
use super::header::ResultsHeader;
use super::store::{RESULTS_FILE, StoreError, read_results};
use crate::episode::EpisodeRecord;

/// Why shards cannot be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// A results file is unreadable, corrupt or not a results file.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// No results file among the inputs.
    #[error("no {RESULTS_FILE} found in {0:?}")]
    NoInputs(Vec<PathBuf>),
    /// Two inputs come from different runs.
    #[error(
        "{} and {} come from different runs ({field}: {first} vs {other}); refusing to merge them",
        first_path.display(),
        other_path.display()
    )]
    Mismatch {
        /// The first input.
        first_path: PathBuf,
        /// The input that differs.
        other_path: PathBuf,
        /// The header field that differs.
        field: &'static str,
        /// The first input's value.
        first: String,
        /// The other input's value.
        other: String,
    },
    /// Two inputs hold the same episode.
    #[error(
        "episode {episode} is in both {} and {}; the shards overlap, refusing to merge them",
        first_path.display(),
        other_path.display()
    )]
    Overlap {
        /// The episode.
        episode: u32,
        /// One file holding it.
        first_path: PathBuf,
        /// The other file holding it.
        other_path: PathBuf,
    },
}

/// The union of several shards' results.
#[derive(Debug, Clone)]
pub struct Merged {
    /// The common header, with shard `0/1`.
    pub header: ResultsHeader,
    /// All episodes by index.
    pub records: BTreeMap<u32, EpisodeRecord>,
    /// The results files read, with their shard.
    pub inputs: Vec<(PathBuf, Shard)>,
    /// Inputs that ended in a torn line (ignored: that episode is simply absent).
    pub torn: Vec<PathBuf>,
}

impl Merged {
    /// Shards of the split the inputs come from that no input holds (for inputs that all use
    /// the same number of shards; empty otherwise, where [`Merged::gaps`] still tells).
    pub fn missing_shards(&self) -> Vec<Shard> {
        let Some(count) = self.inputs.first().map(|(_, s)| s.count) else {
            return Vec::new();
        };
        if self.inputs.iter().any(|(_, s)| s.count != count) {
            return Vec::new();
        }
        (0..count)
            .filter_map(|i| Shard::new(i, count))
            .filter(|s| !self.inputs.iter().any(|(_, have)| have == s))
            .collect()
    }

    /// Episode indices below the highest one present that no input holds.
    pub fn gaps(&self) -> Vec<u32> {
        let end = self.records.keys().next_back().map_or(0, |e| e + 1);
        (0..end).filter(|e| !self.records.contains_key(e)).collect()
    }
}

/// The results files an input names: the file itself, `DIR/episodes.jsonl`, or, for a scenario
/// folder, each `DIR/shard-*/episodes.jsonl`.
pub fn results_files(input: &Path) -> Result<Vec<PathBuf>, StoreError> {
    if input.is_file() {
        return Ok(vec![input.into()]);
    }
    let direct = input.join(RESULTS_FILE);
    if direct.is_file() {
        return Ok(vec![direct]);
    }
    let io = |source| StoreError::Io {
        path: input.into(),
        source,
    };
    let mut found = Vec::new();
    for entry in std::fs::read_dir(input).map_err(io)? {
        let entry = entry.map_err(io)?;
        let name = entry.file_name();
        let file = entry.path().join(RESULTS_FILE);
        if name.to_string_lossy().starts_with("shard-") && file.is_file() {
            found.push(file);
        }
    }
    found.sort();
    Ok(found)
}

/// Reads and merges the results named by `inputs` (see [`results_files`]).
pub fn merge(inputs: &[PathBuf]) -> Result<Merged, MergeError> {
    let mut files = Vec::new();
    for input in inputs {
        files.extend(results_files(input)?);
    }
    let Some(first_path) = files.first().cloned() else {
        return Err(MergeError::NoInputs(inputs.to_vec()));
    };
    let mut header: Option<ResultsHeader> = None;
    let mut records: BTreeMap<u32, EpisodeRecord> = BTreeMap::new();
    let mut owner: BTreeMap<u32, usize> = BTreeMap::new();
    let mut merged_inputs = Vec::new();
    let mut torn = Vec::new();
    for (i, path) in files.iter().enumerate() {
        let results = read_results(path)?;
        let shard = results.header.shard;
        match &header {
            None => {
                header = Some(ResultsHeader {
                    shard: Shard::ALL,
                    ..results.header.clone()
                })
            }
            Some(h) => {
                let other = ResultsHeader {
                    shard: Shard::ALL,
                    ..results.header.clone()
                };
                if let Some((field, first, other)) = other.mismatch(h) {
                    return Err(MergeError::Mismatch {
                        first_path: first_path.clone(),
                        other_path: path.clone(),
                        field,
                        first,
                        other,
                    });
                }
            }
        }
        if results.torn_bytes > 0 {
            torn.push(path.clone());
        }
        for (episode, record) in results.records {
            if let Some(&j) = owner.get(&episode) {
                return Err(MergeError::Overlap {
                    episode,
                    first_path: files[j].clone(),
                    other_path: path.clone(),
                });
            }
            owner.insert(episode, i);
            records.insert(episode, record);
        }
        merged_inputs.push((path.clone(), shard));
    }
    let header = header.expect("at least one results file was read");
    Ok(Merged {
        header,
        records,
        inputs: merged_inputs,
        torn,
    })
}

/// Writes a complete results file (header, then records by episode) atomically into `dir`;
/// an existing file there is replaced only if it holds results of the same run.
pub fn write_results(
    dir: &Path,
    header: &ResultsHeader,
    records: &BTreeMap<u32, EpisodeRecord>,
) -> Result<PathBuf, StoreError> {
    std::fs::create_dir_all(dir).map_err(|source| StoreError::Io {
        path: dir.into(),
        source,
    })?;
    let path = dir.join(RESULTS_FILE);
    if path.exists() {
        // Replace only an earlier merge of the same run; anything else is refused untouched.
        let existing = read_results(&path)?;
        if let Some((field, expected, found)) = existing.header.mismatch(header) {
            return Err(StoreError::Foreign {
                path,
                field,
                expected,
                found,
            });
        }
    }
    let mut out = serde_json::to_vec(header).expect("a header serialises");
    out.push(b'\n');
    for r in records.values() {
        serde_json::to_writer(&mut out, r).expect("an episode record serialises");
        out.push(b'\n');
    }
    sim::fsutil::write_atomic(&path, &out).map_err(|source| StoreError::Io {
        path: path.clone(),
        source,
    })?;
    Ok(path)
}
