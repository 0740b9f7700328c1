//! The compliant wrist that pushes the held part in, shared by the contact engines so they
//! simulate the same device: a kinematic wrist descending along the insertion axis, the part
//! hanging on it by a six-axis spring (a remote-centre-compliance device with its centre at the
//! part's leading face) with an axial force cap (the push force), and when to stop.

use nalgebra::{Isometry3, Vector3};

use super::Mating;

/// The wrist's compliance, motion and stopping rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wrist {
    /// Wrist descent speed, m/s.
    pub speed: f64,
    /// How far below seated the wrist is commanded, metres (loads the axial spring).
    pub overtravel: f64,
    /// Lateral stiffness, N/m.
    pub lateral_stiffness: f64,
    /// Rotational stiffness, N·m/rad.
    pub rotational_stiffness: f64,
    /// Axial stiffness, N/m.
    pub axial_stiffness: f64,
    /// Largest axial push, N.
    pub max_push: f64,
    /// Damping ratio of every spring.
    pub damping_ratio: f64,
    /// Moving mass (platform, fingers and part), kg.
    pub mass: f64,
    /// Moving rotational inertia about each axis, kg·m².
    pub inertia: f64,
    /// Clear height above first contact where the part starts, metres.
    pub standoff: f64,
    /// Time the part must be still to end the simulation, seconds.
    pub settle: f64,
    /// Speed under which the part counts as still, m/s.
    pub still_speed: f64,
    /// Longest simulated time, seconds.
    pub max_time: f64,
}

impl Default for Wrist {
    fn default() -> Self {
        Self {
            speed: 0.025,
            overtravel: 1e-3,
            lateral_stiffness: 2_000.0,
            rotational_stiffness: 50.0,
            axial_stiffness: 5_000.0,
            max_push: 5.0,
            damping_ratio: 1.0,
            mass: 0.05,
            inertia: 2e-6,
            standoff: 2e-4,
            settle: 0.02,
            still_speed: 5e-4,
            max_time: 1.0,
        }
    }
}

impl Wrist {
    /// Damping of a spring of stiffness `k` on mass (or inertia) `m` at the damping ratio.
    pub fn damping(&self, k: f64, m: f64) -> f64 {
        2.0 * self.damping_ratio * (k * m).sqrt()
    }

    /// Where the part starts: the start pose lifted so its leading face is a standoff above
    /// the fit's top, lowered by how far the tilt drops a corner (insertion frame).
    #[allow(non_snake_case)]
    pub fn start_pose(&self, mating: &Mating, ins_T_part: &Isometry3<f64>) -> Isometry3<f64> {
        let start = mating.pose_error(ins_T_part);
        let corner_drop = mating.width_along(&start.tilt_direction) / 2.0 * start.tilt.sin();
        let mut pose = *ins_T_part;
        pose.translation.vector.z = mating.engagement + self.standoff + corner_drop.max(0.0);
        pose
    }

    /// The wrist's commanded pose at time `t` after starting at `start`: straight down at the
    /// descent speed until the overtravel depth below seated.
    pub fn pose_at(&self, start: &Isometry3<f64>, t: f64) -> Isometry3<f64> {
        let z = (start.translation.z - self.speed * t).max(-self.overtravel);
        let mut pose = *start;
        pose.translation.vector = Vector3::new(start.translation.x, start.translation.y, z);
        pose
    }

    /// Whether the wrist has reached its lowest point at time `t`.
    pub fn bottomed(&self, start: &Isometry3<f64>, t: f64) -> bool {
        start.translation.z - self.speed * t <= -self.overtravel
    }

    /// Whether a part moving at `linear` m/s and `angular` rad/s counts as still (the angular
    /// speed is taken at the rim of the fit).
    pub fn is_still(&self, mating: &Mating, linear: f64, angular: f64) -> bool {
        linear <= self.still_speed && angular * mating.half_width.max() <= self.still_speed
    }
}

/// The wrench the held part exerts on the wrist through the compliance device, in the insertion
/// frame at the compliance centre: force (N), then moment (N·m). It is what the flange's
/// force/torque sensor sees of the insertion: a part jammed above its seat pushes back with the
/// axial spring's force, up to [`Wrist::max_push`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WristWrench {
    /// Simulated time, s.
    pub t: f64,
    /// Force on the wrist, insertion frame, N.
    pub force: Vector3<f64>,
    /// Moment on the wrist about the compliance centre, insertion frame, N·m.
    pub moment: Vector3<f64>,
}

impl Wrist {
    /// The springs' load on the wrist at `wrist_pose` when the part is at `part_pose` (both
    /// insertion frame; the two frames coincide when the springs are relaxed), with the
    /// compliance centre at `centre` in the part frame: lateral and rotational springs linear in
    /// the deflection, the axial spring's force capped at the push force. Quasi-static: the
    /// springs' damping is left out (a sensor reading is filtered over many of the engines' steps).
    pub fn spring_wrench(
        &self,
        t: f64,
        wrist_pose: &Isometry3<f64>,
        part_pose: &Isometry3<f64>,
        centre: &nalgebra::Point3<f64>,
    ) -> WristWrench {
        // Deflection of the part's anchor from the wrist's, in the wrist frame.
        let offset = wrist_pose.inverse_transform_point(&(part_pose * centre)) - centre;
        let turn = (wrist_pose.rotation.inverse() * part_pose.rotation).scaled_axis();
        let axial = (self.axial_stiffness * offset.z).clamp(-self.max_push, self.max_push);
        let force = Vector3::new(
            self.lateral_stiffness * offset.x,
            self.lateral_stiffness * offset.y,
            axial,
        );
        let moment = turn * self.rotational_stiffness;
        WristWrench {
            t,
            force: wrist_pose.rotation * force,
            moment: wrist_pose.rotation * moment,
        }
    }
}
