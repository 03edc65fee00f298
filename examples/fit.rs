//! Fitting a motion field from Rust, end to end: a fit recipe built in code, the `Trainer`,
//! the end-point error on held-out points, a run folder saved and loaded back, points
//! warped to another frame, and the motion exported as an animated glTF.
//!
//! ```text
//! cargo run --release --example fit
//! ```
//!
//! It fits DOMA-Affinity to a 20-frame clip of the shipped `md2_faerie` (a quarter of the
//! vertices), about half a minute on 2 cores. The run folder it writes, `runs/example-fit`,
//! is the one `doma fit` writes, so `doma eval`, `doma view` and `doma export` read it too.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use doma::checkpoint::Precision;
use doma::data::mesh::as_points;
use doma::data::normalized_time;
use doma::export::{ExportOptions, export_gltf};
use doma::field::{DomaFieldConfig, Variant};
use doma::io::save_json;
use doma::metrics::{EPE_SCALE, evaluate_epe};
use doma::prelude::*;
use doma::run::{RunConfig, RunDir};
use doma::train::{FitConfig, Trainer};
use doma::warp::warp_points;

fn main() -> anyhow::Result<()> {
    // The backend is a value: `Device::ndarray()` or
    // `Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)` run the same code.
    let device = Device::flex();

    // The recipe: DOMA-Affinity (Eq. 4), the paper's SIREN, 200 iterations of one Adam
    // step per frame, and the smoothness loss `L_H` (Eq. 13) at a small weight.
    let fit = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
        .with_iterations(200)
        .with_smoothness_weight(1e-3);

    // The data and its split, as a run folder records them: the clip's frame 0 is the
    // canonical frame, 25 % of the vertices train and 75 % are held out.
    let data = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj"));
    let mut run = RunConfig::new(data, fit);
    run.test_fraction = 0.75;
    run.frames = Some([112, 132]);
    run.validate()?;
    let sequence = run.load()?;
    let (train, test) = run.split(&sequence.trajectories)?;
    let test = test.expect("a test fraction of 0.75 holds tracks out");
    println!(
        "{}: {} frames, {} training and {} held-out points",
        sequence.name,
        train.frames(),
        train.points(),
        test.points()
    );

    // The fit: one loop for every model (`Trainer`), here with a progress bar.
    let fitted = Trainer::from_config(&run.fit, &train, &device)?
        .progress(true)
        .run()?;
    let epe = evaluate_epe(&fitted.field, &test, &device)?;
    println!(
        "fitted in {:.1} s ({} Adam steps); held-out EPE x1e-4: {:.2}",
        fitted.seconds,
        fitted.steps,
        epe * EPE_SCALE
    );

    // Save it as a run folder: the recipe and data (`config.json`) and the parameters
    // (`model.bpk`); then load it back as the CLI would.
    let dir = RunDir::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("runs/example-fit"));
    std::fs::create_dir_all(&dir.dir)?;
    save_json(&run, &dir.config())?;
    let bytes = fitted.field.encode(Precision::F32)?;
    doma::io::write_atomic(&dir.model(), &bytes)?;
    let field = dir.load_field(&dir.load_config()?, &device)?;
    let reloaded = evaluate_epe(&field, &test, &device)?;
    println!(
        "saved {} ({} bytes of parameters); reloaded EPE x1e-4: {:.2}",
        dir.dir.display(),
        bytes.len(),
        reloaded * EPE_SCALE
    );
    anyhow::ensure!(reloaded == epe, "a reloaded f32 model gives the same EPE");

    // Warp the held-out points from the canonical frame to frame 10 of the clip: each
    // point x moves to y = A(x, t) x + u(x, t).
    let k = 10;
    let start = as_points(test.frame(0));
    let moved = warp_points(&field, &start, normalized_time(k, test.frames()), &device)?;
    let truth = as_points(test.frame(k));
    let error: f64 = moved
        .iter()
        .zip(&truth)
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs() as f64).sum::<f64>())
        .sum::<f64>()
        / moved.len() as f64;
    println!("frame {k}: mean L1 error of the warped held-out points {error:.4}");

    // The motion of the clip's mesh as one animated glTF (morph targets), for Blender or
    // three.js.
    let glb = dir.dir.join("motion.glb");
    let summary = export_gltf(&dir, None, &glb, &ExportOptions::default(), &device)?;
    println!(
        "wrote {}: {} vertices, {} triangles, {} frames",
        glb.display(),
        summary.vertices,
        summary.triangles,
        summary.frames
    );
    Ok(())
}
