//! The parallel gripper: finger geometry and what closing the fingers does to a part.
//!
//! The TCP is at the fingertip centre; a top-down grasp has TCP z pointing down into the table and
//! the fingers closing along TCP y. Each finger is a box `finger_width` along TCP x,
//! `finger_thickness` along TCP y and `finger_length` up from the tips (TCP −z).
//!
//! Closing on a part:
//! 1. the part between the fingers is the one whose material above the fingertips lies in the
//!    opening; none gives [`GraspFailure::NothingBetweenFingers`];
//! 2. it fails when the part is wider than the stroke, when a finger would come down on it
//!    (outside the finger reach), when its centre is off the finger pads across the closing axis,
//!    or when a finger's closing sweep (open position to contact) hits a neighbouring part,
//!    checked with parry against the true poses;
//! 3. the fingers square the part's grasp faces to the jaws unless the two diagonal contacts
//!    already hold it within the friction cone (`atan(b/a) − |ψ| ≤ atan μ`, the classic
//!    parallel-jaw result), then centre it along the closing axis;
//! 4. a residual offset along the closing axis and vertically, and residual rotations about the
//!    closing axis and the approach axis, are drawn from the scenario's grasp noise.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::query::intersection_test;
use parry3d_f64::shape::Cuboid;
use rand::Rng;
use serde::{Deserialize, Serialize};

use super::geometry::PartGeometry;
use super::noise::gauss;
use crate::config::{GripperSpec, NoiseSpec};
use crate::convert::{pose_from_isometry, vec_from_vector};

/// Grip force of the fingers, N (a small electric parallel gripper).
pub const GRIP_FORCE: f64 = 20.0;
/// Gravity, m/s².
const G: f64 = 9.81;

/// Which finger.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Finger {
    /// The finger on TCP −y.
    Left,
    /// The finger on TCP +y.
    Right,
}

/// Why closing the fingers did not grasp a part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, thiserror::Error)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum GraspFailure {
    /// No part lies between the fingers.
    #[error("nothing between the fingers")]
    NothingBetweenFingers,
    /// The part is wider than the finger stroke along the closing axis.
    #[error(
        "{part} #{instance} is {width:.4} m across the jaws, wider than the {stroke:.4} m stroke"
    )]
    TooWide {
        /// Part instance.
        instance: u32,
        /// Part name.
        part: String,
        /// Its width along the closing axis.
        width: f64,
        /// The stroke.
        stroke: f64,
    },
    /// The part is outside the finger reach: a finger would land on it, or its centre is off the
    /// finger pads across the closing axis.
    #[error("{part} #{instance} is outside the finger reach ({detail})")]
    OutsideReach {
        /// Part instance.
        instance: u32,
        /// Part name.
        part: String,
        /// Which way.
        detail: String,
    },
    /// A finger would hit a neighbouring part while coming down or closing.
    #[error(
        "{finger:?} finger would hit neighbour {neighbour_part} #{neighbour} grasping {part} #{instance}"
    )]
    NeighbourCollision {
        /// Part instance being grasped.
        instance: u32,
        /// Its name.
        part: String,
        /// The finger.
        finger: Finger,
        /// The neighbour's instance.
        neighbour: u32,
        /// The neighbour's name.
        neighbour_part: String,
    },
    /// Friction cannot hold the part's weight.
    #[error("{part} #{instance} would slip: friction {friction_force:.3} N < weight {weight:.3} N")]
    Slips {
        /// Part instance.
        instance: u32,
        /// Part name.
        part: String,
        /// Friction force available.
        friction_force: f64,
        /// Weight to hold.
        weight: f64,
    },
}

/// A part the fingers may close on.
#[derive(Debug, Clone, Copy)]
#[allow(non_snake_case)]
pub struct GraspCandidate<'a> {
    /// Instance id.
    pub instance: u32,
    /// Its shapes.
    pub geometry: &'a PartGeometry,
    /// Its true pose.
    pub base_T_part: Isometry3<f64>,
}

/// A successful grasp.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct Grasp {
    /// The grasped instance.
    pub instance: u32,
    /// The part's width between the closed jaws, metres.
    #[serde(default)]
    pub width: f64,
    /// True pose of the part in the TCP frame after closing.
    pub tcp_T_part: Isometry3<f64>,
    /// Offset of the part from the TCP across the closing axis before closing (TCP x), metres:
    /// what the fingers do not correct.
    pub uncorrected_offset: f64,
    /// Yaw of the grasp faces to the jaws before closing, radians.
    pub yaw_before: f64,
    /// Whether the jaws squared the part (false: friction held it at `yaw_before`).
    pub squared: bool,
    /// Residual offset drawn from the grasp noise (TCP frame), metres.
    pub residual_offset: Vector3<f64>,
    /// Residual rotation drawn from the grasp noise (TCP frame, rotation vector), radians.
    pub residual_rotation: Vector3<f64>,
}

/// The width of a part (its `vertices` in the part frame) across the jaws closing along the
/// unit `axis` (part frame), metres: what the fingers must open to at least.
pub fn width_across(vertices: &[Point3<f64>], axis: &Vector3<f64>) -> f64 {
    let (lo, hi) = vertices
        .iter()
        .map(|p| p.coords.dot(axis))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), d| {
            (l.min(d), h.max(d))
        });
    (hi - lo).max(0.0)
}

/// Closes the fingers, open the full stroke, at the true TCP pose `base_T_tcp` among `parts`.
#[allow(non_snake_case)]
pub fn close(
    spec: &GripperSpec,
    noise: &NoiseSpec,
    base_T_tcp: &Isometry3<f64>,
    parts: &[GraspCandidate<'_>],
    rng: &mut impl Rng,
) -> Result<Grasp, GraspFailure> {
    close_from(spec, spec.stroke, noise, base_T_tcp, parts, rng)
}

/// Closes the fingers, `opening` metres apart, at the true TCP pose `base_T_tcp` among `parts`.
#[allow(non_snake_case)]
pub fn close_from(
    spec: &GripperSpec,
    opening: f64,
    noise: &NoiseSpec,
    base_T_tcp: &Isometry3<f64>,
    parts: &[GraspCandidate<'_>],
    rng: &mut impl Rng,
) -> Result<Grasp, GraspFailure> {
    let tcp_T_base = base_T_tcp.inverse();
    let half_open = opening.min(spec.stroke) / 2.0;
    let half_w = spec.finger_width / 2.0;
    // The part between the fingers: material above the tips inside the opening.
    let mut best: Option<(f64, usize, [f64; 4])> = None;
    for (i, c) in parts.iter().enumerate() {
        let t = tcp_T_base * c.base_T_part;
        let mut ext = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let mut any = false;
        for p in &c.geometry.mesh.vertices {
            let q = t * p;
            if q.z <= 0.0 && q.z >= -spec.finger_length {
                any = true;
                ext = [
                    ext[0].min(q.x),
                    ext[1].max(q.x),
                    ext[2].min(q.y),
                    ext[3].max(q.y),
                ];
            }
        }
        let between =
            any && ext[0] < half_w && ext[1] > -half_w && ext[2] < half_open && ext[3] > -half_open;
        if between {
            let d = t.translation.vector.xy().norm();
            if best.as_ref().is_none_or(|b| d < b.0) {
                best = Some((d, i, ext));
            }
        }
    }
    let (_, index, ext) = best.ok_or(GraspFailure::NothingBetweenFingers)?;
    let target = &parts[index];
    let (instance, name) = (target.instance, target.geometry.name.clone());
    let width = ext[3] - ext[2];
    if width > spec.stroke {
        return Err(GraspFailure::TooWide {
            instance,
            part: name,
            width,
            stroke: spec.stroke,
        });
    }
    if ext[3] > half_open || ext[2] < -half_open {
        let side = if ext[3] > half_open { "right" } else { "left" };
        return Err(GraspFailure::OutsideReach {
            instance,
            part: name,
            detail: format!("the {side} finger would land on it"),
        });
    }
    let centre_x = 0.5 * (ext[0] + ext[1]);
    if centre_x.abs() > half_w {
        return Err(GraspFailure::OutsideReach {
            instance,
            part: name,
            detail: format!(
                "its centre is {:.2} mm off the finger pads",
                centre_x.abs() * 1e3
            ),
        });
    }
    // Closing sweeps: from the open fingers to the part's faces once centred.
    let half_t = spec.finger_thickness / 2.0;
    for (finger, y0, y1) in [
        (Finger::Left, -half_open - 2.0 * half_t, -width / 2.0),
        (Finger::Right, width / 2.0, half_open + 2.0 * half_t),
    ] {
        let sweep = Cuboid::new(vec_from_vector(&Vector3::new(
            half_w,
            (y1 - y0).abs() / 2.0,
            spec.finger_length / 2.0,
        )));
        let base_T_sweep =
            base_T_tcp * Isometry3::translation(0.0, 0.5 * (y0 + y1), -spec.finger_length / 2.0);
        let sweep_pose = pose_from_isometry(&base_T_sweep);
        for (j, n) in parts.iter().enumerate() {
            if j == index {
                continue;
            }
            let hit = intersection_test(
                &sweep_pose,
                &sweep,
                &pose_from_isometry(&n.base_T_part),
                n.geometry.hull.as_ref(),
            )
            .map(|r| r.intersecting)
            .unwrap_or(true);
            if hit {
                return Err(GraspFailure::NeighbourCollision {
                    instance,
                    part: name,
                    finger,
                    neighbour: n.instance,
                    neighbour_part: n.geometry.name.clone(),
                });
            }
        }
    }
    let weight = target.geometry.mass * G;
    let friction_force = 2.0 * spec.friction * GRIP_FORCE;
    if friction_force < weight {
        return Err(GraspFailure::Slips {
            instance,
            part: name,
            friction_force,
            weight,
        });
    }

    // Squaring: yaw of the part's grasp closing axis to the jaws (TCP y), modulo a half turn.
    let mut tcp_T_part = tcp_T_base * target.base_T_part;
    let table_T_part_like = target.base_T_part;
    let closing = target
        .geometry
        .stable_pose_of(&table_T_part_like)
        .and_then(|s| {
            target
                .geometry
                .grasps
                .iter()
                .find(|g| g.stable_pose == s.name)
        })
        .map(|g| Vector3::from(g.closing_axis))
        .unwrap_or_else(Vector3::x);
    let closing = if closing.norm() > 0.0 {
        closing.normalize()
    } else {
        Vector3::x()
    };
    // A part with exact symmetries is squared by its twin faces nearest the jaws.
    let closing = perception::symmetry::twin_axis_nearest(
        &closing,
        &tcp_T_part.rotation,
        &Vector3::y(),
        &perception::symmetry::symmetry_group(&target.geometry.symmetries),
    );
    let a_tcp = tcp_T_part.rotation * closing;
    let mut yaw = a_tcp.x.atan2(a_tcp.y);
    let half_pi = std::f64::consts::FRAC_PI_2;
    if yaw > half_pi {
        yaw -= std::f64::consts::PI;
    } else if yaw < -half_pi {
        yaw += std::f64::consts::PI;
    }
    let (lo, hi) = target.geometry.extent_along(&closing);
    let across = {
        let up = tcp_T_part.rotation.inverse() * -Vector3::z();
        let v = up.cross(&closing);
        if v.norm() > 1e-9 {
            v.normalize()
        } else {
            closing.cross(&Vector3::z())
        }
    };
    let (lo2, hi2) = target.geometry.extent_along(&across);
    let (a, b) = ((hi - lo) / 2.0, (hi2 - lo2) / 2.0);
    let diagonal = b.atan2(a);
    let squared = diagonal - yaw.abs() > spec.friction.atan();
    let turn_about = |iso: &Isometry3<f64>, r: UnitQuaternion<f64>, centre: Point3<f64>| {
        let c = iso * centre;
        Isometry3::from_parts(
            Translation3::from(c.coords + r * (iso.translation.vector - c.coords)),
            r * iso.rotation,
        )
    };
    let centre =
        Point3::from((target.geometry.aabb.0.coords + target.geometry.aabb.1.coords) / 2.0);
    if squared {
        // Rotating the closing axis onto TCP y: yaw measured from y toward x, so turn by +yaw.
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
        tcp_T_part = turn_about(&tcp_T_part, r, centre);
    }
    // Centre along the closing axis.
    let ys = target.geometry.mesh.vertices.iter().filter_map(|p| {
        let q = tcp_T_part * p;
        (q.z <= 0.0 && q.z >= -spec.finger_length).then_some(q.y)
    });
    let (ymin, ymax) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| {
        (l.min(y), h.max(y))
    });
    if ymin.is_finite() {
        tcp_T_part.translation.vector.y -= 0.5 * (ymin + ymax);
    }
    // Residuals.
    let residual_offset = Vector3::new(
        0.0,
        gauss(rng, noise.grasp_offset),
        gauss(rng, noise.grasp_offset),
    );
    let residual_rotation = Vector3::new(
        0.0,
        gauss(rng, noise.grasp_rotation),
        gauss(rng, noise.grasp_rotation),
    );
    tcp_T_part.translation.vector += residual_offset;
    tcp_T_part = turn_about(
        &tcp_T_part,
        UnitQuaternion::from_scaled_axis(residual_rotation),
        centre,
    );
    Ok(Grasp {
        instance,
        width,
        tcp_T_part,
        uncorrected_offset: centre_x,
        yaw_before: yaw,
        squared,
        residual_offset,
        residual_rotation,
    })
}
