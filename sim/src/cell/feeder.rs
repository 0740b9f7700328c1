//! The flexible feeder: parts lying in stable poses in a rectangle of the table, placed by
//! sampling the catalog's stable-pose table (no overlap, orientation class by probability, yaw
//! uniform) or by a rapier drop; shaking re-places them, refilling adds the missing ones.

use nalgebra::Isometry3;
use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

use super::error::CellError;
use super::geometry::CellGeometry;
use crate::config::FeederSpec;
use crate::scene::PartModel;

/// Gap kept between the footprints of sampled parts, metres.
const SAMPLE_GAP: f64 = 5e-4;
/// Tries per part before the feeder counts as full.
const TRIES: usize = 2_000;

/// A part lying in the feeder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct FeederPart {
    /// Instance id, unique within an episode.
    pub instance: u32,
    /// Catalog name.
    pub part: String,
    /// True pose in the table frame.
    pub table_T_part: Isometry3<f64>,
}

/// Radius of a part's footprint on the table about its origin.
#[allow(non_snake_case)]
fn footprint_radius(geometry: &CellGeometry, name: &str, table_T_part: &Isometry3<f64>) -> f64 {
    geometry.parts.get(name).map_or(0.0, |g| {
        g.mesh
            .vertices
            .iter()
            .map(|p| (table_T_part.rotation * p).xy().coords.norm())
            .fold(0.0, f64::max)
    })
}

/// Samples `wanted` parts (name, instance) into the feeder region without overlap, avoiding the
/// parts already in `keep`.
pub fn sample(
    spec: &FeederSpec,
    geometry: &CellGeometry,
    wanted: &[(String, u32)],
    keep: &[FeederPart],
    rng: &mut impl Rng,
) -> Result<Vec<FeederPart>, CellError> {
    let mut placed: Vec<(FeederPart, f64)> = keep
        .iter()
        .map(|p| {
            (
                p.clone(),
                footprint_radius(geometry, &p.part, &p.table_T_part),
            )
        })
        .collect();
    let start = placed.len();
    let [cx, cy] = spec.center;
    let [sx, sy] = spec.size;
    for (name, instance) in wanted {
        let g = geometry.part(name)?;
        if g.stable_poses.is_empty() {
            return Err(CellError::NoStablePoses(name.clone()));
        }
        let total: f64 = g.stable_poses.iter().map(|s| s.probability.max(0.0)).sum();
        let mut ok = false;
        for _ in 0..TRIES {
            let mut pick = rng.random_range(0.0..1.0) * total;
            let mut class = &g.stable_poses[0];
            for s in &g.stable_poses {
                class = s;
                pick -= s.probability.max(0.0);
                if pick <= 0.0 {
                    break;
                }
            }
            let yaw = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            let oriented = class.table_T_part(0.0, 0.0, yaw);
            let r = footprint_radius(geometry, name, &oriented);
            let (hx, hy) = (sx / 2.0 - r, sy / 2.0 - r);
            if hx <= 0.0 || hy <= 0.0 {
                break;
            }
            let x = cx + rng.random_range(-hx..hx);
            let y = cy + rng.random_range(-hy..hy);
            let free = placed.iter().all(|(p, pr)| {
                let d = p.table_T_part.translation.vector.xy() - nalgebra::Vector2::new(x, y);
                d.norm() >= r + pr + SAMPLE_GAP
            });
            if free {
                let table_T_part = class.table_T_part(x, y, yaw);
                placed.push((
                    FeederPart {
                        instance: *instance,
                        part: name.clone(),
                        table_T_part,
                    },
                    r,
                ));
                ok = true;
                break;
            }
        }
        if !ok {
            return Err(CellError::FeederFull {
                placed: placed.len() - start,
                wanted: wanted.len(),
            });
        }
    }
    Ok(placed.into_iter().skip(start).map(|(p, _)| p).collect())
}

/// Drops the `wanted` parts into the feeder with rapier (the scene module's multi-part drop over
/// the square inscribed in the region); `models` holds one [`PartModel`] per catalog name.
pub fn drop(
    spec: &FeederSpec,
    models: &[PartModel],
    wanted: &[(String, u32)],
    rng: &mut impl Rng,
) -> Result<Vec<FeederPart>, CellError> {
    let counts: Vec<usize> = models
        .iter()
        .map(|m| wanted.iter().filter(|(n, _)| *n == m.name).count())
        .collect();
    let half = spec.size[0].min(spec.size[1]) / 2.0;
    let placed =
        crate::scene::drop_parts(models, &counts, (spec.center[0], spec.center[1]), half, rng)
            .map_err(|e| CellError::Drop(e.to_string()))?;
    // drop_parts returns bodies model by model; hand out the wanted instance ids in that order.
    let mut ids: Vec<std::collections::VecDeque<u32>> = models
        .iter()
        .map(|m| {
            wanted
                .iter()
                .filter(|(n, _)| *n == m.name)
                .map(|(_, i)| *i)
                .collect()
        })
        .collect();
    let mut out = Vec::new();
    for p in placed {
        let Some(instance) = ids.get_mut(p.model).and_then(|q| q.pop_front()) else {
            continue;
        };
        out.push(FeederPart {
            instance,
            part: models[p.model].name.clone(),
            table_T_part: p.table_T_part,
        });
    }
    Ok(out)
}
