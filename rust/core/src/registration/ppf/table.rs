//! The model's feature table: quantised point-pair features of the model, grouped by key.

use super::*;

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
        // The key table holds one offset per (distance, angle, angle, angle) bin: 4 bytes each.
        let keys = ((1.0 / self.sampling_ratio).ceil() + 2.0) * f64::from(self.angle_bins).powi(3);
        if keys > MAX_KEYS as f64 {
            return Err(Error::invalid(
                "angle_bins",
                format!(
                    "with sampling_ratio {} gives a feature table of {keys:.0} keys ({:.0} MB), over the ceiling of {MAX_KEYS} ({} MB); use fewer angle bins or a larger sampling_ratio",
                    self.sampling_ratio,
                    keys * 4.0 / 1e6,
                    MAX_KEYS * 4 / 1_000_000
                ),
            ));
        }
        Ok(())
    }
}

/// Largest key table of a feature table: 2^25 keys, 134 MB of offsets (the default table has
/// 0.6 million).
pub const MAX_KEYS: usize = 1 << 25;

/// The local frame of an oriented point: `rotation * (x − origin)` puts the point at the origin
/// with its normal along +x.
#[derive(Debug, Clone, Copy)]
pub(super) struct Frame {
    pub(super) rotation: Matrix3<f64>,
    pub(super) origin: Point,
}

impl Frame {
    pub(super) fn new(p: &Point, n: &Vector3<f64>) -> Self {
        let r = UnitQuaternion::rotation_between(n, &Vector3::x())
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), PI));
        Frame {
            rotation: *r.to_rotation_matrix().matrix(),
            origin: *p,
        }
    }

    /// The angle that turns `q` (in this frame) about +x into the half-plane z = 0, y > 0.
    #[inline]
    pub(super) fn alpha(&self, q: &Point) -> f64 {
        let v = self.rotation * (q - self.origin);
        (-v.z).atan2(v.y)
    }
}

/// Quantised feature of the pair (p1, n1) → (p2, n2) and the continuous bin coordinates;
/// `None` for coincident points or a distance beyond the table.
#[derive(Debug, Clone, Copy)]
pub(super) struct Quantised {
    pub(super) bins: [u32; 4],
    /// Fractional position inside each bin, in [0, 1).
    pub(super) frac: [f32; 4],
}

/// A model prepared for PPF detection.
#[derive(Debug, Clone)]
pub struct PpfModel {
    pub(super) config: PpfConfig,
    /// The sampling and distance step, mm.
    pub(super) step: f64,
    pub(super) diameter: f64,
    pub(super) points: Vec<Point>,
    pub(super) normals: Vec<Vector3<f64>>,
    pub(super) frames: Vec<Frame>,
    pub(super) distance_bins: u32,
    /// `offsets[k]..offsets[k + 1]` are the entries of key `k`.
    pub(super) offsets: Vec<u32>,
    /// (model reference point, α_m) of every model pair, grouped by key; α_m as a fraction of a
    /// turn from −π in 1/65536 steps (4 bytes a pair, integer arithmetic in the vote).
    pub(super) entries: Vec<(u16, u16)>,
}

/// α in [−π, π) as a fraction of a turn from −π, in 1/65536 steps.
#[inline]
pub(super) fn turn_fraction(alpha: f64) -> u16 {
    (((alpha + PI) * (65536.0 / (2.0 * PI))) as i64).rem_euclid(65536) as u16
}

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
        crate::cancel::check()?;
        Ok(model)
    }

    pub(super) fn key_count(&self) -> usize {
        let a = self.config.angle_bins as usize;
        self.distance_bins as usize * a * a * a
    }

    #[inline]
    pub(super) fn key(&self, b: &[u32; 4]) -> usize {
        let a = self.config.angle_bins as usize;
        ((b[0] as usize * a + b[1] as usize) * a + b[2] as usize) * a + b[3] as usize
    }

    pub(super) fn build_table(&mut self) {
        let n = self.points.len();
        // Per reference point, the keys and α of its pairs; then a counting sort by key.
        let cancel = crate::cancel::current();
        let rows: Vec<Vec<(u32, u16)>> = (0..n)
            .into_par_iter()
            .map(|i| {
                if cancel.requested() {
                    return Vec::new();
                }
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
    pub(super) fn quantise(&self, p1: &Point, n1: &Vector3<f64>, p2: &Point, n2: &Vector3<f64>) -> Option<Quantised> {
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
}
