//! Grouping rest orientations into stable-pose classes by the face the part rests on.

use nalgebra::Vector3;
use perception::part::{StablePose, TriMesh};

use super::drop::{DropOutcome, geometric_rest_height};

/// Rest orientations whose table normals (in the part frame) are within this angle share a class.
pub const CLASS_ANGLE_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// A stable-pose class with the evidence behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseClass {
    /// The class as stored in the catalog.
    pub pose: StablePose,
    /// Number of drops that rested in it.
    pub count: usize,
    /// Of those, drops still jittering in place at the time limit.
    pub jittering: usize,
    /// Largest |physics height − geometric height| over its settled drops, metres.
    pub max_height_error: f64,
    /// Largest angle between a member's table normal and the class normal, radians.
    pub spread: f64,
}

/// Clusters outcomes by resting face; classes with fewer than `min_count` drops are left out
/// (their drops still count in the denominator). Drops still jittering in place at the time limit
/// count by their face; only settled drops enter the physics-vs-geometry height comparison.
/// Most probable first; ties by direction.
pub fn cluster(outcomes: &[DropOutcome], mesh: &TriMesh, min_count: usize) -> Vec<PoseClass> {
    let settled: Vec<&DropOutcome> = outcomes.iter().collect();
    let total = settled.len().max(1) as f64;
    // Greedy leader clustering in drop order (deterministic), then one re-assignment pass to the
    // nearest final centre, so the result does not depend on which member came first.
    let ups: Vec<Vector3<f64>> = settled
        .iter()
        .map(|o| o.rotation.inverse() * Vector3::z())
        .collect();
    let mut centres: Vec<Vector3<f64>> = Vec::new();
    for up in &ups {
        if !centres.iter().any(|c| c.angle(up) < CLASS_ANGLE_RAD) {
            centres.push(*up);
        }
    }
    for _ in 0..2 {
        let mut sums = vec![Vector3::zeros(); centres.len()];
        for up in &ups {
            sums[nearest(&centres, up)] += up;
        }
        centres = sums
            .iter()
            .zip(&centres)
            .map(|(s, c)| s.try_normalize(1e-12).unwrap_or(*c))
            .collect();
    }
    // A resting class is a face of the convex hull: snap each centre to the nearest hull face's
    // inward normal, so canonical rotations and rest heights are exact, not averaged jitter.
    let faces = hull_up_directions(mesh);
    for c in centres.iter_mut() {
        if let Some(f) = faces.iter().max_by(|a, b| a.dot(c).total_cmp(&b.dot(c)))
            && f.angle(c) < CLASS_ANGLE_RAD
        {
            *c = *f;
        }
    }
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); centres.len()];
    for (i, up) in ups.iter().enumerate() {
        members[nearest(&centres, up)].push(i);
    }
    let mut classes: Vec<PoseClass> = centres
        .iter()
        .zip(&members)
        .filter(|(_, m)| m.len() >= min_count.max(1))
        .map(|(centre, m)| {
            let rotation = StablePose::canonical_rotation(centre);
            let rest_height = geometric_rest_height(mesh, &rotation);
            let max_height_error = m
                .iter()
                .filter(|&&i| settled[i].settled)
                .map(|&i| {
                    (settled[i].height - geometric_rest_height(mesh, &settled[i].rotation)).abs()
                })
                .fold(0.0, f64::max);
            let spread = m.iter().map(|&i| ups[i].angle(centre)).fold(0.0, f64::max);
            PoseClass {
                pose: StablePose {
                    name: String::new(),
                    probability: m.len() as f64 / total,
                    up_in_part: round_vec(centre),
                    rotation: round_vec(&rotation.scaled_axis()),
                    rest_height: round(rest_height),
                },
                count: m.len(),
                jittering: m.iter().filter(|&&i| !settled[i].settled).count(),
                max_height_error,
                spread,
            }
        })
        .collect();
    classes.sort_by(|a, b| {
        b.count.cmp(&a.count).then_with(|| {
            a.pose
                .up_in_part
                .partial_cmp(&b.pose.up_in_part)
                .unwrap_or(std::cmp::Ordering::Equal)
        })
    });
    for (i, c) in classes.iter_mut().enumerate() {
        c.pose.name = StablePose::name_for(&Vector3::from(c.pose.up_in_part), i);
        c.pose.probability = round(c.pose.probability);
    }
    classes
}

/// For each face of the mesh's convex hull, the table-up direction (in the part frame) of the
/// part resting on it: the face's inward normal.
fn hull_up_directions(mesh: &TriMesh) -> Vec<Vector3<f64>> {
    let points: Vec<_> = mesh
        .vertices
        .iter()
        .map(crate::convert::vec_from_point)
        .collect();
    let (verts, tris) = parry3d_f64::transformation::convex_hull(&points);
    tris.iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|i| crate::convert::vector_from_vec(verts[i as usize]));
            (b - a).cross(&(c - a)).try_normalize(1e-18).map(|n| -n)
        })
        .collect()
}

fn nearest(centres: &[Vector3<f64>], up: &Vector3<f64>) -> usize {
    centres
        .iter()
        .enumerate()
        .map(|(i, c)| (i, c.dot(up)))
        .fold(
            (0, f64::NEG_INFINITY),
            |acc, x| if x.1 > acc.1 { x } else { acc },
        )
        .0
}

/// Rounds to 1e-9 (a nanometre, a nanoradian) so catalogs are stable text across platforms.
fn round(x: f64) -> f64 {
    (x * 1e9).round() / 1e9 + 0.0
}

fn round_vec(v: &Vector3<f64>) -> [f64; 3] {
    [round(v.x), round(v.y), round(v.z)]
}
