//! Point-pair-feature detection (Drost, Ulrich, Navab and Ilic, CVPR 2010).
//!
//! Every ordered pair of oriented model points (m₁, n₁), (m₂, n₂) has the feature
//! F = (‖d‖, ∠(n₁, d), ∠(n₂, d), ∠(n₁, n₂)) with d = m₂ − m₁, invariant to rigid motion. The
//! model's pairs are quantised (distance in steps of the sampling distance, angles in
//! `angle_bins` over [0, π]) into a table that maps a feature to the pairs that have it, each
//! with the angle α_m that turns m₂ about the normal n₁ into a fixed half-plane once m₁ sits at
//! the origin with n₁ along +x.
//!
//! Detection: a scene reference point s_r paired with every scene point s_i within the model's
//! diameter looks up the pairs with the same feature; each matching model pair (m_r, α_m)
//! votes for the local pose "m_r on s_r, rotated by α = α_m − α_s about the shared normal".
//! The best local poses of all reference points are clustered (poses that differ by less than
//! the clustering thresholds, modulo the part's symmetry) and the clusters ranked by their votes.
//!
//! Beyond the original: a scene feature near the edge of a bin also looks up the
//! neighbouring bin of that dimension (noise in the normals moves features across boundaries);
//! a peak's votes include half of its two rotation neighbours, and its rotation is refined
//! between them (parabolic), so a pose straddling two rotation bins keeps its strength.

mod cache;
mod cluster;
mod table;
mod vote;

pub use cluster::Hypothesis;
pub use table::{PpfConfig, PpfModel};
pub use vote::{DetectConfig, Vote};

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::search::KdIndex;
use crate::symmetry::Symmetries;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;
use std::f64::consts::PI;
use table::{turn_fraction, Frame};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::mesh::sample::{sample_surface, Density};
    use crate::rng::Rng;
    use crate::voxel::subsample;

    pub(super) fn box_mesh(a: f64, b: f64, c: f64) -> crate::mesh::TriMesh {
        crate::mesh::test_box(
            Point::new(-a / 2.0, -b / 2.0, -c / 2.0),
            Point::new(a / 2.0, b / 2.0, c / 2.0),
        )
    }

    pub(super) fn prepared(points: &[Point], normals: &[Vector3<f64>], diameter: f64) -> PpfModel {
        let keep = subsample(points, 0.04 * diameter);
        PpfModel::new(
            keep.iter().map(|&i| points[i]).collect(),
            keep.iter().map(|&i| normals[i]).collect(),
            diameter,
            PpfConfig::default(),
        )
        .unwrap()
    }

    #[test]
    pub(super) fn local_pose_of_a_model_pair_maps_the_pair_onto_itself() {
        let mesh = crate::mesh::parts::tee(&crate::mesh::parts::TeeParams::default())
            .unwrap()
            .mesh;
        let s = sample_surface(&mesh, Density::Spacing(3.0), 1).unwrap();
        let model = prepared(&s.points, &s.normals, mesh.diameter());
        let mut rng = Rng::new(3);
        let truth = Isometry3::from_parts(Translation3::new(10.0, -20.0, 300.0), rng.rotation());
        let (i, j) = (5, 40);
        let (si, sj) = (truth * model.points[i], truth * model.points[j]);
        let (ni, nj) = (truth * model.normals[i], truth * model.normals[j]);
        let sf = Frame::new(&si, &ni);
        let alpha = model.frames[i].alpha(&model.points[j]) - sf.alpha(&sj);
        let pose = model.local_pose(&sf, i, alpha);
        assert!((pose * model.points[i] - si).norm() < 1e-9);
        assert!((pose * model.points[j] - sj).norm() < 1e-9);
        assert!((pose.rotation * model.normals[j] - nj).norm() < 1e-9);
        // Same feature, same key.
        let qm = model
            .quantise(&model.points[i], &model.normals[i], &model.points[j], &model.normals[j])
            .unwrap();
        let qs = model.quantise(&si, &ni, &sj, &nj).unwrap();
        assert_eq!(qm.bins, qs.bins);
    }

    #[test]
    pub(super) fn vote_recovers_a_posed_asymmetric_box_view() {
        let mesh = box_mesh(80.0, 50.0, 30.0);
        let s = sample_surface(&mesh, Density::Spacing(1.5), 2).unwrap();
        let model = prepared(&s.points, &s.normals, mesh.diameter());
        let mut rng = Rng::new(9);
        let sym = crate::symmetry::Symmetries::none(crate::geometry::centroid(&s.points));
        for trial in 0..4 {
            let truth = Isometry3::from_parts(
                Translation3::new(rng.range(-50.0, 50.0), rng.range(-50.0, 50.0), 100.0),
                rng.rotation(),
            );
            // The view: points whose normals face +z.
            let (pts, nrm): (Vec<Point>, Vec<Vector3<f64>>) = s
                .points
                .iter()
                .zip(&s.normals)
                .map(|(p, n)| (truth * p, truth.rotation * n))
                .filter(|(_, n)| n.z > 0.1)
                .unzip();
            let keep = subsample(&pts, model.step());
            let (sp, sn): (Vec<Point>, Vec<Vector3<f64>>) = keep.iter().map(|&i| (pts[i], nrm[i])).unzip();
            let index = KdIndex::new(&sp);
            let votes = model.vote(&sp, &sn, &index, &DetectConfig::default());
            let hyps = model.cluster(&votes, &sym, &DetectConfig::default());
            // The box has the symmetries of D2; compare modulo those by checking surface distance.
            let best = &hyps[0];
            let err = s
                .points
                .iter()
                .step_by(20)
                .map(|p| (best.t_scene_model * p - truth * p).norm())
                .fold(0.0, f64::max);
            let flipped = [Vector3::x(), Vector3::y(), Vector3::z()].iter().any(|ax| {
                let r = UnitQuaternion::from_scaled_axis(ax * PI);
                s.points
                    .iter()
                    .step_by(20)
                    .map(|p| (best.t_scene_model * (r * p) - truth * p).norm())
                    .fold(0.0, f64::max)
                    < 0.1 * mesh.diameter()
            });
            assert!(
                err < 0.1 * mesh.diameter() || flipped,
                "trial {trial}: max vertex error {err:.1} mm, {} hypotheses",
                hyps.len()
            );
        }
    }

    #[test]
    pub(super) fn bytes_round_trip_and_corruption_is_detected() {
        let mesh = box_mesh(40.0, 30.0, 20.0);
        let s = sample_surface(&mesh, Density::Spacing(1.0), 2).unwrap();
        let model = prepared(&s.points, &s.normals, mesh.diameter());
        let bytes = model.to_bytes();
        let back = PpfModel::from_bytes(&bytes).unwrap();
        assert_eq!(back.entries, model.entries);
        assert_eq!(back.offsets, model.offsets);
        assert_eq!(back.points, model.points);
        assert!(PpfModel::from_bytes(&bytes[..bytes.len() - 3]).is_err());
        let mut bad = bytes.clone();
        bad[0] ^= 1;
        assert!(PpfModel::from_bytes(&bad).is_err());
        let mut bad = bytes;
        let pos = 8 + 16 + 16 + 48 * model.points.len();
        bad[pos..pos + 4].copy_from_slice(&(u32::MAX).to_le_bytes());
        assert!(PpfModel::from_bytes(&bad).is_err());
    }

    #[test]
    pub(super) fn subsample_keeps_points_apart_and_covers() {
        let mut rng = Rng::new(1);
        let pts: Vec<Point> = (0..5000)
            .map(|_| Point::new(rng.range(0.0, 100.0), rng.range(0.0, 100.0), 0.0))
            .collect();
        let keep = subsample(&pts, 5.0);
        for (a, &i) in keep.iter().enumerate() {
            for &j in &keep[a + 1..] {
                assert!((pts[i] - pts[j]).norm() >= 5.0);
            }
        }
        for p in &pts {
            assert!(keep.iter().any(|&i| (pts[i] - p).norm() < 5.0));
        }
    }

    #[test]
    fn a_feature_table_over_the_key_ceiling_is_refused_before_it_is_built() {
        assert_eq!(PpfConfig::default().validate(), Ok(()));
        // 202 distance bins x 90^3 angle bins: 147 million keys, 590 MB of offsets.
        let huge = PpfConfig {
            sampling_ratio: 0.005,
            angle_bins: 90,
            ..PpfConfig::default()
        };
        assert!(matches!(huge.validate(), Err(Error::InvalidInput { arg, .. }) if arg == "angle_bins"));
        let fine = PpfConfig {
            sampling_ratio: 0.005,
            angle_bins: 30,
            ..PpfConfig::default()
        };
        assert_eq!(fine.validate(), Ok(()));
    }
}
