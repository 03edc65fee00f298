//! Warping points and meshes through a fitted motion field (Eq. 4 applied to a whole
//! mesh): what `doma warp`, the Tab. 1 CD/CDN and the Tab. 3 metrics evaluate. It sits
//! above both [`crate::data`] (meshes, trajectories) and [`crate::field`] (the fields), so
//! that neither imports the other.

use burn::tensor::{Device, Tensor, TensorData};

use crate::data::Trajectories;
use crate::data::mesh::{TriMesh, as_points};
use crate::field::MotionField;
use crate::{DomaError, Result};

/// Warps `points` (`[V, 3]`) through `field` at normalised time `t`, in chunks of
/// at most 65 536 rows so that memory stays bounded.
pub fn warp_points(
    field: &dyn MotionField,
    points: &[[f32; 3]],
    t: f64,
    device: &Device,
) -> Result<Vec<[f32; 3]>> {
    const CHUNK: usize = 65_536;
    let mut out = Vec::with_capacity(points.len());
    for chunk in points.chunks(CHUNK) {
        let x = Tensor::<2>::from_data(
            TensorData::new(chunk.as_flattened().to_vec(), [chunk.len(), 3]),
            device,
        );
        let y = field
            .warp(x, t)
            .try_into_vec_as::<f32>()
            .map_err(|e| DomaError::Device(format!("{e:?}")))?;
        out.extend(as_points(&y));
    }
    Ok(out)
}

/// The canonical mesh warped to every frame of a `frames`-frame sequence: `[T, V, 3]`.
/// Normals for any frame follow from [`vertex_normals`].
pub fn warp_mesh_sequence(
    field: &dyn MotionField,
    canonical: &TriMesh,
    frames: usize,
    device: &Device,
) -> Result<Trajectories> {
    let mut positions = Vec::with_capacity(frames * canonical.vertices.len() * 3);
    for k in 0..frames {
        let y = warp_points(
            field,
            &canonical.vertices,
            crate::data::normalized_time(k, frames),
            device,
        )?;
        positions.extend_from_slice(y.as_flattened());
    }
    Trajectories::new(frames, canonical.vertices.len(), positions)
}
