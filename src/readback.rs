//! Device → host reads, in one place, counted.
//!
//! A read of a tensor's values makes the host wait for the device to finish everything
//! queued before it (a sync). On a GPU every sync is a stall: the host stops feeding
//! kernels while the device drains. So doma reads only through this module, and clippy
//! refuses Burn's read methods anywhere else in the crate (`disallowed-methods` in
//! `clippy.toml`; the tests, examples and benchmarks may read freely).
//!
//! [`reads`] counts the reads this process has made. `tests/process/host_sync.rs` uses it to
//! show what the fit loop promises: [`crate::train::Trainer::step`] reads nothing,
//! and [`crate::train::Trainer::iteration`] reads once, its losses, after its last step.
//!
//! What the counter does not see: reads inside Burn itself. Burn's record machinery reads
//! the parameters when a checkpoint is encoded (every `checkpoint_every` iterations, not in
//! a step); the operations a step runs (matmuls, elementwise kernels, the autodiff
//! backward, Adam) read nothing back.

use std::sync::atomic::{AtomicU64, Ordering};

use burn::tensor::{Device, Element, Tensor, kind::Basic};

use crate::{DomaError, Result};

static READS: AtomicU64 = AtomicU64::new(0);

/// How many device → host reads (and explicit syncs) doma has made in this process.
pub fn reads() -> u64 {
    READS.load(Ordering::Relaxed)
}

fn count() {
    READS.fetch_add(1, Ordering::Relaxed);
}

/// The values of `t`, row-major, converted to `E` (one read).
pub fn to_vec<E: Element, const D: usize, K: Basic>(t: Tensor<D, K>) -> Result<Vec<E>> {
    count();
    #[allow(clippy::disallowed_methods)] // The one place that reads.
    t.try_into_vec_as::<E>()
        .map_err(|e| DomaError::Device(format!("reading a tensor back failed: {e:?}")))
}

/// Waits for everything queued on `device` (one sync); benchmarks time steps with it.
pub fn sync(device: &Device) -> Result<()> {
    count();
    #[allow(clippy::disallowed_methods)] // The one place that syncs.
    device
        .sync()
        .map_err(|e| DomaError::Device(format!("the device failed to sync: {e:?}")))
}
