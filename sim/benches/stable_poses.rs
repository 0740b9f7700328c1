//! Stable-pose drops as `cell parts prepare` runs them: 5 000 drops for each of the three USB-C
//! parts of the committed catalog, on every core rayon has, with the default drop settings and
//! the catalog's drop height.
//! Prints wall time, CPU time (user + system, Linux) and each part's share of jittering drops.
//!
//! `cargo bench -p sim --bench stable_poses` (`-- DROPS` for another count per part, `-- FILE.toml`
//! for the parts of another catalog, `-- rest_time=S` for another rest time in seconds, `-- solver_iterations=N`,
//! `-- one_contact_per_point=0` for every triangle's contacts, `-- stop_when_trapped=0` to run
//! every drop to rest, `-- drop_height=M`, `-- friction=F`, `-- restitution=R`, `-- engine=mujoco`
//! for MuJoCo's drops).
//! One timed run, not criterion's repeats: a run takes tens of seconds.
//!
//! `-- paired rest_time=S` drops each part twice, with the default settings (or those changed
//! by `ref.NAME=VALUE` arguments: `-- paired ref.solver_iterations=24` compares with 24 iterations) and
//! with the changed ones, the same orientations in the same order, and counts the drops that came to
//! rest on another face (more than 0.2 rad apart): a paired comparison, far tighter than the
//! shares' sampling noise.
//!
//! `-- cylinder=64,4096,25000` drops generated cylinders (10 mm across, 6 mm tall) tessellated
//! with that many segments (4 triangles per segment) instead of a catalog's parts, and prints
//! each one's hull size, CPU seconds per drop and the share of drops on a cap and on the side,
//! with the full hull and with the simplified contact hull (paired: the same orientations;
//! `-- cylinder=N simplified` drops the simplified one only).

#![allow(missing_docs)]

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Vector3;
use perception::part::{Catalog, PartRole, TriMesh};
use rayon::prelude::*;
use sim::stable_poses::{
    DropBody, DropEngine, DropOutcome, DropSettings, simulate_batch, stable_poses_with,
};

/// CPU seconds this process has used (user + system), from /proc; `None` elsewhere.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name's closing parenthesis; utime and stime are the 12th and
    // 13th of them, in clock ticks (100 per second on Linux).
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let drops = args
        .iter()
        .find_map(|a| a.parse::<usize>().ok())
        .unwrap_or(5000);
    let path = args
        .iter()
        .find(|a| a.ends_with(".toml"))
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml")
        });
    let catalog = Catalog::load(&path).expect("a part catalog");
    let parts: Vec<_> = catalog
        .parts
        .iter()
        .filter(|p| p.role != PartRole::Fixture)
        .map(|p| {
            let (mesh, _) = catalog.load_mesh_repaired(p).expect("the part's mesh");
            (p, mesh)
        })
        .collect();
    // The catalog's own settings; `NAME=VALUE` arguments change them, `ref.NAME=VALUE` the
    // reference of a paired run.
    let base = DropSettings {
        drops,
        ..DropSettings::default()
    }
    .with_catalog(&catalog);
    let mut settings = base.clone();
    apply(&mut settings, &args, "");
    if let Some(list) = args.iter().find_map(|a| a.strip_prefix("cylinder=")) {
        for n in list.split(',') {
            let segments: usize = n.parse().expect("cylinder=SEGMENTS,...");
            fine_cylinder(segments, &settings, args.iter().any(|a| a == "simplified"));
        }
        return;
    }
    if args.iter().any(|a| a == "paired") {
        let mut reference = base;
        apply(&mut reference, &args, "ref.");
        for (part, mesh) in &parts {
            paired(&part.name, mesh, part.density(), &reference, &settings);
        }
        return;
    }
    let engine = args
        .iter()
        .find_map(|a| a.strip_prefix("engine="))
        .map_or(DropEngine::Rapier, |e| {
            DropEngine::from_name(e).expect("engine=rapier or engine=mujoco")
        });
    let (wall, cpu) = (Instant::now(), cpu_seconds());
    let mut total = 0;
    for (part, mesh) in &parts {
        let start = Instant::now();
        let report = stable_poses_with(engine, &part.name, mesh, part.density(), &settings, None)
            .expect("the drops");
        total += report.drops;
        println!(
            "{}: {} drops in {:.1} s, {} still jittering at the {} s limit, mean rest {:.3} s",
            part.name,
            report.drops,
            start.elapsed().as_secs_f64(),
            report.unsettled,
            settings.max_time,
            report.mean_rest_time
        );
        for class in &report.classes {
            let committed = part.stable_pose(&class.pose.name).map(|s| s.probability);
            println!(
                "  {:12} {:6.2} % (catalog {})",
                class.pose.name,
                100.0 * class.pose.probability,
                committed.map_or("-".into(), |p| format!("{:.2} %", 100.0 * p))
            );
        }
    }
    let cpu = match (cpu, cpu_seconds()) {
        (Some(a), Some(b)) => format!("{:.1} CPU-s", b - a),
        _ => "CPU time n/a".into(),
    };
    println!(
        "stable_poses: {total} drops of {} parts in {:.1} s wall, {cpu}, {} threads",
        parts.len(),
        wall.elapsed().as_secs_f64(),
        rayon::current_num_threads()
    );
}

/// Applies the `PREFIXname=value` arguments to `settings`.
fn apply(settings: &mut DropSettings, args: &[String], prefix: &str) {
    let value = |name: &str| {
        args.iter().find_map(|a| {
            a.strip_prefix(prefix)?
                .strip_prefix(name)?
                .strip_prefix('=')
        })
    };
    let flag = |v: &str| matches!(v, "1" | "true" | "on");
    if let Some(t) = value("rest_time") {
        settings.rest_time = t.parse().expect("rest_time=SECONDS");
    }
    if let Some(n) = value("solver_iterations") {
        settings.solver_iterations = n.parse().expect("solver_iterations=N");
    }
    if let Some(v) = value("one_contact_per_point") {
        settings.one_contact_per_point = flag(v);
    }
    if let Some(n) = value("batch") {
        settings.batch = n.parse().expect("batch=N");
    }
    if let Some(v) = value("stop_when_trapped") {
        settings.stop_when_trapped = flag(v);
    }
    if let Some(h) = value("drop_height") {
        settings.drop_height = h.parse().expect("drop_height=METRES");
    }
    if let Some(f) = value("friction") {
        settings.friction = f.parse().expect("friction=COEFFICIENT");
    }
    if let Some(r) = value("restitution") {
        settings.restitution = r.parse().expect("restitution=COEFFICIENT");
    }
}

/// Every drop's outcome in order, batched as [`stable_poses`] batches them, and the CPU seconds.
fn outcomes(body: &DropBody, settings: &DropSettings) -> (Vec<DropOutcome>, f64) {
    let cpu = cpu_seconds();
    let starts: Vec<usize> = (0..settings.drops).step_by(settings.batch).collect();
    let out = starts
        .par_iter()
        .flat_map_iter(|&first| {
            simulate_batch(
                body,
                settings,
                first,
                settings.batch.min(settings.drops - first),
            )
        })
        .collect();
    let spent = match (cpu, cpu_seconds()) {
        (Some(a), Some(b)) => b - a,
        _ => f64::NAN,
    };
    (out, spent)
}

/// Drops one part with both settings and prints how many drops rest on another face.
fn paired(name: &str, mesh: &TriMesh, density: f64, a: &DropSettings, b: &DropSettings) {
    let body = DropBody::new(mesh, density);
    let (first, cpu_a) = outcomes(&body, a);
    let (second, cpu_b) = outcomes(&body, b);
    let up = |o: &DropOutcome| o.rotation.inverse() * Vector3::z();
    let moved = first
        .iter()
        .zip(&second)
        .filter(|(x, y)| up(x).angle(&up(y)) > 0.2)
        .count();
    let unsettled = |o: &[DropOutcome]| o.iter().filter(|o| !o.settled).count();
    println!(
        "{name}: {moved} of {} drops rest on another face; {cpu_a:.1} CPU-s ({}, {} unsettled) \
         against {cpu_b:.1} CPU-s ({}, {} unsettled)",
        first.len(),
        describe(a),
        unsettled(&first),
        describe(b),
        unsettled(&second)
    );
    for (label, out) in [("reference", &first), ("changed", &second)] {
        let report = sim::stable_poses::cluster(out, mesh, (out.len() / 1000).max(2));
        let shares: Vec<String> = report
            .iter()
            .map(|c| {
                format!(
                    "{} {:.2} %",
                    c.pose.name,
                    100.0 * c.count as f64 / out.len() as f64
                )
            })
            .collect();
        println!("  {label}: {}", shares.join(", "));
    }
}

/// The settings a paired comparison varies, in words.
fn describe(s: &DropSettings) -> String {
    format!(
        "from {} mm, friction {}, restitution {}, rest {} s, {} iterations, contacts {}, {}",
        s.drop_height * 1e3,
        s.friction,
        s.restitution,
        s.rest_time,
        s.solver_iterations,
        if s.one_contact_per_point {
            "one per point"
        } else {
            "per triangle"
        },
        if s.stop_when_trapped {
            "stopped when trapped"
        } else {
            "run to rest"
        }
    )
}

/// A closed cylinder of `segments` sides around z, `radius` and `height` in metres, centred on
/// the origin: two fans of `segments` triangles for the caps, two triangles per side.
fn cylinder(segments: usize, radius: f64, height: f64) -> TriMesh {
    let mut vertices = Vec::with_capacity(2 * segments + 2);
    for z in [-height / 2.0, height / 2.0] {
        for k in 0..segments {
            let a = std::f64::consts::TAU * k as f64 / segments as f64;
            vertices.push(nalgebra::Point3::new(radius * a.cos(), radius * a.sin(), z));
        }
    }
    vertices.push(nalgebra::Point3::new(0.0, 0.0, -height / 2.0));
    vertices.push(nalgebra::Point3::new(0.0, 0.0, height / 2.0));
    let n = segments as u32;
    let (bottom, top) = (2 * n, 2 * n + 1);
    let mut triangles = Vec::with_capacity(4 * segments);
    for k in 0..n {
        let next = (k + 1) % n;
        triangles.push([bottom, next, k]);
        triangles.push([top, n + k, n + next]);
        triangles.push([k, next, n + next]);
        triangles.push([k, n + next, n + k]);
    }
    TriMesh::new(vertices, triangles)
}

/// Drops a cylinder of `segments` sides with its full hull and with the simplified contact
/// hull ([`DropBody::new`]), the same orientations, and prints hull sizes, CPU per drop, the
/// drops that rest on another face and the shares.
fn fine_cylinder(segments: usize, settings: &DropSettings, simplified_only: bool) {
    let mesh = cylinder(segments, 0.005, 0.006);
    let axis = |o: &DropOutcome| (o.rotation * Vector3::z()).z.abs();
    let mut runs = Vec::new();
    for (label, body) in [
        (
            "full hull",
            DropBody::with_hull_tolerance(&mesh, 1400.0, 0.0),
        ),
        ("simplified", DropBody::new(&mesh, 1400.0)),
    ]
    .into_iter()
    .skip(usize::from(simplified_only))
    {
        let (out, cpu) = outcomes(&body, settings);
        let cap = out.iter().filter(|o| axis(o) > 0.99).count();
        let side = out.iter().filter(|o| axis(o) < 0.01).count();
        let unsettled = out.iter().filter(|o| !o.settled).count();
        let (v, f) = body.contact_hull_size();
        println!(
            "cylinder {segments} segments ({} triangles), {label} {v} vertices {f} triangles: \
             {} drops, {:.4} CPU-s per drop; cap {:.2} %, side {:.2} %, {unsettled} unsettled",
            mesh.triangles.len(),
            out.len(),
            cpu / out.len() as f64,
            100.0 * cap as f64 / out.len() as f64,
            100.0 * side as f64 / out.len() as f64,
        );
        runs.push(out);
    }
    if runs.len() < 2 {
        return;
    }
    let moved = runs[0]
        .iter()
        .zip(&runs[1])
        .filter(|(a, b)| (axis(a) > 0.5) != (axis(b) > 0.5))
        .count();
    println!("  {moved} of {} drops rest on another face", runs[0].len());
}
