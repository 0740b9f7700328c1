//! UR5e kinematics timings: FK, IK with all solutions, IK nearest to the current joints.

#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use robots::kinematics::{Joints, UrKinematics};
use std::hint::black_box;

fn bench_ik(c: &mut Criterion) {
    let kin = UrKinematics::ur5e();
    // A generic pose with all eight branches, and a few more spread over the workspace.
    let configs: [Joints; 4] = [
        [0.3, -1.2, 1.4, -1.9, -1.5, 2.8],
        [-1.1, -2.0, -1.0, 0.5, 1.2, -0.4],
        [2.0, -0.7, 2.1, -2.9, 0.6, 1.0],
        [0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
    ];
    let poses: Vec<_> = configs.iter().map(|q| kin.forward_tcp(q)).collect();
    for (q, pose) in configs.iter().zip(&poses) {
        let n = kin.inverse_all(pose, q[5]).unwrap().len();
        eprintln!("pose for {q:?}: {n} solutions");
    }

    c.bench_function("fk_tcp", |b| {
        b.iter(|| kin.forward_tcp(black_box(&configs[0])))
    });
    c.bench_function("ik_all_solutions", |b| {
        b.iter(|| kin.inverse_all(black_box(&poses[0]), 0.0).unwrap())
    });
    c.bench_function("ik_all_solutions_4_poses", |b| {
        b.iter(|| {
            for pose in &poses {
                black_box(kin.inverse_all(black_box(pose), 0.0).unwrap());
            }
        })
    });
    c.bench_function("ik_nearest", |b| {
        b.iter(|| {
            kin.inverse_nearest(black_box(&poses[0]), black_box(&configs[0]))
                .unwrap()
        })
    });
}

criterion_group!(benches, bench_ik);
criterion_main!(benches);
