//! The loss terms of the fused step on rows, each with its gradient with respect to what
//! it reads: the trajectory loss's penalty of the warped rows ([`crate::loss::trajectory_loss`])
//! and `L_H` of the tangent rows ([`crate::loss::smoothness`]), in the same arithmetic.

use super::{Float, StepLoss};
use crate::loss::{DataPenalty, SmoothnessNorm};

/// The trajectory loss ([`crate::loss::trajectory_loss`]) of the warped rows `y` against
/// `target`, and its gradient with respect to `y`.
pub(super) fn data_term<E: Float>(
    y: &[E],
    target: &[E],
    weights: Option<&[E]>,
    penalty: DataPenalty,
) -> (f64, Vec<E>) {
    // ρ(r) and ρ'(r) per coordinate.
    let rho = |r: E| -> (E, E) {
        let zero = E::zero();
        let sign = if r > zero {
            E::one()
        } else if r < zero {
            zero - E::one()
        } else {
            zero
        };
        match penalty {
            DataPenalty::L1 => (r.abs(), sign),
            DataPenalty::Huber { delta } => {
                let (a, d) = (r.abs(), E::from_f64(delta));
                let c = if a > d { d } else { a };
                let two = E::from_f64(2.0);
                (c * (a - c / two) / d, sign * c / d)
            }
            DataPenalty::Charbonnier { epsilon } => {
                let e = E::from_f64(epsilon);
                let root = (r * r + e * e).sqrt();
                (root - e, r / root)
            }
        }
    };
    let n = y.len() / 3;
    // Each row's share: 1 / 3n, or w_i / (3 Σ w).
    let norm = match weights {
        None => E::from_f64((3 * n) as f64),
        Some(w) => {
            let total = w.iter().fold(E::zero(), |a, b| a + *b) * E::from_f64(3.0);
            total.max(E::from_f64(f32::MIN_POSITIVE as f64))
        }
    };
    let w_of = |i: usize| weights.map_or(E::one(), |w| w[i]);
    let mut loss = E::zero();
    let mut g = vec![E::zero(); y.len()];
    for i in 0..n {
        let w = w_of(i);
        for c in 0..3 {
            let (value, slope) = rho(y[3 * i + c] - target[3 * i + c]);
            loss = loss + value * w;
            g[3 * i + c] = slope * w / norm;
        }
    }
    ((loss / norm).to_f64(), g)
}

/// `w_H · L_H` (Eq. 13; [`crate::loss::smoothness`]) of the tangent rows (`[3p, O]`, the
/// dual output's rows after the values) over `p` points; its gradient is written into
/// `g` (same shape).
pub(super) fn smoothness<E: Float>(tangents: &[E], p: usize, loss: StepLoss, g: &mut [E]) -> f64 {
    let scale = E::from_f64(loss.smoothness_weight) / E::from_f64(p as f64);
    let mut sum = E::zero();
    for (j, gj) in tangents.iter().zip(g.iter_mut()) {
        let sq = *j * *j;
        match loss.smoothness_norm {
            SmoothnessNorm::Squared => {
                sum = sum + sq;
                *gj = E::from_f64(2.0) * *j * scale;
            }
            SmoothnessNorm::Charbonnier => {
                let root = (sq + E::one()).sqrt();
                sum = sum + (root - E::one());
                *gj = *j / root * scale;
            }
        }
    }
    (sum.to_f64() / p as f64) * loss.smoothness_weight
}
