//! The losses of a DOMA fit (docs/design.md §3, docs/reference.md §4). Each returns a one-element
//! tensor, so that it can be summed and differentiated.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

/// The trajectory (reconstruction) loss, docs/reference.md §4.1: the mean absolute error over
/// all `N × 3` coordinates of `predicted` and `target` (`[N, 3]`). It divides by `3N`,
/// whereas the EPE metric sums over the three coordinates.
pub fn trajectory_l1(predicted: Tensor<2>, target: Tensor<2>) -> Tensor<1> {
    (predicted - target).abs().mean()
}

/// The per-coordinate penalty of the trajectory loss. Real tracks carry outliers; a robust
/// penalty bounds their pull on the fit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DataPenalty {
    /// `|r|`, the paper's trajectory loss.
    L1,
    /// Huber: `r² / (2δ)` for `|r| ≤ δ`, `|r| − δ/2` beyond (L1's slope in the tails).
    Huber {
        /// The threshold `δ`, in normalised units.
        delta: f64,
    },
    /// Charbonnier: `√(r² + ε²) − ε`.
    Charbonnier {
        /// The smoothing `ε`, in normalised units.
        epsilon: f64,
    },
}

impl DataPenalty {
    /// Refuses a threshold that is not finite and positive.
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            DataPenalty::L1 => Ok(()),
            DataPenalty::Huber { delta: s } | DataPenalty::Charbonnier { epsilon: s } => {
                if s.is_finite() && s > 0.0 {
                    Ok(())
                } else {
                    Err(format!("the data penalty's scale {s} must be positive"))
                }
            }
        }
    }

    /// The penalty of each residual (any shape).
    pub fn apply<const D: usize>(&self, residual: Tensor<D>) -> Tensor<D> {
        match *self {
            DataPenalty::L1 => residual.abs(),
            DataPenalty::Huber { delta } => {
                // With c = min(|r|, δ): c (|r| − c/2) / δ is both branches at once.
                let a = residual.abs();
                let c = a.clone().clamp_max(delta);
                c.clone().mul(a - c.div_scalar(2.0)).div_scalar(delta)
            }
            DataPenalty::Charbonnier { epsilon } => residual
                .square()
                .add_scalar(epsilon * epsilon)
                .sqrt()
                .sub_scalar(epsilon),
        }
    }
}

/// `l1`, `huber[:DELTA]` or `charbonnier[:EPSILON]` (the scale in normalised units,
/// default 0.01): the spelling of `doma fit --robust`, of a manifest's and a Python fit's
/// `robust`.
impl std::str::FromStr for DataPenalty {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (kind, scale) = match s.split_once(':') {
            Some((k, v)) => (
                k,
                v.parse::<f64>()
                    .map_err(|_| format!("`{v}` is not a number"))?,
            ),
            None => (s, 0.01),
        };
        let penalty = match kind {
            "l1" if !s.contains(':') => DataPenalty::L1,
            "huber" => DataPenalty::Huber { delta: scale },
            "charbonnier" => DataPenalty::Charbonnier { epsilon: scale },
            _ => {
                return Err(format!(
                    "`{s}` is not l1, huber[:DELTA] or charbonnier[:EPSILON]"
                ));
            }
        };
        penalty.validate()?;
        Ok(penalty)
    }
}

/// The spelling [`DataPenalty`]'s `FromStr` reads: `l1`, `huber:0.01`, `charbonnier:0.002`.
impl std::fmt::Display for DataPenalty {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DataPenalty::L1 => f.write_str("l1"),
            DataPenalty::Huber { delta } => write!(f, "huber:{delta}"),
            DataPenalty::Charbonnier { epsilon } => write!(f, "charbonnier:{epsilon}"),
        }
    }
}

/// The trajectory loss with a per-coordinate `penalty` and per-point `weights` (`[N, 1]`,
/// non-negative, a tracker's confidence): `Σ_i w_i Σ_c ρ(ŷ_ic − y_ic) / (3 Σ_i w_i)`, the
/// weighted mean. With [`DataPenalty::L1`] and no weights it is [`trajectory_l1`], computed
/// the same way. All-zero weights give 0.
pub fn trajectory_loss(
    predicted: Tensor<2>,
    target: Tensor<2>,
    penalty: DataPenalty,
    weights: Option<Tensor<2>>,
) -> Tensor<1> {
    let rho = penalty.apply(predicted - target);
    match weights {
        None => rho.mean(),
        Some(w) => {
            let total = w
                .clone()
                .sum()
                .mul_scalar(3.0)
                .clamp_min(f32::MIN_POSITIVE as f64);
            rho.mul(w).sum().div(total)
        }
    }
}

/// The temporal smoothness loss `L_T`, the time analogue of `L_H` (not in the paper; docs/design.md
/// §3): the mean over points of `‖(y(x, t−Δ) − 2 y(x, t) + y(x, t+Δ)) / Δ²‖²`, the squared
/// norm of a central second difference of the warped positions one frame `Δ` apart (`Δ` in
/// normalised time, so that the weight does not depend on the frame count). A cubic spline
/// minimises the integral of the same quantity; penalising it keeps a sparse field from
/// oscillating inside a track's gap. `before`, `at`, `after` are `[N, 3]`.
pub fn acceleration(before: Tensor<2>, at: Tensor<2>, after: Tensor<2>, delta: f64) -> Tensor<1> {
    (before - at.mul_scalar(2.0) + after)
        .div_scalar(delta * delta)
        .square()
        .sum_dim(1)
        .mean()
}

/// How the smoothness loss `L_H` treats each Jacobian entry (docs/reference.md §4.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum SmoothnessNorm {
    /// The "-H" rows: the sum of the squared entries, `Σ J_rc²`
    /// (`= ‖∇A‖_F² + ‖∇u‖_F²` for Affinity).
    Squared,
    /// Charbonnier per entry, `Σ (√(J_rc² + 1) − 1)`, as the authors' registration code.
    /// (The paper's Eq. 13 applies `Ψ` to the total instead; the code does not.)
    Charbonnier,
}

/// The smoothness loss `L_H` (Eq. 13, in the authors' form; docs/reference.md §4.2): the
/// per-point penalty of the raw-output Jacobian, averaged over the `P` points.
/// `tangent` is `[3, P, O]` (`∂o/∂x` as the tangents of a [`crate::jacobian::Dual`]).
pub fn smoothness(tangent: Tensor<3>, norm: SmoothnessNorm) -> Tensor<1> {
    let points = tangent.dims()[1] as f64;
    let squared = tangent.square();
    let per_entry = match norm {
        SmoothnessNorm::Squared => squared,
        SmoothnessNorm::Charbonnier => squared.add_scalar(1.0).sqrt().sub_scalar(1.0),
    };
    per_entry.sum().div_scalar(points)
}

/// The scale `c` of the elasticity robustifier (docs/reference.md §4.3).
pub const ELASTIC_SCALE: f64 = 0.03;

/// Keeps `p` of the eigenvalue formula away from zero, so that an isotropic
/// `JᵀJ` (a pure scaling, the identity) has finite gradients. It shifts the
/// eigenvalues by about `√3·1e-6` at most.
const EIGEN_EPS: f64 = 1e-12;
/// Keeps `acos` off ±1, where its derivative is infinite (repeated eigenvalues).
const ACOS_MARGIN: f64 = 1e-6;
/// Eigenvalues below this are clamped before the logarithm (a singular warp).
const EIGEN_FLOOR: f64 = 1e-30;

/// The three eigenvalues of the symmetric 3×3 matrices `S` given by their six
/// distinct entries (each `[N, 1]`), by the closed-form trigonometric solution
/// (Smith 1961). Returned largest first, each `[N, 1]`. Plain tensor ops, so it runs
/// on every backend and Burn's reverse mode differentiates it.
pub fn symmetric_eigenvalues(s: [Tensor<2>; 6]) -> [Tensor<2>; 3] {
    let [a, b, c, d, e, f] = s; // S00, S11, S22, S01, S12, S02
    let q = (a.clone() + b.clone() + c.clone()).div_scalar(3.0);
    let (ba, bb, bc) = (a - q.clone(), b - q.clone(), c - q.clone());
    let p1 = d.clone().square() + e.clone().square() + f.clone().square();
    let p2 = ba.clone().square() + bb.clone().square() + bc.clone().square() + p1.mul_scalar(2.0);
    let p = p2.div_scalar(6.0).add_scalar(EIGEN_EPS).sqrt();
    let inv = p.clone().recip();
    let (b00, b11, b22) = (ba * inv.clone(), bb * inv.clone(), bc * inv.clone());
    let (b01, b12, b02) = (d * inv.clone(), e * inv.clone(), f * inv);
    let det = b00 * (b11.clone() * b22.clone() - b12.clone().square())
        - b01.clone() * (b01.clone() * b22 - b12.clone() * b02.clone())
        + b02.clone() * (b01 * b12 - b11 * b02);
    let r = det
        .div_scalar(2.0)
        .clamp(-1.0 + ACOS_MARGIN, 1.0 - ACOS_MARGIN);
    let phi = r.acos().div_scalar(3.0);
    let two_p = p.mul_scalar(2.0);
    let l1 = q.clone() + two_p.clone() * phi.clone().cos();
    let l3 = q.clone() + two_p * phi.add_scalar(2.0 * std::f64::consts::PI / 3.0).cos();
    let l2 = q.mul_scalar(3.0) - l1.clone() - l3.clone();
    [l1, l2, l3]
}

/// The singular values of the 3×3 matrices `M` (`[N, 3]` each) given by their columns
/// `c_k = M[:, k]`: the square roots of the eigenvalues of `MᵀM`, largest first.
pub fn singular_values_3x3(columns: [Tensor<2>; 3]) -> [Tensor<2>; 3] {
    let g = |i: usize, j: usize| (columns[i].clone() * columns[j].clone()).sum_dim(1);
    let lambda = symmetric_eigenvalues([g(0, 0), g(1, 1), g(2, 2), g(0, 1), g(1, 2), g(0, 2)]);
    lambda.map(|l| l.clamp_min(EIGEN_FLOOR).sqrt())
}

/// The elasticity loss "-E" (Nerfies; docs/reference.md §4.3) on the Jacobian of the whole
/// warp, `tangent: [3, N, 3]` (`tangent[k, n, i] = ∂y_i/∂x_k`):
/// `q = Σ_j log² σ_j(∂y/∂x)` per point, then the authors' robustifier
/// `ρ(q) = 2 (q/c)² / ((q/c)² + 4)` with `c = 0.03` (applied to `q` itself, which is
/// already squared: a quirk of the reference that we keep), averaged over points.
pub fn elasticity(tangent: Tensor<3>) -> Tensor<1> {
    let [_, n, _] = tangent.dims();
    let columns = [0, 1, 2].map(|k| tangent.clone().narrow(0, k, 1).reshape([n, 3]));
    let [s1, s2, s3] = singular_values_3x3(columns);
    let q = s1.log().square() + s2.log().square() + s3.log().square();
    elastic_robustifier(q).mean()
}

/// `ρ(q) = 2 (q/c)² / ((q/c)² + 4)`, `c` = [`ELASTIC_SCALE`].
pub fn elastic_robustifier(q: Tensor<2>) -> Tensor<2> {
    let z = q.div_scalar(ELASTIC_SCALE).square();
    z.clone().mul_scalar(2.0) / z.add_scalar(4.0)
}

/// The neighbourhoods of the as-isometric-as-possible loss (AIAP, DPF Eq. 13;
/// docs/reference.md §4.4), computed once on the canonical points: each point's `K` nearest neighbours
/// (itself included) from a k-d tree, and their pairwise canonical distances.
#[derive(Clone, Debug)]
pub struct AiapNeighbourhoods {
    /// `[N·K]` neighbour indices, row-major, closest first.
    pub indices: Vec<usize>,
    /// `K`.
    pub k: usize,
    /// `[N, P]` canonical distances of the `P = K(K−1)/2` pairs `i < j` of each
    /// neighbourhood.
    pub rest_lengths: Vec<f32>,
}

/// The pairs `(i, j)`, `i < j`, of a `k`-neighbourhood.
fn neighbourhood_pairs(k: usize) -> Vec<(usize, usize)> {
    (0..k)
        .flat_map(|i| (i + 1..k).map(move |j| (i, j)))
        .collect()
}

impl AiapNeighbourhoods {
    /// The `k`-nearest neighbourhoods of `canonical` (`k ≥ 2`, at most the point count).
    pub fn new(canonical: &[[f32; 3]], k: usize) -> crate::Result<Self> {
        if k < 2 || k > canonical.len() {
            return Err(crate::DomaError::InvalidConfig(format!(
                "AIAP needs 2 ≤ K ≤ {} neighbours, not {k}",
                canonical.len()
            )));
        }
        let tree = crate::numeric::knn::PointTree::new(canonical)?;
        let indices: Vec<usize> = canonical
            .iter()
            .flat_map(|q| tree.nearest_k(q, k))
            .collect();
        let pairs = neighbourhood_pairs(k);
        let rest_lengths = indices
            .chunks_exact(k)
            .flat_map(|nb| {
                pairs.iter().map(move |&(i, j)| {
                    let (a, b) = (canonical[nb[i]], canonical[nb[j]]);
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
                })
            })
            .collect();
        Ok(AiapNeighbourhoods {
            indices,
            k,
            rest_lengths,
        })
    }

    /// The number of points.
    pub fn points(&self) -> usize {
        self.indices.len() / self.k
    }
}

/// Keeps the distance's derivative finite when two neighbours coincide.
const AIAP_EPS: f64 = 1e-12;

/// The AIAP loss (DPF Eq. 13, docs/reference.md §4.4): the mean absolute difference between the
/// pairwise distances inside each canonical neighbourhood and the same distances after the
/// warp, over all `N × K × K` entries. `deformed` is `[N, 3]`, the warped canonical points
/// in the order of `neighbourhoods`. The diagonal entries are zero on both sides and the
/// matrix is symmetric, so this sums the `i < j` pairs and scales by `2 / K²`: the same
/// number, without `√0` in the graph.
pub fn aiap(deformed: Tensor<2>, neighbourhoods: &AiapNeighbourhoods) -> Tensor<1> {
    let device = deformed.device();
    let k = neighbourhoods.k;
    let n = neighbourhoods.points();
    let pairs = neighbourhood_pairs(k);
    let p = pairs.len();
    let (mut left, mut right) = (Vec::with_capacity(n * p), Vec::with_capacity(n * p));
    for nb in neighbourhoods.indices.chunks_exact(k) {
        for &(i, j) in &pairs {
            left.push(nb[i] as i64);
            right.push(nb[j] as i64);
        }
    }
    let index = |v: Vec<i64>| {
        Tensor::<1, burn::tensor::Int>::from_data(
            burn::tensor::TensorData::new(v, [n * p]),
            &device,
        )
    };
    let a = deformed.clone().select(0, index(left));
    let b = deformed.select(0, index(right));
    let lengths = (a - b).square().sum_dim(1).add_scalar(AIAP_EPS).sqrt(); // [N·P, 1]
    let rest = Tensor::<2>::from_data(
        burn::tensor::TensorData::new(neighbourhoods.rest_lengths.clone(), [n * p, 1]),
        &device,
    );
    (lengths - rest)
        .abs()
        .sum()
        .mul_scalar(2.0 / (n * k * k) as f64)
}

/// Rows of `a` per block of the Chamfer loss: a block's distance matrix is
/// `CHAMFER_BLOCK × M`, so 10k × 40k clouds stay at 2048 × 40 000 × 4 B = 328 MB at once.
pub const CHAMFER_BLOCK: usize = 2048;

/// The mean over `from`'s rows of the squared distance to the nearest row of `to`, in
/// blocks of [`CHAMFER_BLOCK`] rows. `|a|² + |b|² − 2 a·b` makes each block one matmul.
fn chamfer_one_way(from: Tensor<2>, to: Tensor<2>) -> Tensor<1> {
    let n = from.dims()[0];
    let to_sq = to.clone().square().sum_dim(1).transpose(); // [1, M]
    let to_t = to.transpose(); // [3, M]
    let mut total: Option<Tensor<1>> = None;
    let mut start = 0;
    while start < n {
        let len = CHAMFER_BLOCK.min(n - start);
        let a = from.clone().narrow(0, start, len);
        let a_sq = a.clone().square().sum_dim(1); // [len, 1]
        let d2 = (a_sq + to_sq.clone() - a.matmul(to_t.clone()).mul_scalar(2.0)).clamp_min(0.0);
        let part = d2.min_dim(1).sum();
        total = Some(match total {
            Some(t) => t + part,
            None => part,
        });
        start += len;
    }
    total.expect("a non-empty cloud").div_scalar(n as f64)
}

/// The Chamfer loss (`L_CD` of Eq. 3 and Eq. 14, docs/reference.md §4.5) between `a` (`[N, 3]`, e.g. warped canonical
/// samples) and `b` (`[M, 3]`, target samples): the mean squared nearest-neighbour distance
/// from `a` to `b` plus from `b` to `a`. On the device, differentiable, and blocked so that
/// it never holds an `N × M` matrix at once.
///
/// # Panics
/// If either cloud is empty (a programming error; the fit loops check their inputs).
pub fn chamfer(a: Tensor<2>, b: Tensor<2>) -> Tensor<1> {
    assert!(
        a.dims()[0] > 0 && b.dims()[0] > 0,
        "chamfer: empty point cloud"
    );
    chamfer_one_way(a.clone(), b.clone()) + chamfer_one_way(b, a)
}

#[cfg(test)]
mod tests {
    use super::DataPenalty;

    #[test]
    fn robust_penalties_parse_with_and_without_a_scale_and_print_as_they_parse() {
        assert_eq!("l1".parse(), Ok(DataPenalty::L1));
        assert_eq!("huber".parse(), Ok(DataPenalty::Huber { delta: 0.01 }));
        assert_eq!(
            "charbonnier:0.002".parse(),
            Ok(DataPenalty::Charbonnier { epsilon: 0.002 })
        );
        for bad in ["huber:-1", "huber:x", "l2", "l1:3", "charbonnier:0"] {
            assert!(bad.parse::<DataPenalty>().is_err(), "{bad}");
        }
        for text in ["l1", "huber:0.25", "charbonnier:0.002"] {
            let p: DataPenalty = text.parse().unwrap();
            assert_eq!(p.to_string(), text);
        }
    }
}
