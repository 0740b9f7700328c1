//! Orchestrator throughput in the in-process simulated cell, keypoint-noise perception: whole
//! assemblies (three steps) per second on the rayon pool (`RAYON_NUM_THREADS=2` for the 2-core
//! figure), simulated cycle time, where it goes (the mean per orchestrator state) and success
//! rate over the same episodes, and criterion's time for one episode on one core.

use std::path::Path;
use std::time::Instant;

use cell::harness::{SimSetup, run_sim_episode_blocking};
use cell::scenario::Scenario;
use criterion::{Criterion, criterion_group, criterion_main};
use rayon::prelude::*;

fn setup() -> SimSetup {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
    let scenario = Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
    SimSetup::new(scenario).unwrap_or_else(|e| panic!("{e}"))
}

fn throughput(setup: &SimSetup, episodes: u32) {
    let start = Instant::now();
    let records: Vec<_> = (0..episodes)
        .into_par_iter()
        .map(|e| run_sim_episode_blocking(setup, e).map(|o| o.record))
        .collect::<Result<_, _>>()
        .unwrap_or_else(|e| panic!("{e}"));
    let wall = start.elapsed().as_secs_f64();
    let ok: Vec<_> = records.iter().filter(|r| r.success).collect();
    let mean_cycle = ok.iter().map(|r| r.cycle_time_s).sum::<f64>() / ok.len().max(1) as f64;
    let mut cycles: Vec<f64> = ok.iter().map(|r| r.cycle_time_s).collect();
    cycles.sort_by(f64::total_cmp);
    let max_cycle = cycles.last().copied().unwrap_or(0.0);
    // Nearest-rank 95th percentile.
    let p95 = cycles
        .get(((0.95 * cycles.len() as f64).ceil() as usize).saturating_sub(1))
        .copied()
        .unwrap_or(0.0);
    println!(
        "orchestrator: {episodes} episodes on {} threads in {wall:.2} s = {:.1} assemblies/s; \
         success {}/{episodes} ({:.1} %); simulated cycle mean {mean_cycle:.2} s, \
         p95 {p95:.2} s, max {max_cycle:.2} s",
        rayon::current_num_threads(),
        episodes as f64 / wall,
        ok.len(),
        100.0 * ok.len() as f64 / episodes as f64,
    );
    if let Some(line) = cell::run::phases::breakdown_line(&cell::run::phases::phase_means(&records))
    {
        println!("orchestrator: {line}");
    }
}

fn bench(c: &mut Criterion) {
    let setup = setup();
    throughput(&setup, 1000);
    let mut episode = 0u32;
    c.bench_function("sim_episode_keypoint_noise", |b| {
        b.iter(|| {
            episode = episode.wrapping_add(1);
            run_sim_episode_blocking(&setup, episode).unwrap_or_else(|e| panic!("{e}"))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
