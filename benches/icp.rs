//! ICP throughput in point-iterations per second, one thread, at 1e3, 1e4 and 1e5 points.
//! Source and target are independent samplings of the built-in tee with 0.2 mm noise, the
//! source 5° and 10 mm off; every run does exactly ITERATIONS updates (tolerances 0).

use binpick_core::parts::{tee, TeeParams};
use binpick_core::{icp, sample_surface, transform_points, Density, IcpConfig, IcpMethod, IcpTarget, Point, Rng};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use std::hint::black_box;

const ITERATIONS: usize = 10;

fn bench_icp(c: &mut Criterion) {
    let part = tee(&TeeParams::default()).unwrap();
    let mut group = c.benchmark_group("icp");
    group.sample_size(10);
    for &n in &[1_000usize, 10_000, 100_000] {
        let target = sample_surface(&part.mesh, Density::Count(n), 1).unwrap();
        let source = sample_surface(&part.mesh, Density::Count(n), 2).unwrap();
        let mut rng = Rng::new(3);
        let noisy: Vec<Point> = source
            .points
            .iter()
            .map(|p| p + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.2)
            .collect();
        let offset = Isometry3::from_parts(
            Translation3::new(10.0 / 3f64.sqrt(), 10.0 / 3f64.sqrt(), 10.0 / 3f64.sqrt()),
            UnitQuaternion::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)), 5f64.to_radians()),
        );
        let source = transform_points(&offset, &noisy);
        let tgt = IcpTarget::new(target.points, Some(target.normals)).unwrap();
        group.throughput(Throughput::Elements((n * ITERATIONS) as u64));
        for (name, method) in [
            ("point_to_point", IcpMethod::PointToPoint),
            ("point_to_plane", IcpMethod::PointToPlane),
        ] {
            let cfg = IcpConfig {
                method,
                max_correspondence_distance: 20.0,
                max_iterations: ITERATIONS,
                rotation_tolerance: 0.0,
                translation_tolerance: 0.0,
                num_threads: 1,
                ..Default::default()
            };
            group.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                b.iter(|| black_box(icp(&source, &tgt, &Isometry3::identity(), &cfg).unwrap()))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_icp);
criterion_main!(benches);
