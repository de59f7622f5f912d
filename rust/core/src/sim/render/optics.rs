//! The optics of the simulated sensor: the camera's rays (from the one camera model,
//! [`crate::Camera`]), the laser projector, materials, lighting and sensor noise.

use super::*;
use crate::geometry::PerCamera;

/// The largest image side the renderer draws, px (its buffers hold several values per pixel).
const MAX_SIDE: u32 = 16384;

/// How many cameras' ray grids [`pixel_ray_grid`] keeps (a cell renders through one or two).
const GRID_CACHE: usize = 2;
/// The largest camera whose ray grid is kept, pixels (16 MP: 256 MB of rays); a larger one's grid
/// is built for each frame and dropped with it.
const GRID_CACHE_MAX_PIXELS: usize = 1 << 24;

/// Undistorted normalised rays `(x, y)` (`z = 1`) of every pixel centre, row-major, from the one
/// camera model ([`Camera::ray`]): the rays the renderer casts are the ones triangulation
/// inverts. NaN where the distortion cannot be inverted (such a pixel sees nothing). Built on
/// first use and kept for the last few cameras (up to 16 MP): every frame of a capture or a scan after the
/// first skips the per-pixel undistortion.
pub(super) fn pixel_ray_grid(camera: &Camera) -> Result<Arc<Vec<[f64; 2]>>> {
    static CACHE: PerCamera<Vec<[f64; 2]>> = PerCamera::new(GRID_CACHE);
    camera.validate()?;
    if camera.width > MAX_SIDE || camera.height > MAX_SIDE {
        return Err(Error::invalid(
            "camera",
            format!(
                "image size {}×{} is larger than the renderer's {MAX_SIDE} px a side; render a smaller image",
                camera.width, camera.height
            ),
        ));
    }
    let (w, h) = (camera.width as usize, camera.height as usize);
    let build = || -> Vec<[f64; 2]> {
        (0..h)
            .into_par_iter()
            .flat_map_iter(|v| {
                (0..w).map(move |u| match camera.ray(u as f64, v as f64) {
                    Some(r) => [r.x, r.y],
                    None => [f64::NAN; 2],
                })
            })
            .collect()
    };
    Ok(if w * h > GRID_CACHE_MAX_PIXELS {
        Arc::new(build())
    } else {
        CACHE.get_or_build(camera, build)
    })
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
