//! What a dataset run produces, with the seed's defaults.

use std::path::PathBuf;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use perception::camera::Camera;

use super::{DatasetError, Families, FamilyDraw, LookOptions};
use crate::render::RenderSettings;
use crate::scene::Randomisation;

/// Training or test split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Split {
    /// Training data.
    Train,
    /// Held-out test data.
    Test,
}

impl Split {
    /// Folder of the BOP scenes of this split.
    pub fn bop_dir(self) -> &'static str {
        match self {
            Split::Train => "train_pbr",
            Split::Test => "test",
        }
    }

    /// Folder name of the crops of this split.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
        }
    }

    /// A number mixed into the random streams.
    pub(crate) fn code(self) -> u64 {
        match self {
            Split::Train => 1,
            Split::Test => 2,
        }
    }
}

/// A dataset run.
#[derive(Debug, Clone)]
pub struct DatasetConfig {
    /// Output folder.
    pub out: PathBuf,
    /// Master seed: the same seed gives a bit-identical dataset.
    pub seed: u64,
    /// The full-resolution camera (crops are cut from it at full resolution).
    pub camera: Camera,
    /// Nominal camera pose over the board (randomised around it).
    pub nominal_table_T_camera: Isometry3<f64>,
    /// Keypoint training crops per part.
    pub crops_train: usize,
    /// Keypoint test crops per part.
    pub crops_test: usize,
    /// Overview images (all parts, BOP format) for training.
    pub overviews_train: usize,
    /// Overview images for testing.
    pub overviews_test: usize,
    /// Side of a keypoint crop, px.
    pub crop_size: u32,
    /// Crops rendered from one physics drop (with independent lights, camera and sensor).
    pub views_per_drop: usize,
    /// Share of the crop drops whose target is held lying in a stable pose drawn uniformly while
    /// its neighbours fall around it, instead of falling from a random orientation: rare poses
    /// (the top shell's −y, 0.6 % of its drops) then get images too. 0 shows every pose as often
    /// as the drops leave parts in it.
    pub posed_crop_share: f64,
    /// Downscaling of the overview images relative to the full camera.
    pub overview_scale: f64,
    /// Overview window (width, height) around the board, px at the reduced resolution.
    pub overview_size: (u32, u32),
    /// Copies of each part per overview scene, inclusive range.
    pub parts_per_class: (usize, usize),
    /// Feeder frames (crowded parts, full resolution, BOP `train_feeder/`) for training.
    pub feeder_train: usize,
    /// Feeder frames for testing (BOP `test_feeder/`).
    pub feeder_test: usize,
    /// Copies of each part per feeder frame, inclusive range.
    pub feeder_per_class: (usize, usize),
    /// Half-size of the square the feeder parts are dropped into, metres (small: they touch).
    pub feeder_drop_half: f64,
    /// Camera height above the table for the test feeder frames, metres (`None`: randomised
    /// like the training frames).
    pub feeder_camera_distance: Option<f64>,
    /// Randomisation ranges.
    pub randomisation: Randomisation,
    /// The opt-in look (room, area lights, backlit plate), drawn from a stream of its own;
    /// `None` (the default) renders as without it.
    pub look: Option<LookOptions>,
    /// The randomisation families that widen the ranges (lights, plating, plastic, textures,
    /// distractors, sensor), each opt-in and drawn from a stream of its own; all off by
    /// default (renders unchanged).
    pub families: Families,
    /// Render settings.
    pub render: RenderSettings,
    /// Millimetres per unit of the 16-bit depth PNGs.
    pub depth_scale: f64,
    /// Images per BOP scene folder.
    pub images_per_scene: usize,
    /// Show a progress bar.
    pub progress: bool,
}

impl DatasetConfig {
    /// The seed's sizes: 20 000 training and 2 000 test crops per part, plus overview images.
    pub fn new(out: PathBuf, seed: u64) -> Self {
        Self {
            out,
            seed,
            camera: Camera::basler_seed(),
            nominal_table_T_camera: Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 1.51),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
            ),
            crops_train: 20_000,
            crops_test: 2_000,
            overviews_train: 2_000,
            overviews_test: 200,
            crop_size: 128,
            views_per_drop: 4,
            posed_crop_share: 0.0,
            overview_scale: 0.4,
            overview_size: (1000, 700),
            parts_per_class: (1, 3),
            feeder_train: 0,
            feeder_test: 0,
            feeder_per_class: (3, 4),
            feeder_drop_half: 0.015,
            feeder_camera_distance: None,
            randomisation: Randomisation::default(),
            look: None,
            families: Families::default(),
            render: RenderSettings::default(),
            depth_scale: 0.1,
            images_per_scene: 1000,
            progress: true,
        }
    }

    /// Checks sizes and ranges.
    pub fn validate(&self) -> Result<(), DatasetError> {
        self.randomisation.validate()?;
        if let Some(look) = &self.look {
            look.validate()
                .map_err(|e| DatasetError::Config(format!("look: {e}")))?;
        }
        self.families
            .validate()
            .map_err(|e| DatasetError::Config(format!("randomisation families: {e}")))?;
        self.camera
            .validate()
            .map_err(|e| DatasetError::Config(e.to_string()))?;
        let (lo, hi) = self.parts_per_class;
        if lo > hi {
            return Err(DatasetError::Config(format!(
                "parts per class range is inverted: {lo} > {hi}"
            )));
        }
        if hi == 0 {
            return Err(DatasetError::Config(
                "parts per class range is empty: it allows no parts (0..=0)".into(),
            ));
        }
        let (flo, fhi) = self.feeder_per_class;
        if flo > fhi || fhi == 0 {
            return Err(DatasetError::Config(format!(
                "feeder parts per class range {flo}..={fhi} is inverted or empty"
            )));
        }
        if !(self.feeder_drop_half.is_finite() && self.feeder_drop_half > 0.0) {
            return Err(DatasetError::Config(format!(
                "feeder drop half-size {} m must be positive",
                self.feeder_drop_half
            )));
        }
        if !(0.0..=1.0).contains(&self.posed_crop_share) {
            return Err(DatasetError::Config(format!(
                "posed crop share {} must be between 0 and 1",
                self.posed_crop_share
            )));
        }
        if let Some(d) = self.feeder_camera_distance
            && !(d.is_finite() && d >= 0.1)
        {
            return Err(DatasetError::Config(format!(
                "feeder camera distance {d} m must be at least 0.1 m"
            )));
        }
        if self.crop_size == 0 || self.crop_size > self.camera.width.min(self.camera.height) {
            return Err(DatasetError::Config(format!(
                "crop size {} px must be between 1 and the image size",
                self.crop_size
            )));
        }
        if !(self.overview_scale.is_finite()
            && self.overview_scale > 0.0
            && self.overview_scale <= 1.0)
        {
            return Err(DatasetError::Config(format!(
                "overview scale {} must be in (0, 1]",
                self.overview_scale
            )));
        }
        if self.overview_size.0 == 0 || self.overview_size.1 == 0 {
            return Err(DatasetError::Config(
                "overview size must be positive".into(),
            ));
        }
        if self.views_per_drop == 0 || self.images_per_scene == 0 {
            return Err(DatasetError::Config(
                "views per drop and images per scene must be positive".into(),
            ));
        }
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(DatasetError::Config(format!(
                "depth scale {} mm must be positive",
                self.depth_scale
            )));
        }
        Ok(())
    }
}

/// Offset of a work item's look stream tag from its own tag: the look draws from a stream of
/// its own, so the item's other draws are those of a run without it.
pub(crate) const LOOK_TAG: u64 = 1 << 40;

/// Offset of a work item's family stream tags from its own tag (family k draws from the stream
/// of (tag + FAMILY_TAG, index) mixed with k): the item's other draws stay those of a run
/// without the families, and each family's those of a run without the others.
pub(crate) const FAMILY_TAG: u64 = 1 << 41;

/// Applies the configured randomisation families to `scene` from the family streams of item
/// (tag, index), about part `focus` if given; what the sensor must apply is returned (nothing
/// when every family is off).
pub(crate) fn apply_families(
    cfg: &DatasetConfig,
    scene: &mut crate::scene::SampledScene,
    models: &[crate::scene::PartModel],
    focus: Option<usize>,
    tag: u64,
    index: u64,
) -> FamilyDraw {
    let base = item_seed(cfg.seed, tag + FAMILY_TAG, index);
    cfg.families
        .apply(scene, models, focus, |k| item_seed(base, k, 0))
}

/// Dresses `scene` in the configured look, if any, from the look stream of item (tag, index),
/// with the run's shared rooms (baked on first use, once per seed and look), its room dimmed to
/// `key_sky` when the lights family drew its key regime ([`FamilyDraw::key_sky`]).
pub(crate) fn apply_look(
    cfg: &DatasetConfig,
    scene: &mut crate::scene::SampledScene,
    key_sky: Option<f64>,
    tag: u64,
    index: u64,
) {
    let Some(look) = &cfg.look else {
        return;
    };
    let pool = (look.room.pool > 0).then(|| shared_rooms(cfg, look));
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(item_seed(
        cfg.seed,
        tag + LOOK_TAG,
        index,
    ));
    look.apply(scene, pool.as_deref().map(Vec::as_slice), key_sky, &mut rng);
}

/// The shared rooms of a run's seed, look and randomisation, baked once.
fn shared_rooms(
    cfg: &DatasetConfig,
    look: &LookOptions,
) -> std::sync::Arc<Vec<std::sync::Arc<crate::render::Environment>>> {
    type Pool = std::sync::Arc<Vec<std::sync::Arc<crate::render::Environment>>>;
    static CACHE: std::sync::Mutex<Option<(String, Pool)>> = std::sync::Mutex::new(None);
    let key = format!(
        "{} {:?} {:?} {:?}",
        cfg.seed, look, cfg.randomisation, cfg.nominal_table_T_camera
    );
    let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((k, pool)) = cache.as_ref()
        && *k == key
    {
        return pool.clone();
    }
    let camera = nalgebra::Point3::from(cfg.nominal_table_T_camera.translation.vector);
    let pool: Pool = std::sync::Arc::new(look.bake_pool(
        item_seed(cfg.seed, LOOK_TAG, 0),
        &camera,
        &cfg.randomisation,
    ));
    *cache = Some((key, pool.clone()));
    pool
}

/// The random stream of one work item: (master seed, stream tag, index) mixed by splitmix64.
pub(crate) fn item_seed(seed: u64, tag: u64, index: u64) -> u64 {
    let mut z = seed;
    for v in [tag, index] {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15).wrapping_add(v);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
    }
    z
}
