//! Nearest-neighbour search over a fixed point set, backed by kiddo's immutable KD-tree.

use super::corr_tree::CorrespondenceTree;
use crate::geometry::Point;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::sync::OnceLock;

/// A KD-tree over a point set that answers nearest, k-nearest and radius queries.
/// Indices returned refer to the slice the tree was built from.
///
/// k-nearest queries go to this crate's own KD-tree, built on the first such query: it keeps
/// the k best in a flat buffer and answers faster than kiddo's heap-based search on the clouds
/// this crate sees (20 neighbours among 100k samples of the tee's surface: 2.3 µs against
/// 2.8–3.4 µs; 32 among 300 points: 1.3 µs against 2.1 µs, on the 2-core reference machine),
/// which normal estimation feels.
pub struct KdIndex {
    tree: ImmutableKdTree<f64, 3>,
    len: usize,
    points: Vec<Point>,
    knn_tree: OnceLock<CorrespondenceTree>,
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
        KdIndex {
            tree,
            len: points.len(),
            points: points.to_vec(),
            knn_tree: OnceLock::new(),
        }
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
        Some(Neighbour {
            index: r.item as usize,
            distance_squared: r.distance,
        })
    }

    /// The `k` nearest indexed points, nearest first (fewer if the set is smaller).
    pub fn knn(&self, query: &Point, k: usize) -> Vec<Neighbour> {
        let mut found = Vec::with_capacity(k.min(self.len));
        self.knn_into(query, k, &mut found);
        found
            .into_iter()
            .map(|(d, i)| Neighbour {
                index: i as usize,
                distance_squared: d,
            })
            .collect()
    }

    /// [`KdIndex::knn`] into a reused buffer of (squared distance, index), nearest first.
    pub fn knn_into(&self, query: &Point, k: usize, found: &mut Vec<(f64, u32)>) {
        self.knn_tree
            .get_or_init(|| CorrespondenceTree::tree_only(&self.points))
            .knn_into(&[query.x, query.y, query.z], k.min(self.len), f64::INFINITY, found);
    }

    /// The nearest indexed point other than point `i` itself (duplicates of it count).
    pub fn nearest_other(&self, i: usize) -> Option<Neighbour> {
        let p = self.points.get(i)?;
        self.knn_tree
            .get_or_init(|| CorrespondenceTree::tree_only(&self.points))
            .nearest_other(&[p.x, p.y, p.z], i)
            .map(|(index, distance_squared)| Neighbour {
                index,
                distance_squared,
            })
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
            .map(|r| Neighbour {
                index: r.item as usize,
                distance_squared: r.distance,
            })
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

    #[test]
    fn knn_matches_brute_force() {
        let mut rng = crate::rng::Rng::new(9);
        let pts: Vec<Point> = (0..3000)
            .map(|_| Point::new(rng.range(0.0, 50.0), rng.range(0.0, 50.0), rng.range(0.0, 2.0)))
            .collect();
        let idx = KdIndex::new(&pts);
        for _ in 0..300 {
            let q = Point::new(rng.range(-5.0, 55.0), rng.range(-5.0, 55.0), rng.range(-3.0, 5.0));
            for k in [1, 7, 32] {
                let mut brute: Vec<f64> = pts.iter().map(|p| (p - q).norm_squared()).collect();
                brute.sort_by(|a, b| a.total_cmp(b));
                let got: Vec<f64> = idx.knn(&q, k).iter().map(|n| n.distance_squared).collect();
                assert_eq!(got, brute[..k].to_vec());
            }
        }
        for i in (0..pts.len()).step_by(97) {
            let brute = pts
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, p)| (p - pts[i]).norm_squared())
                .fold(f64::INFINITY, f64::min);
            assert_eq!(idx.nearest_other(i).unwrap().distance_squared, brute);
        }
        assert!(KdIndex::new(&[]).knn(&Point::origin(), 3).is_empty());
    }
}
