//! A fit's checkpoint: what a resumed fit needs besides the config and the data.

use burn::module::Module;
use burn::optim::AdamConfig;

use super::Trainer;
use crate::field::MotionField;
use crate::train::fused::is_fused_state;
use crate::train::objective::Objective;
use crate::train::record::{RngState, TrainerSnapshot};
use crate::{DomaError, Result};

impl<M: MotionField + Module, O: Objective<M>> Trainer<M, O> {
    /// Everything a resumed fit needs besides the config and the data: the field's
    /// parameters, Adam's state, the random stream's position and the history.
    pub fn snapshot(&self) -> Result<TrainerSnapshot> {
        // The fused step keeps its optimiser's state on the host, in its own record.
        let optimizer = match &self.fused {
            Some(fused) => fused.optimizer().to_bytes(),
            None => self
                .optim
                .into_bytes()
                .map_err(|e| DomaError::Device(format!("cannot serialise Adam's state: {e}")))?
                .to_vec(),
        };
        Ok(TrainerSnapshot {
            model: crate::checkpoint::encode_checkpoint(
                self.field().clone(),
                crate::checkpoint::Precision::F32,
            )?,
            optimizer,
            rng: RngState::of(&self.rng),
            iterations_done: self.history.len(),
            history: self.history.clone(),
            objective: self.objective.state()?,
        })
    }

    /// Puts a [`Trainer::snapshot`] back: the field's parameters (with their ids, which
    /// key Adam's state), Adam's state, the random stream and the history.
    pub fn restore(&mut self, snapshot: &TrainerSnapshot) -> Result<()> {
        if snapshot.history.len() != snapshot.iterations_done {
            return Err(DomaError::InvalidData(format!(
                "the checkpoint says {} iterations but holds {} records",
                snapshot.iterations_done,
                snapshot.history.len()
            )));
        }
        if is_fused_state(&snapshot.optimizer) && self.fused.is_none() {
            return Err(DomaError::InvalidData(
                "the checkpoint's optimiser state was written by the fused step, and this fit \
                 takes composed steps: resume it with the same --step on a CPU device"
                    .into(),
            ));
        }
        if let Some(fused) = &self.fused {
            fused
                .check_optimizer(&snapshot.optimizer)
                .map_err(DomaError::InvalidData)?;
        }
        let field = self.field.take().expect("the field is always put back");
        let loaded = crate::checkpoint::decode_checkpoint(field.clone(), &snapshot.model);
        self.field = Some(match loaded {
            Ok(f) => f,
            Err(e) => {
                self.field = Some(field);
                return Err(e);
            }
        });
        if !is_fused_state(&snapshot.optimizer) && self.fused.is_some() {
            // A composed fit's checkpoint (Burn's Adam record): the rest is composed too.
            self.fused = None;
            self.objective.stop_host_batches();
        }
        if let Some(fused) = self.fused.as_mut() {
            fused
                .restore_optimizer(&snapshot.optimizer)
                .map_err(DomaError::InvalidData)?;
            if let Some(siren) = self.field.as_ref().and_then(|f| f.siren()) {
                fused.reload(siren)?;
            }
        } else {
            let optim = std::mem::replace(&mut self.optim, AdamConfig::new().init());
            self.optim = optim
                .from_bytes(burn::tensor::Bytes::from_bytes_vec(
                    snapshot.optimizer.clone(),
                ))
                .map_err(|e| {
                    DomaError::InvalidData(format!("the saved Adam state is unreadable: {e}"))
                })?;
        }
        self.objective.restore_state(&snapshot.objective)?;
        self.rng = snapshot.rng.restore();
        self.history = snapshot.history.clone();
        self.clock = None;
        Ok(())
    }
}
