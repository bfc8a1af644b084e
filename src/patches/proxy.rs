//! A finely tessellated object's radiosity mesh: its triangles gathered by
//! vertex clustering (Rossignac & Borrel 1993) into a coarse mesh whose
//! triangles are about a cell wide. An 80k-triangle prop's triangles are
//! a few millimetres across, 30 times finer than the objects' 10 cm
//! patches: with a patch per triangle, each shown copy of it held 78,724
//! patches (23 MB of elements alone), and an update gathered, linked and
//! solved them all. What the room receives from an object and what the
//! object receives from the room vary over the patch size, not over the
//! triangles; the pixels keep the full mesh (camera and shadow rays meet
//! its triangles, and a hit is located on the coarse triangle it was
//! gathered into).
//!
//! Written here rather than taken from a simplification crate: those
//! simplify for level of detail and return new vertices and no map from
//! each input triangle to its output one, which every hit on the full mesh
//! needs to find its patch.

use glam::{DVec3, Vec3};

use super::{Patches, Shape, SurfaceInput};
use crate::geometry::Triangle;
use crate::util::FastMap;

/// Patches of one surface (id 0) meshed on its coarse mesh: every full
/// triangle's hits are located on its coarse triangle's patches, a solid
/// stays a solid facing out, and each patch samples its direct light on
/// the full triangle nearest its centre. With the full triangles
/// gathered under each root element (for their albedo). None when the
/// surface keeps its own triangles.
pub(super) fn coarse_block(
    triangles: &[Triangle],
    size: f64,
) -> Option<(Patches, FastMap<u32, Vec<u32>>)> {
    let proxy = cluster(triangles, size / 4.0)?;
    let input = SurfaceInput {
        surface: 0,
        triangles: &proxy.triangles,
        is_virtual: true,
    };
    let mut block = Patches::build(&[input], size);
    let coarse_root: Vec<u32> = (0..proxy.triangles.len() as u32)
        .map(|k| block.root_of(0, k).unwrap_or(u32::MAX))
        .collect();
    let of: Vec<u32> = (proxy.of_triangle.iter())
        .map(|&k| coarse_root[k as usize])
        .collect();
    let mut members: FastMap<u32, Vec<u32>> = crate::util::fast_map();
    for (t, &r) in of.iter().enumerate().filter(|(_, r)| **r != u32::MAX) {
        members.entry(r).or_default().push(t as u32);
    }
    orient_as_solid(&mut block, triangles, &proxy, &coarse_root);
    block.surface_samples = samples(&block, triangles, &members);
    block.root_of_triangle = vec![of];
    Some((block, members))
}

/// A closed surface is a solid ([`Patches::append`]): its coarse mesh
/// (not always closed: clustering pinches thin parts) is one-sided too,
/// each element facing out as the full triangle its direct light is
/// sampled on faces. An open surface stays as meshed: two-sided, then
/// facing the camera as every open surface does.
fn orient_as_solid(block: &mut Patches, triangles: &[Triangle], proxy: &Proxy, roots: &[u32]) {
    if !crate::geometry::is_closed(triangles) {
        return;
    }
    let Some(outward) = crate::geometry::consistent_winding(triangles) else {
        return;
    };
    let mut facing: FastMap<u32, DVec3> = crate::util::fast_map();
    for (k, &r) in roots.iter().enumerate().filter(|(_, r)| **r != u32::MAX) {
        let n = area_normal(&triangles[proxy.surface_of[k] as usize]);
        facing.entry(r).or_insert(if outward { n } else { -n });
    }
    for el in &mut block.elements {
        if let Some(out) = facing.get(&el.root) {
            if el.normal.dot(*out) < 0.0 {
                el.normal = -el.normal;
            }
            el.one_sided = true;
        }
    }
}

/// Per leaf, the full triangle (of those under its root) whose centroid
/// lies nearest its centre, as a shape (the lowest index among equals).
fn samples(
    block: &Patches,
    triangles: &[Triangle],
    members: &FastMap<u32, Vec<u32>>,
) -> FastMap<u32, Shape> {
    let mut out = crate::util::fast_map();
    for k in 0..block.patch_count() {
        let el = block.patch(k);
        let nearest = (members.get(&el.root).into_iter().flatten().copied()).min_by(|&a, &b| {
            let d = |t: u32| (centroid(&triangles[t as usize]) - el.centre).length_squared();
            d(a).total_cmp(&d(b)).then(a.cmp(&b))
        });
        if let Some(t) = nearest {
            out.insert(
                k as u32,
                Shape::Tri(triangles[t as usize].map(|p| p.as_dvec3())),
            );
        }
    }
    out
}

/// The coarse mesh of a surface and, per triangle of the full mesh, the
/// coarse triangle its hits are located on.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Proxy {
    pub(crate) triangles: Vec<Triangle>,
    /// Per full triangle, its coarse triangle's index.
    pub(crate) of_triangle: Vec<u32>,
    /// Per coarse triangle, the full triangle nearest its centroid among
    /// those gathered into it: the surface there, which a solid's coarse
    /// elements face as (each leaf samples its direct light on its own
    /// nearest full triangle, [`samples`]: a coarse triangle is a chord of
    /// a curved surface, its points up to a few millimetres inside the
    /// solid, where shadow rays would leave through the object's own skin).
    pub(crate) surface_of: Vec<u32>,
}

/// The coarse mesh of `triangles` on cells of edge `cell` and normal bins
/// of ~22° (a thin part's two faces stay apart), or None when it would
/// not hold under half as many triangles (a mesh already as coarse as its
/// patches keeps its own).
pub(crate) fn cluster(triangles: &[Triangle], cell: f64) -> Option<Proxy> {
    let (ids, positions) = weld(triangles);
    let normals = vertex_normals(triangles, &ids, positions.len());
    // Each vertex's cluster: its cell and its normal's bin.
    let mut cluster_of_key: crate::util::FastMap<([i64; 3], usize), u32> = crate::util::fast_map();
    let mut cluster = Vec::with_capacity(positions.len());
    for (p, n) in positions.iter().zip(&normals) {
        let c = (p.as_dvec3() / cell).floor().as_i64vec3().to_array();
        let next = cluster_of_key.len() as u32;
        cluster.push(
            *cluster_of_key
                .entry((c, crate::geometry::normal_bin(*n)))
                .or_insert(next),
        );
    }
    let reps = representatives(&positions, &cluster, cluster_of_key.len());
    // A coarse triangle per distinct triple of clusters, wound as the
    // first full triangle that makes it (then as its members face
    // together: `wind_as_members`).
    let mut of_triple: crate::util::FastMap<[u32; 3], u32> = crate::util::fast_map();
    let mut coarse: Vec<Triangle> = Vec::new();
    let mut coarse_normal: Vec<DVec3> = Vec::new();
    let mut of_triangle = vec![u32::MAX; triangles.len()];
    for (t, v) in ids.iter().enumerate() {
        let c = v.map(|v| cluster[v as usize]);
        if c[0] == c[1] || c[1] == c[2] || c[0] == c[2] {
            continue;
        }
        let mut key = c;
        key.sort_unstable();
        if let Some(&k) = of_triple.get(&key) {
            of_triangle[t] = k;
            continue;
        }
        let tri = c.map(|c| positions[reps[c as usize] as usize]);
        let n = area_normal(&tri);
        if n.length_squared() <= 1e-24 || !n.is_finite() {
            continue;
        }
        let k = coarse.len() as u32;
        of_triple.insert(key, k);
        coarse.push(tri);
        coarse_normal.push(n.normalize());
        of_triangle[t] = k;
    }
    if coarse.is_empty() || 2 * coarse.len() > triangles.len() {
        return None;
    }
    place_collapsed(triangles, &ids, &cluster, &coarse_normal, &mut of_triangle);
    wind_as_members(triangles, &of_triangle, &mut coarse);
    let surface_of = nearest_members(triangles, &coarse, &of_triangle);
    Some(Proxy {
        triangles: coarse,
        of_triangle,
        surface_of,
    })
}

/// The corners' distinct positions (by their bits) and each triangle's
/// three position ids.
fn weld(triangles: &[Triangle]) -> (Vec<[u32; 3]>, Vec<Vec3>) {
    let mut id_of: crate::util::FastMap<[u32; 3], u32> = crate::util::fast_map();
    let mut positions = Vec::new();
    let ids = triangles
        .iter()
        .map(|t| {
            t.map(|p| {
                let next = positions.len() as u32;
                *id_of
                    .entry(p.to_array().map(f32::to_bits))
                    .or_insert_with(|| {
                        positions.push(p);
                        next
                    })
            })
        })
        .collect();
    (ids, positions)
}

/// Area-weighted vertex normals (zero where no triangle has an area).
fn vertex_normals(triangles: &[Triangle], ids: &[[u32; 3]], count: usize) -> Vec<DVec3> {
    let mut sum = vec![DVec3::ZERO; count];
    for (t, v) in triangles.iter().zip(ids) {
        let n = area_normal(t);
        for &v in v {
            sum[v as usize] += n;
        }
    }
    sum.into_iter().map(|n| n.normalize_or_zero()).collect()
}

/// Per cluster, the vertex nearest the mean of its vertices (a vertex of
/// the full mesh, so the coarse mesh's corners lie on the surface; the
/// lowest id among equals).
fn representatives(positions: &[Vec3], cluster: &[u32], count: usize) -> Vec<u32> {
    let mut sum = vec![(DVec3::ZERO, 0u32); count];
    for (p, &c) in positions.iter().zip(cluster) {
        sum[c as usize].0 += p.as_dvec3();
        sum[c as usize].1 += 1;
    }
    let mut best = vec![(f64::INFINITY, u32::MAX); count];
    for (v, (p, &c)) in positions.iter().zip(cluster).enumerate() {
        let (s, n) = sum[c as usize];
        let d = (p.as_dvec3() - s / n as f64).length_squared();
        if d < best[c as usize].0 {
            best[c as usize] = (d, v as u32);
        }
    }
    best.into_iter().map(|(_, v)| v).collect()
}

/// A full triangle whose corners fell into fewer than three clusters (or
/// made a coarse triangle of no area) is located on the coarse triangle
/// of one of its clusters that faces most nearly as it does.
fn place_collapsed(
    triangles: &[Triangle],
    ids: &[[u32; 3]],
    cluster: &[u32],
    coarse_normal: &[DVec3],
    of_triangle: &mut [u32],
) {
    // The coarse triangles around each cluster.
    let mut around: crate::util::FastMap<u32, Vec<u32>> = crate::util::fast_map();
    for (t, v) in ids.iter().enumerate() {
        let k = of_triangle[t];
        if k == u32::MAX {
            continue;
        }
        for &v in v {
            let list = around.entry(cluster[v as usize]).or_default();
            if !list.contains(&k) {
                list.push(k);
            }
        }
    }
    for t in 0..triangles.len() {
        if of_triangle[t] != u32::MAX {
            continue;
        }
        let n = area_normal(&triangles[t]).normalize_or_zero();
        let best = (ids[t].iter())
            .filter_map(|&v| around.get(&cluster[v as usize]))
            .flatten()
            .copied()
            .max_by(|&a, &b| {
                let f = |k: u32| coarse_normal[k as usize].dot(n);
                f(a).total_cmp(&f(b)).then(b.cmp(&a))
            });
        // A piece cut off from every coarse triangle: the first one (its
        // hits still find a patch; such pieces are specks).
        of_triangle[t] = best.unwrap_or(0);
    }
}

/// Winds each coarse triangle as its members face together (clustering
/// folds a few over: the first member to make one may lie across a crease).
fn wind_as_members(triangles: &[Triangle], of_triangle: &[u32], coarse: &mut [Triangle]) {
    let mut facing = vec![DVec3::ZERO; coarse.len()];
    for (t, &k) in of_triangle.iter().enumerate() {
        facing[k as usize] += area_normal(&triangles[t]);
    }
    for (t, n) in coarse.iter_mut().zip(facing) {
        if area_normal(t).dot(n) < 0.0 {
            t.swap(1, 2);
        }
    }
}

/// Per coarse triangle, its member (full triangle) whose centroid lies
/// nearest the coarse triangle's centroid (the lowest index among equals).
fn nearest_members(triangles: &[Triangle], coarse: &[Triangle], of_triangle: &[u32]) -> Vec<u32> {
    let mut best = vec![(f64::INFINITY, u32::MAX); coarse.len()];
    for (t, &k) in of_triangle.iter().enumerate() {
        let d = (centroid(&triangles[t]) - centroid(&coarse[k as usize])).length_squared();
        if d < best[k as usize].0 {
            best[k as usize] = (d, t as u32);
        }
    }
    best.into_iter().map(|(_, t)| t).collect()
}

/// The mean of a triangle's corners.
fn centroid(t: &Triangle) -> DVec3 {
    (t[0].as_dvec3() + t[1].as_dvec3() + t[2].as_dvec3()) / 3.0
}

/// Twice the area times the unit normal (winding decides the sign).
fn area_normal(t: &Triangle) -> DVec3 {
    let [a, b, c] = t.map(|p| p.as_dvec3());
    (b - a).cross(c - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A UV sphere of radius `r` about the origin, wound outwards.
    fn sphere(r: f32, rings: usize, segments: usize) -> Vec<Triangle> {
        let at = |i: usize, j: usize| {
            let (theta, phi) = (
                std::f32::consts::PI * i as f32 / rings as f32,
                std::f32::consts::TAU * j as f32 / segments as f32,
            );
            Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ) * r
        };
        let mut out = Vec::new();
        for i in 0..rings {
            for j in 0..segments {
                let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
                if i > 0 {
                    out.push([a, b, c]);
                }
                if i + 1 < rings {
                    out.push([a, c, d]);
                }
            }
        }
        out
    }

    #[test]
    fn a_fine_sphere_clusters_into_a_coarse_one_on_its_surface() {
        let fine = sphere(0.1, 100, 200);
        assert!(crate::geometry::is_closed(&fine));
        let outward = |t: &Triangle| {
            let c = (t[0] + t[1] + t[2]).as_dvec3() / 3.0;
            area_normal(t).dot(c) > 0.0
        };
        assert!(
            fine.iter()
                .all(|t| outward(t) || area_normal(t).length() < 1e-12)
        );
        let p = cluster(&fine, 0.025).expect("a coarse mesh");
        assert!(
            8 * p.triangles.len() < fine.len(),
            "{} coarse triangles",
            p.triangles.len()
        );
        assert_eq!(p.of_triangle.len(), fine.len());
        assert!(
            p.of_triangle
                .iter()
                .all(|&k| (k as usize) < p.triangles.len())
        );
        // Its corners are the fine mesh's vertices; its faces lie within
        // a chord's sagitta of the sphere and face out as the fine ones.
        let corners: std::collections::HashSet<[u32; 3]> = (fine.iter().flatten())
            .map(|v| v.to_array().map(f32::to_bits))
            .collect();
        for t in &p.triangles {
            assert!(
                t.iter()
                    .all(|v| corners.contains(&v.to_array().map(f32::to_bits)))
            );
            let c = (t[0] + t[1] + t[2]).as_dvec3() / 3.0;
            assert!(
                (c.length() - 0.1).abs() < 0.006,
                "centroid at {}",
                c.length()
            );
            assert!(outward(t));
        }
        // Each coarse triangle's sample triangle is one of its own.
        for (k, &t) in p.surface_of.iter().enumerate() {
            assert_eq!(p.of_triangle[t as usize] as usize, k);
        }
    }

    #[test]
    fn a_coarse_block_locates_every_fine_triangle_and_faces_out() {
        let fine = sphere(0.1, 100, 200);
        let (block, members) = coarse_block(&fine, 0.1).expect("a coarse mesh");
        assert_eq!(members.values().map(Vec::len).sum::<usize>(), fine.len());
        for (t, tri) in fine.iter().enumerate() {
            let x = (tri[0] + tri[1] + tri[2]).as_dvec3() / 3.0;
            let at = block
                .locate(0, t as u32, x)
                .expect("a patch for every triangle");
            let el = block.patch(at.patch as usize);
            assert!(el.one_sided && el.normal.dot(el.centre) > 0.0);
            let w: f64 = at.weights.iter().map(|w| w.1).sum();
            assert!((w - 1.0).abs() < 1e-9 && at.weights.iter().all(|w| w.1 >= 0.0));
        }
        // Every patch samples its light on a fine triangle, on the sphere.
        assert_eq!(block.surface_samples.len(), block.patch_count());
        for k in 0..block.patch_count() {
            let c = block.sample_shape(k).centre();
            assert!((c.length() - 0.1).abs() < 1e-3);
            assert!((c - block.patch(k).centre).length() < 0.05);
        }
    }

    #[test]
    fn a_mesh_as_coarse_as_its_cells_keeps_its_own_triangles() {
        assert!(cluster(&sphere(0.1, 8, 16), 0.025).is_none());
    }
}
