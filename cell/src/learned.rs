//! A scenario's learned models and pipelines, the same for simulated and production runs: the
//! models folder it names, loaded and checked against its catalog, and pipelines built on the
//! process's ONNX Runtime (provisioned on first use).

use perception::PerceptionError;
use perception::estimate::EstimatorConfig;
use perception::learned::{LearnedModels, LearnedPipeline, PipelineConfig};
use perception::onnx::Runtime;

use crate::scenario::Scenario;

/// The scenario's learned models (`[perception] models`, relative to the scenario file), checked
/// against its catalog.
pub fn models(scenario: &Scenario) -> Result<LearnedModels, PerceptionError> {
    let models = scenario.spec.perception.models.as_ref().ok_or_else(|| {
        PerceptionError::Settings(
            "mode \"learned\" needs [perception] models (a folder of ONNX models)".into(),
        )
    })?;
    let dir = scenario.path.parent().unwrap_or(std::path::Path::new("."));
    let models = LearnedModels::in_dir(&dir.join(models))?;
    models.check_catalog(&scenario.catalog)?;
    Ok(models)
}

/// A pipeline for `models` and the scenario's catalog, with `threads` ONNX Runtime and voting
/// threads and the scenario's reprojection gate.
pub fn pipeline(
    scenario: &Scenario,
    models: &LearnedModels,
    threads: usize,
) -> Result<LearnedPipeline, PerceptionError> {
    let runtime = Runtime::get().map_err(|e| PerceptionError::Model(e.to_string()))?;
    let config = PipelineConfig {
        threads,
        estimator: EstimatorConfig::with_gate(scenario.spec.perception.max_rms_px),
        input_scale: scenario.spec.perception.input_scale,
        ..PipelineConfig::default()
    };
    Ok(LearnedPipeline::with_config(
        models,
        &scenario.catalog,
        &runtime,
        config,
    )?)
}

/// The region of the sensor (`[x, y, width, height]`, pixels) where the scenario's calibrated
/// camera sees the feeder: what learned perception searches, in simulated captures and in
/// production's full-sensor images alike.
pub fn feeder_roi(scenario: &Scenario) -> Result<[u32; 4], PerceptionError> {
    let window = sim::cell::calibrated_feeder_window(&scenario.spec.cell).ok_or_else(|| {
        PerceptionError::Settings("the feeder is not in the calibrated camera's view".into())
    })?;
    Ok([window.x0, window.y0, window.width, window.height])
}
