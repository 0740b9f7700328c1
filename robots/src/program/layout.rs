//! The register protocol of our URScript program (`cell.script`): registers 24–47 only.
//!
//! Inputs (client → program) and outputs (program → client). A command runs once: the program
//! executes it when `CMD_ID` changes, echoes the id in `ACCEPTED_ID`, and writes it to `DONE_ID`
//! when finished, with `STATUS` and `ERROR` telling how it ended.

/// input_int: command counter; a new value is a new command.
pub const CMD_ID_REG: usize = 24;
/// input_int: command kind (`KIND_*`).
pub const CMD_KIND_REG: usize = 25;
/// input_int: digital output pin for the set-output commands.
pub const DO_PIN_REG: usize = 26;
/// input_int: digital output level (0 or 1).
pub const DO_LEVEL_REG: usize = 27;
/// input_int: client heartbeat counter (the watchdog stops the arm when it stops changing).
pub const HEARTBEAT_REG: usize = 28;
/// input_double: first of six target registers (joints in rad, or a UR pose vector).
pub const TARGET_REG: usize = 24;
/// input_double: speed (rad/s for movej, m/s for movel).
pub const SPEED_REG: usize = 30;
/// input_double: acceleration (rad/s² or m/s²).
pub const ACCEL_REG: usize = 31;
/// input_double: seconds the set-output commands sleep after setting the output (a gripper's
/// stroke), before reporting done; 0 for no wait, at most [`MAX_DO_WAIT_S`].
pub const DO_WAIT_REG: usize = 32;
/// input_double: force limit of a guarded move (`KIND_MOVE_UNTIL_CONTACT`), N: the move stops
/// when the wrist reads more than this against the direction of motion. Its own recipe
/// ([`force_limit_recipe`]).
pub const FORCE_LIMIT_REG: usize = 33;
/// input_double: blend radius (m) of a path via-point (`KIND_PATH_ADD_*`). Its own recipe
/// ([`blend_recipe`]), sent before the command that uses it.
pub const BLEND_REG: usize = 34;
/// output_int: id of the newest command the program accepted.
pub const ACCEPTED_ID_REG: usize = 24;
/// output_int: id of the newest command that finished.
pub const DONE_ID_REG: usize = 25;
/// output_int: `STATUS_*` of the newest command.
pub const STATUS_REG: usize = 26;
/// output_int: `ERROR_*` of the newest finished command.
pub const ERROR_REG: usize = 27;
/// output_int: incremented every control cycle while the program runs.
pub const PROGRAM_BEAT_REG: usize = 28;
/// output_int: 1 when the newest guarded move stopped on contact, 0 when it reached its target
/// without (written before `DONE_ID`).
pub const CONTACT_REG: usize = 29;

/// Command kind: movej to joints.
pub const KIND_MOVEJ: i32 = 1;
/// Command kind: movel to a pose.
pub const KIND_MOVEL: i32 = 2;
/// Command kind: stop the arm.
pub const KIND_STOP: i32 = 3;
/// Command kind: set a standard digital output.
pub const KIND_SET_STANDARD_DO: i32 = 4;
/// Command kind: set a tool digital output.
pub const KIND_SET_TOOL_DO: i32 = 5;
/// Command kind: guarded linear move to a pose, stopping on contact (`FORCE_LIMIT_REG`).
pub const KIND_MOVE_UNTIL_CONTACT: i32 = 6;

/// Command kind: append a joint via-point (`movej`) to the path buffer: target, speed,
/// acceleration, blend radius (`BLEND_REG`); `DO_PIN_REG` carries its index in the path (0
/// starts a new path).
pub const KIND_PATH_ADD_MOVEJ: i32 = 7;
/// Command kind: append a tool-line via-point (`movel` to a pose) to the path buffer, as
/// [`KIND_PATH_ADD_MOVEJ`].
pub const KIND_PATH_ADD_MOVEL: i32 = 8;
/// Command kind: run the buffered path as one blended `movej`/`movel ..., r=` sequence; done
/// when the arm rests at its last via-point. The buffer is emptied.
pub const KIND_PATH_RUN: i32 = 9;
/// Command kind: set standard analog output `DO_PIN_REG` (0 or 1) to the ratio 0–1 of its range
/// in the first target register (a gripper's opening set-point), then sleep `DO_WAIT_REG`.
pub const KIND_SET_STANDARD_AO: i32 = 10;

/// Status: idle / the last command succeeded.
pub const STATUS_IDLE: i32 = 0;
/// Status: a motion is running.
pub const STATUS_BUSY: i32 = 1;
/// Status: the last command failed (see `ERROR_REG`).
pub const STATUS_FAILED: i32 = 2;

/// Error: none.
pub const ERROR_NONE: i32 = 0;
/// Error: the watchdog saw no heartbeat and stopped the arm.
pub const ERROR_WATCHDOG: i32 = 1;
/// Error: unknown command kind.
pub const ERROR_UNKNOWN_COMMAND: i32 = 2;
/// Error: the motion was interrupted by a stop command.
pub const ERROR_STOPPED: i32 = 3;
/// Error: the controller could not execute the motion (unreachable, singular, invalid).
pub const ERROR_MOTION: i32 = 4;
/// Error: the output wait (`DO_WAIT_REG`) was negative, not a number or over [`MAX_DO_WAIT_S`];
/// the output was not changed.
pub const ERROR_INVALID_WAIT: i32 = 5;
/// Error: a guarded move's force limit (`FORCE_LIMIT_REG`) was not a positive number up to
/// [`MAX_CONTACT_FORCE_N`]; the arm did not move.
pub const ERROR_INVALID_FORCE: i32 = 6;

/// Error: a path command out of order (a via-point index that is not the next, more than
/// [`MAX_PATH_POINTS`], running an empty path) or with a blend radius that is negative or not a
/// number; the arm did not move.
pub const ERROR_INVALID_PATH: i32 = 7;
/// Error: an analog output command named no such output (0 or 1) or a ratio outside 0–1 (or not
/// a number); the output was not changed.
pub const ERROR_INVALID_OUTPUT: i32 = 8;

/// Most via-points a path may have.
pub const MAX_PATH_POINTS: usize = 16;

/// Seconds without a heartbeat change before the watchdog stops the arm.
pub const WATCHDOG_TIMEOUT_S: f64 = 0.5;
/// Deceleration of stop commands and watchdog stops (rad/s²).
pub const STOP_DECELERATION: f64 = 3.0;
/// Longest wait after a set-output command the program accepts (s). The program reads no
/// command while it sleeps, so a stop waits behind it.
pub const MAX_DO_WAIT_S: f64 = 5.0;

/// Largest force limit of a guarded move the program accepts, N (UR's default protective-stop
/// force, which would stop the arm first).
pub const MAX_CONTACT_FORCE_N: f64 = 150.0;

/// Every constant the script declares in its layout block, as (script name, value).
pub const SCRIPT_CONSTANTS: &[(&str, f64)] = &[
    ("CMD_ID_REG", CMD_ID_REG as f64),
    ("CMD_KIND_REG", CMD_KIND_REG as f64),
    ("DO_PIN_REG", DO_PIN_REG as f64),
    ("DO_LEVEL_REG", DO_LEVEL_REG as f64),
    ("HEARTBEAT_REG", HEARTBEAT_REG as f64),
    ("TARGET_REG", TARGET_REG as f64),
    ("SPEED_REG", SPEED_REG as f64),
    ("ACCEL_REG", ACCEL_REG as f64),
    ("DO_WAIT_REG", DO_WAIT_REG as f64),
    ("FORCE_LIMIT_REG", FORCE_LIMIT_REG as f64),
    ("ACCEPTED_ID_REG", ACCEPTED_ID_REG as f64),
    ("DONE_ID_REG", DONE_ID_REG as f64),
    ("STATUS_REG", STATUS_REG as f64),
    ("ERROR_REG", ERROR_REG as f64),
    ("PROGRAM_BEAT_REG", PROGRAM_BEAT_REG as f64),
    ("CONTACT_REG", CONTACT_REG as f64),
    ("BLEND_REG", BLEND_REG as f64),
    ("KIND_MOVEJ", KIND_MOVEJ as f64),
    ("KIND_MOVEL", KIND_MOVEL as f64),
    ("KIND_STOP", KIND_STOP as f64),
    ("KIND_SET_STANDARD_DO", KIND_SET_STANDARD_DO as f64),
    ("KIND_SET_TOOL_DO", KIND_SET_TOOL_DO as f64),
    ("KIND_MOVE_UNTIL_CONTACT", KIND_MOVE_UNTIL_CONTACT as f64),
    ("KIND_PATH_ADD_MOVEJ", KIND_PATH_ADD_MOVEJ as f64),
    ("KIND_PATH_ADD_MOVEL", KIND_PATH_ADD_MOVEL as f64),
    ("KIND_PATH_RUN", KIND_PATH_RUN as f64),
    ("KIND_SET_STANDARD_AO", KIND_SET_STANDARD_AO as f64),
    ("STATUS_IDLE", STATUS_IDLE as f64),
    ("STATUS_BUSY", STATUS_BUSY as f64),
    ("STATUS_FAILED", STATUS_FAILED as f64),
    ("ERROR_NONE", ERROR_NONE as f64),
    ("ERROR_WATCHDOG", ERROR_WATCHDOG as f64),
    ("ERROR_UNKNOWN_COMMAND", ERROR_UNKNOWN_COMMAND as f64),
    ("ERROR_STOPPED", ERROR_STOPPED as f64),
    ("ERROR_MOTION", ERROR_MOTION as f64),
    ("ERROR_INVALID_WAIT", ERROR_INVALID_WAIT as f64),
    ("ERROR_INVALID_FORCE", ERROR_INVALID_FORCE as f64),
    ("ERROR_INVALID_PATH", ERROR_INVALID_PATH as f64),
    ("ERROR_INVALID_OUTPUT", ERROR_INVALID_OUTPUT as f64),
    ("MAX_PATH_POINTS", MAX_PATH_POINTS as f64),
    ("WATCHDOG_TIMEOUT", WATCHDOG_TIMEOUT_S),
    ("STOP_DECELERATION", STOP_DECELERATION),
    ("MAX_DO_WAIT", MAX_DO_WAIT_S),
    ("MAX_CONTACT_FORCE", MAX_CONTACT_FORCE_N),
];

/// Names of the input registers the client writes for a command, in recipe order.
pub fn command_recipe() -> Vec<String> {
    let mut names = vec![
        format!("input_int_register_{CMD_KIND_REG}"),
        format!("input_int_register_{DO_PIN_REG}"),
        format!("input_int_register_{DO_LEVEL_REG}"),
    ];
    names.extend((0..6).map(|i| format!("input_double_register_{}", TARGET_REG + i)));
    names.push(format!("input_double_register_{SPEED_REG}"));
    names.push(format!("input_double_register_{ACCEL_REG}"));
    names.push(format!("input_double_register_{DO_WAIT_REG}"));
    // The id goes last: the controller applies a package at once, so order is only cosmetic.
    names.push(format!("input_int_register_{CMD_ID_REG}"));
    names
}

/// Name of the guarded-move force limit register (its own recipe, sent before the command that
/// uses it, so clients of the plain command recipe are unaffected).
pub fn force_limit_recipe() -> Vec<String> {
    vec![format!("input_double_register_{FORCE_LIMIT_REG}")]
}

/// Name of the path via-point blend radius register (its own recipe, sent before each
/// `KIND_PATH_ADD_*` command).
pub fn blend_recipe() -> Vec<String> {
    vec![format!("input_double_register_{BLEND_REG}")]
}

/// Name of the heartbeat input register (its own recipe).
pub fn heartbeat_recipe() -> Vec<String> {
    vec![format!("input_int_register_{HEARTBEAT_REG}")]
}

/// Output variables the client reads for the program protocol.
pub fn output_registers() -> Vec<String> {
    [
        ACCEPTED_ID_REG,
        DONE_ID_REG,
        STATUS_REG,
        ERROR_REG,
        PROGRAM_BEAT_REG,
        CONTACT_REG,
    ]
    .iter()
    .map(|r| format!("output_int_register_{r}"))
    .collect()
}
