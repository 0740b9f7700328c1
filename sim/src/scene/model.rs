//! A part ready for scenes: its mesh, BVH, convex hull for physics, keypoints and appearance.

use std::sync::Arc;

use nalgebra::Point3;
use perception::part::{Catalog, Material, PartError, PartSpec, TriMesh};

use crate::render::{Appearance, RenderMesh};

/// Why a part could not be prepared for rendering.
#[derive(Debug, thiserror::Error)]
pub enum PartModelError {
    /// The mesh could not be read.
    #[error(transparent)]
    Part(#[from] PartError),
    /// The mesh has no triangles or a parry BVH could not be built from it.
    #[error("part {0}: mesh has no usable triangles")]
    EmptyMesh(String),
}

/// A part with everything scenes, renders and labels need.
#[derive(Debug, Clone)]
pub struct PartModel {
    /// Part name, e.g. "main_shell".
    pub name: String,
    /// BOP object id (1-based, catalog order).
    pub obj_id: u32,
    /// The mesh in the part frame, metres.
    pub mesh: TriMesh,
    /// Its ray-casting BVH.
    pub render_mesh: Arc<RenderMesh>,
    /// The 9 keypoints (8 surface points + the bounding-box centre), part frame, metres.
    pub keypoints: Vec<Point3<f64>>,
    /// Surface class.
    pub material: Material,
    /// Density, kg/m³.
    pub density: f64,
    /// The catalog entry.
    pub spec: PartSpec,
}

impl PartModel {
    /// Builds a model from a mesh and a catalog entry; keypoints come from the catalog when it is
    /// prepared, otherwise they are computed as `cell parts prepare` does (FPS from the centre).
    pub fn new(spec: &PartSpec, mesh: TriMesh, obj_id: u32) -> Result<Self, PartModelError> {
        let render_mesh =
            RenderMesh::new(&mesh).ok_or_else(|| PartModelError::EmptyMesh(spec.name.clone()))?;
        let keypoints = if spec.keypoints.len() == 9 {
            spec.keypoint_points()
        } else {
            let (lo, hi) = mesh.aabb();
            let centre = nalgebra::center(&lo, &hi);
            let samples = perception::part::sample_surface(&mesh, 4000, 1);
            let mut k = perception::part::farthest_point_sample(&samples, 8, centre);
            k.push(centre);
            k
        };
        Ok(Self {
            name: spec.name.clone(),
            obj_id,
            render_mesh: Arc::new(render_mesh),
            keypoints,
            material: spec.material,
            density: spec.density(),
            spec: spec.clone(),
            mesh,
        })
    }

    /// The models of a catalog's parts with the given roles excluded (fixtures usually are).
    pub fn from_catalog(catalog: &Catalog, names: &[String]) -> Result<Vec<Self>, PartModelError> {
        let mut out = Vec::new();
        for (i, spec) in catalog.parts.iter().enumerate() {
            if !names.is_empty() && !names.contains(&spec.name) {
                continue;
            }
            let mesh = catalog.load_mesh(spec)?;
            out.push(Self::new(spec, mesh, i as u32 + 1)?);
        }
        Ok(out)
    }

    /// Nominal appearance of the material.
    pub fn appearance(&self) -> Appearance {
        Appearance::for_material(self.material)
    }

    /// Diameter (largest vertex-to-vertex distance), metres, as BOP defines it.
    pub fn diameter(&self) -> f64 {
        let v = &self.mesh.vertices;
        let mut best = 0.0f64;
        for (i, a) in v.iter().enumerate() {
            for b in &v[i + 1..] {
                best = best.max((a - b).norm_squared());
            }
        }
        best.sqrt()
    }
}
