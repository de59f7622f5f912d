//! Triangle meshes: the type, its measures and unit conversion.

use crate::error::{Error, Result};
use crate::geometry::Point;
use nalgebra::Vector3;

/// A triangle mesh in millimetres; faces index `vertices` counter-clockwise seen from outside.
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    /// Vertex positions, mm.
    pub vertices: Vec<Point>,
    /// Triangles as vertex indices.
    pub faces: Vec<[u32; 3]>,
}

/// The scale that turns a length in `unit` into millimetres.
pub fn unit_scale(unit: &str) -> Result<f64> {
    match unit.trim().to_ascii_lowercase().as_str() {
        "mm" | "millimeter" | "millimetre" | "millimeters" | "millimetres" => Ok(1.0),
        "cm" | "centimeter" | "centimetre" | "centimeters" | "centimetres" => Ok(10.0),
        "m" | "meter" | "metre" | "meters" | "metres" => Ok(1000.0),
        "in" | "inch" | "inches" => Ok(25.4),
        _ => Err(Error::UnknownUnit { unit: unit.to_string() }),
    }
}

impl TriMesh {
    /// Builds a mesh, checking that every index is in range and every vertex finite.
    pub fn new(vertices: Vec<Point>, faces: Vec<[u32; 3]>) -> Result<Self> {
        crate::geometry::check_finite("vertices", &vertices)?;
        let n = vertices.len() as u32;
        if let Some((i, f)) = faces.iter().enumerate().find(|(_, f)| f.iter().any(|&v| v >= n)) {
            return Err(Error::invalid(
                "faces",
                format!("face {i} {f:?} indexes past the {n} vertices"),
            ));
        }
        Ok(TriMesh { vertices, faces })
    }

    /// The three corners of face `i`.
    #[inline]
    pub fn triangle(&self, i: usize) -> [Point; 3] {
        let f = self.faces[i];
        [
            self.vertices[f[0] as usize],
            self.vertices[f[1] as usize],
            self.vertices[f[2] as usize],
        ]
    }

    /// Twice-area-weighted (unnormalised) normal of face `i`.
    #[inline]
    pub fn face_cross(&self, i: usize) -> Vector3<f64> {
        let [a, b, c] = self.triangle(i);
        (b - a).cross(&(c - a))
    }

    /// Total surface area, mm².
    pub fn area(&self) -> f64 {
        (0..self.faces.len()).map(|i| 0.5 * self.face_cross(i).norm()).sum()
    }

    /// Signed enclosed volume, mm³ (positive for a closed outward-facing mesh).
    pub fn volume(&self) -> f64 {
        (0..self.faces.len())
            .map(|i| {
                let [a, b, c] = self.triangle(i);
                a.coords.dot(&b.coords.cross(&c.coords)) / 6.0
            })
            .sum()
    }

    /// Axis-aligned bounds (min, max) of the vertices used by faces.
    pub fn bounds(&self) -> (Point, Point) {
        let mut lo = Point::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let mut hi = Point::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for f in &self.faces {
            for &v in f {
                let p = self.vertices[v as usize];
                lo = lo.inf(&p);
                hi = hi.sup(&p);
            }
        }
        (lo, hi)
    }

    /// Largest distance between two vertices, mm: exact for up to 20 000 vertices, otherwise
    /// the best of repeated farthest-point sweeps (within a fraction of a percent in practice).
    pub fn diameter(&self) -> f64 {
        use rayon::prelude::*;
        let v = &self.vertices;
        if v.len() < 2 {
            return 0.0;
        }
        if v.len() <= 20_000 {
            return v
                .par_iter()
                .enumerate()
                .map(|(i, a)| v[i + 1..].iter().map(|b| (b - a).norm_squared()).fold(0.0, f64::max))
                .reduce(|| 0.0, f64::max)
                .sqrt();
        }
        let mut best = 0.0f64;
        let mut a = v[0];
        for _ in 0..6 {
            let far = v
                .iter()
                .max_by(|p, q| (*p - a).norm_squared().total_cmp(&(*q - a).norm_squared()))
                .unwrap();
            best = best.max((far - a).norm());
            a = *far;
        }
        best
    }

    /// Multiplies every vertex by `s` (for unit conversion).
    pub fn scaled(mut self, s: f64) -> Self {
        for p in &mut self.vertices {
            p.coords *= s;
        }
        self
    }

    /// Drops faces with zero area or repeated corners, returning how many were dropped.
    pub fn drop_degenerate_faces(&mut self) -> usize {
        let before = self.faces.len();
        let verts = &self.vertices;
        self.faces.retain(|f| {
            f[0] != f[1] && f[1] != f[2] && f[0] != f[2] && {
                let (a, b, c) = (verts[f[0] as usize], verts[f[1] as usize], verts[f[2] as usize]);
                (b - a).cross(&(c - a)).norm_squared() > 0.0
            }
        });
        before - self.faces.len()
    }
}

/// An axis-aligned box from `lo` to `hi` as 12 outward-facing triangles: the test fixture of
/// the crate's unit tests (vertex `i` takes `hi` on the axes whose bit is set in `i`).
#[cfg(test)]
pub(crate) fn test_box(lo: Point, hi: Point) -> TriMesh {
    let v: Vec<Point> = (0..8)
        .map(|i| {
            let pick = |bit: usize, axis: usize| if (i >> bit) & 1 == 1 { hi[axis] } else { lo[axis] };
            Point::new(pick(0, 0), pick(1, 1), pick(2, 2))
        })
        .collect();
    let faces = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    TriMesh::new(v, faces).unwrap()
}
