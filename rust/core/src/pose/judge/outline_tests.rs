//! The outline test: a short rod laid along a longer one is a piece of a larger shape; the
//! same rod alone, or beside a neighbour, is a part.

use super::outline::outline;
use super::Judge;
use crate::mesh::sdf::{capped_cylinder, mesh_sdf};
use crate::mesh::{sample_surface, Density, TriMesh};
use crate::pose::tests::{self, config, top_view};
use crate::pose::*;
use nalgebra::{Isometry3, Translation3};
use std::sync::OnceLock;

const RADIUS: f64 = 6.0;

/// A rod along x, `length` mm long, centred on the origin.
fn rod(length: f64) -> TriMesh {
    let (a, b) = (Point::new(-length / 2.0, 0.0, 0.0), Point::new(length / 2.0, 0.0, 0.0));
    let m = RADIUS + 1.0;
    mesh_sdf(
        |p| capped_cylinder(p, &a, &b, RADIUS),
        Point::new(-length / 2.0 - m, -m, -m),
        Point::new(length / 2.0 + m, m, m),
        0.5,
    )
    .unwrap()
}

fn short_rod() -> &'static PoseModel {
    static MODEL: OnceLock<PoseModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mesh = rod(40.0);
        let s = sample_surface(&mesh, Density::Spacing(1.0), 0).unwrap();
        let mut model = PoseModel::new(s.points, s.normals, mesh.diameter(), mesh.area(), None).unwrap();
        model.build_ppf(crate::registration::ppf::PpfConfig::default()).unwrap();
        model
    })
}

/// The scene of `meshes` posed, seen from straight above, on a floor at z = 0.
fn scene(meshes: &[(TriMesh, Isometry3<f64>)]) -> Vec<Point> {
    let pts: Vec<Point> = meshes.iter().flat_map(|(m, t)| top_view(m, t, 3)).collect();
    tests::with_floor(pts, (400.0, 0.0), 1.5, 60, 0.9 * RADIUS)
}

fn judge_of(scene: &[Point], model: &PoseModel) -> Judge {
    let mut cfg = config(CoarseMethod::Ppf);
    cfg.bin = Some(crate::geometry::BinBox {
        min: Point::new(300.0, -100.0, 0.0),
        max: Point::new(500.0, 100.0, 80.0),
    });
    tests::judge_of(scene, scene, Vec::new(), model, &cfg)
}

fn on_floor(x: f64, y: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(x, y, RADIUS), nalgebra::UnitQuaternion::identity())
}

#[test]
fn a_rod_alone_or_beside_another_passes_the_outline_test() {
    let model = short_rod();
    let alone = scene(&[(rod(40.0), on_floor(400.0, 0.0))]);
    let judge = judge_of(&alone, model);
    let o = outline(&judge.depth, model, &on_floor(400.0, 0.0));
    assert!(o.counted >= 8, "{o:?}");
    assert_eq!(o.continued, 0, "{o:?}");
    assert!(judge.verdict(model, &on_floor(400.0, 0.0)).is_ok());
    // A second rod parallel to it, touching its side: the side is a silhouette, not a face's edge.
    let side_by_side = scene(&[
        (rod(40.0), on_floor(400.0, 0.0)),
        (rod(40.0), on_floor(400.0, 2.0 * RADIUS)),
    ]);
    let judge = judge_of(&side_by_side, model);
    assert!(judge.verdict(model, &on_floor(400.0, 0.0)).is_ok());
}

#[test]
fn a_rod_laid_along_a_longer_one_is_refused() {
    let model = short_rod();
    let long = scene(&[(rod(120.0), on_floor(400.0, 0.0))]);
    let judge = judge_of(&long, model);
    // Mid-way along the longer rod, where both of its ends go on. (Flush with the longer rod's end
    // only one end goes on, about a third of the outline: that pose is not refused by this test.)
    for x in [400.0, 390.0] {
        let o = outline(&judge.depth, model, &on_floor(x, 0.0));
        assert!(o.continued_fraction() > 0.4, "at x = {x}: {o:?}");
        match judge.verdict(model, &on_floor(x, 0.0)) {
            Err(Error::NoObjectFound { reason }) => assert!(reason.contains("outline"), "{reason}"),
            other => panic!("a piece of a longer rod passed at x = {x}: {other:?}"),
        }
    }
}

/// A pose of a rod along x turned 45° about y (its +x end up), centred `s` mm along its axis
/// from (400, 0, 60).
fn tilted(s: f64) -> Isometry3<f64> {
    let turn = nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::y_axis(), -std::f64::consts::FRAC_PI_4);
    let axis = turn * nalgebra::Vector3::x();
    Isometry3::from_parts(
        Translation3::from(nalgebra::Vector3::new(400.0, 0.0, 60.0) + s * axis),
        turn,
    )
}

#[test]
fn a_rod_along_a_longer_one_tilted_45_degrees_is_refused_by_its_continuation() {
    use crate::pose::judge::continuation::continuation;
    let model = short_rod();
    // Alone, tilted: the scan ends where the rod ends.
    let alone = scene(&[(rod(40.0), tilted(0.0))]);
    let judge = judge_of(&alone, model);
    let c = continuation(&judge.depth, model, &tilted(0.0));
    assert!(c.confirmed >= 20 && c.beyond_fraction() < 0.1, "{c:?}");
    assert!(judge.verdict(model, &tilted(0.0)).is_ok());
    // Along a rod three times as long: no face of it is turned toward the sensor within 30°, so
    // the outline test says nothing; the scan runs on past both ends in the rod's tangent planes.
    let long = scene(&[(rod(120.0), tilted(0.0))]);
    let judge = judge_of(&long, model);
    for s in [0.0, -10.0] {
        let o = outline(&judge.depth, model, &tilted(s));
        assert!(o.continued_fraction() <= 0.4, "at s = {s}: {o:?}");
        let c = continuation(&judge.depth, model, &tilted(s));
        assert!(c.beyond_fraction() > 0.5, "at s = {s}: {c:?}");
        match judge.verdict(model, &tilted(s)) {
            Err(Error::NoObjectFound { reason }) => assert!(reason.contains("runs on"), "{reason}"),
            other => panic!("a piece of a longer tilted rod passed at s = {s}: {other:?}"),
        }
    }
}
