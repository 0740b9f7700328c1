//! The cell's fixed geometry: part shapes from the catalog and where the table, fixture and
//! assembly targets are.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use parry3d_f64::shape::SharedShape;
use perception::part::{
    Catalog, ConvexPieces, Grasp, ROUND_WITHIN_M, StablePose, Symmetry, TriMesh, convex_pieces,
    round_axes,
};

use super::error::CellError;
use crate::config::{AssemblyStep, CellSpec, Destination};
use crate::convert::vec_from_point;

/// One catalog part's shapes, ready for grasping, collision and insertion.
#[derive(Clone)]
pub struct PartGeometry {
    /// Catalog name.
    pub name: String,
    /// Surface mesh (metres, part frame = bounding-box centre).
    pub mesh: TriMesh,
    /// Convex hull for finger and neighbour collision checks.
    pub hull: SharedShape,
    /// Exact convex pieces for the contact simulation.
    pub pieces: ConvexPieces,
    /// Bounding box corners in the part frame.
    pub aabb: (Point3<f64>, Point3<f64>),
    /// Mass in kg (catalog value, else from the mesh volume and density).
    pub mass: f64,
    /// Stable-pose table (may be empty for cell objects).
    pub stable_poses: Vec<StablePose>,
    /// Grasps per stable pose.
    pub grasps: Vec<Grasp>,
    /// Declared rotational symmetries (the catalog's; empty for a bare mesh): the exact ones make
    /// a turned part seat like the part itself.
    pub symmetries: Vec<Symmetry>,
    /// Axes of those symmetries about which the part is round
    /// ([`perception::part::round_axes`]): a turn about one is no pose error.
    pub round_axes: Vec<Unit<Vector3<f64>>>,
}

impl std::fmt::Debug for PartGeometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PartGeometry")
            .field("name", &self.name)
            .field("triangles", &self.mesh.triangles.len())
            .field("pieces", &self.pieces.pieces.len())
            .field("mass", &self.mass)
            .finish()
    }
}

impl PartGeometry {
    /// Builds the shapes of a catalog part.
    pub fn from_catalog(catalog: &Catalog, name: &str) -> Result<Self, CellError> {
        let spec = catalog
            .part(name)
            .ok_or_else(|| CellError::UnknownPart(name.to_string()))?;
        let mesh = catalog.load_mesh(spec).map_err(|source| CellError::Mesh {
            part: name.to_string(),
            source,
        })?;
        let mass = spec
            .mass
            .unwrap_or_else(|| mesh.volume().abs() * spec.density());
        let mut geometry = Self::from_mesh(
            name,
            mesh,
            mass,
            spec.stable_poses.clone(),
            spec.grasps.clone(),
        )?;
        geometry.round_axes = round_axes(&geometry.mesh, &spec.symmetries, ROUND_WITHIN_M);
        geometry.symmetries = spec.symmetries.clone();
        Ok(geometry)
    }

    /// Builds the shapes of a mesh (metres, part frame).
    pub fn from_mesh(
        name: &str,
        mesh: TriMesh,
        mass: f64,
        stable_poses: Vec<StablePose>,
        grasps: Vec<Grasp>,
    ) -> Result<Self, CellError> {
        let points: Vec<_> = mesh.vertices.iter().map(vec_from_point).collect();
        let hull = perception::part::convex_hull_shape(&points)
            .ok_or_else(|| CellError::DegenerateMesh(name.to_string()))?;
        let pieces = convex_pieces(&mesh);
        let aabb = mesh.aabb();
        Ok(Self {
            name: name.to_string(),
            mesh,
            hull,
            pieces,
            aabb,
            mass,
            stable_poses,
            grasps,
            symmetries: Vec::new(),
            round_axes: Vec::new(),
        })
    }

    /// Extent of the part along a unit direction given in the part frame: (min, max) of v·dir.
    pub fn extent_along(&self, dir: &Vector3<f64>) -> (f64, f64) {
        self.mesh
            .vertices
            .iter()
            .map(|p| p.coords.dot(dir))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
                (lo.min(d), hi.max(d))
            })
    }

    /// The stable-pose class a table pose belongs to: the class whose up direction, or a twin's
    /// under the part's exact symmetries, is nearest the table's up expressed in the part frame.
    #[allow(non_snake_case)]
    pub fn stable_pose_of(&self, table_T_part: &Isometry3<f64>) -> Option<&StablePose> {
        let group = perception::symmetry::symmetry_group(&self.symmetries);
        StablePose::nearest_up_to(&self.stable_poses, &table_T_part.rotation, &group)
            .filter(|(_, tilt)| tilt.cos() > 0.9)
            .map(|(s, _)| s)
    }
}

/// The fixed geometry of a cell: frames and every part's shapes.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
pub struct CellGeometry {
    /// Table frame (tag board plane, z up) in the base frame.
    pub base_T_table: Isometry3<f64>,
    /// Fixture nest frame in the base frame.
    pub base_T_fixture: Isometry3<f64>,
    /// Nominal camera pose in the base frame (what calibration says).
    pub base_T_camera_nominal: Isometry3<f64>,
    /// Shapes per part name (feeder parts and the fixture).
    pub parts: BTreeMap<String, PartGeometry>,
    /// Name of the fixture's part.
    pub fixture_part: String,
}

impl CellGeometry {
    /// Loads the shapes of the fixture, every feeder part and every assembled part.
    pub fn new(
        cell: &CellSpec,
        steps: &[AssemblyStep],
        catalog: &Catalog,
    ) -> Result<Self, CellError> {
        let mut names: Vec<String> = cell.feeder.parts.keys().cloned().collect();
        names.extend(steps.iter().map(|s| s.part.clone()));
        names.push(cell.fixture.part.clone());
        let mut parts = BTreeMap::new();
        for name in names {
            if let std::collections::btree_map::Entry::Vacant(slot) = parts.entry(name) {
                let g = PartGeometry::from_catalog(catalog, slot.key())?;
                slot.insert(g);
            }
        }
        let base_T_table = cell.base_T_table.isometry();
        Ok(Self {
            base_T_table,
            base_T_fixture: base_T_table * cell.fixture.table_T_fixture.isometry(),
            base_T_camera_nominal: cell.camera.base_T_camera.isometry(),
            parts,
            fixture_part: cell.fixture.part.clone(),
        })
    }

    /// The shapes of a part.
    pub fn part(&self, name: &str) -> Result<&PartGeometry, CellError> {
        self.parts
            .get(name)
            .ok_or_else(|| CellError::UnknownPart(name.to_string()))
    }
}

/// The insertion frame of a step: origin at the seated part origin, z against the insertion
/// axis (pointing out of the hole), expressed in the destination frame.
#[allow(non_snake_case)]
pub fn destination_T_insertion(step: &AssemblyStep) -> Isometry3<f64> {
    let target = step.target.isometry();
    let axis = Vector3::from(step.insertion_axis);
    let up = if axis.norm() > 0.0 {
        -axis.normalize()
    } else {
        Vector3::z()
    };
    let r = UnitQuaternion::rotation_between(&Vector3::z(), &up).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    });
    Isometry3::from_parts(Translation3::from(target.translation.vector), r)
}

/// Which placed part a step's destination is: `None` for the fixture.
pub fn destination_part(step: &AssemblyStep) -> Option<&str> {
    match &step.into {
        Destination::Fixture => None,
        Destination::Part(p) => Some(p.as_str()),
    }
}
