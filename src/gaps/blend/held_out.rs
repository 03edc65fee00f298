//! What a class's weights gave on the validation that chose them ([`HeldOut`]): the figure
//! that says whether a blend earns its keep, and how far its fill is to be trusted.

use serde::{Deserialize, Serialize};

use super::Blend;
use crate::gaps::fillers::Filler;

/// Whether neither class of `v` has figures: then a report leaves them out.
pub(super) fn none(v: &[Option<HeldOut>; 2]) -> bool {
    v.iter().all(Option::is_none)
}

/// How a class's weights did on the validation that chose them: stage 1's draws in
/// groups, each group's spans filled with the weights learned on the other groups
/// (cross-fitted), beside the classic filler that did best alone on the same spans. Mean
/// distances per validation span (each span's mean over its entries), in the units of the
/// tracks the blend was learned on ([`Blend::in_units`] takes them to the data's own).
///
/// The short and the pooled long gaps' weights, and a length class's own, never do worse
/// here than their best filler alone: a blend is kept only where it beats every filler
/// alone this way. A length class on the pooled weights may, where its few spans could
/// not tell its own choice from them.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct HeldOut {
    /// The class's weights' mean distance, cross-fitted.
    pub chosen: f64,
    /// The classic filler with the least mean distance alone on the same spans.
    pub best: Filler,
    /// That filler's mean distance alone.
    pub best_alone: f64,
    /// The validation spans judged (the sum of one over each entry's gap length).
    pub spans: f64,
}

impl Blend {
    /// The held-out figures ([`HeldOut`]) multiplied by `scale`: learned on tracks
    /// normalised by `scale`, in the data's own units.
    pub fn in_units(mut self, scale: f64) -> Blend {
        let classes = self.held_out.iter_mut();
        for h in classes
            .chain(self.by_length.iter_mut().map(|c| &mut c.held_out))
            .flatten()
        {
            h.chosen *= scale;
            h.best_alone *= scale;
        }
        self
    }
}
