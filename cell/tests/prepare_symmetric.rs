//! `cell parts prepare` on parts with exact symmetries: the NIST board's square and round pegs
//! (sim::cad::nist), declared symmetric about their axis and end over end. Lying on any side is
//! one stable pose and either end another, as they are for the cell; without the declaration
//! the round peg, a 48-gon, lies in many roll classes.

use cell::prepare::prepare_catalog;
use sim::cad::write_nist_meshes;
use sim::stable_poses::DropSettings;

/// A catalog of the 8 mm pegs, with `symmetries` declared on each (empty for none).
fn catalog(dir: &std::path::Path, square: &str, round: &str) -> std::path::PathBuf {
    let part = |name: &str, symmetries: &str| {
        format!(
            "[[part]]\nname = \"{name}\"\nmesh = \"nist_{name}.obj\"\nunit = \"mm\"\n\
             material = \"aluminium\"\n{symmetries}"
        )
    };
    let path = dir.join("pegs.toml");
    std::fs::write(
        &path,
        format!(
            "name = \"pegs\"\n{}{}",
            part("square_8", square),
            part("round_8", round)
        ),
    )
    .unwrap();
    path
}

/// Drops enough for every class of these pegs and quick in a test.
fn settings() -> DropSettings {
    DropSettings {
        drops: 400,
        ..DropSettings::default()
    }
}

#[test]
fn a_symmetric_peg_has_one_pose_on_its_sides_and_one_on_its_ends() {
    let dir = tempfile::tempdir().unwrap();
    write_nist_meshes(dir.path()).unwrap();
    let declared = |order: u32| {
        format!(
            "symmetries = [{{ axis = [0.0, 0.0, 1.0], order = {order} }}, \
             {{ axis = [1.0, 0.0, 0.0], order = 2 }}]\n"
        )
    };
    let path = catalog(dir.path(), &declared(4), &declared(48));
    let prepared = prepare_catalog(&path, &settings(), None).unwrap();
    for p in &prepared {
        let r = &p.report;
        let names: Vec<&str> = r.classes.iter().map(|c| c.pose.name.as_str()).collect();
        if p.name == "square_8" {
            assert_eq!(r.classes.len(), 2, "{}: {names:?}", p.name);
        } else {
            // A round peg still rolling at the time limit (18 % of this one's drops) is counted
            // at whatever roll it has reached, between two facets: those drops may form one
            // more side class, at no facet's direction.
            assert!(r.classes.len() <= 3, "{}: {names:?}", p.name);
        }
        let side = &r.classes[0];
        let up = side.pose.up_in_part;
        assert!(
            up[2].abs() < 1e-6,
            "{}: lying on a side first ({up:?})",
            p.name
        );
        let end = r
            .classes
            .iter()
            .find(|c| c.pose.up_in_part[2].abs() > 0.5)
            .expect("an end class");
        assert!(
            (end.pose.up_in_part[2].abs() - 1.0).abs() < 1e-6,
            "{}: standing on an end",
            p.name
        );
        let shares: f64 = r.classes.iter().map(|c| c.pose.probability).sum();
        let counted = (r.drops - r.rare - r.leaning) as f64 / r.drops as f64;
        assert!(
            (shares - counted).abs() < 1e-9,
            "{}: {shares} vs {counted}",
            p.name
        );
    }
    let written = std::fs::read_to_string(&path).unwrap();
    let classes: usize = prepared.iter().map(|p| p.report.classes.len()).sum();
    assert_eq!(written.matches("[[part.stable_pose]]").count(), classes);
}

#[test]
fn without_its_symmetries_a_round_peg_lies_in_many_roll_classes() {
    let dir = tempfile::tempdir().unwrap();
    write_nist_meshes(dir.path()).unwrap();
    let path = catalog(dir.path(), "", "");
    let prepared = prepare_catalog(&path, &settings(), None).unwrap();
    let round = prepared.iter().find(|p| p.name == "round_8").unwrap();
    assert!(
        round.report.classes.len() > 4,
        "{} classes",
        round.report.classes.len()
    );
}

#[test]
fn the_two_ends_merge_into_the_end_the_grasp_names() {
    let dir = tempfile::tempdir().unwrap();
    write_nist_meshes(dir.path()).unwrap();
    // Each end takes about half the end drops: whichever the drops favour, the grasp's end names
    // the merged class, so the grasp still applies after preparing.
    for end in ["+z", "-z"] {
        let path = dir.path().join(format!("square{end}.toml"));
        std::fs::write(
            &path,
            format!(
                "name = \"pegs\"\n[[part]]\nname = \"square_8\"\nmesh = \"nist_square_8.obj\"\n\
                 unit = \"mm\"\nmaterial = \"aluminium\"\n\
                 symmetries = [{{ axis = [0.0, 0.0, 1.0], order = 4 }}, \
                 {{ axis = [1.0, 0.0, 0.0], order = 2 }}]\n\
                 [[part.grasp]]\nstable_pose = \"{end}\"\nclosing_axis = [1.0, 0.0, 0.0]\n\
                 grip_height = 0.0075\n"
            ),
        )
        .unwrap();
        let prepared = prepare_catalog(&path, &settings(), None).unwrap();
        let square = &prepared[0];
        let names: Vec<&str> = (square.report.classes.iter())
            .map(|c| c.pose.name.as_str())
            .collect();
        let merged = (square.report.classes.iter())
            .find(|c| c.pose.up_in_part[2].abs() > 0.5)
            .expect("an end class");
        assert_eq!(merged.pose.name, end, "{names:?}");
        let up = if end == "+z" { 1.0 } else { -1.0 };
        assert!((merged.pose.up_in_part[2] - up).abs() < 1e-6, "{end}");
        // Written with the grasp's name, so the catalog reads back pickable in that pose.
        let catalog = perception::part::Catalog::load(&path).unwrap();
        let part = catalog.part("square_8").unwrap();
        assert!(part.stable_pose(end).is_some() && part.grasp_for(end).is_some());
    }
}
