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

use crate::cloud::Point;
use crate::error::{Error, Result};
use crate::knn::KdIndex;
use crate::symmetry::Symmetries;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// Parameters of the model's feature table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PpfConfig {
    /// Sampling distance of model and scene as a fraction of the model's diameter; it is also
    /// the distance quantisation step (Drost's τ_d).
    pub sampling_ratio: f64,
    /// Bins of each angle feature over [0, π] (30: 6° wide).
    pub angle_bins: u32,
    /// Bins of the rotation angle α about the reference normal over [−π, π).
    pub rotation_bins: u32,
}

impl Default for PpfConfig {
    fn default() -> Self {
        PpfConfig {
            sampling_ratio: 0.05,
            angle_bins: 30,
            rotation_bins: 30,
        }
    }
}

impl PpfConfig {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<()> {
        if !(self.sampling_ratio.is_finite() && self.sampling_ratio >= 0.005 && self.sampling_ratio <= 0.25) {
            return Err(Error::invalid(
                "sampling_ratio",
                format!(
                    "must be between 0.005 and 0.25 of the model's diameter, got {}",
                    self.sampling_ratio
                ),
            ));
        }
        if !(6..=90).contains(&self.angle_bins) {
            return Err(Error::invalid(
                "angle_bins",
                format!("must be between 6 and 90, got {}", self.angle_bins),
            ));
        }
        if !(6..=180).contains(&self.rotation_bins) {
            return Err(Error::invalid(
                "rotation_bins",
                format!("must be between 6 and 180, got {}", self.rotation_bins),
            ));
        }
        Ok(())
    }
}

/// The local frame of an oriented point: `rotation * (x − origin)` puts the point at the origin
/// with its normal along +x.
#[derive(Debug, Clone, Copy)]
struct Frame {
    rotation: Matrix3<f64>,
    origin: Point,
}

impl Frame {
    fn new(p: &Point, n: &Vector3<f64>) -> Self {
        let r = UnitQuaternion::rotation_between(n, &Vector3::x())
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), PI));
        Frame {
            rotation: *r.to_rotation_matrix().matrix(),
            origin: *p,
        }
    }

    /// The angle that turns `q` (in this frame) about +x into the half-plane z = 0, y > 0.
    #[inline]
    fn alpha(&self, q: &Point) -> f64 {
        let v = self.rotation * (q - self.origin);
        (-v.z).atan2(v.y)
    }
}

/// Quantised feature of the pair (p1, n1) → (p2, n2) and the continuous bin coordinates;
/// `None` for coincident points or a distance beyond the table.
#[derive(Debug, Clone, Copy)]
struct Quantised {
    bins: [u32; 4],
    /// Fractional position inside each bin, in [0, 1).
    frac: [f32; 4],
}

/// A model prepared for PPF detection.
#[derive(Debug, Clone)]
pub struct PpfModel {
    config: PpfConfig,
    /// The sampling and distance step, mm.
    step: f64,
    diameter: f64,
    points: Vec<Point>,
    normals: Vec<Vector3<f64>>,
    frames: Vec<Frame>,
    distance_bins: u32,
    /// `offsets[k]..offsets[k + 1]` are the entries of key `k`.
    offsets: Vec<u32>,
    /// (model reference point, α_m) of every model pair, grouped by key; α_m as a fraction of a
    /// turn from −π in 1/65536 steps (4 bytes a pair, integer arithmetic in the vote).
    entries: Vec<(u16, u16)>,
}

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

const MAGIC: &[u8; 8] = b"BPPPF\x00\x00\x03";

/// A scene feature this close to a bin boundary (fraction of the bin) also looks up the
/// neighbouring bin.
const SPREAD: f32 = 0.15;

/// α in [−π, π) as a fraction of a turn from −π, in 1/65536 steps.
#[inline]
fn turn_fraction(alpha: f64) -> u16 {
    (((alpha + PI) * (65536.0 / (2.0 * PI))) as i64).rem_euclid(65536) as u16
}

/// Fewest reference points a detection uses.
const MIN_REFERENCES: usize = 60;

impl PpfModel {
    /// Builds the table from oriented model points (already sampled at about `step`), the
    /// model's diameter (mm) and the table's configuration.
    pub fn new(points: Vec<Point>, normals: Vec<Vector3<f64>>, diameter: f64, config: PpfConfig) -> Result<Self> {
        config.validate()?;
        if points.len() != normals.len() {
            return Err(Error::invalid(
                "normals",
                format!("has {} rows but points has {}", normals.len(), points.len()),
            ));
        }
        if points.len() < 4 {
            return Err(Error::TooFewPoints {
                arg: "model".into(),
                got: points.len(),
                needed: 4,
                hint: "; sample the model more densely".into(),
            });
        }
        if points.len() > 60_000 {
            // (and model indices fit the table's 16 bits)
            return Err(Error::invalid(
                "model",
                format!(
                    "{} sampled points would make a table of {} pairs; use a larger sampling_ratio",
                    points.len(),
                    points.len() * points.len()
                ),
            ));
        }
        if !(diameter.is_finite() && diameter > 0.0) {
            return Err(Error::invalid("diameter", "must be a positive length in mm"));
        }
        let step = config.sampling_ratio * diameter;
        let distance_bins = (diameter / step).ceil() as u32 + 2;
        let frames: Vec<Frame> = points.iter().zip(&normals).map(|(p, n)| Frame::new(p, n)).collect();
        let mut model = PpfModel {
            config,
            step,
            diameter,
            points,
            normals,
            frames,
            distance_bins,
            offsets: Vec::new(),
            entries: Vec::new(),
        };
        model.build_table();
        Ok(model)
    }

    fn key_count(&self) -> usize {
        let a = self.config.angle_bins as usize;
        self.distance_bins as usize * a * a * a
    }

    #[inline]
    fn key(&self, b: &[u32; 4]) -> usize {
        let a = self.config.angle_bins as usize;
        ((b[0] as usize * a + b[1] as usize) * a + b[2] as usize) * a + b[3] as usize
    }

    fn build_table(&mut self) {
        let n = self.points.len();
        // Per reference point, the keys and α of its pairs; then a counting sort by key.
        let rows: Vec<Vec<(u32, u16)>> = (0..n)
            .into_par_iter()
            .map(|i| {
                (0..n)
                    .filter(|&j| j != i)
                    .filter_map(|j| {
                        let q = self.quantise(&self.points[i], &self.normals[i], &self.points[j], &self.normals[j])?;
                        Some((
                            self.key(&q.bins) as u32,
                            turn_fraction(self.frames[i].alpha(&self.points[j])),
                        ))
                    })
                    .collect()
            })
            .collect();
        let keys = self.key_count();
        let mut counts = vec![0u32; keys + 1];
        for row in &rows {
            for &(k, _) in row {
                counts[k as usize + 1] += 1;
            }
        }
        for k in 0..keys {
            counts[k + 1] += counts[k];
        }
        let mut fill = counts.clone();
        let mut entries = vec![(0u16, 0u16); counts[keys] as usize];
        for (i, row) in rows.iter().enumerate() {
            for &(k, alpha) in row {
                let slot = &mut fill[k as usize];
                entries[*slot as usize] = (i as u16, alpha);
                *slot += 1;
            }
        }
        self.offsets = counts;
        self.entries = entries;
    }

    #[inline]
    fn quantise(&self, p1: &Point, n1: &Vector3<f64>, p2: &Point, n2: &Vector3<f64>) -> Option<Quantised> {
        let d = p2 - p1;
        let dist = d.norm();
        if dist < 1e-9 {
            return None;
        }
        let u = d / dist;
        let a = self.config.angle_bins as f64;
        let dist_pos = dist / self.step;
        if dist_pos >= (self.distance_bins - 1) as f64 {
            return None;
        }
        let ang = |c: f64| c.clamp(-1.0, 1.0).acos() * (a / PI);
        let pos = [dist_pos, ang(n1.dot(&u)), ang(n2.dot(&u)), ang(n1.dot(n2))];
        let mut bins = [0u32; 4];
        let mut frac = [0f32; 4];
        for k in 0..4 {
            let max = if k == 0 {
                self.distance_bins - 2
            } else {
                self.config.angle_bins - 1
            };
            let b = (pos[k].floor().max(0.0) as u32).min(max);
            bins[k] = b;
            frac[k] = (pos[k] - b as f64).clamp(0.0, 0.999) as f32;
        }
        Some(Quantised { bins, frac })
    }

    /// The sampling distance of model and scene, mm.
    pub fn step(&self) -> f64 {
        self.step
    }

    /// The table's configuration.
    pub fn config(&self) -> &PpfConfig {
        &self.config
    }

    /// The model's sampled points.
    pub fn points(&self) -> &[Point] {
        &self.points
    }

    /// Number of model pairs in the table.
    pub fn pair_count(&self) -> usize {
        self.entries.len()
    }

    /// Serialises the model (for a cache on disk): a versioned little-endian byte layout.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64 + self.points.len() * 48 + self.entries.len() * 4);
        out.extend_from_slice(MAGIC);
        for v in [self.config.sampling_ratio, self.diameter] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in [
            self.config.angle_bins,
            self.config.rotation_bins,
            self.points.len() as u32,
            self.entries.len() as u32,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for (p, n) in self.points.iter().zip(&self.normals) {
            for v in [p.x, p.y, p.z, n.x, n.y, n.z] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        for &(i, a) in &self.entries {
            out.extend_from_slice(&i.to_le_bytes());
            out.extend_from_slice(&a.to_le_bytes());
        }
        // The key table is mostly empty: store (key, count) of the keys that hold pairs.
        let used: Vec<(u32, u32)> = self
            .offsets
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[1] > w[0])
            .map(|(k, w)| (k as u32, w[1] - w[0]))
            .collect();
        out.extend_from_slice(&(used.len() as u32).to_le_bytes());
        for (k, c) in used {
            out.extend_from_slice(&k.to_le_bytes());
            out.extend_from_slice(&c.to_le_bytes());
        }
        out
    }

    /// Reads what [`PpfModel::to_bytes`] wrote; any mismatch is an error (the caller rebuilds).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let bad = |what: &str| {
            Error::invalid(
                "ppf_cache",
                format!("{what}; the cache file is stale or corrupt and will be rebuilt"),
            )
        };
        let mut at = 0usize;
        let mut take = |n: usize| -> Result<&[u8]> {
            let s = bytes.get(at..at + n).ok_or_else(|| bad("truncated"))?;
            at += n;
            Ok(s)
        };
        if take(8)? != MAGIC {
            return Err(bad("wrong magic or version"));
        }
        let f64_at = |s: &[u8]| f64::from_le_bytes(s.try_into().expect("8 bytes"));
        let u32_at = |s: &[u8]| u32::from_le_bytes(s.try_into().expect("4 bytes"));
        let sampling_ratio = f64_at(take(8)?);
        let diameter = f64_at(take(8)?);
        let angle_bins = u32_at(take(4)?);
        let rotation_bins = u32_at(take(4)?);
        let n = u32_at(take(4)?) as usize;
        let m = u32_at(take(4)?) as usize;
        let config = PpfConfig {
            sampling_ratio,
            angle_bins,
            rotation_bins,
        };
        config.validate().map_err(|_| bad("invalid parameters"))?;
        if !(diameter.is_finite() && diameter > 0.0) || n < 4 || n > 60_000 || m > n * n {
            return Err(bad("invalid sizes"));
        }
        let mut points = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        for _ in 0..n {
            let s = take(48)?;
            let v: Vec<f64> = s.chunks_exact(8).map(f64_at).collect();
            if v.iter().any(|x| !x.is_finite()) {
                return Err(bad("non-finite point"));
            }
            points.push(Point::new(v[0], v[1], v[2]));
            normals.push(Vector3::new(v[3], v[4], v[5]));
        }
        let mut entries = Vec::with_capacity(m);
        for _ in 0..m {
            let s = take(4)?;
            let i = u16::from_le_bytes([s[0], s[1]]);
            if i as usize >= n {
                return Err(bad("pair index out of range"));
            }
            entries.push((i, u16::from_le_bytes([s[2], s[3]])));
        }
        let step = sampling_ratio * diameter;
        let distance_bins = (diameter / step).ceil() as u32 + 2;
        let frames = points.iter().zip(&normals).map(|(p, n)| Frame::new(p, n)).collect();
        let mut model = PpfModel {
            config,
            step,
            diameter,
            points,
            normals,
            frames,
            distance_bins,
            offsets: Vec::new(),
            entries,
        };
        let keys = model.key_count();
        let used = u32_at(take(4)?) as usize;
        if used > m.min(keys) {
            return Err(bad("inconsistent table"));
        }
        let mut counts = vec![0u32; keys + 1];
        let mut previous: Option<u32> = None;
        for _ in 0..used {
            let (k, c) = (u32_at(take(4)?), u32_at(take(4)?));
            if k as usize >= keys || c == 0 || previous.is_some_and(|p| k <= p) {
                return Err(bad("inconsistent table"));
            }
            counts[k as usize + 1] = c;
            previous = Some(k);
        }
        for k in 0..keys {
            counts[k + 1] = counts[k]
                .checked_add(counts[k + 1])
                .ok_or_else(|| bad("inconsistent table"))?;
        }
        if at != bytes.len() || counts[keys] as usize != m {
            return Err(bad("inconsistent table"));
        }
        model.offsets = counts;
        Ok(model)
    }

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
        refs.par_chunks(chunk)
            .flat_map_iter(|chunk| {
                let mut acc = vec![0u32; n_model * rot_bins];
                let mut touched: Vec<u32> = Vec::new();
                let mut out = Vec::new();
                for &r in chunk {
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

    fn vote_one(
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
                    acc[cell] += 1;
                }
            }
        }
    }

    #[inline]
    fn unkey(&self, key: usize) -> [u32; 4] {
        let a = self.config.angle_bins as usize;
        [
            (key / (a * a * a)) as u32,
            ((key / (a * a)) % a) as u32,
            ((key / a) % a) as u32,
            (key % a) as u32,
        ]
    }

    #[allow(clippy::too_many_arguments)]
    fn peaks(
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
                best.sort_by(|a, b| b.0.cmp(&a.0));
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
    fn local_pose(&self, scene_frame: &Frame, m: usize, alpha: f64) -> Isometry3<f64> {
        let mf = &self.frames[m];
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), alpha);
        let r = scene_frame.rotation.transpose() * rx.matrix() * mf.rotation;
        let rot = UnitQuaternion::from_matrix(&r);
        let t = scene_frame.origin.coords - (rot * mf.origin).coords;
        Isometry3::from_parts(Translation3::from(t), rot)
    }

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{sample_surface, Density};
    use crate::rng::Rng;
    use crate::voxel::subsample;

    fn box_mesh(a: f64, b: f64, c: f64) -> crate::mesh::TriMesh {
        let v: Vec<Point> = (0..8)
            .map(|i| {
                Point::new(
                    a * ((i & 1) as f64 - 0.5),
                    b * (((i >> 1) & 1) as f64 - 0.5),
                    c * (((i >> 2) & 1) as f64 - 0.5),
                )
            })
            .collect();
        let faces = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        crate::mesh::TriMesh::new(v, faces).unwrap()
    }

    fn prepared(points: &[Point], normals: &[Vector3<f64>], diameter: f64) -> PpfModel {
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
    fn local_pose_of_a_model_pair_maps_the_pair_onto_itself() {
        let mesh = crate::parts::tee(&crate::parts::TeeParams::default()).unwrap().mesh;
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
    fn vote_recovers_a_posed_asymmetric_box_view() {
        let mesh = box_mesh(80.0, 50.0, 30.0);
        let s = sample_surface(&mesh, Density::Spacing(1.5), 2).unwrap();
        let model = prepared(&s.points, &s.normals, mesh.diameter());
        let mut rng = Rng::new(9);
        let sym = crate::symmetry::Symmetries::none(crate::cloud::centroid(&s.points));
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
    fn bytes_round_trip_and_corruption_is_detected() {
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
    fn subsample_keeps_points_apart_and_covers() {
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
}
