//! The scenario's robot description drives the kinematics end to end: a UR10e cell
//! (`scenarios/usbc_ur10e.toml`) passes the check, plans and assembles, and an arm that cannot
//! reach the nominal layout (a UR3e) is refused by the check with the reason.

mod e2e_support;

use cell::harness::{SimSetup, run_sim_episode_blocking};
use cell::scenario::Scenario;
use rayon::prelude::*;

#[test]
fn a_ur10e_cell_checks_plans_and_assembles() {
    let dir = e2e_support::prepared_scenarios();
    let scenario = Scenario::load(&dir.join("usbc_ur10e.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scenario.robot.name, "ur10e");
    let setup = SimSetup::new(scenario).unwrap_or_else(|e| panic!("{e}"));
    // Planner and simulator both use the UR10e's lengths, not a UR5e's.
    assert_eq!(setup.engine.knowledge.kinematics.dh.a2, -0.6127);
    assert_eq!(setup.model.kinematics.dh.a3, -0.57155);
    let outputs: Vec<_> = (0..6u32)
        .into_par_iter()
        .map(|e| run_sim_episode_blocking(&setup, e).expect("episode set up"))
        .collect();
    let successes = outputs.iter().filter(|o| o.record.success).count();
    for o in &outputs {
        assert!(
            o.record.abort.is_none(),
            "episode {}: {:?}",
            o.record.episode,
            o.record.abort
        );
    }
    // The nominal cell seats 99.8 % on a UR5e; the arm does not change that.
    assert!(successes >= 5, "{successes}/6 assembled");
}

#[test]
fn an_arm_that_cannot_reach_the_layout_is_refused_by_the_check() {
    let dir = e2e_support::prepared_scenarios();
    // The nominal cell with the table 15 cm farther out: a UR5e still reaches the fixture and
    // the feeder, a UR3e (0.5 m reach) does not.
    let text = std::fs::read_to_string(dir.join("usbc_nominal.toml"))
        .unwrap()
        .replace(
            "translation = [0.0, -0.45, 0.0]",
            "translation = [0.0, -0.6, 0.0]",
        );
    let path = dir.join("usbc_far.toml");
    Scenario::parse(&text, &path).unwrap_or_else(|e| panic!("{e}"));
    let ur3e = text.replace("robots/ur5e.urdf", "robots/ur3e.urdf");
    let err = Scenario::parse(&ur3e, &path).unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains("out of the ur3e's reach") && message.contains("out of reach"),
        "{message}"
    );
    // Faster than the UR10e's base may turn: refused at the limit's line.
    let text = std::fs::read_to_string(dir.join("usbc_ur10e.toml")).unwrap();
    let fast = text.replace("max_joint_speed = 2.09", "max_joint_speed = 3.14");
    let err = Scenario::parse(&fast, &dir.join("usbc_ur10e.toml")).unwrap_err();
    let problem = &err.0[0];
    assert_eq!(problem.key.as_deref(), Some("cell.limits.max_joint_speed"));
    assert_eq!(
        problem.line,
        fast.lines()
            .position(|l| l.starts_with("max_joint_speed"))
            .unwrap()
            + 1
    );
    assert!(
        problem.message.contains("ur10e's slowest joint"),
        "{problem}"
    );
    // Not a UR arm: refused at `cell.robot`, naming the file and the reason.
    let err = Scenario::parse(
        &text.replace("robots/ur10e.urdf", "parts/usbc.toml"),
        &dir.join("usbc_ur10e.toml"),
    )
    .unwrap_err();
    let problem = &err.0[0];
    assert_eq!(problem.key.as_deref(), Some("cell.robot"));
    assert!(problem.message.contains("usbc.toml"), "{problem}");
}
