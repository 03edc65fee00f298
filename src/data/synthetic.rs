//! The synthetic benchmark of the paper's Tab. 2 (docs/reference.md §6.1).
//!
//! Four 3-D sequences of `T = 20` frames share one draw of `N = 3000` points from
//! `U[−1, 1]³`: rotation, scaling, shearing and translation. The first 750 points
//! train, the other 2250 test. The default seed 0 reproduces the points of the
//! reference measurements bit for bit: numpy's legacy `seed(0); rand(3000, 3)·2 − 1`,
//! i.e. MT19937 seeded with `init_genrand(0)` ([`Mt19937`]).

use serde::{Deserialize, Serialize};

use super::Trajectories;
use crate::Result;

/// The frame count of the synthetic protocol.
pub const FRAMES: usize = 20;
/// The point count of the synthetic protocol.
pub const POINTS: usize = 3000;
/// The training points (the first 25 %).
pub const TRAIN_POINTS: usize = 750;

/// The 32-bit Mersenne Twister MT19937 (Matsumoto & Nishimura 1998), as numpy's
/// legacy `RandomState` uses it.
#[derive(Clone)]
pub struct Mt19937 {
    state: [u32; 624],
    index: usize,
}

impl Mt19937 {
    /// Seeds with `init_genrand(seed)` (numpy's `seed(int)`).
    pub fn new(seed: u32) -> Self {
        let mut state = [0u32; 624];
        state[0] = seed;
        for i in 1..624 {
            let prev = state[i - 1];
            state[i] = 1_812_433_253u32
                .wrapping_mul(prev ^ (prev >> 30))
                .wrapping_add(i as u32);
        }
        Mt19937 { state, index: 624 }
    }

    fn twist(&mut self) {
        for i in 0..624 {
            let y = (self.state[i] & 0x8000_0000) | (self.state[(i + 1) % 624] & 0x7fff_ffff);
            let mut next = self.state[(i + 397) % 624] ^ (y >> 1);
            if y & 1 != 0 {
                next ^= 0x9908_b0df;
            }
            self.state[i] = next;
        }
        self.index = 0;
    }

    /// The next 32-bit output.
    pub fn next_u32(&mut self) -> u32 {
        if self.index >= 624 {
            self.twist();
        }
        let mut y = self.state[self.index];
        self.index += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^ (y >> 18)
    }

    /// A double in `[0, 1)` with 53 random bits, as numpy's `random_sample`:
    /// `((a >> 5)·2²⁶ + (b >> 6)) / 2⁵³`.
    pub fn next_f64(&mut self) -> f64 {
        let a = (self.next_u32() >> 5) as f64;
        let b = (self.next_u32() >> 6) as f64;
        (a * 67_108_864.0 + b) / 9_007_199_254_740_992.0
    }
}

/// The four synthetic motions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Motion {
    /// Rotation about the z axis by `k·π/20` at frame `k` (the authors' generator).
    Rotation,
    /// Uniform scaling by `linspace(0.5, 1.5, T)[k]`.
    Scaling,
    /// `x' = x + s_k z` with `s_k = linspace(0, 1.5, T)[k]`.
    Shearing,
    /// `c_k = linspace(−1, 1, T)[k]` added to every coordinate.
    Translation,
}

impl Motion {
    /// The four motions in the paper's column order.
    pub const ALL: [Motion; 4] = [
        Motion::Rotation,
        Motion::Scaling,
        Motion::Shearing,
        Motion::Translation,
    ];

    /// Where the point `p` (from `U[−1, 1]³`) is at frame `k` of `frames`.
    pub fn apply(self, p: [f64; 3], k: usize, frames: usize) -> [f64; 3] {
        let lin = |a: f64, b: f64| {
            if frames < 2 {
                a
            } else {
                a + (b - a) * k as f64 / (frames - 1) as f64
            }
        };
        let [x, y, z] = p;
        match self {
            Motion::Rotation => {
                let (s, c) = (k as f64 * std::f64::consts::PI / 20.0).sin_cos();
                [x * c - y * s, x * s + y * c, z]
            }
            Motion::Scaling => {
                let s = lin(0.5, 1.5);
                [s * x, s * y, s * z]
            }
            Motion::Shearing => [x + lin(0.0, 1.5) * z, y, z],
            Motion::Translation => {
                let c = lin(-1.0, 1.0);
                [x + c, y + c, z + c]
            }
        }
    }
}

/// `n` points from `U[−1, 1]³` as numpy's `seed(seed); rand(n, 3)·2 − 1` (f64, row-major).
pub fn uniform_points(seed: u32, n: usize) -> Vec<[f64; 3]> {
    let mut rng = Mt19937::new(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.next_f64() * 2.0 - 1.0))
        .collect()
}

/// One synthetic sequence, split into training and test trajectories.
#[derive(Clone, Debug)]
pub struct SyntheticSequence {
    /// The motion.
    pub motion: Motion,
    /// The first [`TRAIN_POINTS`] points' trajectories.
    pub train: Trajectories,
    /// The other points' trajectories.
    pub test: Trajectories,
}

/// The full sequence of `motion` applied to `points` over `frames` frames.
pub fn sequence(motion: Motion, points: &[[f64; 3]], frames: usize) -> Result<Trajectories> {
    let mut positions = Vec::with_capacity(frames * points.len() * 3);
    for k in 0..frames {
        for &p in points {
            positions.extend(motion.apply(p, k, frames).map(|v| v as f32));
        }
    }
    Trajectories::new(frames, points.len(), positions)
}

/// The benchmark sequence of `motion` with the protocol's sizes and split, from `seed`
/// (0 = the reference points).
pub fn benchmark_sequence(motion: Motion, seed: u32) -> Result<SyntheticSequence> {
    let points = uniform_points(seed, POINTS);
    let (train, test) = sequence(motion, &points, FRAMES)?.split_first(TRAIN_POINTS)?;
    Ok(SyntheticSequence {
        motion,
        train,
        test,
    })
}

crate::names::value_names!(Motion);
