//! Meshes and their placed instances, and ray casting against them.

use super::*;

pub(super) struct SceneMesh {
    pub(super) shape: parry3d::shape::TriMesh,
    pub(super) aabb: Aabb,
    pub(super) material: Material,
}

#[derive(Clone)]
pub(super) struct Instance {
    pub(super) mesh: usize,
    pub(super) t_base_object: Isometry3<f64>,
    pub(super) id: i32,
}

/// Meshes and their placed instances, in the robot's base frame. Instance ids are the caller's
/// (parts use their pile ids ≥ 0; by convention −2 is the bin and −3 the table); −1 means "no
/// surface" in id images and cannot be used.
#[derive(Default, Clone)]
pub struct Scene {
    pub(super) meshes: Vec<Arc<SceneMesh>>,
    pub(super) instances: Vec<Instance>,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene")
            .field("meshes", &self.meshes.len())
            .field("instances", &self.instances.len())
            .finish()
    }
}

impl Scene {
    /// An empty scene.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a mesh (mm, its own frame) with its material and returns its index. The mesh's BVH
    /// is built once and shared by all its instances.
    pub fn add_mesh(&mut self, mesh: &TriMesh, material: Material) -> Result<usize> {
        if mesh.faces.is_empty() {
            return Err(Error::invalid("faces", "the mesh has no faces"));
        }
        let valid = material.albedo.iter().all(|a| a.is_finite() && (0.0..=1.0).contains(a))
            && material.specular.is_finite()
            && material.specular >= 0.0
            && material.shininess.is_finite()
            && material.shininess > 0.0;
        if !valid {
            return Err(Error::invalid(
                "material",
                "albedo must be in [0, 1], specular ≥ 0 and shininess > 0",
            ));
        }
        let mut m = mesh.clone();
        m.drop_degenerate_faces();
        if m.faces.is_empty() {
            return Err(Error::invalid("faces", "every face of the mesh is degenerate"));
        }
        let verts = m.vertices.iter().map(convert::point_vec).collect();
        let shape = parry3d::shape::TriMesh::new(verts, m.faces)
            .map_err(|e| Error::invalid("mesh", format!("cannot build a ray-casting mesh: {e}")))?;
        let aabb = shape.local_aabb();
        self.meshes.push(Arc::new(SceneMesh { shape, aabb, material }));
        Ok(self.meshes.len() - 1)
    }

    /// Places mesh `mesh` at `t_base_object` under instance id `id`.
    pub fn add_instance(&mut self, mesh: usize, t_base_object: Isometry3<f64>, id: i32) -> Result<()> {
        if mesh >= self.meshes.len() {
            return Err(Error::invalid(
                "mesh",
                format!("no mesh {mesh}; the scene has {}", self.meshes.len()),
            ));
        }
        if id == -1 {
            return Err(Error::invalid("id", "−1 is reserved for 'no surface'; use another id"));
        }
        if self.instances.iter().any(|i| i.id == id) {
            return Err(Error::invalid("id", format!("an instance with id {id} already exists")));
        }
        self.instances.push(Instance {
            mesh,
            t_base_object,
            id,
        });
        Ok(())
    }

    /// Moves instance `id`.
    pub fn set_pose(&mut self, id: i32, t_base_object: Isometry3<f64>) -> Result<()> {
        let inst = self
            .instances
            .iter_mut()
            .find(|i| i.id == id)
            .ok_or_else(|| Error::invalid("id", format!("no instance {id}")))?;
        inst.t_base_object = t_base_object;
        Ok(())
    }

    /// Removes instance `id`.
    pub fn remove_instance(&mut self, id: i32) -> Result<()> {
        let n = self.instances.len();
        self.instances.retain(|i| i.id != id);
        if self.instances.len() == n {
            return Err(Error::invalid("id", format!("no instance {id}")));
        }
        Ok(())
    }

    /// Ids of the placed instances, in insertion order.
    pub fn instance_ids(&self) -> Vec<i32> {
        self.instances.iter().map(|i| i.id).collect()
    }

    /// Distance (mm) from each point (base frame) to the nearest surface of the scene, and the id
    /// of the instance that surface belongs to; `(∞, −1)` in an empty scene. Exact point-to-mesh
    /// distances: the ground truth a reconstructed cloud is measured against.
    pub fn nearest_surface(&self, points: &[Point]) -> Vec<(f64, i32)> {
        let placed = self.placed(&Isometry3::identity());
        points
            .par_iter()
            .map(|p| {
                let mut bounds: Vec<(f64, usize)> = placed
                    .iter()
                    .enumerate()
                    .map(|(k, pl)| (box_distance(p, &pl.lo, &pl.hi), k))
                    .collect();
                bounds.sort_by(|a, b| a.0.total_cmp(&b.0));
                let mut best = (f64::INFINITY, -1);
                for (lower, k) in bounds {
                    if lower >= best.0 {
                        break;
                    }
                    let pl = &placed[k];
                    let local = convert::point_vec(&(pl.t_object_camera * p));
                    // The f32 projection is refined in f64 below; the slack keeps a surface that
                    // is nearer only within f32 rounding from being skipped.
                    let limit = if best.0.is_finite() {
                        best.0 as f32 + 1e-3
                    } else {
                        f32::MAX
                    };
                    if let Some(proj) = pl.mesh.shape.project_local_point_with_max_dist(local, false, limit) {
                        let d = (convert::point(proj.point) - pl.t_object_camera * p).norm();
                        if d < best.0 {
                            best = (d, pl.id);
                        }
                    }
                }
                best
            })
            .collect()
    }

    pub(super) fn placed(&self, t_base_camera: &Isometry3<f64>) -> Vec<Placed> {
        let t_camera_base = t_base_camera.inverse();
        self.instances
            .iter()
            .map(|inst| {
                let mesh = self.meshes[inst.mesh].clone();
                let t_camera_object = t_camera_base * inst.t_base_object;
                let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                for c in mesh.aabb.vertices() {
                    let p = t_camera_object * convert::point(c);
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                Placed {
                    t_object_camera: t_camera_object.inverse(),
                    t_camera_object,
                    lo,
                    hi,
                    id: inst.id,
                    mesh,
                }
            })
            .collect()
    }

    /// Casts one ray per pixel of `camera` at pose `t_base_camera`: the geometry every laser
    /// frame of this robot pose is lit from.
    pub fn view(&self, camera: &Camera, t_base_camera: &Isometry3<f64>, lighting: &Lighting) -> Result<View> {
        let table = pixel_ray_grid(camera)?;
        let placed = self.placed(t_base_camera);
        let (w, h) = (camera.width as usize, camera.height as usize);
        let lamp = (t_base_camera.inverse().rotation * lighting.lamp_direction)
            .try_normalize(1e-12)
            .unwrap_or_else(Vector3::z);
        let ray_at = |u: usize, v: usize| {
            let [x, y] = table[v * w + u];
            Vector3::new(x, y, 1.0)
        };
        let rows: Vec<(Vec<Hit>, Vec<[f32; 3]>)> = (0..h)
            .into_par_iter()
            .map(|v| {
                let mut hits = Vec::with_capacity(w);
                let mut shade = Vec::with_capacity(w);
                for u in 0..w {
                    let dir = ray_at(u, v).normalize();
                    // A pixel whose ray the distortion model cannot give (NaN) sees nothing.
                    let hit = if dir.x.is_finite() {
                        cast(&placed, &Point::origin(), &dir, f64::INFINITY)
                    } else {
                        None
                    };
                    match hit {
                        None => {
                            hits.push(Hit::NONE);
                            let b = lighting.background as f32;
                            shade.push([b, b, b]);
                        }
                        Some((t, mut n, k)) => {
                            if n.dot(&dir) > 0.0 {
                                n = -n;
                            }
                            let p = dir * t;
                            // Where the neighbouring pixels' rays meet the tangent plane: the
                            // surface's footprint, to integrate the line profile over the pixel.
                            let at = |uu: usize, vv: usize| {
                                let rr = ray_at(uu, vv);
                                let den = n.dot(&rr);
                                if den.abs() < 1e-9 {
                                    p
                                } else {
                                    rr * (n.dot(&p) / den)
                                }
                            };
                            let diff = |a: Vector3<f64>, b: Vector3<f64>, span: f64| {
                                let d = (a - b) / span;
                                if d.norm() > 50.0 {
                                    Vector3::zeros()
                                } else {
                                    d
                                }
                            };
                            let (u0, u1) = (u.saturating_sub(1), (u + 1).min(w - 1));
                            let (v0, v1) = (v.saturating_sub(1), (v + 1).min(h - 1));
                            let dpdu = diff(at(u1, v), at(u0, v), (u1 - u0).max(1) as f64);
                            let dpdv = diff(at(u, v1), at(u, v0), (v1 - v0).max(1) as f64);
                            let m = &placed[k].mesh.material;
                            let lit = lighting.ambient + lighting.lamp * n.dot(&lamp).max(0.0);
                            shade.push([
                                (m.albedo[0] * lit) as f32,
                                (m.albedo[1] * lit) as f32,
                                (m.albedo[2] * lit) as f32,
                            ]);
                            hits.push(Hit {
                                t: t as f32,
                                p: f3(&p),
                                n: f3(&n),
                                dpdu: f3(&dpdu),
                                dpdv: f3(&dpdv),
                                id: placed[k].id,
                                placed: k as u32,
                            });
                        }
                    }
                }
                (hits, shade)
            })
            .collect();
        let mut hits = Vec::with_capacity(w * h);
        let mut shade = Vec::with_capacity(w * h);
        for (a, b) in rows {
            hits.extend(a);
            shade.extend(b);
        }
        Ok(View {
            camera: *camera,
            t_base_camera: *t_base_camera,
            placed,
            hits,
            shade,
            sheets: std::sync::Mutex::new(None),
        })
    }
}

pub(super) struct Placed {
    pub(super) mesh: Arc<SceneMesh>,
    pub(super) t_object_camera: Isometry3<f64>,
    pub(super) t_camera_object: Isometry3<f64>,
    pub(super) lo: [f64; 3],
    pub(super) hi: [f64; 3],
    pub(super) id: i32,
}

#[inline]
pub(super) fn f3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

#[inline]
pub(super) fn v3(a: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(a[0] as f64, a[1] as f64, a[2] as f64)
}

/// Distance from a point to an axis-aligned box (0 inside).
#[inline]
pub(super) fn box_distance(p: &Point, lo: &[f64; 3], hi: &[f64; 3]) -> f64 {
    let mut s = 0.0;
    for k in 0..3 {
        let e = (lo[k] - p[k]).max(p[k] - hi[k]).max(0.0);
        s += e * e;
    }
    s.sqrt()
}

/// Entry distance of a ray into a box, if it enters before `max_t`.
#[inline]
pub(super) fn slab(o: &Point, d: &Vector3<f64>, lo: &[f64; 3], hi: &[f64; 3], max_t: f64) -> Option<f64> {
    let (mut t0, mut t1) = (0.0f64, max_t);
    for k in 0..3 {
        let inv = 1.0 / d[k];
        let (mut a, mut b) = ((lo[k] - o[k]) * inv, (hi[k] - o[k]) * inv);
        if a > b {
            std::mem::swap(&mut a, &mut b);
        }
        if a.is_nan() || b.is_nan() {
            if o[k] < lo[k] || o[k] > hi[k] {
                return None;
            }
            continue;
        }
        t0 = t0.max(a);
        t1 = t1.min(b);
        if t0 > t1 {
            return None;
        }
    }
    Some(t0)
}

/// The first surface along a ray (camera frame, unit `dir`) before `max_t`: distance, normal
/// (camera frame, unoriented) and index of the placed instance.
pub(super) fn cast(
    placed: &[Placed],
    origin: &Point,
    dir: &Vector3<f64>,
    max_t: f64,
) -> Option<(f64, Vector3<f64>, usize)> {
    let mut best: Option<(f64, Vector3<f64>, usize)> = None;
    let mut limit = max_t;
    for (k, pl) in placed.iter().enumerate() {
        if slab(origin, dir, &pl.lo, &pl.hi, limit).is_none() {
            continue;
        }
        let o = pl.t_object_camera * origin;
        let d = pl.t_object_camera.rotation * dir;
        let ray = Ray::new(convert::point_vec(&o), convert::vector(&d));
        let lim = if limit.is_finite() { limit as f32 } else { f32::MAX };
        if let Some(hit) = pl.mesh.shape.cast_local_ray_and_get_normal(&ray, lim, true) {
            let t = hit.time_of_impact as f64;
            if t < limit {
                limit = t;
                best = Some((t, pl.t_camera_object.rotation * convert::vector3(hit.normal), k));
            }
        }
    }
    best
}

#[derive(Clone, Copy)]
pub(super) struct Hit {
    pub(super) t: f32,
    pub(super) p: [f32; 3],
    pub(super) n: [f32; 3],
    pub(super) dpdu: [f32; 3],
    pub(super) dpdv: [f32; 3],
    pub(super) id: i32,
    pub(super) placed: u32,
}

impl Hit {
    const NONE: Hit = Hit {
        t: f32::INFINITY,
        p: [0.0; 3],
        n: [0.0; 3],
        dpdu: [0.0; 3],
        dpdv: [0.0; 3],
        id: -1,
        placed: u32::MAX,
    };
}
