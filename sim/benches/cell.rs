//! Simulated-cell benchmarks: pick-and-insert episodes for the three parts (sampled feeder,
//! analytic scoring, perception excluded) one at a time and 2 cores at a time, and one
//! contact-simulated insertion per contact engine (rapier, and MuJoCo when built in).
//!
//! `cargo bench -p sim --bench cell` (`-- insertion` for the contact engines only)

#![allow(missing_docs, non_snake_case)]

use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Vector2};
use rayon::prelude::*;
use sim::cad::usbc;
use sim::cell::geometry::PartGeometry;
use sim::cell::insertion::{InsertionCase, Mating, ReceiverPart, Scorer};
use sim::cell::{CellModel, SimCell};

#[path = "../tests/support/mod.rs"]
mod support;

use support::{arm, catalog, scenario, script};

fn episodes(c: &mut Criterion) {
    let s = scenario();
    let model: Arc<CellModel> = CellModel::new(
        &s.cell,
        &arm(),
        &s.assembly,
        &s.noise,
        &catalog(),
        Scorer::Analytic,
    )
    .unwrap();
    let mut episode = 0u64;
    c.bench_function("cell/episode_analytic_1_core", |b| {
        b.iter(|| {
            episode += 1;
            let mut cell = SimCell::new(model.clone(), 7, episode).unwrap();
            black_box(script::run_episode(&mut cell).unwrap())
        })
    });
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let batch = 200u64;
    let mut group = c.benchmark_group("cell");
    group.throughput(Throughput::Elements(batch));
    group.sample_size(10);
    let mut first = 0u64;
    group.bench_function("episodes_analytic_2_cores", |b| {
        b.iter(|| {
            first += batch;
            let seated: usize = pool.install(|| {
                (first..first + batch)
                    .into_par_iter()
                    .map(|e| {
                        let mut cell = SimCell::new(model.clone(), 7, e).unwrap();
                        usize::from(script::run_episode(&mut cell).unwrap().success)
                    })
                    .sum()
            });
            black_box(seated)
        })
    });
    group.finish();
}

fn contact_insertion(c: &mut Criterion) {
    let s = scenario();
    let g = |name: &str, mesh| PartGeometry::from_mesh(name, mesh, 1e-3, vec![], vec![]).unwrap();
    let (shell, insert, nest) = (
        g("main_shell", usbc::main_shell()),
        g("insert_mold", usbc::insert_mold()),
        g("fixture_nest", usbc::fixture_nest()),
    );
    let t = usbc::assembly_targets();
    let receivers = [
        ReceiverPart {
            geometry: &shell,
            destination_T_part: Isometry3::identity(),
        },
        ReceiverPart {
            geometry: &nest,
            destination_T_part: t.nest_t_main.inverse(),
        },
    ];
    let mating = Mating::new(&s.assembly[1], &insert, &receivers[..1]);
    // Inside the chamfer: the lead-in guides it, the typical case.
    let start = mating.pose_with_error(Vector2::new(8e-5, -5e-5), 0.0, 1e-3, 2e-3, Vector2::x());
    let case = InsertionCase {
        mating: &mating,
        held: &insert,
        receivers: &receivers,
        ins_T_part: start,
    };
    for (scorer, label) in [(Scorer::Contact, "contact"), (Scorer::Mujoco, "mujoco")] {
        // MuJoCo is absent from a build without sim's `mujoco` feature.
        let Ok(engine) = scorer.build() else { continue };
        c.bench_function(&format!("cell/{label}_insertion_insert_mold"), |b| {
            b.iter(|| black_box(engine.score(&case).unwrap()))
        });
    }
}

criterion_group!(benches, episodes, contact_insertion);
criterion_main!(benches);
