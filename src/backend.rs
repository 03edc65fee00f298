//! Picking the compute backend at the edge of the program.
//!
//! Burn 0.22 selects the backend at run time through a [`Device`] value, so the
//! library never names a backend type: the CLI maps `--backend` to a device here
//! and passes `&Device` down.

#![allow(deprecated)] // `Device::ndarray()` is deprecated in favour of flex, but stays selectable.

use burn::tensor::Device;
#[cfg(feature = "wgpu")]
use burn::tensor::{DeviceKind, DeviceType};
use serde::{Deserialize, Serialize};

use crate::{DomaError, Result};

/// The compute backends that doma is built with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum BackendKind {
    /// Burn's pure-Rust CPU backend (the default CPU device).
    Flex,
    /// The ndarray CPU backend.
    Ndarray,
    /// wgpu: Vulkan/Metal/DX12 GPUs, or Mesa's lavapipe on a machine without one.
    Wgpu,
}

impl BackendKind {
    /// A device of this backend (without autodiff), or an error naming why it
    /// cannot run here (for wgpu: no adapter).
    pub fn device(self) -> Result<Device> {
        match self {
            BackendKind::Flex => Ok(Device::flex()),
            BackendKind::Ndarray => Ok(Device::ndarray()),
            #[cfg(not(feature = "wgpu"))]
            BackendKind::Wgpu => Err(DomaError::BackendUnavailable {
                backend: "wgpu".into(),
                reason: "this build of doma has no wgpu backend: rebuild it with the `wgpu` \
                         feature (`cargo build --release --features wgpu`; for Python, \
                         `MATURIN_PEP517_ARGS=\"--features wgpu\" pip install ./python`)"
                    .into(),
            }),
            #[cfg(feature = "wgpu")]
            BackendKind::Wgpu => {
                if wgpu_available() {
                    if wgpu_software_only() {
                        static WARNED: std::sync::Once = std::sync::Once::new();
                        WARNED.call_once(|| eprintln!("warning: {SOFTWARE_WGPU}"));
                    }
                    Ok(Device::wgpu(DeviceKind::DefaultDevice))
                } else {
                    Err(DomaError::BackendUnavailable {
                        backend: "wgpu".into(),
                        reason: "no wgpu adapter was found (install a GPU driver, or Mesa's \
                                 lavapipe: apt-get install mesa-vulkan-drivers libvulkan1)"
                            .into(),
                    })
                }
            }
        }
    }
}

crate::names::value_names!(BackendKind);

/// Whether at least one wgpu adapter exists. Never panics: a missing Vulkan
/// loader is reported as "no adapter".
/// Always false in a build without the `wgpu` feature.
pub fn wgpu_available() -> bool {
    #[cfg(feature = "wgpu")]
    {
        let probe =
            std::panic::catch_unwind(|| Device::enumerate(DeviceType::Wgpu).into_vec().len());
        matches!(probe, Ok(n) if n > 0)
    }
    #[cfg(not(feature = "wgpu"))]
    false
}

/// What `--backend wgpu` prints (once per process) where the only adapter is a software
/// rasterizer.
pub const SOFTWARE_WGPU: &str = "wgpu found no GPU here, only a software rasterizer (such as \
    Mesa's lavapipe): it runs on the CPU, several times slower than --backend flex";

/// Whether every wgpu adapter of this machine is a software rasterizer (wgpu's `Cpu`
/// kind: lavapipe, llvmpipe, WARP). Never panics; false without the `wgpu` feature.
pub fn wgpu_software_only() -> bool {
    #[cfg(feature = "wgpu")]
    {
        let probe = std::panic::catch_unwind(|| {
            let cpu = Device::wgpu(DeviceKind::Cpu);
            let all = Device::enumerate(DeviceType::Wgpu).into_vec();
            !all.is_empty() && all.iter().all(|d| *d == cpu)
        });
        matches!(probe, Ok(true))
    }
    #[cfg(not(feature = "wgpu"))]
    false
}

/// Tunes glibc's allocator for training loops (a no-op elsewhere): keep freed memory in
/// the heap instead of returning it to the kernel, and serve large blocks from the heap
/// instead of fresh `mmap`s.
///
/// A training step allocates and frees tensors of a few MB each; with glibc's defaults
/// each one is a fresh `mmap` whose pages fault in on first touch, which measured 10–30 %
/// of an `Analytic` step on flex (docs/speed.md). Process-wide, so it is for
/// binaries to call at start-up (the `doma` CLI, the examples and benches do); a library
/// that embeds doma decides for itself.
pub fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it is safe to call at any time.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 256 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
        libc::mallopt(libc::M_TOP_PAD, 64 << 20);
    }
}

/// Makes flex Burn's default device for this process, unless `BURN_DEVICE` already names
/// one.
///
/// Why this exists: Burn 0.22 materialises a loaded optimizer state
/// (`ModuleOptimizer::load_record`, which resuming a fit calls) on `Device::default()`, and
/// takes no device argument; with wgpu compiled in, the default is wgpu. Pinning the
/// default to the CPU means resuming a CPU fit never needs a GPU adapter; the state moves
/// to the fit's own device at the next step. Burn reads the default only from the
/// `BURN_DEVICE` environment variable, so this is the one process-wide setting in doma.
///
/// # Safety
/// It sets an environment variable: call it before any other thread exists (first thing
/// in `main`).
pub unsafe fn pin_default_device() {
    if std::env::var_os("BURN_DEVICE").is_none() {
        // SAFETY: the caller guarantees that no other thread exists yet.
        unsafe { std::env::set_var("BURN_DEVICE", "flex") };
    }
}

/// Whether `device` (with or without autodiff) is one of the CPU backends, flex or ndarray.
pub fn runs_on_cpu(device: &Device) -> bool {
    let plain = device.clone().without_autodiff();
    plain == Device::flex() || plain == Device::ndarray()
}

/// Runs `f` on a thread of rayon's global pool and waits for it.
///
/// Why: the CPU backends (flex's ops, its GEMM, the fused SIREN op) split their work with
/// rayon. Called from outside the pool, every parallel region hands its work to the pool
/// and parks the caller on a latch: a wake-up and a park per region, dozens per training
/// step, which measured about a tenth of an `Analytic` step on flex (docs/speed.md). Called from a pool thread, a region starts on that thread and the others
/// join by work stealing. Runs `f` here when already on a pool thread, and when `device`
/// is not a CPU backend ([`runs_on_cpu`]): wgpu's fusion streams are per thread, and moving
/// a step between threads would move it between streams.
pub fn on_worker<R: Send>(device: &Device, f: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() || !runs_on_cpu(device) {
        return f();
    }
    rayon::scope(|_| f())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(deprecated)]
    fn the_cpu_backends_are_told_apart_from_wgpu_with_and_without_autodiff() {
        assert!(runs_on_cpu(&Device::flex()));
        assert!(runs_on_cpu(&Device::flex().autodiff()));
        assert!(runs_on_cpu(&Device::ndarray().autodiff()));
        #[cfg(feature = "wgpu")]
        {
            assert!(!runs_on_cpu(&Device::wgpu(DeviceKind::DefaultDevice)));
            assert!(!runs_on_cpu(
                &Device::wgpu(DeviceKind::DefaultDevice).autodiff()
            ));
        }
    }

    /// Runs in a build without the feature (`cargo test --release --lib`), not in CI's.
    #[cfg(not(feature = "wgpu"))]
    #[test]
    fn wgpu_in_a_build_without_it_is_refused_naming_the_feature_and_the_command() {
        let e = BackendKind::Wgpu.device().unwrap_err().to_string();
        assert!(
            e.contains("`wgpu` feature") && e.contains("cargo build --release --features wgpu"),
            "{e}"
        );
    }

    #[test]
    fn a_machine_with_only_lavapipe_is_told_apart_from_one_with_a_gpu() {
        // Without the feature there is no wgpu to ask.
        #[cfg(not(feature = "wgpu"))]
        assert!(!wgpu_available() && !wgpu_software_only());
        // CI installs Mesa's lavapipe and has no GPU (.ci/run); elsewhere the answer depends
        // on the machine, and only its consistency is checked.
        if std::env::var_os("CI").is_some() && cfg!(feature = "wgpu") {
            assert!(wgpu_available(), "CI installs lavapipe");
            assert!(wgpu_software_only(), "CI's only wgpu adapter is lavapipe");
        }
        if !wgpu_available() {
            assert!(!wgpu_software_only());
        }
    }

    #[test]
    fn on_worker_runs_the_closure_on_a_pool_thread() {
        assert_eq!(rayon::current_thread_index(), None);
        let index = on_worker(&Device::flex().autodiff(), rayon::current_thread_index);
        assert!(index.is_some());
        #[allow(deprecated)]
        let ndarray = Device::ndarray();
        assert!(on_worker(&ndarray, rayon::current_thread_index).is_some());
        #[cfg(feature = "wgpu")]
        {
            let wgpu = Device::wgpu(DeviceKind::DefaultDevice);
            assert_eq!(on_worker(&wgpu, rayon::current_thread_index), None);
        }
    }
}
