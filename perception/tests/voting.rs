//! Keypoint voting on synthetic vector fields of a 128 × 128 crop.

use nalgebra::Point2;
use perception::voting::{
    VectorField, VoteError, Voter, VotingConfig, keypoint_vector_labels, vote_keypoints,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SIZE: usize = 128;

/// An elliptical blob of about 3 000 foreground pixels, like a part in a seed crop.
fn mask() -> Vec<u8> {
    let mut m = vec![0u8; SIZE * SIZE];
    for y in 0..SIZE {
        for x in 0..SIZE {
            let dx = (x as f64 - 63.2) / 34.0;
            let dy = (y as f64 - 64.7) / 28.0;
            if dx * dx + dy * dy <= 1.0 {
                m[y * SIZE + x] = 1;
            }
        }
    }
    m
}

/// Nine keypoints: eight spread over (and one beyond) the blob, and its centre.
fn keypoints() -> Vec<Point2<f64>> {
    vec![
        Point2::new(40.3, 45.7),
        Point2::new(88.9, 42.2),
        Point2::new(91.4, 85.05),
        Point2::new(37.77, 83.3),
        Point2::new(55.5, 52.25),
        Point2::new(72.1, 76.9),
        Point2::new(108.6, 64.2),
        Point2::new(64.0, 20.5),
        Point2::new(63.2, 64.7),
    ]
}

#[test]
fn clean_field_recovers_keypoints_to_a_twentieth_of_a_pixel() {
    let m = mask();
    let count = m.iter().filter(|&&v| v != 0).count();
    assert!((2800..3200).contains(&count), "{count} foreground pixels");
    let kps = keypoints();
    let vectors = keypoint_vector_labels(SIZE, SIZE, &m, &kps);
    let field = VectorField {
        width: SIZE,
        height: SIZE,
        keypoints: kps.len(),
        mask: &m,
        vectors: &vectors,
    };
    let votes = vote_keypoints(&field, VotingConfig::default()).unwrap();
    for (v, kp) in votes.iter().zip(&kps) {
        let err = (v.position - kp).norm();
        assert!(err < 0.05, "keypoint {kp}: error {err} px");
        assert!(v.inlier_ratio > 0.99, "{}", v.inlier_ratio);
        assert!(v.covariance.symmetric_eigenvalues().min() > 0.0);
        assert!(
            v.covariance.trace() < 0.01,
            "clean field spread {}",
            v.covariance
        );
    }
}

#[test]
fn thirty_percent_outliers_stay_under_half_a_pixel() {
    let m = mask();
    let kps = keypoints();
    let mut vectors = keypoint_vector_labels(SIZE, SIZE, &m, &kps);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let plane = SIZE * SIZE;
    let mut noisy_spread = 0.0;
    for k in 0..kps.len() {
        for i in (0..plane).filter(|&i| m[i] != 0) {
            // Small angular noise on every vector (a real network is never exact) …
            let a: f64 = rng.random_range(-0.02..0.02);
            let (x, y) = (
                f64::from(vectors[2 * k * plane + i]),
                f64::from(vectors[(2 * k + 1) * plane + i]),
            );
            let (s, c) = a.sin_cos();
            vectors[2 * k * plane + i] = (c * x - s * y) as f32;
            vectors[(2 * k + 1) * plane + i] = (s * x + c * y) as f32;
            // … and 30 % pointing anywhere.
            if rng.random_bool(0.3) {
                let t: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                vectors[2 * k * plane + i] = t.cos() as f32;
                vectors[(2 * k + 1) * plane + i] = t.sin() as f32;
            }
        }
    }
    let field = VectorField {
        width: SIZE,
        height: SIZE,
        keypoints: kps.len(),
        mask: &m,
        vectors: &vectors,
    };
    let votes = vote_keypoints(&field, VotingConfig::default()).unwrap();
    for (v, kp) in votes.iter().zip(&kps) {
        let err = (v.position - kp).norm();
        assert!(err < 0.5, "keypoint {kp}: error {err} px");
        assert!((0.6..0.8).contains(&v.inlier_ratio), "{}", v.inlier_ratio);
        noisy_spread += v.covariance.trace();
    }
    assert!(noisy_spread > 9.0 * 0.01, "noise must widen the covariance");
}

#[test]
fn voting_is_deterministic_by_seed_and_reuses_its_voter() {
    let m = mask();
    let kps = keypoints();
    let mut vectors = keypoint_vector_labels(SIZE, SIZE, &m, &kps);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for v in vectors.iter_mut() {
        if *v != 0.0 && rng.random_bool(0.2) {
            *v = rng.random_range(-1.0..1.0);
        }
    }
    let field = VectorField {
        width: SIZE,
        height: SIZE,
        keypoints: kps.len(),
        mask: &m,
        vectors: &vectors,
    };
    let mut voter = Voter::new(VotingConfig::default());
    let a = voter.vote(&field).unwrap();
    let b = voter.vote(&field).unwrap();
    assert_eq!(a, b);
    let other = vote_keypoints(
        &field,
        VotingConfig {
            seed: 1,
            ..VotingConfig::default()
        },
    )
    .unwrap();
    assert_ne!(a, other, "a different seed draws different hypotheses");
}

#[test]
fn bad_fields_are_typed_errors() {
    let m = mask();
    let kps = keypoints();
    let vectors = keypoint_vector_labels(SIZE, SIZE, &m, &kps);
    let cfg = VotingConfig::default();
    let empty = vec![0u8; SIZE * SIZE];
    let field = |mask: &'static [u8], vectors: &'static [f32]| VectorField {
        width: SIZE,
        height: SIZE,
        keypoints: 9,
        mask,
        vectors,
    };
    let empty: &'static [u8] = Box::leak(empty.into_boxed_slice());
    let m: &'static [u8] = Box::leak(m.into_boxed_slice());
    let vectors: &'static [f32] = Box::leak(vectors.into_boxed_slice());
    assert_eq!(
        vote_keypoints(&field(empty, vectors), cfg),
        Err(VoteError::EmptyMask)
    );
    assert!(matches!(
        vote_keypoints(&field(m, &vectors[1..]), cfg),
        Err(VoteError::ShapeMismatch {
            what: "vectors",
            ..
        })
    ));
    assert!(matches!(
        vote_keypoints(&field(&m[1..], vectors), cfg),
        Err(VoteError::ShapeMismatch { what: "mask", .. })
    ));
    let mut nan = vectors.to_vec();
    let first = m.iter().position(|&v| v != 0).unwrap();
    nan[first] = f32::NAN;
    let nan: &'static [f32] = Box::leak(nan.into_boxed_slice());
    assert!(matches!(
        vote_keypoints(&field(m, nan), cfg),
        Err(VoteError::NonFinite { keypoint: 0, .. })
    ));
    let zeros: &'static [f32] = Box::leak(vec![0.0f32; vectors.len()].into_boxed_slice());
    assert!(matches!(
        vote_keypoints(&field(m, zeros), cfg),
        Err(VoteError::TooFewPixels {
            keypoint: 0,
            usable: 0
        })
    ));
    // All vectors parallel: lines never meet.
    let mut parallel = vec![0.0f32; vectors.len()];
    let plane = SIZE * SIZE;
    for k in 0..9 {
        for i in 0..plane {
            if m[i] != 0 {
                parallel[2 * k * plane + i] = 1.0;
            }
        }
    }
    let parallel: &'static [f32] = Box::leak(parallel.into_boxed_slice());
    assert_eq!(
        vote_keypoints(&field(m, parallel), cfg),
        Err(VoteError::NoHypothesis { keypoint: 0 })
    );
    assert!(matches!(
        vote_keypoints(
            &VectorField {
                width: 0,
                height: SIZE,
                keypoints: 9,
                mask: &[],
                vectors: &[]
            },
            cfg
        ),
        Err(VoteError::EmptyField { .. })
    ));
}
