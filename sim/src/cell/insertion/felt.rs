//! What the simulated cell's wrist feels of a held part pressed into its target: where the part
//! stops and the wrist's load there, from the scenario's scorer.
//!
//! With the analytic scorer the stop is the capture model's end height and the load a push
//! along the insertion axis. With a contact engine (rapier or MuJoCo) it is that engine's
//! simulated push for the part's present misalignment: the same call the scorer makes when the
//! part is released, so a guarded move stops where the engine's part stops, the wrist reads the
//! engine's load there (its lateral force and moment, scaled to the press), and the insertion is
//! then scored by that very push. One push per misalignment: [`FeltStops`] keeps the last few.

use std::sync::{Arc, Mutex};

use nalgebra::Isometry3;

use super::Scored;
use super::wrist::WristWrench;

/// Two start poses differing laterally by less than this (insertion frame x, y; metres) are the
/// same misalignment: the engines start every push from the same clear height whatever the
/// start pose's, and along a guarded descent the part's lateral error drifts by a few microns
/// (the planned descent runs about a milliradian off the true insertion axis: 1 µm per 0.9 mm
/// of height, measured), well under the arm's repeatability (UR5e ±30 µm); the push simulated
/// where the part first came down into its target stands for the whole descent. Spiral probes
/// and retries step by tenths of a millimetre, so each is a push of its own.
pub const SAME_LATERAL: f64 = 1e-5;
/// Two start poses whose rotations differ by less than this (radians) are the same
/// misalignment.
pub const SAME_ANGLE: f64 = 1e-5;
/// Misalignments [`FeltStops`] remembers (the oldest goes first).
const REMEMBERED: usize = 16;

/// Where a held part pressed into its target stops, and what the wrist feels there.
#[derive(Debug, Clone, PartialEq)]
pub struct FeltStop {
    /// Height of the stop above seated, metres (the scorer's end height).
    pub height: f64,
    /// The wrist's load at the end of the engine's push (insertion frame, at the compliance
    /// centre); none from the analytic model.
    pub wrench: Option<WristWrench>,
    /// The engine's scored push (the part's verdict for this misalignment); none from the
    /// analytic model, which is scored afresh.
    pub scored: Option<Scored>,
}

/// Which held part, going into which step's target among which placed parts, from which start
/// pose (insertion frame).
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(non_snake_case)]
pub struct FeltKey {
    /// The held instance.
    pub instance: u32,
    /// The assembly step.
    pub step: usize,
    /// Parts placed so far (the receivers around the target).
    pub placed: usize,
    /// The held part's pose in the insertion frame.
    pub ins_T_part: Isometry3<f64>,
}

impl FeltKey {
    /// Whether `other` is the same part, target and misalignment (its height aside).
    pub fn same(&self, other: &FeltKey) -> bool {
        let (a, b) = (&self.ins_T_part, &other.ins_T_part);
        let d = a.translation.vector - b.translation.vector;
        self.instance == other.instance
            && self.step == other.step
            && self.placed == other.placed
            && d.x.abs() < SAME_LATERAL
            && d.y.abs() < SAME_LATERAL
            && 2.0 * (a.rotation.inverse() * b.rotation).imag().norm() < SAME_ANGLE
    }
}

/// The engine pushes already simulated this episode, by misalignment. Shared by the cell's
/// clones' readers through a lock, so the contact model can be asked from `&self`.
#[derive(Debug, Default)]
pub struct FeltStops(Mutex<Vec<(FeltKey, Arc<FeltStop>)>>);

impl Clone for FeltStops {
    fn clone(&self) -> Self {
        FeltStops(Mutex::new(self.entries().clone()))
    }
}

impl FeltStops {
    fn entries(&self) -> std::sync::MutexGuard<'_, Vec<(FeltKey, Arc<FeltStop>)>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The stop of the same misalignment as `key`, if simulated.
    pub fn get(&self, key: &FeltKey) -> Option<Arc<FeltStop>> {
        self.entries()
            .iter()
            .rev()
            .find(|(k, _)| k.same(key))
            .map(|(_, s)| s.clone())
    }

    /// Remembers `stop` for `key`'s misalignment.
    pub fn insert(&self, key: FeltKey, stop: Arc<FeltStop>) {
        let mut e = self.entries();
        if e.len() >= REMEMBERED {
            e.remove(0);
        }
        e.push((key, stop));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    fn key(x: f64, z: f64, yaw: f64) -> FeltKey {
        FeltKey {
            instance: 3,
            step: 1,
            placed: 1,
            ins_T_part: Isometry3::from_parts(
                nalgebra::Translation3::new(x, 0.0001, z),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
            ),
        }
    }

    #[test]
    fn a_misalignment_is_the_same_at_any_height_within_ten_microns_or_microradians() {
        let a = key(0.0001, 0.002, 0.001);
        assert!(a.same(&key(0.0001, -0.0005, 0.001)));
        assert!(a.same(&key(0.0001 + 4e-6, 0.0, 0.001 + 4e-6)));
        assert!(!a.same(&key(0.0001 + 2e-5, 0.002, 0.001)));
        assert!(!a.same(&key(0.0001, 0.002, 0.001 + 2e-5)));
        assert!(!a.same(&FeltKey { placed: 2, ..a }));
        assert!(!a.same(&FeltKey { instance: 4, ..a }));
        let stops = FeltStops::default();
        let stop = Arc::new(FeltStop {
            height: 0.0012,
            wrench: None,
            scored: None,
        });
        stops.insert(a, stop.clone());
        assert_eq!(stops.get(&key(0.0001, 0.0, 0.001)), Some(stop));
        assert_eq!(stops.get(&key(0.0002, 0.0, 0.001)), None);
        for k in 0..REMEMBERED {
            stops.insert(
                key(f64::from(k as u32) * 1e-4 + 0.01, 0.0, 0.0),
                Arc::new(FeltStop {
                    height: 0.0,
                    wrench: None,
                    scored: None,
                }),
            );
        }
        assert_eq!(stops.get(&a), None, "the oldest is forgotten");
    }
}
