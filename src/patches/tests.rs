use super::*;
use crate::scene::Scene;

#[test]
fn gauss_legendre_is_exact_to_degree_2n_minus_1() {
    for n in 1..=8 {
        let (x, w) = gauss_legendre(n);
        for deg in 0..2 * n {
            let q: f64 = x.iter().zip(w).map(|(x, w)| w * x.powi(deg as i32)).sum();
            assert!(
                (q - 1.0 / (deg as f64 + 1.0)).abs() < 1e-13,
                "n {n} degree {deg}: {q}"
            );
        }
    }
}

#[test]
fn triangle_quadrature_integrates_linear_functions() {
    let t = Shape::Tri([
        DVec3::ZERO,
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(0.0, 1.0, 0.0),
    ]);
    for n in 1..6 {
        let q = t.quadrature(n);
        assert_eq!(q.len(), n * n);
        let w: f64 = q.iter().map(|(_, w)| w).sum();
        let mean_x: f64 = q.iter().map(|(p, w)| p.x * w).sum();
        assert!((w - 1.0).abs() < 1e-12 && (mean_x - 2.0 / 3.0).abs() < 1e-12);
    }
}

fn desk() -> Scene {
    Scene::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/desk/scene.toml"
    ))
    .unwrap()
}

fn desk_patches(scene: &Scene, size: f64) -> Patches {
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
    Patches::build(&inputs, size)
}

#[test]
fn the_desk_meshes_into_quads_of_the_target_size_conserving_area() {
    let scene = desk();
    let p = desk_patches(&scene, 0.25);
    assert_eq!(
        p.roots.len(),
        34,
        "every triangle pair of the desk is a parallelogram"
    );
    assert!(
        p.roots
            .iter()
            .all(|&r| matches!(p.elements[r as usize].shape, Shape::Quad { .. }))
    );
    let area: f64 = (0..p.patch_count()).map(|k| p.patch(k).area).sum();
    let input: f64 = scene
        .surfaces
        .iter()
        .flat_map(|s| &s.triangles)
        .map(|t| 0.5 * crate::geometry::double_area(t))
        .sum();
    assert!((area - input).abs() < 1e-9 * input);
    assert!((0..p.patch_count()).all(|k| p.patch(k).shape.size() <= 0.25 + 1e-12));
    // The 4 m floor splits into 16 × 16 patches of 0.25 m, sharing 17 × 17 vertices.
    let floor: Vec<usize> = (0..p.patch_count())
        .filter(|&k| p.patch(k).surface == 2)
        .collect();
    assert_eq!(floor.len(), 256);
    let mut verts: Vec<u32> = floor.iter().flat_map(|&k| p.patch_vertices[k]).collect();
    verts.sort_unstable();
    verts.dedup();
    assert_eq!(verts.len(), 17 * 17);
}

#[test]
fn located_points_are_inside_their_patch_and_interpolate_back() {
    let scene = desk();
    let p = desk_patches(&scene, 0.3);
    let positions: Vec<DVec3> = p.vertices.clone();
    let mut state = 5u64;
    for (si, s) in scene.surfaces.iter().enumerate() {
        for (ti, t) in s.triangles.iter().enumerate() {
            for _ in 0..20 {
                let (mut a, mut b) = (
                    crate::util::rng::unit_random(&mut state),
                    crate::util::rng::unit_random(&mut state),
                );
                if a + b > 1.0 {
                    (a, b) = (1.0 - a, 1.0 - b);
                }
                let [p0, p1, p2] = t.map(|v| v.as_dvec3());
                let x = p0 + (p1 - p0) * a + (p2 - p0) * b;
                let at = p.locate(si as u32, ti as u32, x).unwrap();
                let back = p.interpolate(&positions, &at);
                assert!(
                    (back - x).length() < 1e-6,
                    "surface {si} tri {ti}: {x} -> {back}"
                );
                let el = p.patch(at.patch as usize);
                assert_eq!(el.surface, si as u32);
                assert!((x - el.centre).length() <= el.shape.size() * 0.75 + 1e-9);
            }
        }
    }
}

#[test]
fn lone_triangles_stay_triangles_and_bisect() {
    let t = [[
        glam::Vec3::ZERO,
        glam::Vec3::new(1.0, 0.0, 0.0),
        glam::Vec3::new(0.0, 0.0, 1.0),
    ]];
    let p = Patches::build(
        &[SurfaceInput {
            surface: 0,
            triangles: &t,
            is_virtual: true,
        }],
        0.3,
    );
    assert!(matches!(p.elements[0].shape, Shape::Tri(_)));
    let area: f64 = (0..p.patch_count()).map(|k| p.patch(k).area).sum();
    assert!((area - 0.5).abs() < 1e-12);
    let at = p.locate(0, 0, DVec3::new(0.2, 0.0, 0.3)).unwrap();
    let back = p.interpolate(&p.vertices, &at);
    assert!((back - DVec3::new(0.2, 0.0, 0.3)).length() < 1e-9);
    let constant = p.vertex_values(&vec![DVec3::splat(2.5); p.patch_count()]);
    assert!(
        constant
            .iter()
            .all(|v| (*v - DVec3::splat(2.5)).length() < 1e-12)
    );
}

#[test]
fn virtual_objects_are_meshed_after_the_real_surfaces_the_same_way() {
    let scene = desk();
    let real = Patches::of_scene(&scene, false, 0.25);
    let both = Patches::of_scene(&scene, true, 0.25);
    let n = real.patch_count();
    assert!(both.patch_count() > n);
    for k in 0..n {
        assert_eq!(
            both.patch(k).shape,
            real.patch(k).shape,
            "real patches keep their indices"
        );
    }
    let box_id = scene.surfaces.len() as u32;
    assert!(
        (n..both.patch_count())
            .all(|k| both.patch(k).surface == box_id && both.surface_is_virtual[&box_id])
    );
    let area: f64 = (n..both.patch_count()).map(|k| both.patch(k).area).sum();
    assert!(
        (area - 6.0 * 0.09).abs() < 1e-6,
        "the 0.3 m box has 0.54 m² of faces: {area}"
    );
}

/// The leaf [`Patches::locate_in_root`] finds by distances alone, at every level.
fn leaf_by_distances(patches: &Patches, root: u32, x: DVec3) -> u32 {
    let st = patches.root_params(root, x);
    let mut e = root;
    while let Some([a, b]) = patches.elements[e as usize].children {
        let da = distance_outside(&patches.elements[a as usize].region, st);
        e = if da == 0.0 || da <= distance_outside(&patches.elements[b as usize].region, st) {
            a
        } else {
            b
        };
    }
    e
}

#[test]
fn a_quads_cut_sends_a_point_to_the_leaf_the_distances_choose() {
    use rand::{RngExt, SeedableRng};
    let scene = desk();
    let patches = desk_patches(&scene, 0.1);
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let mut quads = 0;
    for &root in &patches.roots {
        let quad = matches!(patches.elements[root as usize].region, Region::Quad { .. });
        quads += quad as usize;
        for k in 0..400 {
            // Inside, beyond the edges, and exactly on the cuts' lines (a
            // grid of 64ths holds every cut the subdivision makes here).
            let st = match k % 3 {
                0 => DVec2::new(rng.random_range(0.0..=1.0), rng.random_range(0.0..=1.0)),
                1 => DVec2::new(rng.random_range(-0.2..1.2), rng.random_range(-0.2..1.2)),
                _ => DVec2::new(
                    rng.random_range(0..=64) as f64 / 64.0,
                    rng.random_range(0..=64) as f64 / 64.0,
                ),
            };
            let x = patches.root_point(root, st);
            let found = patches.locate_in_root(root, x);
            assert_eq!(
                patches.patches[found.patch as usize],
                leaf_by_distances(&patches, root, x),
                "root {root} at {st}"
            );
        }
    }
    assert!(quads > 10, "{quads} quad roots");
}

/// One virtual surface meshed at 0.1 m.
fn mesh_object(triangles: &[crate::geometry::Triangle]) -> Patches {
    Patches::build(
        &[SurfaceInput {
            surface: 0,
            triangles,
            is_virtual: true,
        }],
        0.1,
    )
}

#[test]
fn every_face_of_the_stool_and_a_reversed_box_faces_out() {
    // One parity test orients a consistently wound solid: each root's
    // normal must point out as a parity test of its own says.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let stool = crate::geometry::load_obj(&dir.join("scenes/lounge/geometry/stool.obj")).unwrap();
    let mut solids: Vec<Vec<crate::geometry::Triangle>> =
        stool.surfaces.iter().map(|o| o.triangles.clone()).collect();
    // A box wound inwards: every face flipped.
    let c = |x: f32, y: f32, z: f32| glam::Vec3::new(x, y, z);
    let quad = |a, b, cc, d| [[a, cc, b], [a, d, cc]];
    let inward: Vec<_> = [
        quad(c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)),
        quad(c(0., 1., 0.), c(0., 1., 1.), c(1., 1., 1.), c(1., 1., 0.)),
        quad(c(0., 0., 0.), c(0., 1., 0.), c(1., 1., 0.), c(1., 0., 0.)),
        quad(c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)),
        quad(c(0., 0., 0.), c(0., 0., 1.), c(0., 1., 1.), c(0., 1., 0.)),
        quad(c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)),
    ]
    .into_iter()
    .flatten()
    .collect();
    assert_eq!(crate::geometry::consistent_winding(&inward), Some(false));
    solids.push(inward);
    let (mut checked, mut embedded) = (0, 0);
    for tris in &solids {
        let p = mesh_object(tris);
        for &r in &p.roots {
            let e = &p.elements[r as usize];
            if !e.one_sided {
                continue;
            }
            let step = 1e-4 * e.shape.size().max(1e-3);
            let inside = |n: DVec3| crate::geometry::encloses(tris, e.centre + n * step);
            // A face sunk into another part of the solid (a leg's top in
            // the seat) has the solid on both sides: no side is out.
            if inside(e.normal) && inside(-e.normal) {
                embedded += 1;
                continue;
            }
            assert!(!inside(e.normal), "root {r} faces in");
            checked += 1;
        }
    }
    println!("{checked} one-sided roots face out, {embedded} lie inside the solid");
    assert!(
        checked > 1000 && embedded * 20 < checked,
        "{checked} out, {embedded} inside"
    );
}

#[test]
fn a_solid_larger_than_the_per_face_limit_is_one_sided_and_faces_out() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let stool =
        crate::geometry::load_obj(&dir.join("scenes/lounge/geometry/stool_dense.obj")).unwrap();
    let tris = &stool.surfaces[0].triangles;
    assert!(tris.len() > MAX_SOLID_TRIANGLES, "{} triangles", tris.len());
    let p = mesh_object(tris);
    assert!(p.roots.iter().all(|&r| p.elements[r as usize].one_sided));
    // Every 97th root (each test is linear in the triangles): out, not in.
    let mut checked = 0;
    for &r in p.roots.iter().step_by(97) {
        let e = &p.elements[r as usize];
        let step = 1e-4 * e.shape.size().max(1e-3);
        let inside = |n: DVec3| crate::geometry::encloses(tris, e.centre + n * step);
        if inside(e.normal) && inside(-e.normal) {
            continue;
        }
        assert!(!inside(e.normal), "root {r} faces in");
        checked += 1;
    }
    assert!(checked > 200, "{checked} roots checked");
}

#[test]
fn a_triangles_cut_sends_a_point_to_the_leaf_the_distances_choose() {
    use rand::{RngExt, SeedableRng};
    // Triangles that pair into no parallelogram (a rough model's walls),
    // 1-4 m across: halved five to seven times at 0.1 m.
    let triangles: Vec<crate::geometry::Triangle> = vec![
        [[0.0, 0.0, 0.0], [3.9, 0.02, 0.0], [0.3, 2.6, 0.01]],
        [[3.9, 0.02, 0.0], [4.1, 2.7, 0.0], [0.3, 2.6, 0.01]],
        [[0.0, 0.0, 1.0], [1.0, 0.3, 1.2], [0.2, 0.9, 1.1]],
    ]
    .into_iter()
    .map(|t| t.map(glam::Vec3::from_array))
    .collect();
    let patches = mesh_object(&triangles);
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut on_cuts = 0;
    for &root in &patches.roots {
        let Region::Tri(q) = patches.elements[root as usize].region else {
            panic!("root {root} is a quad");
        };
        let inside = |u: f64, v: f64| q[0] + (q[1] - q[0]) * u + (q[2] - q[0]) * v * (1.0 - u);
        for _ in 0..2000 {
            // Inside the root, and beyond its edges (the distances decide).
            for st in [
                inside(rng.random_range(0.0..=1.0), rng.random_range(0.0..=1.0)),
                DVec2::new(rng.random_range(-0.2..1.2), rng.random_range(-0.2..1.2)),
            ] {
                let x = patches.root_point(root, st);
                assert_eq!(
                    patches.patches[patches.locate_in_root(root, x).patch as usize],
                    leaf_by_distances(&patches, root, x),
                    "root {root} at {st}"
                );
            }
        }
        // On a cut: in a leaf that holds the point (both halves do).
        for e in 0..patches.elements.len() {
            let el = &patches.elements[e];
            let (Some([a, _]), true) = (el.children, el.root == root) else {
                continue;
            };
            let Region::Tri([_, m, apex]) = patches.elements[a as usize].region else {
                unreachable!("a triangle's halves are triangles");
            };
            let st = m + (apex - m) * rng.random_range(0.0..=1.0);
            let x = patches.root_point(root, st);
            let leaf = patches.patches[patches.locate_in_root(root, x).patch as usize];
            let off = distance_outside(&patches.elements[leaf as usize].region, st);
            assert!(
                off < 1e-12,
                "root {root}: a point on a cut lies {off} outside its leaf"
            );
            on_cuts += 1;
        }
    }
    assert!(on_cuts > 300, "{on_cuts} points on cuts");
}
