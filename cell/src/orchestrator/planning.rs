//! Motion planning for one pick and one insertion.
//!
//! Waypoints: approach (above the grasp), grasp, lift, transfer (above the insertion), pre-insert,
//! insert, release, retreat. Every waypoint is solved by IK (nearest the previous solution) and
//! every motion between them is checked: the arm's joint frames and gripper body stay above the
//! table, and the fingers, palm and held part keep a clearance (parry distances) from the fixture
//! and the parts already placed, except on the final slow insertion into the target. The last
//! millimetres of the grasp and of the insertion are slow Cartesian moves. The insertion target is
//! corrected by the estimated grasp offset: the jaws centre the part along the closing axis (TCP
//! y), so that component of the pre-grasp estimate is removed; the rest is kept.
//!
//! A pick or an insertion whose motions the checks refuse for a clearance is planned again
//! higher: the arm first rises straight up from where it is, and the via-points above the
//! grasp or the target rise as much, in [`RAISE_STEP`]s up to [`MAX_RAISE`] or as far as the
//! workspace limits and the arm's reach allow; the lowest height that passes is kept, with the
//! refusal that sent it higher ([`Plan::raised`]). The step is given up only when no height
//! passes. With blending on, the blended path is checked as it will run ([`super::blended`]).

use nalgebra::{Isometry3, Translation3};
use robots::kinematics::Joints;
use robots::limits::Limits;
use robots::robot::{JointMotion, LinearMotion};
use sim::cell::geometry::PartGeometry;

use super::geometry::CellKnowledge;
use super::selection::Selection;

/// Planning tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanningConfig {
    /// Height of approach, lift, transfer and retreat poses above their grasp or insert pose, m.
    pub clearance_height: f64,
    /// Length of the slow final segment into a grasp, and of the slow segment before the held
    /// part can first touch its receiver in an insertion, metres.
    pub slow_distance: f64,
    /// Speed of the slow final segments, m/s.
    pub slow_speed: f64,
    /// Smallest height of the arm's joint frames and gripper body above the table, metres.
    pub arm_table_margin: f64,
    /// Smallest distance of gripper and held part to the fixture and placed parts in transit, m.
    pub transit_margin: f64,
    /// Joint-space samples checked along each joint move.
    pub samples: usize,
    /// Search offsets of insertion retries.
    pub search: SearchConfig,
    /// Blend radius of the lift → transit → approach chains, m (`[motion] blend_radius`; 0
    /// stops at every via-point). Above 0 the lift, approach and transfer poses rise by it, so
    /// a corner rounded within it keeps the clearance height.
    pub blend_radius: f64,
}

/// How a retried insertion searches for the hole (the cell measures neither the lateral nor the
/// yaw error of a failed insertion, only that it failed and how high it stopped).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchConfig {
    /// Yaw step about the insertion axis after a jam, radians (±step, ±2 step, ...).
    pub yaw_step: f64,
    /// Smallest lateral step after a miss, metres (the step's lead-in or half clearance when
    /// larger).
    pub min_lateral: f64,
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            yaw_step: 0.3f64.to_radians(),
            min_lateral: 5e-5,
        }
    }
}

impl Default for PlanningConfig {
    fn default() -> Self {
        Self {
            clearance_height: crate::scenario::PLANNER_CLEARANCE_HEIGHT,
            slow_distance: crate::scenario::PLANNER_SLOW_DISTANCE,
            slow_speed: 0.02,
            arm_table_margin: 0.02,
            transit_margin: 0.001,
            samples: 10,
            search: SearchConfig::default(),
            blend_radius: 0.0,
        }
    }
}

/// One command of a plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// Joint move.
    MoveJ(Joints, JointMotion),
    /// Straight-line TCP move.
    MoveL(Isometry3<f64>, LinearMotion),
    /// Open the fingers to this far apart, metres.
    Open(f64),
    /// Close the gripper.
    Close,
}

/// A waypoint's name and its command.
pub type NamedMotion = (&'static str, Motion);

/// A held part: its shapes and its estimated `tcp_T_part`.
pub(super) type Held<'a> = (&'a PartGeometry, &'a Isometry3<f64>);

/// Parts already in place (or lying in the feeder) with their poses in the base frame.
pub(super) type Placed<'a> = [(&'a PartGeometry, Isometry3<f64>)];

/// A checked sequence of commands with a name for each.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// (waypoint name, command), in order.
    pub motions: Vec<NamedMotion>,
    /// Joints at the end of the plan.
    pub end_joints: Joints,
    /// An insertion's engagement depth: how far above seated the held part first meets what
    /// it goes into, metres (0 for a pick).
    pub engagement: f64,
    /// Set when the plan at its usual heights was refused and this one runs higher.
    pub raised: Option<Raised>,
}

/// How much higher than usual a plan runs, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Raised {
    /// How far the arm rises first and the via-points are raised, metres.
    pub height: f64,
    /// What refused the plan at its usual heights.
    pub refused: PlanError,
}

impl std::fmt::Display for Raised {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "raised {:.0} mm (the lowest height that passes): at the usual height {}",
            self.height * 1e3,
            self.refused
        )
    }
}

/// The step between the heights a refused plan is tried at, metres.
pub const RAISE_STEP: f64 = 0.005;

/// The most a refused plan is raised, metres.
pub const MAX_RAISE: f64 = 0.3;

/// Why no plan was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// A waypoint has no IK solution within the joint limits.
    #[error("{waypoint} unreachable: {reason}")]
    Unreachable {
        /// The waypoint.
        waypoint: &'static str,
        /// The IK error.
        reason: String,
    },
    /// A waypoint or a motion violates the cell's limits.
    #[error("{waypoint} outside the cell limits: {reason}")]
    Limits {
        /// The waypoint.
        waypoint: &'static str,
        /// The violation.
        reason: String,
    },
    /// A motion would collide.
    #[error("{waypoint}: {what} (clearance {distance_mm:.2} mm)")]
    Collision {
        /// The motion's target waypoint.
        waypoint: &'static str,
        /// What would touch what.
        what: String,
        /// The clearance found, millimetres (negative: penetration below the table).
        distance_mm: f64,
    },
}

/// The fast and slow motions allowed by the limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Speeds {
    /// Joint moves.
    pub joint: JointMotion,
    /// Fast linear moves.
    pub fast: LinearMotion,
    /// Slow final linear moves.
    pub slow: LinearMotion,
}

impl Speeds {
    /// Speeds within `limits`: joint and fast linear moves at the limits, the slow segments at
    /// `slow_speed`.
    pub fn within(limits: &Limits, slow_speed: f64) -> Self {
        Self {
            joint: JointMotion {
                speed: limits.max_joint_speed,
                acceleration: limits.max_joint_acceleration,
            },
            fast: LinearMotion {
                speed: limits.max_tcp_speed,
                acceleration: limits.max_tcp_acceleration,
            },
            slow: LinearMotion {
                speed: slow_speed.min(limits.max_tcp_speed),
                acceleration: (0.5f64).min(limits.max_tcp_acceleration),
            },
        }
    }
}

fn raised(pose: &Isometry3<f64>, h: f64) -> Isometry3<f64> {
    Translation3::new(0.0, 0.0, h) * pose
}

/// The finest step of the clearance search along a motion: how far any point of the gripper or
/// held part moves between two checks where the clearance is within this of the margin, metres.
/// The clearance between checks is at least the margin less this.
const CLEARANCE_RESOLUTION: f64 = 1e-5;

/// Rounding allowed on the margin, metres: a fast descent ends exactly `slow_distance` above
/// what it goes into, which the distance query returns to within this.
pub(super) const MARGIN_ROUNDING: f64 = 1e-6;

/// A motion's TCP path, for [`Planner::check_clear`].
#[derive(Clone, Copy)]
enum TcpPath<'p> {
    /// A joint move: the joints interpolated linearly.
    Joint(&'p Joints, &'p Joints),
    /// A straight-line move: translation interpolated linearly, rotation by slerp.
    Line(&'p Isometry3<f64>, &'p Isometry3<f64>),
}

/// The way down to just above a goal ([`Planner::down_to`]): its motions and the joints at
/// the pose just above the goal and at the higher pose the arm returns to.
struct Descent {
    motions: Vec<NamedMotion>,
    at_pre: Joints,
    at_via: Joints,
}

/// Plans with the cell model.
pub struct Planner<'a> {
    /// The cell.
    pub knowledge: &'a CellKnowledge,
    /// Tuning.
    pub config: PlanningConfig,
    /// Speeds.
    pub speeds: Speeds,
}

impl Planner<'_> {
    /// The IK solutions for `pose` (checked against the workspace limits), most preferred first
    /// ([`CellKnowledge::ik_solutions`]); never empty.
    fn ik_solutions(
        &self,
        waypoint: &'static str,
        pose: &Isometry3<f64>,
        near: &Joints,
    ) -> Result<Vec<Joints>, PlanError> {
        self.knowledge
            .spec
            .limits
            .check_tcp_target(pose)
            .map_err(|e| PlanError::Limits {
                waypoint,
                reason: e.to_string(),
            })?;
        self.knowledge
            .ik_solutions(pose, near)
            .map_err(|e| PlanError::Unreachable {
                waypoint,
                reason: e.to_string(),
            })
    }

    /// The preferred IK solution for `pose` near `near`: on the same arm branch, nearest.
    fn ik(
        &self,
        waypoint: &'static str,
        pose: &Isometry3<f64>,
        near: &Joints,
    ) -> Result<Joints, PlanError> {
        Ok(self.ik_solutions(waypoint, pose, near)?[0])
    }

    fn check_arm(&self, waypoint: &'static str, q: &Joints) -> Result<(), PlanError> {
        let low = self.knowledge.arm_lowest_height(q);
        if low < self.config.arm_table_margin {
            return Err(PlanError::Collision {
                waypoint,
                what: "arm or gripper body too close to the table".into(),
                distance_mm: low * 1e3,
            });
        }
        Ok(())
    }

    /// Checks a joint move from `from` to `to`: its TCP path inside the workspace box (exactly
    /// as [`robots::limited::Limited`] will check it before the move), and at `samples` points
    /// the arm above the table, gripper and held part clear of the table, the fixture and the
    /// placed parts.
    #[allow(non_snake_case)]
    fn check_transit(
        &self,
        waypoint: &'static str,
        from: &Joints,
        to: &Joints,
        held: Option<Held<'_>>,
        placed: &[(&PartGeometry, Isometry3<f64>)],
    ) -> Result<(), PlanError> {
        let k = self.knowledge;
        // A joint move's TCP swings off the straight line: between two targets inside the box
        // it can leave it (a wide feeder-to-fixture move), and the limits would stop the arm.
        k.spec
            .limits
            .check_move_j(
                &k.kinematics,
                from,
                to,
                &self.speeds.joint,
                robots::limited::JOINT_PATH_SAMPLES,
            )
            .map_err(|e| PlanError::Limits {
                waypoint,
                reason: e.to_string(),
            })?;
        let n = self.config.samples.max(1);
        for i in 1..=n {
            let s = i as f64 / n as f64;
            let q: Joints = std::array::from_fn(|j| from[j] + s * (to[j] - from[j]));
            self.check_arm(waypoint, &q)?;
            let tcp = k.kinematics.forward_tcp(&q);
            let low = k.lowest_height(&tcp, held);
            if low < self.config.transit_margin {
                return Err(PlanError::Collision {
                    waypoint,
                    what: "fingertips or held part too close to the table".into(),
                    distance_mm: low * 1e3,
                });
            }
        }
        self.check_clear(waypoint, TcpPath::Joint(from, to), held, placed, false)
    }

    /// Checks that the gripper (fingers at full stroke, palm) and the held part keep
    /// `transit_margin` from every shape in `placed` along the whole of `path`, not only at
    /// samples: from each checked point the search advances as far as no point of them can
    /// close the clearance left above the margin (a bound on their speed along the path:
    /// [`CellKnowledge::arm_reach`] per radian of a joint move, the line's length plus its turn
    /// times [`CellKnowledge::gripper_reach`] for a straight line), and at least
    /// [`CLEARANCE_RESOLUTION`]. `leaving`: a shape already within the margin where the path
    /// starts (the part just released, on a retreat) is not checked.
    fn check_clear(
        &self,
        waypoint: &'static str,
        path: TcpPath<'_>,
        held: Option<Held<'_>>,
        placed: &Placed<'_>,
        leaving: bool,
    ) -> Result<(), PlanError> {
        let k = self.knowledge;
        let margin = self.config.transit_margin;
        let tcp_at = |s: f64| match path {
            TcpPath::Joint(a, b) => {
                let q: Joints = std::array::from_fn(|j| a[j] + s * (b[j] - a[j]));
                k.kinematics.forward_tcp(&q)
            }
            TcpPath::Line(a, b) => a.lerp_slerp(b, s),
        };
        let rate = match path {
            TcpPath::Joint(a, b) => {
                (0..6).map(|j| (b[j] - a[j]).abs()).sum::<f64>() * k.arm_reach(held)
            }
            TcpPath::Line(a, b) => {
                (b.translation.vector - a.translation.vector).norm()
                    + a.rotation.angle_to(&b.rotation) * k.gripper_reach(held)
            }
        };
        let start = tcp_at(0.0);
        for (g, base_T_obstacle) in placed {
            let clearance = |tcp: &Isometry3<f64>| {
                k.gripper_distance(tcp, held, g.hull.as_ref(), base_T_obstacle)
            };
            if leaving && clearance(&start) < margin {
                continue;
            }
            let mut s = 0.0;
            loop {
                let d = clearance(&tcp_at(s));
                if d < margin - MARGIN_ROUNDING {
                    return Err(PlanError::Collision {
                        waypoint,
                        what: format!(
                            "gripper or held part within the {:.1} mm transit margin of {}",
                            margin * 1e3,
                            g.name
                        ),
                        distance_mm: d * 1e3,
                    });
                }
                if s >= 1.0 || rate <= 0.0 {
                    break;
                }
                s = (s + (d - margin).max(CLEARANCE_RESOLUTION) / rate).min(1.0);
            }
        }
        Ok(())
    }

    /// Checks that the fingers, `opening` metres apart, keep `transit_margin` from every part
    /// lying in the feeder (`feeder`: estimated poses, the part to pick included) along a joint
    /// move.
    fn check_fingers(
        &self,
        waypoint: &'static str,
        (from, to): (&Joints, &Joints),
        opening: f64,
        feeder: &[(&PartGeometry, Isometry3<f64>)],
    ) -> Result<(), PlanError> {
        let k = self.knowledge;
        let n = self.config.samples.max(1);
        for i in 1..=n {
            let s = i as f64 / n as f64;
            let q: Joints = std::array::from_fn(|j| from[j] + s * (to[j] - from[j]));
            let tcp = k.kinematics.forward_tcp(&q);
            for (g, base_T_part) in feeder {
                let d = k.finger_distance(&tcp, opening, g.hull.as_ref(), base_T_part);
                if d < self.config.transit_margin {
                    return Err(PlanError::Collision {
                        waypoint,
                        what: format!("a finger too close to {} in the feeder", g.name),
                        distance_mm: d * 1e3,
                    });
                }
            }
        }
        Ok(())
    }

    /// The motions from `start` to `pre`, the pose just above a goal, the joints there and at
    /// `via` (higher above the goal, where the arm returns to): one joint move straight to `pre`
    /// when that path is checked clear (plus `direct_check`), so the arm does not stop above the
    /// goal; otherwise a joint move to `via` (checked) and a fast straight line down. `names`
    /// label the two motions. The arm configurations at `via` are tried in order of preference
    /// ([`CellKnowledge::ik_solutions`]) until one has a clear path: the nearest one can lie
    /// beyond a joint limit's wrap and swing the arm through the table.
    fn down_to(
        &self,
        names: [&'static str; 2],
        start: &Joints,
        via: &Isometry3<f64>,
        pre: Isometry3<f64>,
        (held, placed): (Option<Held<'_>>, &Placed<'_>),
        direct_check: impl Fn(&Joints) -> Result<(), PlanError>,
    ) -> Result<Descent, PlanError> {
        let [to_via, to_pre] = names;
        let s = &self.speeds;
        let mut first_error = None;
        for q_via in self.ik_solutions(to_via, via, start)? {
            let attempt = self.ik(to_pre, &pre, &q_via).and_then(|at_pre| {
                let direct = self
                    .check_transit(to_pre, start, &at_pre, held, placed)
                    .and_then(|()| direct_check(&at_pre));
                let motions = if direct.is_ok() {
                    vec![(to_via, Motion::MoveJ(at_pre, s.joint))]
                } else {
                    self.check_transit(to_via, start, &q_via, held, placed)?;
                    self.check_clear(to_pre, TcpPath::Line(via, &pre), held, placed, false)?;
                    vec![
                        (to_via, Motion::MoveJ(q_via, s.joint)),
                        (to_pre, Motion::MoveL(pre, s.fast)),
                    ]
                };
                Ok(Descent {
                    motions,
                    at_pre,
                    at_via: q_via,
                })
            });
            match attempt {
                Ok(descent) => return Ok(descent),
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
        Err(first_error.expect("ik_solutions is never empty"))
    }

    /// Plans with `plan` at the usual heights (`plan(0.0)`); when a clearance check refuses
    /// that ([`PlanError::Collision`]), again [`RAISE_STEP`] higher at a time up to
    /// [`MAX_RAISE`], until a height passes (the plan is marked [`Plan::raised`] with the first
    /// refusal) or the raised poses leave the workspace limits or the arm's reach. Gives the
    /// first refusal when no height passes.
    fn lowest_clear(
        &self,
        plan: impl Fn(f64) -> Result<Plan, PlanError>,
    ) -> Result<Plan, PlanError> {
        let refused = match plan(0.0) {
            Ok(p) => return Ok(p),
            Err(e @ PlanError::Collision { .. }) => e,
            Err(e) => return Err(e),
        };
        let steps = (MAX_RAISE / RAISE_STEP).round() as usize;
        let mut tried = 0.0;
        for i in 1..=steps {
            let height = i as f64 * RAISE_STEP;
            match plan(height) {
                Ok(mut p) => {
                    p.raised = Some(Raised { height, refused });
                    return Ok(p);
                }
                Err(PlanError::Collision { .. }) => tried = height,
                // Higher poses are outside the workspace or out of reach.
                Err(_) => break,
            }
        }
        Err(match refused {
            PlanError::Collision {
                waypoint,
                what,
                distance_mm,
            } => PlanError::Collision {
                waypoint,
                what: if tried > 0.0 {
                    format!(
                        "{what}; no plan up to {:.0} mm higher passes either",
                        tried * 1e3
                    )
                } else {
                    format!("{what}; no higher plan is within the workspace limits and reach")
                },
                distance_mm,
            },
            e => e,
        })
    }

    /// A straight rise by `height` from joints `start` ([`PlanError`] when the raised pose is
    /// outside the workspace or out of reach, or the way up is not clear): the motion and the
    /// joints at its top. `None` for a height of 0.
    fn rise(
        &self,
        start: &Joints,
        height: f64,
        (held, placed): (Option<Held<'_>>, &Placed<'_>),
    ) -> Result<Option<(NamedMotion, Joints)>, PlanError> {
        if height <= 0.0 {
            return Ok(None);
        }
        let k = self.knowledge;
        let from = k.kinematics.forward_tcp(start);
        let top = raised(&from, height);
        let q_top = self.ik("rise", &top, start)?;
        self.check_arm("rise", &q_top)?;
        self.check_clear("rise", TcpPath::Line(&from, &top), held, placed, true)?;
        Ok(Some((
            ("rise", Motion::MoveL(top, self.speeds.fast)),
            q_top,
        )))
    }

    /// The pick of `selection` starting from joints `start`: the fingers opened to the part,
    /// one joint move to just above the grasp when that path is checked clear of the table, the
    /// placed parts and every part in the `feeder` (estimated poses, the one to pick included);
    /// otherwise a joint move to the approach pose and fast straight down. Then slow to the
    /// grasp, close, lift. Refused for a clearance, it is planned higher
    /// ([`Self::lowest_clear`]): a rise first, a higher approach and lift.
    pub fn pick(
        &self,
        selection: &Selection,
        start: &Joints,
        placed: &[(&PartGeometry, Isometry3<f64>)],
        feeder: &[(&PartGeometry, Isometry3<f64>)],
    ) -> Result<Plan, PlanError> {
        self.lowest_clear(|height| self.pick_at(height, selection, start, placed, feeder))
    }

    /// [`Self::pick`] with the arm rising `height` first and the approach (and lift) that
    /// much higher.
    fn pick_at(
        &self,
        height: f64,
        selection: &Selection,
        start: &Joints,
        placed: &[(&PartGeometry, Isometry3<f64>)],
        feeder: &[(&PartGeometry, Isometry3<f64>)],
    ) -> Result<Plan, PlanError> {
        let c = &self.config;
        let k = self.knowledge;
        let grasp = selection.base_T_grasp;
        // The part as it will hang in the fingers.
        let tcp_T_held = grasped_offset(&selection.tcp_T_part);
        let held = k.part(&selection.detection.part).map(|g| (g, &tcp_T_held));
        // High enough that the held part's lowest point (or the fingertips) clears the highest
        // placed part by the margin and the slow distance, as the transfer above the target
        // does; raised by the blend radius (0 unless blending): a blended corner cuts it by at
        // most that much.
        let over_placed = k.highest_top(placed).map_or(0.0, |top| {
            top + c.transit_margin + c.slow_distance - k.lowest_height(&grasp, held)
        });
        let approach = raised(
            &grasp,
            c.clearance_height.max(over_placed) + c.blend_radius + height,
        );
        let pre = raised(&grasp, c.slow_distance);
        let s = &self.speeds;
        let rise = self.rise(start, height, (None, placed))?;
        let from = rise.as_ref().map_or(*start, |(_, q)| *q);
        let Descent {
            mut motions,
            at_pre: q_pre,
            at_via: q_approach,
        } = self.down_to(
            ["approach", "pre-grasp"],
            &from,
            &approach,
            pre,
            (None, placed),
            |q_pre| self.check_fingers("pre-grasp", (&from, q_pre), selection.opening, feeder),
        )?;
        if let Some((m, _)) = rise {
            motions.insert(0, m);
        }
        // Blended (when on), the way down runs as one path from `start`.
        self.check_blended("pre-grasp", start, &motions, None, placed)?;
        // The fingers open to the part (no wider) as the arm leaves; without an opening margin
        // they are open the full stroke already.
        if selection.opening < self.knowledge.gripper().stroke {
            motions.insert(0, ("open fingers", Motion::Open(selection.opening)));
        }
        let q_grasp = self.ik("grasp", &grasp, &q_pre)?;
        self.check_arm("grasp", &q_grasp)?;
        self.check_clear("lift", TcpPath::Line(&grasp, &approach), held, placed, true)?;
        motions.extend([
            ("grasp", Motion::MoveL(grasp, s.slow)),
            ("close", Motion::Close),
            ("lift", Motion::MoveL(approach, s.fast)),
        ]);
        Ok(Plan {
            motions,
            end_joints: q_approach,
            engagement: 0.0,
            raised: None,
        })
    }

    /// The insertion of a held part (estimated `tcp_T_part`, released by opening the fingers
    /// `opening` apart) into step `step`'s nominal target moved by `correction` (in the insertion frame: identity for a first attempt), from joints
    /// `start` (the lift pose): joint move to the transfer pose, fast down to the pre-insert
    /// pose, slow insertion, release, retreat. Refused for a clearance, it is planned higher
    /// ([`Self::lowest_clear`]): a rise first, a higher transfer and retreat.
    #[allow(non_snake_case)]
    pub fn insert(
        &self,
        step: usize,
        held: ((&PartGeometry, &Isometry3<f64>), f64),
        correction: &Isometry3<f64>,
        start: &Joints,
        placed: &[(&PartGeometry, Isometry3<f64>)],
    ) -> Result<Plan, PlanError> {
        self.insert_after(step, held, correction, start, placed, None)
    }

    /// [`Self::insert`] where the arm first runs `lead` (the pick's lift, held back to start
    /// the insertion's blended path) from the joints given with it to `start`: with blending
    /// on, the blended path from there is checked as one.
    #[allow(non_snake_case)]
    pub fn insert_after(
        &self,
        step: usize,
        held: ((&PartGeometry, &Isometry3<f64>), f64),
        correction: &Isometry3<f64>,
        start: &Joints,
        placed: &[(&PartGeometry, Isometry3<f64>)],
        lead: Option<(&Joints, &NamedMotion)>,
    ) -> Result<Plan, PlanError> {
        self.lowest_clear(|height| {
            self.insert_at(height, step, held, correction, (start, lead), placed)
        })
    }

    /// [`Self::insert_after`] with the arm rising `height` first and the transfer (and
    /// retreat) that much higher.
    #[allow(non_snake_case)]
    fn insert_at(
        &self,
        height: f64,
        step: usize,
        (held, opening): ((&PartGeometry, &Isometry3<f64>), f64),
        correction: &Isometry3<f64>,
        (start, lead): (&Joints, Option<(&Joints, &NamedMotion)>),
        placed: &[(&PartGeometry, Isometry3<f64>)],
    ) -> Result<Plan, PlanError> {
        let k = self.knowledge;
        let c = &self.config;
        let base_T_ins = k.base_T_insertions[step];
        let base_T_target = base_T_ins * correction * base_T_ins.inverse() * k.base_T_targets[step];
        let tcp_T_part = held.1;
        let insert = base_T_target * tcp_T_part.inverse();
        // Back out along the insertion frame's z (out of the hole).
        let out = base_T_ins.rotation * nalgebra::Vector3::z();
        let along = |h: f64| Translation3::from(out * h) * insert;
        let engagement = engagement_depth(held, &base_T_target, placed);
        let transfer = along(
            c.clearance_height.max(engagement + 2.0 * c.slow_distance) + c.blend_radius + height,
        );
        // Slow from before the held part can first touch what it goes into (its engagement
        // depth, from the shapes, and how much lower than estimated the part may truly hang),
        // to seated; the fast descent keeps the transit margin above it.
        let pre = along(engagement + k.held_drop(held) + c.slow_distance.max(c.transit_margin));
        let s = &self.speeds;
        let rise = self.rise(start, height, (Some(held), placed))?;
        let from = rise.as_ref().map_or(*start, |(_, q)| *q);
        // One joint move straight to the pre-insert pose when that path is checked clear (no
        // stop above the target); otherwise transfer, then straight down.
        let Descent {
            mut motions,
            at_pre: q_pre,
            at_via: q_transfer,
        } = self.down_to(
            ["transfer", "pre-insert"],
            &from,
            &transfer,
            pre,
            (Some(held), placed),
            |_| Ok(()),
        )?;
        if let Some((m, _)) = rise {
            motions.insert(0, m);
        }
        // Blended (when on), the lift held back from the pick and the way down run as one path.
        match lead {
            Some((lead_from, lead)) => {
                let chain: Vec<NamedMotion> = std::iter::once(*lead)
                    .chain(motions.iter().copied())
                    .collect();
                self.check_blended("pre-insert", lead_from, &chain, Some(held), placed)?;
            }
            None => self.check_blended("pre-insert", start, &motions, Some(held), placed)?,
        }
        let q_insert = self.ik("insert", &insert, &q_pre)?;
        self.check_arm("insert", &q_insert)?;
        // The fingers leave the released part (not in `placed`) and the receiver they straddle.
        self.check_clear(
            "retreat",
            TcpPath::Line(&insert, &transfer),
            None,
            placed,
            true,
        )?;
        motions.extend([
            ("insert", Motion::MoveL(insert, s.slow)),
            ("release", Motion::Open(opening)),
            ("retreat", Motion::MoveL(transfer, s.fast)),
        ]);
        Ok(Plan {
            motions,
            end_joints: q_transfer,
            engagement,
            raised: None,
        })
    }
}

/// How far above seated the held part (`held.0` with `held.1` = tcp_T_part, seated at
/// `base_T_target`) first reaches the top of the fixture or the placed parts: the depth it
/// engages along the (vertical) insertion, metres; 0 when nothing is above its lowest point.
#[allow(non_snake_case)]
fn engagement_depth(
    held: (&PartGeometry, &Isometry3<f64>),
    base_T_target: &Isometry3<f64>,
    placed: &[(&PartGeometry, Isometry3<f64>)],
) -> f64 {
    let low = |g: &PartGeometry, t: &Isometry3<f64>| {
        g.mesh
            .vertices
            .iter()
            .map(|p| (t * p).z)
            .fold(f64::INFINITY, f64::min)
    };
    let high = |g: &PartGeometry, t: &Isometry3<f64>| {
        g.mesh
            .vertices
            .iter()
            .map(|p| (t * p).z)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let bottom = low(held.0, base_T_target);
    placed
        .iter()
        .map(|(g, t)| high(g, t) - bottom)
        .fold(0.0, f64::max)
}

/// The estimated pose of a grasped part in the TCP frame: the pre-grasp estimate with the
/// component along the closing axis (TCP y) removed, since the jaws centre the part there.
#[allow(non_snake_case)]
pub fn grasped_offset(tcp_T_part_estimate: &Isometry3<f64>) -> Isometry3<f64> {
    let mut t = *tcp_T_part_estimate;
    t.translation.vector.y = 0.0;
    t
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::scenario::Scenario;

    /// What the engine knows of the nominal USB-C cell.
    fn nominal_knowledge() -> std::sync::Arc<CellKnowledge> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
        let scenario = Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
        CellKnowledge::new(&scenario).unwrap_or_else(|e| panic!("{e}"))
    }

    /// A planner with the default configuration in the cell `knowledge` describes.
    fn default_planner(knowledge: &CellKnowledge) -> Planner<'_> {
        let config = PlanningConfig::default();
        Planner {
            knowledge,
            config,
            speeds: Speeds::within(&knowledge.spec.limits, config.slow_speed),
        }
    }

    #[test]
    fn a_refused_plan_takes_the_lowest_height_that_passes() {
        let knowledge = nominal_knowledge();
        let planner = default_planner(&knowledge);
        let refused = |h: f64| PlanError::Collision {
            waypoint: "transfer",
            what: format!("at {:.0} mm", h * 1e3),
            distance_mm: 0.5,
        };
        let plan = || Plan {
            motions: Vec::new(),
            end_joints: [0.0; 6],
            engagement: 0.0,
            raised: None,
        };
        // Nothing refused: planned at the usual heights.
        assert_eq!(planner.lowest_clear(|_| Ok(plan())).unwrap().raised, None);
        // Clear from 12 mm up: the next step up, 15 mm, with the usual height's refusal.
        let tried = std::cell::RefCell::new(Vec::new());
        let p = planner
            .lowest_clear(|h| {
                tried.borrow_mut().push(h);
                if h < 0.012 {
                    Err(refused(h))
                } else {
                    Ok(plan())
                }
            })
            .unwrap();
        let r = p.raised.expect("raised");
        assert!((r.height - 0.015).abs() < 1e-12, "{r}");
        assert_eq!(r.refused, refused(0.0));
        assert_eq!(tried.borrow().len(), 4, "{:?}", tried.borrow());
        // Beyond the workspace from 20 mm: given up with the usual height's refusal and how
        // high it looked.
        let e = planner
            .lowest_clear(|h| {
                if h < 0.02 {
                    Err(refused(h))
                } else {
                    Err(PlanError::Limits {
                        waypoint: "transfer",
                        reason: "above the workspace".into(),
                    })
                }
            })
            .unwrap_err();
        let PlanError::Collision { what, .. } = e else {
            panic!("{e}")
        };
        assert_eq!(what, "at 0 mm; no plan up to 15 mm higher passes either");
        // A refusal that is not a clearance is not tried higher.
        let calls = std::cell::Cell::new(0);
        let e = planner.lowest_clear(|_| {
            calls.set(calls.get() + 1);
            Err(PlanError::Unreachable {
                waypoint: "insert",
                reason: "out of reach".into(),
            })
        });
        assert!(matches!(e, Err(PlanError::Unreachable { .. })));
        assert_eq!(calls.get(), 1);
    }

    #[test]
    fn a_move_whose_nearest_configuration_swings_through_the_table_takes_another() {
        let knowledge = nominal_knowledge();
        let planner = default_planner(&knowledge);
        // From a learned-cell episode: the insert mold lifted off the feeder with the last wrist
        // 0.11 rad short of its +2π limit, and the transfer above the shell needs 1.09 rad more.
        // The nearest configuration within the limits turns the shoulder round instead, and
        // its straight joint path ends 56 mm below the table.
        let start = [
            1.2086,
            -1.4826,
            2.4496,
            -2.5378,
            -std::f64::consts::FRAC_PI_2,
            6.1709,
        ];
        let swung = [
            -1.2026,
            -3.6828,
            1.5167,
            0.5953,
            -std::f64::consts::FRAC_PI_2,
            5.0805,
        ];
        let transfer = knowledge.kinematics.forward_tcp(&swung);
        let nearest = planner.ik("transfer", &transfer, &start).unwrap();
        assert!(
            knowledge.arm_lowest_height(&nearest) < 0.0,
            "the nearest configuration {nearest:?} should be the one through the table"
        );
        let pre = raised(
            &transfer,
            -planner.config.clearance_height + planner.config.slow_distance,
        );
        let Descent {
            motions,
            at_pre: q_pre,
            at_via: q_via,
        } = planner
            .down_to(
                ["transfer", "pre-insert"],
                &start,
                &transfer,
                pre,
                (None, &[]),
                |_| Ok(()),
            )
            .unwrap_or_else(|e| panic!("no clear transfer: {e}"));
        assert!(!motions.is_empty());
        for q in [q_via, q_pre] {
            assert!(knowledge.arm_lowest_height(&q) >= planner.config.arm_table_margin);
            let tcp = knowledge.kinematics.forward_tcp(&q);
            let goal = if q == q_via { transfer } else { pre };
            assert!((tcp.translation.vector - goal.translation.vector).norm() < 1e-6);
        }
        // It keeps the shoulder and turns the wrist back through its range instead.
        assert!((q_via[0] - start[0]).abs() < 0.5, "{q_via:?}");
    }
}
