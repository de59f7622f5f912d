use super::*;

fn plane_mesh(z: f64, half: f64) -> TriMesh {
    TriMesh {
        vertices: vec![
            Point::new(-half, -half, z),
            Point::new(half, -half, z),
            Point::new(half, half, z),
            Point::new(-half, half, z),
        ],
        faces: vec![[0, 1, 2], [0, 2, 3]],
    }
}

fn small_camera() -> Camera {
    Camera {
        width: 160,
        height: 120,
        fx: 200.0,
        fy: 200.0,
        cx: 79.5,
        cy: 59.5,
        skew: 0.0,
        dist: [0.0; 5],
    }
}

#[test]
fn depth_of_a_plane_is_its_distance() {
    let mut scene = Scene::new();
    let m = scene.add_mesh(&plane_mesh(0.0, 1000.0), Material::default()).unwrap();
    scene
        .add_instance(m, Isometry3::translation(0.0, 0.0, 400.0), 5)
        .unwrap();
    let view = scene
        .view(&small_camera(), &Isometry3::identity(), &Lighting::default())
        .unwrap();
    let depth = view.depth();
    assert!(depth.iter().all(|d| (d - 400.0).abs() < 1e-3), "{:?}", &depth[..4]);
    assert!(view.ids().iter().all(|&i| i == 5));
}

#[test]
fn laser_line_lands_where_the_sheet_meets_the_plane() {
    let mut scene = Scene::new();
    let m = scene
        .add_mesh(
            &plane_mesh(0.0, 1000.0),
            Material {
                albedo: [0.8; 3],
                ..Default::default()
            },
        )
        .unwrap();
    scene
        .add_instance(m, Isometry3::translation(0.0, 0.0, 500.0), 0)
        .unwrap();
    let cam = small_camera();
    let view = scene.view(&cam, &Isometry3::identity(), &Lighting::default()).unwrap();
    let laser = Laser {
        sheet_sigma: 1.5,
        power: 150.0,
        ..Default::default()
    };
    let on = view.frame(&laser, 0.02, &SensorNoise::none(), 1).unwrap();
    let off = view
        .frame(
            &Laser {
                power: 0.0,
                ..laser.clone()
            },
            0.02,
            &SensorNoise::none(),
            1,
        )
        .unwrap();
    // The sheet x_L = 0 meets z = 500 along a line of constant camera x (the laser's y axis is
    // the camera's); find it and compare with the red centroid of the middle row.
    let t = laser.t_camera_laser(0.02);
    let (o, xl) = (t.translation.vector, t.rotation * Vector3::x());
    // x such that xl · ((x, 0, 500) − o) = 0
    let x = (xl.dot(&o) - xl.z * 500.0) / xl.x;
    let u_expected = cam.fx * x / 500.0 + cam.cx;
    let row = 60;
    let (mut s, mut sw) = (0.0, 0.0);
    for u in 0..cam.width as usize {
        let i = (row * cam.width as usize + u) * 3;
        let e = on[i] as f64 - off[i] as f64;
        s += e * u as f64;
        sw += e;
    }
    assert!(sw > 100.0, "the line is missing");
    assert!((s / sw - u_expected).abs() < 0.05, "{} vs {u_expected}", s / sw);
}

#[test]
fn nearest_surface_is_the_exact_mesh_distance() {
    let mut scene = Scene::new();
    assert_eq!(scene.nearest_surface(&[Point::origin()]), vec![(f64::INFINITY, -1)]);
    let m = scene.add_mesh(&plane_mesh(0.0, 100.0), Material::default()).unwrap();
    scene
        .add_instance(m, Isometry3::translation(400.0, 0.0, 0.0), 7)
        .unwrap();
    scene
        .add_instance(m, Isometry3::translation(400.0, 0.0, 30.0), 8)
        .unwrap();
    let got = scene.nearest_surface(&[
        Point::new(410.0, 5.0, 3.25),
        Point::new(390.0, 0.0, 20.0),
        Point::new(650.0, 0.0, 0.0),
    ]);
    assert_eq!((got[0].1, got[1].1, got[2].1), (7, 8, 7));
    assert!(
        (got[0].0 - 3.25).abs() < 1e-4 && (got[1].0 - 10.0).abs() < 1e-4 && (got[2].0 - 150.0).abs() < 1e-3,
        "{got:?}"
    );
}

#[test]
fn an_occluder_casts_a_laser_shadow() {
    let mut scene = Scene::new();
    let floor = scene.add_mesh(&plane_mesh(0.0, 1000.0), Material::default()).unwrap();
    scene
        .add_instance(floor, Isometry3::translation(0.0, 0.0, 500.0), 0)
        .unwrap();
    let cam = small_camera();
    let laser = Laser {
        sheet_sigma: 1.0,
        ..Default::default()
    };
    let clear = scene
        .view(&cam, &Isometry3::identity(), &Lighting::default())
        .unwrap()
        .frame(&laser, 0.0, &SensorNoise::none(), 0)
        .unwrap();
    // A small plate in front of the projector, out of the camera's view, hides the line.
    let block = scene.add_mesh(&plane_mesh(0.0, 10.0), Material::default()).unwrap();
    let t = laser.t_camera_laser(0.0);
    scene
        .add_instance(
            block,
            Isometry3::from_parts(
                (t.translation.vector + t.rotation * Vector3::new(0.0, 0.0, 30.0)).into(),
                t.rotation,
            ),
            1,
        )
        .unwrap();
    let shadowed = scene
        .view(&cam, &Isometry3::identity(), &Lighting::default())
        .unwrap()
        .frame(&laser, 0.0, &SensorNoise::none(), 0)
        .unwrap();
    let red = |img: &[u8]| img.chunks(3).map(|p| p[0] as u64).sum::<u64>();
    assert!(
        red(&clear) > red(&shadowed) + 1000,
        "{} {}",
        red(&clear),
        red(&shadowed)
    );
}

/// A camera with a realistic lens (barrel distortion moving the corners by about 8 px,
/// decentring terms) and a skew term: what the renderer and triangulation must agree on.
fn distorted_skewed_camera() -> Camera {
    Camera {
        width: 320,
        height: 240,
        fx: 410.0,
        fy: 405.0,
        cx: 161.3,
        cy: 118.7,
        skew: 1.7,
        dist: [-0.12, 0.08, 0.001, -0.0007, -0.01],
    }
}

#[test]
fn renderer_and_triangulation_share_one_camera_model() {
    let cam = distorted_skewed_camera();
    // A large flat plate, tilted, filling the view.
    let t_camera_plate = Isometry3::new(Vector3::new(20.0, -10.0, 450.0), Vector3::new(0.3, -0.2, 0.1));
    let mut scene = Scene::new();
    let m = scene.add_mesh(&plane_mesh(0.0, 3000.0), Material::default()).unwrap();
    scene.add_instance(m, t_camera_plate, 1).unwrap();
    let view = scene.view(&cam, &Isometry3::identity(), &Lighting::default()).unwrap();
    let points = view.points();
    let normal = t_camera_plate.rotation * Vector3::z();
    let plane = crate::Plane {
        normal,
        offset: normal.dot(&t_camera_plate.translation.vector),
    };
    let w = cam.width as usize;
    let pixels: Vec<[f64; 2]> = (0..points.len()).map(|i| [(i % w) as f64, (i / w) as f64]).collect();
    let rays = crate::pixel_rays(&cam, &pixels).unwrap();
    let table = crate::RayTable::shared(&cam);
    let (mut worst_px, mut worst_mm) = (0.0f64, 0.0f64);
    for ((p, &[u, v]), ray) in points.iter().zip(&pixels).zip(&rays) {
        let rendered = Point::new(p[0] as f64, p[1] as f64, p[2] as f64);
        assert!(rendered.z.is_finite(), "pixel ({u}, {v}) missed the plate");
        // (a) The rendered surface point projects back to its pixel's centre.
        let [pu, pv] = cam.project(&rendered).unwrap();
        worst_px = worst_px.max((pu - u).hypot(pv - v));
        // (b) The pixel's ray, as triangulation undistorts it (exactly and through the ray
        // table the scan path uses), meets the known plane at the rendered point.
        for r in [ray.unwrap(), table.ray(u, v).unwrap()] {
            let q = crate::intersect_ray_plane(&r, &plane).unwrap();
            worst_mm = worst_mm.max((q - rendered).norm());
        }
    }
    eprintln!("render vs camera model: worst reprojection {worst_px:.2e} px, worst triangulation {worst_mm:.2e} mm");
    assert!(worst_px < 0.05, "worst reprojection {worst_px} px");
    assert!(worst_mm < 0.05, "worst triangulation {worst_mm} mm");
}

#[test]
fn the_sheet_index_lights_exactly_the_pixels_trying_every_one_would() {
    // A tilted floor (the sheet's reach differs across it), a glossy plate standing almost
    // edge-on (wide reaches, a laser shadow, reflections), speckle: each frame the index gives
    // is the frame of every pixel tried, and of a view that has drawn no frame before.
    let mut scene = Scene::new();
    let floor = scene.add_mesh(&plane_mesh(0.0, 1000.0), Material::default()).unwrap();
    scene
        .add_instance(
            floor,
            Isometry3::translation(0.0, 0.0, 500.0) * Isometry3::rotation(Vector3::x() * 0.3),
            0,
        )
        .unwrap();
    let glossy = Material {
        specular: 0.6,
        ..Default::default()
    };
    let plate = scene.add_mesh(&plane_mesh(0.0, 40.0), glossy).unwrap();
    scene
        .add_instance(
            plate,
            Isometry3::translation(10.0, 5.0, 450.0) * Isometry3::rotation(Vector3::y() * 1.4),
            1,
        )
        .unwrap();
    let view = scene
        .view(&small_camera(), &Isometry3::identity(), &Lighting::default())
        .unwrap();
    let laser = Laser::default();
    let noise = SensorNoise {
        reflections: 0.5,
        ..Default::default()
    };
    for (k, theta) in [-0.3, -0.12, -0.05, 0.0, 0.07, 0.2].into_iter().enumerate() {
        let indexed = view.frame(&laser, theta, &noise, k as u64).unwrap();
        let every = view.frame_trying(&laser, theta, &noise, k as u64, Some(())).unwrap();
        let lit = every
            .iter()
            .zip(view.ambient_frame(&noise, 99).unwrap().iter())
            .filter(|(a, b)| a > b)
            .count();
        assert!(lit > 0);
        assert!(indexed == every, "angle {theta}: the index missed or added lit pixels");
        // The laser shadows the view keeps from the frames before are the shadows this frame
        // finds on a view that has drawn no other.
        let alone = scene
            .view(&small_camera(), &Isometry3::identity(), &Lighting::default())
            .unwrap()
            .frame(&laser, theta, &noise, k as u64)
            .unwrap();
        assert!(
            indexed == alone,
            "angle {theta}: a shadow kept from another frame is wrong"
        );
    }
}

#[test]
fn pixel_noise_has_the_read_and_shot_noise_asked_for_and_rows_do_not_repeat() {
    // A flat grey image: the noise's mean, spread and row-to-row independence as asked for.
    let (w, h) = (400usize, 200usize);
    let level = 100.0f32;
    let img = vec![[level; 3]; w * h];
    for (read, shot) in [(2.0, 0.0), (1.0, 0.09)] {
        let noise = SensorNoise {
            read_noise: read,
            shot_noise: shot,
            ..SensorNoise::none()
        };
        let out = view::quantise(&img, w, &noise, 7, 11, 0..usize::MAX);
        let values: Vec<f64> = out.iter().map(|&v| v as f64).collect();
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
        // The variance asked for, plus a twelfth for the rounding to whole levels.
        let want = read * read + shot * level as f64 + 1.0 / 12.0;
        assert!((mean - level as f64).abs() < 0.02, "mean {mean}");
        assert!((var / want - 1.0).abs() < 0.02, "variance {var}, want {want}");
        // Neighbouring rows are drawn from their own seeds: uncorrelated.
        let row = 3 * w;
        let cov = values[..n as usize - row]
            .iter()
            .zip(&values[row..])
            .map(|(a, b)| (a - mean) * (b - mean))
            .sum::<f64>()
            / (n - row as f64);
        assert!((cov / var).abs() < 0.01, "row-to-row correlation {}", cov / var);
    }
}
