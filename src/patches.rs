//! [`Patches`]: surfaces meshed for radiosity. Each surface's triangles
//! become root elements (pairs of triangles forming a parallelogram become
//! one quad; other triangles stay triangles), subdivided in two across the
//! longest side until no edge exceeds the target size. The leaves are the
//! patches; the tree above them is the hierarchy hierarchical radiosity
//! links at. Leaf corners are shared vertices (welded per surface) so that
//! radiosity can be interpolated across patches.

use std::collections::HashMap;

use glam::{DVec2, DVec3};

use crate::geometry::Triangle;

/// A planar element's shape in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    Tri([DVec3; 3]),
    /// The parallelogram origin, origin+u, origin+u+v, origin+v.
    Quad {
        origin: DVec3,
        u: DVec3,
        v: DVec3,
    },
}

impl Shape {
    /// The corners in order (3 or 4), without allocating.
    pub fn corners(&self) -> Corners {
        match *self {
            Shape::Tri([a, b, c]) => Corners {
                points: [a, b, c, c],
                len: 3,
            },
            Shape::Quad { origin, u, v } => Corners {
                points: [origin, origin + u, origin + u + v, origin + v],
                len: 4,
            },
        }
    }

    /// `x`'s parameters (s, t) on the shape's plane: origin + s·u + t·v
    /// for a quad, a + s·(b − a) + t·(c − a) for a triangle.
    pub fn params(&self, x: DVec3) -> DVec2 {
        match *self {
            Shape::Quad { origin, u, v } => split::plane_params(x - origin, u, v),
            Shape::Tri([a, b, c]) => split::plane_params(x - a, b - a, c - a),
        }
    }

    /// Smallest and largest coordinates.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let c = self.corners();
        crate::geometry::bounds(c.iter().copied())
    }

    pub fn area(&self) -> f64 {
        match *self {
            Shape::Tri([a, b, c]) => 0.5 * (b - a).cross(c - a).length(),
            Shape::Quad { u, v, .. } => u.cross(v).length(),
        }
    }

    pub fn centre(&self) -> DVec3 {
        match *self {
            Shape::Tri([a, b, c]) => (a + b + c) / 3.0,
            Shape::Quad { origin, u, v } => origin + 0.5 * (u + v),
        }
    }

    pub fn normal(&self) -> DVec3 {
        match *self {
            Shape::Tri([a, b, c]) => (b - a).cross(c - a).normalize(),
            Shape::Quad { u, v, .. } => u.cross(v).normalize(),
        }
    }

    /// The longest edge (for quads, the longer side).
    pub fn size(&self) -> f64 {
        match *self {
            Shape::Tri([a, b, c]) => (b - a).length().max((c - b).length()).max((a - c).length()),
            Shape::Quad { u, v, .. } => u.length().max(v.length()),
        }
    }

    /// A composite rule for integrands that peak inside the shape (a lamp
    /// close to it): the shape split into m×m parts, each with 2×2 Gauss
    /// points (triangles: the centroids of a 2m×2m split); weights sum to 1.
    /// `m` = 1 is [`Shape::quadrature`] of order 2.
    pub(crate) fn split_quadrature(&self, m: usize) -> Vec<(DVec3, f64)> {
        let m = m.max(1);
        match *self {
            Shape::Quad { origin, u, v } if m > 1 => {
                let (du, dv) = (u / m as f64, v / m as f64);
                let cell = Shape::Quad {
                    origin,
                    u: du,
                    v: dv,
                }
                .quadrature(2);
                let w = 1.0 / (m * m) as f64;
                let mut out = Vec::with_capacity(4 * m * m);
                for i in 0..m {
                    for j in 0..m {
                        let shift = du * i as f64 + dv * j as f64;
                        out.extend(cell.iter().map(|(x, cw)| (*x + shift, cw * w)));
                    }
                }
                out
            }
            _ => self.quadrature(if m > 1 { 2 * m } else { 2 }),
        }
    }

    /// Quadrature of order `n`: points with weights summing to 1. Quads:
    /// n×n Gauss-Legendre; triangles: centroids of an n×n regular split.
    pub fn quadrature(&self, n: usize) -> Vec<(DVec3, f64)> {
        let mut out = Vec::with_capacity(n.max(1) * n.max(1));
        self.for_each_quadrature_point(n, |x, w| out.push((x, w)));
        out
    }

    /// [`Shape::quadrature`]'s points and weights, in its order, handed
    /// to `f` one at a time: the links' refinement integrates millions of
    /// form factors, and a list each was a tenth of their time.
    pub fn for_each_quadrature_point(&self, n: usize, mut f: impl FnMut(DVec3, f64)) {
        let n = n.max(1);
        match *self {
            Shape::Quad { origin, u, v } => {
                // The table stops at order 16.
                let (x, w) = gauss_legendre(n);
                let n = x.len();
                for i in 0..n {
                    for j in 0..n {
                        f(origin + u * x[i] + v * x[j], w[i] * w[j]);
                    }
                }
            }
            Shape::Tri([a, b, c]) => {
                let (e1, e2) = (b - a, c - a);
                let w = 1.0 / (n * n) as f64;
                let k = n as f64;
                for i in 0..n {
                    for j in 0..n - i {
                        let (fi, fj) = (i as f64, j as f64);
                        f(
                            a + e1 * ((fi + 1.0 / 3.0) / k) + e2 * ((fj + 1.0 / 3.0) / k),
                            w,
                        );
                        if i + j + 1 < n {
                            f(
                                a + e1 * ((fi + 2.0 / 3.0) / k) + e2 * ((fj + 2.0 / 3.0) / k),
                                w,
                            );
                        }
                    }
                }
            }
        }
    }
}

/// Closed surfaces with more triangles than this and no consistent
/// winding are treated as two-sided.
pub(crate) const MAX_SOLID_TRIANGLES: usize = 20_000;

/// An element's 3 or 4 corners.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corners {
    points: [DVec3; 4],
    len: usize,
}

impl std::ops::Deref for Corners {
    type Target = [DVec3];
    fn deref(&self) -> &[DVec3] {
        &self.points[..self.len]
    }
}

/// Gauss-Legendre nodes on [0, 1] and weights summing to 1, tabulated
/// once for orders up to 16.
pub(crate) fn gauss_legendre(n: usize) -> (&'static [f64], &'static [f64]) {
    static TABLE: std::sync::OnceLock<Vec<(Vec<f64>, Vec<f64>)>> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| (0..=16).map(compute_gauss_legendre).collect());
    let (x, w) = &table[n.min(16)];
    (x, w)
}

fn compute_gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n {
        // Newton on P_n from the Chebyshev guess.
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, z);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * z * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (z * p1 - p0) / (z * z - 1.0);
            let dz = p1 / dp;
            z -= dz;
            if dz.abs() < 1e-15 {
                break;
            }
        }
        x[i] = 0.5 * (1.0 - z);
        w[i] = 1.0 / ((1.0 - z * z) * dp * dp);
    }
    (x, w)
}

/// Where an element lies inside its root, in the root's parameters:
/// quads (s, t) ∈ \[0,1\]², triangles barycentric-style (s, t) with s+t ≤ 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Region {
    Quad { s0: f64, s1: f64, t0: f64, t1: f64 },
    Tri([DVec2; 3]),
}

/// One node of the element hierarchy, its fields in this order
/// (`repr(C)`): locating a point reads `children` and `region` of each
/// element on its way down, which then share a cache line (the order also
/// leaves no padding).
#[derive(Debug, Clone, PartialEq)]
#[repr(C)]
pub struct Element {
    pub children: Option<[u32; 2]>,
    /// Patch index when this element is a leaf.
    pub patch: Option<u32>,
    pub root: u32,
    pub region: Region,
    pub shape: Shape,
    /// The shape's box and size ([`Shape::bounds`], [`Shape::size`]), kept:
    /// shaft tests ask for them for every candidate occluder.
    pub bounds: (DVec3, DVec3),
    pub size: f64,
    pub area: f64,
    pub centre: DVec3,
    pub normal: DVec3,
    pub surface: u32,
    pub parent: Option<u32>,
    /// On a closed surface (a solid): light leaves and arrives on the
    /// outside only, and `normal` points out. Open surfaces are two-sided.
    pub one_sided: bool,
}

/// Input: one surface's triangles, with the id the tracer knows it by.
pub struct SurfaceInput<'a> {
    pub surface: u32,
    pub triangles: &'a [Triangle],
    pub is_virtual: bool,
}

/// A point located on a patch, with interpolation weights on its vertices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location {
    pub patch: u32,
    /// (vertex, weight) pairs; weights sum to 1. Triangles use three.
    pub weights: [(u32, f64); 4],
}

/// The meshed scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Patches {
    pub elements: Vec<Element>,
    pub roots: Vec<u32>,
    /// Element index of each patch (leaf).
    pub patches: Vec<u32>,
    /// Shared vertex positions.
    pub vertices: Vec<DVec3>,
    /// Vertices of each patch in corner order (triangles repeat none: 3 used).
    pub patch_vertices: Vec<[u32; 4]>,
    /// Per surface id: whether it is virtual, and its triangles' roots.
    pub surface_is_virtual: crate::util::FastMap<u32, bool>,
    /// Root element of each triangle, by surface id and triangle (dense:
    /// a lookup per ray hit, where a hashed pair cost as much as the descent).
    root_of_triangle: Vec<Vec<u32>>,
    /// Per patch, a textured object's albedo there (None: the surface's
    /// own reflectance; see [`ObjectMeshes`]).
    pub(crate) albedo: Vec<Option<glam::Vec3>>,
    /// Per patch of an object meshed coarser than its triangles
    /// ([`proxy`]), the triangle of its surface its direct light is
    /// sampled on (none for every other patch).
    pub(crate) surface_samples: crate::util::FastMap<u32, Shape>,
}

impl Patches {
    /// The polygon of every root element of a real surface.
    pub fn real_root_polygons(&self) -> Vec<Vec<DVec3>> {
        self.roots
            .iter()
            .filter(|&&r| !self.is_virtual_element(r))
            .map(|&r| self.elements[r as usize].shape.corners().to_vec())
            .collect()
    }

    /// Whether element `e` lies on a virtual object.
    pub(crate) fn is_virtual_element(&self, e: u32) -> bool {
        self.is_virtual_surface(self.elements[e as usize].surface)
    }

    /// Whether surface `s` is a virtual object's (a surface not meshed here is not).
    pub fn is_virtual_surface(&self, s: u32) -> bool {
        self.surface_is_virtual.get(&s).copied().unwrap_or(false)
    }

    /// Meshes a scene's real surfaces, and with `with_virtual` its enabled
    /// virtual objects after them (real patches come first and are the same
    /// either way).
    pub fn of_scene(scene: &crate::scene::Scene, with_virtual: bool, target_size: f64) -> Patches {
        Self::of_scene_with(scene, with_virtual, target_size, target_size)
    }

    /// [`Patches::of_scene`] with its own patch size for the virtual objects.
    /// Open surfaces face the camera: the photo shows that side, and a
    /// single radiosity for both sides would pass light through walls.
    pub fn of_scene_with(
        scene: &crate::scene::Scene,
        with_virtual: bool,
        target_size: f64,
        virtual_size: f64,
    ) -> Patches {
        let mut p = Self::of_scene_two_sided(scene, with_virtual, target_size, virtual_size);
        p.face_open_surfaces_towards(scene.camera.position);
        p
    }

    /// [`Patches::of_scene_with`] (with the virtual objects) from the
    /// room's own mesh, `room` = `of_scene(scene, false, target_size)`:
    /// its part is the same, so it is copied rather than meshed again, and
    /// the objects' meshes `meshes` keeps are moved rather than meshed (an
    /// update meshes no object it has meshed before).
    pub fn of_scene_from_room(
        room: &Patches,
        scene: &crate::scene::Scene,
        virtual_size: f64,
        meshes: &mut ObjectMeshes,
    ) -> Patches {
        let mut p = room.clone();
        p.append_objects(scene, virtual_size, meshes);
        p.face_open_surfaces_towards(scene.camera.position);
        p
    }

    /// [`Patches::of_scene_with`] with the real leaves in `marks` split once
    /// more (the meshes are otherwise identical: same roots, same order).
    pub(crate) fn of_scene_refined(
        scene: &crate::scene::Scene,
        with_virtual: bool,
        target_size: f64,
        (virtual_size, coarse_from): (f64, Option<usize>),
        marks: &SplitMarks,
    ) -> Patches {
        let objects = (virtual_size, coarse_from);
        let mut p =
            Self::of_scene_two_sided_marked(scene, with_virtual, target_size, objects, marks);
        p.face_open_surfaces_towards(scene.camera.position);
        p
    }

    fn of_scene_two_sided(
        scene: &crate::scene::Scene,
        with_virtual: bool,
        target_size: f64,
        virtual_size: f64,
    ) -> Patches {
        Self::of_scene_two_sided_marked(
            scene,
            with_virtual,
            target_size,
            (virtual_size, None),
            &SplitMarks::new(),
        )
    }

    fn of_scene_two_sided_marked(
        scene: &crate::scene::Scene,
        with_virtual: bool,
        target_size: f64,
        (virtual_size, coarse_from): (f64, Option<usize>),
        marks: &SplitMarks,
    ) -> Patches {
        let inputs: Vec<SurfaceInput> = scene
            .surfaces
            .iter()
            .enumerate()
            .map(|(i, s)| SurfaceInput {
                surface: i as u32,
                triangles: &s.triangles,
                is_virtual: false,
            })
            .collect();
        let mut p = Patches::build(&[], target_size);
        p.append_marked(&inputs, target_size, marks);
        if with_virtual {
            let mut meshes = ObjectMeshes::new(false).coarse_from(coarse_from);
            p.append_objects(scene, virtual_size, &mut meshes);
        }
        p
    }

    /// Meshes the surfaces with leaves no larger than `target_size` metres.
    pub fn build(inputs: &[SurfaceInput], target_size: f64) -> Patches {
        let mut p = Patches {
            elements: Vec::new(),
            roots: Vec::new(),
            patches: Vec::new(),
            vertices: Vec::new(),
            patch_vertices: Vec::new(),
            surface_is_virtual: crate::util::fast_map(),
            root_of_triangle: Vec::new(),
            albedo: Vec::new(),
            surface_samples: crate::util::fast_map(),
        };
        p.append(inputs, target_size);
        p
    }

    /// Makes every element of an open (two-sided) surface one-sided, facing
    /// the half-space that holds `eye`; elements seen edge-on stay two-sided.
    pub(crate) fn face_open_surfaces_towards(&mut self, eye: DVec3) {
        for root in self.roots.clone() {
            let el = &self.elements[root as usize];
            if el.one_sided {
                continue;
            }
            let side = (eye - el.centre).dot(el.normal);
            if side.abs() <= 1e-9 * (eye - el.centre).length() {
                continue;
            }
            let normal = if side > 0.0 { el.normal } else { -el.normal };
            let mut stack = vec![root];
            while let Some(e) = stack.pop() {
                let el = &mut self.elements[e as usize];
                el.normal = normal;
                el.one_sided = true;
                if let Some(children) = el.children {
                    stack.extend(children);
                }
            }
        }
    }

    /// Meshes more surfaces into this mesh, after what it holds.
    pub(crate) fn append(&mut self, inputs: &[SurfaceInput], target_size: f64) {
        self.append_marked(inputs, target_size, &SplitMarks::new());
    }

    /// [`Patches::append`], splitting further every element that holds a
    /// marked leaf (its root and centre) and is at least as large.
    fn append_marked(&mut self, inputs: &[SurfaceInput], target_size: f64, marks: &SplitMarks) {
        let mut weld: crate::util::FastMap<(u32, [i64; 4], [i64; 3]), u32> =
            crate::util::fast_map();
        for input in inputs {
            self.surface_is_virtual
                .insert(input.surface, input.is_virtual);
            // A closed surface is a solid: its faces are one-sided, facing
            // out, or light would bounce around inside it. A consistent
            // winding orients every face by one parity test, linear in the
            // triangles; without one each face takes its own, so only a
            // small solid is oriented that way (a large one stays two-sided).
            let watertight = crate::geometry::is_closed(input.triangles);
            let outward = watertight
                .then(|| crate::geometry::consistent_winding(input.triangles))
                .flatten();
            let closed =
                watertight && (outward.is_some() || input.triangles.len() <= MAX_SOLID_TRIANGLES);
            for (shape, tris) in primitives(input.triangles) {
                let root = self.elements.len() as u32;
                let region = match shape {
                    Shape::Quad { .. } => Region::Quad {
                        s0: 0.0,
                        s1: 1.0,
                        t0: 0.0,
                        t1: 1.0,
                    },
                    Shape::Tri(_) => Region::Tri([DVec2::ZERO, DVec2::X, DVec2::Y]),
                };
                self.push_element(shape, input.surface, root, None, region);
                if closed {
                    let el = &mut self.elements[root as usize];
                    let inward = match (outward, tris.first()) {
                        (Some(out), Some(&t)) => {
                            let [a, b, c] = input.triangles[t as usize].map(|v| v.as_dvec3());
                            ((b - a).cross(c - a).dot(el.normal) > 0.0) != out
                        }
                        _ => {
                            let step = 1e-4 * el.shape.size().max(1e-3);
                            crate::geometry::encloses(input.triangles, el.centre + el.normal * step)
                        }
                    };
                    if inward {
                        el.normal = -el.normal;
                    }
                    el.one_sided = true;
                }
                self.roots.push(root);
                for t in tris {
                    let surface = input.surface as usize;
                    if self.root_of_triangle.len() <= surface {
                        self.root_of_triangle.resize(surface + 1, Vec::new());
                    }
                    let of = &mut self.root_of_triangle[surface];
                    if of.len() <= t as usize {
                        of.resize(t as usize + 1, u32::MAX);
                    }
                    of[t as usize] = root;
                }
                let ordinal = self.roots.len() as u32 - 1;
                self.subdivide(
                    root,
                    target_size,
                    0,
                    &mut weld,
                    marks.get(&ordinal).map_or(&[][..], |m| &m[..]),
                );
            }
        }
    }

    fn push_element(
        &mut self,
        shape: Shape,
        surface: u32,
        root: u32,
        parent: Option<u32>,
        region: Region,
    ) -> u32 {
        // Children face the way their parent faces.
        let (normal, one_sided) = match parent {
            Some(p) => (
                self.elements[p as usize].normal,
                self.elements[p as usize].one_sided,
            ),
            None => (shape.normal(), false),
        };
        self.elements.push(Element {
            bounds: shape.bounds(),
            size: shape.size(),
            area: shape.area(),
            centre: shape.centre(),
            normal,
            one_sided,
            shape,
            surface,
            root,
            parent,
            children: None,
            patch: None,
            region,
        });
        (self.elements.len() - 1) as u32
    }

    fn subdivide(
        &mut self,
        e: u32,
        target: f64,
        depth: u32,
        weld: &mut crate::util::FastMap<(u32, [i64; 4], [i64; 3]), u32>,
        marks: &[(DVec2, f64)],
    ) {
        let el = self.elements[e as usize].clone();
        let size = el.shape.size();
        let marked = || {
            marks.iter().any(|(st, s)| {
                size >= s * (1.0 - 1e-9) && distance_outside(&el.region, *st) <= 1e-12
            })
        };
        if (size <= target && !marked()) || depth >= 40 {
            let patch = self.patches.len() as u32;
            self.patches.push(e);
            self.albedo.push(None);
            self.elements[e as usize].patch = Some(patch);
            let mut ids = [u32::MAX; 4];
            // Vertices are shared within a plane only: a solid's edge joins
            // faces that face different ways and see different light.
            let n = el.shape.normal();
            let n = if n.x.abs() > 1e-9 {
                n * n.x.signum()
            } else if n.y.abs() > 1e-9 {
                n * n.y.signum()
            } else {
                n * n.z.signum()
            };
            let plane = [n.x, n.y, n.z, n.dot(el.centre)].map(|v| (v * 1e4).round() as i64);
            for (k, c) in el.shape.corners().iter().enumerate() {
                let key = (
                    el.surface,
                    plane,
                    (*c * 1e6).round().as_i64vec3().to_array(),
                );
                let next = self.vertices.len() as u32;
                ids[k] = *weld.entry(key).or_insert(next);
                if ids[k] == next {
                    self.vertices.push(*c);
                }
            }
            self.patch_vertices.push(ids);
            return;
        }
        let halves = split(el.shape, el.region);
        let a = self.push_element(halves[0].0, el.surface, el.root, Some(e), halves[0].1);
        let b = self.push_element(halves[1].0, el.surface, el.root, Some(e), halves[1].1);
        self.elements[e as usize].children = Some([a, b]);
        self.subdivide(a, target, depth + 1, weld, marks);
        self.subdivide(b, target, depth + 1, weld, marks);
    }

    pub fn patch_count(&self) -> usize {
        self.patches.len()
    }

    pub fn patch(&self, k: usize) -> &Element {
        &self.elements[self.patches[k] as usize]
    }

    /// The shape patch `k`'s direct light is sampled on: its own, or its
    /// surface's triangle under it ([`Patches::surface_samples`]).
    pub(crate) fn sample_shape(&self, k: usize) -> &Shape {
        (self.surface_samples.get(&(k as u32))).unwrap_or(&self.patch(k).shape)
    }

    /// The patch under world point `x` of triangle `triangle` of `surface`
    /// (as the tracer reports them), with interpolation weights.
    pub fn locate(&self, surface: u32, triangle: u32, x: DVec3) -> Option<Location> {
        let root = self.root_of(surface, triangle)?;
        Some(self.locate_in_root(root, x))
    }

    /// A root element's place in `roots` (the same in every mesh of a scene).
    pub(crate) fn root_ordinal(&self, root: u32) -> u32 {
        self.roots.binary_search(&root).expect("a root element") as u32
    }

    /// The root element holding triangle `triangle` of `surface`.
    pub(crate) fn root_of(&self, surface: u32, triangle: u32) -> Option<u32> {
        self.root_of_triangle
            .get(surface as usize)?
            .get(triangle as usize)
            .copied()
            .filter(|&r| r != u32::MAX)
    }

    /// `x`'s parameters (s, t) in root element `root`.
    pub(crate) fn root_params(&self, root: u32, x: DVec3) -> DVec2 {
        match self.elements[root as usize].shape {
            Shape::Quad { origin, u, v } => plane_params(x - origin, u, v),
            Shape::Tri([a, b, c]) => plane_params(x - a, b - a, c - a),
        }
    }

    /// The world point at parameters `st` of root element `root`.
    pub(crate) fn root_point(&self, root: u32, st: DVec2) -> DVec3 {
        match self.elements[root as usize].shape {
            Shape::Quad { origin, u, v } => origin + u * st.x + v * st.y,
            Shape::Tri([a, b, c]) => a + (b - a) * st.x + (c - a) * st.y,
        }
    }

    /// The leaf of root `root` under world point `x` (in its plane).
    pub(crate) fn locate_in_root(&self, root: u32, x: DVec3) -> Location {
        let st = self.root_params(root, x);
        let mut e = root;
        // Within a quad root (nearly every point), a halved quad's point lies
        // in the half on its side of the cut: the same choice the distances
        // below make, as the distance across the cut is then exactly zero.
        let in_quad = matches!(self.elements[root as usize].region, Region::Quad { .. })
            && st.cmpge(DVec2::ZERO).all()
            && st.cmple(DVec2::ONE).all();
        // Within a triangle root (a rough model's walls pair into no
        // parallelograms), a halved triangle's point lies on its side of
        // the cut from the long edge's midpoint to the opposite corner: a
        // sign, where the distances below take two barycentric solves (a
        // tenth of an update's work on `lounge`). They differ only for a
        // point within rounding of the cut, which lies on both halves.
        // (Asked only of a root that was split: most of an object's are not.)
        let root_el = &self.elements[root as usize];
        let in_tri = match root_el.region {
            Region::Tri(q) if root_el.children.is_some() => {
                barycentric(st, q).iter().all(|w| *w >= 0.0)
            }
            _ => false,
        };
        // The parent's region carried down: each level reads the element
        // it reaches and its first child.
        let mut rp = &self.elements[e as usize].region;
        while let Some([a, b]) = self.elements[e as usize].children {
            let ra = &self.elements[a as usize].region;
            if let (true, Region::Quad { s1, t1, .. }, Region::Quad { s1: ps1, .. }) =
                (in_quad, ra, rp)
            {
                let in_a = match *s1 != *ps1 {
                    true => st.x <= *s1,
                    false => st.y <= *t1,
                };
                (e, rp) = match in_a {
                    true => (a, ra),
                    false => (b, &self.elements[b as usize].region),
                };
                continue;
            }
            if let (true, Region::Tri([corner, m, apex])) = (in_tri, ra) {
                let side = |x: DVec2| (*apex - *m).perp_dot(x - *m);
                let s = side(st);
                (e, rp) = match s == 0.0 || (s > 0.0) == (side(*corner) > 0.0) {
                    true => (a, ra),
                    false => (b, &self.elements[b as usize].region),
                };
                continue;
            }
            // Inside a: a, whatever b's distance (the same choice, one test fewer).
            let da = distance_outside(ra, st);
            let rb = &self.elements[b as usize].region;
            (e, rp) = match da == 0.0 || da <= distance_outside(rb, st) {
                true => (a, ra),
                false => (b, rb),
            };
        }
        let el = &self.elements[e as usize];
        let patch = el.patch.expect("leaves are patches");
        let ids = self.patch_vertices[patch as usize];
        let weights = match el.region {
            Region::Quad { s0, s1, t0, t1 } => {
                let a = ((st.x - s0) / (s1 - s0)).clamp(0.0, 1.0);
                let b = ((st.y - t0) / (t1 - t0)).clamp(0.0, 1.0);
                [
                    (ids[0], (1.0 - a) * (1.0 - b)),
                    (ids[1], a * (1.0 - b)),
                    (ids[2], a * b),
                    (ids[3], (1.0 - a) * b),
                ]
            }
            Region::Tri(q) => {
                let l = barycentric(st, q).map(|w| w.max(0.0));
                let sum = (l[0] + l[1] + l[2]).max(1e-300);
                [
                    (ids[0], l[0] / sum),
                    (ids[1], l[1] / sum),
                    (ids[2], l[2] / sum),
                    (ids[0], 0.0),
                ]
            }
        };
        Location { patch, weights }
    }

    /// Per-vertex values: the area-weighted mean of the patches sharing the vertex.
    pub(crate) fn vertex_values(&self, patch_values: &[DVec3]) -> Vec<DVec3> {
        let mut sum = vec![DVec3::ZERO; self.vertices.len()];
        let mut weight = vec![0.0; self.vertices.len()];
        for (k, ids) in self.patch_vertices.iter().enumerate() {
            let a = self.patch(k).area;
            let n = if matches!(self.patch(k).shape, Shape::Tri(_)) {
                3
            } else {
                4
            };
            for &v in &ids[..n] {
                sum[v as usize] += patch_values[k] * a;
                weight[v as usize] += a;
            }
        }
        sum.iter()
            .zip(&weight)
            .map(|(s, w)| if *w > 0.0 { *s / *w } else { DVec3::ZERO })
            .collect()
    }

    /// Interpolates vertex values at a located point.
    pub(crate) fn interpolate(&self, vertex_values: &[DVec3], at: &Location) -> DVec3 {
        at.weights
            .iter()
            .map(|&(v, w)| vertex_values[v as usize] * w)
            .sum()
    }
}

mod albedo;
mod objects;
mod proxy;
mod split;

pub use objects::ObjectMeshes;

pub use split::split;
use split::*;
pub(crate) use split::{SplitMarks, distance_outside, region_centre};

#[cfg(test)]
mod tests;
