//! PnP + refinement on the 9 keypoints of a USB-C-sized part at 1.6 m (goal ≤ 20 µs).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector2};
use perception::Camera;
use perception::pnp::solve_pnp;

/// The stand-in shell's keypoints: eight near its box corners plus the centre, like the seed's.
fn keypoints() -> Vec<Point3<f64>> {
    perception::ablation::AblationPart::synthetic_shell().keypoints
}

fn bench(c: &mut Criterion) {
    let cam = Camera::basler_seed();
    let model = keypoints();
    let truth = Isometry3::from_parts(
        Translation3::new(0.03, -0.02, 1.6),
        UnitQuaternion::from_euler_angles(2.9, 0.1, 0.7),
    );
    // Deterministic ±1 px perturbations: refinement has work to do.
    let pixels: Vec<Point2<f64>> = model
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let s = i as f64;
            cam.project(&(truth * p)).unwrap() + Vector2::new((s * 1.7).sin(), (s * 2.3).cos())
        })
        .collect();
    c.bench_function("pnp_sqpnp_lm_9_points", |b| {
        b.iter(|| solve_pnp(black_box(&cam), black_box(&model), black_box(&pixels), None).unwrap())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
