//! Step outcomes in the order summaries list them, with their index and record name.

use crate::episode::StepOutcome;

/// Every step outcome, in the order summaries use.
pub const OUTCOMES: [StepOutcome; 4] = [
    StepOutcome::Seated,
    StepOutcome::Jammed,
    StepOutcome::Missed,
    StepOutcome::Aborted,
];

/// Position of an outcome in [`OUTCOMES`].
pub fn outcome_index(o: StepOutcome) -> usize {
    match o {
        StepOutcome::Seated => 0,
        StepOutcome::Jammed => 1,
        StepOutcome::Missed => 2,
        StepOutcome::Aborted => 3,
    }
}

/// The snake_case name of an outcome, as in the records.
pub fn outcome_name(o: StepOutcome) -> &'static str {
    match o {
        StepOutcome::Seated => "seated",
        StepOutcome::Jammed => "jammed",
        StepOutcome::Missed => "missed",
        StepOutcome::Aborted => "aborted",
    }
}
