//! `cell parts ...`: prepare a catalog (keypoints, mass, stable poses) or regenerate the CAD.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use cell::prepare::prepare_catalog_with;
use indicatif::{ProgressBar, ProgressStyle};
use perception::part::AlikePoses;
use sim::stable_poses::{DropSettings, PoseClass};

/// Subcommands of `cell parts`.
#[derive(Debug, clap::Subcommand)]
pub enum PartsCommand {
    /// Compute keypoints, mass properties and stable poses (physics drops) and write them into
    /// the catalog, keeping its comments.
    Prepare(PrepareArgs),
    /// Regenerate this project's part meshes (bit for bit) into a folder: the USB-C parts, nest
    /// and tag board, and the NIST task board's pegs and plate.
    Cad(CadArgs),
}

/// Arguments of `cell parts prepare`.
#[derive(Debug, clap::Args)]
pub struct PrepareArgs {
    /// The catalog file, e.g. scenarios/parts/usbc.toml.
    pub catalog: PathBuf,
    /// Drops per part.
    #[arg(long, default_value_t = 5000)]
    pub drops: usize,
    /// Seed of the drop orientations (the same seed reproduces the table).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Height of each part's lowest point above the table at release, metres: how the parts
    /// arrive on the feeder. Recorded in the catalog (`drop_height`); without this flag the
    /// catalog's value is used, else 0.03 (the seed's own drops).
    #[arg(long)]
    pub drop_height: Option<f64>,
    /// Parts dropped together onto one spot (1: each alone). A crowded feeder settles
    /// differently: parts that come to rest on a neighbour are counted apart.
    #[arg(long, default_value_t = 1)]
    pub crowd: usize,
    /// Physics engine that drops the parts: rapier (the reference) or mujoco (a cross-check;
    /// the table written is then MuJoCo's).
    #[arg(long, default_value = "rapier")]
    pub engine: String,
}

/// Arguments of `cell parts cad`.
#[derive(Debug, clap::Args)]
pub struct CadArgs {
    /// Output folder.
    #[arg(default_value = "scenarios/parts")]
    pub dir: PathBuf,
}

/// Runs a `cell parts` subcommand.
pub fn run(cmd: PartsCommand) -> anyhow::Result<ExitCode> {
    match cmd {
        PartsCommand::Prepare(args) => prepare(args),
        PartsCommand::Cad(args) => {
            let mut written = sim::cad::write_usbc_meshes(&args.dir)?;
            written.extend(sim::cad::write_nist_meshes(&args.dir)?);
            for path in written {
                println!("wrote {}", path.display());
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// What a pair of stable poses that look alike means, and what to do about it.
fn alike_warning(a: &AlikePoses, classes: &[PoseClass]) -> String {
    let pose = |i: usize| &classes[i].pose;
    let (axis, angle) = a
        .turn
        .axis_angle()
        .map_or(([0.0; 3], 0.0), |(axis, angle)| {
            (axis.into_inner().into(), angle)
        });
    format!(
        "resting as \"{}\" ({:.1} % of drops) and as \"{}\" ({:.1} %) it is the same shape to \
         {:.3} mm, turned {:.1}° about [{:.3}, {:.3}, {:.3}] (part frame), which is not among its \
         symmetries: no camera above the table tells these stable poses apart, and a grasp or \
         insertion planned for one is applied to the other. Declare the turn in `symmetries` if \
         it is exact, or change the part so the poses differ",
        pose(a.first).name,
        100.0 * pose(a.first).probability,
        pose(a.second).name,
        100.0 * pose(a.second).probability,
        a.deviation * 1e3,
        angle.to_degrees(),
        axis[0],
        axis[1],
        axis[2],
    )
}

fn prepare(args: PrepareArgs) -> anyhow::Result<ExitCode> {
    if args.drops == 0 {
        anyhow::bail!("--drops must be at least 1");
    }
    if let Some(height) = args.drop_height {
        perception::part::checked_drop_height(height)
            .map_err(|why| anyhow::anyhow!("--drop-height {why}"))?;
    }
    if args.crowd == 0 || args.crowd > 1000 {
        anyhow::bail!("--crowd must be between 1 and 1000, got {}", args.crowd);
    }
    let engine = sim::stable_poses::DropEngine::from_name(&args.engine)
        .ok_or_else(|| anyhow::anyhow!("--engine {:?}: expected rapier or mujoco", args.engine))?;
    let recorded = perception::part::Catalog::load(&args.catalog)?;
    let mut settings = DropSettings {
        drops: args.drops,
        seed: args.seed,
        crowd: args.crowd,
        ..DropSettings::default()
    }
    .with_catalog(&recorded);
    if let Some(height) = args.drop_height {
        settings.drop_height = height;
    }
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} drops ({per_sec}, eta {eta})")?
            .progress_chars("=> "),
    );
    bar.set_message("dropping");
    let start = Instant::now();
    let prepared = prepare_catalog_with(engine, &args.catalog, &settings, Some(&bar))?;
    bar.finish_and_clear();
    let elapsed = start.elapsed().as_secs_f64();
    let total: usize = prepared.iter().map(|p| p.report.drops).sum();
    println!(
        "{}: {} parts, {total} drops from {:.1} mm in {elapsed:.1} s ({:.0} drops/s, {} threads)",
        args.catalog.display(),
        prepared.len(),
        settings.drop_height * 1e3,
        total as f64 / elapsed,
        rayon::current_num_threads()
    );
    for p in &prepared {
        let r = &p.report;
        for w in p.repairs.warnings() {
            eprintln!("warning: {}: {w}", p.name);
        }
        for n in p.repairs.notes() {
            eprintln!("note: {}: {n}", p.name);
        }
        for a in &p.alike {
            eprintln!("warning: {}: {}", p.name, alike_warning(a, &r.classes));
        }
        let share = |n: usize| 100.0 * n as f64 / r.drops.max(1) as f64;
        println!(
            "\n{}: mass {:.3} g, centre of mass ({:.3}, {:.3}, {:.3}) mm; {} drops, {:.1} % at rest \
             (mean {:.3} s), {:.1} % still jittering at the {} s limit, {:.1} % leaning on a \
             neighbour, {:.1} % in rare classes",
            p.name,
            p.mass * 1e3,
            p.center_of_mass.x * 1e3,
            p.center_of_mass.y * 1e3,
            p.center_of_mass.z * 1e3,
            r.drops,
            100.0 - share(r.unsettled),
            r.mean_rest_time,
            share(r.unsettled),
            settings.max_time,
            share(r.leaning),
            share(r.rare)
        );
        println!(
            "  {:<12} {:>8} {:>14} {:>18} {:>10} {:>10}",
            "class", "prob %", "rest height mm", "physics-geom µm", "spread °", "jittering"
        );
        for c in &r.classes {
            println!(
                "  {:<12} {:>8.2} {:>14.4} {:>18.3} {:>10.3} {:>10}",
                c.pose.name,
                c.pose.probability * 100.0,
                c.pose.rest_height * 1e3,
                c.max_height_error * 1e6,
                c.spread.to_degrees(),
                c.jittering
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
