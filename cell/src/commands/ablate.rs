//! `cell ablate`: the seed's Figure 5, PnP's sensitivity to keypoint noise against object
//! distance, with planar refinement side by side. The computation lives in
//! `perception::ablation`; this file parses arguments and writes the CSVs, plots and table.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use nalgebra::Isometry3;
use perception::ablation::{
    AblationConfig, AblationPart, AblationResult, AblationRow, Method, NoiseAxis, run_ablation,
};
use perception::part::{Catalog, PartRole};
use plotters::prelude::*;

/// Arguments of `cell ablate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The part catalog (must be prepared: keypoints and stable poses).
    #[arg(long, default_value = "scenarios/parts/usbc.toml")]
    pub catalog: PathBuf,
    /// Only this part (default: every assembled part of the catalog).
    #[arg(long)]
    pub part: Option<String>,
    /// Use a synthetic part of the main shell's size instead of the catalog (for when the
    /// catalog has not been prepared yet).
    #[arg(long)]
    pub synthetic: bool,
    /// Camera-to-table distances, metres.
    #[arg(long, value_delimiter = ',', default_value = "1.4,1.6,1.8")]
    pub distances: Vec<f64>,
    /// Largest keypoint noise σ, pixels.
    #[arg(long, default_value_t = 5.0)]
    pub noise_max: f64,
    /// Step between noise levels, pixels.
    #[arg(long, default_value_t = 0.5)]
    pub noise_step: f64,
    /// Trials per (part, distance, axis, noise level).
    #[arg(long, default_value_t = 200)]
    pub trials: usize,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Camera tilt away from straight down, degrees.
    #[arg(long, default_value_t = 0.0)]
    pub tilt_deg: f64,
    /// Output folder for CSVs, plots and the setup file.
    #[arg(long, default_value = "target/ablate")]
    pub out: PathBuf,
}

/// Runs the ablation and writes its outputs.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let parts = load_parts(&args)?;
    let noise_px = noise_levels(args.noise_max, args.noise_step)?;
    let config = AblationConfig {
        distances_m: args.distances.clone(),
        noise_px,
        trials: args.trials,
        seed: args.seed,
        camera_tilt: args.tilt_deg.to_radians(),
        ..AblationConfig::default()
    };
    let started = Instant::now();
    let result = run_ablation(&config, &parts)?;
    let elapsed = started.elapsed();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let summary_path = args.out.join("ablation.csv");
    write_atomic(&summary_path, &summary_csv(&result.rows))?;
    let trials_path = args.out.join("trials.csv");
    write_atomic(&trials_path, &trials_csv(&result))?;
    let setup_path = args.out.join("setup.json");
    write_atomic(&setup_path, &setup_json(&config, &parts)?)?;
    let mut plots = Vec::new();
    for &axis in &config.axes {
        for ext in ["png", "svg"] {
            let path = args.out.join(format!("figure5_{}.{ext}", axis.name()));
            plot_axis(&path, &config, &result.rows, axis)
                .with_context(|| format!("cannot draw {}", path.display()))?;
            plots.push(path);
        }
    }
    print!("{}", table(&config, &result.rows));
    let names: Vec<&str> = parts.iter().map(|p| p.name.as_str()).collect();
    println!(
        "\n{} trials ({} per cell; parts: {}) solved in {:.2} s",
        result.trials.len(),
        config.trials,
        names.join(", "),
        elapsed.as_secs_f64()
    );
    println!(
        "wrote {}, {}, {}",
        summary_path.display(),
        trials_path.display(),
        setup_path.display()
    );
    for p in plots {
        println!("wrote {}", p.display());
    }
    Ok(ExitCode::SUCCESS)
}

fn load_parts(args: &Args) -> anyhow::Result<Vec<AblationPart>> {
    if args.synthetic {
        return Ok(vec![AblationPart::synthetic_shell()]);
    }
    let catalog = Catalog::load(&args.catalog)?;
    let specs: Vec<_> = catalog
        .parts
        .iter()
        .filter(|p| p.role != PartRole::Fixture)
        .filter(|p| args.part.as_ref().is_none_or(|n| &p.name == n))
        .collect();
    if specs.is_empty() {
        anyhow::bail!(
            "{}: no assembled part{}",
            args.catalog.display(),
            args.part
                .as_ref()
                .map(|n| format!(" named {n}"))
                .unwrap_or_default()
        );
    }
    specs
        .into_iter()
        .map(|s| {
            AblationPart::from_spec(s).with_context(|| {
                format!(
                    "{}: run `cell parts prepare {}` first, or pass --synthetic",
                    args.catalog.display(),
                    args.catalog.display()
                )
            })
        })
        .collect()
}

fn noise_levels(max: f64, step: f64) -> anyhow::Result<Vec<f64>> {
    if !(max.is_finite() && max >= 0.0 && step.is_finite() && step > 0.0) {
        anyhow::bail!("--noise-max must be ≥ 0 and --noise-step > 0");
    }
    let n = (max / step + 1e-9).floor() as usize;
    if n > 1000 {
        anyhow::bail!("{} noise levels is too many; raise --noise-step", n + 1);
    }
    Ok((0..=n).map(|i| i as f64 * step).collect())
}

/// Writes `text` through the one atomic writer (synced file and directory), naming the file on
/// failure.
fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    sim::fsutil::write_atomic(path, text.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))
}

fn summary_csv(rows: &[AblationRow]) -> String {
    let mut s = String::from(
        "distance_m,axis,noise_px,method,samples,failures,outliers_gt10deg,x_mm_mean,x_mm_std,\
         y_mm_mean,y_mm_std,z_mm_mean,z_mm_std,z_mm_p95,angle_deg_mean,angle_deg_std,\
         angle_deg_p95,sym_angle_deg_mean,add_mm_mean,mssd_mm_mean,mspd_px_mean,class_accuracy\n",
    );
    for r in rows {
        let m = &r.summary;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.4}",
            r.distance_m,
            r.axis.name(),
            r.noise_px,
            r.method.name(),
            m.samples,
            r.failures,
            m.outliers,
            m.x_mm.mean,
            m.x_mm.std,
            m.y_mm.mean,
            m.y_mm.std,
            m.z_mm.mean,
            m.z_mm.std,
            m.z_mm.p95,
            m.angle_deg.mean,
            m.angle_deg.std,
            m.angle_deg.p95,
            m.sym_angle_deg.mean,
            m.add_mm.mean,
            m.mssd_mm.mean,
            m.mspd_px.mean,
            r.class_accuracy
        );
    }
    s
}

fn pose_fields(t: Option<&Isometry3<f64>>) -> String {
    match t {
        Some(t) => {
            let v = t.translation.vector;
            let r = t.rotation.scaled_axis();
            format!(
                "{:.12},{:.12},{:.12},{:.12},{:.12},{:.12}",
                v.x, v.y, v.z, r.x, r.y, r.z
            )
        }
        None => ",,,,,".into(),
    }
}

/// One line per trial: the ground truth, the noisy pixels and our estimates, so that other
/// solvers (scripts/opencv_compare) can be run on exactly the same inputs.
fn trials_csv(result: &AblationResult) -> String {
    let kmax = result
        .trials
        .iter()
        .map(|t| t.pixels.len())
        .max()
        .unwrap_or(0);
    let mut s = String::from(
        "part,distance_m,axis,noise_px,trial,class,gt_tx,gt_ty,gt_tz,gt_rx,gt_ry,gt_rz",
    );
    for m in Method::ALL {
        for f in ["tx", "ty", "tz", "rx", "ry", "rz"] {
            let _ = write!(s, ",{}_{f}", m.name());
        }
    }
    for k in 0..kmax {
        let _ = write!(s, ",u{k},v{k}");
    }
    s.push('\n');
    for t in &result.trials {
        let _ = write!(
            s,
            "{},{},{},{},{},{},{}",
            t.part,
            t.distance_m,
            t.axis.name(),
            t.noise_px,
            t.index,
            t.class,
            pose_fields(Some(&t.camera_T_part))
        );
        for e in &t.estimates {
            let _ = write!(s, ",{}", pose_fields(e.as_ref()));
        }
        for k in 0..kmax {
            match t.pixels.get(k) {
                Some(p) => {
                    let _ = write!(s, ",{:.9},{:.9}", p.x, p.y);
                }
                None => s.push_str(",,"),
            }
        }
        s.push('\n');
    }
    s
}

fn setup_json(config: &AblationConfig, parts: &[AblationPart]) -> anyhow::Result<String> {
    let parts: Vec<serde_json::Value> = parts
        .iter()
        .map(|p| {
            serde_json::json!({
                "name": p.name,
                "keypoints": p.keypoints.iter().map(|k| [k.x, k.y, k.z]).collect::<Vec<_>>(),
            })
        })
        .collect();
    let c = &config.camera;
    Ok(serde_json::to_string_pretty(&serde_json::json!({
        "camera": {
            "width": c.width, "height": c.height,
            "K": [[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]],
            "dist": c.distortion.as_array(),
        },
        "noise": "Gaussian, sigma = noise_px, along x, y or both (iso)",
        "errors": "camera frame: |dx|, |dy|, |dz| in mm; geodesic angle in degrees",
        "parts": parts,
    }))?)
}

fn row(rows: &[AblationRow], d: f64, axis: NoiseAxis, n: f64, m: Method) -> Option<&AblationRow> {
    rows.iter()
        .find(|r| r.distance_m == d && r.axis == axis && r.noise_px == n && r.method == m)
}

fn table(config: &AblationConfig, rows: &[AblationRow]) -> String {
    let mut s = String::new();
    for &axis in &config.axes {
        let _ = writeln!(
            s,
            "\nkeypoint noise along {} (mean of |error|; PnP → planar refinement → planar + keypoint fit)",
            match axis {
                NoiseAxis::X => "x",
                NoiseAxis::Y => "y",
                NoiseAxis::Iso => "x and y (isotropic)",
            }
        );
        let _ = writeln!(
            s,
            "{:>5} {:>6} | {:>6} {:>6} {:>7} {:>6} | {:>6} {:>6} {:>6} {:>6} | {:>6} {:>6} | {:>5}",
            "σ px",
            "d m",
            "ex mm",
            "ey mm",
            "ez mm",
            "eθ °",
            "ex mm",
            "ey mm",
            "ez mm",
            "eθ °",
            "ex mm",
            "eθ °",
            "class"
        );
        for &n in &config.noise_px {
            for &d in &config.distances_m {
                let (Some(p), Some(q), Some(f)) = (
                    row(rows, d, axis, n, Method::Pnp),
                    row(rows, d, axis, n, Method::Planar),
                    row(rows, d, axis, n, Method::PlanarFit),
                ) else {
                    continue;
                };
                let _ = writeln!(
                    s,
                    "{:>5.1} {:>6.2} | {:>6.3} {:>6.3} {:>7.2} {:>6.2} | {:>6.3} {:>6.3} {:>6.3} {:>6.2} | {:>6.3} {:>6.2} | {:>4.0}%",
                    n,
                    d,
                    p.summary.x_mm.mean,
                    p.summary.y_mm.mean,
                    p.summary.z_mm.mean,
                    p.summary.angle_deg.mean,
                    q.summary.x_mm.mean,
                    q.summary.y_mm.mean,
                    q.summary.z_mm.mean,
                    q.summary.angle_deg.mean,
                    f.summary.x_mm.mean,
                    f.summary.angle_deg.mean,
                    q.class_accuracy * 100.0
                );
            }
        }
    }
    s
}

fn plot_axis(
    path: &Path,
    config: &AblationConfig,
    rows: &[AblationRow],
    axis: NoiseAxis,
) -> anyhow::Result<()> {
    cell::report::plots::register_font();
    let size = (1800, 900);
    if path.extension().is_some_and(|e| e == "svg") {
        let root = SVGBackend::new(path, size).into_drawing_area();
        draw(&root, config, rows, axis)?;
        root.present()?;
    } else {
        let root = BitMapBackend::new(path, size).into_drawing_area();
        draw(&root, config, rows, axis)?;
        root.present()?;
    }
    Ok(())
}

type Metric = (&'static str, fn(&AblationRow) -> f64);

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    config: &AblationConfig,
    rows: &[AblationRow],
    axis: NoiseAxis,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
    let metrics: [Metric; 4] = [
        ("e_x (mm)", |r| r.summary.x_mm.mean),
        ("e_y (mm)", |r| r.summary.y_mm.mean),
        ("e_z (mm)", |r| r.summary.z_mm.mean),
        ("e_θ (deg)", |r| r.summary.angle_deg.mean),
    ];
    let title = format!(
        "Mean pose error against keypoint noise σ {} at each camera distance: PnP (top), after planar refinement (bottom)",
        match axis {
            NoiseAxis::X => "along x",
            NoiseAxis::Y => "along y",
            NoiseAxis::Iso => "in x and y",
        }
    );
    let root = root
        .titled(&title, ("sans-serif", 24))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let panels = root.split_evenly((2, 4));
    let colours = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
    ];
    let nmax = config
        .noise_px
        .iter()
        .cloned()
        .fold(0.0, f64::max)
        .max(1e-3);
    for (pi, panel) in panels.iter().enumerate() {
        let method = if pi < 4 { Method::Pnp } else { Method::Planar };
        let (label, f) = metrics[pi % 4];
        let series: Vec<(f64, Vec<(f64, f64)>)> = config
            .distances_m
            .iter()
            .map(|&d| {
                let pts = config
                    .noise_px
                    .iter()
                    .filter_map(|&n| row(rows, d, axis, n, method).map(|r| (n, f(r))))
                    .filter(|(_, v)| v.is_finite())
                    .collect();
                (d, pts)
            })
            .collect();
        let ymax = series
            .iter()
            .flat_map(|(_, p)| p.iter().map(|(_, v)| *v))
            .fold(0.0, f64::max)
            .max(0.01)
            * 1.1;
        let caption = format!("{} — {}", method.name(), label);
        let mut chart = ChartBuilder::on(panel)
            .caption(caption, ("sans-serif", 18))
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..nmax, 0.0..ymax)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        chart
            .configure_mesh()
            .x_desc("keypoint noise σ (px)")
            .y_desc(label)
            .y_label_formatter(&|v| {
                let d = cell::report::plots::tick_decimals(ymax, 10);
                format!("{v:.d$}")
            })
            .draw()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        for (i, (d, pts)) in series.into_iter().enumerate() {
            let colour = colours[i % colours.len()];
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .label(format!("{d:.2} m"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_levels_cover_the_range() {
        assert_eq!(noise_levels(5.0, 0.5).unwrap().len(), 11);
        assert_eq!(
            noise_levels(1.0, 0.3).unwrap(),
            vec![0.0, 0.3, 0.6, 0.8999999999999999]
        );
        assert!(noise_levels(1.0, 0.0).is_err());
        assert!(noise_levels(f64::NAN, 1.0).is_err());
    }
}
