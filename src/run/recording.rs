//! One recording filled end to end, as `doma fill` does it for each file: fitted into a run
//! folder of its own (a temporary one unless kept), completed into the output in the
//! format its extension names, the run folder removed; or completed without a fit. The
//! table of its filled gaps is `gap_table.rs`, their page `report.rs`.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use burn::tensor::Device;

use super::{
    Completion, FillPolicy, FitOutcome, RunDir, RunSpec, complete_run_with, complete_without_fit,
    fit_run, output_kind_for,
};
use crate::train::select::WeightSearch;
use crate::{DomaError, Result};

/// How [`fill_recording`] fills a recording.
#[derive(Clone, Debug, Default)]
pub struct RecordingFill {
    /// Fit a field first (doma's fill, the blend); `false`: the fit-free fill
    /// ([`complete_without_fit`]).
    pub fit: bool,
    /// Which gaps are filled, and by what.
    pub policy: FillPolicy,
    /// The fit's options beside the data (the defaults of `doma fit` where empty).
    pub spec: RunSpec,
    /// Keep the run folder here instead of a temporary one that is removed.
    pub keep_run: Option<PathBuf>,
}

/// Fills the gaps of the recording `input` into `out` ([`RecordingFill`]): its format by
/// its extension, checked before the fit. The run folder is removed afterwards, whether
/// the fill succeeded or not, unless [`RecordingFill::keep_run`] names it. A fit stopped
/// by `interrupt` is an error.
pub fn fill_recording(
    input: &Path,
    out: &Path,
    how: &RecordingFill,
    device: &Device,
    interrupt: &AtomicBool,
) -> Result<Completion> {
    output_kind_for(input, out)?;
    if !how.fit {
        return complete_without_fit(input, out, None, how.policy);
    }
    let (dir, temporary) = match &how.keep_run {
        Some(dir) => (dir.clone(), false),
        None => (temporary_run(), true),
    };
    let run = RunDir::new(&dir);
    let done = (|| {
        let spec = RunSpec {
            data: Some(input.to_path_buf()),
            ..how.spec.clone()
        };
        let new = spec.prepare(&WeightSearch::default(), |_| {})?;
        match fit_run(&run, Some(new), device, interrupt, None, false)? {
            FitOutcome::Finished(_) => complete_run_with(&run, out, None, how.policy, device),
            FitOutcome::Interrupted { .. } => Err(DomaError::Usage(format!(
                "{}: the fit was interrupted",
                input.display()
            ))),
        }
    })();
    if temporary {
        let _ = std::fs::remove_dir_all(&dir);
    }
    done
}

/// A fresh folder name under the system's temporary folder, for one run.
fn temporary_run() -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    std::env::temp_dir().join(format!("doma-fill-{}-{n}", std::process::id()))
}
