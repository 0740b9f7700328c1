//! `cell calibrate SCENARIO`: commission a cell. The camera's pose in the robot base and the
//! table plane, measured from one image of the tag board and pointer touches at its marks
//! (`--method touch`), or from a flange board the arm carries through planned poses and the
//! table board in the same images (`--method hand-eye`), are written into the scenario with
//! their uncertainty (the old values kept in a comment).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use cell::calibrate::commission::{CommissionOptions, Commissioned, Method, commission};
use cell::calibrate::evidence::{BaseEvidence, Calibration};
use cell::calibrate::hand_eye::{HandEyeOptions, MIN_HAND_EYE_VIEWS};
use cell::calibrate::record::{CalibrationRecord, write_calibration};
use cell::camera::CameraSpec;
use cell::run::{LoadedScenario, RobotTarget};
use nalgebra::{Isometry3, Matrix6, Vector3};
use perception::calibration::Board;
use perception::calibration::covariance::difference;

/// Arguments of `cell calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario to calibrate: its camera, board and limits are used, and the result is written
    /// back into it (unless --dry-run).
    pub scenario: PathBuf,
    /// The robot: `sim` (the simulated cell: a world whose camera and table sit a few mm and
    /// mrad from the scenario's poses, found again from rendered pixels and simulated touches),
    /// `virtual-ur` (the same behind a virtual UR on 127.0.0.1, over RTDE) or
    /// `ur://HOST[:PORT]` (a real controller: with --method touch you jog the pointer onto each
    /// mark at the pendant and confirm on this terminal, the TCP read over RTDE and nothing
    /// commanded; --method hand-eye moves the arm and needs --allow-motion and --camera).
    #[arg(long, default_value = "sim")]
    pub robot: RobotTarget,
    /// The camera that sees the board (only with --robot ur://HOST): `folder:/path`,
    /// `cmd:'grab --out {path}'`, `files:/path` or `aravis:[DEVICE]`, as for `cell run`.
    #[arg(long, value_name = "SPEC")]
    pub camera: Option<CameraSpec>,
    /// Length of the pointer along the tool's z axis beyond the controller's TCP, metres (0
    /// when the controller's TCP is set to the pointer's tip).
    #[arg(long, default_value_t = 0.05, value_name = "M")]
    pub pointer_length: f64,
    /// The farthest a touch may lie from where the other touches put it, mm; a worse touch is
    /// named and refused.
    #[arg(long, default_value_t = 0.5, value_name = "MM")]
    pub touch_bound: f64,
    /// The per-axis 1σ of one touch, mm, which the fit's covariance assumes (default: the
    /// scenario's `noise.robot_repeatability`).
    #[arg(long, value_name = "MM")]
    pub touch_sigma: Option<f64>,
    /// How the board is found in the robot base: `touch` (pointer touches at its marks, the arm
    /// only read) or `hand-eye` (the arm carries a flange board through planned poses in view
    /// of the camera; on a real controller it needs --allow-motion and --camera).
    #[arg(long, value_enum, default_value_t = Method::Touch)]
    pub method: Method,
    /// The board the arm carries for --method hand-eye (a board file, e.g.
    /// scenarios/boards/flange.toml, whose ids are not on the table board); default: 2 × 2
    /// tag36h11 tags from id 16 on an 8 cm plate, as scenarios/boards/flange.toml.
    #[arg(long, value_name = "FILE")]
    pub flange_board: Option<PathBuf>,
    /// Poses planned for --method hand-eye.
    #[arg(long, default_value_t = 12, value_name = "N")]
    pub poses: usize,
    /// Allow a real arm to move (--method hand-eye on --robot ur://HOST).
    #[arg(long)]
    pub allow_motion: bool,
    /// Seed of the simulated world (its mount error, lights and sensor); simulation only.
    #[arg(long, default_value_t = 1)]
    pub world_seed: u64,
    /// Measure and print, but leave the scenario file as it is.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let loaded = LoadedScenario::load(&args.scenario)?;
    let scenario = &loaded.scenario;
    anyhow::ensure!(
        args.camera.is_none() || matches!(args.robot, RobotTarget::Ur { .. }),
        "--camera is for a real controller (--robot ur://HOST); the simulated cell renders its \
         own camera"
    );
    anyhow::ensure!(
        args.pointer_length.is_finite() && (0.0..=0.5).contains(&args.pointer_length),
        "--pointer-length {} m: expected 0 to 0.5 m",
        args.pointer_length
    );
    anyhow::ensure!(
        args.touch_bound.is_finite() && args.touch_bound > 0.0,
        "--touch-bound {} mm: expected a positive number",
        args.touch_bound
    );
    let touch_sigma = args
        .touch_sigma
        .map_or(scenario.spec.noise.robot_repeatability, |s| s * 1e-3);
    anyhow::ensure!(
        touch_sigma.is_finite() && touch_sigma > 0.0,
        "--touch-sigma {touch_sigma} mm: expected a positive number"
    );
    anyhow::ensure!(
        args.method == Method::HandEye || (args.flange_board.is_none() && !args.allow_motion),
        "--flange-board and --allow-motion are for --method hand-eye; touch points never move \
         the arm"
    );
    anyhow::ensure!(
        !args.allow_motion || matches!(args.robot, RobotTarget::Ur { .. }),
        "--allow-motion is for a real controller (--robot ur://HOST); the simulated arms move \
         without it"
    );
    anyhow::ensure!(
        (MIN_HAND_EYE_VIEWS..=200).contains(&args.poses),
        "--poses {}: expected {MIN_HAND_EYE_VIEWS} to 200",
        args.poses
    );
    let flange_board = args
        .flange_board
        .as_deref()
        .map(Board::load)
        .transpose()
        .context("reading the flange board")?;
    let options = CommissionOptions {
        tip: Vector3::new(0.0, 0.0, args.pointer_length),
        bound: args.touch_bound * 1e-3,
        touch_sigma,
        world_seed: args.world_seed,
        method: args.method,
        hand_eye: HandEyeOptions {
            poses: args.poses,
            ..HandEyeOptions::default()
        },
        flange_board,
        allow_motion: args.allow_motion,
        ..CommissionOptions::default()
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let Commissioned { calibration, truth } = runtime
        .block_on(commission(
            scenario,
            &args.robot,
            args.camera.as_ref(),
            &options,
        ))
        .with_context(|| format!("calibrating {} on {}", args.scenario.display(), args.robot))?;
    print_calibration(&calibration);
    let board_layout = scenario
        .spec
        .cell
        .board_layout()
        .context("the scenario's board was not read")?;
    if let Some(truth) = truth {
        let cam = difference(&truth.base_T_camera, &calibration.base_T_camera);
        let table = difference(&truth.base_T_table, &calibration.base_T_table);
        println!(
            "simulation only, against the simulator's truth: camera off by {:.3} mm and {:.1} µrad, \
             table by {:.3} mm and {:.1} µrad",
            cam.fixed_rows::<3>(0).norm() * 1e3,
            cam.fixed_rows::<3>(3).norm() * 1e6,
            table.fixed_rows::<3>(0).norm() * 1e3,
            table.fixed_rows::<3>(3).norm() * 1e6,
        );
        // What matters to the cell: where a part it sees on the table is placed in the base.
        let (shift, at) = truth.placement_error(
            &calibration.base_T_camera,
            &calibration.base_T_table,
            &board_layout,
        );
        println!(
            "  a part seen on the board is placed at most {:.3} mm off (at the board's {at})",
            shift * 1e3
        );
    }
    if args.dry_run {
        println!("--dry-run: {} left as it was", args.scenario.display());
        return Ok(ExitCode::SUCCESS);
    }
    // The scenario's board file, as a path from here (the record writes it relative to the
    // scenario again); none for the seed's built-in board.
    let board = scenario.spec.cell.board.as_ref().map(|b| {
        args.scenario
            .parent()
            .unwrap_or(std::path::Path::new("."))
            .join(b)
    });
    let record = CalibrationRecord {
        base_T_camera: calibration.base_T_camera,
        base_T_table: calibration.base_T_table,
        camera_covariance: calibration.camera_covariance,
        table_covariance: calibration.table_covariance,
        method: args.method.recorded(),
        rms_px: calibration.board_pose.rms_px,
        tags: calibration.sighting.tags.len() as u32,
        board,
        date: std::time::SystemTime::now(),
    };
    write_calibration(&args.scenario, &record)
        .with_context(|| format!("writing the calibration into {}", args.scenario.display()))?;
    println!(
        "wrote base_T_camera, base_T_table and [cell.calibration] into {} (the old poses are \
         kept in a comment)",
        args.scenario.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// 1σ of a pose covariance: translation (mm) and rotation (µrad), per axis of the parent frame.
fn sigmas(c: &Matrix6<f64>) -> ([f64; 3], [f64; 3]) {
    let s = |i: usize| c[(i, i)].max(0.0).sqrt();
    (
        [s(0) * 1e3, s(1) * 1e3, s(2) * 1e3],
        [s(3) * 1e6, s(4) * 1e6, s(5) * 1e6],
    )
}

/// A pose as the scenario writes it.
fn pose_text(p: &Isometry3<f64>) -> String {
    let t = p.translation.vector;
    let r = p.rotation.scaled_axis();
    format!(
        "translation [{:.6}, {:.6}, {:.6}] m, rotation [{:.6}, {:.6}, {:.6}] rad",
        t.x, t.y, t.z, r.x, r.y, r.z
    )
}

fn print_calibration(c: &Calibration) {
    let s = &c.sighting;
    println!(
        "board: {} tags decoded in {:.0} ms; reprojection RMS {:.3} px",
        s.tags.len(),
        s.timings.total().as_secs_f64() * 1e3,
        c.board_pose.rms_px
    );
    match &c.base {
        BaseEvidence::Touch { touches, fit } => {
            let worst = fit
                .distances_from_others
                .iter()
                .enumerate()
                .fold((0, 0.0), |a, (i, &d)| if d > a.1 { (i, d) } else { a });
            println!(
                "touch points: {}, RMS {:.3} mm; farthest from the others: {} at {:.3} mm",
                touches.len(),
                fit.rms * 1e3,
                touches[worst.0].name,
                worst.1 * 1e3
            );
        }
        BaseEvidence::HandEye(e) => {
            let worst = e
                .solution
                .residuals
                .iter()
                .map(|r| r.mahalanobis)
                .fold(0.0, f64::max);
            let rms =
                (e.views.iter().map(|v| v.1 * v.1).sum::<f64>() / e.views.len() as f64).sqrt();
            println!(
                "hand-eye: {} of {} planned poses used (left out: {}); flange board \
                 reprojection RMS {:.3} px; worst view residual {:.2} σ",
                e.views.len(),
                e.planned,
                e.left_out.describe(),
                rms,
                worst
            );
            let b = e.solution.flange_T_board;
            println!(
                "  flange board on the TCP: translation [{:.2}, {:.2}, {:.2}] mm",
                b.translation.x * 1e3,
                b.translation.y * 1e3,
                b.translation.z * 1e3
            );
        }
    }
    for (name, pose, cov) in [
        ("base_T_camera", &c.base_T_camera, &c.camera_covariance),
        ("base_T_table", &c.base_T_table, &c.table_covariance),
    ] {
        let (t, r) = sigmas(cov);
        println!("{name}: {}", pose_text(pose));
        println!(
            "  1σ: x {:.3} y {:.3} z {:.3} mm; about x {:.1} y {:.1} z {:.1} µrad",
            t[0], t[1], t[2], r[0], r[1], r[2]
        );
    }
}
