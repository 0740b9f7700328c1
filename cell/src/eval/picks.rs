//! The picks the cell would make from an evaluated frame, told apart by what each picked part
//! turned out to be.

use perception::metrics::PoseErrors;
use serde::{Deserialize, Serialize};

use super::{DetectionRecord, TruthRecord};

/// The poses the cell would pick (confidence at least
/// [`super::EvalOptions::pick_confidence`], in a stable pose it has a grasp for, and with a
/// finger check, room for the open fingers: [`super::EvalOptions::finger_margin`]), over every
/// detection and not only the resting parts', by what each was. A pick that is not
/// assembly-grade costs the cell a failed insertion or a wasted grasp.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Picks {
    /// All of them.
    pub picks: usize,
    /// A resting part in that stable pose, within [`ASSEMBLY_GRADE_MM`] and
    /// [`ASSEMBLY_GRADE_DEG`].
    pub assembly_grade: usize,
    /// A resting part in that stable pose, further off.
    pub off: usize,
    /// A resting part in another stable pose.
    pub wrong_stable_pose: usize,
    /// A part leaning on or lying on another part.
    pub not_resting: usize,
    /// A detection matched to no part.
    pub unmatched: usize,
    /// Poses confident enough and in a stable pose with a grasp whose open fingers would come
    /// nearer another part than the finger margin: not picks.
    #[serde(default)]
    pub crowded: usize,
}

/// Lateral error (camera x, y) of a pose that the cell's insertions take with margin, mm: the
/// learned scenario's capture bands are 0.145 mm (insert mold, top shell) to 0.33 mm.
pub const ASSEMBLY_GRADE_MM: f64 = 0.1;
/// Angle error of an assembly-grade pose, degrees.
pub const ASSEMBLY_GRADE_DEG: f64 = 1.0;

/// What the cell would make of a detection at a pick bar ([`Picks::judge`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Pickable {
    /// Not confident enough, in no stable pose with a grasp, or a barely visible part.
    No,
    /// A pick, but the open fingers would come too near another part.
    Crowded,
    /// A pick.
    Yes,
}

impl Picks {
    /// Whether the cell would pick detection `d` (against its frame's `truths`) at confidence
    /// `pick_at` with fingers that need `finger_margin` metres of room (unchecked when `None`);
    /// picks of ignored (barely visible) instances are not counted. The one rule for every pick
    /// count: a crowded one goes to [`Self::crowded`], a pick to [`Self::add`].
    pub(super) fn judge(
        d: &DetectionRecord,
        truths: &[TruthRecord],
        pick_at: f64,
        finger_margin: Option<f64>,
    ) -> Pickable {
        let confident = d.confidence.is_some_and(|c| c >= pick_at);
        let ignored = d
            .truth
            .and_then(|t| truths.get(t))
            .is_some_and(|t| t.ignored);
        if !(d.graspable && d.stable_pose.is_some() && confident) || ignored {
            return Pickable::No;
        }
        match (finger_margin, d.finger_clearance_mm) {
            (Some(margin), Some(clearance)) if clearance < margin * 1e3 => Pickable::Crowded,
            _ => Pickable::Yes,
        }
    }

    /// Counts pick `d` by what the picked part turned out to be.
    pub(super) fn add(&mut self, d: &DetectionRecord, truths: &[TruthRecord]) {
        self.picks += 1;
        let slot = match (d.truth.and_then(|t| truths.get(t)), d.refined) {
            (None, _) => &mut self.unmatched,
            (Some(t), _) if !t.resting => &mut self.not_resting,
            (Some(_), _) if d.stable_pose != d.true_stable_pose => &mut self.wrong_stable_pose,
            (Some(_), Some(e)) if is_assembly_grade(&e, d.refined_flip_deg) => {
                &mut self.assembly_grade
            }
            (Some(_), _) => &mut self.off,
        };
        *slot += 1;
    }
}

/// Whether refined errors `e` (with the angle to the nearest symmetric twin, `flip_deg`) are
/// within [`ASSEMBLY_GRADE_MM`] and [`ASSEMBLY_GRADE_DEG`].
pub(super) fn is_assembly_grade(e: &PoseErrors, flip_deg: Option<f64>) -> bool {
    e.x_mm.hypot(e.y_mm) <= ASSEMBLY_GRADE_MM
        && flip_deg.unwrap_or(e.angle_deg) <= ASSEMBLY_GRADE_DEG
}
