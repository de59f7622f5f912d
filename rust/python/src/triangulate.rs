//! Laser-line triangulation bindings.

use crate::convert::{camera, matrix4, vectors_to_py, CameraArgs};
use crate::errors::{invalid, run_borrowed};
use binpick_core::{isometry_from_matrix, with_threads};
use binpick_core::{pixel_rays, triangulate_into, FramePose, PointStatus, Sensor};
use nalgebra::{Matrix4, Vector3};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;

fn pixel_list(arr: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; 2]>> {
    let a = arr.as_array();
    if a.ncols() != 2 {
        return Err(invalid(
            "pixels",
            &format!("must have shape (N, 2) holding (u, v), got {:?}", a.shape()),
        ));
    }
    Ok(a.rows().into_iter().map(|r| [r[0], r[1]]).collect())
}

/// Undistorted normalised rays (x, y, 1) of pixels; rows that cannot be undistorted are NaN.
#[pyfunction]
#[pyo3(signature = (camera_args, pixels))]
fn pixel_rays_py<'py>(
    py: Python<'py>,
    camera_args: CameraArgs<'py>,
    pixels: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, pyo3::PyAny>> {
    let cam = camera(&camera_args)?;
    let px = pixel_list(&pixels)?;
    let rays = run_borrowed(py, move || pixel_rays(&cam, &px))?;
    let nan = Vector3::repeat(f64::NAN);
    let v: Vec<Vector3<f64>> = rays.into_iter().map(|r| r.unwrap_or(nan)).collect();
    Ok(vectors_to_py(py, &v).into_any())
}

/// Points (N, 3), status (N,), pixels (N, 2) and the number kept of a triangulated scan.
type ScanArrays<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<u8>>,
    Bound<'py, PyArray2<f64>>,
    usize,
);

/// Triangulates a scan's laser pixels: (points in the base frame (N, 3), status (N,) uint8,
/// pixels (N, 2), kept). The first `kept` rows of points and pixels are the pixels that gave a
/// point (status 0) with their points, in input order; the pixels are the copy made of the
/// input, for the caller to keep without another copy.
#[pyfunction]
#[pyo3(signature = (camera_args, t_camera_laser0, t_flange_camera, angles, t_base_flanges, pixels, frame_index, num_threads))]
#[allow(clippy::too_many_arguments)]
fn triangulate_scan<'py>(
    py: Python<'py>,
    camera_args: CameraArgs<'py>,
    t_camera_laser0: PyReadonlyArray2<'py, f64>,
    t_flange_camera: PyReadonlyArray2<'py, f64>,
    angles: PyReadonlyArray1<'py, f64>,
    t_base_flanges: PyReadonlyArray3<'py, f64>,
    pixels: PyReadonlyArray2<'py, f64>,
    frame_index: PyReadonlyArray1<'py, i64>,
    num_threads: usize,
) -> PyResult<ScanArrays<'py>> {
    let cam = camera(&camera_args)?;
    let laser = matrix4(&t_camera_laser0, "T_camera_laser")?;
    let hand_eye = matrix4(&t_flange_camera, "T_flange_camera")?;
    let angles: Vec<f64> = angles.as_array().to_vec();
    let poses = t_base_flanges.as_array();
    if poses.shape()[1..] != [4, 4] || poses.shape()[0] != angles.len() {
        return Err(invalid(
            "T_base_flanges",
            &format!(
                "must have shape ({}, 4, 4), one pose per angle, got {:?}",
                angles.len(),
                poses.shape()
            ),
        ));
    }
    let pose_mats: Vec<Matrix4<f64>> = (0..angles.len())
        .map(|f| Matrix4::from_fn(|r, c| poses[[f, r, c]]))
        .collect();
    let input = pixels.as_array();
    if input.ncols() != 2 {
        return Err(invalid(
            "pixels",
            &format!("must have shape (N, 2) holding (u, v), got {:?}", input.shape()),
        ));
    }
    let n = input.nrows();
    // The input copy and the outputs are numpy arrays made here: numpy backs large arrays with
    // huge pages, which spares most page faults of fresh memory (a third of the time at 1e6
    // points), and the copy of the pixels is returned for the caller to keep. Until this
    // function returns no other code can reach them, so working on them without the GIL is
    // as safe as on Rust-owned data.
    let px_copy = PyArray2::<f64>::zeros(py, [n, 2], false);
    let points = PyArray2::<f64>::zeros(py, [n, 3], false);
    let mut px_rw = px_copy.readwrite();
    px_rw.as_array_mut().assign(&input);
    let mut points_rw = points.readwrite();
    let (px, _) = px_rw
        .as_slice_mut()
        .expect("a new array is contiguous")
        .as_chunks_mut::<2>();
    let (out, _) = points_rw
        .as_slice_mut()
        .expect("a new array is contiguous")
        .as_chunks_mut::<3>();
    let idx = frame_index.as_array();
    let in_range = |f: i64| (0..=u32::MAX as i64).contains(&f);
    if !idx.iter().fold(true, |ok, &f| ok & in_range(f)) {
        let (i, f) = idx
            .iter()
            .enumerate()
            .find(|(_, &f)| !in_range(f))
            .expect("an entry out of range");
        return Err(invalid(
            "frame_index",
            &format!("entry {i} is {f}; frame indices are ≥ 0"),
        ));
    }
    let idx: Vec<u32> = idx.iter().map(|&f| f as u32).collect();
    let num_threads = crate::convert::threads(num_threads)?;
    let (status, kept) = run_borrowed(py, move || {
        let sensor = Sensor {
            camera: cam,
            t_camera_laser0: isometry_from_matrix("T_camera_laser", &laser)?,
            t_flange_camera: isometry_from_matrix("T_flange_camera", &hand_eye)?,
        };
        let frames = angles
            .iter()
            .zip(&pose_mats)
            .enumerate()
            .map(|(i, (&angle, m))| {
                Ok(FramePose {
                    angle,
                    t_base_flange: isometry_from_matrix(&format!("T_base_flanges[{i}]"), m)?,
                })
            })
            .collect::<binpick_core::Result<Vec<_>>>()?;
        let mut status = vec![PointStatus::Valid; px.len()];
        with_threads(num_threads, || {
            triangulate_into(&sensor, &frames, px, &idx, out, &mut status)
        })?;
        // Moving the valid rows up in place is far cheaper than boolean masks in numpy.
        let mut kept = 0;
        for (i, &s) in status.iter().enumerate() {
            if s == PointStatus::Valid {
                out[kept] = out[i];
                px[kept] = px[i];
                kept += 1;
            }
        }
        Ok((status.into_iter().map(|s| s as u8).collect::<Vec<u8>>(), kept))
    })?;
    drop((px_rw, points_rw));
    Ok((points, PyArray1::from_vec(py, status), px_copy, kept))
}

/// Adds the triangulation functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(triangulate_scan, m)?)?;
    m.add("pixel_rays", wrap_pyfunction!(pixel_rays_py, m)?)?;
    Ok(())
}
