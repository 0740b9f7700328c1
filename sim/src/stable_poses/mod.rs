//! Stable poses from physics, as in the seed's Figure 3: drop a part many times from random
//! orientations onto a plane, let it rest, and group the rest orientations by resting face.

mod basin;
mod cluster;
pub(crate) mod drop;
mod mujoco;
mod symmetric;

pub use basin::FaceBasins;
pub use cluster::{CLASS_ANGLE_RAD, LEAN_HEIGHT, PoseClass, cluster, leaning};
pub use drop::{
    DropBody, DropOutcome, DropSettings, HULL_TOLERANCE, SIMPLIFY_HULL_ABOVE, contact_hull,
    geometric_rest_height, random_rotation, simulate_batch, stratified_rotation,
};
pub use mujoco::{DropEngine, restitution_dampratio, stable_poses_mujoco, stable_poses_with};

use indicatif::ProgressBar;
use perception::part::TriMesh;
use rayon::prelude::*;

/// The result of dropping one part: its classes and how the drops went.
#[derive(Debug, Clone)]
pub struct StablePoseReport {
    /// Classes, most probable first.
    pub classes: Vec<PoseClass>,
    /// Drops simulated.
    pub drops: usize,
    /// Drops still jittering in place at the time limit (classified by their face all the same).
    pub unsettled: usize,
    /// Drops that came to rest on a neighbour rather than flat on the table (crowded drops
    /// only); left out of the classes, counted in their denominator.
    pub leaning: usize,
    /// Drops in classes too rare to keep.
    pub rare: usize,
    /// Mass in kg, from the mesh and density.
    pub mass: f64,
    /// Centre of mass in the part frame, metres.
    pub center_of_mass: nalgebra::Point3<f64>,
    /// Mean simulated time until a drop rested or was trapped on its face, seconds.
    pub mean_rest_time: f64,
}

/// Drops `mesh` `settings.drops` times in parallel batches and clusters the rests.
///
/// Deterministic for a given seed whatever the thread count: drop i's orientation depends only
/// on (seed, i), and batches are fixed slices of the sequence.
pub fn stable_poses(
    mesh: &TriMesh,
    density: f64,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> StablePoseReport {
    let body = DropBody::new(mesh, density);
    let crowd = settings.crowd.max(1);
    let batch = (settings.batch.max(1) / crowd).max(1) * crowd;
    let starts: Vec<usize> = (0..settings.drops).step_by(batch).collect();
    let outcomes: Vec<DropOutcome> = starts
        .par_iter()
        .flat_map_iter(|&first| {
            let count = batch.min(settings.drops - first);
            let out = simulate_batch(&body, settings, first, count);
            if let Some(p) = progress {
                p.inc(count as u64);
            }
            out
        })
        .collect();
    let (mass, center_of_mass) = body.mass_and_com();
    report(&outcomes, mesh, settings, mass, center_of_mass)
}

/// The report of a finished drop sequence, whichever engine dropped it: the rests clustered
/// into classes, with the leaning, rare and still-jittering drops counted apart.
pub(crate) fn report(
    outcomes: &[DropOutcome],
    mesh: &TriMesh,
    settings: &DropSettings,
    mass: f64,
    center_of_mass: nalgebra::Point3<f64>,
) -> StablePoseReport {
    let min_count = (settings.drops / 1000).max(2);
    let classes = cluster(outcomes, mesh, min_count);
    let classified: usize = classes.iter().map(|c| c.count).sum();
    let leaning = leaning(outcomes, mesh).iter().filter(|&&l| l).count();
    let settled = outcomes.len();
    let jittering = outcomes.iter().filter(|o| !o.settled).count();
    StablePoseReport {
        classes,
        drops: outcomes.len(),
        unsettled: jittering,
        leaning,
        rare: settled - classified - leaning,
        mass,
        center_of_mass,
        mean_rest_time: outcomes
            .iter()
            .filter(|o| o.settled)
            .map(|o| o.time)
            .sum::<f64>()
            / (settled - jittering).max(1) as f64,
    }
}
