//! Replays a PyTorch fit step by step in doma, from the same initial weights and the same
//! random draws, and reports where the two first differ.
//!
//! ```text
//! python3 scripts/torch_synthetic.py --motion shearing --dump steps.npz --dump-steps 50
//! cargo run --release --example torch_cross_check -- steps.npz
//! ```
//!
//! The `.npz` (written by `scripts/torch_synthetic.py`) holds the synthetic data, the SIREN's
//! initial weights, and for each step the frame, the learning rate, the jittered `L_H`
//! points and the losses, the first step's gradient and the weights after every step. doma
//! builds a DOMA-Affinity field from those weights and takes the same steps through its own
//! `Trainer` (Adam, the fused analytic op), with an objective that reads each step's `L_H`
//! points from the file instead of drawing them: the trajectory L1 plus `w_H · L_H`, as the
//! fit's own objective computes it. It prints, per step, the relative difference of the
//! losses and the largest difference of the weights, then the first step's gradient against
//! PyTorch's.

use anyhow::{Context, bail};
use burn::tensor::{Device, Tensor, TensorData};
use doma::data::npy::{NpyArray, read_npz};
use doma::field::{DomaField, MotionField, Variant};
use doma::jacobian::Analytic;
use doma::loss::{self, DataPenalty, SmoothnessNorm};
use doma::readback::to_vec;
use doma::siren::{LayerWeights, Siren};
use doma::train::{Objective, ScheduleConfig, Trainer, default_adam};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The SIREN of the synthetic benchmark: 4 → 128 → 128 → 128 → 12.
const WIDTHS: [usize; 5] = [4, 128, 128, 128, 12];
/// `w_H` of the "-H" rows.
const H_WEIGHT: f64 = 0.1;

/// The recorded data and draws, and the next step's index into them.
#[derive(Clone)]
struct Replay {
    canon: Vec<f32>,
    train: Vec<f32>,
    points: Vec<f32>,
    n: usize,
    frames: usize,
    step: usize,
    device: Device,
}

impl Objective<DomaField> for Replay {
    fn frames(&self) -> usize {
        self.frames
    }

    fn step_loss(
        &mut self,
        field: &DomaField,
        k: usize,
        _iteration: usize,
        _rng: &mut ChaCha8Rng,
    ) -> doma::Result<(Tensor<1>, Tensor<1>)> {
        let n = self.n;
        let t = -1.0 + 2.0 * k as f64 / (self.frames - 1) as f64;
        let tensor =
            |v: &[f32]| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [n, 3]), &self.device);
        let x0 = tensor(&self.canon);
        let target = tensor(&self.train[k * n * 3..(k + 1) * n * 3]);
        let warped = field.warp_values(x0, t, &Analytic).warped.value;
        let l1 = loss::trajectory_loss(warped, target, DataPenalty::L1, None);
        let pts = tensor(&self.points[self.step * n * 3..(self.step + 1) * n * 3]);
        let raw = field.raw_dual(pts, t, &Analytic);
        let h = loss::smoothness(raw.tangent.expect("tangents"), SmoothnessNorm::Squared)
            .mul_scalar(H_WEIGHT);
        self.step += 1;
        Ok((l1.clone(), l1 + h))
    }
}

/// PyTorch's flat `[w0, b0, w1, b1, …]` (weights `[out, in]`) as doma's layers.
fn layers(flat: &[f32]) -> Vec<LayerWeights> {
    let mut at = 0;
    WIDTHS
        .windows(2)
        .map(|w| {
            let (fan_in, fan_out) = (w[0], w[1]);
            let torch = &flat[at..at + fan_in * fan_out];
            let mut weight = vec![0.0; fan_in * fan_out];
            for o in 0..fan_out {
                for i in 0..fan_in {
                    weight[i * fan_out + o] = torch[o * fan_in + i] as f64;
                }
            }
            at += fan_in * fan_out;
            let bias = flat[at..at + fan_out].iter().map(|&b| b as f64).collect();
            at += fan_out;
            LayerWeights {
                fan_in,
                fan_out,
                weight,
                bias,
            }
        })
        .collect()
}

/// doma's layers in PyTorch's flat order.
fn flatten(layers: &[LayerWeights]) -> Vec<f64> {
    let mut out = Vec::new();
    for l in layers {
        for o in 0..l.fan_out {
            for i in 0..l.fan_in {
                out.push(l.weight[i * l.fan_out + o]);
            }
        }
        out.extend(&l.bias);
    }
    out
}

/// The held-out EPE ×1e4 of `field` on `test` (`[T, M, 3]`, frame 0 canonical): the L1 norm
/// of the error summed over xyz, averaged over every frame (frame 0 included) and point.
fn epe(field: &DomaField, test: &NpyArray, device: &Device) -> anyhow::Result<f64> {
    let (frames, m) = (test.shape[0], test.shape[1]);
    let frame = |k: usize| {
        Tensor::<2>::from_data(
            TensorData::new(test.data[k * m * 3..(k + 1) * m * 3].to_vec(), [m, 3]),
            device,
        )
    };
    let mut total = 0.0;
    for k in 0..frames {
        let t = -1.0 + 2.0 * k as f64 / (frames - 1) as f64;
        let err = (field.warp(frame(0), t) - frame(k)).abs().sum_dim(1).mean();
        let v: Vec<f64> = to_vec(err)?;
        total += v[0];
    }
    Ok(total / frames as f64 * 1e4)
}

/// The layer and tensor of flat index `at` (`w0`, `b0`, … `w3`, `b3`; 3 is the output).
fn layer_of(mut at: usize) -> String {
    for (l, w) in WIDTHS.windows(2).enumerate() {
        for (name, size) in [("w", w[0] * w[1]), ("b", w[1])] {
            if at < size {
                return format!("{name}{l}[{at}]");
            }
            at -= size;
        }
    }
    "?".into()
}

fn max_diff(a: &[f64], b: &[f32]) -> (f64, usize) {
    let mut worst = (0.0, 0);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let d = (x - *y as f64).abs();
        if d > worst.0 {
            worst = (d, i);
        }
    }
    worst
}

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .context("usage: torch_cross_check STEPS.npz (from scripts/torch_synthetic.py --dump)")?;
    let members = read_npz(&path)?;
    let get = |key: &str| -> anyhow::Result<&NpyArray> {
        members
            .iter()
            .find(|(k, _)| k == key || k.strip_suffix(".npy") == Some(key))
            .map(|(_, a)| a)
            .with_context(|| format!("{path}: no member {key}"))
    };
    let (canon, train, init) = (get("canon")?, get("train")?, get("init")?);
    let [frames, n, _] = train.shape[..] else {
        bail!("{path}: train is not [T, N, 3]");
    };
    let steps = get("frames")?.data.len();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let field = DomaField {
        siren: Siren::from_weights(&layers(&init.data), 30.0, &ad),
        variant: Variant::Affinity,
        time_scale: 1.0,
    };
    let replay = Replay {
        canon: canon.data.clone(),
        train: train.data.clone(),
        points: get("points")?.data.clone(),
        n,
        frames,
        step: 0,
        device: ad.clone(),
    };
    // The first step's gradient, outside the trainer (which does not expose it).
    let mut first = replay.clone();
    let k0 = get("frames")?.data[0] as usize;
    let (_, total) = first.step_loss(&field, k0, 0, &mut ChaCha8Rng::seed_from_u64(0))?;
    let grads = total.backward();
    let mut grad = Vec::new();
    for layer in field.siren.sine.iter().chain([&field.siren.output]) {
        let w: Vec<f64> = to_vec(
            layer
                .weight
                .val()
                .grad(&grads)
                .context("a weight gradient")?,
        )?;
        let b: Vec<f64> = to_vec(
            layer
                .bias
                .as_ref()
                .context("a bias")?
                .val()
                .grad(&grads)
                .context("a bias gradient")?,
        )?;
        let (fan_in, fan_out) = (layer.weight.dims()[0], layer.weight.dims()[1]);
        grad.push(LayerWeights {
            fan_in,
            fan_out,
            weight: w,
            bias: b,
        });
    }
    let grad = flatten(&grad);
    let torch_grad = &get("grad")?.data;
    let scale = torch_grad
        .iter()
        .fold(0.0f64, |m, &g| m.max((g as f64).abs()));
    let (worst, at) = max_diff(&grad, torch_grad);
    println!(
        "step 1 gradient: largest difference {worst:.3e} at entry {at} (largest entry {scale:.3e}); \
         sign differences: {}",
        grad.iter()
            .zip(torch_grad)
            .filter(|(a, b)| a.signum() != (**b as f64).signum() && **a != 0.0)
            .count()
    );

    let mut trainer = Trainer::with_objective(
        field,
        replay,
        &default_adam(),
        ScheduleConfig::new(),
        ChaCha8Rng::seed_from_u64(0),
    );
    let (l1s, totals, lrs) = (&get("l1")?.data, &get("total")?.data, &get("lrs")?.data);
    let (after, after_steps, torch_epe) = (
        &get("after")?.data,
        &get("after_steps")?.data,
        &get("epe")?.data,
    );
    let test = get("test")?;
    let count = init.data.len();
    println!(
        "step   L1 rel. diff  total rel. diff  max |Δw|   in         |Δw| > 1e-6   EPE doma  EPE torch"
    );
    let mut snapshot = 0;
    let mut worst_loss: f64 = 0.0;
    for s in 0..steps {
        let k = get("frames")?.data[s] as usize;
        let losses: Vec<f64> = to_vec(trainer.step(k, lrs[s] as f64)?)?;
        let rel = |a: f64, b: f32| (a - b as f64).abs() / (b as f64).abs();
        let (l1_rel, total_rel) = (rel(losses[0], l1s[s]), rel(losses[1], totals[s]));
        worst_loss = worst_loss.max(total_rel);
        if snapshot >= after_steps.len() || after_steps[snapshot] as usize != s + 1 {
            continue;
        }
        let w = flatten(&trainer.field().siren.to_weights());
        let torch = &after[snapshot * count..(snapshot + 1) * count];
        let (worst, at) = max_diff(&w, torch);
        let many = w
            .iter()
            .zip(torch)
            .filter(|(a, b)| (*a - **b as f64).abs() > 1e-6)
            .count();
        println!(
            "{:5}  {l1_rel:11.3e}  {total_rel:15.3e}  {worst:9.3e}  {:9}  {many:11}  {:9.2}  {:9.2}",
            s + 1,
            layer_of(at),
            epe(trainer.field(), test, &ad)?,
            torch_epe[snapshot]
        );
        snapshot += 1;
    }
    println!("largest relative difference of a step's total loss: {worst_loss:.3e}");
    Ok(())
}
