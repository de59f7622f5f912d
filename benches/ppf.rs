//! Point-pair-feature detection, one thread: building a model's feature table, and the votes of
//! a view (scene samples per second). The part is the built-in tee seen from above at a random
//! pose; the scene is sampled at the PPF step as the pipeline does.

use binpick_core::parts::{tee, TeeParams};
use binpick_core::Symmetries;
use binpick_core::{sample_surface, subsample, Density, DetectConfig, KdIndex, Point, PpfConfig, PpfModel, Rng};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::{Isometry3, Translation3, Vector3};
use std::hint::black_box;

fn bench_ppf(c: &mut Criterion) {
    let part = tee(&TeeParams::default()).unwrap();
    let diameter = part.mesh.diameter();
    let dense = sample_surface(&part.mesh, Density::Spacing(1.0), 1).unwrap();
    let config = PpfConfig::default();
    let keep = subsample(&dense.points, config.sampling_ratio * diameter);
    let (mp, mn): (Vec<Point>, Vec<Vector3<f64>>) = keep.iter().map(|&i| (dense.points[i], dense.normals[i])).unzip();
    let mut group = c.benchmark_group("ppf");
    group.sample_size(10);
    group.throughput(Throughput::Elements((mp.len() * mp.len()) as u64));
    group.bench_function("build_table", |b| {
        b.iter(|| black_box(PpfModel::new(mp.clone(), mn.clone(), diameter, config).unwrap()))
    });
    let model = PpfModel::new(mp, mn, diameter, config).unwrap();

    let mut rng = Rng::new(5);
    let truth = Isometry3::from_parts(Translation3::new(400.0, 0.0, 40.0), rng.rotation());
    let view = sample_surface(&part.mesh, Density::Spacing(0.8), 2).unwrap();
    let (pts, nrm): (Vec<Point>, Vec<Vector3<f64>>) = view
        .points
        .iter()
        .zip(&view.normals)
        .map(|(p, n)| (truth * p, truth.rotation * n))
        .filter(|(_, n)| n.z > 0.1)
        .unzip();
    let keep = subsample(&pts, model.step());
    let (sp, sn): (Vec<Point>, Vec<Vector3<f64>>) = keep.iter().map(|&i| (pts[i], nrm[i])).unzip();
    let index = KdIndex::new(&sp);
    let cfg = DetectConfig::default();
    let sym = Symmetries::none(binpick_core::centroid(&dense.points));
    group.throughput(Throughput::Elements(sp.len() as u64));
    group.bench_function("vote_and_cluster_view", |b| {
        b.iter(|| {
            let votes = model.vote(&sp, &sn, &index, &cfg);
            black_box(model.cluster(&votes, &sym, &cfg))
        })
    });
    group.finish();
}

fn single_thread() {
    let _ = rayon::ThreadPoolBuilder::new().num_threads(1).build_global();
}

fn benches(c: &mut Criterion) {
    single_thread();
    bench_ppf(c);
}

criterion_group!(ppf, benches);
criterion_main!(ppf);
