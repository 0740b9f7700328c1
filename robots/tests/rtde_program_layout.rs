//! The register layout the Rust side uses must match the one `cell.script` declares.

use robots::program::layout::{self, SCRIPT_CONSTANTS};
use robots::program::{CELL_SCRIPT, PROGRAM_NAME, program_name, script_layout_constants};
use robots::rtde::variables::Register;
use std::collections::BTreeMap;

#[test]
fn script_declares_exactly_the_rust_layout() {
    let script: BTreeMap<String, f64> = script_layout_constants(CELL_SCRIPT).into_iter().collect();
    let rust: BTreeMap<String, f64> = SCRIPT_CONSTANTS
        .iter()
        .map(|(n, v)| ((*n).to_owned(), *v))
        .collect();
    assert_eq!(
        script.len(),
        SCRIPT_CONSTANTS.len(),
        "duplicate names in the script block"
    );
    assert_eq!(script, rust);
}

#[test]
fn script_is_our_program_and_uses_only_named_registers() {
    assert_eq!(program_name(CELL_SCRIPT), Some(PROGRAM_NAME));
    for call in [
        "read_input_integer_register(",
        "read_input_float_register(",
        "write_output_integer_register(",
    ] {
        for (i, _) in CELL_SCRIPT.match_indices(call) {
            let arg = &CELL_SCRIPT[i + call.len()..];
            assert!(
                arg.starts_with(|c: char| c.is_ascii_uppercase()),
                "register given as a literal: {}",
                &arg[..arg.find(')').unwrap_or(arg.len())]
            );
        }
    }
}

#[test]
fn every_register_is_in_the_external_client_range() {
    let names = layout::command_recipe()
        .into_iter()
        .chain(layout::heartbeat_recipe())
        .chain(layout::force_limit_recipe())
        .chain(layout::blend_recipe())
        .chain(layout::output_registers());
    for name in names {
        let index = match Register::parse(&name) {
            Some(
                Register::InputInt(i)
                | Register::InputDouble(i)
                | Register::OutputInt(i)
                | Register::OutputDouble(i),
            ) => i,
            other => panic!("{name} is not a word register: {other:?}"),
        };
        assert!((24..=47).contains(&index), "{name} outside 24–47");
    }
    let target_last = layout::TARGET_REG + 5;
    assert!(target_last < layout::SPEED_REG, "target overlaps speed");
}
