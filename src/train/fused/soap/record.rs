//! SOAP's state as a checkpoint stores it, and read back.

use super::{SoapConfig, SoapState};

/// The first bytes of a checkpoint's SOAP state (Burn's Adam record is a burnpack, and
/// the fused Adam state has a magic of its own).
const MAGIC: &[u8; 16] = b"DOMA-FUSED-SOAP1";

impl SoapState<f32> {
    /// The state as a checkpoint stores it: the magic, the settings, `t`, then every
    /// buffer (each matrix's factors, bases and moments, each bias's moments) as a
    /// little-endian length and f32 values.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        let c = self.config;
        for x in [c.beta_1, c.beta_2, c.epsilon] {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(&(c.every as u64).to_le_bytes());
        out.extend_from_slice(&(self.time as u64).to_le_bytes());
        for b in self.buffers() {
            out.extend_from_slice(&(b.len() as u64).to_le_bytes());
            b.iter()
                .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
        }
        out
    }

    /// Whether `bytes` were written by [`SoapState::to_bytes`].
    pub fn is_fused(bytes: &[u8]) -> bool {
        bytes.starts_with(MAGIC)
    }

    /// Reads [`SoapState::to_bytes`] back into a state for the same layers; a message
    /// when the bytes are not such a state or hold other shapes.
    pub fn read_bytes(&mut self, bytes: &[u8]) -> Result<(), String> {
        let mut rest = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or("the optimiser state was not written by the fused SOAP step")?;
        let word = |rest: &mut &[u8]| -> Result<[u8; 8], String> {
            let (w, r) = rest
                .split_first_chunk::<8>()
                .ok_or("the fused SOAP state is truncated")?;
            *rest = r;
            Ok(*w)
        };
        let config = SoapConfig {
            beta_1: f64::from_le_bytes(word(&mut rest)?),
            beta_2: f64::from_le_bytes(word(&mut rest)?),
            epsilon: f64::from_le_bytes(word(&mut rest)?),
            every: usize::try_from(u64::from_le_bytes(word(&mut rest)?))
                .map_err(|_| "the SOAP refresh interval overflows")?,
        };
        config.check()?;
        let time = usize::try_from(u64::from_le_bytes(word(&mut rest)?))
            .map_err(|_| "the SOAP step count overflows")?;
        let mut fresh = self.clone();
        let sizes = fresh.sizes();
        for (k, (buffer, (size, may_be_empty))) in
            fresh.buffers_mut().into_iter().zip(sizes).enumerate()
        {
            let len = u64::from_le_bytes(word(&mut rest)?);
            if len != size as u64 && !(may_be_empty && len == 0) {
                return Err(format!(
                    "the SOAP state's buffer {k} holds {len} values where the model has {size}"
                ));
            }
            let (values, r) = rest
                .split_at_checked(4 * size.min(len as usize))
                .ok_or("the fused SOAP state is truncated")?;
            rest = r;
            *buffer = values
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
        }
        if !rest.is_empty() {
            return Err(format!(
                "the fused SOAP state has {} bytes too many",
                rest.len()
            ));
        }
        fresh.config = config;
        fresh.time = time;
        *self = fresh;
        Ok(())
    }
}

impl<E> SoapState<E> {
    /// Each buffer's size, and whether it may be empty (the bases, before the first
    /// update), in the order of [`SoapState::buffers`].
    fn sizes(&self) -> Vec<(usize, bool)> {
        let mut out = Vec::new();
        for m in &self.matrices {
            let (r, c) = (m.rows * m.rows, m.cols * m.cols);
            let n = m.rows * m.cols;
            out.extend([
                (r, false),
                (c, false),
                (r, true),
                (c, true),
                (n, false),
                (n, false),
            ]);
        }
        for v in &self.vectors {
            out.extend([(v.moment_1.len(), false), (v.moment_2.len(), false)]);
        }
        out
    }

    /// Every buffer, in the order a checkpoint writes them.
    fn buffers(&self) -> Vec<&Vec<E>> {
        let mut out = Vec::new();
        for m in &self.matrices {
            out.extend([
                &m.left,
                &m.right,
                &m.q_left,
                &m.q_right,
                &m.moment_1,
                &m.moment_2,
            ]);
        }
        for v in &self.vectors {
            out.extend([&v.moment_1, &v.moment_2]);
        }
        out
    }

    fn buffers_mut(&mut self) -> Vec<&mut Vec<E>> {
        let mut out = Vec::new();
        for m in &mut self.matrices {
            out.extend([
                &mut m.left,
                &mut m.right,
                &mut m.q_left,
                &mut m.q_right,
                &mut m.moment_1,
                &mut m.moment_2,
            ]);
        }
        for v in &mut self.vectors {
            out.extend([&mut v.moment_1, &mut v.moment_2]);
        }
        out
    }
}
