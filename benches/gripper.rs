//! The grasp planner's collision count, one thread: how many scene points lie inside the
//! gripper at each of a batch of poses (`GripperShape::hits`), and how many it meets along a
//! pick's motion (`GripperShape::hits_swept`: the approach along its axis, each point standing
//! for what lies below it — the planner's question for every grasp it weighs), at 10k to 400k
//! scene points (a scan near a part, and the same spread between laser lines); the planner's
//! own call (`GripperShape::hits_in`: the points bucketed once, the fingers closing to a width,
//! a count stopping past the most a grasp may have); and the part's width between the fingers
//! at each of 1,152 grasps (`GripperShape::widest_between`, measured once per grasp and cell).

use binpick_core::{with_threads, Clearance, GripperShape, Point, PointGrid, Rng, Sweep};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::hint::black_box;

const SHAPE: GripperShape = GripperShape {
    tip_depth: 10.0,
    finger_length: 45.0,
    finger_width: 20.0,
    finger_thickness: 8.0,
    body_radius: 45.0,
    body_length: 60.0,
};

fn cloud(n: usize, half: f64, rng: &mut Rng) -> Vec<Point> {
    (0..n)
        .map(|_| {
            Point::new(
                (rng.uniform() * 2.0 - 1.0) * half,
                (rng.uniform() * 2.0 - 1.0) * half,
                (rng.uniform() * 2.0 - 1.0) * half,
            )
        })
        .collect()
}

fn poses(k: usize, rng: &mut Rng) -> Vec<Isometry3<f64>> {
    (0..k)
        .map(|_| {
            let axis = Vector3::new(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5);
            Isometry3::from_parts(
                Translation3::new(rng.uniform() * 40.0, rng.uniform() * 40.0, rng.uniform() * 40.0),
                UnitQuaternion::from_scaled_axis(axis.normalize() * rng.uniform() * 3.0),
            )
        })
        .collect()
}

fn bench_hits(c: &mut Criterion) {
    // The same poses and clouds for both counts: with the points as points, and swept.
    let swept = Sweep {
        back: 40.0,
        floor: Some(-150.0),
    };
    for (name, sweep) in [
        ("gripper_hits_32_poses", Sweep::default()),
        ("gripper_hits_swept_32_poses", swept),
    ] {
        let mut rng = Rng::new(7);
        let batch = poses(32, &mut rng);
        let openings = vec![40.0; batch.len()];
        let mut group = c.benchmark_group(name);
        for &n in &[10_000usize, 40_000, 400_000] {
            let points = cloud(n, 150.0, &mut rng);
            group.throughput(Throughput::Elements((n * batch.len()) as u64));
            group.bench_with_input(BenchmarkId::from_parameter(n), &points, |b, points| {
                b.iter(|| {
                    with_threads(1, || {
                        black_box(SHAPE.hits_swept(points, &batch, &openings, Clearance::default(), sweep))
                    })
                })
            });
        }
        group.finish();
    }
}

fn bench_planner(c: &mut Criterion) {
    // As the planner counts: the scene bucketed once (not timed), the swept count; then with the
    // fingers closing from 40 to 30 mm; then that count stopping at 16 (the default cell refuses
    // a grasp past 15 points).
    let sweep = Sweep {
        back: 40.0,
        floor: Some(-150.0),
    };
    let mut rng = Rng::new(7);
    let batch = poses(32, &mut rng);
    let (openings, closed) = (vec![40.0; batch.len()], vec![30.0; batch.len()]);
    let mut group = c.benchmark_group("gripper_hits_planner_32_poses");
    for &n in &[10_000usize, 40_000, 400_000] {
        let grid = PointGrid::new(&cloud(n, 150.0, &mut rng));
        group.throughput(Throughput::Elements((n * batch.len()) as u64));
        for (variant, shut, limit) in [
            ("swept", &[][..], usize::MAX),
            ("closing", &closed[..], usize::MAX),
            ("closing_at_most_16", &closed[..], 16),
        ] {
            group.bench_with_input(BenchmarkId::new(variant, n), &grid, |b, grid| {
                b.iter(|| {
                    with_threads(1, || {
                        black_box(SHAPE.hits_in(grid, &batch, &openings, shut, Clearance::default(), sweep, limit))
                    })
                })
            });
        }
    }
    group.finish();
}

fn bench_widest(c: &mut Criterion) {
    let mut rng = Rng::new(8);
    let grasps = poses(1152, &mut rng);
    let part = cloud(12_000, 60.0, &mut rng);
    let mut group = c.benchmark_group("gripper_widest_1152_grasps");
    group.throughput(Throughput::Elements((part.len() * grasps.len()) as u64));
    group.bench_function("12000_points", |b| {
        b.iter(|| with_threads(1, || black_box(SHAPE.widest_between(&part, &grasps, 50.0, 0.5))))
    });
    group.finish();
}

criterion_group!(benches, bench_hits, bench_planner, bench_widest);
criterion_main!(benches);
