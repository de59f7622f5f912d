//! Laser-line triangulation bindings.

use crate::convert::{matrix4, vectors_to_py};
use crate::errors::{invalid, run};
use binpick_core::cloud::isometry_from_matrix;
use binpick_core::parallel;
use binpick_core::triangulate::{pixel_rays, triangulate_into, Camera, FramePose, PointStatus, Sensor};
use nalgebra::{Matrix3, Matrix4, Vector3};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;

fn camera(width: u32, height: u32, k: &PyReadonlyArray2<'_, f64>, dist: &PyReadonlyArray1<'_, f64>) -> PyResult<Camera> {
    let k = k.as_array();
    if k.shape() != [3, 3] {
        return Err(invalid("K", &format!("must have shape (3, 3), got {:?}", k.shape())));
    }
    let d = dist.as_array();
    if d.len() != 5 {
        return Err(invalid("dist", &format!("must hold 5 coefficients [k1, k2, p1, p2, k3], got {}", d.len())));
    }
    let km = Matrix3::from_fn(|r, c| k[[r, c]]);
    Camera::new(width, height, &km, [d[0], d[1], d[2], d[3], d[4]]).map_err(crate::errors::to_py)
}

fn pixel_list(arr: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; 2]>> {
    let a = arr.as_array();
    if a.ncols() != 2 {
        return Err(invalid("pixels", &format!("must have shape (N, 2) holding (u, v), got {:?}", a.shape())));
    }
    // A C-contiguous array (what the Python layer passes) is copied in one pass.
    if let Some(flat) = a.as_slice() {
        return Ok(flat.chunks_exact(2).map(|r| [r[0], r[1]]).collect());
    }
    Ok(a.rows().into_iter().map(|r| [r[0], r[1]]).collect())
}

/// Undistorted normalised rays (x, y, 1) of pixels; rows that cannot be undistorted are NaN.
#[pyfunction]
#[pyo3(signature = (width, height, k, dist, pixels))]
fn pixel_rays_py<'py>(
    py: Python<'py>,
    width: u32,
    height: u32,
    k: PyReadonlyArray2<'py, f64>,
    dist: PyReadonlyArray1<'py, f64>,
    pixels: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, pyo3::PyAny>> {
    let cam = camera(width, height, &k, &dist)?;
    let px = pixel_list(&pixels)?;
    let rays = run(py, move || pixel_rays(&cam, &px))?;
    let nan = Vector3::repeat(f64::NAN);
    let v: Vec<Vector3<f64>> = rays.into_iter().map(|r| r.unwrap_or(nan)).collect();
    Ok(vectors_to_py(py, &v).into_any())
}

/// Points (N, 3), status (N,), pixels (N, 2) of a triangulated scan.
type ScanArrays<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u8>>, Bound<'py, PyArray2<f64>>);

/// Triangulates a scan's laser pixels: (points in the base frame (N, 3), status (N,) uint8,
/// the pixels as copied in (N, 2), for the caller to keep without another copy).
#[pyfunction]
#[pyo3(signature = (width, height, k, dist, t_camera_laser0, t_flange_camera, angles, t_base_flanges, pixels, frame_index, num_threads))]
#[allow(clippy::too_many_arguments)]
fn triangulate_scan<'py>(
    py: Python<'py>,
    width: u32,
    height: u32,
    k: PyReadonlyArray2<'py, f64>,
    dist: PyReadonlyArray1<'py, f64>,
    t_camera_laser0: PyReadonlyArray2<'py, f64>,
    t_flange_camera: PyReadonlyArray2<'py, f64>,
    angles: PyReadonlyArray1<'py, f64>,
    t_base_flanges: PyReadonlyArray3<'py, f64>,
    pixels: PyReadonlyArray2<'py, f64>,
    frame_index: PyReadonlyArray1<'py, i64>,
    num_threads: usize,
) -> PyResult<ScanArrays<'py>> {
    let cam = camera(width, height, &k, &dist)?;
    let laser = matrix4(&t_camera_laser0, "T_camera_laser")?;
    let hand_eye = matrix4(&t_flange_camera, "T_flange_camera")?;
    let angles: Vec<f64> = angles.as_array().to_vec();
    let poses = t_base_flanges.as_array();
    if poses.shape()[1..] != [4, 4] || poses.shape()[0] != angles.len() {
        return Err(invalid(
            "T_base_flanges",
            &format!("must have shape ({}, 4, 4), one pose per angle, got {:?}", angles.len(), poses.shape()),
        ));
    }
    let pose_mats: Vec<Matrix4<f64>> = (0..angles.len()).map(|f| Matrix4::from_fn(|r, c| poses[[f, r, c]])).collect();
    let px = pixel_list(&pixels)?;
    let idx = frame_index.as_array();
    let in_range = |f: i64| (0..=u32::MAX as i64).contains(&f);
    if !idx.iter().fold(true, |ok, &f| ok & in_range(f)) {
        let (i, f) = idx.iter().enumerate().find(|(_, &f)| !in_range(f)).expect("an entry out of range");
        return Err(invalid("frame_index", &format!("entry {i} is {f}; frame indices are ≥ 0")));
    }
    let idx: Vec<u32> = idx.iter().map(|&f| f as u32).collect();
    let (points, status, px) = run(py, move || {
        let sensor = Sensor {
            camera: cam,
            t_camera_laser0: isometry_from_matrix("T_camera_laser", &laser)?,
            t_flange_camera: isometry_from_matrix("T_flange_camera", &hand_eye)?,
        };
        let frames = angles
            .iter()
            .zip(&pose_mats)
            .enumerate()
            .map(|(i, (&angle, m))| Ok(FramePose { angle, t_base_flange: isometry_from_matrix(&format!("T_base_flanges[{i}]"), m)? }))
            .collect::<binpick_core::Result<Vec<_>>>()?;
        let mut points = vec![[0.0; 3]; px.len()];
        let mut status = vec![PointStatus::Valid; px.len()];
        parallel::with_threads(num_threads, || triangulate_into(&sensor, &frames, &px, &idx, &mut points, &mut status))?;
        let status: Vec<u8> = status.into_iter().map(|s| s as u8).collect();
        Ok((points, status, px))
    })?;
    // The buffers become the numpy arrays' storage without a copy.
    let n = points.len();
    let points = Array2::from_shape_vec((n, 3), points.into_flattened()).expect("n×3");
    let px = Array2::from_shape_vec((n, 2), px.into_flattened()).expect("n×2");
    Ok((PyArray2::from_owned_array(py, points), PyArray1::from_vec(py, status), PyArray2::from_owned_array(py, px)))
}

/// Adds the triangulation functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(triangulate_scan, m)?)?;
    m.add("pixel_rays", wrap_pyfunction!(pixel_rays_py, m)?)?;
    Ok(())
}
