use super::form_factor::*;
use super::transport::*;
use super::*;
use crate::geometry::Triangle;
use crate::objects::VirtualBounds;
use crate::patches::{Element, Patches};
use crate::patches::{Shape, SurfaceInput};
use crate::trace::{Layer, TraceRay};
use crate::trace::{SurfaceTriangles, Tracer};
use crate::util::rng::unit_random;
use glam::DVec3;
use glam::{DVec2, Vec3};
use std::time::Instant;

fn element(shape: Shape) -> Element {
    let p = Patches::build(
        &[SurfaceInput {
            surface: 0,
            triangles: &quad_triangles(shape),
            is_virtual: false,
        }],
        10.0,
    );
    p.elements[0].clone()
}

fn quad_triangles(shape: Shape) -> Vec<Triangle> {
    let c = shape.corners();
    let v = |p: DVec3| p.as_vec3();
    vec![[v(c[0]), v(c[1]), v(c[2])], [v(c[0]), v(c[2]), v(c[3])]]
}

#[test]
fn form_factor_of_parallel_unit_squares_at_distance_one() {
    let p = element(Shape::Quad {
        origin: DVec3::ZERO,
        u: DVec3::X,
        v: DVec3::Z,
    });
    let q = element(Shape::Quad {
        origin: DVec3::Y,
        u: DVec3::X,
        v: DVec3::Z,
    });
    let f = element_form_factor(&p, &q, None);
    let exact = 0.199825;
    println!("parallel unit squares: F = {f:.6} (analytic {exact})");
    assert!((f - exact).abs() < 0.005 * exact, "{f}");
}

/// A quad of side `size` (the other side 0.2–0.7 of it) at `at`, turned at random.
fn random_quad(state: &mut u64, at: DVec3, size: f64) -> Element {
    let mut r = || 2.0 * unit_random(state) - 1.0;
    let u = DVec3::new(r(), r(), r()).normalize_or(DVec3::X) * size;
    let w = DVec3::new(r(), r(), r());
    let v = u.cross(w).normalize_or(DVec3::Z) * size * (0.2 + 0.5 * r().abs());
    element(Shape::Quad { origin: at, u, v })
}

#[test]
fn the_far_source_bound_holds_for_every_point_of_the_receiver() {
    // Refinement skips a leaf receiver's factor points where this bound
    // times the source's spread is below ε: it must bound every point
    // factor of the receiver, at any size, turn and distance.
    let mut state = 7u64;
    let (mut tested, mut finite) = (0, 0);
    for _ in 0..400 {
        let size = 0.05 + 0.5 * unit_random(&mut state);
        let p = random_quad(&mut state, DVec3::ZERO, size);
        let at = DVec3::new(
            6.0 * unit_random(&mut state) - 3.0,
            6.0 * unit_random(&mut state) - 3.0,
            6.0 * unit_random(&mut state) - 3.0,
        );
        let size = 0.05 + 0.5 * unit_random(&mut state);
        let q = random_quad(&mut state, at, size);
        let bound = factor_bound(&p, &q);
        assert!(bound > 0.0 && !bound.is_nan(), "{bound}");
        finite += bound.is_finite() as usize;
        let (polygon, corners) = (q.shape.corners(), p.shape.corners());
        let points = (p.shape.quadrature(4).into_iter().map(|(x, _)| x))
            .chain(corners.iter().copied())
            .chain(std::iter::once(p.centre));
        for x in points {
            let f = point_factor(x, &p, &q, &polygon);
            assert!(f <= bound, "factor {f} over the bound {bound}");
            tested += 1;
        }
    }
    // Most pairs lie apart: the bound is finite there.
    assert!(finite > 300, "{finite} of 400 finite");
    println!("{tested} point factors under their bound");
}

#[test]
fn form_factor_of_touching_perpendicular_unit_squares() {
    let p = element(Shape::Quad {
        origin: DVec3::ZERO,
        u: DVec3::X,
        v: DVec3::Z,
    });
    let q = element(Shape::Quad {
        origin: DVec3::ZERO,
        u: DVec3::X,
        v: DVec3::Y,
    });
    let f = element_form_factor(&p, &q, None);
    let exact = 0.200044;
    println!("touching perpendicular unit squares: F = {f:.6} (analytic {exact})");
    assert!((f - exact).abs() < 0.01 * exact, "{f}");
    // Reciprocity with equal areas.
    assert!((element_form_factor(&q, &p, None) - f).abs() < 1e-9);
}

/// The six faces of an axis-aligned box as one surface each.
fn box_faces(size: f32) -> Vec<Vec<Triangle>> {
    let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z) * size;
    let quad = |a: Vec3, b: Vec3, cc: Vec3, d: Vec3| vec![[a, b, cc], [a, cc, d]];
    vec![
        quad(c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)),
        quad(c(0., 1., 0.), c(1., 1., 0.), c(1., 1., 1.), c(0., 1., 1.)),
        quad(c(0., 0., 0.), c(1., 0., 0.), c(1., 1., 0.), c(0., 1., 0.)),
        quad(c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)),
        quad(c(0., 0., 0.), c(0., 1., 0.), c(0., 1., 1.), c(0., 0., 1.)),
        quad(c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)),
    ]
}

fn furnace(rho: f64) {
    let faces = box_faces(1.0);
    let inputs: Vec<SurfaceInput> = faces
        .iter()
        .enumerate()
        .map(|(i, t)| SurfaceInput {
            surface: i as u32,
            triangles: t,
            is_virtual: false,
        })
        .collect();
    let sets: Vec<SurfaceTriangles> = faces
        .iter()
        .enumerate()
        .map(|(i, t)| SurfaceTriangles {
            surface: i as u32,
            triangles: t,
            mask: None,
        })
        .collect();
    let tracer = Tracer::build(&sets, &[]).unwrap();
    let patches = Patches::build(&inputs, 0.125);
    let n = patches.patch_count();
    let emission = vec![DVec3::ONE; n];
    let reflectance = vec![DVec3::splat(rho); n];
    let expected = 1.0 / (1.0 - rho);
    for (name, transport) in [
        ("full", Transport::full(&patches, &tracer, Layer::All)),
        (
            "hierarchical",
            Transport::hierarchical(&patches, &tracer, Layer::All, 0.01),
        ),
    ] {
        let t0 = Instant::now();
        let s = solve(&patches, &transport, &reflectance, &emission, 1e-10, 500);
        let gmres_time = t0.elapsed();
        let worst = s
            .radiosity
            .iter()
            .map(|b| ((b.x - expected) / expected).abs())
            .fold(0.0, f64::max);
        let t0 = Instant::now();
        let plain = solve_by_iteration(&patches, &transport, &reflectance, &emission, 1e-6, 20_000);
        let plain_worst = plain
            .radiosity
            .iter()
            .map(|b| ((b.x - expected) / expected).abs())
            .fold(0.0, f64::max);
        println!(
            "furnace rho={rho} {name}: {n} patches, {} links; GMRES {} iterations {:.2?}, worst error {:.2e}; plain gather {} iterations {:.2?}, worst error {:.2e}",
            transport.link_count(),
            s.iterations,
            gmres_time,
            worst,
            plain.iterations,
            t0.elapsed(),
            plain_worst
        );
        assert!(worst < 0.005, "{name}: B off by {worst}");
        assert!(
            s.residual < 1e-9,
            "{name}: GMRES stopped at residual {}",
            s.residual
        );
        assert!(s.radiosity.iter().all(|b| b.is_finite()));
    }
}

#[test]
fn furnace_box_with_reflectance_one_half() {
    furnace(0.5);
}

#[test]
fn furnace_box_with_reflectance_099_converges() {
    furnace(0.99);
}

#[test]
fn zero_reflectance_and_zero_emission_give_zero_not_nan() {
    let faces = box_faces(1.0);
    let inputs: Vec<SurfaceInput> = faces
        .iter()
        .enumerate()
        .map(|(i, t)| SurfaceInput {
            surface: i as u32,
            triangles: t,
            is_virtual: false,
        })
        .collect();
    let sets: Vec<SurfaceTriangles> = faces
        .iter()
        .enumerate()
        .map(|(i, t)| SurfaceTriangles {
            surface: i as u32,
            triangles: t,
            mask: None,
        })
        .collect();
    let tracer = Tracer::build(&sets, &[]).unwrap();
    let patches = Patches::build(&inputs, 0.5);
    let t = Transport::full(&patches, &tracer, Layer::All);
    let n = patches.patch_count();
    let s = solve(
        &patches,
        &t,
        &vec![DVec3::ZERO; n],
        &vec![DVec3::ONE; n],
        1e-10,
        100,
    );
    assert!(
        s.radiosity
            .iter()
            .all(|b| (*b - DVec3::ONE).abs().max_element() < 1e-12),
        "B = E when nothing reflects"
    );
    let s = solve(
        &patches,
        &t,
        &vec![DVec3::splat(0.7); n],
        &vec![DVec3::ZERO; n],
        1e-10,
        100,
    );
    assert!(s.radiosity.iter().all(|b| *b == DVec3::ZERO) && s.residual == 0.0);
}

/// A unit cube [−1, 0]×[0, 1]×[0, 1] (one closed surface: one-sided faces)
/// standing on a floor from x = `floor_start` to `floor_end` (an open surface).
fn cube_on_floor(floor_start: f32, floor_end: f32, patch_size: f64) -> (Patches, Tracer) {
    let cube: Vec<Triangle> = box_faces(1.0)
        .into_iter()
        .flatten()
        .map(|t| t.map(|v| v - Vec3::X))
        .collect();
    let (a, b, c, d) = (
        Vec3::new(floor_start, 0.0, 0.0),
        Vec3::new(floor_end, 0.0, 0.0),
        Vec3::new(floor_end, 0.0, 1.0),
        Vec3::new(floor_start, 0.0, 1.0),
    );
    let floor: Vec<Triangle> = vec![[a, b, c], [a, c, d]];
    let inputs = [
        SurfaceInput {
            surface: 0,
            triangles: &cube,
            is_virtual: false,
        },
        SurfaceInput {
            surface: 1,
            triangles: &floor,
            is_virtual: false,
        },
    ];
    let sets = [
        SurfaceTriangles {
            surface: 0,
            triangles: &cube,
            mask: None,
        },
        SurfaceTriangles {
            surface: 1,
            triangles: &floor,
            mask: None,
        },
    ];
    (
        Patches::build(&inputs, patch_size),
        Tracer::build(&sets, &[]).unwrap(),
    )
}

#[test]
fn a_solid_s_own_faces_do_not_shadow_what_its_faces_exchange() {
    let (patches, tracer) = cube_on_floor(-3.0, 2.0, 10.0);
    // The cube's faces point out; the open floor may face either way.
    let root_on = |surface: u32, along: fn(DVec3) -> bool| {
        *patches
            .roots
            .iter()
            .find(|&&r| {
                patches.elements[r as usize].surface == surface
                    && along(patches.elements[r as usize].normal)
            })
            .unwrap()
    };
    let face = root_on(0, |n| n.x > 0.99);
    let floor = root_on(1, |n| n.y.abs() > 0.99);
    let (f, q) = (
        &patches.elements[floor as usize],
        &patches.elements[face as usize],
    );
    assert!(q.one_sided && !f.one_sided);
    // The floor runs under the cube and beyond: segments from its hidden part to the
    // face cross the cube, but they carry no light (the face sends none
    // backwards), and from the part in front nothing of the cube is in the way.
    let occluders = occluders_between(&patches, Layer::All, f, q, &patches.roots);
    assert!(
        occluders.is_empty(),
        "the cube's faces {occluders:?} taken for occluders"
    );
    // As tracing says: rays from the floor in front of the face to the face pass.
    let front = element(Shape::Quad {
        origin: DVec3::new(0.0, 0.0, 0.0),
        u: DVec3::X * 2.0,
        v: DVec3::Z,
    });
    assert_eq!(visibility(&front, q, &tracer, Layer::All), 1.0);
}

#[test]
fn a_receiver_partly_behind_a_one_sided_source_gathers_from_the_part_in_front() {
    // The floor reaches 0.1 past the cube's +x face: only that strip sees it.
    let (patches, tracer) = cube_on_floor(-1.0, 0.1, 0.125);
    let transport = Transport::hierarchical(&patches, &tracer, Layer::All, DEFAULT_LINK_EPSILON);
    let face =
        |k: usize| patches.patch(k).surface == 0 && patches.patch(k).normal.dot(DVec3::X) > 0.99;
    let b: Vec<DVec3> = (0..patches.patch_count())
        .map(|k| if face(k) { DVec3::ONE } else { DVec3::ZERO })
        .collect();
    let gathered = transport.gather_rgb(&patches, &b);
    let face_elements: Vec<&Element> = (0..patches.patch_count())
        .filter(|&k| face(k))
        .map(|k| patches.patch(k))
        .collect();
    let (mut got, mut exact, mut area) = (0.0, 0.0, 0.0);
    for k in (0..patches.patch_count()).filter(|&k| patches.patch(k).surface == 1) {
        let p = patches.patch(k);
        got += gathered[k].x * p.area;
        area += p.area;
        // What it gathers: the part of it in front of the face, integrated finely.
        let (lo, hi) = p.bounds;
        if hi.x <= 0.0 {
            continue;
        }
        let strip = element(Shape::Quad {
            origin: DVec3::new(lo.x.max(0.0), 0.0, lo.z),
            u: DVec3::X * (hi.x - lo.x.max(0.0)),
            v: DVec3::Z * (hi.z - lo.z),
        });
        for (x, w) in strip.shape.quadrature(16) {
            exact += strip.area
                * w
                * face_elements
                    .iter()
                    .map(|q| point_factor(x, &strip, q, &q.shape.corners()))
                    .sum::<f64>();
        }
    }
    let (got, exact) = (got / area, exact / area);
    println!("floor partly behind a cube's face: gathers {got:.5}, exact {exact:.5}");
    assert!(
        exact > 0.0 && (got - exact).abs() < 0.05 * exact,
        "gathers {got}, exact {exact}"
    );
}

/// The walls of [`walls_and_a_box`] without and with the box: patches and tracers.
struct Walls {
    room: Patches,
    with: Patches,
    tracer_room: Tracer,
    tracer_with: Tracer,
    cube: Vec<Triangle>,
}

fn walls_with_box(at: Vec3, size: f32) -> Walls {
    let quad = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| vec![[a, b, c], [a, c, d]];
    let left = quad(
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(0.0, 2.0, 2.0),
        Vec3::new(0.0, 0.0, 2.0),
    );
    let right: Vec<Triangle> = left.iter().map(|t| t.map(|v| v + 2.0 * Vec3::X)).collect();
    let cube: Vec<Triangle> = box_faces(size)
        .into_iter()
        .flatten()
        .map(|t| t.map(|v| v + at))
        .collect();
    let walls = [(0, &left), (1, &right)];
    let inputs: Vec<SurfaceInput> = (walls.iter())
        .map(|(s, t)| SurfaceInput {
            surface: *s,
            triangles: t,
            is_virtual: false,
        })
        .collect();
    let sets: Vec<SurfaceTriangles> = (walls.iter())
        .map(|(s, t)| SurfaceTriangles {
            surface: *s,
            triangles: t,
            mask: None,
        })
        .collect();
    let centre = DVec3::new(1.0, 1.0, 1.0);
    let mut room = Patches::build(&inputs, 0.25);
    room.face_open_surfaces_towards(centre);
    let mut with = room.clone();
    with.append(
        &[SurfaceInput {
            surface: 2,
            triangles: &cube,
            is_virtual: true,
        }],
        0.1,
    );
    with.face_open_surfaces_towards(centre);
    let box_set = [SurfaceTriangles {
        surface: 2,
        triangles: &cube,
        mask: None,
    }];
    let (tracer_room, tracer_with) = (
        Tracer::build(&sets, &[]).unwrap(),
        Tracer::build(&sets, &box_set).unwrap(),
    );
    Walls {
        room,
        with,
        tracer_room,
        tracer_with,
        cube,
    }
}

/// A patch of the right wall: its area, and the irradiance it gathers
/// without the box, with it (full matrix), with it as a change, and on
/// the room's links without it.
type WallPatch = (f64, f64, f64, f64, f64);

/// Two facing 2 m walls 2 m apart (x = 0 and x = 2), the left one
/// glowing (B = 1), nothing reflecting, and a black solid box of `size`
/// at `at` (its low corner): per patch of the right wall, the irradiance
/// (its area) without the box, with it by every patch pair traced (the
/// full matrix), and with it as a change to the room's solution (the
/// room's hierarchical links, unchanged, plus what the wall sees of the box
/// in place of what it hides, [`ObjectView`]); last, without the box on
/// the room's hierarchical links. Also the view, and per patch the
/// irradiance lost by brute force ([`traced_loss`]).
fn walls_and_a_box(at: Vec3, size: f32) -> (Vec<WallPatch>, ObjectView, Vec<f64>) {
    let Walls {
        room,
        with,
        tracer_room,
        tracer_with,
        cube,
    } = walls_with_box(at, size);
    // Irradiance per patch of the right wall, the left one glowing.
    let irradiance = |patches: &Patches, transport: &Transport| {
        let n = patches.patch_count();
        let glow: Vec<DVec3> = (0..n)
            .map(|k| DVec3::splat((patches.patch(k).surface == 0) as u8 as f64))
            .collect();
        let s = solve(patches, transport, &vec![DVec3::ZERO; n], &glow, 1e-12, 100);
        (0..n)
            .filter(|&k| patches.patch(k).surface == 1)
            .map(|k| (patches.patch(k).area, s.indirect_irradiance[k].x))
            .collect::<Vec<_>>()
    };
    let epsilon = 0.002;
    let without = irradiance(&room, &Transport::full(&room, &tracer_room, Layer::All));
    let full = irradiance(&with, &Transport::full(&with, &tracer_with, Layer::All));
    let hierarchical = Transport::hierarchical(&room, &tracer_room, Layer::All, epsilon);
    let room_only = irradiance(&room, &hierarchical);
    let bounds = VirtualBounds::of(&[(2, cube.clone())]);
    let view = ObjectView::trace(&with, room.patch_count(), &tracer_with, &bounds);
    // The room's radiosity (the glowing wall) and the box's (black).
    let radiosity: Vec<DVec3> = (0..with.patch_count())
        .map(|k| DVec3::splat((with.patch(k).surface == 0) as u8 as f64))
        .collect();
    let seen = view.irradiance_change(room.patch_count(), &radiosity, &radiosity);
    let changed: Vec<f64> = (0..room.patch_count())
        .filter(|&k| room.patch(k).surface == 1)
        .map(|k| seen[k].x)
        .collect();
    let rows = (without.iter().zip(&full).zip(&room_only).zip(&changed))
        .map(|(((a, b), d), c)| (a.0, a.1, b.1, d.1 + c, d.1))
        .collect();
    let traced = (0..room.patch_count())
        .filter(|&k| room.patch(k).surface == 1)
        .map(|k| traced_loss(room.patch(k), &tracer_with, &tracer_room))
        .collect();
    (rows, view, traced)
}

/// The irradiance a box takes from a patch of the right wall (the left one
/// glowing, B = 1), by brute force: 40,000 cosine-distributed rays from
/// random points of the patch; the fraction that meet the box where they
/// would have met the glowing wall.
fn traced_loss(el: &Element, with: &Tracer, room: &Tracer) -> f64 {
    let point = |s: f64, t: f64| match el.shape {
        Shape::Quad { origin, u, v } => origin + u * s + v * t,
        Shape::Tri([a, b, c]) if s + t > 1.0 => a + (b - a) * (1.0 - s) + (c - a) * (1.0 - t),
        Shape::Tri([a, b, c]) => a + (b - a) * s + (c - a) * t,
    };
    loss_from(point, el.normal, with, room)
}

/// [`traced_loss`] from the points `point(s, t)` for (s, t) uniform in
/// \[0, 1)², facing `normal`.
fn loss_from(
    point: impl Fn(f64, f64) -> DVec3,
    normal: DVec3,
    with: &Tracer,
    room: &Tracer,
) -> f64 {
    let n = 40_000;
    let mut state = 7u64;
    let rays: Vec<TraceRay> = (0..n)
        .map(|_| {
            let x = point(unit_random(&mut state), unit_random(&mut state));
            let d =
                crate::gather::cosine_directions(normal, 1, unit_random(&mut state).to_bits())[0];
            TraceRay::new((x + normal * 1e-5).as_vec3(), d.as_vec3())
        })
        .collect();
    let (mut a, mut b) = (vec![None; n], vec![None; n]);
    with.intersect_batch(&rays, Layer::All, &mut a);
    room.intersect_batch(&rays, Layer::All, &mut b);
    let lost = a.iter().zip(&b).filter(|(a, b)| {
        a.as_ref().is_some_and(|h| h.is_virtual) && b.as_ref().is_some_and(|h| h.surface == 0)
    });
    lost.count() as f64 / n as f64
}

#[test]
fn a_box_between_two_walls_removes_the_light_a_path_through_it_carried() {
    let (patches, _, traced) = walls_and_a_box(Vec3::splat(0.7), 0.6);
    let power = |f: fn(&WallPatch) -> f64| -> f64 { patches.iter().map(|p| p.0 * f(p)).sum() };
    let (lost_full, lost_changed) = (power(|p| p.1 - p.2), power(|p| p.4 - p.3));
    let lost_traced: f64 = patches.iter().zip(&traced).map(|(p, t)| p.0 * t).sum();
    let peak = traced.iter().copied().fold(0.0, f64::max);
    let off: Vec<f64> = (patches.iter().zip(&traced))
        .map(|(p, t)| (p.4 - p.3) - t)
        .collect();
    let worst = off.iter().map(|d| d.abs()).fold(0.0, f64::max);
    let rms = (off.iter().map(|d| d * d).sum::<f64>() / off.len() as f64).sqrt();
    println!(
        "blocked power: full matrix {lost_full:.5}, traced {lost_traced:.5}, as a change {lost_changed:.5}; per patch against the traced loss: worst {:.1}%, rms {:.1}% of the deepest loss",
        100.0 * worst / peak,
        100.0 * rms / peak
    );
    assert!(
        lost_full > 0.02 * power(|p| p.1),
        "the box blocks too little to test"
    );
    for (what, lost) in [("full matrix", lost_full), ("traced", lost_traced)] {
        assert!(
            ((lost_changed - lost) / lost).abs() < 0.05,
            "as a change: {lost_changed} lost against {lost} ({what})"
        );
    }
    // The brute force's own noise is ~1.2% of the deepest loss per patch.
    assert!(
        worst < 0.08 * peak,
        "a patch off by {worst} (deepest loss {peak})"
    );
    assert!(rms < 0.03 * peak, "off by {rms} rms (deepest loss {peak})");
}

#[test]
fn a_box_the_walls_cannot_see_changes_nothing() {
    // Behind the glowing wall: no segment between the walls meets it.
    let (patches, view, _) = walls_and_a_box(Vec3::new(-1.0, 0.7, 0.7), 0.6);
    for (k, p) in patches.iter().enumerate() {
        assert_eq!(p.1.to_bits(), p.2.to_bits(), "full matrix, patch {k}");
        assert_eq!(p.4.to_bits(), p.3.to_bits(), "as a change, patch {k}");
    }
    // No hit kept (each patch's bundle towards the box is empty).
    assert_eq!(view.patch_count(), 0, "no patch sees the box");
}

/// The room patch of the right wall (surface 1) that holds point `x`.
fn right_wall_patch(w: &Walls, x: DVec3) -> usize {
    (0..w.room.patch_count())
        .find(|&k| {
            let el = w.room.patch(k);
            let st = el.shape.params(x);
            el.surface == 1 && st.cmpge(DVec2::ZERO).all() && st.cmple(DVec2::ONE).all()
        })
        .expect("a patch of the right wall holds the point")
}

#[test]
fn near_a_box_the_change_is_held_at_points_finer_than_the_patches() {
    // A black box 5 cm from the right wall: over a 25 cm patch the light it
    // hides there runs from nearly all to a fraction.
    let w = walls_with_box(Vec3::new(1.55, 0.7, 0.7), 0.4);
    let room_count = w.room.patch_count();
    let bounds = VirtualBounds::of(&[(2, w.cube.clone())]);
    let view = ObjectView::trace(&w.with, room_count, &w.tracer_with, &bounds);
    let near = NearView::trace(
        &w.with,
        &ReadPoints::everywhere(room_count),
        &w.tracer_with,
        &bounds,
        0.05,
    );
    let radiosity: Vec<DVec3> = (0..w.with.patch_count())
        .map(|k| DVec3::splat((w.with.patch(k).surface == 0) as u8 as f64))
        .collect();
    let seen = view.irradiance_change(room_count, &radiosity, &radiosity);
    let coarse = w.room.vertex_values(&seen);
    let field = near.field(&w.with, &radiosity, &radiosity[..room_count], &coarse);
    assert!(field.patch_count() > 0, "no patch holds a grid");
    let normal = -DVec3::X;
    let points: Vec<(usize, DVec3)> = [
        (0.9, 0.9),
        (1.05, 0.9),
        (1.2, 1.0),
        (1.3, 0.8),
        (0.6, 0.6),
        (1.1, 1.25),
    ]
    .map(|(y, z)| {
        let x = DVec3::new(2.0, y, z);
        (right_wall_patch(&w, x), x)
    })
    .to_vec();
    // Traced only where these points read it: the same values there, bit
    // for bit, for a fraction of the rays.
    let read = ReadPoints::of(room_count, || {
        points.iter().map(|&(k, x)| (k as u32, x.as_vec3()))
    });
    let sparse = NearView::trace(&w.with, &read, &w.tracer_with, &bounds, 0.05);
    let sparse_field = sparse.field(&w.with, &radiosity, &radiosity[..room_count], &coarse);
    for &(k, x) in &points {
        // Read where a pixel's point is held (in f32), as the composite does.
        let x = x.as_vec3().as_dvec3();
        let (a, b) = (field.at(k as u32, x), sparse_field.at(k as u32, x));
        assert_eq!(
            a.map(|a| a.to_array().map(f64::to_bits)),
            b.map(|b| b.to_array().map(f64::to_bits))
        );
    }
    println!(
        "rays: {} at every point, {} where read",
        near.rays, sparse.rays
    );
    assert!(sparse.rays > 0 && 4 * sparse.rays < near.rays);
    let (mut worst_near, mut worst_coarse, mut deepest) = (0.0f64, 0.0f64, 0.0f64);
    for &(k, x) in &points {
        let (y, z) = (x.y, x.z);
        let el = w.room.patch(k);
        let st = el.shape.params(x);
        let corners = w.room.patch_vertices[k].map(|v| coarse[v as usize].x);
        let patch_mean = corners[0] * (1.0 - st.x) * (1.0 - st.y)
            + corners[1] * st.x * (1.0 - st.y)
            + corners[2] * st.x * st.y
            + corners[3] * (1.0 - st.x) * st.y;
        let fine = patch_mean + field.at(k as u32, x).map_or(0.0, |c| c.x);
        let truth = -loss_from(|_, _| x, normal, &w.tracer_with, &w.tracer_room);
        println!(
            "({y}, {z}): traced {truth:.4}, patch means {patch_mean:.4}, with the points {fine:.4}"
        );
        worst_near = worst_near.max((fine - truth).abs());
        worst_coarse = worst_coarse.max((patch_mean - truth).abs());
        deepest = deepest.max(truth.abs());
    }
    // 256 rays a point at most: ~2.7% noise of a hemisphere's irradiance,
    // four points interpolated.
    assert!(
        worst_near < 0.08 * deepest,
        "off by {worst_near} with the points (deepest {deepest})"
    );
    assert!(
        worst_coarse > 4.0 * worst_near,
        "the patch means are as good: {worst_coarse} against {worst_near}"
    );
}

/// The per-pixel residual's estimator of the objects' change at a room
/// point ([`ChangeSampler`], what `--samples` rounds average) against a
/// brute-force trace of the same change (40,000 rays a point): with the
/// exact value as the control variate the residual is zero in expectation.
/// Sixteen independent scramblings (seeds) of 64 rounds each give the
/// estimate and its standard error (randomised quasi-Monte Carlo); their
/// mean must lie within 4 standard errors of the truth, and 64 rounds
/// must come closer than 4.
#[test]
fn rounds_of_the_per_point_estimator_converge_to_the_traced_change() {
    let w = walls_with_box(Vec3::new(1.55, 0.7, 0.7), 0.4);
    let room_count = w.room.patch_count();
    let bounds = VirtualBounds::of(&[(2, w.cube.clone())]);
    let sampler = ChangeSampler::new(&w.with, &bounds, room_count, &w.tracer_with);
    // Radiance: the glowing wall's 1/π (B = 1), the black box's none.
    let read = |h: &crate::trace::Hit, _: DVec3, _: DVec3, _: u64| {
        let glows = !h.is_virtual && h.surface == 0;
        (DVec3::splat(glows as u8 as f64 / std::f64::consts::PI), 0)
    };
    let (mut early, mut late) = (0.0f64, 0.0f64);
    for (y, z) in [(0.9, 0.9), (1.05, 0.9), (1.3, 0.8), (0.6, 0.6), (1.1, 1.25)] {
        let x = DVec3::new(2.0, y, z);
        let k = right_wall_patch(&w, x);
        let truth = -loss_from(|_, _| x, -DVec3::X, &w.tracer_with, &w.tracer_room);
        // Per seed, the mean after 4 and after 64 rounds.
        let estimates: Vec<(f64, f64)> = (0..16u64)
            .map(|seed| {
                let (mut sum, mut count, mut after_4) = (0.0, 0usize, 0.0);
                for round in 0..64 {
                    sampler.sample(k as u32, x, (seed, round), &read, &mut |v: DVec3| {
                        sum += v.x;
                        count += 1;
                    });
                    if round == 3 {
                        after_4 = sum / count as f64;
                    }
                }
                assert!(count > 0, "no ray at {x}");
                (after_4, sum / count as f64)
            })
            .collect();
        let m = estimates.len() as f64;
        let mean = estimates.iter().map(|e| e.1).sum::<f64>() / m;
        let var = estimates.iter().map(|e| (e.1 - mean).powi(2)).sum::<f64>() / (m - 1.0);
        // With the brute force's own error (a fraction of 40,000 rays).
        let se = (var / m + truth.abs() * (1.0 - truth.abs()) / 40_000.0).sqrt();
        let rms = |f: fn(&(f64, f64)) -> f64| {
            (estimates
                .iter()
                .map(|e| (f(e) - truth).powi(2))
                .sum::<f64>()
                / m)
                .sqrt()
        };
        let (e4, e64) = (rms(|e| e.0), rms(|e| e.1));
        println!(
            "({y}, {z}): traced {truth:.4}; 16 × 64 rounds {mean:.4} ± {se:.4}; rms error of one seed: 4 rounds {e4:.4}, 64 rounds {e64:.4}"
        );
        assert!(
            (mean - truth).abs() < 4.0 * se,
            "({y}, {z}): {mean} against {truth} (standard error {se})"
        );
        early += e4 * e4;
        late += e64 * e64;
    }
    assert!(
        late < early / 4.0,
        "64 rounds not closer than 4: squared error {late} against {early}"
    );
}

#[test]
fn a_transport_gives_back_its_links_with_their_receivers_in_order() {
    let link = |receiver, source, form_factor| Link {
        receiver,
        source,
        form_factor,
    };
    let given = vec![
        link(3, 1, 0.25),
        link(0, 2, 0.5),
        link(3, 0, 0.125),
        link(1, 3, 1.0),
    ];
    let transport = Transport::hierarchical_from_links(given.clone());
    let back: Vec<Link> = transport.links().collect();
    let mut sorted = given;
    sorted.sort_by_key(|l| (l.receiver, l.source));
    assert_eq!(back, sorted);
    assert_eq!(transport.link_count(), 4);
    assert_eq!(transport.memory_bytes(), 4 * 8 + 3 * 12);
}
