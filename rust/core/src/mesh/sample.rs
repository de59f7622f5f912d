//! A part model: its mesh in millimetres and a point cloud sampled evenly over its surface.

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::mesh::TriMesh;
use crate::rng::Rng;
use crate::voxel::DiskGrid;
use nalgebra::Vector3;

/// How densely to sample a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Density {
    /// Even (blue-noise) sampling with about one point per `spacing²` of area (mm); neighbouring
    /// points are never closer than 0.75 × spacing.
    Spacing(f64),
    /// Exactly this many points, independently and uniformly over the area.
    Count(usize),
}

/// Points on a mesh surface with the outward normal of the face each lies on.
#[derive(Debug, Clone, Default)]
pub struct SurfaceSamples {
    /// Sampled points, mm.
    pub points: Vec<Point>,
    /// Unit normals, outward for a closed mesh.
    pub normals: Vec<Vector3<f64>>,
}

/// The most samples a [`Density::Count`] may ask for (10^7, about 0.5 GB of points and normals).
pub const MAX_SAMPLES: usize = 10_000_000;

/// The most samples a [`Density::Spacing`] may imply over the mesh's area (each draws 8 candidates).
pub const MAX_SPACED_SAMPLES: f64 = 5e6;

/// Ratio of the Poisson-disk radius to the nominal spacing: a maximal random disk packing with
/// radius r holds about 0.70 / r² points per unit area; with 8 candidates per s² dart throwing
/// reaches about 0.55 / r², so r = 0.75 s gives close to 1 / s².
const DISK_RATIO: f64 = 0.75;

/// Samples `mesh` uniformly over its area. Deterministic for a `seed`.
pub fn sample_surface(mesh: &TriMesh, density: Density, seed: u64) -> Result<SurfaceSamples> {
    let areas: Vec<f64> = (0..mesh.faces.len()).map(|i| 0.5 * mesh.face_cross(i).norm()).collect();
    let total: f64 = areas.iter().sum();
    if !(total > 0.0) {
        return Err(Error::Degenerate {
            arg: "mesh".into(),
            what: "its surface has zero area".into(),
            advice: "check that the file holds real triangles".into(),
        });
    }
    // Faces wound inward (negative enclosed volume) get their normals flipped.
    let flip = if mesh.volume() < 0.0 { -1.0 } else { 1.0 };
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut acc = 0.0;
    for a in &areas {
        acc += a;
        cumulative.push(acc);
    }
    let mut rng = Rng::new(seed);
    let draw = |rng: &mut Rng| -> (Point, Vector3<f64>) {
        let x = rng.uniform() * total;
        let f = cumulative.partition_point(|&c| c <= x).min(areas.len() - 1);
        let [a, b, c] = mesh.triangle(f);
        let (mut u, mut v) = (rng.uniform(), rng.uniform());
        if u + v > 1.0 {
            u = 1.0 - u;
            v = 1.0 - v;
        }
        let p = a + (b - a) * u + (c - a) * v;
        (p, flip * mesh.face_cross(f).normalize())
    };
    match density {
        Density::Count(n) => {
            if n == 0 {
                return Err(Error::invalid("count", "must be at least 1"));
            }
            if n > MAX_SAMPLES {
                return Err(Error::invalid(
                    "count",
                    format!("{n} samples is over the ceiling of {MAX_SAMPLES}; ask for fewer"),
                ));
            }
            let (points, normals) = (0..n).map(|_| draw(&mut rng)).unzip();
            Ok(SurfaceSamples { points, normals })
        }
        Density::Spacing(s) => {
            if !(s.is_finite() && s > 0.0) {
                return Err(Error::invalid(
                    "spacing",
                    format!("must be a positive length in mm, got {s}"),
                ));
            }
            let expected = total / (s * s);
            if !(expected <= MAX_SPACED_SAMPLES) {
                return Err(Error::invalid(
                    "spacing",
                    format!(
                        "{s} mm would give about {expected:.0} points over {total:.0} mm²; choose a larger spacing"
                    ),
                ));
            }
            let r = DISK_RATIO * s;
            let candidates = (expected * 8.0).ceil() as usize + 64;
            let mut grid = DiskGrid::new(r);
            let mut out = SurfaceSamples::default();
            for _ in 0..candidates {
                let (p, n) = draw(&mut rng);
                if grid.try_insert(p) {
                    out.points.push(p);
                    out.normals.push(n);
                }
            }
            Ok(out)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_cube(size: f64) -> TriMesh {
        crate::mesh::test_box(Point::origin(), Point::new(size, size, size))
    }

    #[test]
    fn spacing_gives_even_density_and_outward_normals() {
        let cube = unit_cube(100.0);
        assert!((cube.volume() - 1e6).abs() < 1e-6);
        let s = sample_surface(&cube, Density::Spacing(2.0), 1).unwrap();
        let expected = cube.area() / 4.0;
        let ratio = s.points.len() as f64 / expected;
        assert!((0.9..1.1).contains(&ratio), "ratio {ratio}");
        let c = Point::new(50.0, 50.0, 50.0);
        for (p, n) in s.points.iter().zip(&s.normals) {
            assert!(n.dot(&(p - c)) > 0.0);
        }
        // No two points closer than the disk radius.
        let idx = crate::search::KdIndex::new(&s.points);
        for p in &s.points {
            let nn = idx.knn(p, 2);
            assert!(nn[1].distance_squared.sqrt() >= DISK_RATIO * 2.0 - 1e-9);
        }
    }

    #[test]
    fn counts_and_spacings_over_the_ceiling_are_refused_before_allocating() {
        let m = unit_cube(10.0);
        for n in [MAX_SAMPLES + 1, 1 << 63, usize::MAX] {
            let err = sample_surface(&m, Density::Count(n), 1).unwrap_err();
            assert!(err.to_string().contains("ceiling"), "{err}");
        }
        for s in [1e-9, f64::MIN_POSITIVE] {
            assert!(sample_surface(&m, Density::Spacing(s), 1).is_err());
        }
    }

    #[test]
    fn count_is_exact_and_seeded() {
        let cube = unit_cube(10.0);
        let a = sample_surface(&cube, Density::Count(500), 7).unwrap();
        let b = sample_surface(&cube, Density::Count(500), 7).unwrap();
        assert_eq!(a.points.len(), 500);
        assert_eq!(a.points, b.points);
    }
}
