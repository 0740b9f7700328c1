//! Stable poses dropped in MuJoCo cross-check rapier's: for each USB-C part the same drop
//! sequence (3 000 drops from 15 mm at the default 1/2 400 s) gives class shares within 3 points (the
//! issue's goal; measured 0.3 / 1.8 / 1.5 points with one contact per point and 16 solver
//! iterations, 0.6 / 2.3 / 0.6 before with every triangle's contacts and 24) and physics rest
//! heights within 10 µm of the geometric ones. With 3 000 drops one class's share varies by about
//! 1.2 points between the engines from chaos alone, so fewer drops would not test 3 points.

#![cfg(feature = "mujoco")]

use sim::cad::usbc;
use sim::stable_poses::{DropSettings, StablePoseReport, stable_poses, stable_poses_mujoco};

/// Largest difference of a class's share between the engines, per part.
fn share_gap(a: &StablePoseReport, b: &StablePoseReport) -> (f64, String) {
    let share = |r: &StablePoseReport, name: &str| {
        r.classes
            .iter()
            .find(|c| c.pose.name == name)
            .map_or(0.0, |c| c.pose.probability)
    };
    a.classes
        .iter()
        .chain(&b.classes)
        .map(|c| {
            let gap = (share(a, &c.pose.name) - share(b, &c.pose.name)).abs();
            (gap, c.pose.name.clone())
        })
        .fold((0.0, String::new()), |m, g| if g.0 > m.0 { g } else { m })
}

#[test]
fn mujoco_and_rapier_drops_give_the_same_stable_poses() {
    let settings = DropSettings {
        drops: 3000,
        seed: 3,
        // The height the committed catalog's tables were dropped from. From the default 30 mm
        // the engines part further: the top shell's cover-down share by 3.3 points.
        drop_height: 0.015,
        ..DropSettings::default()
    };
    let mut failures = Vec::new();
    for (name, mesh, density) in [
        ("main_shell", usbc::main_shell(), 8500.0),
        ("insert_mold", usbc::insert_mold(), 1400.0),
        ("top_shell", usbc::top_shell(), 8500.0),
    ] {
        let rapier = stable_poses(&mesh, density, &settings, None);
        let mujoco = stable_poses_mujoco(name, &mesh, density, &settings, None).unwrap();
        let (gap, class) = share_gap(&rapier, &mujoco);
        eprintln!(
            "{name}: largest share gap {:.1} points ({class})",
            gap * 100.0
        );
        for c in &mujoco.classes {
            eprintln!(
                "  {:<9} mujoco {:.3} rest {:.1} µm (physics−geometry {:.2} µm)",
                c.pose.name,
                c.pose.probability,
                c.pose.rest_height * 1e6,
                c.max_height_error * 1e6
            );
            if c.max_height_error >= 1e-5 {
                failures.push(format!(
                    "{name} {}: MuJoCo rests {} m from the geometric height",
                    c.pose.name, c.max_height_error
                ));
            }
        }
        if gap > 0.03 {
            failures.push(format!(
                "{name} {class}: shares differ by {:.1} points",
                gap * 100.0
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
