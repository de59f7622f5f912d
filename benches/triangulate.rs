//! Triangulation throughput in points per second, one thread, at 1e3 to 1e6 points: laser-line
//! pixels as the extraction gives them (one sub-pixel column per image row, frame after frame,
//! the line moving across the image with the motor), a 1032×778 camera with and without lens
//! distortion. Also undistortion alone: the exact Newton solve against the ray table.

use binpick_core::with_threads;
use binpick_core::{triangulate_into, Camera, FramePose, PointStatus, RayTable, Sensor};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion};
use std::hint::black_box;

const WIDTH: u32 = 1032;
const HEIGHT: u32 = 778;

fn camera(dist: [f64; 5]) -> Camera {
    let k = Matrix3::new(1200.0, 0.0, 520.3, 0.0, 1195.0, 385.7, 0.0, 0.0, 1.0);
    Camera::new(WIDTH, HEIGHT, &k, dist).unwrap()
}

fn sensor(dist: [f64; 5]) -> Sensor {
    Sensor {
        camera: camera(dist),
        t_camera_laser0: Isometry3::from_parts(
            Translation3::new(-150.0, 2.0, 5.0),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 0.015),
        ),
        t_flange_camera: Isometry3::from_parts(
            Translation3::new(30.0, -10.0, 90.0),
            UnitQuaternion::from_euler_angles(0.02, -0.01, 0.3),
        ),
    }
}

/// `n` pixels of a scan: frame `f` lights a wavy line whose mean column sweeps the image.
fn scan(n: usize) -> (Vec<FramePose>, Vec<[f64; 2]>, Vec<u32>) {
    let rows = HEIGHT as usize;
    let frames: Vec<FramePose> = (0..n.div_ceil(rows))
        .map(|f| FramePose {
            angle: 0.1 + 0.4 * (f % 400) as f64 / 400.0,
            t_base_flange: Isometry3::from_parts(
                Translation3::new(400.0, -20.0, 600.0),
                UnitQuaternion::from_euler_angles(3.1, 0.0, 0.1),
            ),
        })
        .collect();
    let (mut pixels, mut index) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for i in 0..n {
        let (f, v) = (i / rows, (i % rows) as f64);
        let centre = 60.0 + (f % 400) as f64 * 2.2;
        pixels.push([centre + 25.0 * (v / 60.0).sin() + 0.37, v]);
        index.push(f as u32);
    }
    (frames, pixels, index)
}

fn bench_triangulate(c: &mut Criterion) {
    let mut group = c.benchmark_group("triangulate");
    for &n in &[1_000usize, 10_000, 100_000, 1_000_000] {
        let (frames, pixels, index) = scan(n);
        let mut points = vec![[0.0; 3]; n];
        let mut status = vec![PointStatus::Valid; n];
        group.throughput(Throughput::Elements(n as u64));
        for (name, dist) in [
            ("distorted", [-0.09, 0.06, 0.0006, -0.0004, -0.01]),
            ("no_distortion", [0.0; 5]),
        ] {
            let s = sensor(dist);
            RayTable::shared(&s.camera);
            group.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                b.iter(|| {
                    with_threads(1, || {
                        triangulate_into(&s, &frames, &pixels, &index, &mut points, &mut status).unwrap()
                    })
                });
                black_box(&points);
            });
        }
    }
    group.finish();
}

fn bench_undistort(c: &mut Criterion) {
    let mut group = c.benchmark_group("undistort");
    let n = 1_000_000;
    let (_, pixels, _) = scan(n);
    let cam = camera([-0.09, 0.06, 0.0006, -0.0004, -0.01]);
    let table = RayTable::new(&cam);
    group.throughput(Throughput::Elements(n as u64));
    group.bench_function("exact_newton", |b| {
        b.iter(|| {
            pixels
                .iter()
                .map(|&[u, v]| cam.ray(u, v).map_or(0.0, |r| r.x))
                .sum::<f64>()
        })
    });
    group.bench_function("ray_table", |b| {
        b.iter(|| {
            pixels
                .iter()
                .map(|&[u, v]| table.ray(u, v).map_or(0.0, |r| r.x))
                .sum::<f64>()
        })
    });
    group.bench_function("build_table", |b| {
        b.iter(|| with_threads(1, || black_box(RayTable::new(&cam))))
    });
    group.finish();
}

criterion_group!(benches, bench_triangulate, bench_undistort);
criterion_main!(benches);
