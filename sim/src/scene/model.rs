//! A part ready for scenes: its mesh, BVH, convex hull for physics, keypoints and appearance.

use std::sync::Arc;

use nalgebra::Point3;
use perception::part::{Catalog, Material, PartError, PartSpec, TriMesh};

use crate::render::{Appearance, RenderMesh};
use crate::stable_poses::DropBody;

/// Why a part could not be prepared for scenes (rendering and physics).
#[derive(Debug, thiserror::Error)]
pub enum PartModelError {
    /// The mesh could not be read.
    #[error(transparent)]
    Part(#[from] PartError),
    /// The mesh has no triangles or a parry BVH could not be built from it.
    #[error("part {0}: mesh has no usable triangles")]
    EmptyMesh(String),
    /// The mesh encloses no volume, so physics can neither shape nor weigh the part.
    #[error(
        "part {0}: its mesh encloses no volume, so it cannot be dropped in physics (flat or degenerate mesh)"
    )]
    NoVolume(String),
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
    /// Material of the mesh's accent triangles (the insert's gold pins), if it has any.
    pub accent: Option<Material>,
    /// Its physics body, the one stable-pose drops use: scene drops collide it by its convex
    /// hull and weigh it as the part itself (at the catalog's density), not as its filled hull.
    pub body: DropBody,
    /// The catalog entry.
    pub spec: PartSpec,
}

impl PartModel {
    /// Builds a model from a mesh and a catalog entry; keypoints come from the catalog when it is
    /// prepared, otherwise they are computed as `cell parts prepare` does (FPS from the centre).
    pub fn new(spec: &PartSpec, mesh: TriMesh, obj_id: u32) -> Result<Self, PartModelError> {
        let flags = if spec.material == Material::DarkPlastic {
            pin_triangles(&mesh)
        } else {
            Vec::new()
        };
        let accent = flags.iter().any(|f| *f).then_some(Material::Gold);
        let render_mesh = RenderMesh::new(&mesh)
            .ok_or_else(|| PartModelError::EmptyMesh(spec.name.clone()))?
            .with_accent(flags);
        // Weighed as its hull, the top shell rested in its 40° tilt in 2 % of the crop drops and
        // face up in 40 %, against the catalog's 8.7 % and 25 %; weighed as itself, in 6 % and 20 %.
        let body = DropBody::new(&mesh, spec.density());
        if !body.has_volume() {
            return Err(PartModelError::NoVolume(spec.name.clone()));
        }
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
            accent,
            body,
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

    /// Nominal appearance of the accent triangles, if any.
    pub fn accent_appearance(&self) -> Option<Appearance> {
        self.accent.map(Appearance::for_material)
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

/// The contact pins of a moulded part: triangles standing above its highest large upward face
/// (a face level holding at least a tenth of the footprint). The insert's pins rise 0.1–0.2 mm
/// above its tongue; a part without pins has none.
fn pin_triangles(mesh: &TriMesh) -> Vec<bool> {
    let (lo, hi) = mesh.aabb();
    let footprint = (hi.x - lo.x) * (hi.y - lo.y);
    let tri = |t: &[u32; 3]| t.map(|i| mesh.vertices[i as usize]);
    // Upward faces: summed area per height level (0.1 µm bins).
    let mut levels: Vec<(f64, f64)> = Vec::new();
    for t in &mesh.triangles {
        let [a, b, c] = tri(t);
        let n = (b - a).cross(&(c - a));
        let area = n.norm() / 2.0;
        if area <= 0.0 || n.z / (2.0 * area) < 0.99 {
            continue;
        }
        let z = (a.z + b.z + c.z) / 3.0;
        match levels.iter_mut().find(|(lz, _)| (lz - z).abs() < 1e-7) {
            Some(level) => level.1 += area,
            None => levels.push((z, area)),
        }
    }
    let Some(top) = levels
        .iter()
        .filter(|(_, area)| *area >= 0.1 * footprint)
        .map(|(z, _)| *z)
        .reduce(f64::max)
    else {
        return vec![false; mesh.triangles.len()];
    };
    mesh.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = tri(t);
            (a.z + b.z + c.z) / 3.0 > top + 1e-7
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn catalog() -> Catalog {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/parts/usbc.toml");
        Catalog::load(std::path::Path::new(path)).unwrap()
    }

    #[test]
    fn a_shell_weighs_as_itself_not_as_its_filled_hull() {
        let catalog = catalog();
        for model in PartModel::from_catalog(&catalog, &[]).unwrap() {
            let hull = model.body.hull().expect("a hull");
            let filled = hull.mass_properties(model.spec.density()).mass();
            let own = model.body.mass.mass();
            assert!(
                own > 0.0 && own <= filled * (1.0 + 1e-9),
                "{}: {own} kg against {filled} kg filled",
                model.name
            );
            // The shells are sheet metal around a cavity (the main shell weighs 19 % of its
            // filled hull); the insert mold is nearly solid (98 %).
            if model.name.ends_with("_shell") {
                assert!(
                    own < 0.5 * filled,
                    "{}: {own} kg against {filled} kg",
                    model.name
                );
            }
        }
    }

    #[test]
    fn a_flat_mesh_is_refused_for_physics_by_name() {
        let catalog = catalog();
        let spec = &catalog.parts[0];
        let p = |x: f64, y: f64| Point3::new(x, y, 0.0);
        let flat = TriMesh {
            vertices: vec![p(0.0, 0.0), p(0.01, 0.0), p(0.01, 0.01), p(0.0, 0.01)],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        match PartModel::new(spec, flat, 1) {
            Err(e @ PartModelError::NoVolume(_)) => assert!(e.to_string().contains(&spec.name)),
            other => panic!("expected NoVolume, got {:?}", other.map(|m| m.name)),
        }
    }
}
