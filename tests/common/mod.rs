//! Helpers shared by the integration tests.
#![allow(dead_code)]
// Tests read device values directly; the crate reads only through `doma::readback`.
#![allow(clippy::disallowed_methods)]

pub mod oracle;
pub mod png;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock};

use burn::tensor::{Device, FloatDType, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Burn's `backward` must not run in parallel threads (burn#5573): tests that call it
/// hold this lock.
static BACKWARD: Mutex<()> = Mutex::new(());

pub fn backward_lock() -> MutexGuard<'static, ()> {
    BACKWARD.lock().unwrap_or_else(|e| e.into_inner())
}

pub fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.try_into_vec_as::<f64>().unwrap()
}

pub fn tensor2(values: Vec<f64>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// A scratch path inside a fresh temporary folder (`tempfile`), removed with everything in
/// it when dropped. Reads as a `Path`.
pub struct Scratch {
    _root: tempfile::TempDir,
    path: PathBuf,
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<OsStr> for Scratch {
    fn as_ref(&self) -> &OsStr {
        self.path.as_os_str()
    }
}

fn temp_root(prefix: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("{prefix}-"))
        .tempdir()
        .expect("a temporary folder")
}

/// A fresh, empty folder named after `prefix`.
pub fn scratch(prefix: &str) -> Scratch {
    let root = temp_root(prefix);
    let path = root.path().to_path_buf();
    Scratch { _root: root, path }
}

/// A path that does not exist yet, in a fresh folder named after `prefix` (for outputs
/// that a command must create itself).
pub fn scratch_path(prefix: &str) -> Scratch {
    let root = temp_root(prefix);
    let path = root.path().join("out");
    Scratch { _root: root, path }
}

/// `‖a − b‖ / ‖b‖` (Euclidean over all entries), guarded against a zero reference.
pub fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "length mismatch");
    let diff: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt();
    let norm: f64 = b.iter().map(|y| y * y).sum::<f64>().sqrt();
    diff / norm.max(1e-30)
}

/// `n` random points in `[-1, 1]^3`, row-major.
pub fn random_points(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..3 * n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// A flex device computing in f64 (one per process: a device's float type is set once).
pub fn f64_flex() -> Device {
    static DEVICE: OnceLock<Device> = OnceLock::new();
    DEVICE
        .get_or_init(|| {
            let mut d = Device::flex();
            d.configure(FloatDType::F64).expect("flex runs in f64");
            d
        })
        .clone()
}

/// The wgpu device for a test, or `None` (after printing `SKIPPED` and why) when this
/// build has no wgpu (the `wgpu` feature) or this machine no adapter. Under CI (`CI` set to
/// anything but `false` or `0`), where the README's test command builds the feature and
/// `.ci/run` installs Mesa's lavapipe, either fails the test instead: a broken wgpu path
/// must not pass by skipping.
pub fn wgpu_device_or_skip(test: &str) -> Option<Device> {
    use doma::backend::{BackendKind, wgpu_available};
    if wgpu_available() {
        return Some(BackendKind::Wgpu.device().expect("an adapter exists"));
    }
    let why = if cfg!(feature = "wgpu") {
        "no wgpu adapter on this machine (install mesa-vulkan-drivers)"
    } else {
        "built without the wgpu feature (cargo test --release --features wgpu)"
    };
    let ci = std::env::var("CI").is_ok_and(|v| !matches!(v.as_str(), "" | "false" | "0"));
    assert!(
        !ci,
        "{test}: {why}, under CI (CI is set): the README's test command builds the feature and \
         .ci/run installs mesa-vulkan-drivers (lavapipe), so the wgpu path is broken"
    );
    eprintln!("SKIPPED {test}: {why}");
    None
}

/// Whether an external tool that a test needs is here. Without it the test is skipped
/// (says so and passes), except under CI (`CI` set), where `.ci/run` installs it: there
/// a missing tool fails the test.
pub fn tool_or_skip(test: &str, tool: &str, present: bool) -> bool {
    if present {
        return true;
    }
    let ci = std::env::var("CI").is_ok_and(|v| !matches!(v.as_str(), "" | "false" | "0"));
    assert!(
        !ci,
        "{test}: {tool} is missing under CI (CI is set); .ci/run installs it"
    );
    eprintln!("SKIPPED {test}: {tool} is not installed (see .ci/run)");
    false
}

/// The shipped faerie's frames `frames` (one motion: 112..123 is its "wave" clip) as a
/// simulated tracker sees them (`doma::data::tracker`), and the mesh's OBJ path.
pub fn faerie_tracker_view(
    frames: std::ops::Range<usize>,
) -> (doma::data::tracker::TrackerView, PathBuf) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let truth = doma::data::traj::read_traj(root.join("md2_faerie.traj"))
        .unwrap()
        .select_frames(frames, 1)
        .unwrap();
    let obj = root.join("md2_faerie.obj");
    let faces = doma::data::mesh::read_obj(&obj).unwrap().faces;
    let view = doma::data::tracker::simulate(
        &truth,
        &faces,
        &doma::data::tracker::TrackerConfig::default(),
    )
    .unwrap();
    (view, obj)
}

/// A new fit of `config` for [`doma::run::fit_run`], its data read.
pub fn new_fit(config: doma::run::RunConfig) -> Option<doma::run::NewFit> {
    Some(doma::run::NewFit::load(config).unwrap())
}
