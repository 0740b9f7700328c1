//! How often the fast analytic scorer agrees with the contact simulation near the capture
//! boundary, where a verdict is hardest: the check to run after changing a part, a clearance or
//! a lead-in, before trusting analytic success rates (the contact simulation is the reference).

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Vector2};
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use super::contact::{self, ContactSettings};
use super::{Mating, PoseError, ReceiverPart, Verdict, analytic};
use crate::cell::geometry::{CellGeometry, PartGeometry, destination_part};
use crate::config::AssemblyStep;

/// One assembly step's held part, what it mates with, and their mating geometry.
#[derive(Debug, Clone)]
pub struct StepGeometry<'a> {
    /// The step's mating geometry.
    pub mating: Mating,
    /// The held part.
    pub held: &'a PartGeometry,
    /// What it goes into (first) and everything already in place around it, seated nominally.
    pub receivers: Vec<ReceiverPart<'a>>,
}

impl<'a> StepGeometry<'a> {
    /// Step `index` of `steps` with every earlier part seated exactly at its target; `None`
    /// when a part or the destination is missing from `geometry`.
    #[allow(non_snake_case)]
    pub fn nominal(
        geometry: &'a CellGeometry,
        steps: &[AssemblyStep],
        index: usize,
    ) -> Option<Self> {
        let step = steps.get(index)?;
        // Every part placed before this step, in the fixture frame.
        let mut fixture_T: BTreeMap<&str, Isometry3<f64>> = BTreeMap::new();
        for s in &steps[..index] {
            let dest = match destination_part(s) {
                None => Isometry3::identity(),
                Some(p) => *fixture_T.get(p)?,
            };
            fixture_T.insert(&s.part, dest * s.target.isometry());
        }
        let fixture = geometry.parts.get(&geometry.fixture_part)?;
        let destination_T_fixture = match destination_part(step) {
            None => Isometry3::identity(),
            Some(p) => fixture_T.get(p)?.inverse(),
        };
        let mut receivers = Vec::new();
        if let Some(p) = destination_part(step) {
            receivers.push(ReceiverPart {
                geometry: geometry.parts.get(p)?,
                destination_T_part: Isometry3::identity(),
            });
        }
        receivers.push(ReceiverPart {
            geometry: fixture,
            destination_T_part: destination_T_fixture,
        });
        for (name, f_T_part) in &fixture_T {
            if Some(*name) != destination_part(step) {
                receivers.push(ReceiverPart {
                    geometry: geometry.parts.get(*name)?,
                    destination_T_part: destination_T_fixture * f_T_part,
                });
            }
        }
        let held = geometry.parts.get(&step.part)?;
        Some(Self {
            mating: Mating::new(step, held, &receivers[..1]),
            held,
            receivers,
        })
    }
}

/// A misalignment near the capture boundary: lateral 0.5–1.5 × the capture half-width in a
/// random direction, yaw within ±2 mrad, tilt up to 4 mrad toward a random direction (the
/// insertion frame pose of the held part, as [`Mating::pose_with_error`] makes it).
pub fn boundary_misalignment(mating: &Mating, rng: &mut impl Rng) -> Isometry3<f64> {
    let angle = rng.random_range(0.0..std::f64::consts::TAU);
    let r = mating.capture() * rng.random_range(0.5..1.5);
    let lateral = Vector2::new(angle.cos(), angle.sin()) * r;
    let yaw = rng.random_range(-2e-3..2e-3);
    let tilt = rng.random_range(0.0..4e-3);
    let toward = rng.random_range(0.0..std::f64::consts::TAU);
    mating.pose_with_error(
        lateral,
        0.0,
        yaw,
        tilt,
        Vector2::new(toward.cos(), toward.sin()),
    )
}

/// One sample on which the scorers disagree.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Disagreement {
    /// Index of the assembly step.
    pub step: usize,
    /// Sample number (reproduces the draw with the same seed).
    pub sample: usize,
    /// The start misalignment.
    pub start: PoseError,
    /// The analytic verdict.
    pub analytic: Verdict,
    /// The contact simulation's verdict (the reference).
    pub contact: Verdict,
}

/// Agreement counts of one step.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StepAgreement {
    /// The held part.
    pub part: String,
    /// Samples drawn for this step.
    pub samples: usize,
    /// Samples with different verdicts.
    pub disagreements: usize,
    /// Samples the analytic scorer seats.
    pub analytic_seated: usize,
    /// Samples the contact simulation seats.
    pub contact_seated: usize,
}

/// The comparison of the two scorers over all steps.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Agreement {
    /// Per step, in assembly order.
    pub steps: Vec<StepAgreement>,
    /// Every disagreeing sample, in sample order.
    pub disagreements: Vec<Disagreement>,
}

impl Agreement {
    /// All samples.
    pub fn samples(&self) -> usize {
        self.steps.iter().map(|s| s.samples).sum()
    }

    /// Fraction of samples on which the verdicts (seated, jammed, missed) are the same.
    pub fn rate(&self) -> f64 {
        let n = self.samples();
        if n == 0 {
            return 1.0;
        }
        1.0 - self.disagreements.len() as f64 / n as f64
    }
}

/// Scores `samples` boundary misalignments with both scorers, cycling through the steps; sample
/// `k` draws from its own stream of `seed`, so the result does not depend on the thread count.
pub fn compare_scorers(
    steps: &[StepGeometry<'_>],
    samples: usize,
    seed: u64,
    settings: &ContactSettings,
) -> Agreement {
    let mut out = Agreement {
        steps: steps
            .iter()
            .map(|s| StepAgreement {
                part: s.mating.part.clone(),
                ..StepAgreement::default()
            })
            .collect(),
        disagreements: Vec::new(),
    };
    if steps.is_empty() {
        return out;
    }
    let verdicts: Vec<(usize, PoseError, Verdict, Verdict)> = (0..samples)
        .into_par_iter()
        .map(|k| {
            let i = k % steps.len();
            let s = &steps[i];
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(k as u64);
            let pose = boundary_misalignment(&s.mating, &mut rng);
            let a = analytic::score(&s.mating, &pose);
            let c = contact::simulate(&s.mating, s.held, &s.receivers, &pose, settings);
            (i, a.start, a.verdict, c.result.verdict)
        })
        .collect();
    for (k, (i, start, a, c)) in verdicts.into_iter().enumerate() {
        let st = &mut out.steps[i];
        st.samples += 1;
        st.analytic_seated += usize::from(a == Verdict::Seated);
        st.contact_seated += usize::from(c == Verdict::Seated);
        if a != c {
            st.disagreements += 1;
            out.disagreements.push(Disagreement {
                step: i,
                sample: k,
                start,
                analytic: a,
                contact: c,
            });
        }
    }
    out
}
