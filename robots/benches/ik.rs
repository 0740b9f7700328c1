//! UR5e kinematics timings: FK, IK with all solutions, IK nearest to the current joints.
//!
//! Criterion measures wall-clock time. On a loaded machine that also counts time spent waiting
//! for a core, so the `on_cpu` group also reports this thread's on-CPU time per call from
//! `/proc/thread-self/schedstat` (Linux; the scheduler updates it every tick, so it is read
//! around loops of about two seconds).

#![allow(missing_docs)]

use criterion::measurement::{Measurement, WallTime};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Isometry3;
use robots::kinematics::{Joints, UrKinematics};
use std::hint::black_box;

/// Nanoseconds this thread has run on a CPU, per the scheduler.
fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

struct Fixture {
    kin: UrKinematics,
    configs: [Joints; 4],
    poses: Vec<Isometry3<f64>>,
}

fn fixture() -> Fixture {
    let kin = UrKinematics::ur5e();
    // Generic poses with all eight branches, spread over the workspace.
    let configs: [Joints; 4] = [
        [0.3, -1.2, 1.4, -1.9, -1.5, 2.8],
        [-1.1, -2.0, -1.0, 0.5, 1.2, -0.4],
        [2.0, -0.7, 2.1, -2.9, 0.6, 1.0],
        [0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
    ];
    let poses: Vec<_> = configs.iter().map(|q| kin.forward_tcp(q)).collect();
    for (q, pose) in configs.iter().zip(&poses) {
        assert_eq!(kin.inverse_all(pose, q[5]).unwrap().len(), 8, "{q:?}");
    }
    Fixture {
        kin,
        configs,
        poses,
    }
}

fn run<M: Measurement + 'static>(c: &mut Criterion<M>, prefix: &str) {
    let Fixture {
        kin,
        configs,
        poses,
    } = fixture();
    c.bench_function(&format!("{prefix}fk_tcp"), |b| {
        b.iter(|| kin.forward_tcp(black_box(&configs[0])))
    });
    c.bench_function(&format!("{prefix}ik_all_solutions"), |b| {
        b.iter(|| kin.inverse_all(black_box(&poses[0]), 0.0).unwrap())
    });
    c.bench_function(&format!("{prefix}ik_all_solutions_x4_poses"), |b| {
        b.iter(|| {
            for pose in &poses {
                black_box(kin.inverse_all(black_box(pose), 0.0).unwrap());
            }
        })
    });
    c.bench_function(&format!("{prefix}ik_nearest"), |b| {
        b.iter(|| {
            kin.inverse_nearest(black_box(&poses[0]), black_box(&configs[0]))
                .unwrap()
        })
    });
}

fn wall(c: &mut Criterion<WallTime>) {
    run(c, "");
}

/// On-CPU nanoseconds per call of `f`, over loops of about `seconds` of wall time.
fn on_cpu_ns_per_call(seconds: f64, mut f: impl FnMut()) -> Option<f64> {
    let wall = std::time::Instant::now();
    let start = thread_cpu_ns()?;
    let mut calls = 0u64;
    while wall.elapsed().as_secs_f64() < seconds {
        for _ in 0..1000 {
            f();
        }
        calls += 1000;
    }
    let spent = thread_cpu_ns()? - start;
    Some(spent as f64 / calls as f64)
}

fn on_cpu(_: &mut Criterion<WallTime>) {
    let Fixture {
        kin,
        configs,
        poses,
    } = fixture();
    let report = |name: &str, ns: Option<f64>| match ns {
        Some(ns) => eprintln!("on-CPU {name:<28} {ns:>9.1} ns/call"),
        None => eprintln!("on-CPU {name}: /proc/thread-self/schedstat unavailable"),
    };
    report(
        "fk_tcp",
        on_cpu_ns_per_call(2.0, || {
            black_box(kin.forward_tcp(black_box(&configs[0])));
        }),
    );
    report(
        "ik_all_solutions",
        on_cpu_ns_per_call(2.0, || {
            black_box(kin.inverse_all(black_box(&poses[0]), 0.0).unwrap());
        }),
    );
    report(
        "ik_all_solutions_x4_poses",
        on_cpu_ns_per_call(2.0, || {
            for pose in &poses {
                black_box(kin.inverse_all(black_box(pose), 0.0).unwrap());
            }
        }),
    );
    report(
        "ik_nearest",
        on_cpu_ns_per_call(2.0, || {
            black_box(
                kin.inverse_nearest(black_box(&poses[0]), black_box(&configs[0]))
                    .unwrap(),
            );
        }),
    );
}

criterion_group!(wall_clock, wall);
criterion_group!(on_cpu_time, on_cpu);
criterion_main!(wall_clock, on_cpu_time);
