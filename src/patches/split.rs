//! Splitting an element in two across its longer side, the regions of
//! its root it covers, and a surface's triangles paired into quads.

use super::*;

/// Which leaves to split once more: per root ordinal (its place in
/// `roots`, stable across rebuilds, unlike its element index), (centre in
/// the root's parameters, leaf size). See [`Patches::of_scene_refined`].
pub(crate) type SplitMarks = HashMap<u32, Vec<(DVec2, f64)>>;

/// An element's two halves: quads across their longer side, triangles
/// across their longest edge.
pub fn split(shape: Shape, region: Region) -> [(Shape, Region); 2] {
    match (shape, region) {
        (Shape::Quad { origin, u, v }, Region::Quad { s0, s1, t0, t1 }) => {
            if u.length() >= v.length() {
                let (h, sm) = (0.5 * u, 0.5 * (s0 + s1));
                [
                    (
                        Shape::Quad { origin, u: h, v },
                        Region::Quad { s0, s1: sm, t0, t1 },
                    ),
                    (
                        Shape::Quad {
                            origin: origin + h,
                            u: h,
                            v,
                        },
                        Region::Quad { s0: sm, s1, t0, t1 },
                    ),
                ]
            } else {
                let (h, tm) = (0.5 * v, 0.5 * (t0 + t1));
                [
                    (
                        Shape::Quad { origin, u, v: h },
                        Region::Quad { s0, s1, t0, t1: tm },
                    ),
                    (
                        Shape::Quad {
                            origin: origin + h,
                            u,
                            v: h,
                        },
                        Region::Quad { s0, s1, t0: tm, t1 },
                    ),
                ]
            }
        }
        (Shape::Tri(p), Region::Tri(q)) => {
            // Bisect the longest edge (i, j); k is the opposite corner.
            let lens = [
                (p[1] - p[0]).length(),
                (p[2] - p[1]).length(),
                (p[0] - p[2]).length(),
            ];
            let i = (0..3).max_by(|&a, &b| lens[a].total_cmp(&lens[b])).unwrap();
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            let (m, mq) = (0.5 * (p[i] + p[j]), 0.5 * (q[i] + q[j]));
            [
                (Shape::Tri([p[i], m, p[k]]), Region::Tri([q[i], mq, q[k]])),
                (Shape::Tri([m, p[j], p[k]]), Region::Tri([mq, q[j], q[k]])),
            ]
        }
        _ => unreachable!("an element's region matches its shape"),
    }
}

/// The centre of a region, in its root's parameters.
pub(crate) fn region_centre(region: &Region) -> DVec2 {
    match *region {
        Region::Quad { s0, s1, t0, t1 } => DVec2::new(0.5 * (s0 + s1), 0.5 * (t0 + t1)),
        Region::Tri(q) => (q[0] + q[1] + q[2]) / 3.0,
    }
}

/// (s, t) with x ≈ s·u + t·v, by least squares in the plane of u and v.
pub(super) fn plane_params(x: DVec3, u: DVec3, v: DVec3) -> DVec2 {
    let (uu, uv, vv) = (u.dot(u), u.dot(v), v.dot(v));
    let (xu, xv) = (x.dot(u), x.dot(v));
    let det = uu * vv - uv * uv;
    DVec2::new((xu * vv - xv * uv) / det, (xv * uu - xu * uv) / det)
}

pub(super) fn barycentric(p: DVec2, q: [DVec2; 3]) -> [f64; 3] {
    let (v0, v1, v2) = (q[1] - q[0], q[2] - q[0], p - q[0]);
    let d = v0.perp_dot(v1);
    let b = v2.perp_dot(v1) / d;
    let c = v0.perp_dot(v2) / d;
    [1.0 - b - c, b, c]
}

/// How far `st` lies outside a region (0 inside): picks the child that
/// holds a point, robustly at shared edges.
pub(crate) fn distance_outside(region: &Region, st: DVec2) -> f64 {
    match *region {
        Region::Quad { s0, s1, t0, t1 } => {
            (s0 - st.x).max(st.x - s1).max(0.0) + (t0 - st.y).max(st.y - t1).max(0.0)
        }
        Region::Tri(q) => barycentric(st, q).iter().map(|w| (-w).max(0.0)).sum(),
    }
}

/// Root primitives of one surface: parallelograms made of two triangles
/// sharing a diagonal, and the remaining triangles, each with the indices
/// of the input triangles it covers.
pub(super) fn primitives(triangles: &[Triangle]) -> Vec<(Shape, Vec<u32>)> {
    let key = |p: glam::Vec3| (p.as_dvec3() * 1e5).round().as_i64vec3().to_array();
    let tris: Vec<[DVec3; 3]> = triangles.iter().map(|t| t.map(|p| p.as_dvec3())).collect();
    let mut by_edge: crate::util::FastMap<([i64; 3], [i64; 3]), Vec<u32>> = crate::util::fast_map();
    for (i, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (key(t[k]), key(t[(k + 1) % 3]));
            by_edge
                .entry(if a < b { (a, b) } else { (b, a) })
                .or_default()
                .push(i as u32);
        }
    }
    let mut used = vec![false; triangles.len()];
    let mut out = Vec::new();
    for i in 0..triangles.len() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let t = tris[i];
        let mut paired = None;
        'edges: for k in 0..3 {
            let (a, b) = (key(triangles[i][k]), key(triangles[i][(k + 1) % 3]));
            let Some(others) = by_edge.get(&if a < b { (a, b) } else { (b, a) }) else {
                continue;
            };
            for &j in others {
                let j = j as usize;
                if used[j] {
                    continue;
                }
                // Shared edge (p, q); opposite corners r (of i) and r2 (of j).
                let (p, q, r) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                let Some(r2) = tris[j]
                    .iter()
                    .copied()
                    .find(|c| (*c - p).length() > 1e-9 && (*c - q).length() > 1e-9)
                else {
                    continue;
                };
                // Within the single-precision corners' own rounding: a
                // solid moved away from the origin keeps its quads.
                let scale = (p - r).length().max((q - r).length());
                let magnitude = [p, q, r, r2]
                    .iter()
                    .map(|c| c.abs().max_element())
                    .fold(0.0, f64::max);
                if ((p + q) - (r + r2)).length()
                    <= 1e-7 * scale.max(1e-9) + 8.0 * f32::EPSILON as f64 * magnitude
                {
                    paired = Some((
                        j,
                        Shape::Quad {
                            origin: r,
                            u: p - r,
                            v: q - r,
                        },
                    ));
                    break 'edges;
                }
            }
        }
        match paired {
            Some((j, quad)) => {
                used[j] = true;
                out.push((quad, vec![i as u32, j as u32]));
            }
            None => out.push((Shape::Tri(t), vec![i as u32])),
        }
    }
    out
}
