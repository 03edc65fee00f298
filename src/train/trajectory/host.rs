//! The trajectory fit's steps as host buffers, for the fused step
//! ([`crate::train::fused`]): the same rows and `L_H` samples, drawn from the same random
//! stream in the same order as the composed step draws them, gathered on the host instead
//! of uploaded.

use rand_chacha::ChaCha8Rng;

use super::TrajectoryObjective;
use crate::train::fused::HostBatch;

/// Each step's `(start, len)` in the iteration's rows.
type Spans = Vec<(usize, usize)>;

/// One iteration's draws, in step order: each step's rows (when a subset is drawn) and its
/// `L_H` samples (when `L_H` has its own), and the next step's index.
#[derive(Debug, Default)]
pub(super) struct HostDraws {
    pub(super) rows: Option<(Vec<i64>, Spans)>,
    pub(super) samples: Option<(Vec<f32>, usize)>,
    next: usize,
}

impl TrajectoryObjective<'_> {
    /// Why the fused step cannot take this objective's steps, if it cannot.
    pub(super) fn host_refusal(&self) -> Option<&'static str> {
        if self.learned.is_some() {
            return Some(
                "it does not learn the canonical positions of tracks unseen in the reference frame",
            );
        }
        None
    }

    /// One iteration's draws for the steps of `order`, in step order: each step's rows,
    /// then its samples, as the steps would draw them one by one. Nothing is drawn when
    /// the steps draw nothing (all rows, no `L_H` samples).
    pub(super) fn draw_iteration(&self, order: &[usize], rng: &mut ChaCha8Rng) -> HostDraws {
        let subset = self.rows.subset();
        let mut draws = HostDraws::default();
        if (self.samples.is_none() && subset.is_none()) || order.is_empty() {
            return draws;
        }
        let (mut rows, mut spans, mut points, mut per_step) =
            (Vec::new(), Vec::new(), Vec::new(), 0);
        for &k in order {
            if let Some(take) = subset {
                let start = rows.len();
                rows.extend(self.rows.draw(&self.data, k, take, rng));
                spans.push((start, rows.len() - start));
            }
            if let Some(s) = &self.samples {
                let (p, n) = s.draw(rng);
                points.extend(p);
                per_step = n;
            }
        }
        draws.rows = subset.map(|_| (rows, spans));
        draws.samples = self.samples.as_ref().map(|_| (points, per_step));
        draws
    }

    /// The fused step's inputs on frame `k`: its rows (prepared, or drawn now), their
    /// canonical positions, targets and weights, and `L_H`'s samples.
    pub(super) fn host_batch(&mut self, k: usize, rng: &mut ChaCha8Rng) -> HostBatch {
        let draws = self.host.get_or_insert_with(HostDraws::default);
        let step = draws.next;
        draws.next += 1;
        let rows: Vec<usize> = match (self.rows.subset(), &draws.rows) {
            (Some(_), Some((rows, spans))) if step < spans.len() => {
                let (start, len) = spans[step];
                rows[start..start + len]
                    .iter()
                    .map(|&r| r as usize)
                    .collect()
            }
            (Some(take), _) => self
                .rows
                .draw(&self.data, k, take, rng)
                .into_iter()
                .map(|r| r as usize)
                .collect(),
            (None, _) => match self.data.observed_in_frame(k) {
                Some(seen) => (0..seen.len()).filter(|&i| seen[i]).collect(),
                None => (0..self.data.points()).collect(),
            },
        };
        let samples = self.samples.as_ref().map(|s| match &draws.samples {
            Some((points, per)) if (step + 1) * per * 3 <= points.len() => {
                points[step * per * 3..(step + 1) * per * 3].to_vec()
            }
            _ => s.draw(rng).0,
        });
        let gather = |src: &[f32], width: usize| -> Vec<f32> {
            rows.iter()
                .flat_map(|&r| src[r * width..(r + 1) * width].iter().copied())
                .collect()
        };
        HostBatch {
            time: self.data.time(k),
            x0: gather(self.data.canonical(), 3),
            target: gather(self.data.frame(k), 3),
            weights: self.data.weights_in_frame(k).map(|w| gather(w, 1)),
            samples,
        }
    }
}
