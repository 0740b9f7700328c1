//! `[motion] blend_radius`: the orchestrator's lift → transit → approach chains as one blended
//! path. A radius that is negative, not finite, or larger than half the shortest segment it
//! would blend is refused at its line and column; an accepted one loads into the planner.

mod support;

use cell::orchestrator::{PlanningConfig, Setup};
use support::load_variant;

#[test]
fn bad_blend_radii_are_refused_at_their_line_and_column() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let p = PlanningConfig::default();
    let over = format!(
        "blend_radius = {}",
        p.clearance_height - p.slow_distance + 1e-4
    );
    for (line, words) in [
        ("blend_radius = -0.001", "zero or positive"),
        ("blend_radius = nan", "finite"),
        ("blend_radius = inf", "finite"),
        (over.as_str(), "larger than half the shortest segment"),
    ] {
        let variant = format!("{text}\n[motion]\n{line}\n");
        let err = load_variant("bad_blend", &variant).unwrap_err();
        let problem = &err.0[0];
        assert_eq!(problem.key.as_deref(), Some("motion.blend_radius"), "{err}");
        assert_eq!(problem.line, support::line_of(&variant, line), "{err}");
        assert_eq!(problem.column, line.find('=').unwrap() + 3, "{err}");
        assert!(problem.message.contains(words), "{err}");
    }
    // An unknown key in the table is refused too.
    let variant = format!("{text}\n[motion]\nblend_radios = 0.005\n");
    let err = load_variant("bad_blend_key", &variant).unwrap_err();
    assert_eq!(
        err.0[0].line,
        support::line_of(&variant, "blend_radios"),
        "{err}"
    );
}

#[test]
fn an_accepted_radius_reaches_the_planner_and_none_means_no_blending() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let p = PlanningConfig::default();
    let max = p.clearance_height - p.slow_distance;
    let variant = format!("{text}\n[motion]\nblend_radius = {max}\n");
    let scenario = load_variant("good_blend", &variant).unwrap();
    assert_eq!(scenario.spec.motion.blend_radius, max);
    let setup = Setup::new(scenario).unwrap();
    assert_eq!(setup.settings.planning.blend_radius, max);
    let plain = cell::scenario::Scenario::load(std::path::Path::new(&support::nominal())).unwrap();
    assert_eq!(plain.spec.motion.blend_radius, 0.0);
    assert_eq!(
        Setup::new(plain).unwrap().settings.planning.blend_radius,
        0.0
    );
}
