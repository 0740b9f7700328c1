//! `cell`: run, check and gate a robot cell that assembles USB Type-C receptacles from three
//! sub-centimetre parts, in simulation or against a Universal Robots controller.

mod commands;

use clap::{Parser, Subcommand};

/// Robot-cell assembly orchestrator with a simulation harness.
///
/// A scenario file describes a whole cell: camera, flexible feeder, UR arm, gripper, fixture, the
/// part catalog and the assembly steps. Typical flow:
///
///   cell check scenarios/usbc_nominal.toml         # validate a scenario before running it
///   cell run scenarios/usbc_nominal.toml           # run its episodes; summary.json, report.html
///   cell replay runs/usbc-nominal/all --episode 3  # one episode again: timeline and pictures
///   cell regress scenarios/usbc_nominal.toml --baseline scenarios/baselines   # gate a change
///   cell parts prepare scenarios/parts/usbc.toml   # after changing a part: keypoints, mass,
///                                                  # stable poses (physics)
///
/// Every command prints what it measured; files it writes are written atomically.
#[derive(Debug, Parser)]
#[command(
    name = "cell",
    version,
    about,
    long_about,
    verbatim_doc_comment,
    propagate_version = true
)]
struct Cli {
    /// Log filter, e.g. "info" or "sim=debug" (also read from RUST_LOG).
    #[arg(long, global = true, default_value = "warn")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Validate a scenario file; every error names file:line:column and what was expected.
    Check(commands::check::Args),
    /// Commission a cell: the camera's pose in the robot base and the table plane from one
    /// tag-board image and pointer touches at the board's marks, written into the scenario with
    /// their measured uncertainty (`--robot sim`, `virtual-ur` or `ur://HOST`).
    Calibrate(commands::calibrate::Args),
    /// Work on a part catalog (keypoints, mass properties, stable poses, CAD).
    #[command(subcommand)]
    Parts(commands::parts::PartsCommand),
    /// The paper's Figure 5: PnP pose error against keypoint noise and distance, raw and after
    /// planar refinement onto stable poses; writes CSVs and plots, prints a table.
    Ablate(commands::ablate::Args),
    /// The tag board as an SVG to print at exact scale (mm units, a 100 mm scale bar to check
    /// with a ruler), from its board file.
    Board(commands::board::Args),
    /// How well the tag board is found and its pose measured: boards rendered under the
    /// randomisation, detected on 20 MP frames, against the simulator's truth and the
    /// Cramér–Rao bound, with time per stage.
    BoardStudy(commands::board_study::Args),
    /// A simulated UR controller (RTDE 30004, dashboard 29999, script port 30003) on loopback,
    /// backed by a kinematic UR5e; runs our program and SDU ur_rtde's control script.
    VirtualUr(commands::virtual_ur::Args),
    /// Synthetic images and labels in the BOP format (overviews with all parts) plus the keypoint
    /// crop set (128 × 128 crops with shifted intrinsics); deterministic, resumable, parallel.
    Dataset(commands::dataset::Args),
    /// The learned perception pipeline against a BOP test split: the paper's Table 1 (raw PnP and
    /// refined, outliers counted), detection precision / recall, stable-pose rate, MSSD / MSPD,
    /// time per stage and the worst crops; writes eval.json and eval.html.
    Eval(commands::eval::Args),
    /// Run a scenario's episodes, resumably (runs/<scenario>/<shard>/episodes.jsonl), then write
    /// summary.json and report.html: in the in-process simulation (parallel), the simulation
    /// behind a loopback virtual UR over RTDE (`--robot virtual-ur`), or a real controller
    /// (`--robot ur://HOST`, after the production pre-flight).
    Run(commands::run::Args),
    /// Re-run one stored episode of a simulated run from its seed: its event timeline, a check
    /// against the stored record, and pictures of its failure.
    Replay(commands::replay::Args),
    /// Combine shard results (`cell run --shard I/N`) into one results set and report.
    Merge(commands::merge::Args),
    /// Success-rate regression gate: run scenarios and compare with their baselines
    /// (one-sided Fisher exact test); exits non-zero on a significant drop.
    Regress(commands::regress::Args),
    /// How often the insertion scorers (analytic, rapier, mujoco) agree near each step's capture
    /// boundary, with the disagreeing cases; exits non-zero below `--min-agreement`.
    Scorers(commands::scorers::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(&cli.log));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Check(args) => commands::check::run(args),
        Command::Calibrate(args) => commands::calibrate::run(args),
        Command::Parts(cmd) => commands::parts::run(cmd),
        Command::Ablate(args) => commands::ablate::run(args),
        Command::Board(args) => commands::board::run(args),
        Command::BoardStudy(args) => commands::board_study::run(args),
        Command::VirtualUr(args) => commands::virtual_ur::run(args),
        Command::Dataset(args) => commands::dataset::run(args),
        Command::Eval(args) => commands::eval::run(args),
        Command::Run(args) => commands::run::run(args),
        Command::Merge(args) => commands::merge::run(args),
        Command::Replay(args) => commands::replay::run(args),
        Command::Regress(args) => commands::regress::run(args),
        Command::Scorers(args) => commands::scorers::run(args),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", commands::error_text(&e));
            std::process::ExitCode::FAILURE
        }
    }
}
