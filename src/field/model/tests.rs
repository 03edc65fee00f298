use super::*;
use crate::siren::WithSirenShape;

fn every_model(frames: usize) -> Vec<ModelConfig> {
    vec![
        ModelConfig::Doma(
            DomaFieldConfig::new(Variant::Affinity)
                .with_n_hidden(3)
                .with_time_scale(Some(2.0)),
        ),
        ModelConfig::Dpf(DpfConfig::new(frames).with_hidden(32)),
        ModelConfig::Mlp(MlpConfig::new().with_pe_octaves(6)),
        ModelConfig::Mlp(MlpConfig::new().with_layers(0)),
        ModelConfig::DctNerf(DctConfig::new(frames).with_layers(1)),
        ModelConfig::Banmo(BanmoConfig::new(frames)),
        ModelConfig::Banmo(BanmoConfig::new(frames).with_transform_layers(3)),
        ModelConfig::BoneCloud(BoneCloudConfig::new(frames)),
    ]
}

/// A field that reads its time scaled by `s` is the same SIREN read at `s·t`: its raw
/// outputs and their spatial Jacobians at `t` are, bit for bit, those of the unscaled field
/// (the same weights) at `s·t`.
#[test]
fn a_time_scaled_field_is_the_same_siren_at_the_scaled_time() {
    use crate::jacobian::Analytic;
    use burn::tensor::{Tensor, TensorData};
    let device = Device::flex();
    let config = DomaFieldConfig::new(Variant::Affinity).with_hidden(16);
    let plain = config.init(4, &device);
    let scaled = config.clone().with_time_scale(Some(12.0)).init(4, &device);
    let values = |t: Tensor<2>| crate::readback::to_vec::<f32, 2, _>(t).unwrap();
    let x = || {
        let p = vec![0.1f32, -0.4, 0.7, 0.5, 0.2, -0.9];
        Tensor::<2>::from_data(TensorData::new(p, [2, 3]), &device)
    };
    for t in [-1.0, -0.3, 0.25, 1.0] {
        let (a, b) = (
            scaled.raw_dual(x(), t, &Analytic),
            plain.raw_dual(x(), 12.0 * t, &Analytic),
        );
        let tangent = |d: &Dual| values(d.tangent.clone().unwrap().reshape([-1, 1]));
        assert_eq!(tangent(&a), tangent(&b), "t = {t}");
        assert_eq!(values(a.value), values(b.value), "t = {t}");
        assert_ne!(
            values(scaled.raw_values(x(), t, &Analytic)),
            values(plain.raw_values(x(), t, &Analytic)),
            "t = {t}"
        );
    }
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 2e6] {
        let refused = config.clone().with_time_scale(Some(bad)).validate();
        assert!(refused.is_err(), "time scale {bad}");
    }
    assert!(config.clone().with_time_scale(Some(1e6)).validate().is_ok());
    assert_eq!(crate::field::time_scale_for(1000), None);
    assert_eq!(crate::field::time_scale_for(1001), Some(1.001));
    assert_eq!(crate::field::time_scale_for(12_000), Some(12.0));
}

#[test]
fn the_closed_form_counts_are_the_built_models_counts() {
    for m in every_model(7) {
        assert_eq!(m.checked_params(), Some(m.num_params()), "{m:?}");
    }
}

#[test]
fn sizes_past_memory_or_usize_are_refused_before_anything_is_built() {
    let huge = usize::MAX / 3;
    let refused = [
        ModelConfig::Doma(DomaFieldConfig::new(Variant::Se3).with_n_hidden(1_000_000_000)),
        ModelConfig::Doma(DomaFieldConfig::new(Variant::Se3).with_hidden(huge)),
        ModelConfig::Dpf(DpfConfig::new(huge)),
        ModelConfig::Mlp(MlpConfig::new().with_layers((1 << 60) + 1)),
        ModelConfig::Mlp(MlpConfig::new().with_d_in(0)),
        ModelConfig::Mlp(MlpConfig::new().with_d_out(7)),
        ModelConfig::DctNerf(DctConfig::new(10).with_coefficients(Some(huge))),
        ModelConfig::DctNerf(DctConfig::new(10).with_layers((1 << 60) + 1)),
        ModelConfig::Banmo(BanmoConfig::new(10).with_frequencies(1 << 62)),
        ModelConfig::Banmo(BanmoConfig::new(10).with_frequencies(64)),
        ModelConfig::Banmo(BanmoConfig::new(10).with_transform_layers(1_000_000_000)),
        ModelConfig::BoneCloud(BoneCloudConfig::new(10).with_bones(1 << 62)),
        ModelConfig::BoneCloud(BoneCloudConfig::new(10).with_sigma(-1.0)),
    ];
    for m in refused {
        let e = m.validate().unwrap_err().to_string();
        assert!(!e.is_empty(), "{m:?}");
    }
}

/// Every numeric field of every model's JSON set, one at a time, to a hostile value.
fn hostile_configs() -> Vec<(String, serde_json::Value)> {
    fn numbers(v: &serde_json::Value, path: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, v) in m {
                    path.push(k.clone());
                    numbers(v, path, out);
                    path.pop();
                }
            }
            serde_json::Value::Number(_) => out.push(path.clone()),
            _ => {}
        }
    }
    let hostile: Vec<serde_json::Value> = vec![
        0.into(),
        1.into(),
        63.into(),
        64.into(),
        65_535.into(),
        (1u64 << 31).into(),
        (1u64 << 32).into(),
        (1u64 << 53).into(),
        (1u64 << 62).into(),
        u64::MAX.into(),
        (-1).into(),
        (-1.5).into(),
        1e300.into(),
        1e-300.into(),
    ];
    let mut out = Vec::new();
    for model in every_model(5) {
        let base = serde_json::to_value(&model).unwrap();
        let mut paths = Vec::new();
        numbers(&base, &mut Vec::new(), &mut paths);
        for path in paths {
            for value in &hostile {
                let mut config = base.clone();
                let mut slot = &mut config;
                for key in &path {
                    slot = &mut slot[key.as_str()];
                }
                *slot = value.clone();
                out.push((format!("{} = {value}", path.join(".")), config));
            }
        }
    }
    out
}

#[test]
fn hostile_model_configs_are_refused_or_build_and_never_panic() {
    let device = Device::flex();
    let canonical: Vec<f32> = (0..30).map(|v| v as f32 * 0.1).collect();
    let (mut refused, mut built) = (0, 0);
    for (what, json) in hostile_configs() {
        let Ok(model) = serde_json::from_value::<ModelConfig>(json) else {
            refused += 1;
            continue;
        };
        let checked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| model.validate()));
        match checked {
            Err(_) => panic!("{what}: validate panicked"),
            Ok(Err(_)) => refused += 1,
            Ok(Ok(())) => {
                let params = model.checked_params().unwrap();
                assert!(params <= MAX_PARAMS, "{what}: {params}");
                // What passes is built (the small ones: a 10⁸ model is 400 MB).
                if params <= 2_000_000 {
                    let m = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        model.init(0, &canonical, &device)
                    }));
                    assert!(m.is_ok(), "{what}: init panicked");
                    assert_eq!(m.unwrap().param_count(), params, "{what}");
                    built += 1;
                }
            }
        }
    }
    assert!(
        refused > 100 && built > 20,
        "{refused} refused, {built} built"
    );
}
