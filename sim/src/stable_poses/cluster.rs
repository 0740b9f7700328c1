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
    /// Largest |physics height − geometric height| over its drops that came to rest in physics
    /// (not ended early on their face), metres.
    pub max_height_error: f64,
    /// Largest angle between a member's table normal and the class normal, radians.
    pub spread: f64,
}

/// Clusters outcomes by resting face; classes with fewer than `min_count` drops and drops
/// resting on a neighbour ([`leaning`]) are left out (their drops still count in the
/// denominator). Drops still jittering in place at the time limit
/// count by their face; only settled drops enter the physics-vs-geometry height comparison.
/// Most probable first; ties by direction.
pub fn cluster(outcomes: &[DropOutcome], mesh: &TriMesh, min_count: usize) -> Vec<PoseClass> {
    let total = outcomes.len().max(1) as f64;
    let faces = hull_up_directions(mesh);
    let on_table: Vec<&DropOutcome> = outcomes
        .iter()
        .filter(|o| !leans(o, mesh, &faces))
        .collect();
    // Greedy leader clustering in drop order (deterministic), then one re-assignment pass to the
    // nearest final centre, so the result does not depend on which member came first.
    let ups: Vec<Vector3<f64>> = on_table
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
    for c in centres.iter_mut() {
        if let Some(f) = faces.iter().max_by(|a, b| a.dot(c).total_cmp(&b.dot(c)))
            && f.angle(c) < CLASS_ANGLE_RAD
        {
            *c = *f;
        }
    }
    let centres = merge_close(centres, &ups);
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
                .filter(|&&i| on_table[i].settled && !on_table[i].trapped)
                .map(|&i| {
                    (on_table[i].height - geometric_rest_height(mesh, &on_table[i].rotation)).abs()
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
                jittering: m.iter().filter(|&&i| !on_table[i].settled).count(),
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
    for c in classes.iter_mut() {
        c.pose.probability = round(c.pose.probability);
    }
    name_uniquely(&mut classes);
    classes
}

/// Merges centres within [`CLASS_ANGLE_RAD`] of each other (the mean shift and the snap onto
/// nearly coplanar hull faces can bring two within a fraction of a degree), keeping the one
/// nearest to more rest directions.
fn merge_close(centres: Vec<Vector3<f64>>, ups: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let mut counts = vec![0usize; centres.len()];
    for up in ups {
        counts[nearest(&centres, up)] += 1;
    }
    let mut order: Vec<usize> = (0..centres.len()).collect();
    order.sort_by(|&a, &b| counts[b].cmp(&counts[a]).then(a.cmp(&b)));
    let mut kept: Vec<Vector3<f64>> = Vec::with_capacity(centres.len());
    for i in order {
        if kept.iter().all(|k| k.angle(&centres[i]) >= CLASS_ANGLE_RAD) {
            kept.push(centres[i]);
        }
    }
    kept
}

/// Names each class from its direction ([`StablePose::name_for`]); where two directions get the
/// same name, the one with the lexicographically larger direction gets "#2" (then "#3", ...),
/// so names are unique and do not depend on the drops' order or the classes' probabilities.
fn name_uniquely(classes: &mut [PoseClass]) {
    let mut order: Vec<usize> = (0..classes.len()).collect();
    let key = |c: &PoseClass| {
        (
            StablePose::name_for(&Vector3::from(c.pose.up_in_part)),
            c.pose.up_in_part,
        )
    };
    order.sort_by(|&a, &b| {
        let (na, ua) = key(&classes[a]);
        let (nb, ub) = key(&classes[b]);
        na.cmp(&nb)
            .then_with(|| ua.partial_cmp(&ub).unwrap_or(std::cmp::Ordering::Equal))
    });
    let mut previous: Option<(String, usize)> = None;
    for i in order {
        let name = key(&classes[i]).0;
        let n = match &previous {
            Some((p, n)) if *p == name => n + 1,
            _ => 1,
        };
        classes[i].pose.name = if n == 1 {
            name.clone()
        } else {
            format!("{name}#{n}")
        };
        previous = Some((name, n));
    }
}

/// A part resting this much higher than its lowest point allows lies on a neighbour, metres:
/// far above the contact's micrometres of play, far below any part's wall thickness.
pub const LEAN_HEIGHT: f64 = 50e-6;

/// For each outcome, whether it came to rest on a neighbour (crowded drops) rather than on the
/// table: it rests higher than its geometry allows by [`LEAN_HEIGHT`], or it is tilted off
/// every face of its convex hull by more than [`CLASS_ANGLE_RAD`] (a single part on a table
/// always ends on a hull face).
pub fn leaning(outcomes: &[DropOutcome], mesh: &TriMesh) -> Vec<bool> {
    let faces = hull_up_directions(mesh);
    outcomes.iter().map(|o| leans(o, mesh, &faces)).collect()
}

fn leans(o: &DropOutcome, mesh: &TriMesh, faces: &[Vector3<f64>]) -> bool {
    let raised = o.height - geometric_rest_height(mesh, &o.rotation) > LEAN_HEIGHT;
    let up = o.rotation.inverse() * Vector3::z();
    let off_faces = faces.iter().all(|f| f.angle(&up) > CLASS_ANGLE_RAD);
    raised || off_faces
}

/// For each face of the mesh's convex hull, the table-up direction (in the part frame) of the
/// part resting on it: the face's inward normal.
fn hull_up_directions(mesh: &TriMesh) -> Vec<Vector3<f64>> {
    let points: Vec<_> = mesh
        .vertices
        .iter()
        .map(crate::convert::vec_from_point)
        .collect();
    let (verts, tris) = perception::part::convex_hull(&points);
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
