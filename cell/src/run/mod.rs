//! Runs: N episodes of a scenario in parallel, each appended to a resumable results file
//! (`<root>/<scenario>/<shard>/episodes.jsonl`), sharded for external schedulers, merged back,
//! and summarised.

pub mod distribution;
pub mod execute;
pub mod header;
pub mod mechanism;
pub mod merge;
pub mod outcomes;
pub mod phases;
pub mod robot_target;
pub mod runner;
pub mod shard;
pub mod store;
pub mod summary;

pub use execute::{
    Driver, EpisodeError, ExecuteError, Executed, Production, ProductionRefusal, execute,
    execute_on, production,
};
pub use header::{ResultsHeader, sha256_hex};
pub use merge::{MergeError, Merged, merge, write_results};
pub use robot_target::RobotTarget;
pub use runner::{LoadedScenario, RunError, RunOptions, RunOutcome, results_dir, run_episodes};
pub use shard::{Shard, ShardParseError};
pub use store::{RESULTS_FILE, Results, ResultsStore, StoreError, read_results};
pub use summary::Summary;
