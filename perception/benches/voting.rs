//! Voting for 9 keypoints on a 128 × 128 crop with ~3 000 foreground pixels, 20 % outlier
//! vectors (goal ≤ 2 ms on one core).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Point2;
use perception::voting::{VectorField, Voter, VotingConfig, keypoint_vector_labels};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SIZE: usize = 128;

fn bench(c: &mut Criterion) {
    let mut mask = vec![0u8; SIZE * SIZE];
    for y in 0..SIZE {
        for x in 0..SIZE {
            let (dx, dy) = ((x as f64 - 63.2) / 34.0, (y as f64 - 64.7) / 28.0);
            if dx * dx + dy * dy <= 1.0 {
                mask[y * SIZE + x] = 1;
            }
        }
    }
    let keypoints: Vec<Point2<f64>> = (0..9)
        .map(|i| {
            let a = f64::from(i) * 0.7;
            Point2::new(64.0 + 30.0 * a.cos(), 64.0 + 25.0 * a.sin())
        })
        .collect();
    let mut vectors = keypoint_vector_labels(SIZE, SIZE, &mask, &keypoints);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let plane = SIZE * SIZE;
    for k in 0..9 {
        for i in (0..plane).filter(|&i| mask[i] != 0) {
            if rng.random_bool(0.2) {
                let t: f32 = rng.random_range(0.0..std::f32::consts::TAU);
                vectors[2 * k * plane + i] = t.cos();
                vectors[(2 * k + 1) * plane + i] = t.sin();
            }
        }
    }
    let field = VectorField {
        width: SIZE,
        height: SIZE,
        keypoints: 9,
        mask: &mask,
        vectors: &vectors,
    };
    let mut voter = Voter::new(VotingConfig::default());
    c.bench_function("vote_9_keypoints_128px_3000fg", |b| {
        b.iter(|| voter.vote(black_box(&field)).unwrap())
    });
    let mut voter = Voter::new(VotingConfig {
        covariance_hypotheses: 0,
        ..VotingConfig::default()
    });
    c.bench_function("vote_9_keypoints_128px_3000fg_no_covariance", |b| {
        b.iter(|| voter.vote(black_box(&field)).unwrap())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
