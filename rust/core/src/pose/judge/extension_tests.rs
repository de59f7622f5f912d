//! The extension test: an elbow read on the corner of a tee is a piece of a larger fitting (the
//! tee's run goes on past the elbow's corner); the elbow itself, in the same place, is a part.

use super::extension::read_ends;
use super::Judge;
use crate::geometry::BinBox;
use crate::mesh::parts::{cross, elbow, tee, FittingParams, Part, TeeParams};
use crate::mesh::{sample_surface, Density, TriMesh};
use crate::pose::tests::{self, config, top_view};
use crate::pose::*;
use crate::registration::ccp::BranchLayout;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::sync::OnceLock;

/// `part` prepared as binpick's built-in parts are (1 mm samples, its branches).
fn prepared(part: Part) -> (PoseModel, TriMesh) {
    let s = sample_surface(&part.mesh, Density::Spacing(1.0), 0).unwrap();
    let layout = layout_of(&part);
    let model = PoseModel::new(
        s.points,
        s.normals,
        part.mesh.diameter(),
        part.mesh.area(),
        Some(layout),
    )
    .unwrap();
    (model, part.mesh)
}

fn elbow_model() -> &'static (PoseModel, TriMesh) {
    static MODEL: OnceLock<(PoseModel, TriMesh)> = OnceLock::new();
    MODEL.get_or_init(|| prepared(elbow(&FittingParams::default()).unwrap()))
}

/// The tee without its boss: every face of it is a cross's.
fn plain_tee_model() -> &'static (PoseModel, TriMesh) {
    static MODEL: OnceLock<(PoseModel, TriMesh)> = OnceLock::new();
    MODEL.get_or_init(|| {
        prepared(
            tee(&TeeParams {
                boss_height: 0.0,
                ..TeeParams::default()
            })
            .unwrap(),
        )
    })
}

fn layout_of(part: &Part) -> BranchLayout {
    BranchLayout {
        directions: part.branches.iter().map(|b| b.direction).collect(),
        lengths: part.branches.iter().map(|b| b.length).collect(),
        radius: part.branches.iter().map(|b| b.radius).fold(0.0, f64::max),
        special: None,
    }
}

/// A fitting lying on the floor (its axes level, 13 mm radius), turned `yaw` about the vertical.
fn lying(yaw: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(400.0, 0.0, 13.0),
        UnitQuaternion::from_scaled_axis(Vector3::z() * yaw),
    )
}

/// `mesh` at `pose` seen from above, on a floor at z = 0, and the judge of the scene.
fn judged_scene(mesh: &TriMesh, pose: &Isometry3<f64>, model: &PoseModel) -> Judge {
    let pts = tests::with_floor(top_view(mesh, pose, 1), (400.0, 0.0), 1.0, 100, 1.0);
    let mut cfg = config(CoarseMethod::Ppf);
    cfg.bin = Some(BinBox {
        min: Point::new(280.0, -120.0, 0.0),
        max: Point::new(520.0, 120.0, 100.0),
    });
    tests::judge_of(&pts, &pts, Vec::new(), model, &cfg)
}

/// `model` posed on `larger` lying at each of `yaws` is refused by the extension test (and the
/// judge's verdict), and posed alone (`own` mesh) reads nothing past any end and passes.
fn refused_on_the_larger_part_and_passed_alone(model: &PoseModel, own: &TriMesh, larger: &TriMesh, yaws: &[f64]) {
    for &yaw in yaws {
        let pose = lying(yaw);
        let on_larger = judged_scene(larger, &pose, model);
        let ends = read_ends(&on_larger.depth, model, &pose);
        assert!(ends.iter().any(|e| e.carried_on()), "yaw {yaw}: {ends:?}");
        match on_larger.verdict(model, &pose) {
            Err(Error::NoObjectFound { reason }) => assert!(reason.contains("past its end"), "{reason}"),
            other => panic!("yaw {yaw}: a piece of the larger part passed: {other:?}"),
        }
        let alone = judged_scene(own, &pose, model);
        let ends = read_ends(&alone.depth, model, &pose);
        assert!(
            ends.iter().all(|e| !e.carried_on() && e.past == 0),
            "yaw {yaw}: {ends:?}"
        );
        assert!(
            alone.verdict(model, &pose).is_ok(),
            "yaw {yaw}: the part itself was refused"
        );
    }
}

#[test]
fn an_elbow_read_on_the_corner_of_a_tee_is_refused_and_the_elbow_itself_is_not() {
    // The elbow's arms lie on the tee's run (+x half) and its branch: every face of the elbow
    // is the tee's, but the run goes on past the elbow's corner.
    let (model, elbow_mesh) = elbow_model();
    refused_on_the_larger_part_and_passed_alone(model, elbow_mesh, &plain_tee_model().1, &[0.3, 2.0, -1.2]);
}

#[test]
fn a_tee_read_on_a_cross_is_refused_and_the_tee_itself_is_not() {
    // The tee's run and branch lie on the cross's; the cross's fourth branch goes on past the
    // tee's junction, opposite its branch.
    let (model, tee_mesh) = plain_tee_model();
    let cross_mesh = cross(&FittingParams::default()).unwrap().mesh;
    refused_on_the_larger_part_and_passed_alone(model, tee_mesh, &cross_mesh, &[0.7, -2.5]);
}
