//! The canonical positions of training tracks not observed in the reference frame, learned
//! with the field (docs/design.md §7): `x = x_placed + δ`, one `δ` per track, where
//! `x_placed` is where the neighbours' motion places the track, updated by Adam at the
//! field's learning rate.

use burn::tensor::{Device, Gradients, IndexingUpdateOp, Int, Tensor, TensorData};

use crate::data::Trajectories;
use crate::{DomaError, Result};

/// Adam's moment decays and ε: the field's own ([`super::schedule::default_adam`]).
const ADAM: (f64, f64, f64) = (0.9, 0.999, 1e-8);

/// The learned offsets `δ` of the tracks unseen in the reference frame, and their Adam
/// state.
pub(super) struct LearnedPositions {
    /// The tracks' rows `[M]`.
    rows: Tensor<1, Int>,
    /// `δ`, `[M, 3]`, an autodiff leaf.
    delta: Tensor<2>,
    /// Adam's first and second moments (off the graph), and its steps.
    moments: Option<(Tensor<2>, Tensor<2>)>,
    steps: usize,
    ad: Device,
}

impl LearnedPositions {
    /// The learned positions of `data`'s tracks unseen in its reference frame, `δ = 0`;
    /// `None` when every track is seen there.
    pub fn new(data: &Trajectories, ad: &Device) -> Option<Self> {
        let seen = data.observed_in_frame(data.reference())?;
        let rows: Vec<i64> = (0..data.points())
            .filter(|&i| !seen[i])
            .map(|i| i as i64)
            .collect();
        let m = rows.len();
        (m > 0).then(|| LearnedPositions {
            rows: Tensor::<1, Int>::from_data(TensorData::new(rows, [m]), ad),
            delta: Tensor::<2>::zeros([m, 3], ad).require_grad(),
            moments: None,
            steps: 0,
            ad: ad.clone(),
        })
    }

    /// `x0` (`[N, 3]`, every training track's placed position) with `δ` added to the
    /// learned rows: the canonical positions a step warps.
    pub fn positions(&self, x0: Tensor<2>) -> Tensor<2> {
        let offsets = Tensor::<2>::zeros(x0.dims(), &self.ad).select_assign(
            0,
            self.rows.clone(),
            self.delta.clone(),
            IndexingUpdateOp::Add,
        );
        x0 + offsets
    }

    /// Adam's update of `δ` from this step's gradient, on the device.
    pub fn update(&mut self, grads: &Gradients, lr: f64) {
        let Some(g) = self.delta.grad(grads) else {
            return;
        };
        let (b1, b2, eps) = ADAM;
        let (m, v) = match self.moments.take() {
            Some((m, v)) => (m, v),
            None => (g.zeros_like(), g.zeros_like()),
        };
        let m = m.mul_scalar(b1) + g.clone().mul_scalar(1.0 - b1);
        let v = v.mul_scalar(b2) + g.square().mul_scalar(1.0 - b2);
        self.steps += 1;
        let t = self.steps as i32;
        let step = m
            .clone()
            .div_scalar(1.0 - b1.powi(t))
            .div(
                v.clone()
                    .div_scalar(1.0 - b2.powi(t))
                    .sqrt()
                    .add_scalar(eps),
            )
            .mul_scalar(lr);
        self.delta = (self.delta.clone().inner() - step)
            .autodiff()
            .require_grad();
        self.moments = Some((m, v));
    }

    /// `δ`, then Adam's two moments (zeros before the first step), then the step count.
    pub fn state(&self) -> Result<Vec<f32>> {
        let mut out: Vec<f32> = crate::readback::to_vec(self.delta.clone().inner())?;
        let n = out.len();
        match &self.moments {
            Some((m, v)) => {
                out.extend(crate::readback::to_vec::<f32, 2, _>(m.clone())?);
                out.extend(crate::readback::to_vec::<f32, 2, _>(v.clone())?);
            }
            None => out.extend(std::iter::repeat_n(0.0, 2 * n)),
        }
        out.push(self.steps as f32);
        Ok(out)
    }

    /// Puts a [`LearnedPositions::state`] back.
    pub fn restore(&mut self, state: &[f32]) -> Result<()> {
        let m = self.rows.dims()[0];
        if state.len() != 9 * m + 1 {
            return Err(DomaError::InvalidData(format!(
                "the checkpoint holds {} values for the learned positions of {m} tracks",
                state.len()
            )));
        }
        let part = |i: usize| {
            Tensor::<2>::from_data(
                TensorData::new(state[3 * m * i..3 * m * (i + 1)].to_vec(), [m, 3]),
                &self.ad,
            )
            .inner()
        };
        self.steps = state[9 * m] as usize;
        self.delta = part(0).autodiff().require_grad();
        self.moments = (self.steps > 0).then(|| (part(1), part(2)));
        Ok(())
    }

    /// `canonical` (`[N, 3]`, every training track's, host) with the learned `δ` added;
    /// `row(r)` maps a fitted row to its row in `canonical`.
    pub fn canonical(&self, canonical: &[f32], row: impl Fn(usize) -> usize) -> Result<Vec<f32>> {
        let delta: Vec<f32> = crate::readback::to_vec(self.delta.clone().inner())?;
        let rows: Vec<i64> = crate::readback::to_vec(self.rows.clone())?;
        let mut x = canonical.to_vec();
        for (j, &r) in rows.iter().enumerate() {
            let i = row(r as usize);
            for c in 0..3 {
                x[3 * i + c] += delta[3 * j + c];
            }
        }
        Ok(x)
    }
}
