//! Forward-mode automatic differentiation with dual tensors (docs/design.md §2, "Autodiff").
//!
//! A [`Dual`] holds a value `[N, C]` and, optionally, its tangents with respect to
//! the three spatial inputs, `[3, N, C]`. Every operation below applies the chain rule
//! to the tangents with ordinary Burn tensor ops, so Burn's reverse mode can then
//! differentiate any loss on the tangents with respect to the network weights
//! (reverse-over-forward). Burn 0.22 has first-order autodiff only (burn#1942), so
//! this is how the θ-gradient of a Jacobian loss is obtained.
//!
//! A dual without tangents is a plain tensor: the same model code serves evaluation
//! (no Jacobian) and training with a Jacobian loss.

use burn::tensor::{Int, Tensor, TensorData, activation};

/// A value `[N, C]` with optional spatial tangents `[3, N, C]`
/// (`tangent[k, n, c] = ∂value[n, c] / ∂x_k`).
#[derive(Clone, Debug)]
pub struct Dual {
    /// The primal value, `[N, C]`.
    pub value: Tensor<2>,
    /// The tangents along the three spatial axes, `[3, N, C]`; `None` means zero
    /// (a constant, or a forward pass that does not need the Jacobian).
    pub tangent: Option<Tensor<3>>,
}

/// `[N, C]` → `[1, N, C]`, so that a value broadcasts against a `[3, N, C]` tangent.
fn lift(value: &Tensor<2>) -> Tensor<3> {
    value.clone().unsqueeze_dim(0)
}

/// Adds two optional tangents (absent = zero).
fn add_tangents(a: Option<Tensor<3>>, b: Option<Tensor<3>>) -> Option<Tensor<3>> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a + b),
        (a, None) => a,
        (None, b) => b,
    }
}

impl Dual {
    /// A constant: the value with zero tangents.
    pub fn constant(value: Tensor<2>) -> Self {
        Dual {
            value,
            tangent: None,
        }
    }

    /// The seed for spatial differentiation: the first three input columns are the
    /// spatial coordinates `x` (tangent `e_k`); any further columns (the time `t`)
    /// are held fixed. `input` is `[N, C]` with `C ≥ 3`.
    pub fn seed_spatial(input: Tensor<2>) -> Self {
        let [n, c] = input.dims();
        assert!(
            c >= 3,
            "a spatial seed needs at least 3 input columns, got {c}"
        );
        let device = input.device();
        let mut eye = vec![0.0f32; 3 * c];
        for k in 0..3 {
            eye[k * c + k] = 1.0;
        }
        let eye = Tensor::<3>::from_data(TensorData::new(eye, [3, 1, c]), &device);
        Dual {
            value: input,
            tangent: Some(eye.repeat_dim(1, n)),
        }
    }

    /// The number of rows `N`.
    pub fn rows(&self) -> usize {
        self.value.dims()[0]
    }

    /// The number of channels `C`.
    pub fn channels(&self) -> usize {
        self.value.dims()[1]
    }

    /// Whether tangents are being carried.
    pub fn has_tangent(&self) -> bool {
        self.tangent.is_some()
    }

    /// `x W + b` for `W: [C, C']`, `b: [C']`. The tangents go through `W` as one
    /// `[3N, C] × [C, C']` matmul rather than three.
    pub fn linear(self, weight: Tensor<2>, bias: Option<Tensor<1>>) -> Self {
        let n = self.rows();
        let c_out = weight.dims()[1];
        let tangent = self.tangent.map(|t| {
            let c_in = t.dims()[2];
            t.reshape([3 * n, c_in])
                .matmul(weight.clone())
                .reshape([3, n, c_out])
        });
        let mut value = self.value.matmul(weight);
        if let Some(b) = bias {
            value = value + b.unsqueeze_dim(0);
        }
        Dual { value, tangent }
    }

    /// Multiplies value and tangents by a constant.
    pub fn mul_scalar(self, s: f64) -> Self {
        Dual {
            value: self.value.mul_scalar(s),
            tangent: self.tangent.map(|t| t.mul_scalar(s)),
        }
    }

    /// Adds a constant to the value.
    pub fn add_scalar(self, s: f64) -> Self {
        Dual {
            value: self.value.add_scalar(s),
            tangent: self.tangent,
        }
    }

    /// `sin(v)`, with tangent `cos(v) ⊙ v̇`.
    pub fn sin(self) -> Self {
        let tangent = self.tangent.map(|t| t * lift(&self.value.clone().cos()));
        Dual {
            value: self.value.sin(),
            tangent,
        }
    }

    /// `exp(v)`, with tangent `exp(v) ⊙ v̇`.
    pub fn exp(self) -> Self {
        let value = self.value.exp();
        let tangent = self.tangent.map(|t| t * lift(&value));
        Dual { value, tangent }
    }

    /// `cos(v)`, with tangent `−sin(v) ⊙ v̇`.
    pub fn cos(self) -> Self {
        let tangent = self
            .tangent
            .map(|t| t * lift(&self.value.clone().sin().neg()));
        Dual {
            value: self.value.cos(),
            tangent,
        }
    }

    /// `max(v, 0)`, with tangent `1[v > 0] ⊙ v̇`.
    pub fn relu(self) -> Self {
        let tangent = self.tangent.map(|t| {
            let mask = self.value.clone().greater_elem(0.0).float();
            t * lift(&mask)
        });
        Dual {
            value: activation::relu(self.value),
            tangent,
        }
    }

    /// `softplus(v) = log(1 + e^v)` (β = 1), with tangent `sigmoid(v) ⊙ v̇`.
    pub fn softplus(self) -> Self {
        let tangent = self
            .tangent
            .map(|t| t * lift(&activation::sigmoid(self.value.clone())));
        Dual {
            value: activation::softplus(self.value, 1.0),
            tangent,
        }
    }

    /// `√v`, with tangent `v̇ / (2√v)`.
    pub fn sqrt(self) -> Self {
        let root = self.value.sqrt();
        let tangent = self
            .tangent
            .map(|t| t / lift(&root.clone().mul_scalar(2.0)));
        Dual {
            value: root,
            tangent,
        }
    }

    /// `max(v, lo)`; the tangent is zero where the clamp is active.
    pub fn clamp_min(self, lo: f64) -> Self {
        let tangent = self.tangent.map(|t| {
            let mask = self.value.clone().greater_equal_elem(lo).float();
            t * lift(&mask)
        });
        Dual {
            value: self.value.clamp_min(lo),
            tangent,
        }
    }

    /// The reciprocal `1 / v`, with tangent `−v̇ / v²`.
    pub fn recip(self) -> Self {
        let inv = self.value.recip();
        let tangent = self.tangent.map(|t| t * lift(&inv.clone().square().neg()));
        Dual {
            value: inv,
            tangent,
        }
    }

    /// Channels `start..start + len`.
    pub fn narrow(self, start: usize, len: usize) -> Self {
        Dual {
            value: self.value.narrow(1, start, len),
            tangent: self.tangent.map(|t| t.narrow(2, start, len)),
        }
    }

    /// The channels at `indices`, in that order.
    pub fn select(self, indices: &[usize]) -> Self {
        let device = self.value.device();
        let idx: Vec<i64> = indices.iter().map(|&i| i as i64).collect();
        let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [indices.len()]), &device);
        Dual {
            value: self.value.select(1, idx.clone()),
            tangent: self.tangent.map(|t| t.select(2, idx)),
        }
    }

    /// The softmax over channels, `[N, C]` → `[N, C]`, rows summing to 1. The row maximum,
    /// a constant, is subtracted first so that `exp` stays in range.
    pub fn softmax(self) -> Self {
        let c = self.channels();
        let shift = Dual::constant(self.value.clone().max_dim(1).detach());
        let ones = Tensor::<2>::ones([1, c], &self.value.device());
        let e = (self - shift.linear(ones, None)).exp();
        let inv = e.clone().sum_channels().recip();
        e * inv
    }

    /// The sum over channels, `[N, 1]`.
    pub fn sum_channels(self) -> Self {
        Dual {
            value: self.value.sum_dim(1),
            tangent: self.tangent.map(|t| t.sum_dim(2)),
        }
    }

    /// Concatenates along the channels. Missing tangents count as zero.
    pub fn cat(parts: Vec<Dual>) -> Self {
        let any_tangent = parts.iter().any(Dual::has_tangent);
        let tangent = any_tangent.then(|| {
            parts
                .iter()
                .map(|p| match &p.tangent {
                    Some(t) => t.clone(),
                    None => {
                        let [n, c] = p.value.dims();
                        Tensor::zeros([3, n, c], &p.value.device())
                    }
                })
                .collect::<Vec<_>>()
        });
        Dual {
            value: Tensor::cat(parts.into_iter().map(|p| p.value).collect(), 1),
            tangent: tangent.map(|t| Tensor::cat(t, 2)),
        }
    }

    /// The Jacobian as a `[N, C, 3]` tensor (`J[n, c, k] = ∂value[n, c] / ∂x_k`), or
    /// `None` if no tangents were carried.
    pub fn jacobian(&self) -> Option<Tensor<3>> {
        self.tangent.as_ref().map(|t| t.clone().permute([1, 2, 0]))
    }
}

/// Elementwise sum (shapes broadcast as in Burn).
impl std::ops::Add for Dual {
    type Output = Dual;
    fn add(self, other: Dual) -> Dual {
        Dual {
            value: self.value + other.value,
            tangent: add_tangents(self.tangent, other.tangent),
        }
    }
}

/// Elementwise difference.
impl std::ops::Sub for Dual {
    type Output = Dual;
    fn sub(self, other: Dual) -> Dual {
        self + other.mul_scalar(-1.0)
    }
}

/// Elementwise product, by the product rule; `[N, 1]` broadcasts against `[N, C]`.
impl std::ops::Mul for Dual {
    type Output = Dual;
    fn mul(self, other: Dual) -> Dual {
        let da = self.tangent.map(|t| t * lift(&other.value));
        let db = other.tangent.map(|t| t * lift(&self.value));
        Dual {
            value: self.value * other.value,
            tangent: add_tangents(da, db),
        }
    }
}
