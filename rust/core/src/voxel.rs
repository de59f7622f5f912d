//! Downsampling: one point per occupied voxel (the mean of the points inside it), and even
//! Poisson-disk subsets (no two kept points closer than a radius).

use crate::error::{Error, Result};
use crate::geometry::Point;
use nalgebra::Vector3;
use std::collections::hash_map::RandomState;
use std::collections::HashMap;
use std::hash::{BuildHasher, BuildHasherDefault, Hasher};
use std::sync::OnceLock;

/// The largest voxel index (per axis, either sign) a grid here uses: 2^52, so that the index is
/// exact in an f64 and its neighbours never overflow an i64.
pub const MAX_VOXEL_INDEX: f64 = 4_503_599_627_370_496.0;

/// The voxel of `p` on a grid of cell `1 / inv`, or `None` when an index exceeds
/// [`MAX_VOXEL_INDEX`] or is not finite (the cast would saturate and merge distant points).
pub(crate) fn voxel_index(p: &Point, inv: f64) -> Option<[i64; 3]> {
    let f = |v: f64| {
        let k = (v * inv).floor();
        (k.abs() <= MAX_VOXEL_INDEX).then_some(k as i64)
    };
    Some([f(p.x)?, f(p.y)?, f(p.z)?])
}

/// Downsampled cloud: the voxel means, the averaged unit normals if normals were given,
/// and for each output point the index of the first input point that fell in its voxel.
#[derive(Debug, Clone)]
pub struct Downsampled {
    /// Mean point of each occupied voxel, in first-seen order.
    pub points: Vec<Point>,
    /// Mean normal of each voxel, renormalised (empty if no normals were given).
    pub normals: Vec<Vector3<f64>>,
    /// Index into the input of the first point of each voxel.
    pub first_index: Vec<usize>,
}

/// Averages the points (and normals) that fall in each cube of edge `voxel_size` mm.
pub fn voxel_downsample(points: &[Point], normals: Option<&[Vector3<f64>]>, voxel_size: f64) -> Result<Downsampled> {
    if !(voxel_size.is_finite() && voxel_size > 0.0) {
        return Err(Error::invalid(
            "voxel_size",
            format!("must be a positive length in mm, got {voxel_size}"),
        ));
    }
    if let Some(n) = normals {
        if n.len() != points.len() {
            return Err(Error::invalid(
                "normals",
                format!("has {} rows but points has {}", n.len(), points.len()),
            ));
        }
    }
    let inv = 1.0 / voxel_size;
    let mut slot_of: CellMap<usize> = CellMap::with_capacity_and_hasher(points.len() / 4 + 1, Default::default());
    let mut sums: Vec<(Vector3<f64>, Vector3<f64>, usize)> = Vec::new();
    let mut first_index = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let key = voxel_index(p, inv).ok_or_else(|| {
            Error::invalid(
                "points",
                format!(
                    "point {i} at {:?} lies more than {MAX_VOXEL_INDEX:.0} voxels of {voxel_size} mm from the \
                     origin; shift the cloud near the origin or use a larger voxel_size",
                    [p.x, p.y, p.z]
                ),
            )
        })?;
        let slot = *slot_of.entry(key).or_insert_with(|| {
            sums.push((Vector3::zeros(), Vector3::zeros(), 0));
            first_index.push(i);
            sums.len() - 1
        });
        let s = &mut sums[slot];
        s.0 += p.coords;
        if let Some(n) = normals {
            s.1 += n[i];
        }
        s.2 += 1;
    }
    let points_out = sums.iter().map(|s| Point::from(s.0 / s.2 as f64)).collect();
    let normals_out = if normals.is_some() {
        sums.iter()
            .zip(&first_index)
            .map(|(s, &i)| {
                let n = s.1.norm();
                if n > 1e-12 {
                    s.1 / n
                } else {
                    normals.unwrap()[i]
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    Ok(Downsampled {
        points: points_out,
        normals: normals_out,
        first_index,
    })
}

/// A hash map keyed by grid cells. A multiply-and-rotate mix replaces the default hash, which
/// costs several times more per lookup on the grids' hot paths (27 lookups per candidate of an
/// even sampling); it starts from a per-process random seed, so that a file cannot be made of
/// points whose cells all collide.
pub(crate) type CellMap<V> = HashMap<[i64; 3], V, BuildHasherDefault<CellHasher>>;

/// The hasher of [`CellMap`]: each written word is mixed in by a multiply and a rotate.
#[derive(Clone, Copy)]
pub(crate) struct CellHasher(u64);

impl Default for CellHasher {
    #[inline]
    fn default() -> Self {
        static SEED: OnceLock<u64> = OnceLock::new();
        CellHasher(*SEED.get_or_init(|| RandomState::new().build_hasher().finish() | 1))
    }
}

impl Hasher for CellHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    #[inline]
    fn write_u64(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    #[inline]
    fn write_i64(&mut self, word: i64) {
        self.write_u64(word as u64);
    }

    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
}

/// Points kept at least `radius` apart: each candidate is accepted unless an accepted point lies
/// closer, looked up on a hash grid of `radius` cells.
pub struct DiskGrid {
    inv: f64,
    r2: f64,
    cells: CellMap<Vec<u32>>,
    points: Vec<Point>,
}

impl DiskGrid {
    /// An empty selection with disk radius `radius` (mm, positive).
    pub fn new(radius: f64) -> Self {
        DiskGrid {
            inv: 1.0 / radius,
            r2: radius * radius,
            cells: CellMap::default(),
            points: Vec::new(),
        }
    }

    /// Accepts `p` when no accepted point lies within the radius; returns whether it did.
    pub fn try_insert(&mut self, p: Point) -> bool {
        let key = [
            (p.x * self.inv).floor() as i64,
            (p.y * self.inv).floor() as i64,
            (p.z * self.inv).floor() as i64,
        ];
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    // Saturating: cells merged far out only cost comparisons, as distances decide.
                    let near = [
                        key[0].saturating_add(dx),
                        key[1].saturating_add(dy),
                        key[2].saturating_add(dz),
                    ];
                    if let Some(ids) = self.cells.get(&near) {
                        if ids
                            .iter()
                            .any(|&k| (self.points[k as usize] - p).norm_squared() < self.r2)
                        {
                            return false;
                        }
                    }
                }
            }
        }
        self.cells.entry(key).or_default().push(self.points.len() as u32);
        self.points.push(p);
        true
    }
}

/// Indices of an even subsample: points visited in order, each kept unless a kept point lies
/// within `radius` (a greedy Poisson-disk selection).
pub fn subsample(points: &[Point], radius: f64) -> Vec<usize> {
    let mut grid = DiskGrid::new(radius);
    (0..points.len()).filter(|&i| grid.try_insert(points[i])).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_point_per_voxel_at_the_mean() {
        let pts = vec![
            Point::new(0.1, 0.1, 0.1),
            Point::new(0.3, 0.5, 0.9),
            Point::new(1.5, 0.0, 0.0),
        ];
        let d = voxel_downsample(&pts, None, 1.0).unwrap();
        assert_eq!(d.points.len(), 2);
        assert!((d.points[0] - Point::new(0.2, 0.3, 0.5)).norm() < 1e-12);
        assert_eq!(d.first_index, vec![0, 2]);
        assert!(voxel_downsample(&pts, None, 0.0).is_err());
    }

    #[test]
    fn points_too_far_for_an_exact_voxel_index_are_refused_not_merged() {
        let far = [0.0, 2e19, 4e19].map(|x| Point::new(x, 0.0, 0.0));
        let err = voxel_downsample(&far, None, 1.0).unwrap_err();
        assert!(err.to_string().contains("point 1"), "{err}");
        let kept = subsample(&[Point::new(9e18, 0.0, 0.0), Point::new(1e19, 0.0, 0.0)], 1.0);
        assert_eq!(kept, vec![0, 1]);
    }
}
