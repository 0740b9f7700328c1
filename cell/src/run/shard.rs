//! `--shard I/N`: a slice of a run's episodes for an external scheduler. Shards count from 1, as
//! SLURM array jobs do (`--array=1-N`, `--shard $SLURM_ARRAY_TASK_ID/N`): episode e belongs to
//! shard (e mod N) + 1. A scheduler with 0-based indices, such as a Kubernetes indexed job
//! (`JOB_COMPLETION_INDEX` from 0 to N − 1), passes `--shard $((JOB_COMPLETION_INDEX + 1))/N`.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The 0-based shard `index` of `count`: the episodes `i` with `i % count == index`; written
/// 1-based as `index + 1`/`count` everywhere people read it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Shard {
    /// Which slice, `0..count` (0-based; the text form is 1-based).
    pub index: u32,
    /// How many slices the run is split into (1: unsharded).
    pub count: u32,
}

/// A `--shard` value that is not `I/N` with `1 <= I <= N`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "invalid shard {given:?}: {reason} (expected I/N with 1 <= I <= N, e.g. 3/8; shards count \
     from 1 like SLURM array tasks: from a 0-based index such as Kubernetes' \
     JOB_COMPLETION_INDEX pass $((INDEX + 1))/N)"
)]
pub struct ShardParseError {
    /// The text given.
    pub given: String,
    /// What is wrong with it.
    pub reason: &'static str,
}

impl Shard {
    /// The whole run in one piece.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Shard `index` of `count`, if `index < count`.
    pub fn new(index: u32, count: u32) -> Option<Self> {
        (index < count).then_some(Self { index, count })
    }

    /// Whether episode `episode` belongs to this shard.
    pub fn contains(&self, episode: u32) -> bool {
        episode % self.count == self.index
    }

    /// Whether this is the whole run.
    pub fn is_all(&self) -> bool {
        self.count == 1
    }

    /// The folder name for this shard's results: `all`, or `shard-I-of-N` (1-based, so the
    /// last shard of two is `shard-2-of-2`).
    pub fn dir_name(&self) -> String {
        if self.is_all() {
            "all".into()
        } else {
            format!("shard-{}-of-{}", self.index + 1, self.count)
        }
    }

    /// This shard's episodes among `0..episodes`.
    pub fn episodes(&self, episodes: u32) -> impl Iterator<Item = u32> + '_ {
        (0..episodes).filter(|e| self.contains(*e))
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index + 1, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |reason| ShardParseError {
            given: s.into(),
            reason,
        };
        let (i, n) = s.split_once('/').ok_or_else(|| err("no '/'"))?;
        let number: u32 = i
            .trim()
            .parse()
            .map_err(|_| err("I is not a whole number"))?;
        let count: u32 = n
            .trim()
            .parse()
            .map_err(|_| err("N is not a whole number"))?;
        if count == 0 {
            return Err(err("N must be at least 1"));
        }
        if number == 0 {
            return Err(err("shards count from 1, so I = 0 is no shard"));
        }
        Shard::new(number - 1, count).ok_or_else(|| err("I must not be more than N"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_partitions() {
        let s: Shard = "3/3".parse().unwrap();
        assert_eq!(s, Shard { index: 2, count: 3 });
        assert_eq!(s.episodes(10).collect::<Vec<_>>(), vec![2, 5, 8]);
        assert_eq!(s.to_string(), "3/3");
        assert_eq!(s.dir_name(), "shard-3-of-3");
        let first: Shard = "1/2".parse().unwrap();
        assert_eq!(first.episodes(5).collect::<Vec<_>>(), vec![0, 2, 4]);
        assert_eq!("2/2".parse::<Shard>().unwrap().dir_name(), "shard-2-of-2");
        assert_eq!(Shard::ALL.dir_name(), "all");
        // Every episode lands in exactly one shard.
        for e in 0..50 {
            assert_eq!(
                (0..7)
                    .filter(|i| Shard::new(*i, 7).unwrap().contains(e))
                    .count(),
                1
            );
        }
    }

    #[test]
    fn rejects_bad_shards() {
        for bad in ["4/3", "0/2", "1/0", "a/2", "1", "-1/2", "1/2/3", ""] {
            assert!(bad.parse::<Shard>().is_err(), "{bad} accepted");
        }
        let zero = "0/2".parse::<Shard>().unwrap_err().to_string();
        assert!(
            zero.contains("count from 1") && zero.contains("INDEX + 1"),
            "{zero}"
        );
    }
}
