//! The simulated cell: physics piles (`SimPile`), the ray-cast scene (`SimScene`), the geometry
//! of one robot pose (`SimView`, lit per laser angle) and checkerboard images. The Python
//! package `binpick.sim` wraps these with validated, documented classes.

use crate::convert::{camera, isometry, points, CameraArgs};
use crate::errors::{invalid, run_borrowed};
use binpick_core::sim::{convex_decomposition, max_interpenetration, BinSpec, Pile, PileParams, SettleReport, ToolBox};
use binpick_core::sim::{render_checkerboard, Checkerboard, Laser, Lighting, Material, Scene, SensorNoise, View};
use binpick_core::{Error, Point};
use nalgebra::{Isometry3, Matrix4, Vector3};
use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;
use std::sync::Arc;

type Arr<'py> = Bound<'py, PyArray2<f64>>;

/// Vertices and faces as new (V, 3) float64 and (M, 3) int64 arrays.
fn mesh_out<'py>(py: Python<'py>, v: &[Point], f: &[[u32; 3]]) -> (Arr<'py>, Bound<'py, PyArray2<i64>>) {
    (crate::convert::points_to_py(py, v), crate::convert::faces_to_py(py, f))
}

fn poses_out<'py>(py: Python<'py>, poses: &[Isometry3<f64>]) -> Bound<'py, PyArray3<f64>> {
    let mut a = Array3::<f64>::zeros((poses.len(), 4, 4));
    for (k, t) in poses.iter().enumerate() {
        let m = t.to_homogeneous();
        for r in 0..4 {
            for c in 0..4 {
                a[[k, r, c]] = m[(r, c)];
            }
        }
    }
    PyArray3::from_owned_array(py, a)
}

/// (push_steps, settle report, ids of the parts that moved).
type PushOut = (usize, (usize, f64, bool, f64), Vec<usize>);

fn report(r: SettleReport) -> (usize, f64, bool, f64) {
    (r.steps, r.simulated_time, r.settled, r.max_speed)
}

/// A pile's parameters: the seed, (friction, restitution, time step, settle time, skin) and the decomposition's.
fn pile_params(seed: u64, physics: (f64, f64, f64, f64, f64), resolution: u32, hulls: u32) -> PileParams {
    let (friction, restitution, time_step, max_settle_time, skin) = physics;
    PileParams {
        seed,
        friction,
        restitution,
        time_step,
        max_settle_time,
        skin,
        decomposition_resolution: resolution,
        max_convex_hulls: hulls,
        ..Default::default()
    }
}

fn bin_spec(center: (f64, f64), size: (f64, f64, f64), floor_z: f64, wall_thickness: f64) -> BinSpec {
    BinSpec {
        center,
        inner_size: Vector3::new(size.0, size.1, size.2),
        floor_z,
        wall_thickness,
    }
}

/// A physics pile: `count` instances of a mesh dropped into a bin and settled.
#[pyclass(module = "binpick._core", name = "SimPile")]
pub struct PySimPile {
    inner: Pile,
}

#[pymethods]
impl PySimPile {
    #[new]
    #[pyo3(signature = (vertices, faces, count, bin_center, bin_size, floor_z, wall_thickness, seed, friction, restitution, time_step, max_settle_time, skin, decomposition_resolution, max_convex_hulls))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f64>,
        faces: PyReadonlyArray2<'_, i64>,
        count: usize,
        bin_center: (f64, f64),
        bin_size: (f64, f64, f64),
        floor_z: f64,
        wall_thickness: f64,
        seed: u64,
        friction: f64,
        restitution: f64,
        time_step: f64,
        max_settle_time: f64,
        skin: f64,
        decomposition_resolution: u32,
        max_convex_hulls: u32,
    ) -> PyResult<Self> {
        let mesh = crate::convert::mesh_from_py(&vertices, &faces)?;
        let bin = bin_spec(bin_center, bin_size, floor_z, wall_thickness);
        let physics = (friction, restitution, time_step, max_settle_time, skin);
        let params = pile_params(seed, physics, decomposition_resolution, max_convex_hulls);
        let inner = run_borrowed(py, move || Pile::drop(&mesh, count, &bin, &params))?;
        Ok(PySimPile { inner })
    }

    /// Parts placed at `poses` (T_base_object (N, 4, 4)) and settled; the rest as `new`.
    #[staticmethod]
    #[pyo3(signature = (vertices, faces, poses, bin_center, bin_size, floor_z, wall_thickness, friction, restitution, time_step, max_settle_time, skin, decomposition_resolution, max_convex_hulls))]
    #[allow(clippy::too_many_arguments)]
    fn placed(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f64>,
        faces: PyReadonlyArray2<'_, i64>,
        poses: PyReadonlyArray3<'_, f64>,
        bin_center: (f64, f64),
        bin_size: (f64, f64, f64),
        floor_z: f64,
        wall_thickness: f64,
        friction: f64,
        restitution: f64,
        time_step: f64,
        max_settle_time: f64,
        skin: f64,
        decomposition_resolution: u32,
        max_convex_hulls: u32,
    ) -> PyResult<Self> {
        let mesh = crate::convert::mesh_from_py(&vertices, &faces)?;
        let poses = crate::convert::isometries(&poses, "poses")?;
        let bin = bin_spec(bin_center, bin_size, floor_z, wall_thickness);
        let physics = (friction, restitution, time_step, max_settle_time, skin);
        let params = pile_params(0, physics, decomposition_resolution, max_convex_hulls);
        let inner = run_borrowed(py, move || Pile::place(&mesh, &poses, &bin, &params))?;
        Ok(PySimPile { inner })
    }

    /// (ids int64 (N,), T_base_object (N, 4, 4)) of the remaining parts.
    fn poses<'py>(&self, py: Python<'py>) -> (Bound<'py, numpy::PyArray1<i64>>, Bound<'py, PyArray3<f64>>) {
        let p = self.inner.poses();
        let ids: Vec<i64> = p.iter().map(|(i, _)| *i as i64).collect();
        let t: Vec<Isometry3<f64>> = p.into_iter().map(|(_, t)| t).collect();
        (numpy::PyArray1::from_vec(py, ids), poses_out(py, &t))
    }

    /// Removes part `id` and settles: (steps, simulated_time, settled, max_speed).
    fn remove(&mut self, py: Python<'_>, id: usize) -> PyResult<(usize, f64, bool, f64)> {
        let pile = &mut self.inner;
        Ok(report(run_borrowed(py, move || pile.remove(id))?))
    }

    /// Moves the remaining parts (in id order) to `poses` (N, 4, 4), at rest, and settles.
    fn set_poses(&mut self, py: Python<'_>, poses: PyReadonlyArray3<'_, f64>) -> PyResult<(usize, f64, bool, f64)> {
        let poses = crate::convert::isometries(&poses, "poses")?;
        let pile = &mut self.inner;
        Ok(report(run_borrowed(py, move || pile.set_poses(&poses))?))
    }

    /// Steps until at rest: (steps, simulated_time, settled, max_speed).
    fn settle(&mut self, py: Python<'_>) -> PyResult<(usize, f64, bool, f64)> {
        let pile = &mut self.inner;
        Ok(report(run_borrowed(py, move || Ok::<_, Error>(pile.settle()))?))
    }

    /// Moves a kinematic tool of boxes (half extents (B, 3), T_tool_box (B, 4, 4)) along
    /// `path` (T_base_tool (P, 4, 4)) at `speed` mm/s, removes it and settles:
    /// (push_steps, settle report, ids of the parts that moved).
    fn push(
        &mut self,
        py: Python<'_>,
        half_extents: PyReadonlyArray2<'_, f64>,
        box_poses: PyReadonlyArray3<'_, f64>,
        path: PyReadonlyArray3<'_, f64>,
        speed: f64,
    ) -> PyResult<PushOut> {
        let halves = crate::convert::vectors(&half_extents, "half_extents")?;
        let poses = crate::convert::isometries(&box_poses, "box_poses")?;
        if halves.len() != poses.len() {
            return Err(invalid(
                "box_poses",
                &format!(
                    "{} poses for {} boxes; pass one pose per box",
                    poses.len(),
                    halves.len()
                ),
            ));
        }
        let boxes: Vec<ToolBox> = halves
            .into_iter()
            .zip(poses)
            .map(|(half_extents, pose_in_tool)| ToolBox {
                pose_in_tool,
                half_extents,
            })
            .collect();
        let path = crate::convert::isometries(&path, "path")?;
        let pile = &mut self.inner;
        let r = run_borrowed(py, move || pile.push(&boxes, &path, speed))?;
        Ok((r.push_steps, report(r.settle), r.moved))
    }

    /// The last settling's (steps, simulated_time, settled, max_speed).
    fn last_settle(&self) -> (usize, f64, bool, f64) {
        report(self.inner.last_settle())
    }

    /// Parts left.
    fn remaining(&self) -> usize {
        self.inner.remaining()
    }

    /// Deepest overlap of the convex collision pieces, mm.
    fn max_contact_penetration(&self) -> f64 {
        self.inner.max_contact_penetration()
    }

    /// The convex pieces (vertices, faces) a part collides with, model frame.
    fn collision_hulls<'py>(&self, py: Python<'py>) -> Vec<(Arr<'py>, Bound<'py, PyArray2<i64>>)> {
        self.inner
            .collision_hulls()
            .iter()
            .map(|(v, f)| mesh_out(py, v, f))
            .collect()
    }
}

/// Convex pieces enclosing a mesh, as the pile uses them: list of (vertices, faces).
#[pyfunction]
#[pyo3(signature = (vertices, faces, decomposition_resolution, max_convex_hulls))]
fn sim_convex_decomposition<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, i64>,
    decomposition_resolution: u32,
    max_convex_hulls: u32,
) -> PyResult<Vec<(Arr<'py>, Bound<'py, PyArray2<i64>>)>> {
    let mesh = crate::convert::mesh_from_py(&vertices, &faces)?;
    let params = PileParams {
        decomposition_resolution,
        max_convex_hulls,
        ..Default::default()
    };
    let hulls = run_borrowed(py, move || convex_decomposition(&mesh, &params))?;
    Ok(hulls.iter().map(|(v, f)| mesh_out(py, v, f)).collect())
}

/// Deepest interpenetration (mm) of mesh instances at `poses` (N, 4, 4), from surface `samples`.
#[pyfunction]
fn sim_max_interpenetration(
    py: Python<'_>,
    vertices: PyReadonlyArray2<'_, f64>,
    faces: PyReadonlyArray2<'_, i64>,
    poses: PyReadonlyArray3<'_, f64>,
    samples: PyReadonlyArray2<'_, f64>,
) -> PyResult<f64> {
    let mesh = crate::convert::mesh_from_py(&vertices, &faces)?;
    let p = poses.as_array();
    if p.shape()[1] != 4 || p.shape()[2] != 4 {
        return Err(invalid(
            "poses",
            &format!("must have shape (N, 4, 4), got {:?}", p.shape()),
        ));
    }
    let t = (0..p.shape()[0])
        .map(|k| binpick_core::isometry_from_matrix(&format!("poses[{k}]"), &Matrix4::from_fn(|r, c| p[[k, r, c]])))
        .collect::<binpick_core::Result<Vec<_>>>()
        .map_err(crate::errors::to_py)?;
    let s = points(&samples, "samples")?;
    run_borrowed(py, move || max_interpenetration(&mesh, &t, &s))
}

/// The bin's render mesh (vertices, faces) in the base frame.
#[pyfunction]
fn sim_bin_mesh<'py>(
    py: Python<'py>,
    center: (f64, f64),
    size: (f64, f64, f64),
    floor_z: f64,
    wall_thickness: f64,
) -> PyResult<(Arr<'py>, Bound<'py, PyArray2<i64>>)> {
    let bin = bin_spec(center, size, floor_z, wall_thickness);
    bin.validate().map_err(crate::errors::to_py)?;
    let m = bin.mesh();
    Ok(mesh_out(py, &m.vertices, &m.faces))
}

type LightingArgs = (f64, f64, [f64; 3], f64);
type NoiseArgs = (f64, f64, f64, f64, f64);
/// The laser of a checkerboard view, as `laser` takes it.
type LaserArgs<'py> = Option<(PyReadonlyArray2<'py, f64>, f64, f64, f64, [f64; 3], f64)>;
/// Distances to the nearest surface and its instance ids.
type Nearest<'py> = (Bound<'py, numpy::PyArray1<f64>>, Bound<'py, numpy::PyArray1<i32>>);

fn lighting(l: LightingArgs) -> Lighting {
    Lighting {
        ambient: l.0,
        lamp: l.1,
        lamp_direction: Vector3::from(l.2),
        background: l.3,
    }
}

fn noise(n: NoiseArgs) -> SensorNoise {
    SensorNoise {
        read_noise: n.0,
        shot_noise: n.1,
        speckle: n.2,
        reflections: n.3,
        blur: n.4,
    }
}

#[allow(clippy::too_many_arguments)]
fn laser(
    t: &PyReadonlyArray2<'_, f64>,
    sheet_sigma: f64,
    power: f64,
    fan_angle: f64,
    color: [f64; 3],
    reference_distance: f64,
) -> PyResult<Laser> {
    Ok(Laser {
        t_camera_laser0: isometry(t, "T_camera_laser")?,
        sheet_sigma,
        power,
        fan_angle,
        color,
        reference_distance,
    })
}

fn image_out<'py>(py: Python<'py>, data: Vec<u8>, h: usize, w: usize) -> Bound<'py, PyArray3<u8>> {
    PyArray3::from_owned_array(py, Array3::from_shape_vec((h, w, 3), data).expect("h×w×3"))
}

/// Meshes and instances in the base frame, ray-cast by `view`.
#[pyclass(module = "binpick._core", name = "SimScene")]
pub struct PySimScene {
    inner: Scene,
}

#[pymethods]
impl PySimScene {
    #[new]
    fn new() -> Self {
        PySimScene { inner: Scene::new() }
    }

    /// Adds a mesh with its material; returns the mesh index.
    fn add_mesh(
        &mut self,
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f64>,
        faces: PyReadonlyArray2<'_, i64>,
        albedo: [f64; 3],
        specular: f64,
        shininess: f64,
    ) -> PyResult<usize> {
        let mesh = crate::convert::mesh_from_py(&vertices, &faces)?;
        let scene = &mut self.inner;
        run_borrowed(py, move || {
            scene.add_mesh(
                &mesh,
                Material {
                    albedo,
                    specular,
                    shininess,
                },
            )
        })
    }

    /// Places mesh `mesh` at `T_base_object` as instance `id`.
    fn add_instance(&mut self, mesh: usize, t_base_object: PyReadonlyArray2<'_, f64>, id: i32) -> PyResult<()> {
        let t = isometry(&t_base_object, "T_base_object")?;
        self.inner.add_instance(mesh, t, id).map_err(crate::errors::to_py)
    }

    /// Moves instance `id`.
    fn set_pose(&mut self, id: i32, t_base_object: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        let t = isometry(&t_base_object, "T_base_object")?;
        self.inner.set_pose(id, t).map_err(crate::errors::to_py)
    }

    /// Removes instance `id`.
    fn remove_instance(&mut self, id: i32) -> PyResult<()> {
        self.inner.remove_instance(id).map_err(crate::errors::to_py)
    }

    /// Ids of the placed instances.
    fn instance_ids(&self) -> Vec<i32> {
        self.inner.instance_ids()
    }

    /// (distances (N,) mm, ids (N,) int32): each point's (base frame) exact distance to the
    /// nearest surface and that surface's instance id; (inf, −1) in an empty scene.
    fn nearest_surface<'py>(&self, py: Python<'py>, points_base: PyReadonlyArray2<'py, f64>) -> PyResult<Nearest<'py>> {
        let pts = points(&points_base, "points")?;
        let scene = self.inner.clone();
        let found = run_borrowed(py, move || Ok::<_, Error>(scene.nearest_surface(&pts)))?;
        let (d, ids): (Vec<f64>, Vec<i32>) = found.into_iter().unzip();
        Ok((numpy::PyArray1::from_vec(py, d), numpy::PyArray1::from_vec(py, ids)))
    }

    /// Casts the camera's rays from `T_base_camera`.
    #[pyo3(signature = (camera_args, t_base_camera, lighting_args, num_threads))]
    fn view(
        &self,
        py: Python<'_>,
        camera_args: CameraArgs<'_>,
        t_base_camera: PyReadonlyArray2<'_, f64>,
        lighting_args: LightingArgs,
        num_threads: usize,
    ) -> PyResult<PySimView> {
        let t = isometry(&t_base_camera, "T_base_camera")?;
        let (cam, light) = (camera(&camera_args)?, lighting(lighting_args));
        let scene = self.inner.clone();
        let num_threads = crate::convert::threads(num_threads)?;
        let view = run_borrowed(py, move || {
            binpick_core::with_threads(num_threads, || scene.view(&cam, &t, &light))
        })?;
        Ok(PySimView { inner: Arc::new(view) })
    }
}

/// The ray-cast geometry of one robot pose.
#[pyclass(module = "binpick._core", name = "SimView")]
pub struct PySimView {
    inner: Arc<View>,
}

impl PySimView {
    /// The image's (height, width), px.
    fn shape(&self) -> (usize, usize) {
        let c = self.inner.camera();
        (c.height as usize, c.width as usize)
    }
}

#[pymethods]
impl PySimView {
    /// (H, W) float32 depth, mm, NaN where nothing is hit.
    fn depth<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec(self.shape(), self.inner.depth()).expect("h×w"),
        )
    }

    /// (H, W) int32 instance ids, −1 for none.
    fn ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i32>> {
        PyArray2::from_owned_array(py, Array2::from_shape_vec(self.shape(), self.inner.ids()).expect("h×w"))
    }

    /// (H, W, 3) float32 surface points in the camera frame (NaN where none).
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f32>> {
        let (h, w) = self.shape();
        let flat: Vec<f32> = self.inner.points().into_iter().flatten().collect();
        PyArray3::from_owned_array(py, Array3::from_shape_vec((h, w, 3), flat).expect("h×w×3"))
    }

    /// (H, W, 3) float32 camera-facing unit normals in the camera frame.
    fn normals<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f32>> {
        let (h, w) = self.shape();
        let flat: Vec<f32> = self.inner.normals().into_iter().flatten().collect();
        PyArray3::from_owned_array(py, Array3::from_shape_vec((h, w, 3), flat).expect("h×w×3"))
    }

    /// The frame without the laser.
    fn ambient_frame<'py>(
        &self,
        py: Python<'py>,
        noise_args: NoiseArgs,
        seed: u64,
    ) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let view = self.inner.clone();
        let n = noise(noise_args);
        let img = run_borrowed(py, move || view.ambient_frame(&n, seed))?;
        let (h, w) = self.shape();
        Ok(image_out(py, img, h, w))
    }

    /// (K, H, W, 3) uint8 frames with the laser at each angle (rad); frame k's noise is seeded
    /// by `seed + k`.
    #[pyo3(signature = (t_camera_laser0, sheet_sigma, power, fan_angle, color, reference_distance, angles, noise_args, seed, num_threads))]
    #[allow(clippy::too_many_arguments)]
    fn frames<'py>(
        &self,
        py: Python<'py>,
        t_camera_laser0: PyReadonlyArray2<'py, f64>,
        sheet_sigma: f64,
        power: f64,
        fan_angle: f64,
        color: [f64; 3],
        reference_distance: f64,
        angles: Vec<f64>,
        noise_args: NoiseArgs,
        seed: u64,
        num_threads: usize,
    ) -> PyResult<Bound<'py, numpy::PyArray4<u8>>> {
        let l = laser(
            &t_camera_laser0,
            sheet_sigma,
            power,
            fan_angle,
            color,
            reference_distance,
        )?;
        let n = noise(noise_args);
        let view = self.inner.clone();
        let k = angles.len();
        let num_threads = crate::convert::threads(num_threads)?;
        let frames = run_borrowed(py, move || {
            binpick_core::with_threads(num_threads, || {
                let mut all: Vec<u8> = Vec::new();
                for (i, a) in angles.iter().enumerate() {
                    let frame = view.frame(&l, *a, &n, seed.wrapping_add(i as u64))?;
                    if all.is_empty() {
                        all = frame; // one frame (a grab): not copied
                    } else {
                        all.extend(frame);
                    }
                }
                Ok::<_, Error>(all)
            })
        })?;
        let (h, w) = self.shape();
        let arr = numpy::ndarray::Array4::from_shape_vec((k, h, w, 3), frames).expect("k×h×w×3");
        Ok(numpy::PyArray4::from_owned_array(py, arr))
    }
}

/// The core's default laser projector, the one definition `binpick.sim.Laser` takes its defaults
/// from: (T_camera_laser0 4×4, sheet_sigma mm, power DN, fan_angle rad, color [R, G, B],
/// reference_distance mm).
#[pyfunction]
fn sim_default_laser(py: Python<'_>) -> PyResult<(Arr<'_>, f64, f64, f64, [f64; 3], f64)> {
    let l = run_borrowed(py, || Ok::<_, Error>(Laser::default()))?;
    Ok((
        crate::convert::isometry_to_py(py, &l.t_camera_laser0),
        l.sheet_sigma,
        l.power,
        l.fan_angle,
        l.color,
        l.reference_distance,
    ))
}

/// (H, W, 3) uint8 image of a checkerboard at `T_camera_board`, optionally with the laser line;
/// with `window` (u0, v0, u1, v1), only those pixels drawn.
#[pyfunction]
#[pyo3(signature = (camera_args, board, t_camera_board, lighting_args, laser_args, angle, noise_args, supersample, seed, window=None))]
#[allow(clippy::too_many_arguments)]
fn sim_render_checkerboard<'py>(
    py: Python<'py>,
    camera_args: CameraArgs<'py>,
    board: (usize, usize, f64, f64),
    t_camera_board: PyReadonlyArray2<'py, f64>,
    lighting_args: LightingArgs,
    laser_args: LaserArgs<'py>,
    angle: f64,
    noise_args: NoiseArgs,
    supersample: usize,
    seed: u64,
    window: Option<[usize; 4]>,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    let cam = camera(&camera_args)?;
    let (h, w) = (cam.height as usize, cam.width as usize);
    let b = Checkerboard {
        cols: board.0,
        rows: board.1,
        square: board.2,
        margin: board.3,
    };
    let t = isometry(&t_camera_board, "T_camera_board")?;
    let l = laser_args.map(|a| laser(&a.0, a.1, a.2, a.3, a.4, a.5)).transpose()?;
    let (light, n) = (lighting(lighting_args), noise(noise_args));
    let img = run_borrowed(py, move || {
        render_checkerboard(
            &cam,
            &b,
            &t,
            &light,
            l.as_ref().map(|l| (l, angle)),
            &n,
            supersample,
            seed,
            window,
        )
    })?;
    Ok(image_out(py, img, h, w))
}

/// Registers the simulator's classes and functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySimPile>()?;
    m.add_class::<PySimScene>()?;
    m.add_class::<PySimView>()?;
    m.add_function(wrap_pyfunction!(sim_convex_decomposition, m)?)?;
    m.add_function(wrap_pyfunction!(sim_max_interpenetration, m)?)?;
    m.add_function(wrap_pyfunction!(sim_bin_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(sim_render_checkerboard, m)?)?;
    m.add_function(wrap_pyfunction!(sim_default_laser, m)?)?;
    Ok(())
}
