//! The regression gate's statistics on constructed record sets at known rates: an equal rate
//! passes, a real drop is flagged, a drop too small for the sample is not, and across many
//! seeded samples the false-alarm rate stays below alpha while real drops are caught.

use cell::episode::{EpisodeRecord, RECORD_VERSION, StepOutcome, StepRecord};
use cell::regress::{Baseline, BaselineError, compare};
use cell::run::{ResultsHeader, Shard, Summary};

const PARTS: [&str; 3] = ["main_shell", "insert_mold", "top_shell"];

fn header() -> ResultsHeader {
    ResultsHeader::new("usbc-nominal", 7, b"scenario bytes", Shard::ALL)
}

/// An episode whose second step seats or misses as given.
fn episode(i: u32, success: bool) -> EpisodeRecord {
    let mut steps = Vec::new();
    for (k, part) in PARTS.iter().enumerate() {
        let seated = success || k != 1;
        steps.push(StepRecord {
            part: (*part).into(),
            outcome: if seated {
                StepOutcome::Seated
            } else {
                StepOutcome::Missed
            },
            attempts: 1,
            insertion_attempts: 1,
            shakes: 0,
            cause: (!seated).then(|| "landed beside the nest".into()),
            sources: if seated {
                vec![]
            } else {
                vec!["calibration_translation".into()]
            },
            pose_error: None,
            perception_error: None,
            perception_verdict: None,
            confidence: None,
            sim_time_s: 5.0,
            force: None,
            seat_check: None,
        });
        if !seated {
            break;
        }
    }
    EpisodeRecord {
        version: RECORD_VERSION,
        scenario: "usbc-nominal".into(),
        seed: 7,
        episode: i,
        success,
        cycle_time_s: 5.0 * steps.len() as f64,
        steps,
        wall_time_s: 0.0,
        abort: None,
        phases: vec![],
    }
}

/// `successes` of `n` episodes, failures spread over the run.
fn exact(successes: u32, n: u32) -> Summary {
    let records: Vec<EpisodeRecord> = (0..n)
        .map(|i| episode(i, (i * successes) / n != ((i + 1) * successes) / n))
        .collect();
    let s = Summary::new(&header(), &records);
    assert_eq!(s.successes, successes);
    s
}

fn baseline(s: &Summary) -> Baseline {
    Baseline::from_summary(s, Some("0123abcd".into()), "2026-11-22T00:00:00Z".into())
}

#[test]
fn equal_rate_passes_and_real_drop_is_flagged() {
    let base = baseline(&exact(190, 200));
    let same = compare(&base, &exact(190, 200), 0.01);
    assert!(!same.regressed(), "{}", same.table());
    assert!(same.notes.is_empty(), "{:?}", same.notes);
    assert_eq!(same.rows.len(), 4);
    // Identical tables: the one-sided p-value is P(X <= 190) for X ~ Hyp(400, 380, 200).
    assert!((same.rows[0].p_value - 0.590_384_207_323_786).abs() < 1e-9);

    // 95 % → 85 %: one-sided Fisher p = 6.42e-4, Holm over 4 rows still below 0.01.
    let drop = compare(&base, &exact(170, 200), 0.01);
    assert!(drop.regressed(), "{}", drop.table());
    assert!((drop.rows[0].p_value - 6.424_663_797_225_995e-4).abs() < 1e-9);
    let step1 = drop
        .rows
        .iter()
        .find(|r| r.what.contains("insert_mold"))
        .unwrap();
    assert!(step1.drop, "{}", drop.table());
    // Steps that did not change are not flagged.
    assert!(
        drop.rows.iter().filter(|r| r.drop).count() == 2,
        "{}",
        drop.table()
    );
    assert!(drop.table().contains("REGRESSED") && drop.table().contains("DROP"));

    // 95 % → 92.5 % in 200 episodes is within noise (p = 0.20).
    let small = compare(&base, &exact(185, 200), 0.01);
    assert!(!small.regressed(), "{}", small.table());
    // An improvement never fails the gate.
    let better = compare(&baseline(&exact(170, 200)), &exact(199, 200), 0.01);
    assert!(!better.regressed());
    // alpha is configurable: 95 % → 90 % gives p = 0.043 for the episode and for step 1 (the
    // other steps never fail: uninformative, uncorrected), Holm-adjusted 0.086.
    let mid = compare(&base, &exact(180, 200), 0.05);
    assert!((mid.rows[0].p_value - 0.043_048_402_119_699_24).abs() < 1e-9);
    assert!((mid.rows[0].p_holm - 2.0 * 0.043_048_402_119_699_24).abs() < 1e-9);
    assert!(!mid.regressed(), "{}", mid.table());
    assert!(compare(&base, &exact(180, 200), 0.1).regressed());
}

/// A fixed pseudo-random function of (stream, index): the project's one seed splitter.
fn mix(stream: u64, i: u64) -> u64 {
    sim::seed::split_seed(stream, i)
}

/// `n` Bernoulli(`rate`) episodes from stream `stream`.
fn sample(stream: u64, rate: f64, n: u32) -> Summary {
    let records: Vec<EpisodeRecord> = (0..n)
        .map(|i| {
            let u = (mix(stream, u64::from(i)) >> 11) as f64 / (1u64 << 53) as f64;
            episode(i, u < rate)
        })
        .collect();
    Summary::new(&header(), &records)
}

#[test]
fn false_alarms_stay_below_alpha_and_real_drops_are_caught() {
    let alpha = 0.01;
    let trials = 300u64;
    let mut false_alarms = 0;
    let mut caught = 0u32;
    for t in 0..trials {
        let base = baseline(&sample(2 * t, 0.95, 200));
        if compare(&base, &sample(2 * t + 1, 0.95, 200), alpha).regressed() {
            false_alarms += 1;
        }
        if compare(&base, &sample(1_000_000 + t, 0.80, 200), alpha).regressed() {
            caught += 1;
        }
    }
    // The gate's exact operating characteristic for these rates (n = 200 each side; episode and
    // step-1 rows carry the same counts, so Holm doubles p), summed over both binomials:
    // false-alarm probability 0.0026 (Fisher is conservative: below alpha), power 0.9792.
    // Over 300 seeded trials: expect 0.78 false alarms and 293.8 ± 2.5 detections.
    assert!(false_alarms <= 5, "{false_alarms} false alarms in {trials}");
    let expected = 0.979_231_8 * trials as f64;
    let sd = (expected * (1.0 - 0.979_231_8)).sqrt();
    assert!(
        (f64::from(caught) - expected).abs() <= 4.0 * sd,
        "caught {caught} of {trials} real drops, expected {expected:.1} ± {sd:.1}"
    );
}

#[test]
fn baselines_round_trip_and_bad_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let b = baseline(&exact(180, 200));
    let path = Baseline::path(dir.path(), &b.scenario);
    assert!(path.ends_with("usbc-nominal.json"));
    assert!(matches!(
        Baseline::load(&path),
        Err(BaselineError::Missing { .. })
    ));
    b.save(&path).unwrap();
    assert_eq!(Baseline::load(&path).unwrap(), b);
    assert_eq!(b.steps[1].reached, 200);
    assert_eq!(b.steps[1].seated, 180);
    assert_eq!(b.steps[2].reached, 180);

    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(
        &path,
        text.replace("\"successes\": 180", "\"successes\": 201"),
    )
    .unwrap();
    let err = Baseline::load(&path).unwrap_err();
    assert!(err.to_string().contains("201 successes of 200"), "{err}");
    std::fs::write(&path, text.replace("\"seed\"", "\"sed\"")).unwrap();
    let err = Baseline::load(&path).unwrap_err();
    assert!(matches!(err, BaselineError::Parse { .. }), "{err}");

    // A changed scenario file is called out in the verdict.
    let mut other = exact(180, 200);
    other.scenario_sha256 = "0".repeat(64);
    let v = compare(&b, &other, 0.01);
    assert!(
        v.notes.iter().any(|n| n.contains("scenario file changed")),
        "{:?}",
        v.notes
    );
}
