use std::path::Path;

use super::*;
use crate::field::model::ModelConfig;
use crate::train::select::WeightSearch;

#[test]
fn an_entry_reads_from_json_and_refuses_unknown_fields() {
    let spec: RunSpec = serde_json::from_str(
        r#"{"data": "a.traj", "model": "scaled-se3", "h_weight": "auto", "frames": [0, 20]}"#,
    )
    .unwrap();
    assert_eq!(spec.model, Some(ModelChoice::ScaledSe3));
    assert_eq!(spec.h_weight, Some(Weight::Auto));
    assert_eq!(spec.frames, Some([0, 20]));
    let err = serde_json::from_str::<RunSpec>(r#"{"data": "a", "iteration": 5}"#)
        .unwrap_err()
        .to_string();
    assert!(err.contains("iteration"), "{err}");
    let err = serde_json::from_str::<RunSpec>(r#"{"h_weight": -1}"#)
        .unwrap_err()
        .to_string();
    assert!(err.contains("non-negative"), "{err}");
}

#[test]
fn overrides_fall_back_to_the_defaults_and_paths_to_the_base() {
    let defaults = RunSpec {
        iterations: Some(50),
        seed: Some(3),
        ..RunSpec::default()
    };
    let item = RunSpec {
        data: Some("seq.traj".into()),
        seed: Some(7),
        ..RunSpec::default()
    }
    .or(&defaults)
    .unwrap()
    .relative_to(Path::new("/data"));
    assert_eq!(item.iterations, Some(50));
    assert_eq!(item.seed, Some(7));
    assert_eq!(item.data.as_deref(), Some(Path::new("/data/seq.traj")));
    let fit = item.fit_config(|| unreachable!("not DPF")).unwrap();
    assert_eq!((fit.schedule.iterations, fit.seed), (50, 7));
    let dpf = RunSpec {
        model: Some(ModelChoice::Dpf),
        ..RunSpec::default()
    }
    .fit_config(|| Ok(12))
    .unwrap();
    assert_eq!(dpf.model.frames(), Some(12));
}

/// A DOMA field of a recording longer than 1,000 frames reads its time stretched by the
/// frames over 1,000, unless the options choose a scale; up to 1,000 frames nothing is
/// set (the paper's field); a model without a DOMA field refuses a scale.
#[test]
fn a_long_recordings_field_reads_its_time_stretched() {
    let dir = tempfile::tempdir().unwrap();
    let prepared = |frames: usize, time_scale: Option<f64>| {
        let path = dir.path().join(format!("walk{frames}.npy"));
        let positions: Vec<f32> = (0..frames * 2 * 3)
            .map(|e| (e % 7) as f32 + (e / 6) as f32 * 1e-3)
            .collect();
        crate::data::npy::write_npy(&path, &[frames, 2, 3], &positions).unwrap();
        let spec = RunSpec {
            data: Some(path),
            iterations: Some(1),
            time_scale,
            ..RunSpec::default()
        };
        let fit = spec.prepare(&WeightSearch::default(), |_| {}).unwrap();
        match fit.config.fit.model {
            ModelConfig::Doma(c) => c.time_scale,
            other => panic!("{other:?}"),
        }
    };
    assert_eq!(prepared(1000, None), None);
    assert_eq!(prepared(2500, None), Some(2.5));
    assert_eq!(prepared(2500, Some(0.5)), Some(0.5));
    let err = RunSpec {
        model: Some(ModelChoice::Dpf),
        time_scale: Some(2.0),
        ..RunSpec::default()
    }
    .fit_config(|| Ok(12))
    .unwrap_err()
    .to_string();
    assert!(err.contains("time_scale"), "{err}");
}
