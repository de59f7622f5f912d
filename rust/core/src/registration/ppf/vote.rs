//! Voting: scene reference points look up their pairs' features and vote for local poses.

use super::*;

/// One local pose from the vote of one scene reference point.
#[derive(Debug, Clone, Copy)]
pub struct Vote {
    /// Model → scene.
    pub t_scene_model: Isometry3<f64>,
    /// Votes the pose received.
    pub votes: f64,
    /// Index of the scene reference point (in the detection's cloud).
    pub reference: usize,
}

/// Parameters of one detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectConfig {
    /// Fraction of the scene samples used as reference points (Drost: 1/5; at least 60 points).
    pub reference_fraction: f64,
    /// Local poses kept per reference point (the best peaks of its accumulator).
    pub peaks_per_reference: usize,
    /// A peak is kept only with at least this fraction of the reference point's best peak.
    pub peak_ratio: f64,
    /// Poses whose model centres are closer than this fraction of the diameter may cluster.
    pub cluster_distance_ratio: f64,
    /// ... and whose rotations differ by less than this (radians, modulo symmetry).
    pub cluster_angle: f64,
    /// Hypotheses returned, best first.
    pub max_hypotheses: usize,
}

impl Default for DetectConfig {
    fn default() -> Self {
        DetectConfig {
            reference_fraction: 0.1,
            peaks_per_reference: 3,
            peak_ratio: 0.8,
            cluster_distance_ratio: 0.1,
            cluster_angle: 24f64.to_radians(),
            max_hypotheses: 16,
        }
    }
}

/// A scene feature this close to a bin boundary (fraction of the bin) also looks up the
/// neighbouring bin.
const SPREAD: f32 = 0.15;

/// Of the pairs whose two points lie in one plane (normals parallel, both square to the line
/// joining them) every FLAT_STRIDE-th votes, with FLAT_STRIDE votes: such pairs share one
/// feature on every flat face, so each votes for all the coplanar pairs of the model at its
/// distance — most of a flat part's voting time — and a sample of them gives the same tally in
/// expectation.
const FLAT_STRIDE: usize = 4;

/// Fewest reference points a detection uses.
const MIN_REFERENCES: usize = 60;

impl PpfModel {
    /// Votes with every `1 / reference_fraction`-th scene point as reference and returns the
    /// best local poses of each (model → scene). `points`/`normals` are the scene sampled at
    /// about [`PpfModel::step`], `index` a KD-tree over them.
    pub fn vote(&self, points: &[Point], normals: &[Vector3<f64>], index: &KdIndex, cfg: &DetectConfig) -> Vec<Vote> {
        // At least MIN_REFERENCES reference points however small the scene.
        let stride = ((1.0 / cfg.reference_fraction.clamp(1e-3, 1.0)).round().max(1.0) as usize)
            .min((points.len() / MIN_REFERENCES).max(1));
        let refs: Vec<usize> = (0..points.len()).step_by(stride).collect();
        let n_model = self.points.len();
        let rot_bins = self.config.rotation_bins as usize;
        let chunk = (refs.len() / (4 * rayon::current_num_threads()).max(1)).max(1);
        let cancel = crate::cancel::current();
        refs.par_chunks(chunk)
            .flat_map_iter(|chunk| {
                let mut acc = vec![0u32; n_model * rot_bins];
                let mut touched: Vec<u32> = Vec::new();
                let mut out = Vec::new();
                for &r in chunk {
                    if cancel.requested() {
                        break;
                    }
                    self.vote_one(points, normals, index, r, &mut acc, &mut touched);
                    self.peaks(&acc, &touched, r, &points[r], &normals[r], cfg, &mut out);
                    for &c in &touched {
                        acc[c as usize] = 0;
                    }
                    touched.clear();
                }
                out
            })
            .collect()
    }

    pub(super) fn vote_one(
        &self,
        points: &[Point],
        normals: &[Vector3<f64>],
        index: &KdIndex,
        r: usize,
        acc: &mut [u32],
        touched: &mut Vec<u32>,
    ) {
        let (sr, nr) = (&points[r], &normals[r]);
        let frame = Frame::new(sr, nr);
        let rb = self.config.rotation_bins as usize;
        let mut keys = [0usize; 16];
        for nb in index.within(sr, self.diameter) {
            let j = nb.index;
            if j == r {
                continue;
            }
            let Some(q) = self.quantise(sr, nr, &points[j], &normals[j]) else {
                continue;
            };
            let flat = self.coplanar(&q.bins);
            if flat && j % FLAT_STRIDE != r % FLAT_STRIDE {
                continue;
            }
            let weight = if flat { FLAT_STRIDE as u32 } else { 1 };
            let alpha_s = turn_fraction(frame.alpha(&points[j]));
            // The feature's own bin plus, per dimension, the neighbouring bin when the feature
            // lies within SPREAD of it.
            let mut nkeys = 1usize;
            keys[0] = self.key(&q.bins);
            for k in 0..4 {
                let max = if k == 0 {
                    self.distance_bins - 2
                } else {
                    self.config.angle_bins - 1
                };
                let other = if q.frac[k] < SPREAD && q.bins[k] > 0 {
                    Some(q.bins[k] - 1)
                } else if q.frac[k] > 1.0 - SPREAD && q.bins[k] < max {
                    Some(q.bins[k] + 1)
                } else {
                    None
                };
                if let Some(o) = other {
                    for t in 0..nkeys {
                        let mut b = self.unkey(keys[t]);
                        b[k] = o;
                        keys[nkeys + t] = self.key(&b);
                    }
                    nkeys *= 2;
                }
            }
            for &key in &keys[..nkeys] {
                let (lo, hi) = (self.offsets[key] as usize, self.offsets[key + 1] as usize);
                for &(m, alpha_m) in &self.entries[lo..hi] {
                    // (α_m − α_s + π) mod 2π, as a fraction of a turn, to a rotation bin.
                    let a = alpha_m.wrapping_sub(alpha_s).wrapping_add(1 << 15);
                    let bin = (a as usize * rb) >> 16;
                    let cell = m as usize * rb + bin;
                    if acc[cell] == 0 {
                        touched.push(cell as u32);
                    }
                    acc[cell] += weight;
                }
            }
        }
    }

    /// Whether a pair's feature bins are those of two points in one plane: the normals within a
    /// bin of parallel, each within a bin of square to the line joining the points.
    #[inline]
    fn coplanar(&self, bins: &[u32; 4]) -> bool {
        let right = self.config.angle_bins / 2;
        let square = |b: u32| b + 1 >= right && b <= right;
        bins[3] == 0 && square(bins[1]) && square(bins[2])
    }

    #[inline]
    pub(super) fn unkey(&self, key: usize) -> [u32; 4] {
        let a = self.config.angle_bins as usize;
        [
            (key / (a * a * a)) as u32,
            ((key / (a * a)) % a) as u32,
            ((key / a) % a) as u32,
            (key % a) as u32,
        ]
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn peaks(
        &self,
        acc: &[u32],
        touched: &[u32],
        r: usize,
        sr: &Point,
        nr: &Vector3<f64>,
        cfg: &DetectConfig,
        out: &mut Vec<Vote>,
    ) {
        let rb = self.config.rotation_bins as usize;
        // Votes of a cell with its two rotation neighbours: a true pose straddling two bins
        // keeps its strength.
        let smooth = |c: usize| -> u32 {
            let (m, b) = (c / rb, c % rb);
            acc[c] + (acc[m * rb + (b + 1) % rb] + acc[m * rb + (b + rb - 1) % rb]) / 2
        };
        let mut best: Vec<(u32, usize)> = Vec::with_capacity(cfg.peaks_per_reference + 1);
        for &c in touched {
            let c = c as usize;
            let v = smooth(c);
            if best.len() < cfg.peaks_per_reference || v > best.last().map_or(0, |b| b.0) {
                if best.iter().any(|b| b.1 == c) {
                    continue;
                }
                best.push((v, c));
                best.sort_by_key(|b| std::cmp::Reverse(b.0));
                best.truncate(cfg.peaks_per_reference);
            }
        }
        let Some(&(top, _)) = best.first() else { return };
        let frame = Frame::new(sr, nr);
        for &(v, c) in &best {
            if (v as f64) < cfg.peak_ratio * top as f64 || v < 3 {
                continue;
            }
            let (m, b) = (c / rb, c % rb);
            // Sub-bin rotation from the neighbours' votes (parabolic peak).
            let (l, h) = (
                acc[m * rb + (b + rb - 1) % rb] as f64,
                acc[m * rb + (b + 1) % rb] as f64,
            );
            let mid = acc[c] as f64;
            let denom = l - 2.0 * mid + h;
            let shift = if denom < 0.0 {
                (0.5 * (l - h) / denom).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            let alpha = -PI + (b as f64 + 0.5 + shift) * 2.0 * PI / rb as f64;
            out.push(Vote {
                t_scene_model: self.local_pose(&frame, m, alpha),
                votes: v as f64,
                reference: r,
            });
        }
    }

    /// Model → scene pose that puts model point `m` on the scene reference of `frame`, turned by
    /// `alpha` about the shared normal.
    pub(super) fn local_pose(&self, scene_frame: &Frame, m: usize, alpha: f64) -> Isometry3<f64> {
        let mf = &self.frames[m];
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), alpha);
        let r = scene_frame.rotation.transpose() * rx.matrix() * mf.rotation;
        let rot = UnitQuaternion::from_matrix(&r);
        let t = scene_frame.origin.coords - (rot * mf.origin).coords;
        Isometry3::from_parts(Translation3::from(t), rot)
    }
}
