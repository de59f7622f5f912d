//! The one place where numpy arrays become nalgebra types and back.

use binpick_core::{BinBox, BranchLayout, Part, Point, TriMesh};
use nalgebra::{Isometry3, Matrix4, Vector3};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;

use crate::errors::invalid;

/// An (N, 3) float64 array as points; the Python layer has already converted dtype and layout.
pub fn points(arr: &PyReadonlyArray2<'_, f64>, arg: &str) -> PyResult<Vec<Point>> {
    let a = arr.as_array();
    if a.ncols() != 3 {
        return Err(invalid(arg, &format!("must have shape (N, 3), got {:?}", a.shape())));
    }
    if let Some(flat) = a.as_slice() {
        // C-contiguous (what the Python layer passes): straight from the buffer.
        return Ok(flat.chunks_exact(3).map(|r| Point::new(r[0], r[1], r[2])).collect());
    }
    Ok(a.rows().into_iter().map(|r| Point::new(r[0], r[1], r[2])).collect())
}

/// An (N, 3) float64 array as vectors.
pub fn vectors(arr: &PyReadonlyArray2<'_, f64>, arg: &str) -> PyResult<Vec<Vector3<f64>>> {
    Ok(points(arr, arg)?.into_iter().map(|p| p.coords).collect())
}

/// A (4, 4) float64 array as a matrix.
pub fn matrix4(arr: &PyReadonlyArray2<'_, f64>, arg: &str) -> PyResult<Matrix4<f64>> {
    let a = arr.as_array();
    if a.shape() != [4, 4] {
        return Err(invalid(arg, &format!("must have shape (4, 4), got {:?}", a.shape())));
    }
    Ok(Matrix4::from_fn(|r, c| a[[r, c]]))
}

/// Points as a new (N, 3) float64 array.
pub fn points_to_py<'py>(py: Python<'py>, pts: &[Point]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = pts.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    PyArray2::from_owned_array(py, Array2::from_shape_vec((pts.len(), 3), flat).expect("n×3"))
}

/// Vectors as a new (N, 3) float64 array.
pub fn vectors_to_py<'py>(py: Python<'py>, v: &[Vector3<f64>]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = v.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    PyArray2::from_owned_array(py, Array2::from_shape_vec((v.len(), 3), flat).expect("n×3"))
}

/// A rigid transform as a new (4, 4) float64 array.
pub fn isometry_to_py<'py>(py: Python<'py>, t: &Isometry3<f64>) -> Bound<'py, PyArray2<f64>> {
    let m = t.to_homogeneous();
    PyArray2::from_owned_array(py, Array2::from_shape_fn((4, 4), |(r, c)| m[(r, c)]))
}

/// Indices as a new int64 array.
pub fn indices_to_py<'py>(py: Python<'py>, idx: &[usize]) -> Bound<'py, PyArray1<i64>> {
    PyArray1::from_vec(py, idx.iter().map(|&i| i as i64).collect())
}

/// A 3-element float64 array as a vector.
pub fn vector3(arr: &PyReadonlyArray1<'_, f64>, arg: &str) -> PyResult<Vector3<f64>> {
    let a = arr.as_array();
    if a.len() != 3 {
        return Err(invalid(arg, &format!("must have 3 elements, got {}", a.len())));
    }
    Ok(Vector3::new(a[0], a[1], a[2]))
}

/// A (2, 3) float64 array ((xmin, ymin, zmin), (xmax, ymax, zmax)) as a bin box (its values
/// are checked where the box is used).
pub fn bin_box(arr: &PyReadonlyArrayDyn<'_, f64>, arg: &str) -> PyResult<BinBox> {
    let a = arr.as_array();
    if a.shape() != [2, 3] {
        return Err(invalid(
            arg,
            &format!(
                "expected ((xmin, ymin, zmin), (xmax, ymax, zmax)), got shape {:?}",
                a.shape()
            ),
        ));
    }
    let corner = |r: usize| Point::new(a[[r, 0]], a[[r, 1]], a[[r, 2]]);
    Ok(BinBox {
        min: corner(0),
        max: corner(1),
    })
}

/// A bin box as a new (2, 3) float64 array.
pub fn bin_box_to_py<'py>(py: Python<'py>, b: &BinBox) -> Bound<'py, PyArray2<f64>> {
    points_to_py(py, &[b.min, b.max])
}

/// Triangles as a new (M, 3) int64 array.
pub fn faces_to_py<'py>(py: Python<'py>, faces: &[[u32; 3]]) -> Bound<'py, PyArray2<i64>> {
    let flat: Vec<i64> = faces.iter().flat_map(|f| f.map(|v| v as i64)).collect();
    PyArray2::from_owned_array(py, Array2::from_shape_vec((faces.len(), 3), flat).expect("m×3"))
}

/// Vertices (V, 3) and faces (M, 3) as a mesh; every face must index a vertex.
pub fn mesh_from_py(vertices: &PyReadonlyArray2<'_, f64>, faces: &PyReadonlyArray2<'_, i64>) -> PyResult<TriMesh> {
    let v = points(vertices, "vertices")?;
    let f = faces.as_array();
    if f.ncols() != 3 {
        return Err(invalid(
            "faces",
            &format!("must have shape (M, 3), got {:?}", f.shape()),
        ));
    }
    let mut out = Vec::with_capacity(f.nrows());
    for (i, r) in f.rows().into_iter().enumerate() {
        if r.iter().any(|&x| x < 0 || x >= v.len() as i64) {
            return Err(invalid(
                "faces",
                &format!("row {i} {:?} indexes outside the {} vertices", r.to_vec(), v.len()),
            ));
        }
        out.push([r[0] as u32, r[1] as u32, r[2] as u32]);
    }
    TriMesh::new(v, out).map_err(crate::errors::to_py)
}

/// Branch rows [dx, dy, dz, length, radius] (none or empty: no layout) and the special
/// feature's direction as a branch layout.
pub fn branch_layout(
    branches: Option<PyReadonlyArray2<'_, f64>>,
    special: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<Option<BranchLayout>> {
    let Some(b) = branches else { return Ok(None) };
    let a = b.as_array();
    if a.ncols() != 5 {
        return Err(invalid("branches", "rows must be [dx, dy, dz, length, radius]"));
    }
    if a.nrows() == 0 {
        return Ok(None);
    }
    let special = special.map(|s| vector3(&s, "special")).transpose()?;
    Ok(Some(BranchLayout {
        directions: a
            .rows()
            .into_iter()
            .map(|r| Vector3::new(r[0], r[1], r[2]).normalize())
            .collect(),
        lengths: a.rows().into_iter().map(|r| r[3]).collect(),
        radius: a.rows().into_iter().map(|r| r[4]).fold(0.0, f64::max),
        special: special.map(|s| s.normalize()),
    }))
}

/// A part's mesh and branches: (vertices, faces, branch rows [dx, dy, dz, length, radius]).
pub fn part_to_py<'py>(py: Python<'py>, part: Part) -> PartArrays<'py> {
    let rows: Vec<f64> = part
        .branches
        .iter()
        .flat_map(|b| [b.direction.x, b.direction.y, b.direction.z, b.length, b.radius])
        .collect();
    let branches = PyArray2::from_owned_array(py, Array2::from_shape_vec((part.branches.len(), 5), rows).expect("k×5"));
    (
        points_to_py(py, &part.mesh.vertices),
        faces_to_py(py, &part.mesh.faces),
        branches,
    )
}

/// (vertices, faces, branch rows) of a built-in part.
pub type PartArrays<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<i64>>,
    Bound<'py, PyArray2<f64>>,
);

/// Rotations as nested (K, 3, 3) lists.
pub fn rotations_to_rows(rotations: &[nalgebra::UnitQuaternion<f64>]) -> Vec<Vec<Vec<f64>>> {
    rotations
        .iter()
        .map(|q| {
            let m = q.to_rotation_matrix();
            (0..3).map(|r| (0..3).map(|c| m[(r, c)]).collect()).collect()
        })
        .collect()
}

/// The camera as every binding takes it, from `binpick.camera.CameraIntrinsics`:
/// `(width, height, K (3, 3), dist (5,) = [k1, k2, p1, p2, k3])`.
pub type CameraArgs<'py> = (u32, u32, PyReadonlyArray2<'py, f64>, numpy::PyReadonlyArray1<'py, f64>);

/// The one camera model (`binpick_core::Camera`) from its Python description; triangulation and
/// the renderer build it here, the same way.
pub fn camera(args: &CameraArgs<'_>) -> PyResult<binpick_core::Camera> {
    let (width, height, k, dist) = args;
    let k = k.as_array();
    if k.shape() != [3, 3] {
        return Err(invalid("K", &format!("must have shape (3, 3), got {:?}", k.shape())));
    }
    let d = dist.as_array();
    if d.len() != 5 {
        return Err(invalid(
            "dist",
            &format!("must hold 5 coefficients [k1, k2, p1, p2, k3], got {}", d.len()),
        ));
    }
    let km = nalgebra::Matrix3::from_fn(|r, c| k[[r, c]]);
    binpick_core::Camera::new(*width, *height, &km, [d[0], d[1], d[2], d[3], d[4]]).map_err(crate::errors::to_py)
}

/// A (4, 4) float64 array as a rigid transform, checked by the core's `isometry_from_matrix`.
pub fn isometry(arr: &PyReadonlyArray2<'_, f64>, arg: &str) -> PyResult<Isometry3<f64>> {
    binpick_core::isometry_from_matrix(arg, &matrix4(arr, arg)?).map_err(crate::errors::to_py)
}

/// An (N, 4, 4) float64 array as rigid transforms, each checked as [`isometry`] checks one.
pub fn isometries(arr: &numpy::PyReadonlyArray3<'_, f64>, arg: &str) -> PyResult<Vec<Isometry3<f64>>> {
    let a = arr.as_array();
    if a.shape()[1..] != [4, 4] {
        return Err(invalid(arg, &format!("must have shape (N, 4, 4), got {:?}", a.shape())));
    }
    a.outer_iter()
        .map(|m| {
            let m = Matrix4::from_fn(|r, c| m[[r, c]]);
            binpick_core::isometry_from_matrix(arg, &m).map_err(crate::errors::to_py)
        })
        .collect()
}

/// Largest `num_threads` accepted: above the machine's cores a request is clamped to them, above
/// this it is refused as a mistake (it would start that many OS threads).
pub const MAX_THREADS: usize = 256;

/// Worker threads for a native call: 0 (all cores) stays 0, a request above the machine's cores
/// is clamped to them, beyond [`MAX_THREADS`] an `InvalidInputError`. Every binding that takes
/// `num_threads` passes it through here, so no call starts more threads than there are cores.
pub fn threads(num_threads: usize) -> PyResult<usize> {
    if num_threads > MAX_THREADS {
        return Err(invalid(
            "num_threads",
            &format!("{num_threads} is above the ceiling of {MAX_THREADS}; pass 0 for all cores"),
        ));
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    Ok(num_threads.min(cores))
}

/// An optional whole-number argument of a config class in [0, `max`]: a bool or a non-integer
/// is an `InvalidTypeError`, a negative or too large integer an `InvalidInputError` naming it.
/// A finite real number (an int or a float, not a bool) from an optional Python argument.
pub fn real_number(value: Option<&Bound<'_, PyAny>>, arg: &str) -> PyResult<Option<f64>> {
    let Some(value) = value else { return Ok(None) };
    let numeric = value.is_instance_of::<pyo3::types::PyInt>() || value.is_instance_of::<pyo3::types::PyFloat>();
    if value.is_instance_of::<pyo3::types::PyBool>() || !numeric {
        return Err(crate::errors::wrong_type(arg, "a number", value));
    }
    match value.extract::<f64>() {
        Ok(v) if v.is_finite() => Ok(Some(v)),
        _ => {
            let shown: String = value.to_string().chars().take(40).collect();
            Err(invalid(arg, &format!("{shown} is not a finite number; pass one")))
        }
    }
}

pub fn whole_number(value: Option<&Bound<'_, PyAny>>, arg: &str, max: u64) -> PyResult<Option<u64>> {
    let Some(value) = value else { return Ok(None) };
    if value.is_instance_of::<pyo3::types::PyBool>() || !value.is_instance_of::<pyo3::types::PyInt>() {
        return Err(crate::errors::wrong_type(arg, "an integer", value));
    }
    match value.extract::<u64>() {
        Ok(v) if v <= max => Ok(Some(v)),
        _ => Err(invalid(
            arg,
            &format!("{value} is outside [0, {max}]; pass an integer inside that range"),
        )),
    }
}
