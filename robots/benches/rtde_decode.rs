//! Client-side decode cost of one RTDE output package: framing, package decode and the typed
//! values of the recipe ur_rtde's receive interface asks a 5.15 controller for (56 variables),
//! and of the small recipe `UrRobot` uses.

#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use robots::rtde::Recipe;
use robots::rtde::package::{Protocol, Reply, split_frame};
use robots::rtde::types::Value;
use robots::rtde::variables::output_type;
use std::hint::black_box;

/// The names ur_rtde 1.6.5's RTDEReceiveInterface requests with default settings.
const RECEIVE_DEFAULTS: &[&str] = &[
    "timestamp",
    "target_q",
    "target_qd",
    "target_qdd",
    "target_current",
    "target_moment",
    "actual_q",
    "actual_qd",
    "actual_current",
    "joint_control_output",
    "actual_TCP_pose",
    "actual_TCP_speed",
    "actual_TCP_force",
    "target_TCP_pose",
    "target_TCP_speed",
    "actual_digital_input_bits",
    "joint_temperatures",
    "actual_execution_time",
    "robot_mode",
    "joint_mode",
    "safety_mode",
    "actual_tool_accelerometer",
    "speed_scaling",
    "target_speed_fraction",
    "actual_momentum",
    "actual_main_voltage",
    "actual_robot_voltage",
    "actual_robot_current",
    "actual_joint_voltage",
    "actual_digital_output_bits",
    "runtime_state",
    "standard_analog_input0",
    "standard_analog_input1",
    "standard_analog_output0",
    "standard_analog_output1",
    "robot_status_bits",
    "safety_status_bits",
    "output_int_register_12",
    "output_int_register_13",
    "output_int_register_14",
    "output_int_register_15",
    "output_int_register_16",
    "output_int_register_17",
    "output_int_register_18",
    "output_int_register_19",
    "output_double_register_12",
    "output_double_register_13",
    "output_double_register_14",
    "output_double_register_15",
    "output_double_register_16",
    "output_double_register_17",
    "output_double_register_18",
    "output_double_register_19",
    "payload",
    "payload_cog",
    "ft_raw_wrench",
];

const UR_ROBOT: &[&str] = &[
    "timestamp",
    "actual_q",
    "actual_TCP_pose",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
    "runtime_state",
    "output_int_register_24",
    "output_int_register_25",
    "output_int_register_26",
    "output_int_register_27",
    "output_int_register_28",
];

fn package(names: &[&str]) -> (Recipe, Vec<u8>) {
    let types: Vec<_> = names.iter().map(|n| output_type(n).expect(n)).collect();
    let recipe = Recipe::new(1, names.iter().map(|s| (*s).to_owned()).collect(), types);
    let values: Vec<Value> = recipe
        .types
        .iter()
        .enumerate()
        .map(|(i, t)| match t.zero() {
            Value::Double(_) => Value::Double(i as f64 * 0.1),
            Value::Vector6d(_) => Value::Vector6d([i as f64 * 0.01; 6]),
            v => v,
        })
        .collect();
    let mut payload = Vec::new();
    recipe.encode(&values, &mut payload).unwrap();
    let mut frame = Vec::new();
    Reply::Data {
        recipe_id: Some(1),
        payload,
    }
    .encode(Protocol::V2, &mut frame)
    .unwrap();
    (recipe, frame)
}

fn decode(recipe: &Recipe, frame: &[u8]) -> Vec<Value> {
    let (ty, payload, _) = split_frame(frame).unwrap().unwrap();
    // The client's path: split off the recipe id, decode the values into a fresh vector.
    assert_eq!(ty, b'U');
    let (_, values) = payload.split_first().unwrap();
    recipe.decode(values).unwrap()
}

fn bench_decode(c: &mut Criterion) {
    for (name, names) in [
        ("ur_rtde_receive_56", RECEIVE_DEFAULTS),
        ("ur_robot_12", UR_ROBOT),
    ] {
        let (recipe, frame) = package(names);
        assert_eq!(decode(&recipe, &frame).len(), names.len());
        c.bench_function(
            &format!("decode_output_package/{name}/{}B", frame.len()),
            |b| b.iter(|| decode(black_box(&recipe), black_box(&frame))),
        );
    }
}

criterion_group!(benches, bench_decode);
criterion_main!(benches);
