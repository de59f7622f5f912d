//! Clustering of the votes' local poses into pose hypotheses, modulo the part's symmetries.

use super::*;

/// A cluster of local poses.
#[derive(Debug, Clone)]
pub struct Hypothesis {
    /// Model → scene (vote-weighted mean of the members, in canonical form).
    pub t_scene_model: Isometry3<f64>,
    /// Sum of the members' votes.
    pub votes: f64,
    /// Members.
    pub members: usize,
}

impl PpfModel {
    /// Clusters local poses (model centres within `cluster_distance_ratio × diameter` and
    /// rotations within `cluster_angle`, both modulo the symmetries) and returns the clusters,
    /// most votes first.
    pub fn cluster(&self, votes: &[Vote], symmetries: &Symmetries, cfg: &DetectConfig) -> Vec<Hypothesis> {
        let center = symmetries.center;
        let mut order: Vec<(Isometry3<f64>, f64)> = votes
            .iter()
            .map(|v| (symmetries.canonical(&v.t_scene_model), v.votes))
            .collect();
        order.sort_by(|a, b| b.1.total_cmp(&a.1));
        let max_d = cfg.cluster_distance_ratio * self.diameter;
        struct Acc {
            first: Isometry3<f64>,
            sum_t: Vector3<f64>,
            sum_q: nalgebra::Vector4<f64>,
            votes: f64,
            members: usize,
        }
        let mut clusters: Vec<Acc> = Vec::new();
        for (t, v) in order {
            let c = t * center;
            let hit = clusters.iter_mut().find(|k| {
                (k.first * center - c).norm() < max_d
                    && symmetries.rotation_distance(&k.first.rotation, &t.rotation) < cfg.cluster_angle
            });
            // Members are averaged in the frame of the cluster's first pose (their symmetric
            // copy nearest to it), so the mean quaternion is meaningful.
            match hit {
                Some(k) => {
                    let t_near = symmetries.nearest_equivalent(&t, &k.first);
                    let q = t_near.rotation.coords;
                    let sign = if q.dot(&k.first.rotation.coords) < 0.0 {
                        -1.0
                    } else {
                        1.0
                    };
                    k.sum_q += q * (sign * v);
                    k.sum_t += (t_near * center).coords * v;
                    k.votes += v;
                    k.members += 1;
                }
                None => clusters.push(Acc {
                    first: t,
                    sum_t: c.coords * v,
                    sum_q: t.rotation.coords * v,
                    votes: v,
                    members: 1,
                }),
            }
        }
        clusters.sort_by(|a, b| b.votes.total_cmp(&a.votes));
        clusters
            .into_iter()
            .take(cfg.max_hypotheses)
            .map(|k| {
                let rot = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(k.sum_q / k.votes));
                let c = k.sum_t / k.votes;
                let t = c - rot * center.coords;
                Hypothesis {
                    t_scene_model: Isometry3::from_parts(Translation3::from(t), rot),
                    votes: k.votes,
                    members: k.members,
                }
            })
            .collect()
    }
}
