//! The fused step against Burn's autodiff step on the same weights and draws, against
//! central finite differences in f64, and inside the trainer.

use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::data::Trajectories;
use crate::field::{DomaField, DomaFieldConfig, MotionField, Variant};
use crate::jacobian::Analytic;
use crate::siren::WithSirenShape;
use crate::train::{FitConfig, SmoothnessSampling, Trainer, TrainerSnapshot, default_adam};

fn field(variant: Variant, ad: &Device) -> DomaField {
    DomaFieldConfig::new(variant)
        .with_hidden(32)
        .with_n_hidden(1)
        .init(3, ad)
}

/// A batch of `n` rows near the identity motion, with `p` `L_H` samples when `p > 0`.
fn batch(rng: &mut ChaCha8Rng, n: usize, p: usize, weighted: bool) -> HostBatch {
    let mut coords =
        |len: usize| -> Vec<f32> { (0..len).map(|_| rng.random_range(-0.8f32..0.8)).collect() };
    let x0 = coords(3 * n);
    let noise = coords(3 * n);
    let target = x0.iter().zip(&noise).map(|(x, e)| x + 0.1 * e).collect();
    let samples = (p > 0).then(|| coords(3 * p));
    let weights = weighted.then(|| coords(n).iter().map(|w| w.abs() + 0.1).collect());
    HostBatch {
        time: rng.random_range(-1.0..1.0),
        x0,
        target,
        weights,
        samples,
    }
}

fn tensor(values: &[f32], cols: usize, device: &Device) -> Tensor<2> {
    Tensor::from_data(
        TensorData::new(values.to_vec(), [values.len() / cols, cols]),
        device,
    )
}

/// Burn's step: the terms `TrajectoryObjective` builds, on the autodiff device.
fn burn_losses(field: &DomaField, b: &HostBatch, loss: StepLoss, ad: &Device) -> [Tensor<1>; 2] {
    let x0 = tensor(&b.x0, 3, ad);
    let on_rows = loss.smoothness_weight > 0.0 && b.samples.is_none();
    let warp = if on_rows {
        field.warp_dual(x0, b.time, &Analytic)
    } else {
        field.warp_values(x0, b.time, &Analytic)
    };
    let weights = b.weights.as_ref().map(|w| tensor(w, 1, ad));
    let data = crate::loss::trajectory_loss(
        warp.warped.value.clone(),
        tensor(&b.target, 3, ad),
        loss.penalty,
        weights,
    );
    let mut total = data.clone();
    if loss.smoothness_weight > 0.0 {
        let raw = match &b.samples {
            Some(s) => field.raw_dual(tensor(s, 3, ad), b.time, &Analytic),
            None => warp.raw,
        };
        let h = crate::loss::smoothness(raw.tangent.unwrap(), loss.smoothness_norm);
        total = total + h.mul_scalar(loss.smoothness_weight);
    }
    [data, total]
}

fn scalar(t: Tensor<1>) -> f64 {
    crate::readback::to_vec::<f64, 1, _>(t).unwrap()[0]
}

fn flat(field: &DomaField) -> Vec<f32> {
    read_params(&field.siren).unwrap()
}

/// Burn's gradient of `total`, in the flat layout.
fn flat_grad(field: &DomaField, grads: &burn::tensor::Gradients) -> Vec<f32> {
    let mut out = Vec::new();
    for layer in field
        .siren
        .sine
        .iter()
        .chain(std::iter::once(&field.siren.output))
    {
        let mut push = |t: Option<Tensor<2>>| {
            out.extend(crate::readback::to_vec::<f32, 2, _>(t.unwrap()).unwrap());
        };
        push(layer.weight.val().grad(grads));
        if let Some(b) = &layer.bias {
            push(b.val().grad(grads).map(|g| g.unsqueeze_dim::<2>(0)));
        }
    }
    out
}

/// The loss terms of each case, with whether the rows carry weights and how many `L_H`
/// samples the batch has (0: `L_H`, when on, on the training rows).
fn cases() -> [(StepLoss, bool, usize); 4] {
    let loss = |penalty, smoothness_weight, smoothness_norm| StepLoss {
        penalty,
        smoothness_weight,
        smoothness_norm,
    };
    [
        (
            loss(DataPenalty::L1, 0.0, SmoothnessNorm::Squared),
            false,
            0,
        ),
        (
            loss(DataPenalty::L1, 0.05, SmoothnessNorm::Squared),
            false,
            16,
        ),
        (
            loss(
                DataPenalty::Huber { delta: 0.05 },
                0.05,
                SmoothnessNorm::Charbonnier,
            ),
            true,
            0,
        ),
        (
            loss(
                DataPenalty::Charbonnier { epsilon: 0.02 },
                0.05,
                SmoothnessNorm::Charbonnier,
            ),
            true,
            16,
        ),
    ]
}

/// 100 steps of every variant and every case: each step from the same weights and the
/// same draws, the fused step's losses, gradient and updated parameters equal Burn's
/// autodiff step and Adam to f32 round-off. After each step Burn's field takes the fused
/// parameters, so that the comparison is per step (two f32 fits drift apart over many
/// steps, as two orders of summation do); each side keeps its own Adam moments.
#[test]
fn every_variant_steps_as_burns_autodiff_step_for_100_steps() {
    let ad = Device::flex().autodiff();
    let lr = 1e-3;
    for variant in Variant::ALL {
        for (case, &(loss, weighted, p)) in cases().iter().enumerate() {
            let mut burn_field = field(variant, &ad);
            let adam = adam_settings(&default_adam()).unwrap();
            let mut fused =
                FusedStep::<f32>::from_siren(&burn_field.siren, variant, loss, adam).unwrap();
            let mut optim = default_adam().init();
            let mut rng = ChaCha8Rng::seed_from_u64(case as u64);
            for step in 0..100 {
                let b = batch(&mut rng, 24, p, weighted);
                let [data, total] = burn_losses(&burn_field, &b, loss, &ad);
                let (bd, bt) = (scalar(data), scalar(total.clone()));
                let grads = total.backward();
                let g_burn = flat_grad(&burn_field, &grads);
                let (losses, g_fused) = fused.gradients(&b.batch());
                let g_fused = g_fused.unwrap();
                let what = format!("{variant:?} case {case} step {step}");
                assert!(
                    (losses.data - bd).abs() <= 1e-5 * (1.0 + bd.abs()),
                    "{what}: data {} vs {bd}",
                    losses.data
                );
                assert!(
                    (losses.total - bt).abs() <= 1e-5 * (1.0 + bt.abs()),
                    "{what}: total {} vs {bt}",
                    losses.total
                );
                let scale = g_burn.iter().fold(0f32, |m, g| m.max(g.abs()));
                for (i, (a, b)) in g_fused.iter().zip(&g_burn).enumerate() {
                    assert!(
                        (a - b).abs() <= 1e-4 * scale,
                        "{what}: gradient {i}: {a} vs {b}"
                    );
                }
                let grads = GradientsParams::from_grads(grads, &burn_field);
                burn_field = optim.step(lr, burn_field, grads);
                let Optimizer::Adam(adam) = &mut fused.optimizer else {
                    unreachable!("a fresh step takes Adam's update")
                };
                adam.update(&mut fused.params, &g_fused, lr);
                let after = flat(&burn_field);
                for (i, (a, b)) in fused.params().iter().zip(&after).enumerate() {
                    assert!(
                        (a - b).abs() <= 1e-6 + 1e-5 * b.abs(),
                        "{what}: parameter {i}: {a} vs {b}"
                    );
                }
                burn_field = fused.write_back(burn_field);
            }
        }
    }
}

/// The gradient of every variant and every case against central differences of the
/// total loss, in f64, on entries of every layer.
#[test]
fn the_gradient_matches_finite_differences_in_f64() {
    let ad = Device::flex().autodiff();
    for variant in Variant::ALL {
        for (case, &(loss, weighted, p)) in cases().iter().enumerate() {
            let burn_field = field(variant, &ad);
            let adam = adam_settings(&default_adam()).unwrap();
            let mut fused =
                FusedStep::<f64>::from_siren(&burn_field.siren, variant, loss, adam).unwrap();
            let b = batch(
                &mut ChaCha8Rng::seed_from_u64(10 + case as u64),
                6,
                p,
                weighted,
            );
            let as64 = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
            let (x0, target) = (as64(&b.x0), as64(&b.target));
            let (weights, samples) = (
                b.weights.as_deref().map(as64),
                b.samples.as_deref().map(as64),
            );
            let batch = StepBatch {
                time: b.time,
                x0: &x0,
                target: &target,
                weights: weights.as_deref(),
                samples: samples.as_deref(),
            };
            let (_, grad) = fused.gradients(&batch);
            let grad = grad.unwrap();
            let base = fused.params().to_vec();
            let h = 1e-6;
            // Entries of the first, a hidden and the output layer, weights and biases.
            let len = base.len();
            for i in [0, 5, 130, 200, len / 2, len - 20, len - 1] {
                let mut at = |v: f64| {
                    let mut p = base.clone();
                    p[i] = v;
                    fused.set_params(&p);
                    fused.gradients(&batch).0.total
                };
                let fd = (at(base[i] + h) - at(base[i] - h)) / (2.0 * h);
                assert!(
                    (grad[i] - fd).abs() <= 1e-5 * (1.0 + fd.abs()),
                    "{variant:?} case {case} parameter {i}: {} vs {fd}",
                    grad[i]
                );
            }
            fused.set_params(&base);
        }
    }
}

/// 30 points on a rotation over 4 frames.
fn tracks() -> Trajectories {
    let (t, n) = (4, 30);
    let mut pos = Vec::with_capacity(t * n * 3);
    for k in 0..t {
        let a = 0.2 * k as f32;
        for i in 0..n {
            let (x, y, z) = (
                (i as f32 * 0.37).sin(),
                (i as f32 * 0.71).cos(),
                i as f32 / 30.0 - 0.5,
            );
            pos.extend([a.cos() * x - a.sin() * y, a.sin() * x + a.cos() * y, z]);
        }
    }
    Trajectories::new(t, n, pos).unwrap()
}

fn config(step: StepKind) -> FitConfig {
    scaled_config(step, None)
}

fn scaled_config(step: StepKind, time_scale: Option<f64>) -> FitConfig {
    let field = DomaFieldConfig::new(Variant::Affinity)
        .with_hidden(32)
        .with_time_scale(time_scale);
    FitConfig::doma(field)
        .with_jacobian(JacobianKind::Analytic)
        .with_smoothness_weight(0.01)
        .with_smoothness_sampling(
            SmoothnessSampling::new()
                .with_max_points(Some(8))
                .with_jitter(0.01),
        )
        .with_points_per_step(Some(12))
        .with_step(Some(step))
}

/// Inside the trainer the fused fit draws the same rows and samples as the composed one:
/// their first iteration's losses agree to round-off, and the fits stay close; also for a
/// field that reads its time scaled (a long recording's), which the fused step must read
/// the same way (the first losses of the two scales differ).
#[test]
fn a_fused_fit_follows_the_composed_fit() {
    let data = tracks();
    let device = Device::flex();
    let mut firsts = Vec::new();
    for time_scale in [None, Some(7.0)] {
        let mut losses = Vec::new();
        for step in [StepKind::Composed, StepKind::Fused] {
            let config = scaled_config(step, time_scale);
            let mut trainer = Trainer::from_config(&config, &data, &device).unwrap();
            assert_eq!(trainer.is_fused(), step == StepKind::Fused);
            let first = trainer.iteration().unwrap().total_loss;
            for _ in 0..4 {
                trainer.iteration().unwrap();
            }
            let last = trainer.history().last().unwrap().total_loss;
            losses.push((first, last));
        }
        let [(c0, c1), (f0, f1)] = [losses[0], losses[1]];
        assert!(
            (c0 - f0).abs() <= 1e-5 * c0,
            "time scale {time_scale:?}, first iteration: {c0} vs {f0}"
        );
        assert!(
            (c1 - f1).abs() <= 1e-2 * c1,
            "time scale {time_scale:?}, fifth iteration: {c1} vs {f1}"
        );
        firsts.push(c0);
    }
    assert!(
        (firsts[0] - firsts[1]).abs() > 1e-3 * firsts[0],
        "the scale changed nothing: {firsts:?}"
    );
}

/// Fits `cfg` for 4 iterations whole, and for 2 then resumed from a checkpoint for the
/// rest: the same parameters, bit for bit. Returns the checkpoint and the whole fit's
/// parameters.
fn resumes_exactly(cfg: &FitConfig, data: &Trajectories) -> (TrainerSnapshot, Vec<f32>) {
    let device = Device::flex();
    let cfg = cfg
        .clone()
        .with_schedule(crate::train::ScheduleConfig::new().with_iterations(4));
    let whole = Trainer::from_config(&cfg, data, &device)
        .unwrap()
        .run()
        .unwrap();
    let mut first = Trainer::from_config(&cfg, data, &device).unwrap();
    first.iteration().unwrap();
    first.iteration().unwrap();
    let snapshot = first.snapshot().unwrap();
    let mut second = Trainer::from_config(&cfg, data, &device).unwrap();
    second.restore(&snapshot).unwrap();
    let resumed = second.run().unwrap();
    let params = |f: &crate::field::model::Model| read_params::<f32>(f.siren().unwrap()).unwrap();
    assert_eq!(params(&whole.field), params(&resumed.field));
    (snapshot, params(&whole.field))
}

/// A fused fit stopped and resumed from its checkpoint ends where the uninterrupted fit
/// ends, bit for bit; a composed fit refuses the fused checkpoint.
#[test]
fn a_fused_fit_resumes_from_its_checkpoint_exactly() {
    let data = tracks();
    let (snapshot, _) = resumes_exactly(&config(StepKind::Fused), &data);
    let device = Device::flex();
    let mut composed = Trainer::from_config(&config(StepKind::Composed), &data, &device).unwrap();
    let err = composed.restore(&snapshot).unwrap_err().to_string();
    assert!(err.contains("fused step"), "{err}");
}

#[test]
fn the_fused_step_is_refused_where_it_does_not_apply_and_auto_falls_back() {
    let data = tracks();
    let device = Device::flex();
    let refused = |cfg: FitConfig, why: &str| {
        let err = refusal(&cfg, &data);
        assert!(err.contains("fused step") && err.contains(why), "{err}");
    };
    refused(
        config(StepKind::Fused).with_jacobian(JacobianKind::Autodiff),
        "analytic",
    );
    refused(
        config(StepKind::Fused).with_elasticity_weight(0.1),
        "elasticity",
    );
    refused(
        config(StepKind::Fused).with_frames_per_step(Some(2)),
        "one frame",
    );
    let auto = config(StepKind::Auto).with_elasticity_weight(0.1);
    assert!(
        !Trainer::from_config(&auto, &data, &device)
            .unwrap()
            .is_fused()
    );
    assert!(
        Trainer::from_config(&config(StepKind::Auto), &data, &device)
            .unwrap()
            .is_fused()
    );
}

/// A SOAP fit stopped and resumed from its checkpoint ends where the uninterrupted fit
/// ends, bit for bit; an Adam fit refuses its checkpoint, and it refuses an Adam one.
#[test]
fn a_soap_fit_resumes_from_its_checkpoint_exactly() {
    let data = tracks();
    let device = Device::flex();
    let soap = SoapConfig {
        every: 3,
        ..SoapConfig::default()
    };
    let cfg = config(StepKind::Fused).with_soap(Some(soap));
    let (snapshot, soap_params) = resumes_exactly(&cfg, &data);
    // SOAP moved the weights elsewhere than Adam does.
    let (adam_snapshot, adam_params) = resumes_exactly(&config(StepKind::Fused), &data);
    assert_ne!(soap_params, adam_params);
    let mut adam = Trainer::from_config(&config(StepKind::Fused), &data, &device).unwrap();
    let err = adam.restore(&snapshot).unwrap_err().to_string();
    assert!(err.contains("SOAP"), "{err}");
    let mut soap = Trainer::from_config(&cfg, &data, &device).unwrap();
    let err = soap.restore(&adam_snapshot).unwrap_err().to_string();
    assert!(err.contains("Adam"), "{err}");
}

/// Why a trainer for `cfg` on `data` cannot be built (it must not be).
fn refusal(cfg: &FitConfig, data: &Trajectories) -> String {
    match Trainer::from_config(cfg, data, &Device::flex()) {
        Ok(_) => panic!("the fit was not refused"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn soap_is_refused_without_the_fused_step() {
    let data = tracks();
    let soap = Some(SoapConfig::default());
    let err = refusal(&config(StepKind::Composed).with_soap(soap), &data);
    assert!(err.contains("SOAP is computed by the fused step"), "{err}");
    // `auto` falls back to the composed step, which cannot take SOAP: the fused step's
    // own reason is given.
    let auto = config(StepKind::Auto)
        .with_soap(soap)
        .with_elasticity_weight(0.1);
    let err = refusal(&auto, &data);
    assert!(err.contains("elasticity"), "{err}");
    let bad = config(StepKind::Fused).with_soap(Some(SoapConfig {
        beta_2: 1.0,
        ..SoapConfig::default()
    }));
    assert!(refusal(&bad, &data).contains("betas"));
}
