//! Generated MJCF: the convex pieces of the parts as MuJoCo collision meshes, with the options
//! and contact defaults of one simulation. Pure text, so it is built and checked without the
//! library; [`super::compile`] turns it into a model.

use std::fmt::Write;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

use super::MujocoError;
use crate::cell::geometry::PartGeometry;

/// Smallest extent a convex piece must have in each of its three directions, metres: below it
/// the piece spans no volume and MuJoCo's hull (qhull) rejects or misrepresents it.
pub const MIN_PIECE_EXTENT: f64 = 1e-8;

/// Simulation options and contact defaults of a generated model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Time step, seconds.
    pub timestep: f64,
    /// Gravity, m/s² (world frame).
    pub gravity: Vector3<f64>,
    /// Sliding friction of every contact.
    pub friction: f64,
    /// Contact time constant, seconds (solref; MuJoCo needs at least two time steps).
    pub contact_timeconst: f64,
    /// Contact damping ratio (solref).
    pub contact_dampratio: f64,
    /// Contact impedance (solimp d0 = dwidth): the share of a push the contact resists at once.
    pub contact_impedance: f64,
    /// Solver iterations per step.
    pub iterations: usize,
    /// Iterations of MuJoCo's no-slip pass (0: off); it removes the creep of soft friction.
    pub noslip_iterations: usize,
}

/// An MJCF document under construction: mesh assets for the convex pieces, with the part and
/// piece each came from so MuJoCo's complaints can be traced back.
#[derive(Debug, Clone)]
pub struct Mjcf {
    options: Options,
    assets: String,
    /// (part, piece index) of mesh asset `piece{i}`.
    pieces: Vec<(String, usize)>,
}

impl Mjcf {
    /// An empty model with these options.
    pub fn new(options: Options) -> Self {
        Self {
            options,
            assets: String::new(),
            pieces: Vec::new(),
        }
    }

    /// Adds every convex piece of `part`, its vertices moved by `pose`, as a mesh asset and
    /// returns the `<geom>` elements that place them (in the frame `pose` maps into). A piece
    /// that spans no volume is refused with the part and piece named.
    pub fn part_geoms(
        &mut self,
        part: &PartGeometry,
        pose: &Isometry3<f64>,
    ) -> Result<String, MujocoError> {
        self.piece_geoms(&part.name, &part.pieces.pieces, pose)
    }

    /// [`Mjcf::part_geoms`] for convex pieces given as vertex lists of the part named `part`.
    pub fn piece_geoms(
        &mut self,
        part: &str,
        pieces: &[Vec<Point3<f64>>],
        pose: &Isometry3<f64>,
    ) -> Result<String, MujocoError> {
        let mut geoms = String::new();
        for (index, piece) in pieces.iter().enumerate() {
            check_piece(part, index, piece)?;
            let name = format!("piece{}", self.pieces.len());
            let _ = write!(self.assets, "    <mesh name=\"{name}\" vertex=\"");
            for p in piece {
                let q = pose * p;
                let _ = write!(self.assets, "{} {} {} ", q.x, q.y, q.z);
            }
            self.assets.push_str("\"/>\n");
            let _ = writeln!(geoms, "      <geom type=\"mesh\" mesh=\"{name}\"/>");
            self.pieces.push((part.to_string(), index));
        }
        Ok(geoms)
    }

    /// The (part, piece) a MuJoCo error message names, if it names one of the meshes.
    pub fn piece_named_in(&self, message: &str) -> Option<(&str, usize)> {
        (0..self.pieces.len())
            .rev()
            .find(|i| message.contains(&format!("piece{i}")))
            .map(|i| (self.pieces[i].0.as_str(), self.pieces[i].1))
    }

    /// The whole document: options, contact defaults, the assets, then `worldbody` and
    /// `actuators` (element text).
    pub fn document(&self, worldbody: &str, actuators: &str) -> String {
        let o = &self.options;
        format!(
            "<mujoco model=\"cell\">\n  <compiler angle=\"radian\" autolimits=\"true\"/>\n  \
             <option timestep=\"{}\" gravity=\"{} {} {}\" integrator=\"implicitfast\" \
             cone=\"elliptic\" iterations=\"{}\" noslip_iterations=\"{}\">\n    <flag multiccd=\"enable\"/>\n  </option>\n  \
             <default>\n    <geom condim=\"3\" friction=\"{} 0 0\" solref=\"{} {}\" \
             solimp=\"{d} {d} 0.001\" density=\"0\"/>\n  </default>\n  <asset>\n{}  </asset>\n  \
             <worldbody>\n{worldbody}  </worldbody>\n  <actuator>\n{actuators}  </actuator>\n\
             </mujoco>\n",
            o.timestep,
            o.gravity.x,
            o.gravity.y,
            o.gravity.z,
            o.iterations.max(1),
            o.noslip_iterations,
            o.friction,
            o.contact_timeconst,
            o.contact_dampratio,
            self.assets,
            d = o.contact_impedance,
        )
    }
}

/// MJCF `pos` and `quat` attributes of a pose.
pub fn pose_attrs(pose: &Isometry3<f64>) -> String {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    format!(
        "pos=\"{} {} {}\" quat=\"{} {} {} {}\"",
        t.x, t.y, t.z, q.w, q.i, q.j, q.k
    )
}

/// A pose from MuJoCo's position and (w, x, y, z) quaternion.
pub fn pose_from(pos: &[f64; 3], quat: &[f64; 4]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Vector3::new(pos[0], pos[1], pos[2]).into(),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            quat[0], quat[1], quat[2], quat[3],
        )),
    )
}

/// Refuses a convex piece that has non-finite vertices or spans no volume (fewer than four
/// vertices, or thinner than [`MIN_PIECE_EXTENT`] in some direction).
pub fn check_piece(part: &str, piece: usize, points: &[Point3<f64>]) -> Result<(), MujocoError> {
    let fail = |reason: String| MujocoError::Piece {
        part: part.to_string(),
        piece,
        reason,
    };
    if let Some(p) = points
        .iter()
        .find(|p| !p.coords.iter().all(|c| c.is_finite()))
    {
        return Err(fail(format!("vertex {p} is not finite")));
    }
    if points.len() < 4 {
        return Err(fail(format!(
            "{} vertices span no volume (a collision mesh needs at least 4)",
            points.len()
        )));
    }
    // Extreme points: the farthest pair, the farthest from their line, the farthest from
    // their plane; each distance is an extent of the piece.
    let a = points[0];
    let b = farthest(points, |p| (p - a).norm());
    let ab = (b - a).normalize();
    let line = |p: &Point3<f64>| {
        let v = p - a;
        (v - ab * v.dot(&ab)).norm()
    };
    let c = farthest(points, line);
    let normal = ab.cross(&(c - a)).try_normalize(0.0);
    let extents = [
        (b - a).norm(),
        line(&c),
        normal.map_or(0.0, |n| {
            points
                .iter()
                .map(|p| (p - a).dot(&n).abs())
                .fold(0.0, f64::max)
        }),
    ];
    if let Some(e) = extents.iter().find(|e| **e < MIN_PIECE_EXTENT) {
        return Err(fail(format!(
            "degenerate: it is {:.3e} m thick (flat or collinear vertices), under the {:.0e} m a \
             MuJoCo collision mesh needs",
            e, MIN_PIECE_EXTENT
        )));
    }
    Ok(())
}

fn farthest(points: &[Point3<f64>], dist: impl Fn(&Point3<f64>) -> f64) -> Point3<f64> {
    points
        .iter()
        .copied()
        .max_by(|p, q| dist(p).total_cmp(&dist(q)))
        .unwrap_or(Point3::origin())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(s: f64) -> Vec<Point3<f64>> {
        let mut v = Vec::new();
        for x in [0.0, s] {
            for y in [0.0, s] {
                for z in [0.0, s] {
                    v.push(Point3::new(x, y, z));
                }
            }
        }
        v
    }

    #[test]
    fn a_solid_piece_passes_and_flat_or_tiny_ones_are_named() {
        check_piece("p", 0, &cube(1e-3)).unwrap();
        let flat: Vec<_> = cube(1e-3).into_iter().filter(|p| p.z == 0.0).collect();
        let err = check_piece("main_shell", 7, &flat).unwrap_err().to_string();
        assert!(
            err.contains("\"main_shell\"") && err.contains("piece 7"),
            "{err}"
        );
        assert!(err.contains("degenerate"), "{err}");
        let err = check_piece("p", 2, &cube(1e-3)[..3])
            .unwrap_err()
            .to_string();
        assert!(err.contains("3 vertices"), "{err}");
        let mut nan = cube(1e-3);
        nan[3].x = f64::NAN;
        assert!(check_piece("p", 0, &nan).is_err());
    }
}
