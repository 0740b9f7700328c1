//! Blended paths: the leading run of fast moves the engine sends to the arm as one blended path
//! ([`leading_path`]), and the planner's check of the transit margin along that path as the arm
//! will run it ([`Planner::check_blended`]): the arm model of [`robots::limited::check_path`],
//! sampled every [`PATH_SAMPLE_PERIOD`], each sample's TCP by forward kinematics.

use robots::kinematics::Joints;
use robots::limited::{PATH_SAMPLE_PERIOD, check_path};
use robots::robot::Waypoint;
use robots::virtual_ur::arm::{ArmError, KinematicArm};
use robots::virtual_ur::path::{PathCycle, execute_path, waypoint_moves};

use super::planning::{Held, MARGIN_ROUNDING, Motion, NamedMotion, Placed, PlanError, Planner};

/// The leading run of fast arm moves of `motions` (joint moves, and straight lines at
/// `fast_speed` or faster; never the slow segments into a grasp or an insertion) as the
/// via-points of one blended path, each rounded by `radius` but the last; `None` when the run
/// has fewer than two moves.
pub fn leading_path(
    motions: &[NamedMotion],
    radius: f64,
    fast_speed: f64,
) -> Option<Vec<Waypoint>> {
    let n = motions
        .iter()
        .take_while(|(_, m)| match m {
            Motion::MoveJ(..) => true,
            Motion::MoveL(_, s) => s.speed >= fast_speed,
            _ => false,
        })
        .count();
    if n < 2 {
        return None;
    }
    let path = motions[..n]
        .iter()
        .enumerate()
        .filter_map(|(i, (_, m))| {
            let blend = if i + 1 < n { radius } else { 0.0 };
            match m {
                Motion::MoveJ(q, s) => Some(Waypoint::joints(*q, *s, blend)),
                Motion::MoveL(p, s) => Some(Waypoint::linear(*p, *s, blend)),
                _ => None,
            }
        })
        .collect();
    Some(path)
}

impl Planner<'_> {
    /// With blending on, checks that the gripper and `held` keep `transit_margin` from every
    /// shape in `placed` along the blended path of `motions`' leading run of fast moves
    /// ([`leading_path`]) from joints `from`, as the arm will run it: the arm model of
    /// [`check_path`] every [`PATH_SAMPLE_PERIOD`], each sample's TCP by forward kinematics.
    /// A sample is skipped while the motion since the last checked one (summed joint travel
    /// times [`super::CellKnowledge::arm_reach`]) cannot have closed the clearance found there
    /// to the margin, so a path far from everything costs a few distance queries. A shape
    /// already within the margin where the path starts (what the fingers leave) is not
    /// checked; nor is a path the limits refuse, which the engine runs stop by stop, each
    /// move checked on its own.
    pub(super) fn check_blended(
        &self,
        waypoint: &'static str,
        from: &Joints,
        motions: &[NamedMotion],
        held: Option<Held<'_>>,
        placed: &Placed<'_>,
    ) -> Result<(), PlanError> {
        let radius = self.config.blend_radius;
        if radius <= 0.0 || placed.is_empty() {
            return Ok(());
        }
        let Some(path) = leading_path(motions, radius, self.speeds.fast.speed) else {
            return Ok(());
        };
        let k = self.knowledge;
        if check_path(&k.spec.limits, &k.kinematics, from, &path).is_err() {
            return Ok(());
        }
        let mut arm = KinematicArm::new(k.kinematics.clone(), *from);
        let mut samples = vec![*from];
        let run = execute_path(
            &mut arm,
            &waypoint_moves(&path),
            PATH_SAMPLE_PERIOD,
            |c: &PathCycle| -> Result<(), ArmError> {
                samples.push(c.state.q);
                Ok(())
            },
        );
        if run.is_err() {
            return Ok(());
        }
        let reach = k.arm_reach(held);
        let margin = self.config.transit_margin;
        for (g, base_T_obstacle) in placed {
            let clearance = |q: &Joints| {
                let tcp = k.kinematics.forward_tcp(q);
                k.gripper_distance(&tcp, held, g.hull.as_ref(), base_T_obstacle)
            };
            if clearance(from) < margin {
                continue;
            }
            // How far the gripper and held part may still move before the next check.
            let mut slack = 0.0;
            for (i, pair) in samples.windows(2).enumerate() {
                let (a, b) = (&pair[0], &pair[1]);
                slack -= (0..6).map(|j| (b[j] - a[j]).abs()).sum::<f64>() * reach;
                if slack > 0.0 && i + 2 < samples.len() {
                    continue;
                }
                let d = clearance(b);
                if d < margin - MARGIN_ROUNDING {
                    return Err(PlanError::Collision {
                        waypoint,
                        what: format!(
                            "gripper or held part within the {:.1} mm transit margin of {} on \
                             the path blended by {:.1} mm",
                            margin * 1e3,
                            g.name,
                            radius * 1e3
                        ),
                        distance_mm: d * 1e3,
                    });
                }
                slack = d - margin;
            }
        }
        Ok(())
    }
}
