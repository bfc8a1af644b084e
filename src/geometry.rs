//! Triangle geometry: [`Mesh`] (named surfaces of triangles) loaded from OBJ
//! files, with degenerate and non-finite triangles dropped and counted.
//!
//! OBJ parsing is `tobj`'s; a pre-pass checks each line first so that a
//! malformed file is reported with its line number (tobj reports only a kind).

use std::path::Path;

use glam::{DVec3, Vec3};

use crate::error::{Error, Result};

mod formats;
mod gltf_material;
mod obj_material;
pub use formats::load_mesh;

/// A triangle's three corners, in metres.
pub(crate) type Triangle = [Vec3; 3];

/// One named surface of an OBJ file (an `o` or `g` group).
#[derive(Debug, Clone)]
pub struct MeshSurface {
    pub name: String,
    pub triangles: Vec<Triangle>,
    /// The diffuse colour (`Kd`) of the group's material, when the OBJ has one.
    pub material_rgb: Option<Vec3>,
    /// A material with more than a diffuse colour (any glTF material; an
    /// OBJ material with `Ks`, `Ns`, `Pr`, `Pm` or `map_Kd`).
    pub material: Option<std::sync::Arc<crate::materials::Material>>,
    /// Per-triangle normals and texture coordinates, aligned with `triangles`.
    pub attributes: crate::materials::Attributes,
}

/// The surfaces of one OBJ file, in order of first appearance.
#[derive(Debug, Clone)]
pub struct Mesh {
    pub surfaces: Vec<MeshSurface>,
    /// Triangles dropped because they had zero area or non-finite corners.
    pub dropped_triangles: usize,
    /// Materials the surfaces use whose texture (`map_Kd`) or specular part
    /// (`Ks` above 0) a real surface does not use, by name.
    pub unused_material_parts: Vec<String>,
    /// What the file's materials ask that arlux reads but cannot honour
    /// (glTF extensions such as transmission or clearcoat, a second set of
    /// texture coordinates, …), each once, by name.
    pub unsupported: Vec<String>,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.surfaces.iter().map(|s| s.triangles.len()).sum()
    }
}

/// Twice the area of a triangle, in f64 so that small triangles far from the
/// origin do not lose their area to rounding.
pub(crate) fn double_area(t: &Triangle) -> f64 {
    let [a, b, c] = t.map(|p| p.as_dvec3());
    (b - a).cross(c - a).length()
}

/// A triangle with non-finite corners, or with (relatively) zero area.
pub(crate) fn is_degenerate(t: &Triangle) -> bool {
    if !t.iter().all(|p| p.is_finite()) {
        return true;
    }
    let [a, b, c] = t.map(|p| p.as_dvec3());
    let longest = (b - a)
        .length_squared()
        .max((c - a).length_squared())
        .max((c - b).length_squared());
    longest == 0.0 || double_area(t) <= 1e-9 * longest
}

/// Unit geometric normal of a non-degenerate triangle (winding order decides
/// the sign; surfaces are two-sided, so callers orient it as they need).
pub fn normal(t: &Triangle) -> DVec3 {
    let [a, b, c] = t.map(|p| p.as_dvec3());
    (b - a).cross(c - a).normalize_or_zero()
}

/// Normal bins per cube face side ([`normal_bin`]): about 22° wide.
const BIN_SIDE: usize = 4;

/// The cube-map cell of unit direction `n`: faces of similar normal share
/// one (the face clusters of Willmott, Heckbert & Garland 1999).
pub(crate) fn normal_bin(n: DVec3) -> usize {
    let a = n.abs();
    let (face, u, v, m) = if a.x >= a.y && a.x >= a.z {
        (usize::from(n.x < 0.0), n.y, n.z, a.x)
    } else if a.y >= a.z {
        (2 + usize::from(n.y < 0.0), n.x, n.z, a.y)
    } else {
        (4 + usize::from(n.z < 0.0), n.x, n.y, a.z)
    };
    let cell =
        |t: f64| (((t / m.max(1e-300) + 1.0) / 2.0 * BIN_SIDE as f64) as usize).min(BIN_SIDE - 1);
    face * BIN_SIDE * BIN_SIDE + cell(u) * BIN_SIDE + cell(v)
}

/// Barycentric weights of `x`, projected on the plane of a, b, c (outside
/// the triangle some are negative; a degenerate triangle gives a's).
pub(crate) fn barycentric(a: DVec3, b: DVec3, c: DVec3, x: DVec3) -> [f64; 3] {
    let (e1, e2, p) = (b - a, c - a, x - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (p1, p2) = (p.dot(e1), p.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det.abs() <= 1e-300 {
        return [1.0, 0.0, 0.0];
    }
    let u = (d22 * p1 - d12 * p2) / det;
    let v = (d11 * p2 - d12 * p1) / det;
    [1.0 - u - v, u, v]
}

/// Distance from `p` to the closest point of triangle `t` (Ericson,
/// Real-Time Collision Detection §5.1.5), in f64.
pub(crate) fn distance_to_triangle(p: DVec3, t: &Triangle) -> f64 {
    let [a, b, c] = t.map(|v| v.as_dvec3());
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + ab * v)).length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).length();
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (p - (a + ab * v + ac * w)).length()
}

/// Whether the triangles close a volume: after welding corners that coincide,
/// every edge is shared by an even number of triangles.
pub(crate) fn is_closed(triangles: &[Triangle]) -> bool {
    let key = |p: Vec3| (p * 1e5).round().as_ivec3().to_array();
    let mut edges: crate::util::FastMap<([i32; 3], [i32; 3]), u32> = crate::util::fast_map();
    for t in triangles {
        for i in 0..3 {
            let (a, b) = (key(t[i]), key(t[(i + 1) % 3]));
            *edges
                .entry(if a < b { (a, b) } else { (b, a) })
                .or_default() += 1;
        }
    }
    !edges.is_empty() && edges.values().all(|n| n % 2 == 0)
}

/// Whether a closed surface's triangles all wind outwards (Some(true)) or
/// all inwards (Some(false)); None when their winding is not consistent
/// (an edge crossed twice the same way). One parity test then orients
/// every face, where a test per face cost O(n²) (80 ms for a
/// 2,000-triangle chair, at every move).
pub(crate) fn consistent_winding(triangles: &[Triangle]) -> Option<bool> {
    let key = |p: Vec3| (p * 1e5).round().as_ivec3().to_array();
    let mut edges: crate::util::FastMap<([i32; 3], [i32; 3]), i32> = crate::util::fast_map();
    for t in triangles {
        for i in 0..3 {
            let (a, b) = (key(t[i]), key(t[(i + 1) % 3]));
            if a != b {
                let (k, d) = if a < b { ((a, b), 1) } else { ((b, a), -1) };
                *edges.entry(k).or_default() += d;
            }
        }
    }
    if edges.is_empty() || edges.values().any(|n| *n != 0) {
        return None;
    }
    // Voted over the three largest faces: a sliver could mislead one test.
    let mut order: Vec<(f64, DVec3, DVec3)> = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| v.as_dvec3());
            let n = (b - a).cross(c - a);
            (n.length(), (a + b + c) / 3.0, n.normalize_or_zero())
        })
        .collect();
    order.sort_by(|x, y| y.0.total_cmp(&x.0));
    let votes = order
        .iter()
        .take(3)
        .filter(|(area, centre, n)| {
            let step = 1e-4 * area.sqrt().max(1e-3);
            !encloses(triangles, *centre + *n * step)
        })
        .count();
    Some(2 * votes > order.len().min(3))
}

/// Whether `p` lies inside the closed volume bounded by `triangles`, by the
/// parity of ray crossings, voted over three skew directions so that a ray
/// grazing an edge cannot decide alone.
pub(crate) fn encloses(triangles: &[Triangle], p: DVec3) -> bool {
    let dirs = [
        DVec3::new(0.5773, 0.5774, 0.5775),
        DVec3::new(-0.6123, 0.3536, 0.7072),
        DVec3::new(0.2673, -0.8018, 0.5345),
    ];
    let inside_votes = dirs
        .iter()
        .filter(|d| {
            let crossings = triangles
                .iter()
                .filter(|t| ray_hits_triangle(p, d.normalize(), t))
                .count();
            crossings % 2 == 1
        })
        .count();
    inside_votes >= 2
}

/// Möller-Trumbore in f64, for geometric checks outside the tracer.
fn ray_hits_triangle(o: DVec3, d: DVec3, t: &Triangle) -> bool {
    ray_triangle(o, d, t).is_some()
}

/// Where the ray from `o` along `d` meets triangle `t` (Möller-Trumbore in
/// f64): its parameter, in units of `d`, when in front of `o`.
pub(crate) fn ray_triangle(o: DVec3, d: DVec3, t: &Triangle) -> Option<f64> {
    let [a, b, c] = t.map(|v| v.as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-14 {
        return None;
    }
    let inv = 1.0 / det;
    let tv = o - a;
    let u = tv.dot(pv) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = tv.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) * inv).filter(|&t| t > 0.0)
}

/// The smallest box holding the points: (min corner, max corner); an empty
/// set gives lo > hi.
pub fn bounds(points: impl IntoIterator<Item = DVec3>) -> (DVec3, DVec3) {
    points
        .into_iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        })
}

/// The eight corners of the box spanned by `lo` and `hi`.
pub(crate) fn box_corners(lo: DVec3, hi: DVec3) -> [DVec3; 8] {
    std::array::from_fn(|i| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

/// Whether the segment a→b meets the box [lo, hi] (slab test; the box is
/// grown by a millionth of its size, so that touching counts).
pub(crate) fn segment_meets_box(a: DVec3, b: DVec3, lo: DVec3, hi: DVec3) -> bool {
    let pad = 1e-6 * (hi - lo).max_element().max(1.0);
    let (lo, hi) = (lo - pad, hi + pad);
    let d = b - a;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        if d[k].abs() < 1e-300 {
            if a[k] < lo[k] || a[k] > hi[k] {
                return false;
            }
        } else {
            let (mut ta, mut tb) = ((lo[k] - a[k]) / d[k], (hi[k] - a[k]) / d[k]);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// A box turned about the vertical axis: `lo`..`hi` in its own frame,
/// whose x axis is (cos, 0, sin) in the world. Objects stand on floors and
/// turn about the vertical; their world-aligned box grows with the angle
/// (a cube turned 20° covers 1.64 times its own footprint), this one does not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UprightBox {
    pub lo: DVec3,
    pub hi: DVec3,
    cos: f64,
    sin: f64,
}

impl UprightBox {
    /// The box of least footprint around `points` among those turned about
    /// the vertical: one side lies along an edge of the points' convex hull
    /// seen from above (Freeman & Shapira's rectangle of least area).
    pub fn around(points: &[DVec3]) -> UprightBox {
        let hull = plan_hull(points);
        let mut best = (f64::INFINITY, 1.0, 0.0);
        for k in 0..hull.len() {
            let e = hull[(k + 1) % hull.len()] - hull[k];
            let len = e.length();
            if len <= 0.0 {
                continue;
            }
            let (c, s) = (e.x / len, e.y / len);
            let (mut lo, mut hi) = (glam::DVec2::INFINITY, glam::DVec2::NEG_INFINITY);
            for p in &hull {
                let q = glam::DVec2::new(c * p.x + s * p.y, -s * p.x + c * p.y);
                lo = lo.min(q);
                hi = hi.max(q);
            }
            let area = (hi - lo).x * (hi - lo).y;
            if area < best.0 {
                best = (area, c, s);
            }
        }
        let (_, cos, sin) = best;
        let frame = UprightBox {
            lo: DVec3::ZERO,
            hi: DVec3::ZERO,
            cos,
            sin,
        };
        let (lo, hi) = bounds(points.iter().map(|p| frame.to_frame(*p)));
        UprightBox { lo, hi, ..frame }
    }

    /// `p` in the box's frame.
    pub(crate) fn to_frame(self, p: DVec3) -> DVec3 {
        DVec3::new(
            self.cos * p.x + self.sin * p.z,
            p.y,
            -self.sin * p.x + self.cos * p.z,
        )
    }

    /// This box grown by `pad` on every side.
    pub(crate) fn padded(&self, pad: f64) -> UprightBox {
        UprightBox {
            lo: self.lo - pad,
            hi: self.hi + pad,
            ..*self
        }
    }

    /// The eight corners, in the world.
    pub fn corners(&self) -> [DVec3; 8] {
        box_corners(self.lo, self.hi).map(|q| {
            DVec3::new(
                self.cos * q.x - self.sin * q.z,
                q.y,
                self.sin * q.x + self.cos * q.z,
            )
        })
    }

    /// Whether the segment a→b meets the box ([`segment_meets_box`] in its frame).
    pub(crate) fn meets_segment(&self, a: DVec3, b: DVec3) -> bool {
        segment_meets_box(self.to_frame(a), self.to_frame(b), self.lo, self.hi)
    }
}

/// The convex hull of the points seen from above, (x, z) counter-clockwise
/// (Andrew's monotone chain); a single point or a segment when they are.
fn plan_hull(points: &[DVec3]) -> Vec<glam::DVec2> {
    // A mesh's triangles list each vertex about six times: the distinct
    // plan points alone are sorted (an 80,000-triangle object's bounds took
    // 12 ms an update, nearly all of it this sort). The sorted, deduplicated
    // list is the same, so is the hull.
    let mut seen = std::collections::HashSet::with_capacity_and_hasher(
        points.len() / 4,
        foldhash::fast::FixedState::default(),
    );
    let mut p: Vec<glam::DVec2> = (points.iter())
        .filter(|q| seen.insert((q.x.to_bits(), q.z.to_bits())))
        .map(|q| glam::DVec2::new(q.x, q.z))
        .collect();
    // Equal under `total_cmp` is equal bits: an unstable sort orders as a stable one.
    p.sort_unstable_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: glam::DVec2, a: glam::DVec2, b: glam::DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<glam::DVec2> = Vec::with_capacity(2 * p.len());
    // The lower chain left to right, then the upper one right to left.
    for pass in 0..2 {
        let start = hull.len();
        for k in 0..p.len() {
            let q = if pass == 0 { p[k] } else { p[p.len() - 1 - k] };
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// The largest coordinate a vertex may have, metres. Rays are traced in
/// single precision: at 1e6 m a float steps by 6 cm, coarser than the
/// offsets that keep a shadow ray off its own surface (and Embree aborts
/// on rays near 1e15).
pub(crate) const MAX_COORDINATE: f32 = 1e6;

/// Loads an OBJ file. Every `o`/`g` name is one surface; repeated names
/// (a group split by `usemtl`, or reopened later) are merged. The file is
/// read as bytes: a comment or name in another encoding than UTF-8 (an
/// exporter's Latin-1) is kept with its unknown bytes replaced.
pub fn load_obj(path: &Path) -> Result<Mesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    let text = String::from_utf8_lossy(&bytes);
    check_obj_lines(path, &text)?;
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let (models, materials) = tobj::load_obj_buf(&mut text.as_bytes(), &options, |mtl| {
        tobj::load_mtl(dir.join(mtl))
    })
    .map_err(|e| Error::file(path, format!("malformed OBJ: {e}")))?;
    // A missing or broken .mtl only matters where its colour is needed; the
    // caller reports that with the key that needed it.
    let materials = materials.unwrap_or_default();

    let mut surfaces: Vec<MeshSurface> = Vec::new();
    let mut dropped = 0;
    let mut unused: Vec<String> = Vec::new();
    let mut pbr = obj_material::ObjMaterials::new(&dir, &materials);
    for model in &models {
        let m = &model.mesh;
        let corner = |i: u32| -> Vec3 {
            let i = i as usize * 3;
            Vec3::new(m.positions[i], m.positions[i + 1], m.positions[i + 2])
        };
        let mut triangles = Vec::with_capacity(m.indices.len() / 3);
        let mut attributes = crate::materials::Attributes::default();
        for (k, f) in m.indices.chunks_exact(3).enumerate() {
            let t = [corner(f[0]), corner(f[1]), corner(f[2])];
            if is_degenerate(&t) {
                dropped += 1;
            } else {
                triangles.push(t);
                obj_material::push_attributes(m, k, &mut attributes);
            }
        }
        let material = m.material_id.and_then(|id| materials.get(id));
        if let Some(mat) = material {
            let specular = mat.specular.is_some_and(|k| k.iter().any(|&c| c > 0.0));
            if (specular || mat.diffuse_texture.is_some()) && !unused.contains(&mat.name) {
                unused.push(mat.name.clone());
            }
        }
        let kd = material.and_then(|mat| mat.diffuse).map(Vec3::from_array);
        let full = m.material_id.map(|id| pbr.get(id)).transpose()?.flatten();
        match surfaces.iter_mut().find(|s| s.name == model.name) {
            Some(s) => {
                s.triangles.extend(triangles);
                s.material_rgb = s.material_rgb.or(kd);
                s.material = s.material.clone().or(full);
                s.attributes.append(attributes, s.triangles.len());
            }
            None => surfaces.push(MeshSurface {
                name: model.name.clone(),
                triangles,
                material_rgb: kd,
                material: full,
                attributes,
            }),
        }
    }
    surfaces.retain(|s| !s.triangles.is_empty());
    if surfaces.is_empty() {
        let why = if dropped > 0 {
            format!("no usable triangles ({dropped} degenerate or non-finite triangles dropped)")
        } else {
            "no triangles".to_string()
        };
        return Err(Error::file(path, why));
    }
    Ok(Mesh {
        surfaces,
        dropped_triangles: dropped,
        unused_material_parts: unused,
        unsupported: pbr.unsupported(),
    })
}

/// Checks the statements arlux relies on (`v` and `f`) line by line, so that
/// a malformed file is reported at its line.
fn check_obj_lines(path: &Path, text: &str) -> Result<()> {
    let mut positions = 0i64;
    let mut texcoords = 0i64;
    let mut normals = 0i64;
    for (n, raw) in text.lines().enumerate() {
        let line_no = n + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        let args: Vec<&str> = words.collect();
        let bad = |msg: String| Error::line(path, line_no, msg);
        let floats = |min: usize, what: &str| -> Result<()> {
            if args.len() < min {
                return Err(bad(format!(
                    "{what} needs {min} numbers, found {}",
                    args.len()
                )));
            }
            for a in &args[..min] {
                a.parse::<f32>()
                    .map_err(|_| bad(format!("{what}: '{a}' is not a number")))?;
            }
            Ok(())
        };
        match tag {
            "v" => {
                floats(3, "vertex")?;
                if let Some(far) = args[..3]
                    .iter()
                    .filter_map(|a| a.parse::<f32>().ok())
                    .find(|c| c.abs() > MAX_COORDINATE)
                {
                    return Err(bad(format!(
                        "vertex coordinate {far} lies beyond ±{MAX_COORDINATE} m: single-precision rays cannot resolve a room there (move the model near the origin)"
                    )));
                }
                positions += 1;
            }
            "vt" => {
                floats(1, "texture coordinate")?;
                texcoords += 1;
            }
            "vn" => {
                floats(3, "normal")?;
                normals += 1;
            }
            "f" => {
                if args.len() < 3 {
                    return Err(bad(format!(
                        "face needs at least 3 vertices, found {}",
                        args.len()
                    )));
                }
                for a in &args {
                    let mut parts = a.split('/');
                    let counts = [positions, texcoords, normals];
                    for (k, count) in counts.iter().enumerate() {
                        let Some(p) = parts.next() else { break };
                        if p.is_empty() && k > 0 {
                            continue;
                        }
                        let index: i64 = p
                            .parse()
                            .map_err(|_| bad(format!("face: '{a}' is not a vertex reference")))?;
                        let resolved = if index < 0 { count + index + 1 } else { index };
                        if index == 0 || resolved < 1 || resolved > *count {
                            return Err(bad(format!(
                                "face: '{a}' refers to {} {index}, but only {count} are defined above",
                                ["vertex", "texture coordinate", "normal"][k]
                            )));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn groups_become_surfaces_and_degenerates_are_counted() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            "a.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv nan 0 0\no first\nf 1 2 3\nf 1 2 4\ng second\nf 1 2 3\nf 5 2 3\no first\nf 3 2 1\n",
        );
        let mesh = load_obj(&p).unwrap();
        let names: Vec<_> = mesh.surfaces.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["first", "second"]);
        assert_eq!(mesh.surfaces[0].triangles.len(), 2);
        assert_eq!(mesh.dropped_triangles, 2, "one collinear, one NaN");
    }

    #[test]
    fn malformed_lines_are_reported_with_their_number() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "bad.obj", "v 0 0 0\nv 1 0 x\nf 1 2 3\n");
        let e = load_obj(&p).unwrap_err();
        assert_eq!(e.location, crate::error::Location::Line(2), "{e}");
        let p = write(
            dir.path(),
            "bad2.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 4\n",
        );
        let e = load_obj(&p).unwrap_err();
        assert_eq!(e.location, crate::error::Location::Line(5), "{e}");
        assert!(e.to_string().contains("only 3"), "{e}");
    }

    #[test]
    fn an_upright_box_fits_a_turned_cube_exactly() {
        let turn = |p: DVec3, a: f64| {
            DVec3::new(
                a.cos() * p.x - a.sin() * p.z,
                p.y,
                a.sin() * p.x + a.cos() * p.z,
            )
        };
        let a = 20f64.to_radians();
        let cube: Vec<DVec3> =
            box_corners(DVec3::new(-0.15, 0.0, -0.15), DVec3::new(0.15, 0.3, 0.15))
                .iter()
                .map(|p| turn(*p, a) + DVec3::new(0.4, 0.0, -0.2))
                .collect();
        let b = UprightBox::around(&cube);
        let size = b.hi - b.lo;
        assert!(
            (size - DVec3::splat(0.3)).abs().max_element() < 1e-12,
            "{size}"
        );
        for c in b.corners() {
            assert!(
                cube.iter().any(|p| (*p - c).length() < 1e-12),
                "corner {c} not the cube's"
            );
        }
        // Through the world box's corner beside the cube: the world box meets it, the upright one does not.
        let (lo, hi) = bounds(cube.iter().copied());
        let (from, to) = (
            DVec3::new(lo.x - 0.05, 0.15, lo.z + 0.06),
            DVec3::new(lo.x + 0.06, 0.15, lo.z - 0.05),
        );
        assert!(segment_meets_box(from, to, lo, hi) && !b.meets_segment(from, to));
        assert!(b.meets_segment(DVec3::new(0.4, 1.0, -0.2), DVec3::new(0.4, -1.0, -0.2)));
        // Points in a vertical plane, and a single point: boxes without thickness.
        let flat = UprightBox::around(&[
            DVec3::ZERO,
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(0.5, 1.0, 0.5),
        ]);
        assert!(
            (flat.hi - flat.lo).z.abs() < 1e-12
                && ((flat.hi - flat.lo).x - 2f64.sqrt()).abs() < 1e-12
        );
        let one = UprightBox::around(&[DVec3::ONE]);
        assert_eq!(one.corners(), [DVec3::ONE; 8]);
    }

    /// The plan hull of a mesh's corners, each listed several times (with
    /// signed zeros and points above one another), is the hull of every
    /// point sorted and deduplicated, in the same order, bit for bit.
    #[test]
    fn the_plan_hull_of_repeated_points_is_that_of_every_point() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut corners: Vec<DVec3> = (0..500)
            .map(|_| DVec3::new(next(), next(), next()))
            .collect();
        corners.extend([DVec3::new(-0.0, 0.1, 0.5), DVec3::new(0.0, 0.2, 0.5)]);
        corners.extend([DVec3::new(0.6, 0.0, 0.0), DVec3::new(0.6, 1.0, 0.0)]);
        let points: Vec<DVec3> = (0..6)
            .flat_map(|k| corners.iter().cycle().skip(k * 7).take(corners.len()))
            .copied()
            .collect();
        let mut all: Vec<glam::DVec2> = points.iter().map(|q| glam::DVec2::new(q.x, q.z)).collect();
        all.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
        all.dedup();
        let bits = |h: Vec<glam::DVec2>| {
            h.iter()
                .map(|p| (p.x.to_bits(), p.y.to_bits()))
                .collect::<Vec<_>>()
        };
        let three: Vec<DVec3> = all.iter().map(|p| DVec3::new(p.x, 0.0, p.y)).collect();
        let hull = plan_hull(&points);
        assert!(hull.len() >= 3);
        assert_eq!(bits(hull), bits(plan_hull(&three)));
    }

    #[test]
    fn closed_boxes_enclose_their_inside_only() {
        let p =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/geometry/box.obj");
        let b = load_obj(&p).unwrap();
        let tris = &b.surfaces[0].triangles;
        assert!(is_closed(tris));
        assert!(encloses(tris, DVec3::new(0.01, 0.1, -0.02)));
        assert!(!encloses(tris, DVec3::new(0.4, 0.1, 0.0)));
        assert!(!is_closed(&tris[..10]));
        let d = distance_to_triangle(DVec3::new(0.0, 0.5, 0.0), &tris[8]);
        assert!((d - 0.2).abs() < 1e-6, "top face at y=0.3: {d}");
    }

    #[test]
    fn a_file_of_only_degenerate_triangles_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            "flat.obj",
            "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
        );
        let e = load_obj(&p).unwrap_err();
        assert!(e.to_string().contains("1 degenerate"), "{e}");
    }
}
