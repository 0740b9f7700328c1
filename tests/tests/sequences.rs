//! Assembly sequences are data: a two-step USB-C sequence (main shell into the fixture, insert
//! mold into the shell) and a four-step NIST peg sequence (four pegs into the plate's holes), each
//! written as a scenario variant in a scratch folder and run end to end in keypoint-noise mode.

mod e2e_support;

use cell::episode::StepOutcome;
use cell::harness::{SimSetup, run_sim_episode_blocking};
use cell::scenario::Scenario;
use rayon::prelude::*;
use toml_edit::{DocumentMut, value};

const EPISODES: u32 = 6;

/// Copies the scenarios folder, keeps only the `[[assembly]]` steps at `keep` (in that order) of
/// scenario `file` and only their parts in the feeder (as many as the scenario puts there), and
/// loads the result.
fn sequence(file: &str, keep: &[usize]) -> (tempfile::TempDir, SimSetup) {
    let dir = tempfile::tempdir().unwrap();
    e2e_support::copy_dir(&e2e_support::prepared_scenarios(), dir.path());
    let path = dir.path().join(file);
    let mut doc: DocumentMut = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    let steps = doc["assembly"].as_array_of_tables().unwrap().clone();
    let feeder = doc["cell"]["feeder"]["parts"]
        .as_inline_table()
        .unwrap()
        .clone();
    let mut kept = toml_edit::ArrayOfTables::new();
    let mut parts = toml_edit::InlineTable::new();
    for &i in keep {
        let step = steps.get(i).unwrap().clone();
        let name = step["part"].as_str().unwrap();
        parts.insert(name, feeder.get(name).unwrap().clone());
        kept.push(step);
    }
    doc["assembly"] = toml_edit::Item::ArrayOfTables(kept);
    doc["cell"]["feeder"]["parts"] = value(parts);
    std::fs::write(&path, doc.to_string()).unwrap();
    let scenario = Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let setup = SimSetup::new(scenario).unwrap_or_else(|e| panic!("{e}"));
    (dir, setup)
}

/// Runs `EPISODES` episodes and asserts each placed exactly `parts`, in order, every one seated.
fn assert_assembles(setup: &SimSetup, parts: &[&str]) {
    let outputs: Vec<_> = (0..EPISODES)
        .into_par_iter()
        .map(|e| run_sim_episode_blocking(setup, e).expect("episode set up"))
        .collect();
    for o in &outputs {
        let r = &o.record;
        assert!(r.abort.is_none(), "episode {}: {:?}", r.episode, r.abort);
        let done: Vec<(&str, StepOutcome)> = r
            .steps
            .iter()
            .map(|s| (s.part.as_str(), s.outcome))
            .collect();
        let want: Vec<(&str, StepOutcome)> =
            parts.iter().map(|p| (*p, StepOutcome::Seated)).collect();
        assert_eq!(done, want, "episode {}", r.episode);
        assert!(r.success, "episode {}", r.episode);
        // Each insertion started within its step's capture band (clearance / 2 + lead-in), and
        // was scored from the true poses.
        for (s, step) in r.steps.iter().zip(&setup.engine.scenario.spec.assembly) {
            let e = s.pose_error.as_ref().expect("an insertion's pose error");
            let capture_mm = (step.clearance / 2.0 + step.lead_in) * 1e3;
            assert!(
                e.dx_mm.abs() < capture_mm
                    && e.dy_mm.abs() < capture_mm
                    && s.insertion_attempts >= 1,
                "episode {}, {}: {e:?}",
                r.episode,
                s.part
            );
        }
    }
}

#[test]
fn a_two_step_usb_c_sequence_assembles_end_to_end() {
    let (_dir, setup) = sequence("usbc_nominal.toml", &[0, 1]);
    assert_eq!(setup.engine.scenario.spec.assembly.len(), 2);
    assert_assembles(&setup, &["main_shell", "insert_mold"]);
}

#[test]
fn a_four_step_nist_peg_sequence_assembles_end_to_end() {
    // Square 12 and 16 mm (the far row), then round 8 and 16 mm, into the plate's holes.
    let (_dir, setup) = sequence("nist_pegs_nominal.toml", &[1, 2, 3, 5]);
    assert_eq!(setup.engine.scenario.spec.assembly.len(), 4);
    assert_assembles(&setup, &["square_12", "square_16", "round_8", "round_16"]);
}
