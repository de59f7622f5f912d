//! The shapes a pile's parts collide through: the mesh simplified by vertex clustering,
//! decomposed by V-HACD, and each piece replaced by the exact convex hull of the mesh triangles it
//! covers, so the hulls enclose the real surface and piled meshes do not interpenetrate beyond
//! the solver's contact tolerance.

use super::convert;
use super::pile::PileParams;
use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use parry3d::math::{Pose, Vector};
use parry3d::shape::SharedShape;
use parry3d::transformation::vhacd::{VHACDParameters, VHACD};
use std::collections::HashMap;

/// Simplifies a mesh by clustering its vertices on a grid of `cell` mm (each cluster becomes the
/// mean of its vertices) and dropping faces that collapse.
pub fn simplify(mesh: &TriMesh, cell: f64) -> TriMesh {
    if cell <= 0.0 {
        return mesh.clone();
    }
    let mut index: HashMap<(i64, i64, i64), u32> = HashMap::new();
    let mut sums: Vec<(Vector3<f64>, f64)> = Vec::new();
    let remap: Vec<u32> = mesh
        .vertices
        .iter()
        .map(|p| {
            let key = (
                (p.x / cell).floor() as i64,
                (p.y / cell).floor() as i64,
                (p.z / cell).floor() as i64,
            );
            let id = *index.entry(key).or_insert_with(|| {
                sums.push((Vector3::zeros(), 0.0));
                sums.len() as u32 - 1
            });
            sums[id as usize].0 += p.coords;
            sums[id as usize].1 += 1.0;
            id
        })
        .collect();
    let vertices = sums.iter().map(|(s, n)| Point::from(s / *n)).collect();
    let mut seen = std::collections::HashSet::new();
    let faces = mesh
        .faces
        .iter()
        .map(|f| f.map(|v| remap[v as usize]))
        .filter(|f| f[0] != f[1] && f[1] != f[2] && f[0] != f[2])
        .filter(|f| {
            let mut k = *f;
            k.sort_unstable();
            seen.insert(k)
        })
        .collect();
    TriMesh { vertices, faces }
}

/// A convex piece: its vertices and triangles.
pub type Hull = (Vec<Point>, Vec<[u32; 3]>);

/// Convex pieces (vertices, triangles) whose union encloses `mesh`: V-HACD on the simplified mesh,
/// each piece the exact hull of the simplified triangles it covers.
pub fn convex_decomposition(mesh: &TriMesh, params: &PileParams) -> Result<Vec<Hull>> {
    params.validate()?;
    let shape = decomposition_shape(mesh, params)?;
    if shape.as_compound().is_none() {
        return Err(Error::invalid("mesh", "the convex decomposition failed"));
    }
    Ok(hulls_of(&shape))
}

/// The convex pieces (vertices, triangles) of a compound shape, in its frame.
pub(super) fn hulls_of(shape: &SharedShape) -> Vec<Hull> {
    let Some(c) = shape.as_compound() else {
        return Vec::new();
    };
    c.shapes()
        .iter()
        .filter_map(|(pos, s)| {
            let (v, i) = s
                .as_convex_polyhedron()
                .or_else(|| s.as_round_convex_polyhedron().map(|r| &r.inner_shape))?
                .to_trimesh();
            Some((
                v.into_iter().map(|p| convert::point(pos.transform_point(p))).collect(),
                i,
            ))
        })
        .collect()
}

pub(super) fn decomposition_shape(mesh: &TriMesh, params: &PileParams) -> Result<SharedShape> {
    if mesh.faces.len() < 4 {
        return Err(Error::invalid(
            "mesh",
            format!("has {} faces; a part needs a closed mesh", mesh.faces.len()),
        ));
    }
    let coarse = simplify(mesh, params.simplify_cell);
    let mut coarse = if coarse.faces.len() >= 4 { coarse } else { mesh.clone() };
    coarse.drop_degenerate_faces();
    let verts: Vec<Vector> = coarse.vertices.iter().map(convert::point_vec).collect();
    let vhacd = VHACDParameters {
        resolution: params.decomposition_resolution,
        max_convex_hulls: params.max_convex_hulls,
        ..Default::default()
    };
    let pieces =
        VHACD::decompose(&vhacd, &verts, &coarse.faces, false).compute_convex_hulls(vhacd.convex_hull_downsampling);
    // V-HACD's hulls bound the voxelised volume: a voxel too fat in places, too thin in others.
    // Each piece is rebuilt as the hull of the mesh's own vertices it holds (within a margin, so
    // that neighbouring pieces overlap); a vertex no piece holds joins the piece it is least
    // outside of. The union then encloses the mesh and hugs its surface.
    let planes: Vec<Vec<(Vector, f32)>> = pieces
        .iter()
        .map(|(v, f)| {
            let c = v.iter().fold(Vector::ZERO, |a, p| a + *p) / v.len().max(1) as f32;
            f.iter()
                .filter_map(|t| {
                    let (a, b, d) = (v[t[0] as usize], v[t[1] as usize], v[t[2] as usize]);
                    let mut n = (b - a).cross(d - a).try_normalize()?;
                    if n.dot(a - c) < 0.0 {
                        n = -n;
                    }
                    Some((n, n.dot(a)))
                })
                .collect()
        })
        .collect();
    if planes.is_empty() {
        return Err(Error::invalid(
            "mesh",
            "the convex decomposition produced no piece; pass a closed, non-flat mesh",
        ));
    }
    let (lo, hi) = mesh.bounds();
    let margin = (0.5 * (hi - lo).max() / params.decomposition_resolution as f64) as f32;
    let mut points: Vec<Vec<Vector>> = vec![Vec::new(); planes.len()];
    let outside = |p: Vector| -> Vec<f32> {
        planes
            .iter()
            .map(|pl| pl.iter().map(|(n, d)| n.dot(p) - d).fold(f32::NEG_INFINITY, f32::max))
            .collect()
    };
    for p in mesh.vertices.iter().map(convert::point_vec) {
        let out = outside(p);
        let mut held = false;
        for (i, o) in out.iter().enumerate() {
            if *o <= margin {
                points[i].push(p);
                held = true;
            }
        }
        if !held {
            let best = out
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .map(|(i, _)| i)
                .expect("a piece");
            points[best].push(p);
        }
    }
    // A low-poly CAD mesh (a box-like bracket: a dozen vertices) leaves pieces with too few of
    // its vertices to span a volume (a flat hull has no mass and never falls); points sampled
    // over the faces fill those pieces.
    const FEW: usize = 16;
    if points.iter().any(|p| p.len() < FEW) {
        let spacing = (4.0 * margin as f64).max(1e-3 * (hi - lo).max());
        let surface =
            crate::mesh::sample::sample_surface(mesh, crate::mesh::sample::Density::Spacing(spacing), params.seed)?
                .points;
        let sparse: Vec<bool> = points.iter().map(|p| p.len() < FEW).collect();
        for p in surface.iter().map(convert::point_vec) {
            for (i, o) in outside(p).iter().enumerate() {
                if sparse[i] && *o <= margin {
                    points[i].push(p);
                }
            }
        }
    }
    let parts: Vec<(Pose, SharedShape)> = points
        .iter()
        .filter(|p| p.len() >= 4)
        .filter_map(|pts| SharedShape::round_convex_hull(pts, params.skin as f32).map(|s| (Pose::IDENTITY, s)))
        .collect();
    if parts.is_empty() {
        return Err(Error::invalid(
            "mesh",
            "the convex decomposition produced no piece; pass a closed, non-flat mesh",
        ));
    }
    Ok(SharedShape::compound(parts))
}
