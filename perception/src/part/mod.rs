//! Part models: meshes, mass properties, keypoints, symmetries, grasps and stable poses, and the
//! catalog file that holds them for one part set.

mod alike;
mod catalog;
mod error;
mod hull;
mod keypoints;
mod mass;
mod mesh;
mod mesh_bodies;
mod mesh_io;
mod mesh_repair;
mod mesh_topology;
mod pieces;
mod round;
mod stable_pose;
mod step_io;
mod step_kernel;
mod turned_surface;

pub use alike::{ALIKE_WITHIN_REL, AlikePoses, alike_stable_poses};
pub use catalog::{
    Catalog, Grasp, HoleWeight, MAX_CHORDAL_TOLERANCE_M, MIN_CHORDAL_TOLERANCE_M, Material,
    PartRole, PartSpec, Symmetry, ViewSymmetry, checked_drop_height, line_column,
};
pub use error::{MeshAt, PartError};
pub use hull::{EXACT_HULL_MAX_POINTS, HULL_JITTER_REL, convex_hull, convex_hull_shape};
pub use keypoints::{farthest_point_sample, sample_surface};
pub use mass::{UNION_NOISE_REL, UNION_RAYS, UnionMoments, VolumeMoments};
pub use mesh::{MeshDefect, OpenRegion, TriMesh};
pub use mesh_bodies::{FilledHoles, HOLE_PLANARITY_REL, MAX_FILLED_HOLE_M};
pub use mesh_io::{LengthUnit, load_mesh, load_mesh_repaired, write_obj};
pub use mesh_repair::{MeshRepairs, WELD_TOLERANCE_REL};
pub use pieces::{ConvexPieces, convex_pieces};
pub use round::{ROUND_WITHIN_M, round_axes};
pub use stable_pose::{StablePose, footprints_mm2};
pub use step_io::{ANGULAR_TOLERANCE_RAD, CHORDAL_TOLERANCE_MM, tessellate_step};
pub use step_kernel::{OCP_VERSION, StepKernel};
