//! Adam's update on raw buffers, as Burn 0.22's `Adam` computes it (its
//! `AdaptiveMomentum::transform`): the same moments, bias corrections and order of
//! operations, in the parameters' float type, so that a fused step moves the parameters
//! as Burn's optimiser would, up to round-off.

use super::Float;

/// Adam's hyper-parameters (no weight decay, no AMSGrad, no gradient clipping: the fused
/// step is refused for configs that ask for them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamSettings {
    /// `β₁`.
    pub beta_1: f32,
    /// `β₂`.
    pub beta_2: f32,
    /// `ε`.
    pub epsilon: f32,
}

/// The moments of every parameter of a flat buffer, and the step count.
#[derive(Clone, Debug)]
pub struct AdamState<E> {
    pub(super) settings: AdamSettings,
    pub(super) time: usize,
    pub(super) moment_1: Vec<E>,
    pub(super) moment_2: Vec<E>,
}

impl<E: Float> AdamState<E> {
    /// No step taken yet, for `len` parameters.
    pub fn new(settings: AdamSettings, len: usize) -> Self {
        AdamState {
            settings,
            time: 0,
            moment_1: vec![E::zero(); len],
            moment_2: vec![E::zero(); len],
        }
    }

    /// The hyper-parameters.
    pub fn settings(&self) -> AdamSettings {
        self.settings
    }

    /// One update of `params` by their gradient `grad` at learning rate `lr`:
    /// `m ← β₁ m + (1 − β₁) g`, `v ← β₂ v + (1 − β₂) g²`, and
    /// `θ ← θ − lr · m c / (√v + ε √(1 − β₂ᵗ))` with `c = √(1 − β₂ᵗ) / (1 − β₁ᵗ)`.
    pub fn update(&mut self, params: &mut [E], grad: &[E], lr: f64) {
        let AdamSettings {
            beta_1,
            beta_2,
            epsilon,
        } = self.settings;
        self.time += 1;
        // Burn computes the scalars in f32 and casts them to the element type.
        let time = self.time as i32;
        let bias_2 = (1.0 - beta_2.powi(time)).sqrt();
        let combined = bias_2 / (1.0 - beta_1.powi(time));
        let cast = |v: f32| E::from_f64(v as f64);
        let (b1, f1) = (cast(beta_1), cast(1.0 - beta_1));
        let (b2, f2) = (cast(beta_2), cast(1.0 - beta_2));
        let (c, eps, lr) = (cast(combined), cast(epsilon * bias_2), E::from_f64(lr));
        let first = self.time == 1;
        let moments = self.moment_1.iter_mut().zip(self.moment_2.iter_mut());
        for ((p, g), (m, v)) in params.iter_mut().zip(grad).zip(moments) {
            // The first step starts the moments at (1 − β) g, as Burn does.
            let (m_prev, v_prev) = if first {
                (E::zero(), E::zero())
            } else {
                (*m * b1, *v * b2)
            };
            *m = m_prev + *g * f1;
            *v = v_prev + *g * *g * f2;
            let step = *m * c / (v.sqrt() + eps);
            *p = *p - step * lr;
        }
    }
}

/// The first bytes of a checkpoint's Adam state written by the fused step (Burn's own
/// state is a burnpack, which never starts with them).
const MAGIC: &[u8; 16] = b"DOMA-FUSED-ADAM1";

impl AdamState<f32> {
    /// The state as a checkpoint stores it: the magic, `t`, the length, then both moments
    /// as little-endian f32.
    pub fn to_bytes(&self) -> Vec<u8> {
        let len = self.moment_1.len();
        let mut out = Vec::with_capacity(32 + 8 * len);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(self.time as u64).to_le_bytes());
        out.extend_from_slice(&(len as u64).to_le_bytes());
        for v in self.moment_1.iter().chain(&self.moment_2) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    /// Whether `bytes` were written by [`AdamState::to_bytes`].
    pub fn is_fused(bytes: &[u8]) -> bool {
        bytes.starts_with(MAGIC)
    }

    /// Reads [`AdamState::to_bytes`] back, for `settings`; a message when the bytes are
    /// not such a state.
    pub fn from_bytes(bytes: &[u8], settings: AdamSettings) -> Result<Self, String> {
        let rest = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or("the Adam state was not written by the fused step")?;
        let word = |i: usize| -> Result<u64, String> {
            rest.get(8 * i..8 * i + 8)
                .and_then(|b| b.try_into().ok())
                .map(u64::from_le_bytes)
                .ok_or_else(|| "the fused Adam state is truncated".to_string())
        };
        let (time, len) = (word(0)?, word(1)?);
        let floats = &rest[16..];
        let expected = usize::try_from(len)
            .ok()
            .and_then(|l| l.checked_mul(8))
            .ok_or("the fused Adam state's length overflows")?;
        if floats.len() != expected {
            return Err(format!(
                "the fused Adam state holds {} bytes of moments for {len} parameters",
                floats.len()
            ));
        }
        let values: Vec<f32> = floats
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let half = values.len() / 2;
        Ok(AdamState {
            settings,
            time: usize::try_from(time).map_err(|_| "the fused Adam step count overflows")?,
            moment_1: values[..half].to_vec(),
            moment_2: values[half..].to_vec(),
        })
    }
}
