//! The parameters between Burn's module and the fused step's flat buffer: read once from
//! the SIREN, written back into the module (same parameter ids) after an iteration.

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{Tensor, TensorData};

use super::{Float, FusedStep};
use crate::Result;
use crate::jacobian::analytic::OpSpec;
use crate::siren::Siren;

impl FusedStep<f32> {
    /// Writes the flat parameters into `field`'s float parameters, in the order the
    /// module visits them (the analytic op's layout), keeping their ids (which key a
    /// checkpoint's Adam state) and their `require_grad`.
    pub fn write_back<M: Module>(&self, field: M) -> M {
        let mut writer = Writer {
            flat: &self.params,
            offset: 0,
        };
        let field = field.map(&mut writer);
        debug_assert_eq!(writer.offset, self.params.len());
        field
    }
}

/// The SIREN's parameters in the analytic op's flat layout, read back from the device.
pub(super) fn read_params<E: Float>(siren: &Siren) -> Result<Vec<E>> {
    let mut flat = Vec::with_capacity(OpSpec::of(siren, false).param_count());
    for layer in siren.sine.iter().chain(std::iter::once(&siren.output)) {
        let w = crate::readback::to_vec::<f64, 2, _>(layer.weight.val())?;
        flat.extend(w.into_iter().map(E::from_f64));
        if let Some(b) = &layer.bias {
            let b = crate::readback::to_vec::<f64, 1, _>(b.val())?;
            flat.extend(b.into_iter().map(E::from_f64));
        }
    }
    Ok(flat)
}

/// Writes consecutive slices of a flat buffer into every float parameter it visits.
struct Writer<'a> {
    flat: &'a [f32],
    offset: usize,
}

impl ModuleMapper for Writer<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        param.map(|tensor| {
            let shape = tensor.shape();
            let len = shape.num_elements();
            let values = self.flat[self.offset..self.offset + len].to_vec();
            self.offset += len;
            let device = tensor.device();
            let fresh = Tensor::<D>::from_data(TensorData::new(values, shape), &device);
            if tensor.is_require_grad() {
                fresh.require_grad()
            } else {
                fresh
            }
        })
    }
}
