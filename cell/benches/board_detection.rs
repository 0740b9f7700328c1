//! Board detection on a 20 MP frame (issue 42 goal: ≤ 200 ms per image on 2 cores, per stage):
//! one board rendered under the randomisation (seed 42, the first image of `cell board-study`),
//! pasted at its sensor origin into a 5472 × 3648 frame of noisy grey table. Timed: the
//! reference detector with sub-pixel refinement (`BoardDetector::detect`, 2 threads), the pose
//! (`board_pose`), and the two together.

#![allow(non_snake_case)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use perception::calibration::board_pose::board_pose;
use perception::calibration::detect::BoardDetector;
use perception::calibration::{Board, DetectorSettings};
use perception::{Camera, FrameImage};
use sim::scene::{Randomisation, board_render_settings, embed_in_full_frame, sample_board_view};

/// The full frame of the study's first board.
fn frame(board: &Board, camera: &Camera) -> FrameImage {
    let mut rng = sim::seed::stream_rng(42, 0, 0);
    let view = sample_board_view(board, camera, &Randomisation::default(), &mut rng)
        .unwrap_or_else(|e| panic!("{e}"));
    let window = view.window().expect("the board is in view");
    let image = view
        .render(window, &board_render_settings(), &mut rng)
        .unwrap_or_else(|e| panic!("{e}"));
    embed_in_full_frame(&image.image, camera, 90, 4)
}

fn bench(c: &mut Criterion) {
    let board = Board::seed();
    let camera = Camera::basler_seed();
    let frame = frame(&board, &camera);
    let settings = DetectorSettings::default();
    let mut detector = BoardDetector::new(&board, &settings).unwrap_or_else(|e| panic!("{e}"));
    let sighting = detector.detect(&frame).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(sighting.tags.len(), board.tags().len());
    let t = sighting.timings;
    eprintln!(
        "one detection: convert {:.1} ms, decode {:.1} ms, refine {:.1} ms",
        t.convert.as_secs_f64() * 1e3,
        t.decode.as_secs_f64() * 1e3,
        t.refine.as_secs_f64() * 1e3
    );
    let mut group = c.benchmark_group("board 20 MP, 2 threads");
    group.sample_size(20);
    group.bench_function("detect + refine", |b| {
        b.iter(|| black_box(detector.detect(black_box(&frame)).unwrap()))
    });
    group.bench_function("pose", |b| {
        b.iter(|| black_box(board_pose(&camera, &board, black_box(&sighting)).unwrap()))
    });
    group.bench_function("detect + refine + pose", |b| {
        b.iter(|| {
            let s = detector.detect(black_box(&frame)).unwrap();
            black_box(board_pose(&camera, &board, &s).unwrap())
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
