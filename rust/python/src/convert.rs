//! The one place where numpy arrays become nalgebra types and back.

use binpick_core::Point;
use nalgebra::{Isometry3, Matrix4, Vector3};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::errors::invalid;

/// An (N, 3) float64 array as points; the Python layer has already converted dtype and layout.
pub fn points(arr: &PyReadonlyArray2<'_, f64>, arg: &str) -> PyResult<Vec<Point>> {
    let a = arr.as_array();
    if a.ncols() != 3 {
        return Err(invalid(arg, &format!("must have shape (N, 3), got {:?}", a.shape())));
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
