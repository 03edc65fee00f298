//! Checkpoints: a fitted field's parameters as a burnpack (`.bpk`) file, written atomically
//! (to a temporary file in the same folder, then renamed), optionally in `f16`, next to the
//! `config.json` that rebuilds the module (docs/design.md §5). Tab. 3 reports their size.

use std::path::Path;

use burn::module::{Module, ModuleMapper, Param};
use burn::store::ModuleRecord;
use burn::tensor::{DType, Tensor};
use serde::{Deserialize, Serialize};

use crate::io::write_atomic;
use crate::{DomaError, Result};

/// The float precision of a checkpoint's parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Precision {
    /// 32-bit floats: loads back bit-exactly.
    #[default]
    F32,
    /// 16-bit floats: half the bytes; loads back rounded to `f16` and cast to the
    /// module's precision.
    F16,
}

/// Casts every float parameter to `dtype`.
struct CastTo(DType);

impl ModuleMapper for CastTo {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let dtype = self.0;
        param.map(|t| t.cast(dtype))
    }
}

/// Renumbers every parameter `0, 1, 2, …` in module order. Burn draws parameter ids at
/// random, and a burnpack stores them, so two identical fits would write different files;
/// with these ids a reproduction can be checked with a checksum.
struct StableIds(u64);

impl ModuleMapper for StableIds {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let id = burn::module::ParamId::from(self.0);
        self.0 += 1;
        Param::initialized(id, param.into_value())
    }
}

/// `module` with its parameters renumbered `0, 1, 2, …` (see [`encode_stable`]). Only for
/// saving a result: an optimizer's state is keyed by the ids it was built with.
pub fn with_stable_ids<M: Module>(module: M) -> M {
    module.map(&mut StableIds(0))
}

/// [`encode_checkpoint`] of `module` with stable parameter ids: the same weights give the
/// same bytes. What `model.bpk` holds.
pub fn encode_stable<M: Module>(module: M, precision: Precision) -> Result<Vec<u8>> {
    encode_checkpoint(with_stable_ids(module), precision)
}

/// The burnpack bytes of `module`'s parameters in `precision`.
pub fn encode_checkpoint<M: Module>(module: M, precision: Precision) -> Result<Vec<u8>> {
    let module = match precision {
        Precision::F32 => module,
        Precision::F16 => module.map(&mut CastTo(DType::F16)),
    };
    let bytes = module
        .into_record()
        .into_bytes()
        .map_err(|e| DomaError::Device(format!("cannot serialise the checkpoint: {e}")))?;
    Ok(bytes.to_vec())
}

/// Writes `module`'s parameters to `path` (a `.bpk` file) atomically; returns its size in
/// bytes.
pub fn save_checkpoint<M: Module>(module: M, path: &Path, precision: Precision) -> Result<u64> {
    let bytes = encode_checkpoint(module, precision)?;
    write_atomic(path, &bytes)?;
    Ok(bytes.len() as u64)
}

/// Counts the parameters whose values are not all finite.
struct NonFinite {
    index: usize,
    first_bad: Option<usize>,
}

impl burn::module::ModuleVisitor for NonFinite {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let finite = crate::readback::to_vec::<f64, D, _>(param.val())
            .map(|v| v.iter().all(|x| x.is_finite()))
            .unwrap_or(false);
        if !finite && self.first_bad.is_none() {
            self.first_bad = Some(self.index);
        }
        self.index += 1;
    }
}

/// The shapes of a module's parameter tensors, in visiting order.
#[derive(Default)]
struct Shapes(Vec<Vec<usize>>);

impl burn::module::ModuleVisitor for Shapes {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.0.push(param.val().dims().to_vec());
    }
}

fn shapes<M: Module>(module: &M) -> Vec<Vec<usize>> {
    let mut s = Shapes::default();
    module.visit(&mut s);
    s.0
}

/// Loads the burnpack `bytes` into `module` (a freshly initialised module of the same
/// shape), casting them to the module's precision. Bytes that are not a burnpack, or hold
/// other shapes, are [`DomaError::InvalidData`]; [`load_checkpoint`] names the file.
pub fn decode_checkpoint<M: Module>(module: M, bytes: &[u8]) -> Result<M> {
    let record = ModuleRecord::from_bytes(burn::tensor::Bytes::from_bytes_vec(bytes.to_vec()))
        .map_err(|e| DomaError::InvalidData(format!("not a burnpack checkpoint: {e}")))?
        .cast_to_module_dtype();
    // Loading a record takes its tensors as they are: a checkpoint of another width would
    // load, and run, as a model its config does not describe.
    let expected = shapes(&module);
    let module = module
        .try_load_record(record)
        .map_err(|e| DomaError::InvalidData(format!("does not fit the model: {e}")))?;
    let found = shapes(&module);
    if found.len() != expected.len() {
        return Err(DomaError::InvalidData(format!(
            "holds {} parameter tensors, but the model has {}",
            found.len(),
            expected.len()
        )));
    }
    if let Some(i) = (0..found.len()).find(|&i| found[i] != expected[i]) {
        return Err(DomaError::InvalidData(format!(
            "parameter tensor {i} has shape {:?}, but the model's is {:?}",
            found[i], expected[i]
        )));
    }
    // NaN weights would surface later as NaN predictions blamed on the data.
    let mut check = NonFinite {
        index: 0,
        first_bad: None,
    };
    module.visit(&mut check);
    match check.first_bad {
        Some(i) => Err(DomaError::InvalidData(format!(
            "parameter tensor {i} of the checkpoint holds NaN or infinite values"
        ))),
        None => Ok(module),
    }
}

/// Loads the parameters in `path` into `module` (see [`decode_checkpoint`]). A file that
/// is not a burnpack, or that holds other shapes, is [`DomaError::Malformed`].
pub fn load_checkpoint<M: Module>(module: M, path: &Path) -> Result<M> {
    let bytes = std::fs::read(path).map_err(|e| DomaError::io(path, e))?;
    decode_checkpoint(module, &bytes).map_err(|e| DomaError::Malformed {
        path: path.to_path_buf(),
        reason: match e {
            DomaError::InvalidData(reason) => reason,
            other => other.to_string(),
        },
    })
}
