//! `cell check SCENARIO`: validate a scenario file.

use std::path::PathBuf;
use std::process::ExitCode;

use cell::scenario::Scenario;

/// Arguments of `cell check`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario files to validate.
    #[arg(required = true)]
    pub scenarios: Vec<PathBuf>,
}

/// Validates each scenario; prints every problem as file:line:column and fails if any.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let mut failed = false;
    for path in &args.scenarios {
        match Scenario::load(path) {
            Ok(s) => println!(
                "{}: ok ({}, {} assembly steps, {} episodes, catalog {})",
                path.display(),
                s.spec.name,
                s.spec.assembly.len(),
                s.spec.episodes,
                s.catalog.name
            ),
            Err(e) => {
                eprintln!("{e}");
                failed = true;
            }
        }
    }
    Ok(if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}
