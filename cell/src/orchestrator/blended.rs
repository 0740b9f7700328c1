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
    /// A sample is skipped while the motion since the last checked one (the TCP's travel plus
    /// its turn times [`super::CellKnowledge::gripper_reach`], sample to sample) cannot have
    /// closed the clearance found there to the margin, so a path far from everything costs a
    /// few distance queries. A shape
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
        // The TCP at every sample, and how far any point of the gripper or held part moves from
        // one sample to the next: at most the TCP's travel plus its turn times their reach.
        let tcps: Vec<_> = samples
            .iter()
            .map(|q| k.kinematics.forward_tcp(q))
            .collect();
        let reach = k.gripper_reach(held);
        let moved: Vec<f64> = tcps
            .windows(2)
            .map(|w| {
                (w[1].translation.vector - w[0].translation.vector).norm()
                    + w[0].rotation.angle_to(&w[1].rotation) * reach
            })
            .collect();
        let margin = self.config.transit_margin;
        for (g, base_T_obstacle) in placed {
            let clearance = |tcp| k.gripper_distance(tcp, held, g.hull.as_ref(), base_T_obstacle);
            if clearance(&tcps[0]) < margin {
                continue;
            }
            // How far the gripper and held part may still move before the next check.
            let mut slack = 0.0;
            for (i, step) in moved.iter().enumerate() {
                slack -= step;
                if slack > 0.0 && i + 1 < moved.len() {
                    continue;
                }
                let d = clearance(&tcps[i + 1]);
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

#[cfg(test)]
mod tests {
    use std::path::Path;

    use nalgebra::{Isometry3, Translation3, Vector3};
    use robots::robot::LinearMotion;

    use super::*;
    use crate::orchestrator::geometry::CellKnowledge;
    use crate::orchestrator::planning::{PlanningConfig, Speeds};
    use crate::scenario::Scenario;

    /// An obstacle inside a rounded corner: clear of both straight moves by more than the
    /// margin, so the moves pass stop by stop and a check at the via-points passes too, but
    /// 0.5 mm from the blended path as the arm runs it, which is refused.
    #[test]
    fn an_obstacle_inside_a_rounded_corner_refuses_the_blended_path() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
        let scenario = Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let k = CellKnowledge::new(&scenario).unwrap_or_else(|e| panic!("{e}"));
        let config = PlanningConfig {
            blend_radius: 0.02,
            ..PlanningConfig::default()
        };
        let planner = Planner {
            knowledge: &k,
            config,
            speeds: Speeds::within(&k.spec.limits, config.slow_speed),
        };
        let fast = LinearMotion {
            speed: planner.speeds.fast.speed,
            acceleration: planner.speeds.fast.acceleration,
        };
        // Above the fixture, across 80 mm, then 60 mm straight down: an L the blend rounds.
        let from = k.base_T_targets[0].translation.vector + Vector3::new(-0.08, 0.0, 0.1);
        let pose = |p: Vector3<f64>| {
            Isometry3::from_parts(Translation3::from(p), crate::orchestrator::top_down(0.0))
        };
        let corner = from + Vector3::new(0.08, 0.0, 0.0);
        let end = corner - Vector3::new(0.0, 0.0, 0.06);
        let q_start = k
            .ik_solutions(&pose(from), &[0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
            .unwrap()[0];
        let motions: Vec<NamedMotion> = vec![
            ("transfer", Motion::MoveL(pose(corner), fast)),
            ("pre-insert", Motion::MoveL(pose(end), fast)),
        ];
        let path = leading_path(&motions, config.blend_radius, fast.speed).unwrap();
        check_path(&k.spec.limits, &k.kinematics, &q_start, &path)
            .unwrap_or_else(|e| panic!("the blended path runs: {e}"));
        // The blended path's samples and the one farthest inside the corner.
        let mut arm = KinematicArm::new(k.kinematics.clone(), q_start);
        let mut tcps = Vec::new();
        execute_path(
            &mut arm,
            &waypoint_moves(&path),
            PATH_SAMPLE_PERIOD,
            |c: &PathCycle| -> Result<(), ArmError> {
                tcps.push(k.kinematics.forward_tcp(&c.state.q).translation.vector);
                Ok(())
            },
        )
        .unwrap();
        let inside = |p: &Vector3<f64>| (corner.z - p.z).min(corner.x - p.x);
        let deepest = tcps
            .iter()
            .copied()
            .max_by(|a, b| inside(a).total_cmp(&inside(b)))
            .unwrap();
        assert!(
            inside(&deepest) > 0.004,
            "the corner is cut by {}",
            inside(&deepest)
        );
        // A part inside the corner, moved out along the corner's diagonal until it comes
        // 0.5 mm from the blended path.
        let g = k.part("main_shell").unwrap();
        let out = Vector3::new(1.0, 0.0, 1.0).normalize();
        let (lo, hi) = g.aabb;
        let half = 0.5 * (hi - lo).norm();
        let at = |t: f64| {
            Isometry3::translation(
                deepest.x - out.x * (half + 0.03) + out.x * t,
                deepest.y,
                deepest.z - out.z * (half + 0.03) + out.z * t,
            ) * Isometry3::translation(
                -0.5 * (lo.x + hi.x),
                -0.5 * (lo.y + hi.y),
                -0.5 * (lo.z + hi.z),
            )
        };
        let blended_min = |o: &Isometry3<f64>| {
            tcps.iter()
                .map(|p| k.gripper_distance(&pose(*p), None, g.hull.as_ref(), o))
                .fold(f64::INFINITY, f64::min)
        };
        let (mut a, mut b) = (0.0, half + 0.03);
        assert!(blended_min(&at(a)) > 0.0005 && blended_min(&at(b)) < 0.0005);
        for _ in 0..40 {
            let m = 0.5 * (a + b);
            if blended_min(&at(m)) > 0.0005 {
                a = m;
            } else {
                b = m;
            }
        }
        let obstacle = at(a);
        let placed = [(g, obstacle)];
        // Stop by stop, each straight move keeps the margin.
        for (p0, p1) in [(pose(from), pose(corner)), (pose(corner), pose(end))] {
            let line_min = (0..=1000)
                .map(|i| {
                    let tcp = p0.lerp_slerp(&p1, i as f64 / 1000.0);
                    k.gripper_distance(&tcp, None, g.hull.as_ref(), &obstacle)
                })
                .fold(f64::INFINITY, f64::min);
            assert!(line_min > config.transit_margin, "{line_min}");
        }
        let e = planner
            .check_blended("pre-insert", &q_start, &motions, None, &placed)
            .expect_err("the blended path passes 0.5 mm from the part");
        assert!(
            e.to_string().contains("on the path blended by 20.0 mm"),
            "{e}"
        );
        // Without blending nothing is checked here (the moves are checked on their own).
        let unblended = Planner {
            config: PlanningConfig::default(),
            ..planner
        };
        assert_eq!(
            unblended.check_blended("pre-insert", &q_start, &motions, None, &placed),
            Ok(())
        );
    }
}
