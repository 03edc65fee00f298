//! The timed steps of `doma bench`, public so that the criterion benchmarks (`benches/`)
//! time the same code: each is built once, then [`JacobianStep::run`],
//! [`FitStep::run`] or [`WarpStep::run`] is one step, synced.

use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::backend::BackendKind;
use crate::data::Trajectories;
use crate::error::Result;
use crate::field::model::Model;
use crate::field::{DomaField, DomaFieldConfig, MotionField, Variant};
use crate::jacobian::{JacobianKind, JacobianMethod};
use crate::loss::{self, SmoothnessNorm};
use crate::readback::sync;
use crate::train::{FitConfig, Trainer, TrajectoryObjective};

/// `points` random points in `[-1, 1]³`, `[points, 3]` on `device`.
fn random_points(points: usize, seed: u64, device: &Device) -> Tensor<2> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x: Vec<f32> = (0..3 * points)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    Tensor::<2>::from_data(TensorData::new(x, [points, 3]), device)
}

/// Outputs + J (Eq. 6) + the backward of `L_H + mean(o)` at random points, for an
/// Affinity field at d = 128, n = 2 (the `jacobian` rows).
pub struct JacobianStep {
    device: Device,
    field: DomaField,
    x: Tensor<2>,
    jac: Box<dyn JacobianMethod>,
}

impl JacobianStep {
    /// The step on `backend` by `method` at `points` points.
    pub fn new(backend: BackendKind, method: JacobianKind, points: usize) -> Result<Self> {
        let device = backend.device()?;
        let ad = device.clone().autodiff();
        Ok(JacobianStep {
            field: DomaFieldConfig::new(Variant::Affinity).init(0, &ad),
            x: random_points(points, 7, &ad),
            jac: method.method(),
            device,
        })
    }

    /// One step, synced; on a pool thread on the CPU, as `Trainer::step` runs
    /// (`backend::on_worker`).
    pub fn run(&self) -> Result<()> {
        crate::backend::on_worker(&self.device, || {
            let raw = self.field.raw_dual(self.x.clone(), 0.5, self.jac.as_ref());
            let tangent = raw.tangent.expect("a Jacobian method yields tangents");
            let l = loss::smoothness(tangent, SmoothnessNorm::Squared) + raw.value.mean();
            drop(l.backward());
            sync(&self.device)
        })
    }
}

/// One Adam step of a fit, frame after frame (the `fit_step` rows): the synthetic
/// protocol's Affinity(-H) step by [`FitStep::synthetic`], any fit by [`FitStep::new`].
pub struct FitStep<'a> {
    device: Device,
    trainer: Trainer<Model, TrajectoryObjective<'a>>,
    frames: usize,
    lr: f64,
    k: usize,
}

impl<'a> FitStep<'a> {
    /// A fit of `config` to `train` on `device`, stepped at the schedule's learning rate.
    pub fn new(config: &FitConfig, train: &'a Trajectories, device: &Device) -> Result<Self> {
        Ok(FitStep {
            device: device.clone(),
            trainer: Trainer::from_config(config, train, device)?,
            frames: train.frames(),
            lr: config.schedule.learning_rate,
            k: 0,
        })
    }

    /// The synthetic protocol's step (`train`: its training points), Affinity with
    /// `L_H` at 0.1 when `smoothness`, else the trajectory L1 alone.
    pub fn synthetic(
        train: &'a Trajectories,
        method: JacobianKind,
        smoothness: bool,
        device: &Device,
    ) -> Result<Self> {
        FitStep::new(&synthetic_config(method, smoothness), train, device)
    }

    /// One step on the next frame, synced.
    pub fn run(&mut self) -> Result<()> {
        self.trainer.step(self.k % self.frames, self.lr)?;
        self.k += 1;
        sync(&self.device)
    }
}

/// The synthetic protocol's Affinity fit, with `L_H` at 0.1 when `smoothness`.
pub fn synthetic_config(method: JacobianKind, smoothness: bool) -> FitConfig {
    FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
        .with_smoothness_weight(if smoothness { 0.1 } else { 0.0 })
        .with_jacobian(method)
}

/// One chunk of evaluation ([`crate::warp::WARP_CHUNK`] points) through a method's value
/// path, on the backend's plain (non-autodiff) device (the `warp` rows).
pub struct WarpStep {
    device: Device,
    field: DomaField,
    x: Tensor<2>,
    jac: Box<dyn JacobianMethod>,
}

impl WarpStep {
    /// The step on `backend` by `method`.
    pub fn new(backend: BackendKind, method: JacobianKind) -> Result<Self> {
        let device = backend.device()?;
        Ok(WarpStep {
            field: DomaFieldConfig::new(Variant::Affinity).init(0, &device),
            x: random_points(crate::warp::WARP_CHUNK, 13, &device),
            jac: method.method(),
            device,
        })
    }

    /// One step, synced.
    pub fn run(&self) -> Result<()> {
        let y = self
            .field
            .warp_values(self.x.clone(), 0.5, self.jac.as_ref())
            .warped
            .value;
        sync(&self.device)?;
        drop(y);
        Ok(())
    }
}
