//! `cell check` on the gripper's opening: a margin the stroke cannot give the widest grasped
//! part, or a negative one, is refused at its line and column; a margin that fits is accepted,
//! and the fingers then open to each part, no wider.

mod support;

use support::{line_of, load_variant as load, root};

/// The nominal USB-C scenario with `opening_margin = margin` in its `[cell.gripper]`.
fn with_margin(margin: &str) -> String {
    let text = std::fs::read_to_string(root().join("scenarios/usbc_nominal.toml")).unwrap();
    let line = (text.lines())
        .find(|l| l.starts_with("opening_margin = "))
        .expect("the nominal scenario sets a margin");
    text.replacen(line, &format!("opening_margin = {margin}"), 1)
}

#[test]
fn a_margin_the_stroke_cannot_give_is_refused_at_its_line() {
    // The top shell is 11.8 mm across its grasp: 2 mm each side needs 15.8 mm of a 14 mm stroke.
    let text = with_margin("0.002");
    let Err(err) = load("grip_wide", &text) else {
        panic!("accepted")
    };
    let p = (err.0.iter())
        .find(|p| p.key.as_deref() == Some("cell.gripper.opening_margin"))
        .unwrap_or_else(|| panic!("nothing at the margin: {err}"));
    assert!(
        p.message.contains("\"top_shell\"") && p.message.contains("14.00 mm stroke"),
        "{p:?}"
    );
    assert_eq!(p.line, line_of(&text, "opening_margin = 0.002"));
    assert_eq!(p.column, "opening_margin = ".len() + 1);

    let text = with_margin("-0.001");
    let Err(err) = load("grip_negative", &text) else {
        panic!("accepted")
    };
    assert!(
        err.0
            .iter()
            .any(|p| p.key.as_deref() == Some("cell.gripper.opening_margin")
                && p.message.contains("zero or positive")),
        "{err}"
    );
}

#[test]
fn a_margin_that_fits_opens_the_fingers_to_each_part() {
    let s = load("grip_fits", &with_margin("0.001")).unwrap_or_else(|e| panic!("{e}"));
    let g = &s.spec.cell.gripper;
    assert_eq!(g.opening_margin, Some(0.001));
    let knowledge = cell::orchestrator::CellKnowledge::new(&s).unwrap_or_else(|e| panic!("{e}"));
    for part in s.catalog.parts.iter().filter(|p| !p.grasps.is_empty()) {
        for grasp in &part.grasps {
            let axis = nalgebra::Vector3::from(grasp.closing_axis);
            let opening = knowledge.grasp_opening(&part.name, &axis);
            let mesh = s.catalog.load_mesh(part).unwrap();
            let width = sim::cell::gripper::width_across(&mesh.vertices, &axis.normalize());
            assert!(
                (opening - (width + 0.002)).abs() < 1e-9 && opening <= g.stroke,
                "{}: opens {opening} m for a part {width} m wide",
                part.name
            );
        }
    }
}
