//! The wgpu implementation of [`super::SirenBackend`].
//!
//! Burn 0.22 runs wgpu as `Fusion<CubeBackend>`: the primitive ops of the default bodies
//! ([`super::forward`]) are recorded lazily and their elementwise chains (the slices,
//! `sin`, `cos`, the tangent products and the backward's `g_z`, `g_ż`) are compiled into
//! fused CubeCL kernels by Burn's fusion engine, around the one matmul per layer.

use burn::backend::wgpu::CubeBackend;
use burn_fusion::Fusion;

use super::SirenBackend;

impl SirenBackend for CubeBackend {}
impl SirenBackend for Fusion<CubeBackend> {}
