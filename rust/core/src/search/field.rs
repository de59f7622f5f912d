//! An approximate nearest-point lookup for coarse pose checks.
//!
//! Coarse checks (scoring a hundred CCP readings, a few ICP steps from each of the best) ask
//! many nearest-point questions of poses that are still tens of degrees off, where an exact
//! search has to look far. Here a voxel grid around the point set holds, in every cell, the
//! point nearest the cell's centre, found once by a wavefront that starts from the cells the
//! points lie in and spreads to face neighbours while it brings a nearer point. A lookup is one
//! array read. The point it returns is at most one cell diagonal farther from the query than the
//! true nearest (|q − p_c| ≤ |q − c| + |c − p*| ≤ 2|q − c| + |q − p*|), and the wavefront can
//! add about as much again near the boundaries between points' regions — errors a coarse check
//! does not feel. Refinement and verification use the exact search
//! ([`crate::search::corr_tree::CorrespondenceTree`]).

use crate::geometry::Point;
use std::collections::VecDeque;

/// Largest grid built (cells); beyond it the cells grow. Lookups are random, so the grid is
/// kept small (16-bit indices, at most 2 MB) to stay in cache: one that spills to memory
/// shared with other processes costs more in misses than it saves in search.
const MAX_CELLS: usize = 1 << 20;

/// Point indices per cell: 16 bits while the set allows, 32 beyond.
enum Indices {
    Small(Vec<u16>),
    Large(Vec<u32>),
}

/// A voxel grid of nearest points over the box of a point set grown by a margin.
pub struct NearestField {
    origin: [f64; 3],
    inv_cell: f64,
    cell: f64,
    dims: [usize; 3],
    /// Index of the point nearest each cell's centre (x fastest, then y, then z).
    nearest: Indices,
}

impl NearestField {
    /// Builds the field with cells of about `cell` mm over the points' bounding box grown by
    /// `margin` mm on every side. `None` for an empty set, a non-positive cell or points whose
    /// extent overflows an f64.
    pub fn new(points: &[Point], cell: f64, margin: f64) -> Option<NearestField> {
        if points.is_empty() || !(cell > 0.0) || !margin.is_finite() || points.len() >= (u32::MAX - 1) as usize {
            return None;
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in points {
            for d in 0..3 {
                lo[d] = lo[d].min(p[d] - margin.max(0.0));
                hi[d] = hi[d].max(p[d] + margin.max(0.0));
            }
        }
        // Coordinates far apart (±1e308) overflow the extent to infinity: no grid covers them.
        if (0..3).any(|d| !(hi[d] - lo[d]).is_finite()) {
            return None;
        }
        let mut cell = cell;
        let dims = loop {
            let dims: [usize; 3] = std::array::from_fn(|d| ((hi[d] - lo[d]) / cell).ceil().max(1.0) as usize);
            if dims.iter().map(|&n| n as f64).product::<f64>() <= MAX_CELLS as f64 {
                break dims;
            }
            cell *= 1.25;
        };
        let n = dims.iter().product::<usize>();
        let mut field = NearestField {
            origin: lo,
            inv_cell: 1.0 / cell,
            cell,
            dims,
            nearest: Indices::Small(Vec::new()),
        };
        let mut nearest = vec![u32::MAX; n];
        let mut best = vec![f64::INFINITY; n];
        let mut queue: VecDeque<u32> = VecDeque::new();
        for (i, p) in points.iter().enumerate() {
            let Some(c) = field.cell_of(&[p.x, p.y, p.z]) else {
                continue;
            };
            let d = dist2(p, &field.centre(c));
            if d < best[c] {
                if best[c].is_infinite() {
                    queue.push_back(c as u32);
                }
                best[c] = d;
                nearest[c] = i as u32;
            }
        }
        let (sx, sy) = (1, dims[0]);
        let sz = dims[0] * dims[1];
        while let Some(c) = queue.pop_front() {
            let c = c as usize;
            let s = nearest[c];
            let p = &points[s as usize];
            let (x, y, z) = (c % dims[0], (c / dims[0]) % dims[1], c / sz);
            let neighbours = [
                (x > 0).then(|| c - sx),
                (x + 1 < dims[0]).then(|| c + sx),
                (y > 0).then(|| c - sy),
                (y + 1 < dims[1]).then(|| c + sy),
                (z > 0).then(|| c - sz),
                (z + 1 < dims[2]).then(|| c + sz),
            ];
            for nb in neighbours.into_iter().flatten() {
                let d = dist2(p, &field.centre(nb));
                if d < best[nb] {
                    best[nb] = d;
                    nearest[nb] = s;
                    queue.push_back(nb as u32);
                }
            }
        }
        field.nearest = if points.len() < u16::MAX as usize {
            Indices::Small(nearest.into_iter().map(|i| i as u16).collect())
        } else {
            Indices::Large(nearest)
        };
        Some(field)
    }

    /// Cell edge, mm.
    pub fn cell(&self) -> f64 {
        self.cell
    }

    /// The point (input index) nearest the centre of the cell holding `q`; `None` outside the grid.
    #[inline]
    pub fn nearest(&self, q: &[f64; 3]) -> Option<usize> {
        let c = self.cell_of(q)?;
        Some(match &self.nearest {
            Indices::Small(v) => v[c] as usize,
            Indices::Large(v) => v[c] as usize,
        })
    }

    #[inline]
    fn cell_of(&self, q: &[f64; 3]) -> Option<usize> {
        let mut idx = [0usize; 3];
        for d in 0..3 {
            let f = (q[d] - self.origin[d]) * self.inv_cell;
            if !(f >= 0.0 && f < self.dims[d] as f64) {
                return None;
            }
            idx[d] = f as usize;
        }
        Some(idx[0] + self.dims[0] * (idx[1] + self.dims[1] * idx[2]))
    }

    fn centre(&self, c: usize) -> Point {
        let (x, y, z) = (
            c % self.dims[0],
            (c / self.dims[0]) % self.dims[1],
            c / (self.dims[0] * self.dims[1]),
        );
        Point::new(
            self.origin[0] + (x as f64 + 0.5) * self.cell,
            self.origin[1] + (y as f64 + 0.5) * self.cell,
            self.origin[2] + (z as f64 + 0.5) * self.cell,
        )
    }
}

#[inline]
fn dist2(p: &Point, q: &Point) -> f64 {
    (p - q).norm_squared()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn points_whose_extent_overflows_get_no_field_instead_of_a_hang() {
        let far = [Point::new(-1e308, 0.0, 0.0), Point::new(1e308, 0.0, 0.0)];
        assert!(NearestField::new(&far, 1.0, 0.0).is_none());
        let apart = [Point::new(-1e16, 0.0, 0.0), Point::new(1e16, 1e16, 1e16)];
        assert!(NearestField::new(&apart, 1.0, 0.0).is_some());
    }

    /// The answer is never more than two cell diagonals farther than the true nearest point.
    #[test]
    fn lookups_are_within_two_cell_diagonals_of_the_nearest() {
        let mut rng = Rng::new(7);
        // Points on a cylinder surface, as CAD samples are.
        let pts: Vec<Point> = (0..800)
            .map(|_| {
                let a = rng.range(0.0, std::f64::consts::TAU);
                Point::new(rng.range(-40.0, 40.0), 13.0 * a.cos(), 13.0 * a.sin())
            })
            .collect();
        let field = NearestField::new(&pts, 1.5, 20.0).unwrap();
        let diag = field.cell() * 3f64.sqrt();
        let mut worst: f64 = 0.0;
        for _ in 0..5000 {
            let q = [rng.range(-55.0, 55.0), rng.range(-30.0, 30.0), rng.range(-30.0, 30.0)];
            let qp = Point::new(q[0], q[1], q[2]);
            let truth = pts.iter().map(|p| (p - qp).norm()).fold(f64::INFINITY, f64::min);
            let got = (pts[field.nearest(&q).expect("inside the grid")] - qp).norm();
            worst = worst.max(got - truth);
        }
        assert!(
            worst <= 2.0 * diag,
            "worst excess {worst:.2} mm, two diagonals {:.2} mm",
            2.0 * diag
        );
        assert!(field.nearest(&[200.0, 0.0, 0.0]).is_none());
        assert!(NearestField::new(&[], 1.0, 1.0).is_none());
    }
}
