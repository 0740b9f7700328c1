//! The learned pipeline for one frame: preprocess → segment → instances → crops → keypoint net →
//! voting → pose, timing every stage. Image pixels in the results are full-sensor pixels (the
//! frame image's origin added).

use std::time::Instant;

use nalgebra::{Isometry3, Point2};

use super::LearnedError;
use super::crops::{CropBatch, crop_origin};
use super::detection::{LearnedDetection, LearnedDetections, StageTimes};
use super::image::Preprocessor;
use super::instances::{InstanceConfig, InstanceGrouper};
use super::keypoint_net::KeypointNet;
use super::models::{LearnedModels, SEGMENTER_MULTIPLE};
use super::segmenter::{SegmentMap, Segmenter};
use crate::Camera;
use crate::estimate::{EstimatorConfig, Observation, PoseEstimator};
use crate::frame::FrameImage;
use crate::onnx::{BatchSession, Runtime};
use crate::part::Catalog;
use crate::voting::{KeypointVote, VotingConfig};

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
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            instances: InstanceConfig::default(),
            voting: VotingConfig::default(),
            estimator: EstimatorConfig::with_gate(4.0),
            min_score: 0.3,
            threads: 2,
        }
    }
}

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
    batch: CropBatch,
    estimator: Option<(Isometry3<f64>, PoseEstimator)>,
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
        models.check_catalog(catalog)?;
        let segmenter = BatchSession::open(runtime, &models.segmenter.path, config.threads)?;
        let keypoints = BatchSession::open(runtime, &models.keypoints.path, config.threads)?;
        // The files may have changed since `models` was read: check the contract again.
        LearnedModels {
            segmenter: segmenter.manifest().clone(),
            keypoints: keypoints.manifest().clone(),
        }
        .check_catalog(catalog)?;
        Ok(Self {
            parts: models.parts().to_vec(),
            catalog: catalog.clone(),
            config,
            segmenter: Segmenter::new(segmenter),
            keypoint_net: KeypointNet::new(keypoints, config.voting, config.threads),
            preprocessor: Preprocessor::default(),
            map: SegmentMap::default(),
            grouper: InstanceGrouper::new(config.instances),
            batch: CropBatch::default(),
            estimator: None,
        })
    }

    /// The parts it detects, in the models' class order.
    pub fn parts(&self) -> &[String] {
        &self.parts
    }

    /// Its settings.
    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// The segmenter's reading of the last frame (diagnostics).
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
        let [hp, wp] = self
            .preprocessor
            .prepare(&image.pixels, roi, SEGMENTER_MULTIPLE)?;
        times.preprocess = lap(&mut t);

        let valid = [roi[2] as usize, roi[3] as usize];
        self.segmenter
            .run(self.preprocessor.tensor(), [hp, wp], valid, &mut self.map)?;
        times.segment = lap(&mut t);

        let mut instances = self.grouper.group(&self.map);
        instances.retain(|i| i.score >= self.config.min_score);
        times.instances = lap(&mut t);

        // Region pixel → image pixel → sensor pixel.
        let region = [roi[0], roi[1]];
        let sensor = [image.origin[0] + roi[0], image.origin[1] + roi[1]];
        self.batch.clear(self.parts.len());
        let mut origins = Vec::with_capacity(instances.len());
        for inst in &instances {
            let centre = [
                inst.centre[0] + f64::from(region[0]),
                inst.centre[1] + f64::from(region[1]),
            ];
            let origin = crop_origin(centre);
            self.batch.push(&image.pixels, origin, inst.part)?;
            origins.push([
                origin[0] + i64::from(image.origin[0]),
                origin[1] + i64::from(image.origin[1]),
            ]);
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
        let mut detections = Vec::with_capacity(instances.len());
        for ((inst, origin), votes) in instances.iter().zip(&origins).zip(votes) {
            let part = self.parts[inst.part].clone();
            let shift = |v: &KeypointVote| KeypointVote {
                position: Point2::new(
                    v.position.x + origin[0] as f64,
                    v.position.y + origin[1] as f64,
                ),
                ..*v
            };
            let (keypoints, pose) = match votes {
                Ok(v) => {
                    let keypoints: Vec<KeypointVote> = v.iter().map(shift).collect();
                    let observations: Vec<Observation> = keypoints
                        .iter()
                        .enumerate()
                        .map(|(k, v)| Observation {
                            keypoint: k,
                            pixel: v.position,
                            covariance: Some(v.covariance),
                        })
                        .collect();
                    let pose = estimator
                        .estimate(&part, camera, &observations)
                        .map_err(|e| e.to_string());
                    (keypoints, pose)
                }
                Err(e) => (Vec::new(), Err(format!("voting: {e}"))),
            };
            detections.push(LearnedDetection {
                part,
                score: inst.score,
                mask: inst.mask(self.map.width, valid, sensor),
                centre: [
                    inst.centre[0] + f64::from(sensor[0]),
                    inst.centre[1] + f64::from(sensor[1]),
                ],
                crop_origin: *origin,
                keypoints,
                pose,
            });
        }
        times.pose = lap(&mut t);
        times.total = start.elapsed();
        Ok(LearnedDetections { detections, times })
    }
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
