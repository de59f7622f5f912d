use super::groups::*;
use super::*;
use crate::mesh::sample::{sample_surface, Density};
use crate::mesh::TriMesh;

type Mesh = (Vec<Point>, Vec<[u32; 3]>);

fn cuboid(half: [f64; 3], offset: V3) -> Mesh {
    let h = V3::from(half);
    let m = crate::mesh::test_box(Point::from(offset - h), Point::from(offset + h));
    (m.vertices, m.faces)
}

/// A right prism over a regular `sides`-gon with a vertex on +x, axis z, centred at the origin.
fn prism(sides: usize, radius: f64, half_height: f64) -> Mesh {
    let polygon: Vec<(f64, f64)> = (0..sides)
        .map(|k| TAU * k as f64 / sides as f64)
        .map(|a| (radius * a.cos(), radius * a.sin()))
        .collect();
    prism_over(&polygon, half_height)
}

/// A right prism over a convex counter-clockwise `polygon` around the origin, axis z, centred
/// at the origin.
fn prism_over(polygon: &[(f64, f64)], half_height: f64) -> Mesh {
    let mut v = vec![Point::new(0.0, 0.0, -half_height), Point::new(0.0, 0.0, half_height)];
    for z in [-half_height, half_height] {
        v.extend(polygon.iter().map(|&(x, y)| Point::new(x, y, z)));
    }
    let n = polygon.len() as u32;
    let (b, t) = (|k: u32| 2 + k % n, |k: u32| 2 + n + k % n);
    let mut f = Vec::new();
    for k in 0..n {
        f.push([0, b(k + 1), b(k)]);
        f.push([1, t(k), t(k + 1)]);
        f.push([b(k), b(k + 1), t(k + 1)]);
        f.push([b(k), t(k + 1), t(k)]);
    }
    (v, f)
}

fn merge(meshes: &[Mesh]) -> Mesh {
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for (mv, mf) in meshes {
        let base = v.len() as u32;
        v.extend_from_slice(mv);
        f.extend(mf.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }
    (v, f)
}

/// The part posed in its model frame by a seeded rotation and translation, sampled evenly.
struct Case {
    sym: Symmetries,
    pose: Isometry3<f64>,
}

fn detect(mesh: Mesh, spacing: f64, seed: u64) -> Case {
    let mut rng = Rng::new(seed);
    let pose = Isometry3::from_parts(
        Translation3::new(
            rng.range(-100.0, 100.0),
            rng.range(-100.0, 100.0),
            rng.range(-100.0, 100.0),
        ),
        rng.rotation(),
    );
    let mesh = TriMesh::new(mesh.0.iter().map(|p| pose.transform_point(p)).collect(), mesh.1).unwrap();
    assert!(mesh.volume() > 0.0);
    let s = sample_surface(&mesh, Density::Spacing(spacing), seed).unwrap();
    let sym = detect_symmetries(&s.points, &s.normals, &SymmetryConfig::default()).unwrap();
    Case { sym, pose }
}

/// The detected group equals `expected` (in the part's own frame), element by element within 1°.
fn assert_group(case: &Case, expected: &[Rot]) {
    let q = case.pose.rotation;
    let got = &case.sym.rotations;
    assert_eq!(got.len(), expected.len(), "group size; got {got:?}");
    assert!(got[0].angle() < 1e-12, "identity first");
    for e in expected {
        let e = q * e * q.inverse();
        let best = got.iter().map(|g| g.angle_to(&e)).fold(f64::INFINITY, f64::min);
        assert!(
            best < 1f64.to_radians(),
            "missing {:?} by {:.3}°",
            e.axis_angle(),
            best.to_degrees()
        );
    }
    // Exactly closed: every product is an element to rounding.
    for a in got {
        for b in got {
            let p = a * b;
            assert!(got.iter().any(|g| g.angle_to(&p) < 1e-9));
        }
    }
}

fn dihedral(n: usize) -> Vec<Rot> {
    let spins: Vec<Rot> = (0..n).map(|k| rot(&V3::z(), TAU * k as f64 / n as f64)).collect();
    let flip = rot(&V3::x(), PI);
    spins.iter().copied().chain(spins.iter().map(|s| s * flip)).collect()
}

fn random_pose(rng: &mut Rng) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(
            rng.range(-500.0, 500.0),
            rng.range(-500.0, 500.0),
            rng.range(0.0, 800.0),
        ),
        rng.rotation(),
    )
}

fn assert_same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>) {
    assert!(
        a.rotation.angle_to(&b.rotation) < 1e-9,
        "rotations differ by {:e}",
        a.rotation.angle_to(&b.rotation)
    );
    assert!((a.translation.vector - b.translation.vector).norm() < 1e-7);
}

/// `canonical` is the same for T and T·S, and `pose_error` of T·S against T is zero, for every
/// symmetry S (plus, with a continuous axis, turns by random angles); a 3° perturbation about
/// the centre reads as 3° (at most 3° with a continuous axis, where other turns may come closer).
fn check_poses(sym: &Symmetries, seed: u64) {
    let mut rng = Rng::new(seed);
    let mut all = sym.transforms(0.3);
    if let Some(a) = sym.continuous_axis {
        for r in &sym.rotations {
            for _ in 0..20 {
                all.push(sym.about_center(&(r * rot(&a, rng.range(-PI, PI)))));
            }
        }
    }
    for _ in 0..5 {
        let t = random_pose(&mut rng);
        let canon = sym.canonical(&t);
        assert!(canon.rotation.angle() <= t.rotation.angle() + 1e-12);
        let wobble = sym.about_center(&rot(
            &V3::new(rng.normal(), rng.normal(), rng.normal()),
            3f64.to_radians(),
        ));
        for s in &all {
            let ts = t * s;
            assert_same_pose(&sym.canonical(&ts), &canon);
            let (r, d) = sym.pose_error(&ts, &t);
            assert!(r < 1e-7 && d < 1e-6, "error {r} rad, {d} mm");
            let (r, _) = sym.pose_error(&(ts * wobble), &t);
            if sym.continuous_axis.is_some() {
                assert!(r <= 3f64.to_radians() + 1e-9);
            } else {
                assert!((r - 3f64.to_radians()).abs() < 1e-9, "{}", r.to_degrees());
            }
        }
    }
}

#[test]
fn box_with_three_sides_has_the_d2_group() {
    let case = detect(cuboid([30.0, 20.0, 12.0], V3::zeros()), 1.8, 1);
    assert!(case.sym.continuous_axis.is_none());
    assert_group(
        &case,
        &[Rot::identity(), rot(&V3::x(), PI), rot(&V3::y(), PI), rot(&V3::z(), PI)],
    );
    assert!(
        (case.sym.center - case.pose.translation.vector).coords.norm() < 0.3,
        "{:?}",
        case.sym.center
    );
    check_poses(&case.sym, 11);
}

#[test]
fn square_prism_has_the_d4_group() {
    let case = detect(prism(4, 20.0 * 2f64.sqrt(), 35.0), 2.2, 2);
    assert_group(&case, &dihedral(4));
    assert!((case.sym.center - case.pose.translation.vector).coords.norm() < 0.3);
    check_poses(&case.sym, 12);
}

#[test]
fn hexagonal_prism_has_the_d6_group() {
    let case = detect(prism(6, 25.0, 25.0), 1.8, 3);
    assert_group(&case, &dihedral(6));
    assert!((case.sym.center - case.pose.translation.vector).coords.norm() < 0.3);
    check_poses(&case.sym, 13);
}

#[test]
fn cylinder_has_a_continuous_axis_and_a_flip() {
    let case = detect(prism(128, 20.0, 30.0), 1.8, 4);
    let sym = &case.sym;
    let axis = sym.continuous_axis.expect("continuous axis");
    let z = case.pose.rotation * V3::z();
    assert!(same_line(&axis, &z, 1f64.to_radians()), "axis {axis:?}, expected {z:?}");
    assert_eq!(sym.rotations.len(), 2);
    let flip = sym.rotations[1];
    assert!((flip.angle() - PI).abs() < 1e-9 && flip.axis().unwrap().dot(&axis).abs() < 1e-9);
    assert_eq!(sym.order(), None);
    assert!((sym.center - case.pose.translation.vector).coords.norm() < 0.3);
    assert_eq!(sym.transforms(TAU / 90.0).len(), 180);
    check_poses(sym, 14);
}

#[test]
fn cube_has_the_octahedral_group() {
    let case = detect(cuboid([20.0; 3], V3::zeros()), 1.8, 5);
    assert_group(&case, &octahedral().0);
    check_poses(&case.sym, 15);
}

#[test]
fn box_with_an_off_centre_bump_is_asymmetric() {
    let part = merge(&[
        cuboid([30.0, 20.0, 12.0], V3::zeros()),
        cuboid([6.0, 6.0, 3.5], V3::new(14.0, 7.0, 15.0)),
    ]);
    let case = detect(part, 1.8, 6);
    let sym = &case.sym;
    assert!(sym.is_trivial(), "{sym:?}");
    assert_eq!(sym.order(), Some(1));
    let mut rng = Rng::new(16);
    for _ in 0..20 {
        let (est, truth) = (random_pose(&mut rng), random_pose(&mut rng));
        let (r, d) = sym.pose_error(&est, &truth);
        assert!((r - est.rotation.angle_to(&truth.rotation)).abs() < 1e-12);
        assert!((d - (est.translation.vector - truth.translation.vector).norm()).abs() < 1e-9);
        assert_same_pose(&sym.canonical(&est), &est);
    }
}

/// A convex polyhedron from its vertices: every triple at the edge length whose plane has all
/// vertices on one side, wound outward.
fn polyhedron(v: Vec<Point>, edge: f64) -> Mesh {
    let n = v.len();
    let is_edge = |i: usize, j: usize| ((v[i] - v[j]).norm() - edge).abs() < 1e-9;
    let mut f = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                if is_edge(i, j) && is_edge(j, k) && is_edge(i, k) {
                    let normal = (v[j] - v[i]).cross(&(v[k] - v[i]));
                    let t = if normal.dot(&(v[i].coords)) > 0.0 {
                        [i, j, k]
                    } else {
                        [i, k, j]
                    };
                    f.push(t.map(|x| x as u32));
                }
            }
        }
    }
    (v, f)
}

#[test]
fn tetrahedron_has_the_tetrahedral_group() {
    let s = 18.0;
    let v = [(1.0, 1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0)]
        .map(|(x, y, z)| Point::new(s * x, s * y, s * z));
    let mesh = polyhedron(v.to_vec(), s * 8f64.sqrt());
    assert_eq!(mesh.1.len(), 4);
    let case = detect(mesh, 1.8, 7);
    assert_group(&case, &tetrahedral().0);
    check_poses(&case.sym, 17);
}

#[test]
fn icosahedron_has_the_icosahedral_group() {
    let (s, phi) = (14.0, (1.0 + 5f64.sqrt()) / 2.0);
    let mut v = Vec::new();
    for a in [-1.0, 1.0] {
        for b in [-phi, phi] {
            v.extend([
                Point::new(0.0, s * a, s * b),
                Point::new(s * a, s * b, 0.0),
                Point::new(s * b, 0.0, s * a),
            ]);
        }
    }
    let mesh = polyhedron(v, 2.0 * s);
    assert_eq!(mesh.1.len(), 20);
    let case = detect(mesh, 1.8, 8);
    assert_group(&case, &icosahedral()[0].0);
    check_poses(&case.sym, 18);
}

#[test]
fn a_centred_boss_leaves_a_cyclic_group() {
    // A square prism with a square boss centred on one end keeps only its 4-fold turns.
    let part = merge(&[
        prism(4, 20.0 * 2f64.sqrt(), 35.0),
        cuboid([6.0, 6.0, 3.5], V3::new(0.0, 0.0, 38.0)),
    ]);
    let case = detect(part, 2.2, 9);
    assert_group(
        &case,
        &(0..4).map(|k| rot(&V3::z(), TAU * k as f64 / 4.0)).collect::<Vec<_>>(),
    );
    check_poses(&case.sym, 19);
}

#[test]
fn independent_uniform_samples_work_with_the_default_tolerance() {
    let mut rng = Rng::new(10);
    let pose = Isometry3::from_parts(Translation3::new(5.0, 6.0, 7.0), rng.rotation());
    let (v, f) = prism(4, 20.0 * 2f64.sqrt(), 35.0);
    let mesh = TriMesh::new(v.iter().map(|p| pose.transform_point(p)).collect(), f).unwrap();
    let s = sample_surface(&mesh, Density::Count(3000), 10).unwrap();
    let sym = detect_symmetries(&s.points, &s.normals, &SymmetryConfig::default()).unwrap();
    assert_group(&Case { sym, pose }, &dihedral(4));
}

#[test]
fn standard_groups_are_complete() {
    assert_eq!(tetrahedral().0.len(), 12);
    assert_eq!(octahedral().0.len(), 24);
    let ico = icosahedral();
    assert_eq!(ico.len(), 2);
    assert!(ico.iter().all(|g| g.0.len() == 60));
}

#[test]
fn bad_input_is_rejected() {
    let (v, f) = cuboid([30.0, 20.0, 12.0], V3::zeros());
    let s = sample_surface(&TriMesh::new(v, f).unwrap(), Density::Spacing(3.0), 1).unwrap();
    let cfg = SymmetryConfig::default();
    assert!(matches!(
        detect_symmetries(&s.points[..10], &s.normals[..10], &cfg),
        Err(Error::TooFewPoints { .. })
    ));
    assert!(matches!(
        detect_symmetries(&s.points, &s.normals[1..], &cfg),
        Err(Error::InvalidInput { .. })
    ));
    let mut zero = s.normals.clone();
    zero[3] = V3::zeros();
    assert!(matches!(
        detect_symmetries(&s.points, &zero, &cfg),
        Err(Error::InvalidInput { .. })
    ));
    for bad in [
        SymmetryConfig {
            tolerance: Some(-1.0),
            ..cfg
        },
        SymmetryConfig {
            min_agreement: 0.0,
            ..cfg
        },
        SymmetryConfig { max_order: 1, ..cfg },
        SymmetryConfig { max_points: 10, ..cfg },
    ] {
        assert!(
            matches!(
                detect_symmetries(&s.points, &s.normals, &bad),
                Err(Error::InvalidInput { .. })
            ),
            "{bad:?}"
        );
    }
    let none = Symmetries::none(Point::new(1.0, 2.0, 3.0));
    assert!(none.is_trivial());
    assert_eq!(none.transforms(0.1).len(), 1);
}

/// How many of the feature samples of `n` lie within `radius` of `centre` or of its image
/// under the turn.
fn samples_at(n: &NearSymmetry, centre: V3, radius: f64) -> usize {
    let image = n.transform(0.0) * Point::from(centre);
    n.feature
        .iter()
        .filter(|p| (p.coords - centre).norm() < radius || (*p - image).norm() < radius)
        .count()
}

/// Near-symmetries of `mesh` (sampled every `spacing` mm), with its proper group.
fn near_of(mesh: Mesh, spacing: f64) -> (Symmetries, Vec<NearSymmetry>) {
    let mesh = TriMesh::new(mesh.0, mesh.1).unwrap();
    let s = sample_surface(&mesh, Density::Spacing(spacing), 3).unwrap();
    let cfg = SymmetryConfig::default();
    let sym = detect_symmetries(&s.points, &s.normals, &cfg).unwrap();
    let near = detect_near_symmetries(&s.points, &s.normals, &sym, &cfg).unwrap();
    (sym, near)
}

#[test]
fn a_block_with_a_boss_has_its_three_half_turns_as_near_symmetries_broken_at_the_boss() {
    // 60 × 40 × 20 mm block with a 12 × 12 × 3 mm boss on top near one corner.
    let boss_centre = V3::new(20.0, 12.0, 11.5);
    let block = merge(&[
        cuboid([30.0, 20.0, 10.0], V3::zeros()),
        cuboid([6.0, 6.0, 1.5], boss_centre),
    ]);
    let (sym, near) = near_of(block, 1.0);
    assert!(sym.is_trivial(), "the boss breaks every symmetry: {sym:?}");
    assert_eq!(near.len(), 3, "{near:?}");
    for n in &near {
        let angle = n.angle.expect("discrete");
        assert!((angle - PI).abs() < 2f64.to_radians(), "half turns, got {angle}");
        assert!([V3::x(), V3::y(), V3::z()].iter().any(|a| n.axis.dot(a).abs() > 0.999));
        assert!(n.agreement >= NEAR_AGREEMENT && n.agreement < 0.98, "{}", n.agreement);
        // The feature is the boss and the place it maps to: near the boss or its image.
        let near_boss = samples_at(n, boss_centre, 9.0);
        assert!(
            near_boss as f64 > 0.9 * n.feature.len() as f64,
            "{near_boss} of {}",
            n.feature.len()
        );
    }
}

#[test]
fn a_shaft_with_a_flat_has_a_continuous_near_axis_and_a_plain_shaft_none() {
    // A 48-gon shaft, radius 10 mm, 80 mm long, round within the tolerance; with a 3 mm flat
    // key on its side it is round no more.
    let shaft = prism(48, 10.0, 40.0);
    let (sym, near) = near_of(shaft.clone(), 1.0);
    assert!(sym.continuous_axis.is_some());
    assert!(
        near.iter().all(|n| n.angle.is_some()),
        "no continuous near axis: {near:?}"
    );
    let keyed = merge(&[shaft, cuboid([1.5, 2.0, 30.0], V3::new(10.5, 0.0, 0.0))]);
    let (sym, near) = near_of(keyed, 1.0);
    assert!(sym.continuous_axis.is_none(), "{sym:?}");
    let cont = near.iter().find(|n| n.angle.is_none()).expect("a continuous near axis");
    assert!(cont.axis.z.abs() > 0.999);
    assert!(!cont.feature.is_empty());
    // The feature is the key, but for a few samples at sampling gaps.
    let off = cont.feature.iter().filter(|p| p.x <= 5.0).count();
    assert!(
        off * 50 <= cont.feature.len(),
        "{off} of {} off the key",
        cont.feature.len()
    );
}

#[test]
fn a_feature_smaller_than_the_agreement_allows_still_breaks_the_symmetries_it_moves() {
    // A 100 × 100 × 6 mm plate: a 4 × 4 × 2 mm boss near one corner of its top is 0.2 % of the
    // surface, under the 2 % an agreement of 98 % lets pass, but a patch a scan shows plainly.
    let plate = cuboid([50.0, 50.0, 3.0], V3::zeros());
    let boss_centre = V3::new(40.0, 40.0, 4.0);
    let (sym, near) = near_of(plate.clone(), 1.0);
    assert_eq!(
        sym.rotations.len(),
        8,
        "the plain plate keeps its square's group: {sym:?}"
    );
    assert!(near.iter().all(|n| n.agreement < 0.98), "{near:?}");
    let bossed = merge(&[plate, cuboid([2.0, 2.0, 1.0], boss_centre)]);
    let (sym, near) = near_of(bossed, 1.0);
    assert!(sym.is_trivial(), "the boss breaks every turn of the square: {sym:?}");
    // The square's seven turns are near-symmetries, each mapping all but the boss.
    let square: Vec<&NearSymmetry> = near.iter().filter(|n| n.agreement >= 0.98).collect();
    assert_eq!(square.len(), 7, "{near:?}");
    for n in square {
        let at_boss = samples_at(n, boss_centre, 6.0);
        assert!(
            at_boss >= 8,
            "{at_boss} of {} feature samples at the boss",
            n.feature.len()
        );
    }
}

#[test]
fn a_flat_that_its_own_displaced_centre_halves_still_breaks_the_half_turn_about_the_axis() {
    // A 60 mm shaft of radius 6 mm with a flat 1 mm deep along its whole length (a D-shaft),
    // sampled every 0.8 mm (a tolerance of about 0.65 mm). Its only symmetry is the half turn
    // about the flat's normal (x). A half turn about the shaft's axis, about a centre the flat
    // displaced by 0.2 mm, puts the flat about 0.6 mm from the round side and passed at the full
    // tolerance; the turns about the axis are near-symmetries, broken along the flat.
    let polygon: Vec<(f64, f64)> = (0..120)
        .map(|k| TAU * k as f64 / 120.0)
        .map(|a| ((6.0 * a.cos()).min(5.0), 6.0 * a.sin()))
        .fold(Vec::new(), |mut p: Vec<(f64, f64)>, q| {
            if p.last().is_none_or(|l| (l.0 - q.0).abs() + (l.1 - q.1).abs() > 1e-9) {
                p.push(q);
            }
            p
        });
    let (sym, near) = near_of(prism_over(&polygon, 30.0), 0.8);
    assert_eq!(sym.rotations.len(), 2, "{sym:?}");
    let flip = sym.rotations[1];
    assert!(
        (flip.angle() - PI).abs() < 1e-6 && flip.axis().unwrap().x.abs() > 0.999,
        "{flip:?}"
    );
    let turn = near
        .iter()
        .filter(|n| n.angle.is_some_and(|a| a > 0.5 * PI) && n.axis.z.abs() > 0.999)
        .max_by(|a, b| a.agreement.total_cmp(&b.agreement))
        .expect("a turn about the axis is a near-symmetry");
    let on_flat = turn.feature.iter().filter(|p| p.x.abs() > 4.5).count();
    assert!(
        on_flat >= 8 && on_flat * 2 >= turn.feature.len(),
        "{on_flat} of {} feature samples on the flat or its image",
        turn.feature.len()
    );
}

#[test]
fn a_coarsely_tessellated_round_keeps_its_continuous_axis() {
    // A 12-sided cylinder 30 mm across: its facets lie up to 0.51 mm inside the circle, within
    // the tolerance (about 0.53 mm at these samples) but not within half of it. A turn about the
    // axis maps facets between each other's vertices; it is still the round it stands for.
    let (sym, near) = near_of(prism(12, 15.0, 25.0), 0.66);
    assert!(sym.continuous_axis.is_some_and(|a| a.z.abs() > 0.999), "{sym:?}");
    assert_eq!(sym.rotations.len(), 2, "{sym:?}");
    assert!(near.iter().all(|n| n.angle.is_some()), "{near:?}");
}

#[test]
fn detecting_both_at_once_gives_what_the_two_detections_give() {
    let plate = merge(&[
        cuboid([50.0, 50.0, 3.0], V3::zeros()),
        cuboid([2.0, 2.0, 1.0], V3::new(40.0, 40.0, 4.0)),
    ]);
    let keyed = merge(&[prism(48, 10.0, 40.0), cuboid([1.5, 2.0, 30.0], V3::new(10.5, 0.0, 0.0))]);
    for mesh in [plate, keyed] {
        let mesh = TriMesh::new(mesh.0, mesh.1).unwrap();
        let s = sample_surface(&mesh, Density::Spacing(1.0), 3).unwrap();
        let cfg = SymmetryConfig::default();
        let (sym, near) = detect_all_symmetries(&s.points, &s.normals, &cfg).unwrap();
        let alone = detect_symmetries(&s.points, &s.normals, &cfg).unwrap();
        assert_eq!(sym, alone);
        let apart = detect_near_symmetries(&s.points, &s.normals, &alone, &cfg).unwrap();
        assert!(!near.is_empty());
        assert_eq!(near, apart);
    }
}
