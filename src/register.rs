//! Guided mesh alignment (Sec. 4.2): the objective of Eq. 14, DPF's Eq. 3 plus the
//! smoothness term `L_H` (DESIGN and the issues call it Eq. 12). A motion field warps a
//! template's surface samples onto each frame's target cloud (no correspondence, like
//! scans), steered by sparse guidance keypoints whose correspondence is known (like
//! SMPL-X vertices).
//!
//! Per step (one frame, frames in a fresh random order each iteration; REFERENCE §5.1):
//! `w_V · L1(y(keypoints), keypoints_k) + w_CD(it) · CD(y(X), S_k) + w_A · AIAP(y(X), X)
//! + w_H · L_H(keypoints + 0.1ε)`, where `X` are fixed samples of the template surface
//! (their AIAP neighbourhoods are found once) and `S_k` are points drawn afresh on frame
//! `k`'s target surface at every step.
//!
//! **The Chamfer weight schedule** (from the authors' code; the paper does not mention it):
//! `w_CD(it) = 1e3 · 0.95^(n − it − 1)` when `it > 0.25 n`, else 0. So the Chamfer term is
//! off for the first quarter (the guidance alone places the template) and matters only in
//! the last ~100 iterations. The learning rate decays linearly from the first iteration
//! (the authors' `num_epochs_fix` is ≈ 0).

use std::time::Instant;

use burn::config::Config;
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use crate::data::Trajectories;
use crate::data::mesh::{SurfaceSamples, TriMesh, as_points};
use crate::field::MotionField;
use crate::jacobian::JacobianKind;
use crate::loss::{self, AiapNeighbourhoods, SmoothnessNorm};
use crate::train::{Fitted, IterationRecord};
use crate::{DomaError, Result};

/// The weights and sizes of a guided alignment (REFERENCE §5.1 unless stated).
#[derive(Config, Debug)]
pub struct RegistrationConfig {
    /// Iterations (passes over all frames); the authors run 2000.
    #[config(default = 2000)]
    pub iterations: usize,
    /// Adam's base learning rate.
    #[config(default = 1e-4)]
    pub learning_rate: f64,
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
    /// How the spatial Jacobian of `L_H` is computed.
    #[config(default = "JacobianKind::Autodiff")]
    pub jacobian: JacobianKind,
    /// Seeds the samples, the frame order and the jitter.
    #[config(default = 0)]
    pub seed: u64,
    /// No progress bar.
    #[config(default = false)]
    pub quiet: bool,
}

impl RegistrationConfig {
    /// The Chamfer weight during iteration `it` (0-based) of the schedule above.
    pub fn chamfer_weight_at(&self, it: usize) -> f64 {
        let n = self.iterations;
        if (it as f64) > self.chamfer_start * n as f64 {
            self.chamfer_weight * self.chamfer_decay.powi((n - it - 1) as i32)
        } else {
            0.0
        }
    }

    /// The learning-rate factor in iteration `it`: linear decay from the start,
    /// `1 − it / (n + 1)`.
    pub fn lr_factor(&self, it: usize) -> f64 {
        1.0 - it as f64 / (self.iterations + 1) as f64
    }

    /// Refuses values that cannot run.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(DomaError::InvalidConfig(m));
        if self.iterations == 0 || self.canonical_samples == 0 || self.target_samples == 0 {
            return bad("iterations and sample counts must be at least 1".into());
        }
        for (name, w) in [
            ("learning rate", self.learning_rate),
            ("guidance weight", self.guidance_weight),
            ("Chamfer weight", self.chamfer_weight),
            ("Chamfer decay", self.chamfer_decay),
            ("AIAP weight", self.aiap_weight),
            ("smoothness weight", self.smoothness_weight),
            ("smoothness jitter", self.smoothness_jitter),
        ] {
            if !(w.is_finite() && w >= 0.0) {
                return bad(format!("{name} {w} must be finite and non-negative"));
            }
        }
        Ok(())
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

/// Aligns `field` (parameters on `device.autodiff()`) to `task` by Eq. 14. Returns the
/// fitted field (a validation snapshot) and its history; `trajectory_loss` in the history is
/// the guidance L1.
pub fn register<M: MotionField + Module>(
    field: M,
    task: &RegistrationTask,
    config: &RegistrationConfig,
    device: &Device,
) -> Result<Fitted<M>> {
    config.validate()?;
    task.validate()?;
    let ad = device.clone().autodiff();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed.wrapping_add(0x000A_116E));
    let template = &task.template;
    let samples = SurfaceSamples::draw(
        &template.vertices,
        &template.faces,
        config.canonical_samples,
        &mut rng,
    )?;
    let canonical = samples.points(&template.vertices, &template.faces);
    let neighbourhoods = if config.aiap_weight > 0.0 {
        Some(AiapNeighbourhoods::new(&canonical, config.aiap_neighbours)?)
    } else {
        None
    };
    let g = task.keypoints.points();
    let nc = canonical.len();
    let keypoints0 = task.keypoints.frame(0).to_vec();
    // Keypoints and template samples go through the field together: [G + Nc, 3].
    let mut x_host = keypoints0.clone();
    x_host.extend_from_slice(canonical.as_flattened());
    let x = Tensor::<2>::from_data(TensorData::new(x_host, [g + nc, 3]), &ad);
    let key_targets: Vec<Tensor<2>> = (0..task.keypoints.frames())
        .map(|k| task.keypoints.frame_tensor(k, &ad))
        .collect();
    let target_poses: Vec<Vec<[f32; 3]>> = (0..task.targets.frames())
        .map(|k| as_points(task.targets.frame(k)))
        .collect();
    let method = config.jacobian.method();
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();

    let bar = crate::train::progress_bar(config.iterations, config.quiet);
    let start = Instant::now();
    let frames = task.keypoints.frames();
    let mut field = field;
    let mut history = Vec::with_capacity(config.iterations);
    for it in 0..config.iterations {
        let lr = config.learning_rate * config.lr_factor(it);
        let w_cd = config.chamfer_weight_at(it);
        let mut order: Vec<usize> = (0..frames).collect();
        order.shuffle(&mut rng);
        let mut step_losses = Vec::with_capacity(frames);
        for &k in &order {
            let t = task.keypoints.time(k);
            // The value path of the field's Jacobian method (fused sine layers for Analytic).
            let y = field
                .warp_values(x.clone(), t, method.as_ref())
                .warped
                .value;
            let y_key = y.clone().narrow(0, 0, g);
            let y_can = y.narrow(0, g, nc);
            let guidance = loss::trajectory_l1(y_key, key_targets[k].clone());
            let mut total = guidance.clone().mul_scalar(config.guidance_weight);
            if w_cd > 0.0 {
                let s = SurfaceSamples::draw(
                    &target_poses[k],
                    &task.target_faces,
                    config.target_samples,
                    &mut rng,
                )?;
                let pts = s.points(&target_poses[k], &task.target_faces);
                let target = Tensor::<2>::from_data(
                    TensorData::new(pts.as_flattened().to_vec(), [pts.len(), 3]),
                    &ad,
                );
                total = total + loss::chamfer(y_can.clone(), target).mul_scalar(w_cd);
            }
            if let Some(nb) = &neighbourhoods {
                total = total + loss::aiap(y_can, nb).mul_scalar(config.aiap_weight);
            }
            if config.smoothness_weight > 0.0 {
                let jittered: Vec<f32> = keypoints0
                    .iter()
                    .map(|&v| {
                        v + (config.smoothness_jitter * crate::train::gaussian(&mut rng)) as f32
                    })
                    .collect();
                let p = Tensor::<2>::from_data(TensorData::new(jittered, [g, 3]), &ad);
                let raw = field.raw_dual(p, t, Some(method.as_ref()));
                let tangent = raw.tangent.expect("a Jacobian method yields tangents");
                total = total
                    + loss::smoothness(tangent, SmoothnessNorm::Charbonnier)
                        .mul_scalar(config.smoothness_weight);
            }
            step_losses.push(Tensor::cat(
                vec![guidance.detach(), total.clone().detach()],
                0,
            ));
            let grads = GradientsParams::from_grads(total.backward(), &field);
            field = optim.step(lr, field, grads);
        }
        let (guidance_mean, total_mean) = crate::train::read_step_losses(step_losses, &order, it)?;
        let record = IterationRecord {
            iteration: it,
            learning_rate: lr,
            trajectory_loss: guidance_mean,
            total_loss: total_mean,
            seconds: start.elapsed().as_secs_f64(),
        };
        bar.set_message(format!(
            "guide {:.2e}  loss {:.2e}",
            record.trajectory_loss, record.total_loss
        ));
        bar.inc(1);
        history.push(record);
    }
    bar.finish_and_clear();
    Ok(Fitted {
        field: field.valid(),
        history,
        seconds: start.elapsed().as_secs_f64(),
        steps: config.iterations * frames,
    })
}
