//! One robot pose's view: the laser frame lit per motor angle, with sensor noise.

use super::*;
use std::sync::atomic::{AtomicU8, Ordering};

/// The geometry a camera sees from one robot pose: per pixel the first surface, its normal and
/// instance id, and its ambient shading. Lit by the laser per motor angle with [`View::frame`].
pub struct View {
    pub(super) camera: Camera,
    pub(super) t_base_camera: Isometry3<f64>,
    pub(super) placed: Vec<Placed>,
    pub(super) hits: Vec<Hit>,
    pub(super) shade: Vec<[f32; 3]>,
    /// The pixels indexed by the motor angle whose sheet reaches them, for the last laser asked for.
    pub(super) sheets: std::sync::Mutex<Option<Arc<SheetIndex>>>,
}

/// The reaches a pixel is indexed under, rad: each pixel under the least that holds its own
/// (a surface seen edge-on spreads the sheet over more of the motor's turn); one whose reach
/// exceeds the last (near the projector's turning axis) is tried at every angle.
const REACHES: [f64; 5] = [0.004, 0.01, 0.03, 0.1, 0.3];

/// The pixels a view sees, by the motor angle whose laser sheet passes through their surface
/// point, for one laser pose and sheet: the projector turns about its own y axis through its
/// origin, so in its frame at angle 0 a point (x, y, z) lies at distance ρ·sin(φ − θ) from the
/// sheet at angle θ, with φ = atan2(x, z), ρ = √(x² + z²). A pixel can be lit at θ only where
/// that distance is within the 5σ the frame's test allows — σ² the sheet's plus the pixel's
/// footprint across it, at most |∂p/∂u|² + |∂p/∂v|² — so a frame tries only the pixels whose φ
/// is within that reach of θ (or of θ ± π), and lights exactly the pixels testing every one
/// would.
pub(super) struct SheetIndex {
    key: [u64; 18],
    /// Per entry of [`REACHES`], (φ, pixel) of the pixels indexed under it, sorted by φ.
    levels: Vec<Vec<(f64, u32)>>,
    /// The pixels whose reach exceeds every level's: tried at every angle.
    wide: Vec<u32>,
    /// Per pixel, whether something hides its surface point from the projector: 0 not yet
    /// known, 1 in the light, 2 in shadow. The projector turns about an axis through its
    /// origin, so the answer holds at every motor angle — found once, for the first frame that
    /// lights the pixel, and kept for the sweep's next frames.
    shadow: Vec<AtomicU8>,
}

impl SheetIndex {
    fn key(laser: &Laser, sigma2: f64, pixel_var: f64) -> [u64; 18] {
        let mut key = [0u64; 18];
        for (k, v) in laser.t_camera_laser0.to_homogeneous().iter().enumerate() {
            key[k] = v.to_bits();
        }
        key[16] = sigma2.to_bits();
        key[17] = pixel_var.to_bits();
        key
    }

    fn build(view: &View, laser: &Laser, sigma2: f64, pixel_var: f64) -> SheetIndex {
        let t_laser_camera = laser.t_camera_laser0.inverse();
        let mut levels = vec![Vec::new(); REACHES.len()];
        let mut wide = Vec::new();
        for (i, h) in view.hits.iter().enumerate() {
            if h.id == -1 {
                continue;
            }
            let q = t_laser_camera * Point::from(v3(&h.p));
            let rho = (q.x * q.x + q.z * q.z).sqrt();
            let g = v3(&h.dpdu).norm_squared() + v3(&h.dpdv).norm_squared();
            let r = 5.0 * (sigma2 + g * pixel_var).sqrt() / rho.max(1e-9);
            // |sin(φ − θ)| ≤ r: within asin(r) of φ (or of φ ± π); a little slack for rounding.
            let reach = if r < 1.0 {
                r.asin() * 1.001 + 1e-9
            } else {
                f64::INFINITY
            };
            match REACHES.iter().position(|&level| reach <= level) {
                Some(k) => levels[k].push((q.x.atan2(q.z), i as u32)),
                None => wide.push(i as u32),
            }
        }
        for level in &mut levels {
            level.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        }
        SheetIndex {
            key: Self::key(laser, sigma2, pixel_var),
            levels,
            wide,
            shadow: view.hits.iter().map(|_| AtomicU8::new(0)).collect(),
        }
    }

    /// Whether pixel `i` is in the laser's shadow: `test` finds it out the first time.
    fn in_shadow(&self, i: usize, test: impl FnOnce() -> bool) -> bool {
        match self.shadow[i].load(Ordering::Relaxed) {
            0 => {
                let shadowed = test();
                self.shadow[i].store(1 + u8::from(shadowed), Ordering::Relaxed);
                shadowed
            }
            known => known == 2,
        }
    }

    /// The pixels the sheet at `theta` can reach, in row-major order.
    fn candidates(&self, theta: f64) -> Vec<u32> {
        use std::f64::consts::PI;
        let mut out = self.wide.clone();
        for (level, &reach) in self.levels.iter().zip(REACHES.iter()) {
            for centre in [theta - 2.0 * PI, theta - PI, theta, theta + PI, theta + 2.0 * PI] {
                let lo = level.partition_point(|&(phi, _)| phi < centre - reach);
                let hi = level.partition_point(|&(phi, _)| phi <= centre + reach);
                out.extend(level[lo..hi].iter().map(|&(_, i)| i));
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }
}

impl std::fmt::Debug for View {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("View")
            .field("camera", &self.camera)
            .field("t_base_camera", &self.t_base_camera)
            .finish()
    }
}

/// Approximately standard-normal number from one 64-bit draw (sum of four 16-bit uniforms):
/// ample for sensor noise, several times cheaper than Box–Muller.
#[inline]
pub(super) fn fast_normal(rng: &mut Rng) -> f32 {
    let x = rng.next_u64();
    let s = (x & 0xFFFF) + ((x >> 16) & 0xFFFF) + ((x >> 32) & 0xFFFF) + (x >> 48);
    // s < 2¹⁸: the same value converted from i32, in one instruction on the baseline x86-64 target.
    ((s as i32 as f32 + 2.0) / 65536.0 - 2.0) * 1.732_050_8
}

/// Two approximately standard-normal numbers from one 64-bit draw, each the sum of four 8-bit
/// uniforms (1021 levels over ±3.5 σ: finer than the 8-bit pixel it is added to): the pixel
/// noise of a frame, two to three million numbers, at half the draws of [`fast_normal`].
#[inline]
fn fast_normals(x: u64) -> [f32; 2] {
    const BYTES: u64 = 0x00FF_00FF_00FF_00FF;
    const HALVES: u64 = 0x0000_FFFF_0000_FFFF;
    let pairs = (x & BYTES) + ((x >> 8) & BYTES); // four 16-bit sums of two bytes
                                                  // Each sum of four bytes has mean 510 and variance 4 · (256² − 1) / 12 = 21845.
    const SCALE: f32 = 1.0 / 147.800_54;
    let quads = (pairs & HALVES) + ((pairs >> 16) & HALVES); // two 32-bit sums of four bytes
    [
        ((quads & 0xFFFF_FFFF) as i32 as f32 - 510.0) * SCALE,
        ((quads >> 32) as i32 as f32 - 510.0) * SCALE,
    ]
}

pub(super) fn mix_seed(seed: u64, a: u64, b: u64) -> u64 {
    let mut z = seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z ^ (z >> 29)
}

/// Adds sensor noise to a float image and quantises it to 8 bits, rows in parallel, each row's
/// noise seeded from (`seed`, `salt`, row) so the result does not depend on the thread count.
/// Only the rows `noisy` get noise (the others are rounded as they are: rows not drawn).
pub(super) fn quantise(
    img: &[[f32; 3]],
    width: usize,
    noise: &SensorNoise,
    seed: u64,
    salt: u64,
    noisy: std::ops::Range<usize>,
) -> Vec<u8> {
    quantise_adding(img, &[], width, noise, seed, salt, noisy)
}

/// [`quantise`] of `img` with light added at some pixels: `adds` (pixel, RGB), sorted by pixel,
/// each pixel's in the order they were added: row by row, the row's light summed in one
/// reused buffer (not a copy of the image), its noise drawn, then rounded in a second pass.
pub(super) fn quantise_adding(
    img: &[[f32; 3]],
    adds: &[(usize, [f32; 3])],
    width: usize,
    noise: &SensorNoise,
    seed: u64,
    salt: u64,
    noisy_rows: std::ops::Range<usize>,
) -> Vec<u8> {
    let mut out = vec![0u8; img.len() * 3];
    let noisy = noise.read_noise > 0.0 || noise.shot_noise > 0.0;
    let (read2, shot) = ((noise.read_noise * noise.read_noise) as f32, noise.shot_noise as f32);
    let rows = out.par_chunks_mut(width * 3).enumerate();
    rows.for_each_init(
        || (Vec::new(), Vec::new()),
        |(light, normals): &mut (Vec<f32>, Vec<f32>), (row, buf)| {
            let start = row * width;
            light.clear();
            light.extend_from_slice(img[start..start + width].as_flattened());
            let first = adds.partition_point(|&(i, _)| i < start);
            for (i, add) in adds[first..].iter().take_while(|&&(i, _)| i < start + width) {
                for (v, add) in light[(i - start) * 3..][..3].iter_mut().zip(add) {
                    *v += add;
                }
            }
            if noisy && noisy_rows.contains(&row) {
                // The row's numbers drawn first (one generator, in order), then added in a loop
                // the compiler can run several values at a time.
                let mut rng = Rng::new(mix_seed(seed, salt, row as u64));
                normals.resize(light.len().next_multiple_of(2), 0.0);
                for pair in normals.chunks_exact_mut(2) {
                    pair.copy_from_slice(&fast_normals(rng.next_u64()));
                }
                for (v, n) in light.iter_mut().zip(normals.iter()) {
                    *v += (read2 + shot * v.max(0.0)).sqrt() * n;
                }
            }
            // Rounded half away from zero, as `round()` (whose library call costs more than the
            // noise): for v ≥ −0.5 that is ⌊v + 0.5⌋, and below it both clamp to 0.
            for (o, v) in buf.iter_mut().zip(light.iter()) {
                *o = (v + 0.5).clamp(0.0, 255.0) as u8;
            }
        },
    );
    out
}

impl View {
    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Pose of the camera in the base frame.
    pub fn t_base_camera(&self) -> Isometry3<f64> {
        self.t_base_camera
    }

    /// Depth image: z of the surface point in the camera frame, mm; NaN where nothing is hit.
    pub fn depth(&self) -> Vec<f32> {
        self.hits
            .iter()
            .map(|h| if h.id == -1 { f32::NAN } else { h.p[2] })
            .collect()
    }

    /// Instance-id image: the id of the surface each pixel sees, −1 for none.
    pub fn ids(&self) -> Vec<i32> {
        self.hits.iter().map(|h| h.id).collect()
    }

    /// Surface point of every pixel in the camera frame, mm (NaN where nothing is hit).
    pub fn points(&self) -> Vec<[f32; 3]> {
        self.hits
            .iter()
            .map(|h| if h.id == -1 { [f32::NAN; 3] } else { h.p })
            .collect()
    }

    /// Camera-facing unit normal of every pixel's surface in the camera frame (0 where none).
    pub fn normals(&self) -> Vec<[f32; 3]> {
        self.hits.iter().map(|h| h.n).collect()
    }

    /// The image under ambient light alone, with sensor noise.
    pub fn ambient_frame(&self, noise: &SensorNoise, seed: u64) -> Result<Vec<u8>> {
        noise.validate()?;
        Ok(quantise(
            &self.shade,
            self.camera.width as usize,
            noise,
            seed,
            u64::MAX,
            0..usize::MAX,
        ))
    }

    /// The RGB frame the camera grabs with the laser at motor angle `theta` (rad): the scene
    /// under ambient light plus the laser line where the sheet meets the first surface it
    /// reaches from the projector, with sensor noise. `seed` fixes the noise.
    pub fn frame(&self, laser: &Laser, theta: f64, noise: &SensorNoise, seed: u64) -> Result<Vec<u8>> {
        self.frame_trying(laser, theta, noise, seed, None)
    }

    /// [`View::frame`], trying the pixels the sheet index finds (`every`: every pixel instead).
    pub(super) fn frame_trying(
        &self,
        laser: &Laser,
        theta: f64,
        noise: &SensorNoise,
        seed: u64,
        every: Option<()>,
    ) -> Result<Vec<u8>> {
        laser.validate()?;
        noise.validate()?;
        if !theta.is_finite() {
            return Err(Error::invalid("angle", format!("must be finite, got {theta}")));
        }
        let w = self.camera.width as usize;
        let t = laser.t_camera_laser(theta);
        let o = Point::from(t.translation.vector);
        let r = t.rotation.to_rotation_matrix();
        let (xl, yl, zl) = (
            r.matrix().column(0).into_owned(),
            r.matrix().column(1).into_owned(),
            r.matrix().column(2).into_owned(),
        );
        let tan_half_fan = (laser.fan_angle / 2.0).tan();
        let sigma2 = laser.sheet_sigma * laser.sheet_sigma;
        let pixel_var = 1.0 / 12.0 + noise.blur * noise.blur;
        let salt = theta.to_bits();
        let index = self.sheet_index(laser, sigma2, pixel_var);
        let tried: Vec<u32> = match every {
            Some(()) => (0..self.hits.len() as u32).collect(),
            None => index.candidates(theta),
        };
        let mut adds: Vec<(usize, [f32; 3])> = Vec::new();
        let mut lit: Vec<(usize, f64)> = Vec::new();
        // Row by row, each row's speckle drawn in pixel order from its own seed, as when every
        // pixel of the image is tried: the same frame, from the pixels the sheet can reach.
        let mut row_now = usize::MAX;
        let mut rng = Rng::new(0);
        for i in tried {
            let i = i as usize;
            let (row, h) = (i / w, &self.hits[i]);
            let p = Point::from(v3(&h.p));
            let wv = p - o;
            let d = xl.dot(&wv);
            let (a, b) = (xl.dot(&v3(&h.dpdu)), xl.dot(&v3(&h.dpdv)));
            let s2 = sigma2 + (a * a + b * b) * pixel_var;
            if d * d > 25.0 * s2 {
                continue;
            }
            let along = zl.dot(&wv);
            if along <= 0.0 || yl.dot(&wv).abs() > tan_half_fan * along {
                continue;
            }
            let dist = wv.norm();
            let to_laser = -wv / dist;
            let n = v3(&h.n);
            let cos_i = n.dot(&to_laser);
            if cos_i <= 0.0 {
                continue;
            }
            // Laser shadow: something between the projector and this point.
            let margin = 0.05 + 1e-4 * dist;
            if index.in_shadow(i, || cast(&self.placed, &o, &(wv / dist), dist - margin).is_some()) {
                continue;
            }
            if row != row_now {
                row_now = row;
                rng = Rng::new(mix_seed(seed ^ 0x5EC1_E000, salt, row as u64));
            }
            let profile = (sigma2 / s2).sqrt() * (-0.5 * d * d / s2).exp();
            let irradiance = laser.power * profile * laser.reference_distance / dist;
            let m = &self.placed[h.placed as usize].mesh.material;
            let view_dir = -p.coords / p.coords.norm();
            let half = (to_laser + view_dir).normalize();
            let spec = m.specular * n.dot(&half).max(0.0).powf(m.shininess);
            let mut gain = 1.0;
            if noise.speckle > 0.0 {
                gain = (1.0 + noise.speckle * fast_normal(&mut rng) as f64).max(0.0);
            }
            adds.push((
                i,
                std::array::from_fn(|c| (irradiance * gain * laser.color[c] * (m.albedo[c] * cos_i + spec)) as f32),
            ));
            if noise.reflections > 0.0 && m.specular > 0.0 {
                lit.push((i, irradiance * gain));
            }
        }
        if noise.reflections > 0.0 {
            self.add_reflections(&mut adds, &lit, laser, &o, noise.reflections);
        }
        adds.sort_by_key(|&(i, _)| i); // stable: each pixel's light in the order it came
        Ok(quantise_adding(&self.shade, &adds, w, noise, seed, salt, 0..usize::MAX))
    }

    /// The sheet index of this view for `laser` (built on first use, kept for the next frames).
    fn sheet_index(&self, laser: &Laser, sigma2: f64, pixel_var: f64) -> Arc<SheetIndex> {
        let key = SheetIndex::key(laser, sigma2, pixel_var);
        let mut cache = self.sheets.lock().unwrap_or_else(|e| e.into_inner());
        match cache.as_ref() {
            Some(index) if index.key == key => index.clone(),
            _ => {
                let index = Arc::new(SheetIndex::build(self, laser, sigma2, pixel_var));
                *cache = Some(index.clone());
                index
            }
        }
    }

    /// One mirror bounce of the laser off glossy surfaces: the reflected light lands on another
    /// surface and shows there as a stray spot or line, as on shiny real parts.
    pub(super) fn add_reflections(
        &self,
        adds: &mut Vec<(usize, [f32; 3])>,
        lit: &[(usize, f64)],
        laser: &Laser,
        o: &Point,
        strength: f64,
    ) {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        for &(i, irradiance) in lit {
            let hit = &self.hits[i];
            let p = Point::from(v3(&hit.p));
            let n = v3(&hit.n);
            let m = &self.placed[hit.placed as usize].mesh.material;
            let incoming = (p - o).normalize();
            let out = incoming - n * (2.0 * incoming.dot(&n));
            let start = p + n * 0.05;
            let Some((t, n2, k)) = cast(&self.placed, &start, &out, 2000.0) else {
                continue;
            };
            let q = start + out * t;
            let Some([qu, qv]) = self.camera.project(&q) else {
                continue;
            };
            let (ui, vi) = (qu.round(), qv.round());
            if ui < 0.0 || vi < 0.0 || ui >= w as f64 || vi >= h as f64 {
                continue;
            }
            let j = vi as usize * w + ui as usize;
            // Only where the camera itself sees that surface point (not hidden behind another).
            if (self.hits[j].t as f64 - q.coords.norm()).abs() > 1.0 {
                continue;
            }
            let cos2 = n2.dot(&out).abs();
            let albedo = self.placed[k].mesh.material.albedo;
            let e = strength * m.specular * irradiance * cos2;
            adds.push((j, std::array::from_fn(|c| (e * laser.color[c] * albedo[c]) as f32)));
        }
    }
}
