//! Watertight meshes from signed distance functions, by marching tetrahedra.
//!
//! Each grid cube is split into six tetrahedra around its main diagonal (the Kuhn split, which
//! neighbouring cubes share face by face); the zero crossing on each tetrahedron edge becomes a
//! vertex shared by every tetrahedron on that edge, so the surface closes without cracks.

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::collections::HashMap;

/// Cube corners as (dx, dy, dz) bits: corner i = (i & 1, (i >> 1) & 1, (i >> 2) & 1).
const KUHN: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// The most grid points [`mesh_sdf`] evaluates (2^26, about 0.5 GB of values): a finer
/// `resolution` for the part's size is refused before the grid is allocated.
pub const MAX_GRID_POINTS: f64 = 67_108_864.0;

/// Meshes the surface `sdf = 0` (negative inside) within the box `lo..hi` on a grid of `cell` mm.
/// The box must enclose the solid with at least one cell to spare. A grid of more than
/// [`MAX_GRID_POINTS`] points is refused as an invalid `resolution`.
pub fn mesh_sdf<F: Fn(&Point) -> f64 + Sync>(sdf: F, lo: Point, hi: Point, cell: f64) -> Result<TriMesh> {
    let n = ((hi - lo) / cell).map(|v| v.ceil() + 2.0);
    let points = n.x * n.y * n.z;
    if !(points.is_finite() && points <= MAX_GRID_POINTS) {
        return Err(Error::invalid(
            "resolution",
            format!(
                "{cell} mm over a {:.1} × {:.1} × {:.1} mm part needs {points:.3e} grid points, over the \
                 ceiling of {MAX_GRID_POINTS:.0}; choose a coarser resolution",
                hi.x - lo.x,
                hi.y - lo.y,
                hi.z - lo.z
            ),
        ));
    }
    let (nx, ny, nz) = (n.x as usize, n.y as usize, n.z as usize);
    let at = |i: usize, j: usize, k: usize| {
        Point::new(lo.x + i as f64 * cell, lo.y + j as f64 * cell, lo.z + k as f64 * cell)
    };
    let cancel = crate::cancel::current();
    let values: Vec<f64> = (0..nx * ny * nz)
        .into_par_iter()
        .map(|g| {
            if cancel.requested() {
                return 1.0;
            }
            let (i, j, k) = (g % nx, (g / nx) % ny, g / (nx * ny));
            let v = sdf(&at(i, j, k));
            // A value of exactly zero would put a vertex on a grid point; nudge it outside.
            if v == 0.0 {
                1e-12
            } else {
                v
            }
        })
        .collect();
    crate::cancel::check()?;
    let gid = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    let mut vertices: Vec<Point> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    let mut vertex_on = |a: usize, b: usize, vertices: &mut Vec<Point>| -> u32 {
        let key = if a < b { (a, b) } else { (b, a) };
        *edge_vertex.entry(key).or_insert_with(|| {
            let pa = at(a % nx, (a / nx) % ny, a / (nx * ny));
            let pb = at(b % nx, (b / nx) % ny, b / (nx * ny));
            let (va, vb) = (values[a], values[b]);
            let t = va / (va - vb);
            vertices.push(pa + (pb - pa) * t);
            (vertices.len() - 1) as u32
        })
    };
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let corner = |c: usize| gid(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                let ids: [usize; 8] = std::array::from_fn(corner);
                let inside_any = ids.iter().any(|&g| values[g] < 0.0);
                let outside_any = ids.iter().any(|&g| values[g] > 0.0);
                if !(inside_any && outside_any) {
                    continue;
                }
                for tet in KUHN {
                    let g = tet.map(|c| ids[c]);
                    let (ins, outs): (Vec<usize>, Vec<usize>) = g.iter().partition(|&&x| values[x] < 0.0);
                    let tris: Vec<[u32; 3]> = match ins.len() {
                        1 => vec![[
                            vertex_on(ins[0], outs[0], &mut vertices),
                            vertex_on(ins[0], outs[1], &mut vertices),
                            vertex_on(ins[0], outs[2], &mut vertices),
                        ]],
                        3 => vec![[
                            vertex_on(outs[0], ins[0], &mut vertices),
                            vertex_on(outs[0], ins[1], &mut vertices),
                            vertex_on(outs[0], ins[2], &mut vertices),
                        ]],
                        2 => {
                            let a = vertex_on(ins[0], outs[0], &mut vertices);
                            let b = vertex_on(ins[0], outs[1], &mut vertices);
                            let c = vertex_on(ins[1], outs[1], &mut vertices);
                            let d = vertex_on(ins[1], outs[0], &mut vertices);
                            vec![[a, b, c], [a, c, d]]
                        }
                        _ => vec![],
                    };
                    let centre = |set: &[usize]| {
                        set.iter().fold(Vector3::zeros(), |s, &x| {
                            s + at(x % nx, (x / nx) % ny, x / (nx * ny)).coords
                        }) / set.len() as f64
                    };
                    let outward = centre(&outs) - centre(&ins);
                    for mut t in tris {
                        let (p0, p1, p2) = (
                            vertices[t[0] as usize],
                            vertices[t[1] as usize],
                            vertices[t[2] as usize],
                        );
                        if (p1 - p0).cross(&(p2 - p0)).dot(&outward) < 0.0 {
                            t.swap(1, 2);
                        }
                        faces.push(t);
                    }
                }
            }
        }
    }
    let mut mesh = TriMesh { vertices, faces };
    mesh.drop_degenerate_faces();
    Ok(mesh)
}

/// Signed distance to a capped cylinder of radius `r` around the segment `a`–`b`.
pub fn capped_cylinder(p: &Point, a: &Point, b: &Point, r: f64) -> f64 {
    let axis = b - a;
    let len = axis.norm();
    let u = axis / len;
    let rel = p - a;
    let along = rel.dot(&u);
    let radial = (rel - u * along).norm();
    let dr = radial - r;
    let dz = (along - len * 0.5).abs() - len * 0.5;
    let outside = Vector3::new(dr.max(0.0), dz.max(0.0), 0.0).norm();
    outside + dr.max(dz).min(0.0)
}

/// Signed distance (exact zero set, approximate elsewhere) to an elliptic cylinder whose axis
/// runs from `a` along unit `axis` for `height` mm, with semi-axes `ra` along `u` and `rb` along `axis × u`.
pub fn elliptic_cylinder(
    p: &Point,
    a: &Point,
    axis: &Vector3<f64>,
    u: &Vector3<f64>,
    height: f64,
    ra: f64,
    rb: f64,
) -> f64 {
    let w = axis.cross(u);
    let rel = p - a;
    let (x, y, z) = (rel.dot(u), rel.dot(&w), rel.dot(axis));
    let dr = ((x / ra).powi(2) + (y / rb).powi(2)).sqrt() * ra.min(rb) - ra.min(rb);
    let dz = (z - height * 0.5).abs() - height * 0.5;
    let outside = Vector3::new(dr.max(0.0), dz.max(0.0), 0.0).norm();
    outside + dr.max(dz).min(0.0)
}

/// Signed distance to a sphere.
pub fn sphere(p: &Point, c: &Point, r: f64) -> f64 {
    (p - c).norm() - r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_over_the_ceiling_is_refused_before_it_is_allocated() {
        let c = Point::origin();
        let lo = Point::new(-22.0, -22.0, -22.0);
        let err = mesh_sdf(|p| sphere(p, &c, 20.0), lo, -lo, 1e-6).unwrap_err();
        assert!(err.to_string().contains("resolution"), "{err}");
        assert!(mesh_sdf(|p| sphere(p, &c, 20.0), lo, -lo, f64::MIN_POSITIVE).is_err());
    }

    #[test]
    fn sphere_mesh_is_closed_and_accurate() {
        let c = Point::origin();
        let m = mesh_sdf(
            |p| sphere(p, &c, 20.0),
            Point::new(-22.0, -22.0, -22.0),
            Point::new(22.0, 22.0, 22.0),
            1.0,
        )
        .unwrap();
        let v = m.volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 8000.0;
        assert!((v - exact).abs() / exact < 0.01, "volume {v} vs {exact}");
        // Closed: every edge is shared by exactly two faces, in opposite directions.
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for f in &m.faces {
            for e in 0..3 {
                *edges.entry((f[e], f[(e + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1), "open edge {a}-{b}");
        }
        for p in &m.vertices {
            assert!((p.coords.norm() - 20.0).abs() < 0.05);
        }
    }
}
