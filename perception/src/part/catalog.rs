//! The part catalog: one TOML file per part set, with each part's mesh, material, symmetries,
//! grasps, and the keypoints, mass properties and stable poses that `cell parts prepare` computes.

use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::mesh_io::load_part_mesh;
use super::{LengthUnit, MeshAt, MeshRepairs, PartError, StablePose, TriMesh};

/// A part set: the parts of one product, read from a catalog file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Catalog {
    /// Name of the part set, e.g. "usbc".
    pub name: String,
    /// One line for people.
    #[serde(default)]
    pub description: String,
    /// Height of each part's lowest point above the table when the stable-pose drops released
    /// it, metres: how the parts arrive on the feeder, which the table's shares depend on.
    /// Written by `cell parts prepare`; absent in a catalog never prepared.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "drop_height"
    )]
    pub drop_height: Option<f64>,
    /// The parts.
    #[serde(rename = "part")]
    pub parts: Vec<PartSpec>,
    /// Folder the catalog was read from; mesh paths are relative to it.
    #[serde(skip)]
    pub dir: PathBuf,
    /// The catalog file, for error messages.
    #[serde(skip)]
    pub file: PathBuf,
    /// (line, column) of each part's `mesh` value in the file, by part index.
    #[serde(skip)]
    pub mesh_locations: Vec<(usize, usize)>,
}

/// The drop heights a catalog or `cell parts prepare --drop-height` may give, metres.
const DROP_HEIGHT_RANGE: std::ops::RangeInclusive<f64> = 0.0..=1.0;

/// `height` if it is a drop height a catalog may record (0–1 m), else what is wrong with it.
pub fn checked_drop_height(height: f64) -> Result<f64, String> {
    if DROP_HEIGHT_RANGE.contains(&height) {
        Ok(height)
    } else {
        Err(format!(
            "must be between {} and {} m, got {height}",
            DROP_HEIGHT_RANGE.start(),
            DROP_HEIGHT_RANGE.end()
        ))
    }
}

/// A catalog's `drop_height`, refused unless [`checked_drop_height`] accepts it.
fn drop_height<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    checked_drop_height(f64::deserialize(d)?)
        .map(Some)
        .map_err(|why| serde::de::Error::custom(format!("drop_height {why}")))
}

/// Where each `[[part]]`'s located keys (`mesh`, `view_symmetries`) are written, read with spans.
#[derive(Deserialize)]
struct PartKeySpans {
    #[serde(default)]
    part: Vec<PartKeys>,
}

#[derive(Deserialize)]
struct PartKeys {
    mesh: Option<toml::Spanned<toml::Value>>,
    view_symmetries: Option<toml::Spanned<toml::Value>>,
    chordal_tolerance: Option<toml::Spanned<toml::Value>>,
}

/// Finest chordal tolerance a catalog may ask of a STEP tessellation, metres (0.1 µm): finer
/// gives millions of triangles on a centimetre part.
pub const MIN_CHORDAL_TOLERANCE_M: f64 = 1e-7;
/// Coarsest chordal tolerance a catalog may ask, metres (0.5 mm): coarser turns a small hole or
/// fillet into a different shape, and a value above it is most likely millimetres typed as
/// metres.
pub const MAX_CHORDAL_TOLERANCE_M: f64 = 0.5e-3;

/// Whether a catalog entry is assembled or is part of the cell. What each part does in the
/// product (its order, target and insertion direction) is the scenario's `[[assembly]]` sequence,
/// never its role.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PartRole {
    /// A part that lies in the feeder and is picked and assembled (the default). The names
    /// `main`, `inserted` and `top` of older catalogs are read as this.
    #[default]
    #[serde(alias = "main", alias = "inserted", alias = "top")]
    Part,
    /// Not assembled: a fixture, board or other cell object.
    Fixture,
}

impl PartRole {
    /// True for an assembled part (serde's test for leaving the default out of a file).
    pub fn is_part(&self) -> bool {
        *self == PartRole::Part
    }
}

/// Surface class, which decides how the part looks to the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Material {
    /// Reflective sheet metal (shells).
    Metal,
    /// Dark moulded plastic (insert bodies).
    DarkPlastic,
    /// Gold-plated contacts.
    Gold,
    /// Anodised aluminium board printed with black and white tags.
    TagBoard,
    /// Machined aluminium (fixtures).
    Aluminium,
}

impl Material {
    /// Default density in kg/m³ for mass properties when the catalog gives none.
    pub fn density(self) -> f64 {
        match self {
            Material::Metal => 8_500.0,
            Material::DarkPlastic => 1_400.0,
            Material::Gold => 19_300.0,
            Material::TagBoard | Material::Aluminium => 2_700.0,
        }
    }
}

/// A rotational symmetry of the part about an axis through its origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Symmetry {
    /// Axis in the part frame (need not be unit length).
    pub axis: [f64; 3],
    /// Order n: the part maps onto itself after turning 360°/n.
    pub order: u32,
    /// False for a near-symmetry (features break it only slightly): a pose ambiguity for vision,
    /// but not an equivalence for assembly.
    #[serde(default = "yes")]
    pub exact: bool,
}

fn yes() -> bool {
    true
}

/// A stable pose whose view from above repeats on a turn about the vertical (a featureless face
/// up, a square outline): vision finds the part's place and its yaw only up to that turn.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewSymmetry {
    /// Name of the stable pose (e.g. "-z").
    pub stable_pose: String,
    /// Order n ≥ 2: the view repeats after a turn of 360°/n about the vertical through the part
    /// origin.
    pub order: u32,
}

/// A [`PartSpec::hole_weight`]: a finite number, at least 1 (1, the default, weighs holes'
/// edges like any other sample).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(transparent)]
pub struct HoleWeight(f64);

impl HoleWeight {
    /// The weight.
    pub fn get(self) -> f64 {
        self.0
    }

    fn is_one(&self) -> bool {
        self.0 == 1.0
    }
}

impl Default for HoleWeight {
    fn default() -> Self {
        Self(1.0)
    }
}

impl<'de> Deserialize<'de> for HoleWeight {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let w = f64::deserialize(d)?;
        if w.is_finite() && w >= 1.0 {
            Ok(Self(w))
        } else {
            Err(serde::de::Error::custom(format!(
                "hole_weight must be a finite number of at least 1, got {w}"
            )))
        }
    }
}

/// A top-down grasp of a part resting in one stable pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grasp {
    /// Name of the stable pose (e.g. "+z") this grasp applies to.
    pub stable_pose: String,
    /// Finger closing direction in the part frame; must be horizontal in that stable pose.
    pub closing_axis: [f64; 3],
    /// Height of the fingertip centre above the table, metres.
    pub grip_height: f64,
}

/// One part of a catalog.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartSpec {
    /// Unique name, e.g. "main_shell".
    pub name: String,
    /// `fixture` for cell objects (nests, boards); absent or `part` for what is assembled.
    #[serde(default, skip_serializing_if = "PartRole::is_part")]
    pub role: PartRole,
    /// Mesh file, relative to the catalog file.
    pub mesh: PathBuf,
    /// Unit of the mesh file's numbers; required except for a STEP file, which declares its
    /// own (and whose own is used whatever this says).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<LengthUnit>,
    /// Largest distance, in metres like the catalog's other lengths, between a STEP file's
    /// tessellation and its exact surfaces; absent:
    /// [`CHORDAL_TOLERANCE_MM`](super::CHORDAL_TOLERANCE_MM). STEP meshes only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chordal_tolerance: Option<f64>,
    /// Surface class.
    pub material: Material,
    /// Density in kg/m³; the material's default when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density: Option<f64>,
    /// Declared rotational symmetries (exact and near).
    #[serde(default)]
    pub symmetries: Vec<Symmetry>,
    /// How many times the other outline samples the edges of holes through the part (cut-outs
    /// in a flat face) weigh in the contour fit's last round: a cut-out's edge is one clean step
    /// at the face, where a thin-walled shell's outer outline is a wall whose rim, outer face and
    /// shadow blur it by a pixel or two. Absent: 1, like any other sample.
    #[serde(default, skip_serializing_if = "HoleWeight::is_one")]
    pub hole_weight: HoleWeight,
    /// Stable poses whose view from above repeats on a turn: the learned pipeline poses a part
    /// resting in one by its outline when its keypoints fail, and evaluation scores its yaw up to
    /// the turn.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub view_symmetries: Vec<ViewSymmetry>,
    /// Top-down grasps, each for one stable pose; poses without one are not pickable.
    #[serde(default, rename = "grasp")]
    pub grasps: Vec<Grasp>,
    /// Mass in kg (computed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass: Option<f64>,
    /// Centre of mass in the part frame, metres (computed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center_of_mass: Option<[f64; 3]>,
    /// 8 farthest-point-sampled surface keypoints then the bounding-box centre, metres (computed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keypoints: Vec<[f64; 3]>,
    /// Resting classes on a flat table, most probable first (computed).
    #[serde(default, rename = "stable_pose", skip_serializing_if = "Vec::is_empty")]
    pub stable_poses: Vec<StablePose>,
}

impl PartSpec {
    /// Density used for mass properties.
    pub fn density(&self) -> f64 {
        self.density.unwrap_or_else(|| self.material.density())
    }

    /// The keypoints as points.
    pub fn keypoint_points(&self) -> Vec<Point3<f64>> {
        self.keypoints.iter().map(|k| Point3::from(*k)).collect()
    }

    /// The stable pose with this name.
    pub fn stable_pose(&self, name: &str) -> Option<&StablePose> {
        self.stable_poses.iter().find(|s| s.name == name)
    }

    /// The order of the view symmetry of a stable pose (1 when its view does not repeat).
    pub fn view_order(&self, stable_pose: &str) -> u32 {
        self.view_symmetries
            .iter()
            .find(|v| v.stable_pose == stable_pose)
            .map_or(1, |v| v.order)
    }

    /// The grasp for a stable pose, if the part is pickable in it.
    pub fn grasp_for(&self, stable_pose: &str) -> Option<&Grasp> {
        self.grasps.iter().find(|g| g.stable_pose == stable_pose)
    }

    /// Whether the mesh is a STEP file (`.step` or `.stp`).
    pub fn is_step(&self) -> bool {
        self.mesh
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("step") || e.eq_ignore_ascii_case("stp"))
    }

    /// What is wrong with the mesh's unit or chordal tolerance, if anything, and whether it is
    /// the tolerance (else the unit, at the mesh key).
    fn mesh_key_problem(&self) -> Option<(bool, String)> {
        let name = &self.name;
        if !self.is_step() && self.unit.is_none() {
            return Some((
                false,
                format!(
                    "part \"{name}\": unit = \"mm\" or \"m\" is required for mesh {}; only a STEP \
                     file declares its own unit",
                    self.mesh.display()
                ),
            ));
        }
        let t = self.chordal_tolerance?;
        let problem = if !self.is_step() {
            format!(
                "chordal_tolerance applies to STEP meshes only; {} is given as triangles",
                self.mesh.display()
            )
        } else if !(t.is_finite() && t > 0.0) {
            format!("chordal_tolerance {t}: expected a positive length in metres")
        } else if t > MAX_CHORDAL_TOLERANCE_M {
            format!(
                "chordal_tolerance {t} m is {} mm, coarser than the {} mm allowed: lengths in the \
                 catalog are in metres ({t} mm would be {:e})",
                t * 1e3,
                MAX_CHORDAL_TOLERANCE_M * 1e3,
                t * 1e-3
            )
        } else if t < MIN_CHORDAL_TOLERANCE_M {
            format!(
                "chordal_tolerance {t:e} m is finer than the {:.1} µm allowed",
                MIN_CHORDAL_TOLERANCE_M * 1e6
            )
        } else {
            return None;
        };
        Some((true, format!("part \"{name}\": {problem}")))
    }

    /// Chordal tolerance of the mesh's STEP tessellation, millimetres.
    pub fn chordal_tolerance_mm(&self) -> f64 {
        self.chordal_tolerance
            .map_or(super::CHORDAL_TOLERANCE_MM, |t| t * 1e3)
    }

    /// What is wrong with the view symmetries, if anything: an order below 2, or (once prepared)
    /// a stable pose the part does not have.
    fn view_symmetry_problem(&self) -> Option<String> {
        for v in &self.view_symmetries {
            if v.order < 2 {
                return Some(format!(
                    "view symmetry of \"{}\" has order {}; it must be at least 2",
                    v.stable_pose, v.order
                ));
            }
            if !self.stable_poses.is_empty() && self.stable_pose(&v.stable_pose).is_none() {
                let names: Vec<&str> = self.stable_poses.iter().map(|s| s.name.as_str()).collect();
                return Some(format!(
                    "view symmetry names stable pose \"{}\", which the part does not have (it has {})",
                    v.stable_pose,
                    names.join(", ")
                ));
            }
        }
        None
    }

    /// Whether `prepare` has filled in keypoints, mass and stable poses.
    pub fn is_prepared(&self) -> bool {
        self.mass.is_some() && self.keypoints.len() == 9 && !self.stable_poses.is_empty()
    }

    /// Centre of mass as a point (the origin when not computed yet).
    pub fn center_of_mass_point(&self) -> Point3<f64> {
        self.center_of_mass
            .map(Point3::from)
            .unwrap_or_else(Point3::origin)
    }

    /// The symmetry axes that are exact, as unit vectors with their orders.
    pub fn exact_symmetries(&self) -> Vec<(Vector3<f64>, u32)> {
        self.symmetries
            .iter()
            .filter(|s| s.exact && s.order > 1)
            .filter_map(|s| {
                Vector3::from(s.axis)
                    .try_normalize(1e-12)
                    .map(|a| (a, s.order))
            })
            .collect()
    }
}

impl Catalog {
    /// Reads and validates a catalog file; errors name the file, line and column.
    pub fn load(path: &Path) -> Result<Self, PartError> {
        let text = std::fs::read_to_string(path).map_err(|source| PartError::Io {
            path: path.into(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses catalog text read from `path` (used for error locations and relative mesh paths).
    pub fn parse(text: &str, path: &Path) -> Result<Self, PartError> {
        let mut catalog: Catalog = toml::from_str(text).map_err(|e| {
            let (line, column) = e
                .span()
                .map(|s| line_column(text, s.start))
                .unwrap_or((1, 1));
            PartError::Catalog {
                path: path.into(),
                line,
                column,
                message: e.message().trim().to_string(),
            }
        })?;
        catalog.dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        catalog.file = path.into();
        let spans = toml::from_str::<PartKeySpans>(text).ok();
        let at = |part: usize, key: fn(&PartKeys) -> Option<&toml::Spanned<toml::Value>>| {
            spans
                .as_ref()
                .and_then(|m| key(m.part.get(part)?))
                .map_or((1, 1), |s| line_column(text, s.span().start))
        };
        catalog.mesh_locations = (0..catalog.parts.len())
            .map(|i| at(i, |p| p.mesh.as_ref()))
            .collect();
        for (i, part) in catalog.parts.iter().enumerate() {
            if let Some((tolerance, message)) = part.mesh_key_problem() {
                let (line, column) = if tolerance {
                    at(i, |p| p.chordal_tolerance.as_ref())
                } else {
                    at(i, |p| p.mesh.as_ref())
                };
                return Err(PartError::Catalog {
                    path: path.into(),
                    line,
                    column,
                    message,
                });
            }
            if let Some(message) = part.view_symmetry_problem() {
                let (line, column) = at(i, |p| p.view_symmetries.as_ref());
                return Err(PartError::Catalog {
                    path: path.into(),
                    line,
                    column,
                    message: format!("part \"{}\": {message}", part.name),
                });
            }
        }
        Ok(catalog)
    }

    /// The part with this name.
    pub fn part(&self, name: &str) -> Option<&PartSpec> {
        self.parts.iter().find(|p| p.name == name)
    }

    /// Absolute path of a part's mesh file.
    pub fn mesh_path(&self, part: &PartSpec) -> PathBuf {
        self.dir.join(&part.mesh)
    }

    /// Loads a part's mesh in metres, in the part frame; an error names the catalog file and
    /// the line of the part's `mesh` key, the mesh file and why it failed.
    pub fn load_mesh(&self, part: &PartSpec) -> Result<TriMesh, PartError> {
        self.load_mesh_repaired(part).map(|(mesh, _)| mesh)
    }

    /// As [`Catalog::load_mesh`], and says what loading repaired (see [`load_mesh_repaired`]).
    pub fn load_mesh_repaired(&self, part: &PartSpec) -> Result<(TriMesh, MeshRepairs), PartError> {
        load_part_mesh(
            &self.mesh_path(part),
            part.unit,
            part.chordal_tolerance_mm(),
        )
        .map_err(|error| {
            let index = self.parts.iter().position(|p| p.name == part.name);
            let (line, column) = index
                .and_then(|i| self.mesh_locations.get(i).copied())
                .unwrap_or((1, 1));
            PartError::Mesh(Box::new(MeshAt {
                catalog: self.file.clone(),
                line,
                column,
                part: part.name.clone(),
                mesh: part.mesh.clone(),
                error,
            }))
        })
    }
}

/// 1-based line and column of a byte offset in `text` (columns count characters).
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The line, column and message of the error that a one-part catalog, whose last line is
    /// `last`, is refused with.
    fn refusal_of_part_line(last: &str) -> (usize, usize, String) {
        let text = format!(
            "name = \"x\"\n[[part]]\nname = \"a\"\nrole = \"main\"\nmesh = \"a.obj\"\nunit = \"mm\"\nmaterial = \"metal\"\n{last}\n"
        );
        match Catalog::parse(&text, Path::new("c.toml")) {
            Err(PartError::Catalog {
                line,
                column,
                message,
                ..
            }) => (line, column, message),
            other => panic!("expected a located error, got {other:?}"),
        }
    }

    #[test]
    fn a_part_without_a_role_is_assembled_and_older_role_names_read_as_one() {
        let part = |role: &str| {
            let text = format!(
                "name = \"x\"\n[[part]]\nname = \"a\"\n{role}mesh = \"a.obj\"\nunit = \"mm\"\nmaterial = \"metal\"\n"
            );
            Catalog::parse(&text, Path::new("c.toml")).map(|c| c.parts[0].role)
        };
        assert_eq!(part("").unwrap(), PartRole::Part);
        for old in ["main", "inserted", "top", "part"] {
            assert_eq!(
                part(&format!("role = \"{old}\"\n")).unwrap(),
                PartRole::Part,
                "{old}"
            );
        }
        assert_eq!(part("role = \"fixture\"\n").unwrap(), PartRole::Fixture);
        assert!(part("role = \"lid\"\n").is_err());
    }

    #[test]
    fn unknown_key_is_located() {
        let (line, column, message) = refusal_of_part_line("colour = 3");
        assert_eq!((line, column), (8, 1), "{message}");
        assert!(message.contains("colour"), "{message}");
    }

    #[test]
    fn a_hole_weight_below_one_is_located() {
        let (line, column, message) = refusal_of_part_line("hole_weight = 0.5");
        assert_eq!((line, column), (8, 15), "{message}");
        assert!(message.contains("hole_weight must be"), "{message}");
        assert!(message.contains("0.5"), "{message}");
    }

    #[test]
    fn a_drop_height_is_read_and_one_out_of_range_is_located() {
        let parse = |line: &str| {
            let text = format!(
                "name = \"x\"\n{line}\n[[part]]\nname = \"a\"\nmesh = \"a.obj\"\nunit = \"mm\"\nmaterial = \"metal\"\n"
            );
            Catalog::parse(&text, Path::new("c.toml"))
        };
        assert_eq!(parse("").unwrap().drop_height, None);
        assert_eq!(parse("drop_height = 0.03").unwrap().drop_height, Some(0.03));
        match parse("drop_height = -0.01") {
            Err(PartError::Catalog {
                line,
                column,
                message,
                ..
            }) => {
                assert_eq!((line, column), (2, 15), "{message}");
                assert!(message.contains("drop_height must be"), "{message}");
                assert!(message.contains("-0.01"), "{message}");
            }
            other => panic!("expected a located error, got {other:?}"),
        }
    }

    #[test]
    fn a_view_symmetry_of_order_one_is_located() {
        let (line, column, message) =
            refusal_of_part_line("view_symmetries = [{ stable_pose = \"-z\", order = 1 }]");
        assert_eq!((line, column), (8, 19), "{message}");
        assert!(
            message.contains("order 1") && message.contains("\"a\""),
            "{message}"
        );
    }

    #[test]
    fn the_upside_down_insert_mold_repeats_every_quarter_turn_and_a_misnamed_pose_is_refused() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let catalog = Catalog::parse(&text, &path).unwrap();
        let mold = catalog.part("insert_mold").unwrap();
        assert_eq!((mold.view_order("-z"), mold.view_order("+z")), (4, 1));
        let key = "view_symmetries = [{ stable_pose = \"-z\"";
        let line = text[..text.find(key).unwrap()].matches('\n').count() + 1;
        let bad = text.replacen(key, "view_symmetries = [{ stable_pose = \"-q\"", 1);
        match Catalog::parse(&bad, &path) {
            Err(PartError::Catalog {
                line: l, message, ..
            }) => {
                assert_eq!(l, line, "{message}");
                assert!(
                    message.contains("\"-q\"") && message.contains("+z, -z"),
                    "{message}"
                );
            }
            other => panic!("expected a located error, got {other:?}"),
        }
    }

    #[test]
    fn line_column_counts_from_one() {
        assert_eq!(line_column("ab\ncd", 0), (1, 1));
        assert_eq!(line_column("ab\ncd", 4), (2, 2));
        assert_eq!(line_column("ab", 99), (1, 3));
    }
}
