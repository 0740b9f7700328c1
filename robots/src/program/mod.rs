//! Our URScript control program and its register layout.

pub mod layout;

/// The program text uploaded to port 30003.
pub const CELL_SCRIPT: &str = include_str!("cell.script");
/// The name the program's `def` line declares; the virtual controller recognises it by this.
pub const PROGRAM_NAME: &str = "cell_program";
/// Name of the SDU ur_rtde control script's `def`.
pub const UR_RTDE_PROGRAM_NAME: &str = "rtde_control";

/// The name of the first `def NAME():` in a URScript text, if any.
pub fn program_name(script: &str) -> Option<&str> {
    script.lines().find_map(|line| {
        let rest = line.trim_start().strip_prefix("def ")?;
        let name = rest.split('(').next()?.trim();
        (!name.is_empty() && rest.trim_end().ends_with(':')).then_some(name)
    })
}

/// The `NAME = value` constants of the script's layout block (between the marker comments).
pub fn script_layout_constants(script: &str) -> Vec<(String, f64)> {
    script
        .lines()
        .skip_while(|l| !l.contains("--- layout begin ---"))
        .take_while(|l| !l.contains("--- layout end ---"))
        .filter_map(|l| {
            let l = l.trim().trim_start_matches("global ").trim();
            let (name, value) = l.split_once('=')?;
            Some((name.trim().to_owned(), value.trim().parse().ok()?))
        })
        .collect()
}
