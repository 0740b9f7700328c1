//! `cell check SCENARIO [--camera SPEC]`: validate a scenario file, and open a production camera
//! source for it (the same checks as a production run's pre-flight, without capturing).

use std::path::PathBuf;
use std::process::ExitCode;

use cell::camera::CameraSpec;
use cell::orchestrator::open_camera;
use cell::scenario::Scenario;

/// Arguments of `cell check`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario files to validate.
    #[arg(required = true)]
    pub scenarios: Vec<PathBuf>,
    /// Also open this production camera source (see `cell run --camera`) for each scenario's
    /// camera: a missing folder, a command whose program is not found or a camera that does
    /// not answer is refused.
    #[arg(long, value_name = "SPEC")]
    pub camera: Option<CameraSpec>,
}

/// Validates each scenario; prints every problem as file:line:column and fails if any.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let mut failed = false;
    for path in &args.scenarios {
        match Scenario::load(path) {
            Ok(s) => {
                println!(
                    "{}: ok ({}, {} assembly steps, {} episodes, catalog {})",
                    path.display(),
                    s.spec.name,
                    s.spec.assembly.len(),
                    s.spec.episodes,
                    s.catalog.name
                );
                if let Some(spec) = &args.camera {
                    match open_camera(&s, spec) {
                        Ok(c) => println!(
                            "{}: camera ok ({}, {} × {} images expected)",
                            path.display(),
                            c.describe(),
                            s.spec.cell.camera.intrinsics.width,
                            s.spec.cell.camera.intrinsics.height
                        ),
                        Err(e) => {
                            eprintln!("{}: camera: {e}", path.display());
                            failed = true;
                        }
                    }
                }
            }
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
