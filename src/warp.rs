//! Warping points and meshes through a fitted motion field (Eq. 4 applied to a whole
//! mesh): what `doma warp`, the Tab. 1 CD/CDN and the Tab. 3 metrics evaluate. It sits
//! above both [`crate::data`] (meshes, trajectories) and [`crate::field`] (the fields), so
//! that neither imports the other.

use burn::tensor::{Device, Tensor, TensorData};

use crate::Result;
use crate::data::Trajectories;
use crate::data::mesh::{TriMesh, as_points};
use crate::field::MotionField;

/// The rows that [`warp_points`] sends through the field at once. A chunk's peak is its
/// fused SIREN op's workspaces (each sine layer's pre-activation and output, kept for a
/// backward) plus the head's temporaries: about `chunk × 4 B × (2 · layers · hidden + 64)`,
/// i.e. 55 MB for the paper's SIREN (3 sine layers, 128 wide), whatever the number of
/// points (`tests/process/bounded_memory.rs` measures it).
pub const WARP_CHUNK: usize = 16_384;

/// Warps `points` (`[V, 3]`) through `field` at normalised time `t`, in chunks of
/// [`WARP_CHUNK`] rows so that memory stays bounded.
pub fn warp_points(
    field: &dyn MotionField,
    points: &[[f32; 3]],
    t: f64,
    device: &Device,
) -> Result<Vec<[f32; 3]>> {
    warp_points_in_chunks(field, points, t, device, WARP_CHUNK)
}

/// [`warp_points`] with `chunk` rows at a time (at least 1).
pub fn warp_points_in_chunks(
    field: &dyn MotionField,
    points: &[[f32; 3]],
    t: f64,
    device: &Device,
    chunk: usize,
) -> Result<Vec<[f32; 3]>> {
    let mut out = Vec::with_capacity(points.len());
    for chunk in points.chunks(chunk.max(1)) {
        let x = Tensor::<2>::from_data(
            TensorData::new(chunk.as_flattened().to_vec(), [chunk.len(), 3]),
            device,
        );
        let y = crate::readback::to_vec::<f32, 2, _>(field.warp(x, t))?;
        out.extend(as_points(&y));
    }
    Ok(out)
}

/// Warps `points` to each frame `k` of `frames` (of a `total`-frame sequence) and hands
/// every frame to `sink(k, warped)` before the next is computed: memory holds the points,
/// one frame's result and one chunk's activations ([`WARP_CHUNK`]), however many frames.
pub fn warp_frames(
    field: &dyn MotionField,
    points: &[[f32; 3]],
    frames: std::ops::Range<usize>,
    total: usize,
    device: &Device,
    mut sink: impl FnMut(usize, Vec<[f32; 3]>) -> Result<()>,
) -> Result<()> {
    for k in frames {
        let t = crate::data::normalized_time(k, total);
        sink(k, warp_points(field, points, t, device)?)?;
    }
    Ok(())
}

/// The canonical mesh warped to every frame of a `frames`-frame sequence: `[T, V, 3]`
/// (all of it in memory; [`warp_frames`] streams instead).
/// Normals for any frame follow from [`crate::data::mesh::vertex_normals`].
pub fn warp_mesh_sequence(
    field: &dyn MotionField,
    canonical: &TriMesh,
    frames: usize,
    device: &Device,
) -> Result<Trajectories> {
    let mut positions = Vec::with_capacity(frames * canonical.vertices.len() * 3);
    warp_frames(
        field,
        &canonical.vertices,
        0..frames,
        frames,
        device,
        |_, y| {
            positions.extend_from_slice(y.as_flattened());
            Ok(())
        },
    )?;
    Trajectories::new(frames, canonical.vertices.len(), positions)
}
