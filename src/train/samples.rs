//! The points where `L_H` (Eq. 13) is evaluated when they are not the step's training
//! points (docs/reference.md §5): a random subset of the canonical points observed in the
//! reference frame, jittered by Gaussian noise, as the authors' code samples them.

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand::seq::SliceRandom;

use super::config::SmoothnessSampling;
use super::record::gaussian;

/// The samples of an iteration's steps, drawn at its start and uploaded at once.
struct PreparedSamples {
    /// Every step's samples, end to end: `[steps · per_step, 3]`.
    points: Tensor<2>,
    /// Samples per step.
    per_step: usize,
    /// The next step's index.
    next: usize,
}

/// Where a fit's `L_H` samples come from, and the current iteration's draws.
pub(super) struct SmoothnessSamples {
    /// The canonical points `[N, 3]` (host) that samples are drawn around.
    x0: Vec<f32>,
    sampling: SmoothnessSampling,
    prepared: Option<PreparedSamples>,
    ad: Device,
}

impl SmoothnessSamples {
    /// Samples around `x0` (`[N, 3]`, host) as `sampling` says, on `ad`.
    pub fn new(x0: Vec<f32>, sampling: SmoothnessSampling, ad: &Device) -> Self {
        SmoothnessSamples {
            x0,
            sampling,
            prepared: None,
            ad: ad.clone(),
        }
    }

    /// One step's samples (host) and their count.
    pub fn draw(&self, rng: &mut impl Rng) -> (Vec<f32>, usize) {
        smoothness_samples(&self.x0, &self.sampling, rng)
    }

    /// Forgets the last iteration's samples.
    pub fn clear(&mut self) {
        self.prepared = None;
    }

    /// The samples of an iteration's `steps` steps, `per_step` each, end to end (host),
    /// uploaded in one transfer.
    pub fn prepare(&mut self, points: Vec<f32>, steps: usize, per_step: usize) {
        let rows = steps * per_step;
        self.prepared = Some(PreparedSamples {
            points: Tensor::<2>::from_data(TensorData::new(points, [rows, 3]), &self.ad),
            per_step,
            next: 0,
        });
    }

    /// The next step's samples: the prepared ones, or drawn here (a step outside
    /// `Trainer::iteration`, as benchmarks take).
    pub fn step(&mut self, rng: &mut impl Rng) -> Tensor<2> {
        match self.prepared.as_mut() {
            Some(p) if (p.next + 1) * p.per_step <= p.points.dims()[0] => {
                p.next += 1;
                p.points
                    .clone()
                    .narrow(0, (p.next - 1) * p.per_step, p.per_step)
            }
            _ => {
                let (points, n) = self.draw(rng);
                Tensor::<2>::from_data(TensorData::new(points, [n, 3]), &self.ad)
            }
        }
    }
}

/// Draws the `L_H` sample points: a random subset of at most `max_points` rows of `x0`
/// (`[N, 3]`, host), jittered by Gaussian noise.
fn smoothness_samples(
    x0: &[f32],
    sampling: &SmoothnessSampling,
    rng: &mut impl Rng,
) -> (Vec<f32>, usize) {
    let n = x0.len() / 3;
    let mut rows: Vec<usize> = (0..n).collect();
    let take = sampling.max_points.map_or(n, |m| m.min(n));
    if take < n {
        rows.shuffle(rng);
        rows.truncate(take);
    }
    let sigma = sampling.jitter;
    let mut out = Vec::with_capacity(take * 3);
    for &i in &rows {
        for c in 0..3 {
            let noise = if sigma > 0.0 {
                sigma * gaussian(rng)
            } else {
                0.0
            };
            out.push((x0[3 * i + c] as f64 + noise) as f32);
        }
    }
    (out, take)
}
