//! Rendering of a printed calibration checkerboard.

use super::*;

/// A printed calibration checkerboard. Its frame follows OpenCV: the origin at the first inner
/// corner, x along the `cols` direction, y along `rows`, z into the board; inner corners at
/// `(i·square, j·square, 0)` for `i < cols − 1`, `j < rows − 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkerboard {
    /// Squares along x.
    pub cols: usize,
    /// Squares along y.
    pub rows: usize,
    /// Square edge, mm.
    pub square: f64,
    /// White border around the squares, mm.
    pub margin: f64,
}

impl Default for Checkerboard {
    fn default() -> Self {
        Checkerboard {
            cols: 10,
            rows: 7,
            square: 20.0,
            margin: 15.0,
        }
    }
}

/// Renders a checkerboard at `t_camera_board` under `lighting` with `supersample`² samples per
/// pixel, optionally with the laser line at an angle on it, and sensor noise: the images the
/// camera and laser calibrations are computed from. `window` `[u0, v0, u1, v1]` (pixels,
/// half-open): only those pixels are drawn, each as in the whole image (its noise too); the rest
/// are the background's, noiseless outside the window's rows (a view that shows the board in a
/// part of the picture).
#[allow(clippy::too_many_arguments)]
pub fn render_checkerboard(
    camera: &Camera,
    board: &Checkerboard,
    t_camera_board: &Isometry3<f64>,
    lighting: &Lighting,
    laser: Option<(&Laser, f64)>,
    noise: &SensorNoise,
    supersample: usize,
    seed: u64,
    window: Option<[usize; 4]>,
) -> Result<Vec<u8>> {
    let table = pixel_ray_grid(camera)?;
    noise.validate()?;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let [u_lo, v_lo, u_hi, v_hi] = window.unwrap_or([0, 0, w, h]);
    if u_lo >= u_hi || v_lo >= v_hi || u_hi > w || v_hi > h {
        return Err(Error::invalid(
            "window",
            format!(
                "(u0, v0, u1, v1) must satisfy u0 < u1 ≤ {w} and v0 < v1 ≤ {h}, got ({u_lo}, {v_lo}, {u_hi}, {v_hi})"
            ),
        ));
    }
    if board.cols < 2 || board.rows < 2 || !(board.square > 0.0) || !(board.margin >= 0.0) {
        return Err(Error::invalid(
            "board",
            "needs at least 2 × 2 squares, a positive square size and a margin ≥ 0",
        ));
    }
    if supersample == 0 || supersample > 16 {
        return Err(Error::invalid(
            "supersample",
            format!("must be in 1..=16, got {supersample}"),
        ));
    }
    if let Some((l, th)) = laser {
        l.validate()?;
        if !th.is_finite() {
            return Err(Error::invalid("angle", "must be finite"));
        }
    }
    let n = t_camera_board.rotation * Vector3::z();
    let p0 = Point::from(t_camera_board.translation.vector);
    let t_board_camera = t_camera_board.inverse();
    let lamp = lighting.lamp_direction.try_normalize(1e-12).unwrap_or_else(Vector3::z);
    let shade = lighting.ambient + lighting.lamp * n.dot(&lamp).abs();
    let (xmin, ymin) = (-board.square - board.margin, -board.square - board.margin);
    let (xmax, ymax) = (
        (board.cols - 1) as f64 * board.square + board.margin,
        (board.rows - 1) as f64 * board.square + board.margin,
    );
    let laser_frame = laser.map(|(l, th)| {
        let t = l.t_camera_laser(th);
        let r = t.rotation.to_rotation_matrix().into_inner();
        (
            l,
            Point::from(t.translation.vector),
            r.column(0).into_owned(),
            r.column(1).into_owned(),
            r.column(2).into_owned(),
        )
    });
    let k = supersample;
    let (gx, gy) = (
        (board.cols - 1) as f64 * board.square,
        (board.rows - 1) as f64 * board.square,
    );
    // The board point seen along ray (x, y, 1), camera frame and board frame; None where the
    // ray runs parallel to the board or meets its plane behind the camera.
    let meet = |x: f64, y: f64| -> Option<(Point, Point)> {
        let r = Vector3::new(x, y, 1.0);
        let den = n.dot(&r);
        let tt = if den.abs() > 1e-12 {
            n.dot(&p0.coords) / den
        } else {
            -1.0
        };
        (tt > 0.0).then(|| {
            let p = Point::from(r * tt);
            (p, t_board_camera * p)
        })
    };
    // A region of the board's plane that is convex and of one colour: a square, one of the
    // four bands of the white margin, or one of the half-planes beyond the board. A pixel whose
    // footprint has its four corners in the same region is of that colour throughout.
    let region = |b: &Point| -> (i64, i64) {
        if b.x < xmin {
            (-10, 0)
        } else if b.x > xmax {
            (-11, 0)
        } else if b.y < ymin {
            (-12, 0)
        } else if b.y > ymax {
            (-13, 0)
        } else if b.x < -board.square {
            (-20, 0)
        } else if b.x >= gx {
            (-21, 0)
        } else if b.y < -board.square {
            (-22, 0)
        } else if b.y >= gy {
            (-23, 0)
        } else {
            ((b.x / board.square).floor() as i64, (b.y / board.square).floor() as i64)
        }
    };
    // The radiance of the board at `x` (camera frame), board point `b`.
    let radiance = |x: &Point, b: &Point| -> [f64; 3] {
        if b.x < xmin || b.x > xmax || b.y < ymin || b.y > ymax {
            return [lighting.background; 3];
        }
        let inside = b.x >= -board.square && b.x < gx && b.y >= -board.square && b.y < gy;
        let black =
            inside && ((b.x / board.square).floor() as i64 + (b.y / board.square).floor() as i64).rem_euclid(2) == 0;
        let albedo = if black { 0.08 } else { 0.85 };
        let mut rgb = [albedo * shade; 3];
        if let Some((l, o, xl, yl, zl)) = &laser_frame {
            let wv = x - o;
            let along = zl.dot(&wv);
            if along > 0.0 && yl.dot(&wv).abs() <= (l.fan_angle / 2.0).tan() * along {
                let d = xl.dot(&wv);
                let dist = wv.norm();
                let cos_i = n.dot(&(wv / dist)).abs();
                let e = l.power * (-0.5 * d * d / (l.sheet_sigma * l.sheet_sigma)).exp() * l.reference_distance / dist
                    * cos_i
                    * albedo;
                for (v, c) in rgb.iter_mut().zip(&l.color) {
                    *v += e * c;
                }
            }
        }
        rgb
    };
    // The laser's light is below a millionth of its peak this far from the sheet.
    let dark = laser_frame.as_ref().map(|(l, ..)| 5.3 * l.sheet_sigma);
    let img: Vec<[f32; 3]> = (0..h)
        .into_par_iter()
        .flat_map_iter(|v| {
            let table = &table;
            let (meet, region, radiance, laser_frame) = (&meet, &region, &radiance, &laser_frame);
            (0..w).map(move |u| {
                if u < u_lo || u >= u_hi || v < v_lo || v >= v_hi {
                    return [lighting.background as f32; 3];
                }
                let at = |uu: usize, vv: usize| table[vv * w + uu];
                let c = at(u, v);
                let (u0, u1) = (u.saturating_sub(1), (u + 1).min(w - 1));
                let (v0, v1) = (v.saturating_sub(1), (v + 1).min(h - 1));
                let du = [
                    (at(u1, v)[0] - at(u0, v)[0]) / (u1 - u0).max(1) as f64,
                    (at(u1, v)[1] - at(u0, v)[1]) / (u1 - u0).max(1) as f64,
                ];
                let dv = [
                    (at(u, v1)[0] - at(u, v0)[0]) / (v1 - v0).max(1) as f64,
                    (at(u, v1)[1] - at(u, v0)[1]) / (v1 - v0).max(1) as f64,
                ];
                let ray = |su: f64, sv: f64| (c[0] + su * du[0] + sv * dv[0], c[1] + su * du[1] + sv * dv[1]);
                // One sample stands for the pixel when its footprint (the parallelogram the
                // supersamples fill) is of one colour with no laser light: its four corners all
                // miss the board's plane, or all lie in one convex region of one colour, on the
                // same side of the sheet and far from it (the sheet's distance is affine on the
                // board, so the footprint's nearest point to it is a corner).
                if k > 1 {
                    let corners = [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)].map(|(su, sv)| {
                        let (x, y) = ray(su, sv);
                        meet(x, y)
                    });
                    let uniform = if corners.iter().all(Option::is_none) {
                        true
                    } else if let [Some(a), Some(b), Some(c2), Some(d)] = &corners {
                        let r0 = region(&a.1);
                        let same = [b, c2, d].iter().all(|q| region(&q.1) == r0);
                        let unlit = match (laser_frame, dark) {
                            (Some((_, o, xl, ..)), Some(far)) => {
                                let side = |q: &(Point, Point)| xl.dot(&(q.0 - o));
                                let s0 = side(a);
                                s0.abs() > far && [b, c2, d].iter().all(|q| (side(q) * s0.signum()) > far)
                            }
                            _ => true,
                        };
                        same && unlit
                    } else {
                        false
                    };
                    if uniform {
                        let (x, y) = ray(0.0, 0.0);
                        let rgb = match meet(x, y) {
                            Some((p, b)) => radiance(&p, &b),
                            None => [lighting.background; 3],
                        };
                        return [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32];
                    }
                }
                let mut acc = [0.0f64; 3];
                for i in 0..k {
                    for j in 0..k {
                        let (su, sv) = ((i as f64 + 0.5) / k as f64 - 0.5, (j as f64 + 0.5) / k as f64 - 0.5);
                        let (x, y) = ray(su, sv);
                        let rgb = match meet(x, y) {
                            Some((p, b)) => radiance(&p, &b),
                            None => [lighting.background; 3],
                        };
                        for ch in 0..3 {
                            acc[ch] += rgb[ch];
                        }
                    }
                }
                let s = (k * k) as f64;
                [(acc[0] / s) as f32, (acc[1] / s) as f32, (acc[2] / s) as f32]
            })
        })
        .collect();
    Ok(quantise(&img, w, noise, seed, 0xB0A2D, v_lo..v_hi))
}
