//! Nearest-neighbour search over a fixed point set, backed by kiddo's immutable KD-tree.

use crate::cloud::Point;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::num::NonZeroUsize;

/// A KD-tree over a point set that answers nearest, k-nearest and radius queries.
/// Indices returned refer to the slice the tree was built from.
pub struct KdIndex {
    tree: ImmutableKdTree<f64, 3>,
    len: usize,
}

/// One neighbour: its index in the indexed set and its squared distance (mm²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbour {
    /// Index of the point in the indexed set.
    pub index: usize,
    /// Squared Euclidean distance to the query, mm².
    pub distance_squared: f64,
}

impl KdIndex {
    /// Builds the tree. An empty set gives an index whose queries return nothing.
    pub fn new(points: &[Point]) -> Self {
        let entries: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = ImmutableKdTree::new_from_slice(&entries).expect("kiddo tree from finite points");
        KdIndex { tree, len: points.len() }
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no point is indexed.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The nearest indexed point to `query`, or `None` for an empty index.
    #[inline]
    pub fn nearest(&self, query: &Point) -> Option<Neighbour> {
        if self.len == 0 {
            return None;
        }
        let r = self
            .tree
            .query(&[query.x, query.y, query.z])
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        Some(Neighbour { index: r.item as usize, distance_squared: r.distance })
    }

    /// The `k` nearest indexed points, nearest first (fewer if the set is smaller).
    pub fn knn(&self, query: &Point, k: usize) -> Vec<Neighbour> {
        let Some(k) = NonZeroUsize::new(k.min(self.len)) else { return Vec::new() };
        self.tree
            .query(&[query.x, query.y, query.z])
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .into_iter()
            .map(|r| Neighbour { index: r.item as usize, distance_squared: r.distance })
            .collect()
    }

    /// Every indexed point within `radius` (mm, inclusive) of `query`, in no particular order.
    pub fn within(&self, query: &Point, radius: f64) -> Vec<Neighbour> {
        if self.len == 0 {
            return Vec::new();
        }
        self.tree
            .query(&[query.x, query.y, query.z])
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .unsorted()
            .execute()
            .into_iter()
            .map(|r| Neighbour { index: r.item as usize, distance_squared: r.distance })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplicate_points_do_not_break_the_tree() {
        let mut pts = vec![Point::new(1.0, 2.0, 3.0); 500];
        pts.extend((0..500).map(|i| Point::new(5.0, i as f64 * 0.01, 0.0)));
        let idx = KdIndex::new(&pts);
        assert_eq!(idx.knn(&Point::new(1.0, 2.0, 3.1), 40).len(), 40);
        assert_eq!(idx.within(&Point::new(1.0, 2.0, 3.0), 0.5).len(), 500);
        assert!((idx.nearest(&Point::new(5.0, 1.0, 0.2)).unwrap().distance_squared - 0.04).abs() < 1e-9);
    }
}
