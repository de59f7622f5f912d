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
