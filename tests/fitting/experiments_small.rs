//! The 2-D image and fluid experiments' building blocks on hand-computed values, and tiny
//! end-to-end runs that check their records.

use crate::common;
use doma::backend::BackendKind;
use doma::data::Trajectories;
use doma::experiments::Experiment;
use doma::experiments::fluid::{self, FluidRecord, mean_motion};
use doma::experiments::image2d::{self, Image2dJob, Motion2d, grid};
use doma::field::Variant;
use doma::field::model::ModelName;

#[test]
fn the_pixel_grid_is_centred_and_y_up() {
    let g = grid(4);
    assert_eq!(g.len(), 16);
    // Row 0 is the top row (y = +0.75), column 0 the left (x = −0.75).
    assert_eq!(g[0], (-0.75, 0.75));
    assert_eq!(g[15], (0.75, -0.75));
}

#[test]
fn the_2d_motions_follow_their_schedules() {
    let t = 30;
    // Frame 0: rotation and shearing are the identity, scaling 0.5, translation −1.
    assert_eq!(Motion2d::Rotation.apply(0.3, -0.2, 0, t), (0.3, -0.2));
    assert_eq!(Motion2d::Shearing.apply(0.3, -0.2, 0, t), (0.3, -0.2));
    assert_eq!(Motion2d::Scaling.apply(0.4, -0.2, 0, t), (0.2, -0.1));
    assert_eq!(Motion2d::Translation.apply(0.3, -0.2, 0, t), (-0.7, -1.2));
    // Last frame: scale 1.5, shear 1.5, +1; rotation by 2π·29/30.
    assert_eq!(
        Motion2d::Scaling.apply(0.4, -0.2, 29, t),
        (0.4 * 1.5, -0.2 * 1.5)
    );
    let (x, y) = Motion2d::Shearing.apply(0.3, -0.2, 29, t);
    assert!(x.abs() < 1e-15 && y == -0.2, "0.3 + 1.5 · (−0.2) = 0");
    let (x, y) = Motion2d::Rotation.apply(1.0, 0.0, 15, t);
    assert!(
        (x + 1.0).abs() < 1e-12 && y.abs() < 1e-12,
        "half a turn at frame 15"
    );
}

#[test]
fn mean_motion_and_the_fluid_table_by_hand() {
    // Two points: one moves by (3, 4, 0) = 5, one stays: mean 2.5.
    let clip =
        Trajectories::new(2, 2, vec![0., 0., 0., 1., 1., 1., 3., 4., 0., 1., 1., 1.]).unwrap();
    assert_eq!(mean_motion(&clip), 2.5);
    let rec = |clip: usize, variant: ModelName, hidden: usize, epe: f64| FluidRecord {
        experiment: Experiment::Fluid,
        clip_start: clip,
        motion: 0.1,
        variant,
        hidden,
        iters: 1,
        epe_x1e4: epe,
        params: 0,
        checkpoint_bytes: 0,
        seconds: 0.0,
        curve: vec![],
    };
    let t = fluid::table(&[
        rec(10, ModelName::Dpf, 64, 100.0),
        rec(20, ModelName::Dpf, 64, 300.0),
        rec(10, ModelName::Dpf, 128, 50.0),
    ]);
    assert!(t.contains("2 clips"), "{t}");
    assert!(t.contains("200.00") && t.contains("50.00"), "{t}");
    // The records keep their JSON spelling: typed enums, the same strings as ever.
    let json = serde_json::to_value(rec(10, ModelName::DomaAffinity, 64, 1.0)).unwrap();
    assert_eq!(json["experiment"], "fluid");
    assert_eq!(json["variant"], "DOMA-Affinity");
    let back: FluidRecord = serde_json::from_value(json).unwrap();
    assert_eq!(back.variant, ModelName::DomaAffinity);
}

#[test]
fn a_tiny_image2d_run_writes_its_pictures() {
    let dir = common::scratch_path("doma-i2d");
    let job = Image2dJob {
        resolution: 16,
        frames: 4,
        motions: vec![Motion2d::Scaling],
        variants: vec![Variant::Trans, Variant::Affinity],
        widths: vec![8],
        iterations: 2,
        backend: BackendKind::Flex,
        seed: 0,
        quiet: true,
        png_dir: Some(dir.to_path_buf()),
    };
    let records = image2d::run(&job, |_| {}).unwrap();
    assert_eq!(records.len(), 2);
    assert!(
        records
            .iter()
            .all(|r| r.epe_x1e4.is_finite() && r.resolution == 16)
    );
    for name in [
        "scaling_truth.png",
        "scaling_trans_8.png",
        "scaling_affinity_8.png",
    ] {
        let png = std::fs::read(dir.join(name)).unwrap();
        assert_eq!(&png[..4], b"\x89PNG");
    }
    assert!(image2d::table(&records).contains("Affinity 8D"));
}

#[test]
fn a_tiny_fluid_run_records_its_learning_curve() {
    // 40 particles on a rotating ring, two 4-frame clips; the second one barely moves.
    let (frames, n) = (8usize, 40usize);
    let mut pos = Vec::new();
    for k in 0..frames {
        let a = if k < 4 {
            0.2 * k as f32
        } else {
            0.6 + 1e-5 * k as f32
        };
        for i in 0..n {
            let phi = std::f32::consts::TAU * i as f32 / n as f32;
            let r = 1.0 + 0.1 * (i % 3) as f32;
            pos.extend([r * (phi + a).cos(), r * (phi + a).sin(), 0.01 * i as f32]);
        }
    }
    let dir = common::scratch("doma-fluid");
    let data = dir.join("ring.traj");
    doma::data::traj::write_traj(&data, &Trajectories::new(frames, n, pos).unwrap()).unwrap();
    let job = fluid::FluidJob {
        data,
        clip_len: 4,
        start: 0,
        step: 4,
        clips: None,
        min_motion: 0.01,
        models: vec![
            doma::experiments::meshes::AlignModel::Dpf,
            doma::experiments::meshes::AlignModel::Affinity,
        ],
        widths: vec![16],
        iterations: 3,
        backend: BackendKind::Flex,
        seed: 0,
        quiet: true,
        eval_every: 2,
    };
    let (mut runs, mut skips) = (0, Vec::new());
    let records = fluid::run(&job, |_| runs += 1, |start, _| skips.push(start)).unwrap();
    // An explicit clip list runs those clips; one past the end is refused up front.
    let listed = fluid::FluidJob {
        clips: Some(vec![4]),
        models: vec![doma::experiments::meshes::AlignModel::Trans],
        min_motion: 0.0,
        eval_every: 0,
        ..job.clone()
    };
    let r = fluid::run(&listed, |_| {}, |_, _| {}).unwrap();
    assert_eq!(r.len(), 1);
    assert_eq!((r[0].clip_start, r[0].curve.len()), (4, 0));
    let past = fluid::FluidJob {
        clips: Some(vec![0, 5]),
        ..listed
    };
    let err = fluid::run(&past, |_| {}, |_, _| {}).unwrap_err();
    assert!(err.to_string().contains("clip 5"), "{err}");
    let pngs = fluid::curve_plots(&records, &dir.join("curves")).unwrap();
    assert_eq!(pngs, vec![dir.join("curves/fluid_clip0_16d.png")]);
    assert_eq!(&std::fs::read(&pngs[0]).unwrap()[..4], b"\x89PNG");
    assert_eq!(skips, vec![4]);
    assert_eq!((runs, records.len()), (2, 2));
    for r in &records {
        let its: Vec<usize> = r.curve.iter().map(|c| c.iteration).collect();
        assert_eq!(its, vec![2, 3], "{r:?}");
        // The curve's last point is the reported result.
        assert_eq!(r.curve[1].test_epe_x1e4, r.epe_x1e4, "{r:?}");
        assert!(r.curve.iter().all(|c| c.train_epe_x1e4 > 0.0), "{r:?}");
    }
}

#[test]
fn mesh_records_keep_their_json_spelling() {
    use doma::experiments::meshes::{AlignReg, MeshRecord};
    let r = MeshRecord {
        experiment: Experiment::MeshAlignment,
        sequence: "cdp".into(),
        variant: ModelName::DomaTrans,
        reg: AlignReg::Ah.into(),
        weight: Some(0.001),
        weight_search: None,
        iters: 1,
        backend: BackendKind::Flex,
        epe_x1e4: None,
        cd_x1e4: Some(1.0),
        cdn: None,
        std_e: None,
        std_v: None,
        params: 1,
        checkpoint_bytes: 1,
        seconds: 0.0,
    };
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["experiment"], "mesh_alignment");
    assert_eq!(json["variant"], "DOMA-Trans");
    assert_eq!(json["reg"], "ah");
    assert_eq!(json["backend"], "flex");
    assert_eq!(serde_json::from_value::<MeshRecord>(json).unwrap(), r);
    let table = doma::experiments::meshes::table(&[r]);
    assert!(table.contains("DOMA-Trans-AH"), "{table}");
}
