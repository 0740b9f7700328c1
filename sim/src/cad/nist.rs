//! The peg-in-hole set of the NIST Assembly Task Board 1, authored by this project: round and
//! square ("rectangular") pegs of 8, 12 and 16 mm and a fixture plate with one blind hole for
//! each, assembled top-down.
//!
//! Source: NIST, "Assembly Performance Metrics and Test Methods" (Intelligent Systems Division),
//! and Kimble et al., "Benchmarking Protocols for Evaluating Small Parts Robotic Assembly
//! Systems", IEEE Robotics and Automation Letters 5(2), 2020 (PMC7537423): task board 1 holds
//! round and rectangular pegs of 8, 12 and 16 mm inserted into holes in the board. The stored
//! copies of those pages give neither the hole tolerances nor the peg lengths, so this module
//! chooses them and says why (docs/guides/assembly-sequence.md):
//! - **Fit**: ISO 286 H9/d9 (a free running fit; the NIST board is known for generous
//!   tolerances, chosen so that many robots can be compared), at the middle of both tolerance
//!   bands: 8 mm: hole +18 µm, peg −58 µm, 0.076 mm total clearance; 12 and 16 mm: hole
//!   +21.5 µm, peg −71.5 µm, 0.093 mm. The square pegs take the same deviations on their widths.
//! - **Lead-in**: a 0.5 mm × 45° chamfer on every hole's rim; the pegs' ends are square.
//! - **Length**: 14 mm for every peg, 6 mm of it in its hole. A top-down parallel gripper can only
//!   insert a peg that stands on its end in the feeder, and a long peg almost never lands so.
//!   12 mm would still leave the fingers 4.5 mm of grip above the plate, but it makes the 12 mm
//!   square peg a near-cube (11.93 × 11.93 × 12 mm): standing and lying it shows the camera the
//!   same square to 0.07 mm, half a pixel, so no image tells its stable poses apart. At 14 mm
//!   every square peg's length is 1.9–6.1 mm (14 px or more at the seed's camera) from its width.
//!
//! Round pegs are regular 48-gons through their circle and round holes regular 48-gons around
//! theirs, so the gap is at least the nominal clearance at any turn of the peg (the flats are
//! 17 µm off the 16 mm circle, less than the 46.5 µm half-clearance). Dimensions in mm.

use nalgebra::{Isometry3, Point3};
use perception::part::TriMesh;

use super::solid::{Rect, Solid};
use crate::config::{AssemblyStep, Destination, PoseSpec, Tolerances};

/// Sides of the polygons that stand for circles (a multiple of 8, so the polygon has vertices on
/// both axes and on the diagonals, where the plate's square cells have their corners).
pub const CIRCLE_SIDES: usize = 48;
/// Length of every peg (mm).
pub const PEG_LENGTH_MM: f64 = 14.0;
/// Depth of every hole (mm): the peg's engagement when seated.
pub const HOLE_DEPTH_MM: f64 = 6.0;
/// Lead-in chamfer on every hole's rim (mm).
pub const HOLE_CHAMFER_MM: f64 = 0.5;
/// Thickness of the plate under the holes (mm).
pub const PLATE_BASE_MM: f64 = 4.0;
/// Distance between neighbouring holes (mm): fingers around one peg stay clear of the next.
pub const HOLE_PITCH_MM: f64 = 36.0;

/// A peg's cross-section.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PegShape {
    /// A cylinder.
    Round,
    /// A square prism (the board's "rectangular" pegs).
    Square,
}

/// One peg of the set and its hole.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peg {
    /// Catalog name, e.g. `round_8`.
    pub name: &'static str,
    /// The file its mesh is stored in, e.g. `round_8.obj`.
    pub file_name: &'static str,
    /// Cross-section.
    pub shape: PegShape,
    /// Nominal size: diameter or width (mm).
    pub nominal_mm: f64,
    /// Where its hole is on the plate (mm, plate frame).
    pub hole_xy_mm: (f64, f64),
}

impl Peg {
    /// ISO 286 H9 hole and d9 peg deviations at the middle of their bands (µm): (hole, peg).
    fn deviations_um(&self) -> (f64, f64) {
        if self.nominal_mm <= 10.0 {
            (18.0, -58.0)
        } else {
            (21.5, -71.5)
        }
    }

    /// The peg's diameter or width (mm).
    pub fn peg_size_mm(&self) -> f64 {
        self.nominal_mm + self.deviations_um().1 * 1e-3
    }

    /// The hole's diameter or width (mm).
    pub fn hole_size_mm(&self) -> f64 {
        self.nominal_mm + self.deviations_um().0 * 1e-3
    }

    /// Total clearance between peg and hole (mm).
    pub fn clearance_mm(&self) -> f64 {
        self.hole_size_mm() - self.peg_size_mm()
    }

    /// The peg's mesh (metres, part frame at its bounding-box centre).
    pub fn mesh(&self) -> TriMesh {
        let mut s = Solid::new();
        let half = self.peg_size_mm() / 2.0;
        match self.shape {
            PegShape::Square => {
                s.cuboid(Rect::centred(2.0 * half, 2.0 * half), 0.0, PEG_LENGTH_MM);
            }
            PegShape::Round => {
                // The 48-gon through the circle, fanned into quadrilaterals: hexahedra, as every
                // `Solid` is built (the convex pieces merge them back into one prism).
                let ring = polygon(half);
                for k in (1..CIRCLE_SIDES - 1).step_by(2) {
                    let quad = [ring[0], ring[k], ring[k + 1], ring[(k + 2) % CIRCLE_SIDES]];
                    s.hexahedron(at(quad, 0.0), at(quad, PEG_LENGTH_MM));
                }
            }
        }
        s.into_part_mesh()
    }

    /// `plate_T_peg`: the peg seated in its hole, on the hole's floor (part frames are
    /// bounding-box centres).
    pub fn seated(&self) -> Isometry3<f64> {
        let plate_centre_z = (PLATE_BASE_MM + HOLE_DEPTH_MM) / 2.0;
        let peg_centre_z = PLATE_BASE_MM + PEG_LENGTH_MM / 2.0;
        let (x, y) = self.hole_xy_mm;
        Isometry3::translation(x * 1e-3, y * 1e-3, (peg_centre_z - plate_centre_z) * 1e-3)
    }

    /// The assembly step that inserts this peg straight down into its hole in the plate (the
    /// plate is the destination, at its own frame), with the scenario's 0.5 mm lead-in and
    /// 0.1 mm / 0.01 rad tolerances.
    pub fn insertion_step(&self) -> AssemblyStep {
        let t = self.seated().translation.vector;
        AssemblyStep {
            part: self.name.into(),
            into: Destination::Fixture,
            target: PoseSpec {
                translation: [t.x, t.y, t.z],
                rotation: [0.0; 3],
            },
            insertion_axis: [0.0, 0.0, -1.0],
            clearance: self.clearance_mm() * 1e-3,
            lead_in: 0.0005,
            tolerances: Tolerances {
                lateral: 1e-4,
                depth: 1e-4,
                tilt: 0.01,
            },
        }
    }
}

/// The six pegs: round ones in the row at +y, square ones at −y, 8, 12 and 16 mm from −x to +x.
pub const PEGS: [Peg; 6] = [
    peg("round_8", "nist_round_8.obj", PegShape::Round, 8.0, 0),
    peg("round_12", "nist_round_12.obj", PegShape::Round, 12.0, 1),
    peg("round_16", "nist_round_16.obj", PegShape::Round, 16.0, 2),
    peg("square_8", "nist_square_8.obj", PegShape::Square, 8.0, 3),
    peg("square_12", "nist_square_12.obj", PegShape::Square, 12.0, 4),
    peg("square_16", "nist_square_16.obj", PegShape::Square, 16.0, 5),
];

const fn peg(
    name: &'static str,
    file_name: &'static str,
    shape: PegShape,
    nominal_mm: f64,
    index: usize,
) -> Peg {
    let column = (index % 3) as f64 - 1.0;
    let row = if index < 3 { 0.5 } else { -0.5 };
    Peg {
        name,
        file_name,
        shape,
        nominal_mm,
        hole_xy_mm: (column * HOLE_PITCH_MM, row * HOLE_PITCH_MM),
    }
}

/// The plate's outline (mm): three columns and two rows of square cells, one per hole.
fn plate_outline() -> Rect {
    Rect::centred(3.0 * HOLE_PITCH_MM, 2.0 * HOLE_PITCH_MM)
}

/// The fixture plate: a slab with a blind hole for every peg, each hole's rim chamfered.
pub fn fixture_plate() -> TriMesh {
    let mut s = Solid::new();
    s.cuboid(plate_outline(), 0.0, PLATE_BASE_MM);
    let z0 = PLATE_BASE_MM;
    let z1 = PLATE_BASE_MM + HOLE_DEPTH_MM;
    let zc = z1 - HOLE_CHAMFER_MM;
    for p in &PEGS {
        let (x, y) = p.hole_xy_mm;
        let h = HOLE_PITCH_MM / 2.0;
        let cell = Rect::new(x - h, x + h, y - h, y + h);
        let half = p.hole_size_mm() / 2.0;
        match p.shape {
            PegShape::Square => {
                let hole = Rect::new(x - half, x + half, y - half, y + half);
                s.ring(z0, zc, (cell, hole), (cell, hole));
                s.ring(zc, z1, (cell, hole), (cell, hole.grown(HOLE_CHAMFER_MM)));
            }
            PegShape::Round => {
                // Around the 48-gon whose flats touch the hole's circle: one hexahedron per side,
                // from the polygon out to the cell's square along the rays through its vertices.
                let outer = half / (std::f64::consts::PI / CIRCLE_SIDES as f64).cos();
                let hole = polygon(outer);
                let rim = polygon(outer + HOLE_CHAMFER_MM);
                let square = hole.map(|(px, py)| {
                    let scale = h / px.abs().max(py.abs());
                    (px * scale, py * scale)
                });
                let shift = |q: (f64, f64)| (q.0 + x, q.1 + y);
                for k in 0..CIRCLE_SIDES {
                    let n = (k + 1) % CIRCLE_SIDES;
                    let quad = |inner: &[(f64, f64); CIRCLE_SIDES]| {
                        [inner[k], square[k], square[n], inner[n]].map(shift)
                    };
                    s.hexahedron(at(quad(&hole), z0), at(quad(&hole), zc));
                    s.hexahedron(at(quad(&hole), zc), at(quad(&rim), z1));
                }
            }
        }
    }
    s.into_part_mesh()
}

/// The vertices of the regular [`CIRCLE_SIDES`]-gon of circumradius `r` about the origin,
/// counter-clockwise from +x.
fn polygon(r: f64) -> [(f64, f64); CIRCLE_SIDES] {
    std::array::from_fn(|k| {
        let a = std::f64::consts::TAU * k as f64 / CIRCLE_SIDES as f64;
        (r * a.cos(), r * a.sin())
    })
}

fn at(quad: [(f64, f64); 4], z: f64) -> [Point3<f64>; 4] {
    quad.map(|(x, y)| Point3::new(x, y, z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use perception::part::convex_pieces;

    #[test]
    fn the_pegs_and_plate_are_closed_with_the_volumes_of_their_shapes() {
        let plate = fixture_plate();
        plate.check_closed().unwrap();
        let mm3 = |m: &TriMesh| m.volume() * 1e9;
        let n = CIRCLE_SIDES as f64;
        let polygon_area = |r: f64| 0.5 * n * r * r * (std::f64::consts::TAU / n).sin();
        let mut holes = 0.0;
        for p in &PEGS {
            let m = p.mesh();
            m.check_closed().unwrap();
            let size = p.peg_size_mm();
            let area = match p.shape {
                PegShape::Square => size * size,
                PegShape::Round => polygon_area(size / 2.0),
            };
            assert!((mm3(&m) - area * PEG_LENGTH_MM).abs() < 1e-6, "{}", p.name);
            // One convex piece per peg: the fan merges back into the prism.
            assert_eq!(convex_pieces(&m).pieces.len(), 1, "{}", p.name);
            // Hole: straight wall below the chamfer, a frustum (area grows quadratically) in it.
            let hole = p.hole_size_mm();
            let chamfered = |grow: f64| match p.shape {
                PegShape::Square => (hole + 2.0 * grow).powi(2),
                PegShape::Round => {
                    let r = hole / 2.0 / (std::f64::consts::PI / n).cos() + grow;
                    polygon_area(r)
                }
            };
            let (a0, a1) = (chamfered(0.0), chamfered(HOLE_CHAMFER_MM));
            let frustum = HOLE_CHAMFER_MM / 3.0 * (a0 + a1 + (a0 * a1).sqrt());
            holes += a0 * (HOLE_DEPTH_MM - HOLE_CHAMFER_MM) + frustum;
        }
        let slab = 3.0 * HOLE_PITCH_MM * 2.0 * HOLE_PITCH_MM * (PLATE_BASE_MM + HOLE_DEPTH_MM);
        assert!(
            (mm3(&plate) - (slab - holes)).abs() < 1e-3,
            "{} vs {}",
            mm3(&plate),
            slab - holes
        );
    }

    #[test]
    fn a_seated_peg_stands_on_its_hole_floor_with_the_stated_clearance_all_round() {
        let plate = fixture_plate();
        let (lo, _) = plate.aabb();
        for p in &PEGS {
            let mesh = p.mesh().transformed(&p.seated());
            let (plo, phi) = mesh.aabb();
            let floor = lo.z + PLATE_BASE_MM * 1e-3;
            assert!((plo.z - floor).abs() < 1e-12, "{}", p.name);
            assert!((phi.z - plo.z - PEG_LENGTH_MM * 1e-3).abs() < 1e-12);
            // The nearest plate vertex at hole depth is half the clearance from the peg's
            // outline on every side (the hole's flats, or the square's walls).
            let (x, y) = p.hole_xy_mm;
            let centre = Point3::new(x * 1e-3, y * 1e-3, 0.0);
            let half_gap = p.clearance_mm() / 2.0 * 1e-3;
            let peg_r = p.peg_size_mm() / 2.0 * 1e-3;
            let wall = plate
                .vertices
                .iter()
                .filter(|v| (v.z - floor).abs() < 1e-9)
                .map(|v| {
                    let d = nalgebra::Vector2::new(v.x - centre.x, v.y - centre.y);
                    match p.shape {
                        PegShape::Square => d.x.abs().max(d.y.abs()),
                        PegShape::Round => d.norm(),
                    }
                })
                .fold(f64::INFINITY, f64::min);
            let expect = match p.shape {
                PegShape::Square => peg_r + half_gap,
                PegShape::Round => {
                    (peg_r + half_gap) / (std::f64::consts::PI / CIRCLE_SIDES as f64).cos()
                }
            };
            assert!(
                (wall - expect).abs() < 1e-12,
                "{}: {wall} vs {expect}",
                p.name
            );
        }
        assert!((PEGS[0].clearance_mm() - 0.076).abs() < 1e-12);
        assert!((PEGS[5].clearance_mm() - 0.093).abs() < 1e-12);
    }
}
