//! Multi-part drops: several parts fall onto the tag board together with rapier and come to
//! rest touching the board and each other, giving physically realistic scene poses.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, RngExt};
use rapier3d_f64::math::Vector;
use rapier3d_f64::prelude::{ColliderBuilder, RigidBodyBuilder};

use super::PartModel;
use crate::convert::{
    rot_from_unit_quaternion, unit_quaternion_from_rot, vec_from_vector, vector_from_vec,
};
use crate::stable_poses::drop::{drop_world, geometric_rest_height, random_rotation};

/// A part resting in a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedPart {
    /// Index of its model in the slice given to [`drop_parts`].
    pub model: usize,
    /// Its pose in the table frame.
    #[allow(non_snake_case)]
    pub table_T_part: Isometry3<f64>,
}

/// Why a drop could not be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DropError {
    /// The region to drop parts into is not a positive, finite size.
    #[error("drop region half-size {0} m must be positive and finite")]
    BadRegion(f64),
}

/// Simulation settings of a scene drop.
const DT: f64 = 1.0 / 500.0;
const MAX_TIME: f64 = 1.5;
const REST_SPEED: f64 = 2e-3;
const REST_ANGULAR_SPEED: f64 = 0.1;
const REST_TIME: f64 = 0.04;
const BOARD_HALF: f64 = 0.105;
const BOARD_THICKNESS: f64 = 0.003;

/// One part of a drop that lies on the board in a chosen orientation and is held there while
/// the others fall onto and around it, so that a rare stable pose can be shown as often as a
/// common one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldPart {
    /// Its index among the dropped parts (in model order, as [`drop_parts`] returns them).
    pub index: usize,
    /// Its orientation on the board, `table_R_part`.
    pub rotation: UnitQuaternion<f64>,
}

/// Drops `counts[i]` copies of `models[i]` from random orientations over the square of half-size
/// `half` centred on (`cx`, `cy`) of the board, and returns their rest poses.
///
/// Parts start stacked in height so none overlap at release; they may end touching.
pub fn drop_parts(
    models: &[PartModel],
    counts: &[usize],
    centre: (f64, f64),
    half: f64,
    rng: &mut impl Rng,
) -> Result<Vec<PlacedPart>, DropError> {
    drop_parts_around(models, counts, centre, half, None, rng)
}

/// As [`drop_parts`], except that the part `held` names lies on the board in its orientation
/// (at its lowest point's height, at a random place in the square as the others) and does not
/// move while the rest fall onto and around it.
pub fn drop_parts_around(
    models: &[PartModel],
    counts: &[usize],
    (cx, cy): (f64, f64),
    half: f64,
    held: Option<HeldPart>,
    rng: &mut impl Rng,
) -> Result<Vec<PlacedPart>, DropError> {
    if !(half.is_finite() && half > 0.0) {
        return Err(DropError::BadRegion(half));
    }
    // As for the stable-pose drops: parts rest at their geometric height on a stiff table.
    let mut world = drop_world(DT);
    let board = ColliderBuilder::cuboid(BOARD_HALF, BOARD_HALF, BOARD_THICKNESS / 2.0)
        .translation(Vector::new(0.0, 0.0, -BOARD_THICKNESS / 2.0))
        .friction(0.5)
        .restitution(0.1)
        .build();
    world.colliders.insert(board);
    let table = ColliderBuilder::cuboid(2.0, 2.0, 0.05)
        .translation(Vector::new(0.0, 0.0, -BOARD_THICKNESS - 0.05))
        .friction(0.5)
        .build();
    world.colliders.insert(table);

    let mut bodies = Vec::new();
    // The falling parts start above the held one, which lies within its diameter of the board.
    let mut z = held
        .and_then(|h| model_of(counts, h.index))
        .map_or(0.0, |m| models[m].mesh.extents().norm());
    for (m, model) in models.iter().enumerate() {
        let count = counts.get(m).copied().unwrap_or(0);
        if count == 0 {
            continue;
        }
        let radius = model.mesh.extents().norm() / 2.0;
        for _ in 0..count {
            let (x, y) = (
                cx + rng.random_range(-half..=half),
                cy + rng.random_range(-half..=half),
            );
            let (builder, centre, rotation) = match held.filter(|h| h.index == bodies.len()) {
                Some(r) => {
                    let height = geometric_rest_height(&model.mesh, &r.rotation);
                    (
                        RigidBodyBuilder::fixed(),
                        Vector3::new(x, y, height),
                        r.rotation,
                    )
                }
                None => {
                    z += radius + 0.002;
                    let centre = Vector3::new(x, y, z);
                    z += radius;
                    (
                        RigidBodyBuilder::dynamic().ccd_enabled(true),
                        centre,
                        random_rotation(rng),
                    )
                }
            };
            let rb = builder
                .translation(vec_from_vector(&centre))
                .rotation(rot_from_unit_quaternion(&rotation).to_scaled_axis())
                .build();
            let h = world.bodies.insert(rb);
            // Collides by its hull, weighs as itself (`PartModel::body` says why).
            let hull = model
                .body
                .hull()
                .expect("PartModel::new refuses parts without one");
            let collider = ColliderBuilder::new(hull.clone())
                .mass_properties(model.body.mass)
                .friction(0.4)
                .restitution(0.1)
                .build();
            world
                .colliders
                .insert_with_parent(collider, h, &mut world.bodies);
            bodies.push((m, h));
        }
    }
    let mut calm = 0.0;
    let mut t = 0.0;
    while t < MAX_TIME && calm < REST_TIME {
        world.step();
        t += DT;
        let still = bodies.iter().all(|(_, h)| {
            let rb = &world.bodies[*h];
            rb.is_sleeping()
                || (rb.linvel().length() < REST_SPEED && rb.angvel().length() < REST_ANGULAR_SPEED)
        });
        calm = if still { calm + DT } else { 0.0 };
    }
    Ok(bodies
        .into_iter()
        .map(|(model, h)| {
            let rb = &world.bodies[h];
            let p = vector_from_vec(rb.translation());
            let r = unit_quaternion_from_rot(rb.rotation());
            PlacedPart {
                model,
                table_T_part: Isometry3::from_parts(Translation3::from(p), r),
            }
        })
        .collect())
}

/// The model of the `index`-th dropped part when `counts[m]` copies of each model `m` are dropped.
fn model_of(counts: &[usize], index: usize) -> Option<usize> {
    let mut first = 0;
    counts.iter().position(|&n| {
        first += n;
        index < first
    })
}
