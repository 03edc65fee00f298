//! `resume.ckpt`: the last checkpoint of a fit, one file written atomically: a magic, then
//! three length-prefixed parts (the JSON metadata with the history and the random stream,
//! the model's burnpack, Adam's burnpack).

use serde::{Deserialize, Serialize};

use super::RunDir;
use crate::io::write_atomic;
use crate::train::{IterationRecord, RngState, TrainerSnapshot};
use crate::{DomaError, Result};

const MAGIC: &[u8; 8] = b"DOMARUN1";

/// The JSON part of `resume.ckpt`.
#[derive(Serialize, Deserialize)]
struct ResumeMeta {
    iterations_done: usize,
    history: Vec<IterationRecord>,
    rng: RngState,
    /// The objective's learned state (the canonical positions of tracks unseen in the
    /// reference frame, with Adam's moments); absent before there was any.
    #[serde(default)]
    objective: Vec<f32>,
}

impl RunDir {
    pub(super) fn write_resume(&self, snapshot: &TrainerSnapshot) -> Result<()> {
        let meta = ResumeMeta {
            iterations_done: snapshot.iterations_done,
            history: snapshot.history.clone(),
            rng: snapshot.rng.clone(),
            objective: snapshot.objective.clone(),
        };
        let json = serde_json::to_vec(&meta)
            .map_err(|e| DomaError::InvalidData(format!("cannot serialise the checkpoint: {e}")))?;
        let mut bytes = MAGIC.to_vec();
        for part in [&json, &snapshot.model, &snapshot.optimizer] {
            bytes.extend_from_slice(&(part.len() as u64).to_le_bytes());
            bytes.extend_from_slice(part);
        }
        write_atomic(&self.resume(), &bytes)
    }

    pub(super) fn read_resume(&self) -> Result<TrainerSnapshot> {
        let path = self.resume();
        let bytes = std::fs::read(&path).map_err(|e| DomaError::io(&path, e))?;
        let bad = |reason: String| DomaError::Malformed {
            path: path.clone(),
            reason,
        };
        if bytes.len() < 8 || &bytes[..8] != MAGIC {
            return Err(bad("not a doma checkpoint (wrong magic)".into()));
        }
        let mut at = 8;
        let mut parts = Vec::with_capacity(3);
        for name in ["metadata", "model", "optimizer"] {
            let len = bytes
                .get(at..at + 8)
                .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
                .ok_or_else(|| bad(format!("truncated before the {name} length")))?;
            let end = usize::try_from(len)
                .ok()
                .and_then(|l| (at + 8).checked_add(l))
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| bad(format!("truncated: the {name} part is cut off")))?;
            parts.push(bytes[at + 8..end].to_vec());
            at = end;
        }
        if at != bytes.len() {
            return Err(bad(format!("{} trailing bytes", bytes.len() - at)));
        }
        let meta: ResumeMeta =
            serde_json::from_slice(&parts[0]).map_err(|e| bad(format!("bad metadata: {e}")))?;
        Ok(TrainerSnapshot {
            model: std::mem::take(&mut parts[1]),
            optimizer: std::mem::take(&mut parts[2]),
            rng: meta.rng,
            iterations_done: meta.iterations_done,
            history: meta.history,
            objective: meta.objective,
        })
    }
}
