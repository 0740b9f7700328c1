//! Which perception a simulated episode runs: keypoint noise on the true scene, or the learned
//! pipeline on the rendered feeder window. Learned pipelines hold ONNX Runtime sessions, so they
//! are pooled across episodes: a worker takes one, runs its episode, and gives it back.

use std::sync::Mutex;

use nalgebra::Isometry3;
use perception::learned::{LearnedModels, LearnedPerception, LearnedPipeline};
use perception::{Frame, PartPerception, Perceived, PerceptionError};

use super::{HarnessError, keypoint_noise_for};
use crate::learned;
use crate::scenario::{PerceptionMode, Scenario};

/// Learned pipelines for a scenario, built on demand and reused.
pub struct PipelinePool {
    scenario: Scenario,
    models: LearnedModels,
    #[allow(non_snake_case)]
    base_T_table: Isometry3<f64>,
    /// Where the calibrated camera sees the feeder (sensor pixels).
    roi: [u32; 4],
    idle: Mutex<Vec<LearnedPipeline>>,
}

impl PipelinePool {
    /// A pool for the scenario's models; they are checked against its catalog now.
    pub fn new(scenario: &Scenario) -> Result<Self, HarnessError> {
        Ok(Self {
            models: learned::models(scenario)?,
            base_T_table: scenario.spec.cell.base_T_table.isometry(),
            roi: learned::feeder_roi(scenario)?,
            scenario: scenario.clone(),
            idle: Mutex::new(Vec::new()),
        })
    }

    /// A pipeline for one episode: an idle one, or a new one (one ONNX Runtime thread each: the
    /// runner already runs an episode per core).
    fn take(&self) -> Result<LearnedPipeline, HarnessError> {
        if let Some(p) = self.idle.lock().unwrap_or_else(|e| e.into_inner()).pop() {
            return Ok(p);
        }
        Ok(learned::pipeline(&self.scenario, &self.models, 1)?)
    }

    fn give_back(&self, pipeline: LearnedPipeline) {
        self.idle
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(pipeline);
    }
}

/// How a scenario's simulated episodes perceive.
pub enum SimPerception {
    /// True keypoints with noise (the paper's ablation); the camera delivers the true scene.
    KeypointNoise,
    /// The learned pipeline on rendered pixels.
    Learned(Box<PipelinePool>),
}

impl SimPerception {
    /// The scenario's perception; learned models are loaded and checked now.
    pub fn new(scenario: &Scenario) -> Result<Self, HarnessError> {
        Ok(match scenario.spec.perception.mode {
            PerceptionMode::KeypointNoise => SimPerception::KeypointNoise,
            PerceptionMode::Learned => {
                SimPerception::Learned(Box::new(PipelinePool::new(scenario)?))
            }
        })
    }

    /// Whether the camera must deliver rendered pixels.
    pub fn needs_pixels(&self) -> bool {
        matches!(self, SimPerception::Learned(_))
    }

    /// The perception of `episode`.
    pub fn for_episode<'a>(
        &'a self,
        scenario: &Scenario,
        episode: u32,
    ) -> Result<EpisodePerception<'a>, HarnessError> {
        Ok(match self {
            SimPerception::KeypointNoise => {
                EpisodePerception::KeypointNoise(Box::new(keypoint_noise_for(scenario, episode)?))
            }
            SimPerception::Learned(pool) => EpisodePerception::Learned {
                perception: Some(Box::new(
                    LearnedPerception::new(pool.take()?, pool.base_T_table).with_roi(pool.roi),
                )),
                pool,
            },
        })
    }
}

/// One episode's perception; a learned pipeline goes back to its pool when the episode ends.
pub enum EpisodePerception<'a> {
    /// Keypoint noise on the episode's perception stream.
    KeypointNoise(Box<dyn PartPerception + 'a>),
    /// A pooled learned pipeline.
    Learned {
        /// The pipeline behind the seam (always `Some` until dropped).
        perception: Option<Box<LearnedPerception>>,
        /// Where it returns.
        pool: &'a PipelinePool,
    },
}

impl PartPerception for EpisodePerception<'_> {
    fn perceive(&mut self, frame: &Frame) -> Result<Perceived, PerceptionError> {
        match self {
            EpisodePerception::KeypointNoise(p) => p.perceive(frame),
            EpisodePerception::Learned { perception, .. } => match perception {
                Some(p) => p.perceive(frame),
                None => Err(PerceptionError::Settings(
                    "the pipeline was returned".into(),
                )),
            },
        }
    }
}

impl Drop for EpisodePerception<'_> {
    fn drop(&mut self) {
        if let EpisodePerception::Learned { perception, pool } = self
            && let Some(p) = perception.take()
        {
            pool.give_back(p.into_pipeline());
        }
    }
}
