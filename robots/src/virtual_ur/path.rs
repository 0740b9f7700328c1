//! Blended paths: ur_rtde's `moveJ(path)`, `moveL(path)` and `movePath` inject one URScript
//! statement per via-point into the control script's `exec_move_path()`
//! (`signal_async_progress(i)` and `movej(q, a=…, v=…, r=…)` / `movel(p[…], a=…, v=…, r=…)`),
//! re-upload it and send command 45. This module reads those statements and applies URScript's
//! rule for blend radii that overlap.
//!
//! It is also the one model of a blended path's execution outside the controller:
//! [`execute_path`] runs a path on a [`KinematicArm`] (the virtual UR's own arm model) cycle by
//! cycle, so the simulated cell times its blended paths, and [`crate::limited::Limited`] samples
//! them, with exactly the motion the virtual UR executes over RTDE.

use super::arm::{ArmError, ArmModel, ArmState, KinematicArm};
use crate::kinematics::{Joints, UrKinematics, to_ur_pose};
use crate::robot::{Waypoint, WaypointTarget};

pub use super::path_move::PathMove;

/// Where a path statement goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PathTarget {
    /// Joint positions (`[…]`).
    Joints([f64; 6]),
    /// A TCP pose (`p[…]`).
    Pose([f64; 6]),
}

/// One `movej`/`movel` statement of an injected path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathStatement {
    /// `movel` (a straight tool line) rather than `movej` (a joint-space move).
    pub linear: bool,
    /// The via-point.
    pub target: PathTarget,
    /// `v`: joint speed (rad/s) for movej, tool speed (m/s) for movel.
    pub speed: f64,
    /// `a`: joint (rad/s²) or tool (m/s²) acceleration.
    pub accel: f64,
    /// `r`: blend radius (m).
    pub blend: f64,
}

/// The arm model's moves for a [`Waypoint`] path (poses as UR pose vectors).
pub fn waypoint_moves(path: &[Waypoint]) -> Vec<PathMove> {
    path.iter()
        .map(|w| match w.target {
            WaypointTarget::Joints(q) => PathMove::Joint {
                q,
                speed: w.speed,
                accel: w.acceleration,
                blend: w.blend,
            },
            WaypointTarget::Linear(pose) => PathMove::Linear {
                pose: to_ur_pose(&pose),
                speed: w.speed,
                accel: w.acceleration,
                blend: w.blend,
            },
        })
        .collect()
}

/// The TCP positions of a path's start (joints `start`) and of every via-point, as
/// [`settle_blends`] takes them: joint via-points through `kinematics`' forward kinematics
/// (with its TCP), tool-line via-points as given.
pub fn via_points(kinematics: &UrKinematics, start: &Joints, moves: &[PathMove]) -> Vec<[f64; 3]> {
    let tcp = |q: &Joints| {
        let p = kinematics.forward_tcp(q).translation.vector;
        [p.x, p.y, p.z]
    };
    std::iter::once(tcp(start))
        .chain(moves.iter().map(|m| match m {
            PathMove::Joint { q, .. } => tcp(q),
            PathMove::Linear { pose, .. } => [pose[0], pose[1], pose[2]],
        }))
        .collect()
}

/// How a path ran in [`execute_path`].
#[derive(Debug, Clone, PartialEq)]
pub struct PathRun {
    /// Seconds from the path's start until the arm rests at its end: whole control cycles, as
    /// the virtual UR's arm model counts them.
    pub duration: f64,
    /// The joints it ends at.
    pub q: Joints,
    /// URScript's warnings for blends it skipped ([`settle_blends`]).
    pub warnings: Vec<String>,
}

/// One control cycle of a path in [`execute_path`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathCycle {
    /// Seconds since the path started (the end of this cycle).
    pub t: f64,
    /// The arm after this cycle: joints, their speeds and accelerations over the cycle, TCP.
    pub state: ArmState,
    /// Every segment moving in this cycle is a straight tool line.
    pub tool_lines: bool,
}

/// The virtual UR's control period, s (500 Hz, its default configuration): the cycle a
/// simulated cell times its blended paths at, so in-process and over RTDE they count the same.
pub const CONTROLLER_PERIOD: f64 = 0.002;

/// Longest a path may run in [`execute_path`] before it is given up as not ending, s.
pub const MAX_PATH_DURATION: f64 = 600.0;

/// Runs a blended path on `arm` (from its present joints) at control period `dt`: the blend
/// radii settled by URScript's rule, then the arm model's blended execution stepped cycle by
/// cycle until the arm rests; `each` sees every cycle and may stop the run with an error.
pub fn execute_path<E: From<ArmError>>(
    arm: &mut KinematicArm,
    moves: &[PathMove],
    dt: f64,
    mut each: impl FnMut(&PathCycle) -> Result<(), E>,
) -> Result<PathRun, E> {
    let start = arm.state().q;
    let points = via_points(arm.kinematics(), &start, moves);
    let (moves, warnings) = settle_blends(moves, &points);
    arm.command_path(&moves)?;
    let mut t = 0.0;
    let mut cycles = 0u64;
    while arm.is_moving() {
        let tool_lines = arm.path_on_tool_lines().unwrap_or(false);
        arm.step(dt, 1.0)?;
        cycles += 1;
        t = cycles as f64 * dt;
        each(&PathCycle {
            t,
            state: arm.state(),
            tool_lines,
        })?;
        if t > MAX_PATH_DURATION {
            return Err(ArmError::InvalidParameter("a path that does not end").into());
        }
    }
    Ok(PathRun {
        duration: t,
        q: arm.state().q,
        warnings,
    })
}

/// The line ur_rtde injects the path after.
const INJECTION_MARK: &str = "# inject move path";

/// The statements ur_rtde injected into `exec_move_path()`: an empty list when the script
/// carries no path; an error naming a statement this module does not execute (`movep`,
/// `movec`, anything else).
pub fn injected_path(script: &str) -> Result<Vec<PathStatement>, String> {
    let Some(at) = script.find(INJECTION_MARK) else {
        return Ok(Vec::new());
    };
    let mut moves = Vec::new();
    for line in script[at + INJECTION_MARK.len()..].lines().skip(1) {
        let line = line.trim();
        if line == "end" {
            break;
        }
        if line.is_empty()
            || line.starts_with('#')
            || line.starts_with("signal_async_progress(")
            || line.starts_with("textmsg(")
        {
            continue;
        }
        moves.push(statement(line).map_err(|e| format!("path statement `{line}`: {e}"))?);
    }
    Ok(moves)
}

fn statement(line: &str) -> Result<PathStatement, String> {
    let (call, rest) = line
        .split_once('(')
        .ok_or_else(|| "not a call".to_owned())?;
    let linear = match call.trim() {
        "movej" => false,
        "movel" => true,
        "movep" => return Err("movep (constant-speed process moves) is not simulated".into()),
        "movec" => return Err("movec (circular moves) is not simulated".into()),
        other => return Err(format!("`{other}` is not a move this controller executes")),
    };
    let args = rest
        .trim_end()
        .strip_suffix(')')
        .ok_or_else(|| "no closing parenthesis".to_owned())?;
    let (pose, list) = match args.trim_start().strip_prefix("p[") {
        Some(list) => (true, list),
        None => (
            false,
            args.trim_start()
                .strip_prefix('[')
                .ok_or_else(|| "no target list".to_owned())?,
        ),
    };
    let (values, kwargs) = list
        .split_once(']')
        .ok_or_else(|| "unterminated target list".to_owned())?;
    let values: Vec<f64> = values
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|e| format!("{v:?}: {e}")))
        .collect::<Result<_, _>>()?;
    let values: [f64; 6] = values
        .try_into()
        .map_err(|v: Vec<f64>| format!("{} target values, not 6", v.len()))?;
    let (mut speed, mut accel, mut blend) = (None, None, 0.0);
    for kw in kwargs.split(',').map(str::trim).filter(|k| !k.is_empty()) {
        let (key, value) = kw
            .split_once('=')
            .ok_or_else(|| format!("argument `{kw}`"))?;
        let value: f64 = value
            .trim()
            .parse()
            .map_err(|e| format!("argument `{kw}`: {e}"))?;
        match key.trim() {
            "v" => speed = Some(value),
            "a" => accel = Some(value),
            "r" => blend = value,
            other => return Err(format!("argument `{other}` is not simulated")),
        }
    }
    let target = if pose {
        PathTarget::Pose(values)
    } else {
        PathTarget::Joints(values)
    };
    Ok(PathStatement {
        linear,
        target,
        speed: speed.ok_or("no speed v")?,
        accel: accel.ok_or("no acceleration a")?,
        blend,
    })
}

/// URScript's rule for blend radii (its manual, `movel`/`movej`): a blend region that
/// overlaps the blend radius of the previous or the following via-point is not done, with an
/// "Overlapping Blends" warning. `points` are the TCP positions of the path's start and of
/// every via-point (one more than `moves`). The path's last via-point is where it ends: its
/// radius is dropped (nothing follows to blend into). Returns the moves with the radii that
/// are done and a warning per skipped blend. Kept blends satisfy, for every segment,
/// `r_start + r_end ≤ length`, so two blends never share a stretch of path.
pub fn settle_blends(moves: &[PathMove], points: &[[f64; 3]]) -> (Vec<PathMove>, Vec<String>) {
    assert_eq!(
        points.len(),
        moves.len() + 1,
        "a start and one point per move"
    );
    let length = |i: usize| {
        let (a, b) = (points[i], points[i + 1]);
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    let mut out: Vec<PathMove> = moves.to_vec();
    let mut warnings = Vec::new();
    let n = moves.len();
    for i in 0..n {
        let r = out[i].blend();
        if r <= 0.0 {
            out[i] = out[i].with_blend(0.0);
            continue;
        }
        if i + 1 == n {
            out[i] = out[i].with_blend(0.0);
            continue;
        }
        let before = if i == 0 { 0.0 } else { out[i - 1].blend() };
        let after = if i + 2 == n {
            0.0
        } else {
            moves[i + 1].blend().max(0.0)
        };
        let (into, out_of) = (length(i), length(i + 1));
        if r + before > into || r + after > out_of {
            warnings.push(format!(
                "Overlapping Blends: the blend of {r} m at via-point {i} overlaps the previous or \
                 next one (segments of {into:.4} m and {out_of:.4} m, neighbouring radii \
                 {before} m and {after} m): via-point {i} is reached without blending"
            ));
            out[i] = out[i].with_blend(0.0);
        }
    }
    (out, warnings)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_what_ur_rtde_injects() {
        let script = "def rtde_control():\n    def exec_move_path():\n        textmsg(\"exec_move_path\")\n        # inject move path\n\tsignal_async_progress(0)\n\tmovel(p[-0.4919,-0.1333,0.4379,2.22144,2.22144,-3.48787e-16],a=1.2,v=0.25,r=0.01)\n\tsignal_async_progress(1)\n\tmovej([0.4,-1.3,1.4,-1.6,-1.25,0.2],a=1,v=0.5,r=0)\n    end\n    textmsg(\"x\")\nend\n";
        let path = injected_path(script).unwrap();
        assert_eq!(path.len(), 2);
        assert!(path[0].linear);
        assert_eq!(
            path[0].target,
            PathTarget::Pose([-0.4919, -0.1333, 0.4379, 2.22144, 2.22144, -3.48787e-16])
        );
        assert_eq!(
            (path[0].speed, path[0].accel, path[0].blend),
            (0.25, 1.2, 0.01)
        );
        assert!(!path[1].linear);
        assert_eq!(
            path[1].target,
            PathTarget::Joints([0.4, -1.3, 1.4, -1.6, -1.25, 0.2])
        );
        assert!(
            injected_path("def rtde_control():\nend\n")
                .unwrap()
                .is_empty()
        );
        let movep = script.replace("movej(", "movep(");
        assert!(injected_path(&movep).unwrap_err().contains("movep"));
    }

    #[test]
    fn overlapping_blends_are_skipped_with_a_warning() {
        let mv = |blend| PathMove::Linear {
            pose: [0.0; 6],
            speed: 0.1,
            accel: 1.0,
            blend,
        };
        let points = [[0.0; 3], [0.1, 0.0, 0.0], [0.1, 0.1, 0.0], [0.2, 0.1, 0.0]];
        // 4 cm and 5 cm radii on a 10 cm segment: both kept; the last radius is dropped.
        let (out, warnings) = settle_blends(&[mv(0.04), mv(0.05), mv(0.03)], &points);
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(
            out.iter().map(PathMove::blend).collect::<Vec<_>>(),
            [0.04, 0.05, 0.0]
        );
        // 6 cm and 5 cm overlap on the 10 cm segment between them: the first is skipped.
        let (out, warnings) = settle_blends(&[mv(0.06), mv(0.05), mv(0.0)], &points);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(warnings[0].starts_with("Overlapping Blends"));
        assert_eq!(
            out.iter().map(PathMove::blend).collect::<Vec<_>>(),
            [0.0, 0.05, 0.0]
        );
        // A radius longer than the segment from the start overlaps the start.
        let (out, warnings) = settle_blends(&[mv(0.2), mv(0.0)], &points[..3]);
        assert_eq!((out[0].blend(), warnings.len()), (0.0, 1));
    }
}
