//! The simulated cell on one core: dropping and settling a pile of 20 tees (parts per second),
//! casting the camera's view of that pile at 1032 × 778 (pixels per second), and lighting one
//! laser frame from the view (pixels per second); and the cell's predicted push (`sim_predict`):
//! placing one located tee in the bin (its collision hulls built), and one trial of a push — the
//! tee set back where it lies, a closed gripper's fingers pushing it 40 mm, the tee settled. The layout is the default cell of
//! `binpick.sim`: the bin centred at (400, 0), the camera 580 mm above its floor looking down.

use binpick_core::parts::{tee, TeeParams};
use binpick_core::sim::{BinSpec, Laser, Lighting, Material, Pile, PileParams, Scene, SensorNoise, ToolBox};
use binpick_core::{with_threads, Camera};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::PI;
use std::hint::black_box;

const PARTS: usize = 20;
const SEED: u64 = 3;

/// The default cell's camera: the paper's 1032 × 778 sensor with mild barrel distortion.
fn camera() -> Camera {
    Camera {
        dist: [-0.04, 0.01, 0.0, 0.0, 0.0],
        ..Camera::default()
    }
}

/// The camera 580 mm above the bin's floor at (400, 0), looking straight down (z down, x along +x).
fn t_base_camera() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(400.0, 0.0, 580.0),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI),
    )
}

/// The bin and the settled pile as a render scene (parts are the mesh the pile was dropped with).
fn scene(pile: &Pile, mesh: &binpick_core::TriMesh) -> Scene {
    let mut s = Scene::new();
    let bin = s
        .add_mesh(
            &pile.bin().mesh(),
            Material {
                albedo: [0.30, 0.34, 0.40],
                ..Default::default()
            },
        )
        .unwrap();
    s.add_instance(bin, Isometry3::identity(), -2).unwrap();
    let part = s
        .add_mesh(
            mesh,
            Material {
                albedo: [0.72, 0.72, 0.70],
                ..Default::default()
            },
        )
        .unwrap();
    for (id, t) in pile.poses() {
        s.add_instance(part, t, id as i32).unwrap();
    }
    s
}

fn bench_sim(c: &mut Criterion) {
    let part = tee(&TeeParams::default()).unwrap();
    let bin = BinSpec::default();
    let params = PileParams {
        seed: SEED,
        ..Default::default()
    };

    let mut group = c.benchmark_group("sim_pile");
    group.sample_size(10);
    group.throughput(Throughput::Elements(PARTS as u64));
    group.bench_with_input(BenchmarkId::new("drop_and_settle_tees", PARTS), &PARTS, |b, &n| {
        b.iter(|| with_threads(1, || black_box(Pile::drop(&part.mesh, n, &bin, &params).unwrap())))
    });
    group.finish();

    let pile = Pile::drop(&part.mesh, PARTS, &bin, &params).unwrap();
    let scene = scene(&pile, &part.mesh);
    let cam = camera();
    let pixels = (cam.width * cam.height) as u64;
    let (pose, light) = (t_base_camera(), Lighting::default());

    let mut group = c.benchmark_group("sim_render");
    group.sample_size(10);
    group.throughput(Throughput::Elements(pixels));
    group.bench_function(BenchmarkId::new("view_1032x778", format!("{PARTS}_tees")), |b| {
        b.iter(|| with_threads(1, || black_box(scene.view(&cam, &pose, &light).unwrap())))
    });
    let view = with_threads(1, || scene.view(&cam, &pose, &light).unwrap());
    let (laser, noise) = (Laser::default(), SensorNoise::default());
    group.bench_function(BenchmarkId::new("laser_frame_1032x778", format!("{PARTS}_tees")), |b| {
        b.iter(|| with_threads(1, || black_box(view.frame(&laser, 0.0, &noise, SEED).unwrap())))
    });
    group.finish();
}

/// The closed fingers of the simulated cell's gripper (two 8 × 20 × 90 mm boxes side by side, the
/// tool frame at their tips, z up along them) and a straight path: down beside the part at
/// (x, y), 60 mm along +x 8 mm above the floor, up again.
fn push_path(x: f64, y: f64) -> (Vec<ToolBox>, Vec<Isometry3<f64>>) {
    let fingers = [-4.0, 4.0]
        .iter()
        .map(|dx| ToolBox {
            pose_in_tool: Isometry3::translation(*dx, 0.0, 45.0),
            half_extents: Vector3::new(4.0, 10.0, 45.0),
        })
        .collect();
    let at = |x: f64, z: f64| Isometry3::translation(x, y, z);
    (
        fingers,
        vec![at(x, 60.0), at(x, 8.0), at(x + 60.0, 8.0), at(x + 60.0, 60.0)],
    )
}

fn bench_predict(c: &mut Criterion) {
    let part = tee(&TeeParams::default()).unwrap();
    let bin = BinSpec::default();
    let params = PileParams {
        seed: SEED,
        ..Default::default()
    };
    // One tee as a pile left it, alone in the bin.
    let (_, lying) = Pile::drop(&part.mesh, 1, &bin, &params).unwrap().poses()[0];
    // The fingers go down 20 mm short of its nearest point along +x and push 40 mm into it.
    let nearest = part
        .mesh
        .vertices
        .iter()
        .map(|v| (lying * v).x)
        .fold(f64::INFINITY, f64::min);
    let (fingers, path) = push_path(nearest - 20.0, lying.translation.vector.y);

    let mut group = c.benchmark_group("sim_predict");
    group.sample_size(10);
    group.bench_function("place_one_tee", |b| {
        b.iter(|| {
            with_threads(1, || {
                black_box(Pile::place(&part.mesh, &[lying], &bin, &params).unwrap())
            })
        })
    });
    let mut pile = Pile::place(&part.mesh, &[lying], &bin, &params).unwrap();
    group.bench_function("push_trial_one_tee", |b| {
        b.iter(|| {
            with_threads(1, || {
                pile.set_poses(&[lying]).unwrap();
                black_box(pile.push(&fingers, &path, 250.0).unwrap())
            })
        })
    });
    group.finish();
}

criterion_group!(benches, bench_sim, bench_predict);
criterion_main!(benches);
