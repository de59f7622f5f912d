//! Built-in parametric parts: the paper's plumbing tee, an elbow and a cross.
//!
//! Every part is a watertight mesh in millimetres, meshed from its signed distance function,
//! in the frame of the paper's Fig. 6b: the origin where the branch axes meet, x along the run
//! (the straight-through pipe), y along the side branch, z = x × y.

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::mesh::sdf::{capped_cylinder, elliptic_cylinder, mesh_sdf, sphere};
use crate::mesh::TriMesh;
use nalgebra::Vector3;

/// One cylindrical branch of a pipe fitting, as CCP needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Branch {
    /// Unit direction from the junction to the branch's open end, in the model frame.
    pub direction: Vector3<f64>,
    /// Distance from the junction to the end face, mm.
    pub length: f64,
    /// Outer radius, mm.
    pub radius: f64,
}

/// A built part: its mesh and the layout of its cylindrical branches.
#[derive(Debug, Clone)]
pub struct Part {
    /// Closed, outward-wound mesh, mm.
    pub mesh: TriMesh,
    /// Cylindrical branches from the junction at the origin.
    pub branches: Vec<Branch>,
}

/// Dimensions of the tee (mm). The defaults are a ¾-inch plumbing tee as in the paper: three
/// 26 mm branches, the run 80 mm end to end, the side branch 40 mm from the run's axis, and an
/// elliptical boss (22 × 16 mm) standing 17 mm above the axes on +z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TeeParams {
    /// Outer diameter of the three branches.
    pub outer_diameter: f64,
    /// Run length, end face to end face (along x).
    pub run_length: f64,
    /// Side branch length from the run's axis to its end face (along +y).
    pub branch_length: f64,
    /// Boss semi-axes along x and y.
    pub boss_semi_axes: (f64, f64),
    /// Height of the boss's top face above the axes (along +z); 0 for no boss.
    pub boss_height: f64,
    /// Meshing grid, mm.
    pub resolution: f64,
}

impl Default for TeeParams {
    fn default() -> Self {
        TeeParams {
            outer_diameter: 26.0,
            run_length: 80.0,
            branch_length: 40.0,
            boss_semi_axes: (11.0, 8.0),
            boss_height: 17.0,
            resolution: 0.6,
        }
    }
}

/// Dimensions of the elbow and the cross (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittingParams {
    /// Outer diameter of every branch.
    pub outer_diameter: f64,
    /// Each branch's length from the junction to its end face.
    pub branch_length: f64,
    /// Meshing grid, mm.
    pub resolution: f64,
}

impl Default for FittingParams {
    fn default() -> Self {
        FittingParams {
            outer_diameter: 26.0,
            branch_length: 40.0,
            resolution: 0.6,
        }
    }
}

fn positive(name: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            name,
            format!("must be a positive length in mm, got {v}"),
        ))
    }
}

fn check_resolution(res: f64, radius: f64) -> Result<()> {
    positive("resolution", res)?;
    if res > radius / 3.0 {
        return Err(Error::invalid(
            "resolution",
            format!(
                "{res} mm is too coarse for a {radius} mm radius; use at most {:.3}",
                radius / 3.0
            ),
        ));
    }
    Ok(())
}

fn branches_mesh(
    branches: &[Branch],
    extra: impl Fn(&Point) -> f64 + Sync,
    res: f64,
    z_extent: f64,
) -> Result<TriMesh> {
    let mut lo = Point::new(0.0, 0.0, 0.0);
    let mut hi = Point::new(0.0, 0.0, 0.0);
    for b in branches {
        let end = Point::from(b.direction * b.length);
        lo = lo.inf(&(end - Vector3::repeat(b.radius)));
        hi = hi.sup(&(end + Vector3::repeat(b.radius)));
        lo = lo.inf(&Point::from(Vector3::repeat(-b.radius)));
        hi = hi.sup(&Point::from(Vector3::repeat(b.radius)));
    }
    hi.z = hi.z.max(z_extent);
    let pad = Vector3::repeat(2.0 * res);
    let origin = Point::origin();
    mesh_sdf(
        |p| {
            let d = branches
                .iter()
                .map(|b| capped_cylinder(p, &origin, &Point::from(b.direction * b.length), b.radius))
                .fold(f64::INFINITY, f64::min);
            d.min(extra(p))
        },
        lo - pad,
        hi + pad,
        res,
    )
}

/// The paper's plumbing tee.
pub fn tee(p: &TeeParams) -> Result<Part> {
    positive("outer_diameter", p.outer_diameter)?;
    positive("run_length", p.run_length)?;
    positive("branch_length", p.branch_length)?;
    let r = p.outer_diameter / 2.0;
    check_resolution(p.resolution, r)?;
    if p.branch_length <= r {
        return Err(Error::invalid(
            "branch_length",
            format!("must exceed the radius {r} mm so the branch shows"),
        ));
    }
    if p.run_length / 2.0 <= r {
        return Err(Error::invalid(
            "run_length",
            format!("must exceed the outer diameter {} mm", p.outer_diameter),
        ));
    }
    let (ba, bb) = p.boss_semi_axes;
    if p.boss_height > 0.0 {
        positive("boss_semi_axes", ba.min(bb))?;
        if p.boss_height <= r {
            return Err(Error::invalid(
                "boss_height",
                format!("must exceed the radius {r} mm to stand out of the pipe, or be 0 for no boss"),
            ));
        }
    }
    let half = p.run_length / 2.0;
    let branches = vec![
        Branch {
            direction: Vector3::x(),
            length: half,
            radius: r,
        },
        Branch {
            direction: -Vector3::x(),
            length: half,
            radius: r,
        },
        Branch {
            direction: Vector3::y(),
            length: p.branch_length,
            radius: r,
        },
    ];
    let boss_h = p.boss_height;
    let origin = Point::origin();
    let mesh = {
        // The run is one cylinder end to end; the branch and the boss are unions.
        let run_a = Point::new(-half, 0.0, 0.0);
        let run_b = Point::new(half, 0.0, 0.0);
        let side = Point::new(0.0, p.branch_length, 0.0);
        let mut m = mesh_sdf(
            |q| {
                let mut d = capped_cylinder(q, &run_a, &run_b, r).min(capped_cylinder(q, &origin, &side, r));
                if boss_h > 0.0 {
                    d = d.min(elliptic_cylinder(
                        q,
                        &origin,
                        &Vector3::z(),
                        &Vector3::x(),
                        boss_h,
                        ba,
                        bb,
                    ));
                }
                d
            },
            Point::new(-half - r, -r, -r) - Vector3::repeat(2.0 * p.resolution),
            Point::new(half + r, p.branch_length + r, r.max(boss_h)) + Vector3::repeat(2.0 * p.resolution),
            p.resolution,
        )?;
        m.drop_degenerate_faces();
        m
    };
    Ok(Part { mesh, branches })
}

/// A 90° elbow: branches along +x and +y joined by a sphere at the corner.
pub fn elbow(p: &FittingParams) -> Result<Part> {
    fitting(p, &[Vector3::x(), Vector3::y()], true)
}

/// A cross: four branches along ±x and ±y.
pub fn cross(p: &FittingParams) -> Result<Part> {
    fitting(p, &[Vector3::x(), -Vector3::x(), Vector3::y(), -Vector3::y()], false)
}

fn fitting(p: &FittingParams, dirs: &[Vector3<f64>], corner_sphere: bool) -> Result<Part> {
    positive("outer_diameter", p.outer_diameter)?;
    positive("branch_length", p.branch_length)?;
    let r = p.outer_diameter / 2.0;
    check_resolution(p.resolution, r)?;
    if p.branch_length <= r {
        return Err(Error::invalid(
            "branch_length",
            format!("must exceed the radius {r} mm so the branch shows"),
        ));
    }
    let branches: Vec<Branch> = dirs
        .iter()
        .map(|d| Branch {
            direction: *d,
            length: p.branch_length,
            radius: r,
        })
        .collect();
    let origin = Point::origin();
    let mesh = branches_mesh(
        &branches,
        |q| {
            if corner_sphere {
                sphere(q, &origin, r)
            } else {
                f64::INFINITY
            }
        },
        p.resolution,
        r,
    )?;
    Ok(Part { mesh, branches })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tee_is_closed_with_the_expected_extent() {
        let t = tee(&TeeParams::default()).unwrap();
        let (lo, hi) = t.mesh.bounds();
        assert!((lo.x + 40.0).abs() < 0.3 && (hi.x - 40.0).abs() < 0.3, "{lo} {hi}");
        assert!((hi.y - 40.0).abs() < 0.3 && (lo.y + 13.0).abs() < 0.3);
        assert!((hi.z - 17.0).abs() < 0.3 && (lo.z + 13.0).abs() < 0.3);
        // Volume close to the union of the parts (run + branch stub beyond the run + boss above it).
        let r: f64 = 13.0;
        let pi = std::f64::consts::PI;
        let run = pi * r * r * 80.0;
        assert!(t.mesh.volume() > run);
    }

    #[test]
    fn bad_dimensions_are_rejected() {
        assert!(tee(&TeeParams {
            outer_diameter: -1.0,
            ..Default::default()
        })
        .is_err());
        assert!(tee(&TeeParams {
            resolution: 10.0,
            ..Default::default()
        })
        .is_err());
        assert!(cross(&FittingParams {
            branch_length: 5.0,
            ..Default::default()
        })
        .is_err());
        assert_eq!(elbow(&FittingParams::default()).unwrap().branches.len(), 2);
    }

    #[test]
    fn a_resolution_too_fine_for_the_grid_ceiling_is_refused_at_once() {
        let t = std::time::Instant::now();
        let err = tee(&TeeParams {
            resolution: 1e-6,
            ..Default::default()
        })
        .unwrap_err();
        assert!(
            err.to_string().contains("resolution") && err.to_string().contains("ceiling"),
            "{err}"
        );
        assert!(t.elapsed().as_millis() < 100);
        assert!(elbow(&FittingParams {
            resolution: 1e-6,
            ..Default::default()
        })
        .is_err());
    }
}
