//! The optics of the simulated sensor: the camera, the laser projector, materials, lighting and sensor noise.

use super::*;

/// An OpenCV pinhole camera with radial-tangential distortion.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Image width, px.
    pub width: usize,
    /// Image height, px.
    pub height: usize,
    /// Focal length along x, px.
    pub fx: f64,
    /// Focal length along y, px.
    pub fy: f64,
    /// Principal point x, px (pixel centres at integer coordinates).
    pub cx: f64,
    /// Principal point y, px.
    pub cy: f64,
    /// Distortion `[k1, k2, p1, p2, k3]`.
    pub dist: [f64; 5],
}

impl Default for Camera {
    /// The paper's camera (AVT Guppy F-080C, 1032 × 778) with an 8 mm-class lens, no distortion.
    fn default() -> Self {
        Camera {
            width: 1032,
            height: 778,
            fx: 1600.0,
            fy: 1600.0,
            cx: 515.5,
            cy: 388.5,
            dist: [0.0; 5],
        }
    }
}

impl Camera {
    /// Checks sizes, focal lengths and distortion.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return Err(Error::invalid(
                "camera",
                format!(
                    "image size {}×{} must be between 1 and 16384 px",
                    self.width, self.height
                ),
            ));
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(name, format!("focal length must be positive, got {v}")));
            }
        }
        if !(self.cx.is_finite() && self.cy.is_finite() && self.dist.iter().all(|d| d.is_finite())) {
            return Err(Error::invalid(
                "camera",
                "principal point and distortion must be finite",
            ));
        }
        Ok(())
    }

    /// Applies lens distortion to normalised image coordinates.
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.dist;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Removes lens distortion from normalised image coordinates (fixed-point iteration).
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if self.dist.iter().all(|d| *d == 0.0) {
            return (xd, yd);
        }
        let [k1, k2, p1, p2, k3] = self.dist;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..100 {
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            let (nx, ny) = ((xd - dx) / radial, (yd - dy) / radial);
            let step = (nx - x).abs() + (ny - y).abs();
            x = nx;
            y = ny;
            if step < 1e-14 {
                break;
            }
        }
        (x, y)
    }

    /// The pixel where a point in the camera frame appears, or `None` behind the camera.
    pub fn project(&self, p: &Point) -> Option<(f64, f64)> {
        if p.z <= 1e-9 {
            return None;
        }
        let (x, y) = self.distort(p.x / p.z, p.y / p.z);
        Some((self.fx * x + self.cx, self.fy * y + self.cy))
    }

    /// Undistorted normalised coordinates of every pixel centre, row-major.
    pub(super) fn ray_table(&self) -> Vec<[f64; 2]> {
        (0..self.height)
            .into_par_iter()
            .flat_map_iter(|v| {
                (0..self.width).map(move |u| {
                    let (x, y) = self.undistort((u as f64 - self.cx) / self.fx, (v as f64 - self.cy) / self.fy);
                    [x, y]
                })
            })
            .collect()
    }
}

/// The laser line projector on the flange, turned by the motor about its own y axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Laser {
    /// Pose of the laser frame in the camera frame at motor angle 0.
    pub t_camera_laser0: Isometry3<f64>,
    /// Gaussian σ of the light sheet's thickness, mm.
    pub sheet_sigma: f64,
    /// Peak brightness on a white surface facing the laser at `reference_distance`, DN.
    pub power: f64,
    /// Full opening angle of the fan of light within the sheet, rad.
    pub fan_angle: f64,
    /// Relative response of the camera's R, G, B channels to the laser's light.
    pub color: [f64; 3],
    /// Distance at which `power` applies, mm; the sheet spreads as 1 / distance.
    pub reference_distance: f64,
}

impl Default for Laser {
    /// A red line laser 130 mm to the camera's right (+x), aimed at the optical axis 520 mm out.
    /// The single definition of the default projector: `binpick.sim.Laser` reads it through
    /// `binpick._core.sim_default_laser`.
    fn default() -> Self {
        let aim = (-130.0f64).atan2(520.0);
        Laser {
            t_camera_laser0: Isometry3::new(Vector3::new(130.0, 0.0, 0.0), Vector3::y() * aim),
            sheet_sigma: 0.35,
            power: 400.0,
            fan_angle: 60f64.to_radians(),
            color: [1.0, 0.12, 0.05],
            reference_distance: 500.0,
        }
    }
}

impl Laser {
    /// Pose of the laser frame in the camera frame at motor angle `theta` (rad).
    pub fn t_camera_laser(&self, theta: f64) -> Isometry3<f64> {
        self.t_camera_laser0 * Isometry3::rotation(Vector3::y() * theta)
    }

    /// Checks the numbers.
    pub fn validate(&self) -> Result<()> {
        let ok = self.sheet_sigma.is_finite()
            && self.sheet_sigma > 0.0
            && self.power.is_finite()
            && self.power >= 0.0
            && self.fan_angle > 0.0
            && self.fan_angle < std::f64::consts::PI
            && self.reference_distance > 0.0
            && self.color.iter().all(|c| c.is_finite() && *c >= 0.0);
        if !ok {
            return Err(Error::invalid(
                "laser",
                "sheet_sigma and reference_distance must be positive, power and colour ≥ 0, fan_angle in (0, π)",
            ));
        }
        Ok(())
    }
}

/// How a surface reflects light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Diffuse reflectance of R, G, B in [0, 1].
    pub albedo: [f64; 3],
    /// Strength of the specular (glossy) highlight of the laser, ≥ 0.
    pub specular: f64,
    /// Phong exponent of the highlight.
    pub shininess: f64,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            albedo: [0.7, 0.7, 0.68],
            specular: 0.0,
            shininess: 20.0,
        }
    }
}

/// Ambient illumination of the cell (what the camera sees without the laser).
#[derive(Debug, Clone, PartialEq)]
pub struct Lighting {
    /// Brightness of a white surface under diffuse ambient light, DN.
    pub ambient: f64,
    /// Extra brightness of a white surface facing the ceiling lamp, DN.
    pub lamp: f64,
    /// Direction towards the lamp in the robot's base frame.
    pub lamp_direction: Vector3<f64>,
    /// Brightness where no surface is hit, DN.
    pub background: f64,
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting {
            ambient: 55.0,
            lamp: 45.0,
            lamp_direction: Vector3::new(0.3, -0.2, 1.0),
            background: 6.0,
        }
    }
}

/// What the sensor and optics add to an ideal image.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorNoise {
    /// Read noise σ, DN.
    pub read_noise: f64,
    /// Shot noise: the variance grows by this many DN² per DN of signal.
    pub shot_noise: f64,
    /// Laser speckle contrast (σ / mean of the laser's brightness per pixel), 0 for none.
    pub speckle: f64,
    /// Strength of laser light mirrored once off glossy surfaces onto others, 0 for none.
    pub reflections: f64,
    /// Optical blur σ, px, widening the line.
    pub blur: f64,
}

impl Default for SensorNoise {
    fn default() -> Self {
        SensorNoise {
            read_noise: 1.5,
            shot_noise: 0.08,
            speckle: 0.0,
            reflections: 0.0,
            blur: 0.6,
        }
    }
}

impl SensorNoise {
    /// An ideal sensor (no noise, no speckle, no reflections) with the default optics blur.
    pub fn none() -> Self {
        SensorNoise {
            read_noise: 0.0,
            shot_noise: 0.0,
            speckle: 0.0,
            reflections: 0.0,
            ..Default::default()
        }
    }

    pub(super) fn validate(&self) -> Result<()> {
        let v = [
            self.read_noise,
            self.shot_noise,
            self.speckle,
            self.reflections,
            self.blur,
        ];
        if !v.iter().all(|x| x.is_finite() && *x >= 0.0) {
            return Err(Error::invalid(
                "noise",
                "read_noise, shot_noise, speckle, reflections and blur must be finite and ≥ 0",
            ));
        }
        Ok(())
    }
}
