//! ICP and KD-tree against oracles: brute-force neighbours, and known seeded transforms.

use binpick_core::parts::{tee, TeeParams};
use binpick_core::{icp, sample_surface, transform_points, Density, IcpConfig, IcpMethod, IcpTarget, RobustKernel};
use binpick_core::{KdIndex, Point, Rng};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

fn random_points(rng: &mut Rng, n: usize) -> Vec<Point> {
    (0..n)
        .map(|_| Point::new(rng.range(-50.0, 50.0), rng.range(-50.0, 50.0), rng.range(-50.0, 50.0)))
        .collect()
}

#[test]
fn kdtree_matches_brute_force() {
    let mut rng = Rng::new(11);
    let pts = random_points(&mut rng, 2000);
    let idx = KdIndex::new(&pts);
    for _ in 0..200 {
        let q = Point::new(rng.range(-60.0, 60.0), rng.range(-60.0, 60.0), rng.range(-60.0, 60.0));
        let mut brute: Vec<(usize, f64)> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| (i, (p - q).norm_squared()))
            .collect();
        brute.sort_by(|a, b| a.1.total_cmp(&b.1));
        let nn = idx.nearest(&q).unwrap();
        assert!((nn.distance_squared - brute[0].1).abs() < 1e-9);
        let k = idx.knn(&q, 7);
        for (a, b) in k.iter().zip(&brute[..7]) {
            assert!((a.distance_squared - b.1).abs() < 1e-9);
        }
        let r = 12.0;
        let mut within: Vec<usize> = idx.within(&q, r).iter().map(|n| n.index).collect();
        within.sort();
        let mut expect: Vec<usize> = brute.iter().filter(|x| x.1 <= r * r).map(|x| x.0).collect();
        expect.sort();
        assert_eq!(within, expect);
    }
    assert!(KdIndex::new(&[]).nearest(&Point::origin()).is_none());
}

fn tee_cloud(count: usize, seed: u64) -> (Vec<Point>, Vec<Vector3<f64>>) {
    let part = tee(&TeeParams {
        resolution: 1.0,
        ..Default::default()
    })
    .unwrap();
    let s = sample_surface(&part.mesh, Density::Count(count), seed).unwrap();
    (s.points, s.normals)
}

fn random_offset(rng: &mut Rng, max_angle: f64, max_shift: f64) -> Isometry3<f64> {
    let axis = nalgebra::Unit::new_normalize(Vector3::new(rng.normal(), rng.normal(), rng.normal()));
    let rot = UnitQuaternion::from_axis_angle(&axis, rng.range(0.0, max_angle));
    let dir = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
    Isometry3::from_parts(Translation3::from(dir * rng.range(0.0, max_shift)), rot)
}

fn errors(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    (
        a.rotation.angle_to(&b.rotation),
        (a.translation.vector - b.translation.vector).norm(),
    )
}

#[test]
fn noiseless_transforms_are_recovered_to_1e6() {
    let (target, normals) = tee_cloud(4000, 1);
    let tgt = IcpTarget::new(target.clone(), Some(normals)).unwrap();
    let mut rng = Rng::new(2);
    for method in [IcpMethod::PointToPoint, IcpMethod::PointToPlane] {
        for trial in 0..5 {
            // Place the target far from the origin too: the sums must stay well conditioned.
            let t_true = Isometry3::translation(300.0, -200.0, 500.0)
                * random_offset(&mut rng, 0.15, 5.0)
                * Isometry3::translation(-300.0, 200.0, -500.0);
            let source = transform_points(&t_true.inverse(), &target);
            let cfg = IcpConfig {
                method,
                max_correspondence_distance: 20.0,
                max_iterations: 200,
                rotation_tolerance: 1e-10,
                translation_tolerance: 1e-9,
                ..Default::default()
            };
            let res = icp(&source, &tgt, &Isometry3::identity(), &cfg).unwrap();
            let (er, et) = errors(&res.t_target_source, &t_true);
            assert!(
                er < 1e-6 && et < 1e-6,
                "{method:?} trial {trial}: rotation error {er:e} rad, translation {et:e} mm after {} its",
                res.iterations
            );
            assert!(res.converged);
            assert!(res.fitness > 0.999 && res.rmse < 1e-5);
        }
    }
}

#[test]
fn noisy_independent_samplings_are_registered_within_the_noise() {
    let (target, normals) = tee_cloud(20000, 3);
    let (src_clean, _) = tee_cloud(8000, 4);
    let tgt = IcpTarget::new(target, Some(normals)).unwrap();
    let mut rng = Rng::new(5);
    let sigma = 0.2;
    for method in [IcpMethod::PointToPoint, IcpMethod::PointToPlane] {
        for _ in 0..3 {
            let t_true = random_offset(&mut rng, 0.12, 6.0);
            let noisy: Vec<Point> = src_clean
                .iter()
                .map(|p| p + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * sigma)
                .collect();
            let source = transform_points(&t_true.inverse(), &noisy);
            let cfg = IcpConfig {
                method,
                max_correspondence_distance: 15.0,
                max_iterations: 100,
                ..Default::default()
            };
            let res = icp(&source, &tgt, &Isometry3::identity(), &cfg).unwrap();
            let (er, et) = errors(&res.t_target_source, &t_true);
            assert!(
                er.to_degrees() < 0.25 && et < 0.2,
                "{method:?}: {:.3}° {et:.3} mm",
                er.to_degrees()
            );
        }
    }
}

#[test]
fn robust_kernels_and_trimming_reject_outliers() {
    let (target, normals) = tee_cloud(10000, 6);
    let (src_clean, _) = tee_cloud(3000, 7);
    let tgt = IcpTarget::new(target, Some(normals)).unwrap();
    let mut rng = Rng::new(8);
    let t_true = random_offset(&mut rng, 0.1, 4.0);
    // 30 % of the source is clutter a few mm off the part.
    let mut source = src_clean.clone();
    for p in source.iter_mut().take(900) {
        *p += Vector3::new(0.0, 0.0, 6.0 + rng.range(0.0, 3.0));
    }
    let source = transform_points(&t_true.inverse(), &source);
    let base = IcpConfig {
        method: IcpMethod::PointToPlane,
        max_correspondence_distance: 12.0,
        max_iterations: 100,
        ..Default::default()
    };
    let plain = icp(&source, &tgt, &Isometry3::identity(), &base).unwrap();
    let (plain_r, plain_t) = errors(&plain.t_target_source, &t_true);
    for cfg in [
        IcpConfig {
            kernel: RobustKernel::Tukey(3.0),
            ..base.clone()
        },
        IcpConfig {
            trim_fraction: 0.35,
            ..base.clone()
        },
    ] {
        let res = icp(&source, &tgt, &Isometry3::identity(), &cfg).unwrap();
        let (er, et) = errors(&res.t_target_source, &t_true);
        assert!(
            er.to_degrees() < 0.2 && et < 0.2,
            "{cfg:?}: {:.3}° {et:.3} mm",
            er.to_degrees()
        );
        assert!(et < plain_t || er < plain_r);
    }
}

#[test]
fn misuse_is_an_error_not_a_panic() {
    let (target, _) = tee_cloud(500, 9);
    let tgt = IcpTarget::new(target.clone(), None).unwrap();
    let cfg = IcpConfig {
        method: IcpMethod::PointToPlane,
        ..Default::default()
    };
    assert!(
        icp(&target, &tgt, &Isometry3::identity(), &cfg).is_err(),
        "point-to-plane without normals"
    );
    let line: Vec<Point> = (0..50).map(|i| Point::new(i as f64, 0.0, 0.0)).collect();
    assert!(IcpTarget::new(line.clone(), None).is_err());
    let p2p = IcpConfig {
        method: IcpMethod::PointToPoint,
        ..Default::default()
    };
    assert!(icp(&line, &tgt, &Isometry3::identity(), &p2p).is_err());
    assert!(icp(&target[..2], &tgt, &Isometry3::identity(), &p2p).is_err());
    let bad = IcpConfig {
        max_correspondence_distance: f64::NAN,
        ..p2p.clone()
    };
    assert!(icp(&target, &tgt, &Isometry3::identity(), &bad).is_err());
    // Far away: no correspondences is an outcome, not an error.
    let far = transform_points(&Isometry3::translation(1e4, 0.0, 0.0), &target);
    let res = icp(&far, &tgt, &Isometry3::identity(), &p2p).unwrap();
    assert!(!res.converged && res.num_inliers == 0 && res.fitness == 0.0);
}
