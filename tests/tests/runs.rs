//! Runs, results files, shards and merges: resumable, refusing foreign or corrupt files, shards
//! merging to exactly the unsharded result.
//!
//! The episode function here is test data for the harness (storage, resume, sharding, merge,
//! summary), not a simulation: each record is a fixed function of (seed, episode), which is
//! exactly the determinism the real orchestrator guarantees, so equalities can be exact.

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::path::Path;

use cell::episode::{EpisodeRecord, PoseError, RECORD_VERSION, StepOutcome, StepRecord};
use cell::run::{
    LoadedScenario, MergeError, RESULTS_FILE, ResultsHeader, ResultsStore, RunError, RunOptions,
    Shard, StoreError, Summary, merge, read_results, results_dir, run_episodes, write_results,
};
use cell::scenario::Scenario;

fn nominal() -> LoadedScenario {
    LoadedScenario::load(&cell_tests::repo_root().join("scenarios/usbc_nominal.toml"))
        .expect("the nominal scenario is valid")
}

/// A fixed pseudo-random function of (seed, episode, salt): the project's one seed splitter.
fn mix(seed: u64, episode: u32, salt: u64) -> u64 {
    sim::seed::split_seed(sim::seed::split_seed(seed, salt), u64::from(episode))
}

fn unit(seed: u64, episode: u32, salt: u64) -> f64 {
    (mix(seed, episode, salt) >> 11) as f64 / (1u64 << 53) as f64
}

/// A deterministic record for (scenario, episode): three steps, the second failing for about
/// one episode in five with a named error source after two insertions; about one seated step in
/// four seats on its second insertion.
fn record(s: &Scenario, episode: u32) -> EpisodeRecord {
    let seed = s.spec.seed;
    let parts = ["main_shell", "insert_mold", "top_shell"];
    let mut steps = Vec::new();
    let mut success = true;
    for (i, part) in parts.iter().enumerate() {
        let u = unit(seed, episode, i as u64);
        let failed = i == 1 && u < 0.2;
        let outcome = if failed {
            if u < 0.1 {
                StepOutcome::Jammed
            } else {
                StepOutcome::Missed
            }
        } else {
            StepOutcome::Seated
        };
        steps.push(StepRecord {
            part: (*part).into(),
            outcome,
            attempts: 1 + (mix(seed, episode, 10 + i as u64) % 2) as u32,
            // A failed step used its second insertion; about one seated step in four needed one.
            insertion_attempts: if failed {
                2
            } else {
                1 + u32::from(mix(seed, episode, 80 + i as u64).is_multiple_of(4))
            },
            shakes: (mix(seed, episode, 20 + i as u64) % 3) as u32,
            cause: failed.then(|| "lateral error beyond the chamfer".into()),
            sources: if failed {
                vec!["perception".into(), "robot_repeatability".into()]
            } else {
                vec![]
            },
            pose_error: Some(PoseError {
                dx_mm: 0.1 * (unit(seed, episode, 30 + i as u64) - 0.5),
                dy_mm: 0.1 * (unit(seed, episode, 40 + i as u64) - 0.5),
                depth_mm: if failed { 0.4 } else { 0.0 },
                tilt_deg: unit(seed, episode, 50 + i as u64),
                yaw_deg: unit(seed, episode, 60 + i as u64) - 0.5,
            }),
            perception_error: None,
            perception_verdict: None,
            confidence: None,
            sim_time_s: 4.0 + unit(seed, episode, 70 + i as u64),
            force: None,
            seat_check: None,
        });
        if failed {
            success = false;
            break;
        }
    }
    EpisodeRecord {
        version: RECORD_VERSION,
        scenario: s.spec.name.clone(),
        seed,
        episode,
        success,
        cycle_time_s: steps.iter().map(|t| t.sim_time_s).sum(),
        steps,
        wall_time_s: 0.01,
        abort: None,
        phases: vec![],
    }
}

/// The infallible episode function `f` in the runner's fallible shape.
fn ok(
    f: impl Fn(&Scenario, u32) -> EpisodeRecord + Sync,
) -> impl Fn(&Scenario, u32) -> Result<EpisodeRecord, Infallible> + Sync {
    move |s, e| Ok(f(s, e))
}

fn options(episodes: u32) -> RunOptions {
    RunOptions {
        episodes,
        jobs: 2,
        progress: false,
    }
}

/// Runs `shard` of `episodes` into `root` and returns the stored records.
fn run_shard(
    l: &LoadedScenario,
    root: &Path,
    shard: Shard,
    episodes: u32,
) -> BTreeMap<u32, EpisodeRecord> {
    let dir = results_dir(root, &l.scenario.spec.name, shard);
    let (mut store, _) = ResultsStore::open(&dir, l.header(shard)).unwrap();
    run_episodes(&l.scenario, &mut store, &options(episodes), ok(record)).unwrap();
    store.records().clone()
}

#[test]
fn resumed_run_equals_uninterrupted_run() {
    let l = nominal();
    let tmp = tempfile::tempdir().unwrap();
    let whole = run_shard(&l, &tmp.path().join("a"), Shard::ALL, 60);
    assert_eq!(whole.len(), 60);

    // Interrupted: the episode function dies at episode 37 (a crash mid-run).
    let root = tmp.path().join("b");
    let dir = results_dir(&root, &l.scenario.spec.name, Shard::ALL);
    let crashed = std::panic::catch_unwind(|| {
        let (mut store, _) = ResultsStore::open(&dir, l.header(Shard::ALL)).unwrap();
        let dying = |s: &Scenario, e: u32| {
            assert!(e != 37, "simulated crash");
            Ok::<_, Infallible>(record(s, e))
        };
        let _ = run_episodes(&l.scenario, &mut store, &options(60), dying);
    });
    assert!(crashed.is_err());
    let partial = read_results(&dir.join(RESULTS_FILE)).unwrap();
    assert!(partial.records.len() < 60 && !partial.records.contains_key(&37));
    // A torn line on top, as a crash inside write() leaves it.
    let torn = br#"{"version":1,"scenario":"usbc-nominal","seed":7,"episode":37,"succ"#;
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(dir.join(RESULTS_FILE))
        .unwrap();
    std::io::Write::write_all(&mut f, torn).unwrap();
    drop(f);

    let (mut store, report) = ResultsStore::open(&dir, l.header(Shard::ALL)).unwrap();
    assert_eq!(report.truncated_bytes, torn.len());
    assert_eq!(report.present, partial.records.len());
    let outcome = run_episodes(&l.scenario, &mut store, &options(60), ok(record)).unwrap();
    assert_eq!(outcome.resumed + outcome.ran, 60);
    assert_eq!(outcome.resumed, partial.records.len());
    assert_eq!(store.records(), &whole);
    drop(store);
    let reread = read_results(&dir.join(RESULTS_FILE)).unwrap();
    assert_eq!(reread.torn_bytes, 0);
    assert_eq!(reread.records, whole);
    let h = l.header(Shard::ALL);
    assert_eq!(
        Summary::new(&h, reread.records.values()),
        Summary::new(&h, whole.values())
    );

    // Asking for more episodes extends the run; nothing already stored reruns.
    let (mut store, _) = ResultsStore::open(&dir, l.header(Shard::ALL)).unwrap();
    let more = run_episodes(&l.scenario, &mut store, &options(70), ok(record)).unwrap();
    assert_eq!((more.resumed, more.ran), (60, 10));
}

#[test]
fn shards_merge_to_exactly_the_unsharded_result() {
    let l = nominal();
    let tmp = tempfile::tempdir().unwrap();
    let whole = run_shard(&l, &tmp.path().join("whole"), Shard::ALL, 50);
    let root = tmp.path().join("sharded");
    for i in 0..3 {
        let part = run_shard(&l, &root, Shard::new(i, 3).unwrap(), 50);
        assert!(part.keys().all(|e| e % 3 == i));
    }
    let scenario_dir = root.join(&l.scenario.spec.name);
    let merged = merge(&[scenario_dir]).unwrap();
    assert_eq!(merged.inputs.len(), 3);
    assert!(merged.gaps().is_empty());
    assert_eq!(merged.header, l.header(Shard::ALL));
    assert_eq!(merged.records, whole);
    // The merged file is byte for byte the unsharded results written in episode order.
    let a = write_results(&tmp.path().join("m"), &merged.header, &merged.records).unwrap();
    let b = write_results(&tmp.path().join("w"), &l.header(Shard::ALL), &whole).unwrap();
    assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    let h = l.header(Shard::ALL);
    assert_eq!(
        Summary::new(&h, merged.records.values()),
        Summary::new(&h, whole.values())
    );

    // A missing shard shows up as gaps.
    let partial = merge(&[
        results_dir(&root, &l.scenario.spec.name, Shard::new(0, 3).unwrap()),
        results_dir(&root, &l.scenario.spec.name, Shard::new(2, 3).unwrap()),
    ])
    .unwrap();
    assert_eq!(
        partial.gaps(),
        (0..49).filter(|e| e % 3 == 1).collect::<Vec<_>>()
    );
}

#[test]
fn merge_refuses_other_scenarios_and_overlaps() {
    let mut l = nominal();
    let tmp = tempfile::tempdir().unwrap();
    let s0 = Shard::new(0, 2).unwrap();
    let s1 = Shard::new(1, 2).unwrap();
    run_shard(&l, &tmp.path().join("a"), s0, 10);
    // The same scenario name and seed, but an edited file: a different run.
    l.bytes.extend_from_slice(b"\n# tolerances tightened\n");
    run_shard(&l, &tmp.path().join("b"), s1, 10);
    let name = l.scenario.spec.name.clone();
    let err = merge(&[
        results_dir(&tmp.path().join("a"), &name, s0),
        results_dir(&tmp.path().join("b"), &name, s1),
    ])
    .unwrap_err();
    assert!(
        matches!(
            err,
            MergeError::Mismatch {
                field: "scenario_sha256",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("different runs"));

    // Overlap: shards 1/2 and 1/4 both hold episode 1.
    run_shard(&l, &tmp.path().join("d"), s1, 4);
    run_shard(&l, &tmp.path().join("e"), Shard::new(1, 4).unwrap(), 4);
    let err = merge(&[
        results_dir(&tmp.path().join("d"), &name, s1),
        results_dir(&tmp.path().join("e"), &name, Shard::new(1, 4).unwrap()),
    ])
    .unwrap_err();
    assert!(
        matches!(err, MergeError::Overlap { episode: 1, .. }),
        "{err}"
    );
}

fn assert_refused_untouched(dir: &Path, header: ResultsHeader, check: impl Fn(&StoreError)) {
    let path = dir.join(RESULTS_FILE);
    let before = std::fs::read(&path).unwrap();
    let err = ResultsStore::open(dir, header).unwrap_err();
    check(&err);
    assert_eq!(
        std::fs::read(&path).unwrap(),
        before,
        "the refused file was modified"
    );
}

#[test]
fn foreign_or_corrupt_results_are_refused_and_left_untouched() {
    let l = nominal();
    let tmp = tempfile::tempdir().unwrap();
    let dir = results_dir(tmp.path(), &l.scenario.spec.name, Shard::ALL);
    run_shard(&l, tmp.path(), Shard::ALL, 8);
    let path = dir.join(RESULTS_FILE);
    let good = std::fs::read(&path).unwrap();

    // Another scenario file, another seed, another shard.
    let mut other = l.clone();
    other.bytes.push(b' ');
    assert_refused_untouched(&dir, other.header(Shard::ALL), |e| {
        assert!(
            matches!(
                e,
                StoreError::Foreign {
                    field: "scenario_sha256",
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("refusing"), "{e}");
    });
    let mut h = l.header(Shard::ALL);
    h.seed += 1;
    assert_refused_untouched(&dir, h, |e| {
        assert!(
            matches!(e, StoreError::Foreign { field: "seed", .. }),
            "{e}"
        )
    });
    assert_refused_untouched(&dir, l.header(Shard::new(0, 2).unwrap()), |e| {
        assert!(
            matches!(e, StoreError::Foreign { field: "shard", .. }),
            "{e}"
        )
    });

    // An unparsable line that is not the last one.
    let text = String::from_utf8(good.clone()).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines[3] = "{\"version\":1,\"scenario\":\"usbc-nominal\",garbage";
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    assert_refused_untouched(&dir, l.header(Shard::ALL), |e| {
        assert!(matches!(e, StoreError::Corrupt { line: 4, .. }), "{e}")
    });
    // A complete last line that does not parse is corruption, not a torn append.
    let mut lines: Vec<&str> = text.lines().collect();
    let n = lines.len();
    lines[n - 1] = "not json";
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    assert_refused_untouched(&dir, l.header(Shard::ALL), |e| {
        assert!(matches!(e, StoreError::Corrupt { .. }), "{e}")
    });
    // A duplicated episode.
    let lines: Vec<&str> = text.lines().collect();
    std::fs::write(&path, format!("{text}{}\n", lines[2])).unwrap();
    assert_refused_untouched(&dir, l.header(Shard::ALL), |e| {
        assert!(e.to_string().contains("appears twice"), "{e}")
    });
    // Not a results file at all, and an empty file.
    std::fs::write(&path, "episode,success\n0,true\n").unwrap();
    assert_refused_untouched(&dir, l.header(Shard::ALL), |e| {
        assert!(matches!(e, StoreError::NotResults { .. }), "{e}")
    });
    std::fs::write(&path, "").unwrap();
    assert_refused_untouched(&dir, l.header(Shard::ALL), |e| {
        assert!(matches!(e, StoreError::NotResults { .. }), "{e}")
    });

    // The merged output folder is protected the same way.
    std::fs::write(&path, &good).unwrap();
    let mut h = l.header(Shard::ALL);
    h.scenario = "another".into();
    let err = write_results(&dir, &h, &BTreeMap::new()).unwrap_err();
    assert!(matches!(err, StoreError::Foreign { .. }), "{err}");
    assert_eq!(std::fs::read(&path).unwrap(), good);
}

#[test]
fn a_second_writer_is_locked_out() {
    let l = nominal();
    let tmp = tempfile::tempdir().unwrap();
    let (_held, _) = ResultsStore::open(tmp.path(), l.header(Shard::ALL)).unwrap();
    let err = ResultsStore::open(tmp.path(), l.header(Shard::ALL)).unwrap_err();
    assert!(matches!(err, StoreError::Locked { .. }), "{err}");
}

#[test]
fn records_that_do_not_belong_are_rejected() {
    let l = nominal();
    let tmp = tempfile::tempdir().unwrap();
    let (mut store, _) =
        ResultsStore::open(tmp.path(), l.header(Shard::new(1, 2).unwrap())).unwrap();
    let err = store.append(record(&l.scenario, 4)).unwrap_err();
    assert!(err.to_string().contains("not in shard 2/2"), "{err}");
    store.append(record(&l.scenario, 5)).unwrap();
    assert!(store.append(record(&l.scenario, 5)).is_err());
    let wrong = |s: &Scenario, e: u32| record(s, e + 1);
    let err = run_episodes(&l.scenario, &mut store, &options(10), ok(wrong)).unwrap_err();
    assert!(matches!(err, RunError::WrongEpisode { .. }), "{err}");
    // An episode that cannot be set up stops the run; what was stored stays.
    let failing = |_: &Scenario, e: u32| -> Result<EpisodeRecord, std::io::Error> {
        Err(std::io::Error::other(format!("no cell for episode {e}")))
    };
    let err = run_episodes(&l.scenario, &mut store, &options(10), failing).unwrap_err();
    assert!(matches!(err, RunError::Episode { .. }), "{err}");
    assert!(err.to_string().contains("no cell for episode"), "{err}");
    assert!(store.contains(5));
}

#[test]
fn an_invalid_scenario_never_starts_a_run() {
    let tmp = tempfile::tempdir().unwrap();
    let src = std::fs::read_to_string(cell_tests::repo_root().join("scenarios/usbc_nominal.toml"))
        .unwrap();
    // Same folder as the real scenario so relative paths resolve; only `episodes` is broken.
    let bad = src.replacen("episodes = 200", "episodes = -3", 1);
    assert_ne!(bad, src);
    let path = tmp.path().join("bad.toml");
    std::fs::write(&path, bad).unwrap();
    let err = LoadedScenario::load(&path).unwrap_err();
    assert!(matches!(err, RunError::Scenario(_)), "{err}");
    assert!(err.to_string().contains("bad.toml:"), "{err}");
}

#[test]
fn summary_counts_match_the_records() {
    let l = nominal();
    let tmp = tempfile::tempdir().unwrap();
    let records = run_shard(&l, tmp.path(), Shard::ALL, 200);
    let s = Summary::new(&l.header(Shard::ALL), records.values());
    let failed: Vec<&EpisodeRecord> = records.values().filter(|r| !r.success).collect();
    assert_eq!(s.episodes, 200);
    assert_eq!(s.failures as usize, failed.len());
    assert_eq!(s.successes + s.failures, 200);
    assert!(s.success_ci95.lo < s.success_rate && s.success_rate < s.success_ci95.hi);
    // Step 1 fails exactly in the failed episodes; step 2 is reached only after step 1 seats.
    assert_eq!(s.steps.len(), 3);
    assert_eq!(s.steps[0].reached, 200);
    assert_eq!(s.steps[1].reached, 200);
    assert_eq!(s.steps[1].reached - s.steps[1].seated, s.failures);
    assert_eq!(s.steps[2].reached, s.successes);
    assert_eq!(s.steps[1].jammed + s.steps[1].missed, s.failures);
    // Every failure blames perception and robot repeatability: each 100 % of the budget.
    assert_eq!(s.error_budget.len(), 2);
    for e in &s.error_budget {
        assert_eq!(e.failures, s.failures);
        assert_eq!(e.share, 1.0);
    }
    let cycle = s.cycle_time_s.unwrap();
    assert_eq!(cycle.n as u32, s.successes);
    assert!(cycle.min >= 12.0 && cycle.max <= 15.0 && cycle.min <= cycle.p50);
    // Insertions: every reached step inserted, a seated step once or (after a retry) twice, a
    // failed one twice, so mean = 1 + (seated after a retry + failed) / inserted.
    for t in &s.steps {
        assert_eq!(t.inserted, t.reached);
        let failed = t.reached - t.seated;
        let mean = t.mean_insertion_attempts.unwrap();
        let expected = 1.0 + f64::from(t.seated_after_retry + failed) / f64::from(t.inserted);
        assert!((mean - expected).abs() < 1e-12, "{t:?}");
        // About a quarter of the seated steps needed a retry.
        let share = f64::from(t.seated_after_retry) / f64::from(t.seated);
        assert!((0.1..0.4).contains(&share), "{t:?}");
    }
    assert_eq!(s.steps[1].reached - s.steps[1].seated, s.failures);
    // summary.json and the HTML report carry them.
    let json = serde_json::to_value(&s).unwrap();
    for (i, t) in s.steps.iter().enumerate() {
        assert_eq!(
            json["steps"][i]["mean_insertion_attempts"].as_f64(),
            t.mean_insertion_attempts
        );
        assert_eq!(
            json["steps"][i]["seated_after_retry"].as_u64(),
            Some(u64::from(t.seated_after_retry))
        );
    }
    let html = cell::report::render_html(&s, &records, &Default::default())
        .unwrap()
        .html;
    assert!(html.contains("<th>insertions per inserted episode</th><th>seated after a retry</th>"));
    for t in &s.steps {
        let cells = format!(
            "<td>{:.2}</td><td>{:.2}</td><td>{}</td><td>{}</td>",
            t.mean_attempts,
            t.mean_insertion_attempts.unwrap(),
            t.seated_after_retry,
            t.shakes
        );
        assert!(html.contains(&cells), "{cells} not in the report");
    }
}

/// Results and summaries written before insertions were counted still load: their steps count
/// no insertion, and the report shows dashes rather than zeros.
#[test]
fn results_and_summaries_from_before_insertion_counts_still_load() {
    let l = nominal();
    let old: BTreeMap<u32, EpisodeRecord> = (0..20)
        .map(|e| {
            let mut v = serde_json::to_value(record(&l.scenario, e)).unwrap();
            for step in v["steps"].as_array_mut().unwrap() {
                step.as_object_mut().unwrap().remove("insertion_attempts");
            }
            (e, serde_json::from_value(v).unwrap())
        })
        .collect();
    let s = Summary::new(&l.header(Shard::ALL), old.values());
    assert_eq!(s.episodes, 20);
    for t in &s.steps {
        assert!(t.reached > 0);
        assert_eq!(t.inserted, 0);
        assert_eq!(t.mean_insertion_attempts, None);
        assert_eq!(t.seated_after_retry, 0);
    }
    let html = cell::report::render_html(&s, &old, &Default::default())
        .unwrap()
        .html;
    assert!(html.contains(&format!(
        "<td>{:.2}</td><td>–</td><td>–</td><td>{}</td>",
        s.steps[0].mean_attempts, s.steps[0].shakes
    )));
    // A summary.json without the insertion fields reads back with none counted.
    let mut v = serde_json::to_value(&s).unwrap();
    for step in v["steps"].as_array_mut().unwrap() {
        let step = step.as_object_mut().unwrap();
        for key in ["inserted", "mean_insertion_attempts", "seated_after_retry"] {
            assert!(step.remove(key).is_some(), "{key}");
        }
    }
    let back: Summary = serde_json::from_value(v).unwrap();
    assert_eq!(back, s);
}
