//! Which training rows a step of the trajectory fit reads (docs/design.md §7): every
//! training point (the paper's protocol), a frame's observed ones where a tracker missed
//! some, or a fresh random subset of K of them each step (`points_per_step`).

use burn::tensor::{Device, Int, Tensor, TensorData};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::data::Trajectories;

/// The training rows of one step.
pub(super) enum StepRows {
    /// Every training point.
    All,
    /// These rows (boxed: a tensor is large beside the other variants).
    Rows(Box<Tensor<1, Int>>),
    /// None: the frame has no observed training point.
    Nothing,
}

/// The rows of an iteration's steps, drawn at its start and uploaded at once.
#[derive(Clone)]
pub(super) struct PreparedRows {
    /// Every step's rows, end to end.
    rows: Tensor<1, Int>,
    /// Each step's `(start, len)` in `rows`.
    spans: Vec<(usize, usize)>,
    /// The next step's index.
    next: usize,
}

/// The row selection of a fit: each frame's observed rows, the subset size, and the
/// current iteration's drawn subsets.
pub(super) struct TrainingRows {
    /// Training points per step when fewer than all.
    subset: Option<usize>,
    prepared: Option<PreparedRows>,
    ad: Device,
}

impl TrainingRows {
    /// The row selection of `data`'s frames, with `subset` points per step (`None`: all),
    /// on `ad`.
    pub fn new(data: &Trajectories, subset: Option<usize>, ad: &Device) -> Self {
        TrainingRows {
            subset: subset.filter(|&k| k < data.points()),
            prepared: None,
            ad: ad.clone(),
        }
    }

    /// What frame `k` of `data` observes, as rows on `ad`: made for the step, not kept (a
    /// tensor per frame held through the fit costs hundreds of bytes beside a frame's few
    /// rows).
    fn frame_rows(data: &Trajectories, k: usize, ad: &Device) -> StepRows {
        let Some(seen) = data.observed_in_frame(k) else {
            return StepRows::All;
        };
        if seen.iter().all(|&o| o) {
            return StepRows::All;
        }
        let rows: Vec<i64> = (0..data.points())
            .filter(|&i| seen[i])
            .map(|i| i as i64)
            .collect();
        match rows.len() {
            0 => StepRows::Nothing,
            len => StepRows::Rows(Box::new(upload(rows, len, ad))),
        }
    }

    /// Training points per step when fewer than all.
    pub fn subset(&self) -> Option<usize> {
        self.subset
    }

    /// A step's subset on frame `k` of `data`: `take` distinct rows of all the training
    /// points when the frame observes all of them, else of its observed ones (fewer when
    /// it has fewer).
    pub fn draw(
        &self,
        data: &Trajectories,
        k: usize,
        take: usize,
        rng: &mut ChaCha8Rng,
    ) -> Vec<i64> {
        match data.observed_in_frame(k) {
            // A frame that observes every point draws as one without a mask: the rows of
            // its observed points are then `0..n`, and the draw the same.
            None => step_rows(data.points(), take, rng),
            Some(seen) => {
                let rows: Vec<usize> = (0..seen.len()).filter(|&i| seen[i]).collect();
                step_rows(rows.len(), take.min(rows.len()), rng)
                    .into_iter()
                    .map(|r| rows[r as usize] as i64)
                    .collect()
            }
        }
    }

    /// Forgets the last iteration's subsets.
    pub fn clear(&mut self) {
        self.prepared = None;
    }

    /// The subsets of an iteration's steps (`rows`, each step's `(start, len)` in it),
    /// uploaded in one transfer.
    pub fn prepare(&mut self, rows: Vec<i64>, spans: Vec<(usize, usize)>) {
        let len = rows.len();
        self.prepared = Some(PreparedRows {
            rows: upload(rows, len, &self.ad),
            spans,
            next: 0,
        });
    }

    /// The rows of the next step, on frame `k`: the prepared subset, or one drawn here (a
    /// step outside `Trainer::iteration`, as benchmarks take).
    pub fn step(&mut self, data: &Trajectories, k: usize, rng: &mut ChaCha8Rng) -> StepRows {
        let Some(take) = self.subset else {
            return Self::frame_rows(data, k, &self.ad);
        };
        let rows = match self.prepared.as_mut() {
            Some(p) if p.next < p.spans.len() => {
                let (start, len) = p.spans[p.next];
                p.next += 1;
                (len > 0).then(|| p.rows.clone().narrow(0, start, len))
            }
            _ => {
                let rows = self.draw(data, k, take, rng);
                let len = rows.len();
                (len > 0).then(|| upload(rows, len, &self.ad))
            }
        };
        rows.map_or(StepRows::Nothing, |r| StepRows::Rows(Box::new(r)))
    }

    /// The current iteration's rows, all steps end to end (for tests).
    #[cfg(test)]
    pub fn prepared_rows(&self) -> Option<Tensor<1, Int>> {
        self.prepared.as_ref().map(|p| p.rows.clone())
    }
}

/// Row indices on the device.
fn upload(rows: Vec<i64>, len: usize, ad: &Device) -> Tensor<1, Int> {
    Tensor::<1, Int>::from_data(TensorData::new(rows, [len]), ad)
}

/// A step's training rows: `k` distinct rows of `n`, drawn uniformly.
pub(super) fn step_rows(n: usize, k: usize, rng: &mut impl Rng) -> Vec<i64> {
    rand::seq::index::sample(rng, n, k)
        .into_iter()
        .map(|i| i as i64)
        .collect()
}
