//! The success-rate regression gate: baselines kept in the repository, exact tests of a drop,
//! and the verdict table.

pub mod baseline;
pub mod stats;
pub mod verdict;

pub use baseline::{Baseline, BaselineError, StepCounts};
pub use stats::{Counts, Interval, drop_p_value, holm, wilson};
pub use verdict::{Comparison, Verdict, compare};
