//! One robot pose's view: the laser frame lit per motor angle, with sensor noise.

use super::*;

/// The geometry a camera sees from one robot pose: per pixel the first surface, its normal and
/// instance id, and its ambient shading. Lit by the laser per motor angle with [`View::frame`].
pub struct View {
    pub(super) camera: Camera,
    pub(super) t_base_camera: Isometry3<f64>,
    pub(super) placed: Vec<Placed>,
    pub(super) hits: Vec<Hit>,
    pub(super) shade: Vec<[f32; 3]>,
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
    ((s as f32 + 2.0) / 65536.0 - 2.0) * 1.732_050_8
}

pub(super) fn mix_seed(seed: u64, a: u64, b: u64) -> u64 {
    let mut z = seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z ^ (z >> 29)
}

/// Adds sensor noise to a float image and quantises it to 8 bits, rows in parallel, each row's
/// noise seeded from (`seed`, `salt`, row) so the result does not depend on the thread count.
pub(super) fn quantise(img: &[[f32; 3]], width: usize, noise: &SensorNoise, seed: u64, salt: u64) -> Vec<u8> {
    let mut out = vec![0u8; img.len() * 3];
    let noisy = noise.read_noise > 0.0 || noise.shot_noise > 0.0;
    let (read2, shot) = ((noise.read_noise * noise.read_noise) as f32, noise.shot_noise as f32);
    out.par_chunks_mut(width * 3).enumerate().for_each(|(row, buf)| {
        let mut rng = Rng::new(mix_seed(seed, salt, row as u64));
        for (u, px) in img[row * width..(row + 1) * width].iter().enumerate() {
            for c in 0..3 {
                let mut v = px[c];
                if noisy {
                    v += (read2 + shot * v.max(0.0)).sqrt() * fast_normal(&mut rng);
                }
                buf[u * 3 + c] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    });
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
        Ok(quantise(&self.shade, self.camera.width as usize, noise, seed, u64::MAX))
    }

    /// The RGB frame the camera grabs with the laser at motor angle `theta` (rad): the scene
    /// under ambient light plus the laser line where the sheet meets the first surface it
    /// reaches from the projector, with sensor noise. `seed` fixes the noise.
    pub fn frame(&self, laser: &Laser, theta: f64, noise: &SensorNoise, seed: u64) -> Result<Vec<u8>> {
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
        let mut img = self.shade.clone();
        let lit: Vec<(usize, f64)> = img
            .par_chunks_mut(w)
            .enumerate()
            .flat_map_iter(|(row, buf)| {
                let mut rng = Rng::new(mix_seed(seed ^ 0x5EC1_E000, salt, row as u64));
                let mut lit_here = Vec::new();
                for (u, px) in buf.iter_mut().enumerate() {
                    let h = &self.hits[row * w + u];
                    if h.id == -1 {
                        continue;
                    }
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
                    if cast(&self.placed, &o, &(wv / dist), dist - margin).is_some() {
                        continue;
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
                    for (c, p) in px.iter_mut().enumerate() {
                        *p += (irradiance * gain * laser.color[c] * (m.albedo[c] * cos_i + spec)) as f32;
                    }
                    if noise.reflections > 0.0 && m.specular > 0.0 {
                        lit_here.push((row * w + u, irradiance * gain));
                    }
                }
                lit_here
            })
            .collect();
        if noise.reflections > 0.0 {
            self.add_reflections(&mut img, &lit, laser, &o, noise.reflections);
        }
        Ok(quantise(&img, w, noise, seed, salt))
    }

    /// One mirror bounce of the laser off glossy surfaces: the reflected light lands on another
    /// surface and shows there as a stray spot or line, as on shiny real parts.
    pub(super) fn add_reflections(
        &self,
        img: &mut [[f32; 3]],
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
            for c in 0..3 {
                img[j][c] += (e * laser.color[c] * albedo[c]) as f32;
            }
        }
    }
}
