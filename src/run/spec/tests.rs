use std::path::Path;

use super::*;

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
