//! How often insertion scorers agree near the capture boundary, where a verdict is hardest: the
//! check to run after changing a part, a clearance or a lead-in, before trusting analytic
//! success rates (the rapier contact simulation is the reference), and where two independent
//! contact engines (rapier and MuJoCo) disagree, the cases that show where a success rate is
//! fragile.

use std::collections::BTreeMap;
use std::sync::Arc;

use nalgebra::{Isometry3, Vector2};
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use super::{
    InsertionCase, InsertionScorer, Mating, PoseError, ReceiverPart, ScorerError, Verdict,
};
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

/// Sample `k` of a seeded draw around the capture boundaries: step `k` mod the steps, with a
/// [`boundary_misalignment`] from stream `k` of `seed` (the same seed, the same cases, however
/// the samples are split between threads). `steps` must not be empty.
pub fn boundary_case<'a>(
    steps: &'a [StepGeometry<'a>],
    seed: u64,
    k: usize,
) -> (usize, InsertionCase<'a>) {
    let i = k % steps.len();
    let s = &steps[i];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(k as u64);
    let case = InsertionCase {
        mating: &s.mating,
        held: s.held,
        receivers: &s.receivers,
        ins_T_part: boundary_misalignment(&s.mating, &mut rng),
    };
    (i, case)
}

/// One engine's outcome of a sample.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EngineOutcome {
    /// The scorer's name.
    pub engine: String,
    /// Its verdict.
    pub verdict: Verdict,
    /// Where it left the part.
    pub end: PoseError,
}

/// One sample on which the scorers disagree: the start and every engine's verdict and end.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Disagreement {
    /// Index of the assembly step.
    pub step: usize,
    /// Sample number (reproduces the draw with the same seed).
    pub sample: usize,
    /// The start misalignment.
    pub start: PoseError,
    /// Each engine's outcome, in the order the engines were given.
    pub outcomes: Vec<EngineOutcome>,
}

impl Disagreement {
    /// The verdict of `engine`, if it took part.
    pub fn verdict(&self, engine: &str) -> Option<Verdict> {
        self.outcomes
            .iter()
            .find(|o| o.engine == engine)
            .map(|o| o.verdict)
    }
}

/// How often two engines disagree on one step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairAgreement {
    /// The first engine.
    pub a: String,
    /// The second engine.
    pub b: String,
    /// Samples on which their verdicts differ.
    pub disagreements: usize,
}

/// Agreement counts of one step.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StepAgreement {
    /// The held part.
    pub part: String,
    /// Samples drawn for this step.
    pub samples: usize,
    /// Samples on which not every engine gives the same verdict.
    pub disagreements: usize,
    /// Samples each engine seats, by engine name.
    pub seated: BTreeMap<String, usize>,
    /// Every pair of engines, in the order given.
    pub pairs: Vec<PairAgreement>,
}

impl StepAgreement {
    /// Fraction of this step's samples on which engines `a` and `b` agree (1 when either is
    /// absent or there are no samples).
    pub fn pair_rate(&self, a: &str, b: &str) -> f64 {
        let Some(p) = self
            .pairs
            .iter()
            .find(|p| (p.a == a && p.b == b) || (p.a == b && p.b == a))
        else {
            return 1.0;
        };
        if self.samples == 0 {
            return 1.0;
        }
        1.0 - p.disagreements as f64 / self.samples as f64
    }
}

/// The comparison of the scorers over all steps.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Agreement {
    /// The engines compared, in the order given.
    pub engines: Vec<String>,
    /// Per step, in assembly order.
    pub steps: Vec<StepAgreement>,
    /// Every sample on which the engines do not all agree, in sample order.
    pub disagreements: Vec<Disagreement>,
}

impl Agreement {
    /// All samples.
    pub fn samples(&self) -> usize {
        self.steps.iter().map(|s| s.samples).sum()
    }

    /// Fraction of samples on which every engine gives the same verdict.
    pub fn rate(&self) -> f64 {
        let n = self.samples();
        if n == 0 {
            return 1.0;
        }
        1.0 - self.disagreements.len() as f64 / n as f64
    }

    /// Fraction of all samples on which engines `a` and `b` agree.
    pub fn pair_rate(&self, a: &str, b: &str) -> f64 {
        let n = self.samples();
        if n == 0 {
            return 1.0;
        }
        let differ = self
            .disagreements
            .iter()
            .filter(|d| d.verdict(a) != d.verdict(b))
            .count();
        1.0 - differ as f64 / n as f64
    }
}

/// Scores `samples` boundary misalignments with every scorer, cycling through the steps; sample
/// `k` draws from its own stream of `seed`, so the result does not depend on the thread count.
pub fn compare_scorers(
    steps: &[StepGeometry<'_>],
    samples: usize,
    seed: u64,
    scorers: &[Arc<dyn InsertionScorer>],
) -> Result<Agreement, ScorerError> {
    let names: Vec<String> = scorers.iter().map(|s| s.name().to_string()).collect();
    let pairs: Vec<(usize, usize)> = (0..scorers.len())
        .flat_map(|a| (a + 1..scorers.len()).map(move |b| (a, b)))
        .collect();
    let mut out = Agreement {
        engines: names.clone(),
        steps: steps
            .iter()
            .map(|s| StepAgreement {
                part: s.mating.part.clone(),
                seated: names.iter().map(|n| (n.clone(), 0)).collect(),
                pairs: pairs
                    .iter()
                    .map(|&(a, b)| PairAgreement {
                        a: names[a].clone(),
                        b: names[b].clone(),
                        disagreements: 0,
                    })
                    .collect(),
                ..StepAgreement::default()
            })
            .collect(),
        disagreements: Vec::new(),
    };
    if steps.is_empty() {
        return Ok(out);
    }
    let scored: Vec<(usize, PoseError, Vec<EngineOutcome>)> = (0..samples)
        .into_par_iter()
        .map(|k| {
            let (i, case) = boundary_case(steps, seed, k);
            let start = steps[i].mating.pose_error(&case.ins_T_part);
            let outcomes = scorers
                .iter()
                .map(|sc| {
                    sc.score(&case).map(|r| EngineOutcome {
                        engine: sc.name().to_string(),
                        verdict: r.result.verdict,
                        end: r.result.end,
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok((i, start, outcomes))
        })
        .collect::<Result<_, ScorerError>>()?;
    for (k, (i, start, outcomes)) in scored.into_iter().enumerate() {
        let st = &mut out.steps[i];
        st.samples += 1;
        for o in &outcomes {
            if o.verdict == Verdict::Seated {
                *st.seated.entry(o.engine.clone()).or_default() += 1;
            }
        }
        for (p, &(a, b)) in st.pairs.iter_mut().zip(&pairs) {
            p.disagreements += usize::from(outcomes[a].verdict != outcomes[b].verdict);
        }
        if outcomes.iter().any(|o| o.verdict != outcomes[0].verdict) {
            st.disagreements += 1;
            out.disagreements.push(Disagreement {
                step: i,
                sample: k,
                start,
                outcomes,
            });
        }
    }
    Ok(out)
}
