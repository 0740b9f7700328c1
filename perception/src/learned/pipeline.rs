//! The learned pipeline for one frame: preprocess → segment → instances → crops → keypoint net →
//! voting → pose, timing every stage. Image pixels in the results are full-sensor pixels (the
//! frame image's origin added).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use nalgebra::{Isometry3, Point2};

use super::LearnedError;
use super::contour_stage::ContourStage;
use super::crops::{CropBatch, crop_origin};
use super::detection::{LearnedDetection, LearnedDetections, StageTimes};
use super::image::Preprocessor;
use super::instances::{Instance, InstanceConfig, InstanceGrouper, join_split};
use super::keypoint_net::KeypointNet;
use super::models::{CROP_SIZE, LearnedModels, SEGMENTER_MULTIPLE, SEGMENTER_STRIDE};
use super::net_view::{InputScale, NetView};
use super::owners::CellOwners;
use super::segmenter::{SegmentMap, Segmenter};
use crate::Camera;
use crate::contour::{ContourConfig, Owner};
use crate::estimate::{EstimateError, EstimatorConfig, Observation, PoseEstimate, PoseEstimator};
use crate::frame::FrameImage;
use crate::onnx::{BatchSession, Runtime};
use crate::part::{Catalog, footprints_mm2};
use crate::planar::ClassSet;
use crate::stacking::StackingCheck;
use crate::voting::{KeypointVote, VoteError, VotingConfig};

/// Settings of the learned pipeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipelineConfig {
    /// Grouping of segmenter cells into instances.
    pub instances: InstanceConfig,
    /// Keypoint voting (PVNet RANSAC with covariances).
    pub voting: VotingConfig,
    /// Pose estimation (reprojection gate, planar refinement).
    pub estimator: EstimatorConfig,
    /// Instances scoring below this are not reported.
    pub min_score: f64,
    /// Threads for ONNX Runtime (intra-op) and for voting.
    pub threads: usize,
    /// Contour alignment of the keypoint poses on the frame's edges (`None`: keypoints only).
    pub contour: Option<ContourConfig>,
    /// Two estimates whose parts (their convex pieces) interpenetrate deeper than this, metres,
    /// are both withdrawn: one part lies on the other, which no stable pose describes (`None`:
    /// no check).
    pub stacking_tolerance: Option<f64>,
    /// A keypoint pose that leans further than this from its stable pose, radians, is kept but
    /// gets no confidence, so the cell does not pick it: no stable pose describes it, and on the
    /// eval sets such estimates were mostly of parts lying on another part.
    pub max_lean: f64,
    /// A detection whose mask covers more of the table than this multiple of a stable pose's
    /// footprint is not posed in that stable pose: lying so, the part could not cover it.
    pub max_overfill: f64,
    /// Two instances of one part that share a border are joined when together they cover no
    /// more of the table than this multiple of the part's largest stable-pose footprint
    /// ([`join_split`]); 0 joins none.
    pub max_joined_fill: f64,
    /// The table scale both nets see a frame at ([`NetView`]); poses, masks and keypoints are
    /// still reported in sensor pixels, and contour alignment reads the frame as captured.
    pub input_scale: InputScale,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            instances: InstanceConfig::default(),
            voting: VotingConfig::default(),
            estimator: EstimatorConfig::with_gate(4.0),
            min_score: 0.3,
            threads: 2,
            contour: Some(ContourConfig::default()),
            stacking_tolerance: Some(STACKING_TOLERANCE),
            max_lean: MAX_LEAN,
            max_overfill: MAX_OVERFILL,
            max_joined_fill: MAX_JOINED_FILL,
            input_scale: InputScale::Trained,
        }
    }
}

/// Default lean of a pickable keypoint pose from its stable pose, radians: 30°, five times the
/// planar refiner's tilt deviation. On the four eval sets and seed 3, it kept 7 parts lying on
/// another part and 1 in another stable pose from being picked, at the cost of 2 assembly-grade
/// picks; 25° and 20° also took 4 and 9 assembly-grade picks away (docs/perception.md).
pub const MAX_LEAN: f64 = std::f64::consts::PI / 6.0;

/// Default largest mask for a stable pose, as a multiple of its footprint: masks of parts posed
/// in the right stable pose covered at most 1.27 times its footprint on the four eval sets and
/// seed 3 (a narrow side-lying insert mold, its mask a cell wider all round), while 11 main
/// shells and insert molds taken for a side pose showed 1.5–2.5 times that pose's footprint.
pub const MAX_OVERFILL: f64 = 1.4;

/// Default largest share of a part's largest footprint that two bordering instances of it may
/// cover and still be joined as one part split in two. On the four eval sets and seed 3 it took
/// 0–6 false positives per set away (pieces of side-lying insert molds and top shells) and
/// missed nothing more; at 1.0 it also joined real neighbours, finding 6 parts fewer on the test set.
pub const MAX_JOINED_FILL: f64 = 0.8;

/// Default deepest overlap of two estimates put down to estimation error, metres: several times
/// the contour-aligned lateral error (≈ 0.05 mm median, 0.2 mm at the 90th percentile).
pub const STACKING_TOLERANCE: f64 = 0.0005;

/// The learned perception pipeline: both networks' sessions and every buffer, reused per frame.
pub struct LearnedPipeline {
    parts: Vec<String>,
    catalog: Catalog,
    config: PipelineConfig,
    segmenter: Segmenter,
    keypoint_net: KeypointNet,
    preprocessor: Preprocessor,
    map: SegmentMap,
    grouper: InstanceGrouper,
    owners: CellOwners,
    batch: CropBatch,
    estimator: Option<(Isometry3<f64>, PoseEstimator)>,
    contour: Option<ContourStage>,
    stacking: Option<StackingCheck>,
    /// Each part's footprint in each of its stable poses, mm² (part, then class).
    footprints: Vec<Vec<f64>>,
    /// Each part's largest extent (its mesh's bounding box), metres.
    extents: Vec<f64>,
    /// The table scale the nets see frames at, pixels per mm (`None`: as captured).
    input_px_per_mm: Option<f64>,
}

impl LearnedPipeline {
    /// Loads both models (checksums, signatures, contract, parts against `catalog`) with the
    /// default settings.
    pub fn load(
        models: &LearnedModels,
        catalog: &Catalog,
        runtime: &Runtime,
    ) -> Result<Self, LearnedError> {
        Self::with_config(models, catalog, runtime, PipelineConfig::default())
    }

    /// Loads both models with these settings.
    pub fn with_config(
        models: &LearnedModels,
        catalog: &Catalog,
        runtime: &Runtime,
        config: PipelineConfig,
    ) -> Result<Self, LearnedError> {
        if config.threads == 0 {
            return Err(LearnedError::Settings("threads must be ≥ 1".into()));
        }
        if !(0.0..=1.0).contains(&config.min_score) {
            return Err(LearnedError::Settings(format!(
                "min_score must lie in [0, 1], got {}",
                config.min_score
            )));
        }
        if config
            .stacking_tolerance
            .is_some_and(|t| !(t.is_finite() && t >= 0.0))
        {
            return Err(LearnedError::Settings(format!(
                "stacking_tolerance must be ≥ 0 m, got {:?}",
                config.stacking_tolerance
            )));
        }
        if !(config.max_lean > 0.0 && config.max_lean <= std::f64::consts::PI) {
            return Err(LearnedError::Settings(format!(
                "max_lean must lie in (0, π] rad, got {}",
                config.max_lean
            )));
        }
        if !(config.max_overfill.is_finite() && config.max_overfill > 0.0) {
            return Err(LearnedError::Settings(format!(
                "max_overfill must be a positive multiple of a footprint, got {}",
                config.max_overfill
            )));
        }
        if !(config.max_joined_fill.is_finite() && config.max_joined_fill >= 0.0) {
            return Err(LearnedError::Settings(format!(
                "max_joined_fill must be a multiple ≥ 0 of a footprint, got {}",
                config.max_joined_fill
            )));
        }
        if !config.input_scale.is_valid() {
            return Err(LearnedError::Settings(format!(
                "input_scale must be a positive number of pixels per mm, got {:?}",
                config.input_scale
            )));
        }
        models.check_catalog(catalog)?;
        let trained = (models.segmenter.training.as_ref()).and_then(|t| t.table_px_per_mm);
        let segmenter = BatchSession::open(runtime, &models.segmenter.path, config.threads)?;
        let keypoints = BatchSession::open(runtime, &models.keypoints.path, config.threads)?;
        // The files may have changed since `models` was read: check the contract again.
        LearnedModels {
            segmenter: segmenter.manifest().clone(),
            keypoints: keypoints.manifest().clone(),
        }
        .check_catalog(catalog)?;
        let specs = models
            .parts()
            .iter()
            .map(|name| {
                catalog.part(name).ok_or_else(|| LearnedError::Part {
                    part: name.clone(),
                    reason: "not in the catalog".into(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let meshes = specs
            .iter()
            .map(|spec| {
                catalog.load_mesh(spec).map_err(|e| LearnedError::Part {
                    part: spec.name.clone(),
                    reason: format!("mesh: {e}"),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let footprints: Vec<Vec<f64>> = specs
            .iter()
            .zip(&meshes)
            .map(|(spec, mesh)| footprints_mm2(mesh, &spec.stable_poses))
            .collect();
        let extents = meshes.iter().map(|m| m.extents().max()).collect();
        let contour = config
            .contour
            .map(|c| ContourStage::new(&specs, &meshes, &footprints, c));
        let stacking = config
            .stacking_tolerance
            .map(|t| StackingCheck::new(&meshes, t));
        Ok(Self {
            parts: models.parts().to_vec(),
            catalog: catalog.clone(),
            config,
            segmenter: Segmenter::new(segmenter),
            keypoint_net: KeypointNet::new(keypoints, config.voting, config.threads),
            preprocessor: Preprocessor::default(),
            map: SegmentMap::default(),
            grouper: InstanceGrouper::new(config.instances),
            owners: CellOwners::default(),
            batch: CropBatch::default(),
            estimator: None,
            contour,
            stacking,
            footprints,
            extents,
            input_px_per_mm: config.input_scale.target(trained),
        })
    }

    /// The parts it detects, in the models' class order.
    pub fn parts(&self) -> &[String] {
        &self.parts
    }

    /// The largest extent of detectable part `part` (its mesh's bounding box), metres: how far
    /// above the table a part it cannot pose may reach.
    pub fn part_extent(&self, part: &str) -> Option<f64> {
        let i = self.parts.iter().position(|p| p == part)?;
        self.extents.get(i).copied()
    }

    /// Its settings.
    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// The table scale the nets see frames at, pixels per mm (`None`: as captured).
    pub fn input_px_per_mm(&self) -> Option<f64> {
        self.input_px_per_mm
    }

    /// The segmenter's reading of the last frame (diagnostics), in the nets' pixels.
    pub fn segment_map(&self) -> &SegmentMap {
        &self.map
    }

    /// Detects the parts in `roi` (`[x, y, width, height]` in pixels of `image`; default the
    /// whole image) of `image`, seen by `camera` (the whole sensor) with the table at
    /// `camera_T_table`. Masks, centres, crops and keypoints are in sensor pixels.
    #[allow(non_snake_case)]
    pub fn detect(
        &mut self,
        image: &FrameImage,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
        roi: Option<[u32; 4]>,
    ) -> Result<LearnedDetections, LearnedError> {
        let start = Instant::now();
        let mut times = StageTimes::default();
        image.check_on_sensor(camera).map_err(LearnedError::Image)?;
        let roi = roi.unwrap_or([0, 0, image.width(), image.height()]);
        let mut t = start;
        let px_per_mm = camera.table_px_per_mm(camera_T_table);
        // Sensor pixel of the region's first pixel.
        let sensor = [image.origin[0] + roi[0], image.origin[1] + roi[1]];
        let view = NetView::new(sensor, [roi[2], roi[3]], px_per_mm, self.input_px_per_mm);
        let resampled = view.resample(&image.pixels, roi)?;
        // The nets' image and the region in it: the frame's, or the region resampled.
        let (net_image, net_roi) = match &resampled {
            Some(r) => (r, [0, 0, r.width(), r.height()]),
            None => (&image.pixels, roi),
        };
        let [hp, wp] = self
            .preprocessor
            .prepare(net_image, net_roi, SEGMENTER_MULTIPLE)?;
        times.preprocess = lap(&mut t);

        let net_valid = [net_roi[2] as usize, net_roi[3] as usize];
        self.segmenter.run(
            self.preprocessor.tensor(),
            [hp, wp],
            net_valid,
            &mut self.map,
        )?;
        times.segment = lap(&mut t);

        let net_px_per_mm = view.net_px_per_mm(px_per_mm);
        let mut instances = self.grouper.group(&self.map, net_px_per_mm);
        let cell_mm2 = (SEGMENTER_STRIDE * SEGMENTER_STRIDE) as f64 / net_px_per_mm.powi(2);
        let max_cells: Vec<usize> = (self.footprints.iter())
            .map(|f| {
                let largest = f.iter().copied().fold(0.0, f64::max);
                (self.config.max_joined_fill * largest / cell_mm2).floor() as usize
            })
            .collect();
        join_split(&mut instances, self.map.width, self.map.height, &max_cells);
        instances.retain(|i| i.score >= self.config.min_score);
        times.instances = lap(&mut t);

        // Crops of the nets' image: their origins in the nets' pixels of the region, and their
        // windows on the sensor.
        self.batch.clear(self.parts.len());
        let mut origins = Vec::with_capacity(instances.len());
        let mut windows = Vec::with_capacity(instances.len());
        for inst in &instances {
            let centre = [
                inst.centre[0] + f64::from(net_roi[0]),
                inst.centre[1] + f64::from(net_roi[1]),
            ];
            let origin = crop_origin(centre);
            self.batch.push(net_image, net_roi, origin, inst.part)?;
            let origin = [
                origin[0] - i64::from(net_roi[0]),
                origin[1] - i64::from(net_roi[1]),
            ];
            origins.push(origin);
            windows.push(view.sensor_window(origin, CROP_SIZE));
        }
        times.crops = lap(&mut t);

        let votes = if instances.is_empty() {
            Vec::new()
        } else {
            self.keypoint_net.infer(&self.batch)?;
            times.keypoint_net = lap(&mut t);
            let v = self.keypoint_net.vote(instances.len());
            times.voting = lap(&mut t);
            v
        };

        let estimator = estimator_for(
            &mut self.estimator,
            &self.catalog,
            self.config.estimator,
            camera_T_table,
        )?;
        let contour = self.contour.as_ref();
        if contour.is_some() {
            let (w, h) = (self.map.width, self.map.height);
            self.owners.set(&instances, w, h, view);
        }
        let owners = &self.owners;
        let (max_lean, max_overfill) = (self.config.max_lean, self.config.max_overfill);
        let (parts, footprints) = (&self.parts, &self.footprints);
        let jobs: Vec<_> = instances.iter().zip(&origins).zip(votes).collect();
        let pose_of = |k: usize| {
            let ((inst, origin), votes) = &jobs[k];
            let crop = (**origin, windows[k]);
            let ctx = PoseContext {
                estimator,
                contour,
                image,
                camera,
                owners: &|y, x, row: &mut [Owner]| owners.owner_row(k, y, x, row),
                px_per_mm,
                view,
                max_lean,
                footprints: &footprints[inst.part],
                max_overfill,
            };
            let visible_mm2 = inst.cells.len() as f64 * cell_mm2;
            ctx.pose(inst.part, &parts[inst.part], votes, crop, visible_mm2)
        };
        let threads = self.config.threads.min(jobs.len()).max(1);
        let mut poses: Vec<PoseOutcome> = if threads <= 1 {
            (0..jobs.len()).map(pose_of).collect()
        } else {
            // Workers take the next detection as they free up: poses differ widely in cost
            // (a refused estimate is not aligned).
            let next = AtomicUsize::new(0);
            let mut done: Vec<(usize, PoseOutcome)> = std::thread::scope(|s| {
                let handles: Vec<_> = (0..threads)
                    .map(|_| {
                        s.spawn(|| {
                            let mut mine = Vec::new();
                            loop {
                                let i = next.fetch_add(1, Ordering::Relaxed);
                                if i >= jobs.len() {
                                    break mine;
                                }
                                mine.push((i, pose_of(i)));
                            }
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .flat_map(|h| h.join().expect("a pose worker panicked"))
                    .collect()
            });
            done.sort_unstable_by_key(|(i, _)| *i);
            done.into_iter().map(|(_, p)| p).collect()
        };
        if let Some(check) = &self.stacking {
            withdraw_stacked(check, &instances, &view, &self.parts, &mut poses);
        }
        let mut detections = Vec::with_capacity(instances.len());
        let valid = [roi[2] as usize, roi[3] as usize];
        for ((inst, window), (keypoints, pose, refused)) in
            instances.iter().zip(&windows).zip(poses)
        {
            let centre = view.to_sensor(Point2::from(inst.centre));
            detections.push(LearnedDetection {
                part: self.parts[inst.part].clone(),
                score: inst.score,
                mask: inst.mask(self.map.width, valid, &view),
                centre: [centre.x, centre.y],
                crop_origin: [window[0], window[1]],
                keypoints,
                pose,
                refused,
            });
        }
        times.pose = lap(&mut t);
        times.total = start.elapsed();
        Ok(LearnedDetections { detections, times })
    }
}

/// One detection's keypoints, its pose or why there is none, and an estimate that was refused.
type PoseOutcome = (
    Vec<KeypointVote>,
    Result<PoseEstimate, String>,
    Option<PoseEstimate>,
);

/// What the pose stage of one frame shares between its workers, and which part each pixel shows
/// as the detection at hand sees it.
struct PoseContext<'a> {
    estimator: &'a PoseEstimator,
    contour: Option<&'a ContourStage>,
    image: &'a FrameImage,
    camera: &'a Camera,
    owners: &'a (dyn Fn(i64, i64, &mut [Owner]) + Sync),
    /// The image scale on the table, pixels per mm.
    px_per_mm: f64,
    /// How the nets' pixels map to the sensor's.
    view: NetView,
    /// [`PipelineConfig::max_lean`].
    max_lean: f64,
    /// The detected part's footprint in each of its stable poses, mm².
    footprints: &'a [f64],
    /// [`PipelineConfig::max_overfill`].
    max_overfill: f64,
}

impl PoseContext<'_> {
    /// Keypoints → pose estimate → contour alignment for one detection of part `class` whose
    /// keypoint crop starts at net pixel `crop.0` of the region and covers the sensor window
    /// `crop.1` (`[x, y, width, height]`), and whose mask covers
    /// `visible_mm2` of the table (or, when the keypoints place nothing, its outline alone), in a
    /// stable pose whose footprint can show that much.
    fn pose(
        &self,
        class: usize,
        part: &str,
        votes: &Result<Vec<KeypointVote>, VoteError>,
        (origin, window): ([i64; 2], [i64; 4]),
        visible_mm2: f64,
    ) -> PoseOutcome {
        let v = match votes {
            Ok(v) => v,
            Err(e) => return (Vec::new(), Err(format!("voting: {e}")), None),
        };
        let (keypoints, observations) = sensor_observations(v, origin, &self.view);
        let footprints = self.footprints;
        let admitted = ClassSet::filter(footprints.len(), |c| {
            visible_mm2 <= self.max_overfill * footprints[c]
        });
        if admitted.is_empty_below(footprints.len()) {
            let largest = footprints.iter().copied().fold(0.0, f64::max);
            let reason = format!(
                "its mask covers {visible_mm2:.0} mm² of the table, more than {:.1} × the {largest:.0} mm² \
                 a {part} covers lying in any stable pose",
                self.max_overfill
            );
            // The keypoints' own estimate, in any stable pose, is still what evaluation reports
            // as this detection's raw PnP.
            let refused = match self.estimator.estimate(part, self.camera, &observations) {
                Ok(estimate) => Some(estimate),
                Err(EstimateError::Rms { estimate, .. }) => Some(*estimate),
                Err(_) => None,
            };
            return (keypoints, Err(reason), refused);
        }
        match self
            .estimator
            .estimate_in(part, self.camera, &observations, admitted)
        {
            Ok(mut pose) => {
                if let Some(stage) = self.contour {
                    stage.refine(
                        &mut pose,
                        class,
                        part,
                        self.estimator,
                        self.image,
                        self.camera,
                        window,
                        admitted,
                        self.owners,
                    );
                }
                let keypoint_planar = pose
                    .contour
                    .as_ref()
                    .map_or(&pose.planar, |c| &c.keypoint_planar);
                if keypoint_planar.tilt > self.max_lean {
                    pose.confidence = 0.0;
                }
                (keypoints, Ok(pose), None)
            }
            Err(e) => {
                let reason = e.to_string();
                let refused = match e {
                    EstimateError::Rms { estimate, .. } => Some(*estimate),
                    _ => None,
                };
                if let (Some(stage), Some(estimate), Some(centre)) =
                    (self.contour, &refused, keypoints.last())
                    && let Some(rescued) = stage.rescue(
                        estimate,
                        class,
                        part,
                        self.estimator,
                        self.image,
                        self.camera,
                        window,
                        centre.position,
                        self.px_per_mm,
                        visible_mm2,
                        admitted,
                        self.owners,
                    )
                {
                    return (keypoints, Ok(rescued), None);
                }
                (keypoints, Err(reason), refused)
            }
        }
    }
}

/// Withdraws the poses of parts that lie on or under another detected part (their estimates on
/// the table overlap): each becomes a refused estimate with the reason, which names the other
/// part and its centre in sensor pixels (`view`: where the instances' net pixels lie).
/// An outline-only pose ([`crate::estimate::ContourRefinement::outline_only`]) is the weaker
/// witness: it is withdrawn for any overlap, but withdraws no keypoint pose (a part leaning on
/// others can show an outline that fits a featureless pose on the table).
#[allow(non_snake_case)]
fn withdraw_stacked(
    check: &StackingCheck,
    instances: &[Instance],
    view: &NetView,
    parts: &[String],
    poses: &mut [PoseOutcome],
) {
    let (posed, estimates): (Vec<usize>, Vec<_>) = poses
        .iter()
        .enumerate()
        .filter_map(|(i, (_, pose, _))| {
            let table_T_part = pose.as_ref().ok()?.planar.table_T_part;
            Some((i, (instances[i].part, table_T_part)))
        })
        .unzip();
    let outline_only: Vec<bool> = posed
        .iter()
        .map(|&i| poses[i].1.as_ref().is_ok_and(PoseEstimate::is_outline_only))
        .collect();
    let overlaps = check.overlaps_where(&estimates, |k, other| {
        outline_only[k] || !outline_only[other]
    });
    for (k, overlap) in overlaps.into_iter().enumerate() {
        let Some(o) = overlap else { continue };
        let (i, other) = (posed[k], &instances[posed[o.other]]);
        let centre = view.to_sensor(Point2::from(other.centre));
        let reason = format!(
            "lies on or under the {} at ({:.0}, {:.0}) px: on the table their poses overlap by {:.2} mm",
            parts[other.part],
            centre.x,
            centre.y,
            1e3 * o.depth
        );
        if let Ok(pose) = std::mem::replace(&mut poses[i].1, Err(reason)) {
            poses[i].2 = Some(pose);
        }
    }
}

/// Votes in crop pixels → the same votes in sensor pixels (the crop's origin, net pixel
/// `crop_origin` of the region that `view` shows, added, and then mapped to the sensor) and the
/// pose estimator's observations (keypoint k = vote k, with its covariance).
pub fn sensor_observations(
    votes: &[KeypointVote],
    crop_origin: [i64; 2],
    view: &NetView,
) -> (Vec<KeypointVote>, Vec<Observation>) {
    let keypoints: Vec<KeypointVote> = votes
        .iter()
        .map(|v| KeypointVote {
            position: view.to_sensor(Point2::new(
                v.position.x + crop_origin[0] as f64,
                v.position.y + crop_origin[1] as f64,
            )),
            covariance: view.covariance_to_sensor(&v.covariance),
            ..*v
        })
        .collect();
    let observations = keypoints
        .iter()
        .enumerate()
        .map(|(k, v)| Observation {
            keypoint: k,
            pixel: v.position,
            covariance: Some(v.covariance),
        })
        .collect();
    (keypoints, observations)
}

/// The pose estimator for the table at `camera_T_table`, rebuilt only when it moves.
#[allow(non_snake_case)]
fn estimator_for<'a>(
    cache: &'a mut Option<(Isometry3<f64>, PoseEstimator)>,
    catalog: &Catalog,
    config: EstimatorConfig,
    camera_T_table: &Isometry3<f64>,
) -> Result<&'a PoseEstimator, LearnedError> {
    if cache.as_ref().is_none_or(|(at, _)| at != camera_T_table) {
        let estimator = PoseEstimator::new(catalog, *camera_T_table, config)
            .map_err(LearnedError::Estimator)?;
        *cache = Some((*camera_T_table, estimator));
    }
    Ok(&cache.as_ref().expect("set above").1)
}

/// Time since `t`, restarting `t`.
fn lap(t: &mut Instant) -> std::time::Duration {
    let now = Instant::now();
    let d = now - *t;
    *t = now;
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learned::crops::crop_camera;
    use crate::learned::keypoint_net::field_to_crop;
    use crate::learned::models::{CROP_SIZE, FIELD_SIZE};
    use crate::part::{PartSpec, TriMesh};
    use crate::voting::{VectorField, Voter};
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use std::path::Path;

    /// The committed catalog, the seed's camera 1.5 m straight above the table, the camera's
    /// pose on the table and an estimator with a reprojection gate of `gate_px`.
    #[allow(non_snake_case)]
    fn overhead(gate_px: f64) -> (Catalog, Camera, Isometry3<f64>, PoseEstimator) {
        overhead_of("usbc.toml", gate_px)
    }

    /// [`overhead`] for the committed catalog `file`.
    #[allow(non_snake_case)]
    fn overhead_of(file: &str, gate_px: f64) -> (Catalog, Camera, Isometry3<f64>, PoseEstimator) {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenarios/parts")
            .join(file);
        let catalog = Catalog::load(&root).unwrap();
        let camera_T_table = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let estimator = PoseEstimator::new(
            &catalog,
            camera_T_table,
            EstimatorConfig::with_gate(gate_px),
        )
        .unwrap();
        (catalog, Camera::basler_seed(), camera_T_table, estimator)
    }

    /// Where `camera` sees the keypoints of `part` at `camera_T_part`, sensor pixels.
    #[allow(non_snake_case)]
    fn keypoint_pixels(
        camera: &Camera,
        camera_T_part: &Isometry3<f64>,
        part: &crate::part::PartSpec,
    ) -> Vec<Point2<f64>> {
        part.keypoint_points()
            .iter()
            .map(|k| camera.project(&(camera_T_part * k)).unwrap())
            .collect()
    }

    /// A perfect keypoint-net output (contract layout: cell (i, j) centre at crop pixel
    /// (2j + 0.5, 2i + 0.5)) for keypoints at crop pixels `kps`, foreground within 28 px of `c`.
    fn perfect_field(kps: &[Point2<f64>], c: Point2<f64>) -> (Vec<u8>, Vec<f32>) {
        let n = FIELD_SIZE;
        let mut mask = vec![0u8; n * n];
        let mut vectors = vec![0f32; 2 * kps.len() * n * n];
        for i in 0..n {
            for j in 0..n {
                let p = Point2::new(2.0 * j as f64 + 0.5, 2.0 * i as f64 + 0.5);
                if (p - c).norm() > 28.0 {
                    continue;
                }
                mask[i * n + j] = 1;
                for (k, kp) in kps.iter().enumerate() {
                    let d = (kp - p).normalize();
                    vectors[2 * k * n * n + i * n + j] = d.x as f32;
                    vectors[(2 * k + 1) * n * n + i * n + j] = d.y as f32;
                }
            }
        }
        (mask, vectors)
    }

    /// An outline-only pose that overlaps a keypoint pose is withdrawn alone; two keypoint
    /// poses that overlap are both withdrawn.
    #[test]
    #[allow(non_snake_case)]
    fn an_outline_only_pose_withdraws_no_keypoint_pose() {
        let (catalog, camera, camera_T_table, estimator) = overhead(1.0);
        let part = catalog.part("insert_mold").unwrap();
        let mesh = catalog.load_mesh(part).unwrap();
        let check = StackingCheck::new(&[mesh], STACKING_TOLERANCE);
        // Insert molds face up at these table points: the first two 2 mm apart (overlapping),
        // the last two as well, the middle pair 20 mm apart.
        let at = [0.0, 0.002, 0.022, 0.024];
        let pose_at = |x: f64, outline_only: bool| {
            let table_T_part = part.stable_poses[0].table_T_part(x, 0.0, 0.3);
            let observations: Vec<Observation> =
                keypoint_pixels(&camera, &(camera_T_table * table_T_part), part)
                    .into_iter()
                    .enumerate()
                    .map(|(keypoint, pixel)| Observation {
                        keypoint,
                        pixel,
                        covariance: None,
                    })
                    .collect();
            let mut pose = estimator
                .estimate("insert_mold", &camera, &observations)
                .unwrap();
            if outline_only {
                let fit = crate::contour::ContourFit {
                    x,
                    y: 0.0,
                    yaw: 0.3,
                    support: 1.0,
                };
                let refiner = estimator.refiner("insert_mold").unwrap();
                pose.adopt_contour(fit, 0, refiner, 1.0);
                pose.contour.as_mut().unwrap().outline_only = true;
            }
            pose
        };
        let mut poses: Vec<PoseOutcome> = at
            .iter()
            .enumerate()
            .map(|(i, &x)| (Vec::new(), Ok(pose_at(x, i == 1)), None))
            .collect();
        let instances: Vec<Instance> = at
            .iter()
            .map(|_| Instance {
                part: 0,
                score: 1.0,
                centre: [0.0, 0.0],
                cells: Vec::new(),
            })
            .collect();
        withdraw_stacked(
            &check,
            &instances,
            &NetView::new([0, 0], [64, 64], 7.0, None),
            &["insert_mold".into()],
            &mut poses,
        );
        let kept: Vec<bool> = poses.iter().map(|(_, p, _)| p.is_ok()).collect();
        assert_eq!(kept, [true, false, false, false]);
        assert!(
            poses
                .iter()
                .skip(1)
                .all(|(_, _, refused)| refused.is_some())
        );
    }

    /// The glue between the nets and PnP: crop origin, field → crop pixels, crop → sensor pixels,
    /// covariances and the estimator. A perfect field must give the true pose back.
    #[test]
    #[allow(non_snake_case)]
    fn a_perfect_keypoint_field_gives_the_true_pose_back() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
        let catalog = Catalog::load(&root).unwrap();
        let camera = Camera::basler_seed();
        let table_T_camera = Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 1.51),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let camera_T_table = table_T_camera.inverse();
        let estimator =
            PoseEstimator::new(&catalog, camera_T_table, EstimatorConfig::with_gate(1.0)).unwrap();
        let mut voter = Voter::new(VotingConfig::default());
        for (name, x, y, yaw) in [
            ("main_shell", 0.012, -0.008, 0.4),
            ("insert_mold", -0.01, 0.015, 2.2),
            ("top_shell", 0.003, 0.021, -1.3),
        ] {
            let part = catalog.part(name).unwrap();
            let table_T_part = part.stable_poses[0].table_T_part(x, y, yaw);
            let camera_T_part = camera_T_table * table_T_part;
            let sensor = keypoint_pixels(&camera, &camera_T_part, part);
            let centre = sensor[8];
            let origin = crop_origin([centre.x, centre.y]);
            let shift = Vector3::new(origin[0] as f64, origin[1] as f64, 0.0).xy();
            let crop: Vec<Point2<f64>> = sensor.iter().map(|p| p - shift).collect();
            // The crop camera sees the keypoints where the crop holds them.
            let cc = crop_camera(&camera, origin);
            for (k, p) in part.keypoint_points().iter().zip(&crop) {
                assert!((cc.project(&(camera_T_part * k)).unwrap() - p).norm() < 1e-9);
            }
            let (mask, vectors) = perfect_field(&crop, crop[8]);
            let field = VectorField {
                width: FIELD_SIZE,
                height: FIELD_SIZE,
                keypoints: crop.len(),
                mask: &mask,
                vectors: &vectors,
            };
            let votes: Vec<KeypointVote> = voter
                .vote(&field)
                .unwrap()
                .iter()
                .map(field_to_crop)
                .collect();
            for (v, p) in votes.iter().zip(&crop) {
                assert!(
                    (v.position - p).norm() < 0.05,
                    "{name}: {} vs {p}",
                    v.position
                );
                assert!(v.position.x >= 0.0 && v.position.x < CROP_SIZE as f64);
            }
            let sensor_view = NetView::new([0, 0], [camera.width, camera.height], 7.0, None);
            let (kps, observations) = sensor_observations(&votes, origin, &sensor_view);
            assert!((kps[8].position - sensor[8]).norm() < 0.05);
            let pose = estimator.estimate(name, &camera, &observations).unwrap();
            let err = pose.planar.table_T_part.translation.vector - table_T_part.translation.vector;
            assert!(err.xy().norm() < 2e-5, "{name}: {err}");
            assert_eq!(pose.stable_pose, part.stable_poses[0].name);
            assert!(pose.rms_px < 0.1, "{name}: rms {}", pose.rms_px);
        }
    }

    /// The pose stage without contour alignment, for a part with these `footprints`.
    fn keypoints_only<'a>(
        estimator: &'a PoseEstimator,
        camera: &'a Camera,
        image: &'a FrameImage,
        footprints: &'a [f64],
    ) -> PoseContext<'a> {
        PoseContext {
            estimator,
            contour: None,
            image,
            camera,
            owners: &|_, _, row: &mut [Owner]| row.fill(Owner::Nobody),
            px_per_mm: 7.0,
            view: NetView::new([0, 0], [camera.width, camera.height], 7.0, None),
            max_lean: MAX_LEAN,
            footprints,
            max_overfill: MAX_OVERFILL,
        }
    }

    /// Votes exactly on the keypoints of `part` at `camera_T_part`, with their crop's origin.
    #[allow(non_snake_case)]
    fn exact_votes(
        camera: &Camera,
        camera_T_part: &Isometry3<f64>,
        part: &PartSpec,
    ) -> (Vec<KeypointVote>, ([i64; 2], [i64; 4])) {
        let sensor = keypoint_pixels(camera, camera_T_part, part);
        let origin = crop_origin([sensor[8].x, sensor[8].y]);
        let votes = sensor
            .iter()
            .map(|p| KeypointVote {
                position: Point2::new(p.x - origin[0] as f64, p.y - origin[1] as f64),
                covariance: nalgebra::Matrix2::identity() * 0.25,
                inliers: 500,
                inlier_ratio: 0.9,
                hypotheses: 128,
            })
            .collect();
        let side = CROP_SIZE as i64;
        (votes, (origin, [origin[0], origin[1], side, side]))
    }

    /// Each stable pose's footprint of catalog part `name`, mm².
    fn footprints(catalog: &Catalog, name: &str) -> Vec<f64> {
        let part = catalog.part(name).unwrap();
        let mesh = catalog.load_mesh(part).unwrap();
        footprints_mm2(&mesh, &part.stable_poses)
    }

    /// A part lying on another one leans away from every stable pose: its keypoint pose is kept
    /// (no reprojection gate here refuses it) but gets no confidence, so the cell does not pick
    /// it; the same part resting flat keeps its confidence.
    #[test]
    #[allow(non_snake_case)]
    fn a_keypoint_pose_leaning_past_the_limit_gets_no_confidence() {
        let (catalog, camera, camera_T_table, estimator) = overhead(1e4);
        let image = FrameImage::full(image::DynamicImage::new_luma8(1, 1));
        let footprints = footprints(&catalog, "top_shell");
        let ctx = keypoints_only(&estimator, &camera, &image, &footprints);
        let part = catalog.part("top_shell").unwrap();
        let flat = part.stable_poses[0].table_T_part(0.004, -0.003, 0.7);
        // Propped up 40° about the part's x axis, as on the edge of a neighbour.
        let propped = flat
            * Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.002),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 40f64.to_radians()),
            );
        let confidence = |table_T_part: &Isometry3<f64>| {
            let (votes, crop) = exact_votes(&camera, &(camera_T_table * table_T_part), part);
            let (_, pose, _) = ctx.pose(2, "top_shell", &Ok(votes), crop, 60.0);
            let pose = pose.unwrap();
            (pose.planar.tilt.to_degrees(), pose.confidence)
        };
        let (tilt, c) = confidence(&flat);
        assert!(tilt < 1.0 && c > 0.5, "flat: tilt {tilt}°, confidence {c}");
        let (tilt, c) = confidence(&propped);
        assert!(
            tilt > 30.0 && c == 0.0,
            "propped: tilt {tilt}°, confidence {c}"
        );
    }

    /// `mesh` at `camera_T_part` drawn into `image` (the table grey 128): faces up bright (220),
    /// the others `side` grey, 4 × 4 samples a pixel, for a convex mesh (its faces towards the
    /// camera never overlap). Returns the pixels it covers more than half of.
    #[allow(non_snake_case)]
    fn draw_convex(
        image: &mut image::GrayImage,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
        camera_T_part: &Isometry3<f64>,
        mesh: &TriMesh,
        side: u8,
    ) -> Vec<(i64, i64)> {
        let up = camera_T_table.rotation * Vector3::z();
        let faces: Vec<([Point2<f64>; 3], u8)> = mesh
            .triangles
            .iter()
            .filter_map(|t| {
                let [a, b, c] = t.map(|i| camera_T_part * mesh.vertices[i as usize]);
                let normal = (b - a).cross(&(c - a)).normalize();
                (normal.dot(&a.coords) < 0.0).then(|| {
                    let shade = if normal.dot(&up) > 0.9 { 220 } else { side };
                    ([a, b, c].map(|p| camera.project(&p).unwrap()), shade)
                })
            })
            .collect();
        let (mut lo, mut hi) = (
            Point2::new(f64::MAX, f64::MAX),
            Point2::new(f64::MIN, f64::MIN),
        );
        for p in faces.iter().flat_map(|(f, _)| f) {
            (lo.x, lo.y, hi.x, hi.y) = (lo.x.min(p.x), lo.y.min(p.y), hi.x.max(p.x), hi.y.max(p.y));
        }
        let inside = |[a, b, c]: &[Point2<f64>; 3], p: Point2<f64>| {
            let side = |u: Point2<f64>, v: Point2<f64>| (v - u).perp(&(p - u));
            let (x, y, z) = (side(*a, *b), side(*b, *c), side(*c, *a));
            (x >= 0.0 && y >= 0.0 && z >= 0.0) || (x <= 0.0 && y <= 0.0 && z <= 0.0)
        };
        let mut covered = Vec::new();
        for v in lo.y.floor() as i64 - 2..=hi.y.ceil() as i64 + 2 {
            for u in lo.x.floor() as i64 - 2..=hi.x.ceil() as i64 + 2 {
                let (mut level, mut count) = (0.0, 0);
                for k in 0..16 {
                    let p = Point2::new(
                        u as f64 - 0.375 + 0.25 * (k % 4) as f64,
                        v as f64 - 0.375 + 0.25 * (k / 4) as f64,
                    );
                    let shade = faces.iter().find(|(f, _)| inside(f, p)).map(|(_, s)| *s);
                    level += f64::from(shade.unwrap_or(128)) / 16.0;
                    count += usize::from(shade.is_some());
                }
                image.put_pixel(u as u32, v as u32, image::Luma([level.round() as u8]));
                if count > 8 {
                    covered.push((u, v));
                }
            }
        }
        covered
    }

    /// A NIST 12 mm square peg lying (12 × 14 mm seen from above) where the camera looks in at
    /// 8°, its side face towards the camera as grey as the table, and keypoints that say so:
    /// the lying outline misses its edge on the table there, while the standing one (12 × 12
    /// mm of top and 2 mm of side face) ends on the lying peg's top rim and finds every edge. The
    /// outline alone would stand it up; the part's mask, which holds that side face, keeps it
    /// lying.
    #[test]
    #[allow(non_snake_case)]
    fn the_mask_keeps_a_lying_square_peg_from_a_standing_outline_that_finds_more_edges() {
        let (catalog, camera, camera_T_table, estimator) = overhead_of("nist_pegs.toml", 1e4);
        let part = catalog.part("square_12").unwrap();
        let mesh = catalog.load_mesh(part).unwrap();
        // 0.21 m from under the camera, 1.5 m up: tan 8° = 0.14, and 12 mm + 0.14 × 14 mm = 14 mm.
        let truth = part.stable_pose("-x").unwrap().table_T_part(0.21, 0.0, 0.0);
        let mut pixels =
            image::GrayImage::from_pixel(camera.width, camera.height, image::Luma([128]));
        let camera_T_part = camera_T_table * truth;
        let mask: std::collections::HashSet<(i64, i64)> = draw_convex(
            &mut pixels,
            &camera,
            &camera_T_table,
            &camera_T_part,
            &mesh,
            128,
        )
        .into_iter()
        .collect();
        let image = FrameImage::full(image::DynamicImage::ImageLuma8(pixels));
        let footprints = footprints(&catalog, "square_12");
        let stage = ContourStage::new(
            &[part],
            std::slice::from_ref(&mesh),
            std::slice::from_ref(&footprints),
            ContourConfig::default(),
        );
        let stable_pose = |owners: &(dyn Fn(i64, i64, &mut [Owner]) + Sync)| {
            let ctx = PoseContext {
                contour: Some(&stage),
                owners,
                ..keypoints_only(&estimator, &camera, &image, &footprints)
            };
            let (votes, crop) = exact_votes(&camera, &camera_T_part, part);
            let visible_mm2 = mask.len() as f64 / 7.09f64.powi(2);
            let (_, pose, _) = ctx.pose(0, "square_12", &Ok(votes), crop, visible_mm2);
            let pose = pose.unwrap();
            let error = pose.planar.table_T_part.translation.vector - truth.translation.vector;
            (pose.stable_pose, error.xy().norm())
        };
        let (outline_alone, _) = stable_pose(&|_, _, row| row.fill(Owner::Nobody));
        assert_eq!(outline_alone, "+z", "the outline alone stands it up");
        let (with_mask, error) = stable_pose(&|y, x, row| {
            for (k, owner) in row.iter_mut().enumerate() {
                if mask.contains(&(x + k as i64, y)) {
                    *owner = Owner::Me;
                }
            }
        });
        assert_eq!(with_mask, "-x", "the mask keeps it lying");
        assert!(error < 5e-5, "{:.3} mm off", error * 1e3);
    }

    /// A main shell's keypoints that say it lies on its side, in a mask that shows a face-up
    /// shell's area: no side pose can show that much, so the estimate is snapped onto a face-up
    /// or face-down pose; a mask larger than any pose can show is refused.
    #[test]
    #[allow(non_snake_case)]
    fn a_mask_larger_than_a_stable_poses_footprint_rules_that_pose_out() {
        let (catalog, camera, camera_T_table, estimator) = overhead(1e4);
        let image = FrameImage::full(image::DynamicImage::new_luma8(1, 1));
        let footprints = footprints(&catalog, "main_shell");
        let ctx = keypoints_only(&estimator, &camera, &image, &footprints);
        let part = catalog.part("main_shell").unwrap();
        let side = part.stable_pose("+x").unwrap();
        let on_side = camera_T_table * side.table_T_part(0.002, 0.001, 0.3);
        let area = |pose: &str| {
            footprints[part
                .stable_poses
                .iter()
                .position(|s| s.name == pose)
                .unwrap()]
        };
        assert!(area("+z") > 2.5 * area("+x"), "{footprints:?}");
        let stable_pose = |visible_mm2: f64| {
            let (votes, crop) = exact_votes(&camera, &on_side, part);
            let (_, pose, _) = ctx.pose(0, "main_shell", &Ok(votes), crop, visible_mm2);
            pose.map(|p| p.stable_pose)
        };
        assert_eq!(stable_pose(area("+x")).unwrap(), "+x");
        assert_eq!(stable_pose(MAX_OVERFILL * area("+x") * 0.99).unwrap(), "+x");
        let taken = stable_pose(0.95 * area("+z")).unwrap();
        assert!(taken == "+z" || taken == "-z", "{taken}");
        let largest = footprints.iter().copied().fold(0.0, f64::max);
        assert_eq!(largest, area("+z"));
        let reason = stable_pose(MAX_OVERFILL * largest + 1.0).unwrap_err();
        assert!(
            reason.contains("mm²") && reason.contains("main_shell"),
            "{reason}"
        );
        // The refused detection still carries its keypoints' estimate, for evaluation's raw PnP.
        let (votes, crop) = exact_votes(&camera, &on_side, part);
        let (_, _, refused) = ctx.pose(
            0,
            "main_shell",
            &Ok(votes),
            crop,
            MAX_OVERFILL * largest + 1.0,
        );
        let raw = refused.expect("the keypoints' estimate").pnp.camera_T_part;
        let off = (raw.translation.vector - on_side.translation.vector).norm();
        assert!(off < 1e-4, "raw PnP {:.3} mm off", off * 1e3);
    }
}
