//! Guided mesh alignment (Sec. 4.2): the objective of Eq. 14, DPF's Eq. 3 plus the
//! smoothness term `L_H`. A motion field warps a
//! template's surface samples onto each frame's target cloud (no correspondence, like
//! scans), steered by sparse guidance keypoints whose correspondence is known (like
//! SMPL-X vertices).
//!
//! Per step (one frame, frames in a fresh random order each iteration; docs/reference.md §5.1):
//! `w_V · L1(y(keypoints), keypoints_k) + w_CD(it) · CD(y(X), S_k) + w_A · AIAP(y(X), X)
//! + w_H · L_H(keypoints + 0.1ε)`, where `X` are fixed samples of the template surface
//! (their AIAP neighbourhoods are found once) and `S_k` are points drawn afresh on frame
//! `k`'s target surface at every step. The loop is the common [`crate::train::Trainer`];
//! this module supplies its objective ([`RegistrationObjective`]).
//!
//! **The Chamfer weight schedule** (from the authors' code; the paper does not mention it):
//! `w_CD(it) = 1e3 · 0.95^(n − it − 1)` when `it > 0.25 n`, else 0. So the Chamfer term is
//! off for the first quarter (the guidance alone places the template) and matters only in
//! the last ~100 iterations. The learning rate decays linearly from the first iteration
//! (the authors' `num_epochs_fix` is ≈ 0).

use burn::config::Config;
use burn::module::Module;
use burn::optim::AdamConfig;
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::data::Trajectories;
use crate::data::mesh::{SurfaceSamples, TriMesh, as_points};
use crate::field::MotionField;
use crate::jacobian::{JacobianKind, JacobianMethod};
use crate::loss::{self, AiapNeighbourhoods, SmoothnessNorm};
use crate::train::{
    Fitted, Objective, ScheduleConfig, Trainer, WithSchedule, check_weights, default_adam, gaussian,
};
use crate::{DomaError, Result};

/// The weights and sizes of a guided alignment (docs/reference.md §5.1 unless stated).
#[derive(Config, Debug)]
pub struct RegistrationConfig {
    /// Iterations (the authors run 2000) and Adam's base rate; the learning rate decays
    /// linearly from the first iteration (the authors' `num_epochs_fix` is ≈ 0).
    #[config(default = "ScheduleConfig::new().with_iterations(2000).with_lr_flat_iterations(0)")]
    pub schedule: ScheduleConfig,
    /// Adam's hyper-parameters.
    #[config(default = "default_adam()")]
    pub optimizer: AdamConfig,
    /// The guidance L1 weight `α₂` (w_V).
    #[config(default = 1.0)]
    pub guidance_weight: f64,
    /// The Chamfer weight `α₁` at the last iteration.
    #[config(default = 1e3)]
    pub chamfer_weight: f64,
    /// The per-iteration decay of the Chamfer weight, counted back from the last iteration.
    #[config(default = 0.95)]
    pub chamfer_decay: f64,
    /// The fraction of the iterations before the Chamfer term switches on.
    #[config(default = 0.25)]
    pub chamfer_start: f64,
    /// The AIAP weight `α₃` ("-A": 1; 0 = off).
    #[config(default = 0.0)]
    pub aiap_weight: f64,
    /// The AIAP neighbourhood size `K` (itself included).
    #[config(default = 5)]
    pub aiap_neighbours: usize,
    /// The smoothness weight `α₄` ("-H": 0.001; 0 = off). Charbonnier per entry.
    #[config(default = 0.0)]
    pub smoothness_weight: f64,
    /// The Gaussian jitter of the keypoints that carry `L_H`.
    #[config(default = 0.1)]
    pub smoothness_jitter: f64,
    /// Template surface samples `X` (fixed; the authors draw 10 000 per step).
    #[config(default = 10000)]
    pub canonical_samples: usize,
    /// Target surface samples per step (the authors: 10 000).
    #[config(default = 10000)]
    pub target_samples: usize,
    /// How the spatial Jacobian of `L_H` is computed (and the value path of SIREN layers).
    #[config(default = "JacobianKind::Autodiff")]
    pub jacobian: JacobianKind,
    /// Seeds the samples, the frame order and the jitter.
    #[config(default = 0)]
    pub seed: u64,
}

impl WithSchedule for RegistrationConfig {
    fn schedule_mut(&mut self) -> &mut ScheduleConfig {
        &mut self.schedule
    }
}

impl RegistrationConfig {
    /// The Chamfer weight during iteration `it` (0-based) of the schedule above.
    pub fn chamfer_weight_at(&self, it: usize) -> f64 {
        let n = self.schedule.iterations;
        if (it as f64) > self.chamfer_start * n as f64 {
            self.chamfer_weight * self.chamfer_decay.powi((n - it - 1) as i32)
        } else {
            0.0
        }
    }

    /// Refuses values that cannot run.
    pub fn validate(&self) -> Result<()> {
        self.schedule.validate()?;
        if self.canonical_samples == 0 || self.target_samples == 0 {
            return Err(DomaError::InvalidConfig(
                "sample counts must be at least 1".into(),
            ));
        }
        check_weights(&[
            ("guidance weight", self.guidance_weight),
            ("Chamfer weight", self.chamfer_weight),
            ("Chamfer decay", self.chamfer_decay),
            ("AIAP weight", self.aiap_weight),
            ("smoothness weight", self.smoothness_weight),
            ("smoothness jitter", self.smoothness_jitter),
        ])
    }
}

/// What is aligned: the template (frame 0), sparse guidance keypoints with known
/// trajectories, and each frame's target surface.
#[derive(Clone, Debug)]
pub struct RegistrationTask {
    /// The template mesh in the canonical frame.
    pub template: TriMesh,
    /// The guidance keypoints in every frame, `[T, G, 3]` (frame 0 = canonical).
    pub keypoints: Trajectories,
    /// Each frame's target surface: its vertices `[T, V, 3]`, sharing `target_faces`.
    pub targets: Trajectories,
    /// The target surfaces' triangles.
    pub target_faces: Vec<[u32; 3]>,
}

impl RegistrationTask {
    fn validate(&self) -> Result<()> {
        if self.keypoints.frames() != self.targets.frames() {
            return Err(DomaError::InvalidData(format!(
                "{} keypoint frames but {} target frames",
                self.keypoints.frames(),
                self.targets.frames()
            )));
        }
        crate::data::mesh::check_faces(&self.target_faces, self.targets.points())
            .map_err(DomaError::InvalidData)
    }
}

/// The objective of Eq. 14 for one step: guidance L1, the scheduled Chamfer term, AIAP
/// and `L_H` on jittered keypoints.
pub struct RegistrationObjective<'a> {
    task: &'a RegistrationTask,
    config: &'a RegistrationConfig,
    method: Box<dyn JacobianMethod>,
    ad: Device,
    /// Keypoints and template samples go through the field together: `[G + Nc, 3]`.
    x: Tensor<2>,
    keypoints0: Vec<f32>,
    canonical_len: usize,
    key_targets: Vec<Tensor<2>>,
    target_poses: Vec<Vec<[f32; 3]>>,
    neighbourhoods: Option<AiapNeighbourhoods>,
}

impl<'a> RegistrationObjective<'a> {
    /// Draws the template's surface samples from `rng` and finds their AIAP
    /// neighbourhoods (once).
    pub fn new(
        task: &'a RegistrationTask,
        config: &'a RegistrationConfig,
        device: &Device,
        rng: &mut ChaCha8Rng,
    ) -> Result<Self> {
        let ad = device.clone().autodiff();
        let template = &task.template;
        let samples = SurfaceSamples::draw(
            &template.vertices,
            &template.faces,
            config.canonical_samples,
            rng,
        )?;
        let canonical = samples.points(&template.vertices, &template.faces);
        let neighbourhoods = if config.aiap_weight > 0.0 {
            Some(AiapNeighbourhoods::new(&canonical, config.aiap_neighbours)?)
        } else {
            None
        };
        let g = task.keypoints.points();
        let keypoints0 = task.keypoints.frame(0).to_vec();
        let mut x_host = keypoints0.clone();
        x_host.extend_from_slice(canonical.as_flattened());
        Ok(RegistrationObjective {
            task,
            config,
            method: config.jacobian.method(),
            x: Tensor::<2>::from_data(TensorData::new(x_host, [g + canonical.len(), 3]), &ad),
            keypoints0,
            canonical_len: canonical.len(),
            key_targets: (0..task.keypoints.frames())
                .map(|k| task.keypoints.frame_tensor(k, &ad))
                .collect(),
            target_poses: (0..task.targets.frames())
                .map(|k| as_points(task.targets.frame(k)))
                .collect(),
            neighbourhoods,
            ad,
        })
    }

    /// The Chamfer term against fresh samples of frame `k`'s target surface.
    fn chamfer(&self, y_can: Tensor<2>, k: usize, rng: &mut ChaCha8Rng) -> Result<Tensor<1>> {
        let (pose, faces) = (&self.target_poses[k], &self.task.target_faces);
        let s = SurfaceSamples::draw(pose, faces, self.config.target_samples, rng)?;
        let pts = s.points(pose, faces);
        let target = Tensor::<2>::from_data(
            TensorData::new(pts.as_flattened().to_vec(), [pts.len(), 3]),
            &self.ad,
        );
        Ok(loss::chamfer(y_can, target))
    }

    /// `L_H` (Charbonnier) at the keypoints jittered by `smoothness_jitter`.
    fn smoothness<M: MotionField>(&self, field: &M, t: f64, rng: &mut ChaCha8Rng) -> Tensor<1> {
        let sigma = self.config.smoothness_jitter;
        let jittered: Vec<f32> = self
            .keypoints0
            .iter()
            .map(|&v| v + (sigma * gaussian(rng)) as f32)
            .collect();
        let g = self.task.keypoints.points();
        let p = Tensor::<2>::from_data(TensorData::new(jittered, [g, 3]), &self.ad);
        let raw = field.raw_dual(p, t, self.method.as_ref());
        let tangent = raw.tangent.expect("raw_dual yields tangents");
        loss::smoothness(tangent, SmoothnessNorm::Charbonnier)
    }
}

impl<M: MotionField> Objective<M> for RegistrationObjective<'_> {
    fn primary_name(&self) -> &'static str {
        "guide"
    }

    fn frames(&self) -> usize {
        self.task.keypoints.frames()
    }

    fn step_loss(
        &mut self,
        field: &M,
        k: usize,
        iteration: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<(Tensor<1>, Tensor<1>)> {
        let config = self.config;
        let t = self.task.keypoints.time(k);
        let g = self.task.keypoints.points();
        // The value path of the field's Jacobian method (fused sine layers for Analytic).
        let y = field
            .warp_values(self.x.clone(), t, self.method.as_ref())
            .warped
            .value;
        let y_key = y.clone().narrow(0, 0, g);
        let y_can = y.narrow(0, g, self.canonical_len);
        let guidance = loss::trajectory_l1(y_key, self.key_targets[k].clone());
        let mut total = guidance.clone().mul_scalar(config.guidance_weight);
        let w_cd = config.chamfer_weight_at(iteration);
        if w_cd > 0.0 {
            total = total + self.chamfer(y_can.clone(), k, rng)?.mul_scalar(w_cd);
        }
        if let Some(nb) = &self.neighbourhoods {
            total = total + loss::aiap(y_can, nb).mul_scalar(config.aiap_weight);
        }
        if config.smoothness_weight > 0.0 {
            total = total
                + self
                    .smoothness(field, t, rng)
                    .mul_scalar(config.smoothness_weight);
        }
        Ok((guidance, total))
    }
}

/// Aligns `field` (parameters on `device.autodiff()`) to `task` by Eq. 14 through the
/// common loop ([`Trainer`]). Returns the fitted field (a validation snapshot) and its
/// history; `trajectory_loss` in the history is the guidance L1. `progress` shows a bar.
pub fn register<M: MotionField + Module>(
    field: M,
    task: &RegistrationTask,
    config: &RegistrationConfig,
    device: &Device,
    progress: bool,
) -> Result<Fitted<M>> {
    config.validate()?;
    task.validate()?;
    crate::field::check_method(&field, config.jacobian)?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed.wrapping_add(0x000A_116E));
    let objective = RegistrationObjective::new(task, config, device, &mut rng)?;
    Trainer::with_objective(
        field,
        objective,
        &config.optimizer,
        config.schedule.clone(),
        rng,
    )
    .progress(progress)
    .run()
}
