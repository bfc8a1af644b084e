use super::*;
use crate::light::{test_panel, test_spot};
use crate::objects::clear_sides;
use crate::trace::SurfaceTriangles;
use glam::Vec3;
use std::collections::HashSet;

/// The 12 triangles of the box lo..hi, wound outwards.
fn cube(lo: Vec3, hi: Vec3) -> Vec<crate::geometry::Triangle> {
    let c = |i: usize| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let quads = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    quads
        .iter()
        .flat_map(|q| [[c(q[0]), c(q[1]), c(q[2])], [c(q[0]), c(q[2]), c(q[3])]])
        .collect()
}

/// A tracer holding one virtual object (surface 7) and no room.
fn object_only(triangles: &[crate::geometry::Triangle]) -> Tracer {
    Tracer::build(
        &[],
        &[SurfaceTriangles {
            surface: 7,
            triangles,
            mask: None,
        }],
    )
    .unwrap()
}

#[test]
fn a_solids_faces_are_clear_of_it_where_nothing_of_it_lies_in_front() {
    let (lo, hi) = (Vec3::ZERO, Vec3::splat(0.3));
    let one = cube(lo, hi);
    let centre = (lo + hi) / 2.0;
    for (t, side) in one.iter().zip(clear_sides(&one, 1.0)) {
        let outward = (t[0] + t[1] + t[2]) / 3.0 - centre;
        assert!(
            side.dot(outward) > 0.0 && (side.length() - 1.0).abs() < 1e-6,
            "{t:?}: {side}"
        );
    }
    // Two boxes as one solid: a face turned to the other box is not clear.
    let mut two = one.clone();
    two.extend(cube(Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.3, 0.3, 0.3)));
    let sides = clear_sides(&two, 1.3);
    let facing = |t: &crate::geometry::Triangle| {
        t.iter().all(|p| p.x == 0.3) || t.iter().all(|p| p.x == 1.0)
    };
    for (t, side) in two.iter().zip(&sides) {
        assert_eq!(*side == Vec3::ZERO, facing(t), "{t:?}: {side}");
    }
    // An open box is no solid: its inside may shadow its faces.
    assert!(
        clear_sides(&one[..10], 1.0)
            .iter()
            .all(|s| *s == Vec3::ZERO)
    );
}

#[test]
fn a_face_clear_of_its_solid_gets_the_light_tracing_the_solid_gives() {
    let boxed = cube(Vec3::new(-0.15, 0.0, -0.15), Vec3::new(0.15, 0.3, 0.15));
    let tracer = object_only(&boxed);
    let bounds = VirtualBounds::of(&[(7, boxed.clone())]);
    // Panels whose planes cut the box's side faces' planes: part of each
    // light lies behind a side face, where only the solid blocks it.
    let lights = [
        test_panel(DVec3::new(0.0, 1.0, 0.0)),
        test_panel(DVec3::new(0.2, 0.6, -0.1)),
        test_spot(DVec3::new(0.5, 0.8, 0.3)),
        test_spot(DVec3::new(0.1, 0.2, 0.9)),
    ];
    let settings = PdaSettings::default();
    let (mut compared, mut saved) = (0, 0);
    for (k, t) in boxed.iter().enumerate() {
        let [a, b, c] = t.map(|p| p.as_dvec3());
        let n = (b - a).cross(c - a).normalize();
        let hit = Hit {
            surface: 7,
            triangle: k as u32,
            u: 0.0,
            v: 0.0,
            t: 1.0,
            normal: n.as_vec3(),
            is_virtual: true,
        };
        assert!(bounds.is_clear_of_own(&hit));
        for (i, (s, r)) in [(0.2, 0.3), (0.6, 0.2), (0.25, 0.5)]
            .into_iter()
            .enumerate()
        {
            let x = a + (b - a) * s + (c - a) * r;
            for (l, light) in lights.iter().enumerate() {
                let seed = (k * 16 + i * 4 + l) as u64;
                let q = LightQuery {
                    tracer: &tracer,
                    light,
                    bounds: &bounds,
                    settings,
                };
                let p = TermPoint {
                    x,
                    n,
                    own: None,
                    seed,
                };
                let (traced, all_rays) = light_term(q, p, None, None);
                let own = TermPoint { own: Some(0), ..p };
                let (known, fewer) = light_term(q, own, None, None);
                assert_eq!(known, traced, "face {k}, point {i}, light {l}");
                compared += 1;
                saved += all_rays - fewer;
            }
        }
    }
    assert!(
        compared == 144 && saved > 0,
        "{compared} terms, {saved} rays saved"
    );
}

#[test]
fn only_edges_with_a_polygon_on_either_side_in_the_image_are_no_outline() {
    let eye = |at: DVec3| {
        Camera::new(
            64,
            64,
            at,
            DVec3::splat(0.5),
            DVec3::Y,
            crate::camera::Projection::FovY { degrees: 60.0 },
        )
        .unwrap()
    };
    let roots_of = |triangles: &[crate::geometry::Triangle]| {
        let patches = Patches::build(
            &[crate::patches::SurfaceInput {
                surface: 7,
                triangles,
                is_virtual: true,
            }],
            0.5,
        );
        patches
            .roots
            .iter()
            .map(|&r| patches.elements[r as usize].clone())
            .collect::<Vec<_>>()
    };
    let boxed = cube(Vec3::ZERO, Vec3::ONE);
    let roots = roots_of(&boxed);
    let roots: Vec<&crate::patches::Element> = roots.iter().collect();
    assert_eq!(roots.len(), 6);
    // The edges meeting at (1,1,1), and those meeting at (0,0,0), along x, y, z.
    let near: Vec<EdgeKey> = [DVec3::X, DVec3::Y, DVec3::Z]
        .iter()
        .map(|a| edge_key(DVec3::ONE, DVec3::ONE - *a))
        .collect();
    let far: Vec<EdgeKey> = [DVec3::X, DVec3::Y, DVec3::Z]
        .iter()
        .map(|a| edge_key(DVec3::ZERO, *a))
        .collect();
    let set = |keys: &[EdgeKey]| keys.iter().copied().collect::<HashSet<_>>();
    // Seeing the faces x = 1, y = 1 and z = 1: the three edges between two
    // of them and the three between two unseen faces; the six others are
    // the outline.
    assert_eq!(
        interior_edges(&eye(DVec3::new(3.0, 2.0, 2.5)), &roots),
        set(&[near.clone(), far.clone()].concat())
    );
    // The face y = 1 seen edge-on: its edges are outline, as are those
    // between a seen face and an unseen one.
    assert_eq!(
        interior_edges(&eye(DVec3::new(3.0, 1.0, 2.5)), &roots),
        set(&[near[1], far[0], far[1], far[2]])
    );
    // An edge whose ends differ in the last bit is taken for outline.
    let mut moved = boxed.clone();
    moved
        .iter_mut()
        .flatten()
        .filter(|p| **p == Vec3::ONE)
        .for_each(|p| p.x = f32::from_bits(p.x.to_bits() - 1));
    let roots = roots_of(&moved);
    let roots: Vec<&crate::patches::Element> = roots.iter().collect();
    assert!(interior_edges(&eye(DVec3::new(3.0, 2.0, 2.5)), &roots).is_disjoint(&set(&near)));
    // An open surface folded along x = 1, z: a floor panel and a wall
    // panel. From outside the wall the floor lies behind it, and the
    // fold is outline; from the floor's side the two meet in the image.
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let folded = vec![
        [v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(1.0, 0.0, 1.0)],
        [v(0.0, 0.0, 0.0), v(1.0, 0.0, 1.0), v(0.0, 0.0, 1.0)],
        [v(1.0, 0.0, 0.0), v(1.0, 1.0, 0.0), v(1.0, 1.0, 1.0)],
        [v(1.0, 0.0, 0.0), v(1.0, 1.0, 1.0), v(1.0, 0.0, 1.0)],
    ];
    // As a render meshes it: both panels turned to the camera, so their
    // normals alone would call the fold seen from outside no outline.
    let fold = edge_key(DVec3::new(1.0, 0.0, 0.0), DVec3::new(1.0, 0.0, 1.0));
    for (at, expected) in [
        (DVec3::new(3.0, 2.0, 2.5), set(&[])),
        (DVec3::new(-2.0, 2.0, 2.5), set(&[fold])),
    ] {
        let mut patches = Patches::build(
            &[crate::patches::SurfaceInput {
                surface: 7,
                triangles: &folded,
                is_virtual: true,
            }],
            0.5,
        );
        patches.face_open_surfaces_towards(at);
        let roots = root_elements(&patches);
        assert!(roots.len() == 2 && roots.iter().all(|e| (at - e.centre).dot(e.normal) > 0.0));
        assert_eq!(interior_edges(&eye(at), &roots), expected, "seen from {at}");
    }
}

#[test]
fn an_object_the_room_cannot_shadow_gets_the_light_tracing_the_room_gives() {
    let boxed = cube(Vec3::new(-0.15, 0.0, -0.15), Vec3::new(0.15, 0.3, 0.15));
    // The floor the box stands on, and a table top above it.
    let (f0, f1, f2, f3) = (
        Vec3::new(-2.0, 0.0, -2.0),
        Vec3::new(-2.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, -2.0),
    );
    let floor = vec![[f0, f1, f2], [f0, f2, f3]];
    let top = cube(Vec3::new(-0.5, 0.7, -0.5), Vec3::new(0.5, 0.75, 0.5));
    let polygons = |t: &[crate::geometry::Triangle]| -> Vec<Vec<DVec3>> {
        t.chunks(2)
            .map(|q| {
                [q[0][0], q[0][1], q[0][2], q[1][2]]
                    .iter()
                    .map(|p| p.as_dvec3())
                    .collect()
            })
            .collect()
    };
    // The spot beside the box, below the table top.
    let lights = [
        test_panel(DVec3::new(0.0, 1.2, 0.0)),
        test_spot(DVec3::new(1.5, 0.5, 0.3)),
    ];
    let settings = PdaSettings::default();
    let (mut compared, mut saved) = (0, 0);
    for (room, expected) in [
        (floor.clone(), [true, true]),
        ([floor.clone(), top.clone()].concat(), [false, true]),
    ] {
        let tracer = Tracer::build(
            &[SurfaceTriangles {
                surface: 1,
                triangles: &room,
                mask: None,
            }],
            &[SurfaceTriangles {
                surface: 7,
                triangles: &boxed,
                mask: None,
            }],
        )
        .unwrap();
        let bounds = VirtualBounds::of(&[(7, boxed.clone())]).with_room(&polygons(&room), &lights);
        assert_eq!(bounds.room_clear, vec![expected.to_vec()]);
        for (k, t) in boxed.iter().enumerate() {
            let [a, b, c] = t.map(|p| p.as_dvec3());
            let n = (b - a).cross(c - a).normalize();
            for (i, (s, r)) in [(0.2, 0.3), (0.6, 0.2), (0.01, 0.01)]
                .into_iter()
                .enumerate()
            {
                let x = a + (b - a) * s + (c - a) * r;
                for (l, light) in lights.iter().enumerate() {
                    let seed = (k * 16 + i * 4 + l) as u64;
                    let q = LightQuery {
                        tracer: &tracer,
                        light,
                        bounds: &bounds,
                        settings,
                    };
                    let p = TermPoint {
                        x,
                        n,
                        own: Some(0),
                        seed,
                    };
                    let (traced, all_rays) = light_term(q, p, None, None);
                    let mut clear = RealMask::CLEAR;
                    let (known, fewer) = light_term(q, p, None, expected[l].then_some(&mut clear));
                    assert_eq!(known, traced, "face {k}, point {i}, light {l}");
                    compared += 1;
                    saved += all_rays - fewer;
                }
            }
        }
    }
    assert!(
        compared == 144 && saved > 0,
        "{compared} terms, {saved} rays saved"
    );
}

#[test]
fn pixels_across_a_crease_of_an_object_are_shaded_per_sub_pixel() {
    let boxed = cube(Vec3::splat(-0.5), Vec3::splat(0.5));
    let input = |triangles| crate::patches::SurfaceInput {
        surface: 7,
        triangles,
        is_virtual: true,
    };
    // Every edge of a box is a crease; a flat panel of several polygons has none.
    let patches = Patches::build(&[input(&boxed)], 0.25);
    assert_eq!(crease_edges(&root_elements(&patches)).len(), 12);
    let v = |x: f32, z: f32| Vec3::new(x, 0.0, z);
    let flat = vec![
        [v(0.0, 0.0), v(1.0, 0.0), v(1.0, 1.0)],
        [v(0.0, 0.0), v(1.0, 1.0), v(0.0, 1.0)],
        [v(1.0, 0.0), v(2.0, 0.0), v(2.0, 1.0)],
        [v(1.0, 0.0), v(2.0, 1.0), v(1.0, 1.0)],
    ];
    let panel = Patches::build(&[input(&flat)], 2.0);
    let roots = root_elements(&panel);
    assert!(roots.len() >= 2 && crease_edges(&roots).is_empty());

    // The box seen from above a corner, lit from one side: its three
    // faces in view take three different lights.
    let tracer = object_only(&boxed);
    let camera = Camera::new(
        48,
        48,
        DVec3::new(2.0, 1.6, 2.4),
        DVec3::ZERO,
        DVec3::Y,
        crate::camera::Projection::FovY { degrees: 40.0 },
    )
    .unwrap();
    let bounds = VirtualBounds::of(&[(7, boxed.clone())]);
    let lights = [test_spot(DVec3::new(2.5, 2.0, 0.3))];
    let build = |shaded_per_pixel| {
        PixelDataArray::build(&PdaInput {
            camera: &camera,
            tracer: &tracer,
            patches: &patches,
            lights: &lights,
            active: &[true],
            bounds: &bounds,
            settings: PdaSettings::default(),
            for_updates: false,
            band: None,
            shaded_per_pixel,
        })
    };
    let pda = build(&[]);
    let full = pda.supersample * pda.supersample;
    // With a material, whose samples spread over the pixel each at its
    // own point, a pixel wholly on the box is one pixel whatever faces
    // cross it; its outline's pixels still mix box and background.
    let shaded = build(&[7]);
    let outline = |pda: &PixelDataArray| -> Vec<u32> {
        (pda.edges.iter())
            .filter(|e| e.count < full)
            .map(|e| e.pixel)
            .collect()
    };
    assert!(shaded.edges.iter().all(|e| e.count < full));
    assert_eq!(outline(&shaded), outline(&pda));
    assert!(shaded.virtual_pixels.len() == pda.virtual_pixels.len());
    let planes = |e: &EdgePixel| {
        let points = &pda.edge_samples.points[e.start as usize..(e.start + e.count) as usize];
        let mut normals: Vec<Vec3> = Vec::new();
        for p in points.iter().filter(|p| p.is_virtual) {
            if normals.iter().all(|n| n.dot(p.normal) < 0.99) {
                normals.push(p.normal);
            }
        }
        normals.len()
    };
    // Pixels wholly on the box with sub-pixels on two or three faces.
    let inside: Vec<&EdgePixel> = pda.edges.iter().filter(|e| e.count == full).collect();
    assert!(inside.iter().all(|e| planes(e) >= 2));
    // Every pixel a crease in view passes close to its centre is one of
    // them or an outline pixel (the 2 × 2 sub-pixels about the centre lie
    // either side of a line within 0.125 of it): the three edges from the
    // corner nearest the camera.
    let near = DVec3::splat(0.5);
    let mut checked = 0;
    for end in [
        DVec3::new(-0.5, 0.5, 0.5),
        DVec3::new(0.5, -0.5, 0.5),
        DVec3::new(0.5, 0.5, -0.5),
    ] {
        for k in 1..400 {
            let x = near + (end - near) * (k as f64 / 400.0);
            let (px, py, _) = camera.project(x).unwrap();
            if (px.fract() - 0.5).abs() > 0.08 || (py.fract() - 0.5).abs() > 0.08 {
                continue;
            }
            checked += 1;
            let pixel = py as u32 * 48 + px as u32;
            assert!(
                pda.edges.iter().any(|e| e.pixel == pixel),
                "pixel {px:.1}, {py:.1} on the crease to {end}"
            );
        }
    }
    assert!(
        checked >= 6 && inside.len() >= 20,
        "{checked} checked, {} crease pixels",
        inside.len()
    );
}

/// A mesh's root elements.
fn root_elements(patches: &Patches) -> Vec<&crate::patches::Element> {
    patches
        .roots
        .iter()
        .map(|&r| &patches.elements[r as usize])
        .collect()
}
