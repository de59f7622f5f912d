//! Clouds, normals, voxels, meshes, PLY files and built-in parts.

use crate::convert::{faces_to_py, indices_to_py, mesh_from_py, part_to_py, points, points_to_py, vector3};
use crate::convert::{isometries, threads, vectors, vectors_to_py, PartArrays};
use crate::errors::{invalid, run, run_borrowed};
use binpick_core::parts;
use binpick_core::{estimate_normals as core_normals, unit_scale, Orientation};
use binpick_core::{read_mesh as core_read_mesh, read_ply as core_read_ply, write_ply as core_write_ply};
use binpick_core::{sample_surface, voxel_downsample as core_voxel, with_threads};
use binpick_core::{Clearance, Density, GripperShape, KdIndex, Point, PointGrid, Sweep};
use nalgebra::Vector3;
use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use std::path::PathBuf;
use std::sync::Arc;

type Arr<'py> = Bound<'py, PyArray2<f64>>;

/// Normals by k-NN PCA, facing `viewpoint` (a point) or else `direction`.
#[pyfunction]
#[pyo3(signature = (points_in, k, viewpoint, direction, num_threads))]
fn estimate_normals<'py>(
    py: Python<'py>,
    points_in: PyReadonlyArray2<'py, f64>,
    k: usize,
    viewpoint: Option<PyReadonlyArray1<'py, f64>>,
    direction: Option<PyReadonlyArray1<'py, f64>>,
    num_threads: usize,
) -> PyResult<Arr<'py>> {
    let pts = points(&points_in, "points")?;
    let orientation = match (viewpoint, direction) {
        (Some(v), _) => Orientation::TowardPoint(Point::from(vector3(&v, "viewpoint")?)),
        (None, Some(d)) => Orientation::TowardDirection(vector3(&d, "direction")?),
        (None, None) => Orientation::TowardDirection(Vector3::z()),
    };
    let num_threads = threads(num_threads)?;
    let normals = run(py, move || {
        with_threads(num_threads, || {
            let index = KdIndex::new(&pts);
            core_normals(&pts, &index, k, orientation)
        })
    })?;
    Ok(vectors_to_py(py, &normals))
}

/// The depth noise σ (mm) of a scan along the direction toward its sensor (`viewpoint`, a point,
/// or else `direction`), read without a model; None where too few patches fit.
#[pyfunction]
#[pyo3(signature = (points_in, viewpoint, direction))]
fn scan_noise(
    py: Python<'_>,
    points_in: PyReadonlyArray2<'_, f64>,
    viewpoint: Option<PyReadonlyArray1<'_, f64>>,
    direction: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<Option<f64>> {
    let pts = points(&points_in, "points")?;
    let orientation = match (viewpoint, direction) {
        (Some(v), _) => Orientation::TowardPoint(Point::from(vector3(&v, "viewpoint")?)),
        (None, Some(d)) => Orientation::TowardDirection(vector3(&d, "direction")?),
        (None, None) => Orientation::TowardDirection(Vector3::z()),
    };
    run(py, move || Ok(binpick_core::scan_noise(&pts, orientation)))
}

/// The distance (mm) from each point to its nearest `reference` point (a KD-tree over the
/// reference; infinity when the reference is empty).
#[pyfunction]
#[pyo3(signature = (points_in, reference, num_threads))]
fn nearest_distances<'py>(
    py: Python<'py>,
    points_in: PyReadonlyArray2<'py, f64>,
    reference: PyReadonlyArray2<'py, f64>,
    num_threads: usize,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    use rayon::prelude::*;
    let pts = points(&points_in, "points")?;
    let refs = points(&reference, "reference")?;
    let num_threads = threads(num_threads)?;
    let d = run(py, move || {
        with_threads(num_threads, || {
            let index = KdIndex::new(&refs);
            Ok(pts
                .par_iter()
                .map(|p| index.nearest(p).map_or(f64::INFINITY, |n| n.distance_squared.sqrt()))
                .collect::<Vec<f64>>())
        })
    })?;
    Ok(numpy::PyArray1::from_vec(py, d))
}

/// The gripper of `shape` = (tip depth, finger length, finger width, finger thickness, body
/// radius, body length), mm; those and the `lengths` it is used with must be finite.
fn gripper_shape(shape: [f64; 6], lengths: &[f64]) -> PyResult<GripperShape> {
    if shape.iter().chain(lengths).any(|v| !v.is_finite()) {
        return Err(invalid("shape", "every length must be finite (mm)"));
    }
    let [tip_depth, finger_length, finger_width, finger_thickness, body_radius, body_length] = shape;
    Ok(GripperShape {
        tip_depth,
        finger_length,
        finger_width,
        finger_thickness,
        body_radius,
        body_length,
    })
}

/// The fingers' `openings`, one for each of `count` points or poses (`what`).
fn one_each(openings: &PyReadonlyArray1<'_, f64>, count: usize, what: &str) -> PyResult<Vec<f64>> {
    let openings = openings.as_slice()?.to_vec();
    if openings.len() != count {
        return Err(invalid("openings", &format!("one opening per {what}")));
    }
    Ok(openings)
}

/// Which `points_in` (gripper frame) lie inside the gripper of `shape`, the fingers `openings`
/// (one per point) apart; see `GripperShape::occupied`.
#[pyfunction]
#[pyo3(signature = (points_in, openings, shape, margin, grow))]
fn gripper_occupied<'py>(
    py: Python<'py>,
    points_in: PyReadonlyArray2<'py, f64>,
    openings: PyReadonlyArray1<'py, f64>,
    shape: [f64; 6],
    margin: f64,
    grow: f64,
) -> PyResult<Bound<'py, numpy::PyArray1<bool>>> {
    let pts = points(&points_in, "points")?;
    let (shape, clearance) = (gripper_shape(shape, &[margin, grow])?, Clearance { margin, grow });
    let openings = one_each(&openings, pts.len(), "point")?;
    let inside = pts
        .iter()
        .zip(&openings)
        .map(|(p, &w)| shape.occupied(p, w, clearance))
        .collect();
    Ok(numpy::PyArray1::from_vec(py, inside))
}

/// Scene points (base frame, (N, 3)) bucketed once for many counts of the gripper against them:
/// `gripper_hits` takes one in place of an array (the planner counts one scene at batch after
/// batch of grasps).
#[pyclass(frozen, module = "binpick._core")]
pub struct GripperPoints {
    grid: Arc<PointGrid>,
}

#[pymethods]
impl GripperPoints {
    #[new]
    #[pyo3(signature = (points_in))]
    fn new(py: Python<'_>, points_in: PyReadonlyArray2<'_, f64>) -> PyResult<Self> {
        let pts = points(&points_in, "points")?;
        let grid = run_borrowed(py, || Ok(PointGrid::new(&pts)))?;
        Ok(Self { grid: Arc::new(grid) })
    }

    fn __len__(&self) -> usize {
        self.grid.len()
    }
}

/// How many `points_in` (base frame: an (N, 3) array or a `GripperPoints`) the gripper of `shape`
/// meets at each pose `T_base_gripper` (K, 4, 4), its fingers `openings[k]` apart, coming in
/// `back` mm along its axis, each point standing for what lies below it down to `floor` (None:
/// itself), its fingers closing from there to `closed[k]` (None: not closing), each count stopping
/// at `limit` (None: every point); see `GripperShape::hits_in`.
#[pyfunction]
#[pyo3(signature = (points_in, poses, openings, closed, shape, margin, grow, back, floor, limit, num_threads))]
#[allow(clippy::too_many_arguments)]
fn gripper_hits<'py>(
    py: Python<'py>,
    points_in: &Bound<'py, PyAny>,
    poses: numpy::PyReadonlyArray3<'py, f64>,
    openings: PyReadonlyArray1<'py, f64>,
    closed: Option<PyReadonlyArray1<'py, f64>>,
    shape: [f64; 6],
    margin: f64,
    grow: f64,
    back: f64,
    floor: Option<f64>,
    limit: Option<usize>,
    num_threads: usize,
) -> PyResult<Bound<'py, numpy::PyArray1<i64>>> {
    let grid = match points_in.cast::<GripperPoints>() {
        Ok(prepared) => Grid::Shared(prepared.get().grid.clone()),
        Err(_) => Grid::Points(points(&points_in.extract::<PyReadonlyArray2<'py, f64>>()?, "points")?),
    };
    let poses = isometries(&poses, "T_base_gripper")?;
    let (shape, clearance) = (gripper_shape(shape, &[margin, grow, back])?, Clearance { margin, grow });
    if floor.is_some_and(|f| !f.is_finite()) {
        return Err(invalid("floor", "a finite height in mm, or None"));
    }
    let sweep = Sweep { back, floor };
    let limit = limit.unwrap_or(usize::MAX);
    let openings = one_each(&openings, poses.len(), "pose")?;
    let closed = match closed {
        Some(widths) => {
            let widths = widths.as_slice()?.to_vec();
            if widths.len() != poses.len() || widths.iter().any(|w| !w.is_finite() || *w < 0.0) {
                return Err(invalid("closed", "one finite width ≥ 0 mm per pose"));
            }
            widths
        }
        None => Vec::new(),
    };
    let num_threads = threads(num_threads)?;
    let counts = run(py, move || {
        Ok(with_threads(num_threads, || match &grid {
            Grid::Shared(grid) => shape.hits_in(grid, &poses, &openings, &closed, clearance, sweep, limit),
            Grid::Points(pts) => shape.hits_in(
                &PointGrid::new(pts),
                &poses,
                &openings,
                &closed,
                clearance,
                sweep,
                limit,
            ),
        }))
    })?;
    Ok(numpy::PyArray1::from_vec(
        py,
        counts.into_iter().map(|c| c as i64).collect(),
    ))
}

/// The points `gripper_hits` counts: bucketed already, or as given.
enum Grid {
    Shared(Arc<PointGrid>),
    Points(Vec<Point>),
}

/// For each grasp `T_gripper_object` (K, 4, 4): half the width of the part's `points_in` (object
/// frame) between the fingers of the gripper of `shape`, open `open_width` mm, or −1 when none
/// lies between them; see `GripperShape::widest_between`.
#[pyfunction]
#[pyo3(signature = (points_in, grasps, shape, open_width, graze, num_threads))]
fn gripper_widest<'py>(
    py: Python<'py>,
    points_in: PyReadonlyArray2<'py, f64>,
    grasps: numpy::PyReadonlyArray3<'py, f64>,
    shape: [f64; 6],
    open_width: f64,
    graze: f64,
    num_threads: usize,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    let pts = points(&points_in, "points")?;
    let grasps = isometries(&grasps, "grasps")?;
    let shape = gripper_shape(shape, &[open_width, graze])?;
    let num_threads = threads(num_threads)?;
    let widest = run(py, move || {
        Ok(with_threads(num_threads, || {
            shape.widest_between(&pts, &grasps, open_width, graze)
        }))
    })?;
    Ok(numpy::PyArray1::from_vec(py, widest))
}

/// Voxel downsampling: (points, normals or None, first indices).
#[pyfunction]
#[pyo3(signature = (points_in, normals, voxel_size))]
fn voxel_downsample<'py>(
    py: Python<'py>,
    points_in: PyReadonlyArray2<'py, f64>,
    normals: Option<PyReadonlyArray2<'py, f64>>,
    voxel_size: f64,
) -> PyResult<(Arr<'py>, Option<Arr<'py>>, Bound<'py, numpy::PyArray1<i64>>)> {
    let pts = points(&points_in, "points")?;
    let ns = normals.as_ref().map(|n| vectors(n, "normals")).transpose()?;
    let has_normals = ns.is_some();
    let d = run(py, move || core_voxel(&pts, ns.as_deref(), voxel_size))?;
    let n_out = has_normals.then(|| vectors_to_py(py, &d.normals));
    Ok((points_to_py(py, &d.points), n_out, indices_to_py(py, &d.first_index)))
}

/// Reads a mesh file and converts it to mm: (vertices, faces).
#[pyfunction]
fn read_mesh<'py>(py: Python<'py>, path: PathBuf, unit: &str) -> PyResult<(Arr<'py>, Bound<'py, PyArray2<i64>>)> {
    let unit = unit.to_string();
    let mesh = run(py, move || {
        let scale = unit_scale(&unit)?;
        Ok(core_read_mesh(&path)?.scaled(scale))
    })?;
    Ok((points_to_py(py, &mesh.vertices), faces_to_py(py, &mesh.faces)))
}

/// Samples a mesh: (points, normals, diameter, area).
#[pyfunction]
#[pyo3(signature = (vertices, faces, spacing, count, seed))]
fn sample_mesh<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, i64>,
    spacing: Option<f64>,
    count: Option<usize>,
    seed: u64,
) -> PyResult<(Arr<'py>, Arr<'py>, f64, f64)> {
    let mesh = mesh_from_py(&vertices, &faces)?;
    let density = match (spacing, count) {
        (Some(s), None) => Density::Spacing(s),
        (None, Some(c)) => Density::Count(c),
        _ => return Err(invalid("spacing/count", "give exactly one of spacing (mm) or count")),
    };
    let (s, diameter, area) = run(py, move || {
        Ok((sample_surface(&mesh, density, seed)?, mesh.diameter(), mesh.area()))
    })?;
    Ok((
        points_to_py(py, &s.points),
        vectors_to_py(py, &s.normals),
        diameter,
        area,
    ))
}

/// Reads a PLY point cloud: (points, normals or None).
#[pyfunction]
fn read_ply<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(Arr<'py>, Option<Arr<'py>>)> {
    let d = run(py, move || core_read_ply(&path))?;
    Ok((
        points_to_py(py, &d.points),
        d.normals.as_ref().map(|n| vectors_to_py(py, n)),
    ))
}

/// LZF-decompresses `data` to exactly `size` bytes (PCL's `binary_compressed`): (bytes, None), or
/// (None, why) for a corrupt stream, which the caller names with its file.
#[pyfunction]
fn lzf_decompress<'py>(py: Python<'py>, data: &[u8], size: usize) -> (Option<Bound<'py, PyBytes>>, Option<String>) {
    match py.detach(|| binpick_core::lzf_decompress(data, size)) {
        Ok(plain) => (Some(PyBytes::new(py, &plain)), None),
        Err(why) => (None, Some(why)),
    }
}

/// Writes a PLY point cloud.
#[pyfunction]
#[pyo3(signature = (path, points_in, normals, ascii))]
fn write_ply(
    py: Python<'_>,
    path: PathBuf,
    points_in: PyReadonlyArray2<'_, f64>,
    normals: Option<PyReadonlyArray2<'_, f64>>,
    ascii: bool,
) -> PyResult<()> {
    let pts = points(&points_in, "points")?;
    let ns = normals.as_ref().map(|n| vectors(n, "normals")).transpose()?;
    run(py, move || core_write_ply(&path, &pts, ns.as_deref(), ascii))
}

/// The paper's tee: (vertices, faces, branches as rows [dx, dy, dz, length, radius]).
#[pyfunction]
fn part_tee<'py>(
    py: Python<'py>,
    outer_diameter: f64,
    run_length: f64,
    branch_length: f64,
    boss_semi_axes: (f64, f64),
    boss_height: f64,
    resolution: f64,
) -> PyResult<PartArrays<'py>> {
    let p = parts::TeeParams {
        outer_diameter,
        run_length,
        branch_length,
        boss_semi_axes,
        boss_height,
        resolution,
    };
    Ok(part_to_py(py, run(py, move || parts::tee(&p))?))
}

/// An elbow or a cross: (vertices, faces, branches).
#[pyfunction]
fn part_fitting<'py>(
    py: Python<'py>,
    kind: &str,
    outer_diameter: f64,
    branch_length: f64,
    resolution: f64,
) -> PyResult<PartArrays<'py>> {
    let p = parts::FittingParams {
        outer_diameter,
        branch_length,
        resolution,
    };
    let part = match kind {
        "elbow" => run(py, move || parts::elbow(&p))?,
        "cross" => run(py, move || parts::cross(&p))?,
        other => {
            return Err(invalid(
                "kind",
                &format!("unknown fitting {other:?}; use \"elbow\" or \"cross\""),
            ))
        }
    };
    Ok(part_to_py(py, part))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(estimate_normals, m)?)?;
    m.add_function(wrap_pyfunction!(scan_noise, m)?)?;
    m.add_function(wrap_pyfunction!(voxel_downsample, m)?)?;
    m.add_function(wrap_pyfunction!(nearest_distances, m)?)?;
    m.add_function(wrap_pyfunction!(gripper_occupied, m)?)?;
    m.add_class::<GripperPoints>()?;
    m.add_function(wrap_pyfunction!(gripper_hits, m)?)?;
    m.add_function(wrap_pyfunction!(gripper_widest, m)?)?;
    m.add_function(wrap_pyfunction!(read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(sample_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(read_ply, m)?)?;
    m.add_function(wrap_pyfunction!(write_ply, m)?)?;
    m.add_function(wrap_pyfunction!(lzf_decompress, m)?)?;
    m.add_function(wrap_pyfunction!(part_tee, m)?)?;
    m.add_function(wrap_pyfunction!(part_fitting, m)?)?;
    Ok(())
}
