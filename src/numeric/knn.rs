//! Nearest neighbours on the host: a k-d tree over a point cloud, shared by the data layer
//! (a track's neighbours), the losses (AIAP neighbourhoods), the metrics (Chamfer) and the
//! field's fill (its lenders).

use crate::{DomaError, Result};

/// A k-d tree over a point cloud, for nearest-neighbour queries on the host.
pub struct PointTree {
    tree: kiddo::ImmutableKdTree<f32, 3>,
}

impl PointTree {
    /// Builds the tree. Refuses an empty cloud.
    pub fn new(points: &[[f32; 3]]) -> Result<Self> {
        let tree = kiddo::ImmutableKdTree::new_from_slice(points)
            .map_err(|e| DomaError::InvalidData(format!("cannot build a k-d tree: {e:?}")))?;
        Ok(PointTree { tree })
    }

    /// The nearest point to `q`: `(index, squared distance)`.
    pub fn nearest(&self, q: &[f32; 3]) -> (usize, f32) {
        let r = self
            .tree
            .query(q)
            .nearest_one::<kiddo::SquaredEuclidean<f32>>()
            .execute();
        (r.item as usize, r.distance)
    }

    /// The `k` nearest points to `q` (itself included when `q` is in the tree), closest
    /// first.
    pub fn nearest_k(&self, q: &[f32; 3], k: usize) -> Vec<usize> {
        let k = std::num::NonZero::new(k).expect("k ≥ 1");
        self.tree
            .query(q)
            .nearest_n::<kiddo::SquaredEuclidean<f32>>(k)
            .execute()
            .into_iter()
            .map(|r| r.item as usize)
            .collect()
    }
}
