//! Part models: meshes, mass properties, keypoints, symmetries, grasps and stable poses, and the
//! catalog file that holds them for one part set.

mod catalog;
mod error;
mod keypoints;
mod mesh;
mod mesh_io;
mod stable_pose;

pub use catalog::{Catalog, Grasp, Material, PartRole, PartSpec, Symmetry, line_column};
pub use error::{MeshAt, PartError};
pub use keypoints::{farthest_point_sample, sample_surface};
pub use mesh::{MeshDefect, TriMesh};
pub use mesh_io::{LengthUnit, load_mesh, write_obj};
pub use stable_pose::StablePose;
