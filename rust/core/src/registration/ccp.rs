//! The computed closer point (CCP) coarse pose of the paper (§4.1, Eq. 20–29), generalised from
//! the tee to any part made of cylindrical branches that meet at a junction.
//!
//! Steps, as in the paper: the centre of mass p_c (Eq. 20); the closer centre p'_c, the mean of
//! the points within `s` of p_c (Eq. 21); the endpoints, the points farthest from p'_c in
//! different directions (Eq. 22); for parts with a special feature (the tee's boss), the special
//! endpoint, the endpoint farthest from the plane fitted to the points around p'_c; the groups,
//! points within τ of an endpoint and nearest its line (Eq. 25–27); and the axes from p'_c to each
//! group's mean (Eq. 28). The paper then names x_D and y_D by the tee's layout; here every
//! assignment of the observed axes to the model's branches that the layout allows gives a
//! candidate rotation (Kabsch on the axis directions), so that any branch layout works. The
//! candidates are returned best first by a short ICP check against the model in the caller.
//!
//! What a model needs for CCP: its branches (unit direction from the junction at the model
//! origin, length, radius) and, if it has one, the direction of its special feature.

use crate::error::{Error, Result};
use crate::geometry::{centroid, covariance, kabsch, principal_axes, Point};
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

/// The branch layout of a model, in the model frame (junction at the origin).
#[derive(Debug, Clone, PartialEq)]
pub struct BranchLayout {
    /// Unit directions of the branches.
    pub directions: Vec<Vector3<f64>>,
    /// Branch lengths from the junction, mm.
    pub lengths: Vec<f64>,
    /// Largest branch radius, mm.
    pub radius: f64,
    /// Direction of the special feature (the tee's boss), if any.
    pub special: Option<Vector3<f64>>,
}

/// The smallest angle between two declared branch directions, rad (10°): closer ones are one
/// branch declared twice, and CCP could not tell them apart.
pub const MIN_BRANCH_ANGLE: f64 = 10.0 * std::f64::consts::PI / 180.0;

impl BranchLayout {
    /// Checks the declaration: at least two branches, one length each, finite non-zero
    /// directions no two within [`MIN_BRANCH_ANGLE`], positive lengths and radius, and a finite
    /// non-zero special direction. Errors name `branches`.
    pub fn validate(&self) -> Result<()> {
        let bad = |problem: String| Err(Error::invalid("branches", problem));
        let n = self.directions.len();
        if n < 2 || self.lengths.len() != n {
            return bad(format!(
                "{n} directions and {} lengths; declare at least two branches, one length each",
                self.lengths.len()
            ));
        }
        let finite = |v: &Vector3<f64>| v.iter().all(|x| x.is_finite()) && v.norm() > 1e-9;
        if let Some(i) = self.directions.iter().position(|d| !finite(d)) {
            return bad(format!("direction {i} is zero or not finite; give each branch's axis"));
        }
        if let Some(i) = self.lengths.iter().position(|l| !(l.is_finite() && *l > 0.0)) {
            return bad(format!(
                "length {i} must be a positive length in mm, got {}",
                self.lengths[i]
            ));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return bad(format!(
                "the radius must be a positive length in mm, got {}",
                self.radius
            ));
        }
        if self.special.is_some_and(|s| !finite(&s)) {
            return bad("the special direction is zero or not finite".into());
        }
        for i in 0..n {
            for j in i + 1..n {
                let cos = self.directions[i].normalize().dot(&self.directions[j].normalize());
                if cos > MIN_BRANCH_ANGLE.cos() {
                    return bad(format!(
                        "directions {i} and {j} are {:.1}° apart, under {:.0}°: one branch declared twice; \
                         declare each branch once",
                        cos.clamp(-1.0, 1.0).acos().to_degrees(),
                        MIN_BRANCH_ANGLE.to_degrees()
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Tuning of CCP; `None` fields take defaults derived from the layout.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CcpConfig {
    /// s of Eq. 21, mm (default: 1.5 × the branch radius).
    pub closer_radius: Option<f64>,
    /// τ of Eq. 25, mm (default: 0.8 × the shortest branch length).
    pub tau: Option<f64>,
}

/// What CCP found in the data, and the candidate poses.
#[derive(Debug, Clone)]
pub struct CcpResult {
    /// p_c, the centre of mass (Eq. 20).
    pub center: Point,
    /// p'_c, the closer centre (Eq. 21).
    pub closer_center: Point,
    /// The endpoints found (Eq. 22).
    pub endpoints: Vec<Point>,
    /// The special endpoint, when the layout has a special feature.
    pub special_endpoint: Option<Point>,
    /// Unit axes from p'_c to each group's mean, one per non-special endpoint.
    pub axes: Vec<Vector3<f64>>,
    /// Number of points in each group.
    pub group_sizes: Vec<usize>,
    /// Candidate poses `T_data_model` (model frame → data frame), the paper's reading first.
    pub candidates: Vec<Isometry3<f64>>,
}

/// An observed branch axis (unit, from p'_c) and the size of its group, the weight it gets.
type Observed = (Vector3<f64>, usize);

/// Runs CCP on a data cloud (one object's points). `view` is the direction toward the sensor in
/// the data frame if known; it places the translation on the visible half of the model.
pub fn ccp(
    data: &[Point],
    layout: &BranchLayout,
    model_points: &[Point],
    model_normals: &[Vector3<f64>],
    view: Option<Vector3<f64>>,
    cfg: &CcpConfig,
) -> Result<CcpResult> {
    if layout.directions.len() < 2 {
        return Err(Error::invalid("model", "CCP needs a model with at least two cylindrical branches; declare them (Model branches) or use method=\"ppf\""));
    }
    if data.len() < 10 {
        return Err(Error::TooFewPoints {
            arg: "data".into(),
            got: data.len(),
            needed: 10,
            hint: "; CCP needs the object's points".into(),
        });
    }
    let s = cfg.closer_radius.unwrap_or(1.5 * layout.radius);
    let tau = cfg
        .tau
        .unwrap_or(0.8 * layout.lengths.iter().cloned().fold(f64::INFINITY, f64::min));
    // Eq. 20–21.
    let pc = centroid(data);
    let near: Vec<Point> = data.iter().copied().filter(|p| (p - pc).norm() <= s).collect();
    let pcc = if near.len() >= 3 { centroid(&near) } else { pc };
    let n_end = layout.directions.len() + usize::from(layout.special.is_some());
    let mut endpoints = farthest_endpoints(data, &pcc, n_end, 0.5 * layout.radius);
    let special_endpoint = if layout.special.is_some() && endpoints.len() >= 3 {
        take_special_endpoint(data, &pcc, layout.radius, &mut endpoints)
    } else {
        None
    };
    if endpoints.len() < 2 {
        return Err(Error::NoObjectFound {
            reason: format!(
                "CCP found {} branch endpoint(s); it needs two visible branches",
                endpoints.len()
            ),
        });
    }
    let (axes, group_sizes) = group_axes(data, &pcc, &endpoints, tau);
    let special_dir = special_endpoint.map(|e| (e - pcc).normalize());
    let place = |rot: &UnitQuaternion<f64>| {
        let model_ref = visible_centroid(model_points, model_normals, rot, view);
        Isometry3::from_parts(Translation3::from(pc.coords - rot * model_ref.coords), *rot)
    };
    let candidates: Vec<Isometry3<f64>> = readings(&axes, &group_sizes, special_dir, layout)
        .iter()
        .flat_map(|(obs, sp)| rotations(obs, *sp, layout))
        .map(|r| place(&r))
        .collect();
    if candidates.is_empty() {
        return Err(Error::NoObjectFound {
            reason: "CCP found no branch assignment consistent with the model's layout".into(),
        });
    }
    Ok(CcpResult {
        center: pc,
        closer_center: pcc,
        endpoints,
        special_endpoint,
        axes,
        group_sizes,
        candidates,
    })
}

/// Eq. 22: up to `n` endpoints by farthest-point sampling from p'_c, none nearer than
/// `min_reach` to those taken.
fn farthest_endpoints(data: &[Point], pcc: &Point, n: usize, min_reach: f64) -> Vec<Point> {
    let mut endpoints: Vec<Point> = Vec::with_capacity(n);
    let mut dist: Vec<f64> = data.iter().map(|p| (p - pcc).norm()).collect();
    for _ in 0..n {
        let (i, d) = dist
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, d)| (i, *d))
            .unwrap();
        if d < min_reach {
            break;
        }
        let e = data[i];
        endpoints.push(e);
        for (k, p) in data.iter().enumerate() {
            dist[k] = dist[k].min((p - e).norm());
        }
    }
    endpoints
}

/// Removes and returns the special endpoint: the one farthest from the plane of the points
/// within two branch radii of p'_c (none when too few points are there).
fn take_special_endpoint(data: &[Point], pcc: &Point, radius: f64, endpoints: &mut Vec<Point>) -> Option<Point> {
    let ring: Vec<Point> = data
        .iter()
        .copied()
        .filter(|p| (p - pcc).norm() <= 2.0 * radius)
        .collect();
    if ring.len() < 3 {
        return None;
    }
    let (c, cov) = covariance(&ring);
    let (_, axes) = principal_axes(&cov);
    let n = axes[2];
    let k = (0..endpoints.len())
        .max_by(|&a, &b| {
            (endpoints[a] - c)
                .dot(&n)
                .abs()
                .total_cmp(&(endpoints[b] - c).dot(&n).abs())
        })
        .unwrap();
    Some(endpoints.remove(k))
}

/// Eq. 25–28: each point within τ of an endpoint joins the group whose line p'_c → endpoint it
/// is nearest; the axes run from p'_c to each group's mean, with the groups' sizes.
fn group_axes(data: &[Point], pcc: &Point, endpoints: &[Point], tau: f64) -> (Vec<Vector3<f64>>, Vec<usize>) {
    let mut sums = vec![Vector3::zeros(); endpoints.len()];
    let mut counts = vec![0usize; endpoints.len()];
    for p in data {
        let mut best: Option<(usize, f64)> = None;
        for (g, e) in endpoints.iter().enumerate() {
            if (p - e).norm() >= tau {
                continue;
            }
            let axis = e - pcc;
            let rel = e - p;
            let lambda = (rel - axis * (rel.dot(&axis) / axis.norm_squared())).norm();
            if best.is_none_or(|b| lambda < b.1) {
                best = Some((g, lambda));
            }
        }
        if let Some((g, _)) = best {
            sums[g] += p.coords;
            counts[g] += 1;
        }
    }
    let mut axes = Vec::new();
    let mut group_sizes = Vec::new();
    for (g, e) in endpoints.iter().enumerate() {
        let mean = if counts[g] > 0 {
            Point::from(sums[g] / counts[g] as f64)
        } else {
            *e
        };
        let u = mean - pcc;
        if u.norm() > 1e-9 {
            axes.push(u.normalize());
            group_sizes.push(counts[g].max(1));
        }
    }
    (axes, group_sizes)
}

/// The readings of the observed axes, each a set of axes read as branches and perhaps one as
/// the special feature. First the paper's reading (the special endpoint is the feature, the
/// others are branches); then, because a partial view may hide the feature or show an end face
/// as the farthest point, every subset of two or more axes read as branches, each with every
/// other observed axis as the feature too (the paper's plane test misses it when the part lies
/// on its side).
fn readings(
    axes: &[Vector3<f64>],
    group_sizes: &[usize],
    special_dir: Option<Vector3<f64>>,
    layout: &BranchLayout,
) -> Vec<(Vec<Observed>, Option<Vector3<f64>>)> {
    let observed: Vec<Observed> = axes.iter().copied().zip(group_sizes.iter().copied()).collect();
    let mut all_axes = observed.clone();
    if let Some(d) = special_dir {
        all_axes.push((d, group_sizes.iter().sum::<usize>() / group_sizes.len().max(1)));
    }
    let mut out = Vec::new();
    if special_dir.is_some() && axes.len() >= 2 {
        out.push((observed, special_dir));
    }
    let n = all_axes.len();
    let special_choices: Vec<Option<usize>> = if layout.special.is_some() {
        std::iter::once(None).chain((0..n).map(Some)).collect()
    } else {
        vec![None]
    };
    for special in special_choices {
        for mask in 1u32..(1 << n) {
            if special.is_some_and(|s| mask & (1 << s) != 0)
                || mask.count_ones() < 2
                || mask.count_ones() as usize > layout.directions.len()
            {
                continue;
            }
            let obs: Vec<Observed> = (0..n).filter(|i| mask & (1 << i) != 0).map(|i| all_axes[i]).collect();
            out.push((obs, special.map(|s| all_axes[s].0)));
        }
    }
    out
}

/// The rotations (model → data) of one reading: Kabsch on the axis directions for every
/// injective assignment of the observed axes to the model's branches, dropping those whose
/// fitted branches miss what was seen by more than 50°.
fn rotations(obs: &[Observed], special: Option<Vector3<f64>>, layout: &BranchLayout) -> Vec<UnitQuaternion<f64>> {
    let k = obs.len().min(layout.directions.len());
    let mut out = Vec::new();
    for assignment in injective_maps(k, layout.directions.len()) {
        let mut h = Matrix3::zeros();
        for (o, &m) in assignment.iter().enumerate() {
            h += (obs[o].1 as f64) * layout.directions[m] * obs[o].0.transpose();
        }
        if let (Some(ms), Some(ds)) = (layout.special, special) {
            let w = obs.iter().map(|x| x.1).sum::<usize>() as f64 / obs.len() as f64;
            h += w * ms * ds.transpose();
        }
        let Some(r) = kabsch(&h) else { continue };
        let worst = assignment
            .iter()
            .enumerate()
            .map(|(o, &m)| (r * layout.directions[m]).dot(&obs[o].0))
            .fold(1.0, f64::min);
        if worst < 50f64.to_radians().cos() {
            continue;
        }
        out.push(UnitQuaternion::from_rotation_matrix(&r));
    }
    out
}

/// Centroid of the model points that face the sensor under rotation `rot` (all points if no view).
fn visible_centroid(
    points: &[Point],
    normals: &[Vector3<f64>],
    rot: &UnitQuaternion<f64>,
    view: Option<Vector3<f64>>,
) -> Point {
    match view {
        Some(v) => {
            let v_model = rot.inverse() * v;
            let vis: Vec<Point> = points
                .iter()
                .zip(normals)
                .filter(|(_, n)| n.dot(&v_model) > 0.0)
                .map(|(p, _)| *p)
                .collect();
            if vis.is_empty() {
                centroid(points)
            } else {
                centroid(&vis)
            }
        }
        None => centroid(points),
    }
}

/// All injective maps from `k` observed items into `n` model items.
fn injective_maps(k: usize, n: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    let mut cur = Vec::with_capacity(k);
    fn rec(k: usize, n: usize, cur: &mut Vec<usize>, out: &mut Vec<Vec<usize>>) {
        if cur.len() == k {
            out.push(cur.clone());
            return;
        }
        for j in 0..n {
            if !cur.contains(&j) {
                cur.push(j);
                rec(k, n, cur, out);
                cur.pop();
            }
        }
    }
    rec(k, n, &mut cur, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn injective_maps_count() {
        assert_eq!(injective_maps(3, 3).len(), 6);
        assert_eq!(injective_maps(2, 4).len(), 12);
    }

    #[test]
    fn repeated_parallel_zero_or_nan_branches_are_refused_naming_branches() {
        let tee = |directions: Vec<Vector3<f64>>| BranchLayout {
            lengths: vec![40.0; directions.len()],
            directions,
            radius: 13.0,
            special: Some(Vector3::z()),
        };
        let (x, y) = (Vector3::x(), Vector3::y());
        assert!(tee(vec![x, -x, y]).validate().is_ok());
        for bad in [
            vec![x, x, x],
            vec![x, Vector3::new(1.0, 0.01, 0.0), y],
            vec![x, Vector3::zeros(), y],
            vec![x, Vector3::new(f64::NAN, 0.0, 0.0), y],
            vec![x],
        ] {
            let err = tee(bad.clone()).validate().unwrap_err();
            assert!(err.to_string().starts_with("branches"), "{bad:?}: {err}");
        }
        let mut short = tee(vec![x, -x, y]);
        short.lengths[1] = 0.0;
        assert!(short.validate().is_err());
    }
}
