//! The wrist's force/torque sensor through real insertions of the USB-C parts (rapier, and MuJoCo
//! where this build has it): free of contact the wrist carries nothing, a jammed or seated part
//! pushes back with the wrist's push force along the insertion axis, and the sensor reading —
//! zeroed before the insertion, as a program does — shows that force within the sensor's noise.

#![allow(non_snake_case)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use sim::cad::usbc;
use sim::cell::geometry::PartGeometry;
use sim::cell::insertion::contact::{self, ContactSettings, WristWrench};
use sim::cell::insertion::{Mating, ReceiverPart, Verdict};
use sim::cell::wrench::{Load, WristWrenchModel};

mod support;

/// Step 1 (the insert mould into the main shell seated in the nest).
fn step1() -> (
    PartGeometry,
    PartGeometry,
    PartGeometry,
    sim::config::AssemblyStep,
) {
    let g = |name: &str, mesh| PartGeometry::from_mesh(name, mesh, 2e-3, vec![], vec![]).unwrap();
    (
        g("insert_mold", usbc::insert_mold()),
        g("main_shell", usbc::main_shell()),
        g("fixture_nest", usbc::fixture_nest()),
        support::scenario().assembly[1].clone(),
    )
}

/// The tool pointing down onto the part: the part 1 cm below the TCP, its z up.
fn tcp_T_part() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.01),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

/// Checks one engine's trace of an insertion.
fn check_trace(engine: &str, mating: &Mating, start: &Isometry3<f64>, trace: &[WristWrench]) {
    let w = ContactSettings::default().wrist;
    assert!(trace.len() > 10, "{engine}: {} samples", trace.len());
    // Before the part touches anything the springs carry only what sets the part moving with the
    // wrist (its mass brought to the descent speed): under the sensor's noise.
    let first = &trace[0];
    assert!(
        first.force.norm() < 0.05 * w.max_push,
        "{engine}: {:?} in free air",
        first.force
    );
    // At the end the wrist has overtravelled and the part pushes back along the axis with the
    // push force (the axial spring is at its cap), with little lateral load.
    let last = trace.last().unwrap();
    assert!(
        (last.force.z - w.max_push).abs() < 0.05 * w.max_push,
        "{engine}: axial {} N against the {} N push",
        last.force.z,
        w.max_push
    );
    assert!(
        last.force.xy().norm() < 0.5 * w.max_push,
        "{engine}: {:?}",
        last.force
    );

    // Through the sensor: zeroed with the part in the gripper before the insertion (gravity
    // only), then the last 20 ms averaged (10 readings).
    let base_T_ins = Isometry3::identity();
    let mut model = WristWrenchModel::new(&Isometry3::translation(0.0, 0.0, 0.15), 5);
    let held = Load::part(2e-3, &tcp_T_part());
    let start_tcp = base_T_ins * start * tcp_T_part().inverse();
    let truth = model.truth(&start_tcp, Some(held), &[0.0; 6]);
    model.sensor.zero(&truth);
    let readings = model.insertion_readings(
        trace,
        &base_T_ins,
        start,
        &w,
        &tcp_T_part(),
        held,
        &mating.lead_point,
    );
    let tail = &readings[readings.len() - 10..];
    let mean_z = tail.iter().map(|r| r.wrench[2]).sum::<f64>() / tail.len() as f64;
    let tol = 4.0 * model.sensor.sigma()[2] / (tail.len() as f64).sqrt();
    // The tool points down the insertion axis: pushed back up, it reads −push along its z.
    assert!(
        (mean_z + w.max_push).abs() < tol + 0.05 * w.max_push,
        "{engine}: sensor {mean_z} N against −{} N (tolerance {tol})",
        w.max_push
    );
}

#[test]
fn a_jammed_and_a_seated_insertion_read_the_push_force_axially() {
    let (held, shell, nest, step) = step1();
    let t = usbc::assembly_targets();
    let receivers = vec![
        ReceiverPart {
            geometry: &shell,
            destination_T_part: Isometry3::identity(),
        },
        ReceiverPart {
            geometry: &nest,
            destination_T_part: t.nest_t_main.inverse(),
        },
    ];
    let mating = Mating::new(&step, &held, &receivers[..1]);
    let settings = ContactSettings::default();
    let dir = Vector2::x();
    let cases = [
        (
            Verdict::Seated,
            mating.pose_with_error(Vector2::zeros(), 0.0, 0.0, 0.0, dir),
        ),
        (
            Verdict::Jammed,
            mating.pose_with_error(
                Vector2::zeros(),
                0.0,
                0.0,
                2.0 * mating.jam_angle(&dir),
                dir,
            ),
        ),
    ];
    for (verdict, pose) in cases {
        let run = contact::simulate(&mating, &held, &receivers, &pose, &settings);
        assert_eq!(run.result.verdict, verdict);
        let start = settings.wrist.start_pose(&mating, &pose);
        check_trace(&format!("rapier {verdict:?}"), &mating, &start, &run.wrench);
        // The jammed part stopped high: the force alone does not tell it from a seated one, the
        // depth does (the orchestrator's seat check uses both).
        if verdict == Verdict::Jammed {
            assert!(run.result.end.height > mating.tolerances.depth);
        }

        #[cfg(feature = "mujoco")]
        if let Err(e) = sim::mujoco::ensure_available() {
            eprintln!("MuJoCo's trace not checked: {e}");
        } else {
            let engine = sim::cell::insertion::mujoco::Mujoco::default();
            let case = sim::cell::insertion::InsertionCase {
                mating: &mating,
                held: &held,
                receivers: &receivers,
                ins_T_part: pose,
            };
            let (scored, trace) = engine.score_with_wrench(&case).unwrap();
            assert_eq!(scored.result.verdict, verdict, "mujoco");
            check_trace(&format!("mujoco {verdict:?}"), &mating, &start, &trace);
        }
    }
}
