use super::*;
use crate::geometry::Triangle;
use crate::patches::{Shape, SurfaceInput};
use crate::trace::{SurfaceTriangles, Tracer};
use glam::Vec3;
use std::time::Instant;

fn element(shape: Shape) -> Element {
    let p = Patches::build(&[SurfaceInput { surface: 0, triangles: &quad_triangles(shape), is_virtual: false }], 10.0);
    p.elements[0].clone()
}

fn quad_triangles(shape: Shape) -> Vec<Triangle> {
    let c = shape.corners();
    let v = |p: DVec3| p.as_vec3();
    vec![[v(c[0]), v(c[1]), v(c[2])], [v(c[0]), v(c[2]), v(c[3])]]
}

#[test]
fn form_factor_of_parallel_unit_squares_at_distance_one() {
    let p = element(Shape::Quad { origin: DVec3::ZERO, u: DVec3::X, v: DVec3::Z });
    let q = element(Shape::Quad { origin: DVec3::Y, u: DVec3::X, v: DVec3::Z });
    let f = element_form_factor(&p, &q, None);
    let exact = 0.199825;
    println!("parallel unit squares: F = {f:.6} (analytic {exact})");
    assert!((f - exact).abs() < 0.005 * exact, "{f}");
}

#[test]
fn form_factor_of_touching_perpendicular_unit_squares() {
    let p = element(Shape::Quad { origin: DVec3::ZERO, u: DVec3::X, v: DVec3::Z });
    let q = element(Shape::Quad { origin: DVec3::ZERO, u: DVec3::X, v: DVec3::Y });
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
    let inputs: Vec<SurfaceInput> =
        faces.iter().enumerate().map(|(i, t)| SurfaceInput { surface: i as u32, triangles: t, is_virtual: false }).collect();
    let sets: Vec<SurfaceTriangles> = faces.iter().enumerate().map(|(i, t)| SurfaceTriangles { surface: i as u32, triangles: t }).collect();
    let tracer = Tracer::build(&sets, &[]).unwrap();
    let patches = Patches::build(&inputs, 0.125);
    let n = patches.patch_count();
    let emission = vec![DVec3::ONE; n];
    let reflectance = vec![DVec3::splat(rho); n];
    let expected = 1.0 / (1.0 - rho);
    for (name, transport) in [
        ("full", Transport::full(&patches, &tracer, Layer::All)),
        ("hierarchical", Transport::hierarchical(&patches, &tracer, Layer::All, 0.01)),
    ] {
        let t0 = Instant::now();
        let s = solve(&patches, &transport, &reflectance, &emission, 1e-10, 500);
        let gmres_time = t0.elapsed();
        let worst = s.radiosity.iter().map(|b| ((b.x - expected) / expected).abs()).fold(0.0, f64::max);
        let t0 = Instant::now();
        let plain = solve_by_iteration(&patches, &transport, &reflectance, &emission, 1e-6, 20_000);
        let plain_worst = plain.radiosity.iter().map(|b| ((b.x - expected) / expected).abs()).fold(0.0, f64::max);
        println!(
            "furnace rho={rho} {name}: {n} patches, {} links; GMRES {} iterations {:.2?}, worst error {:.2e}; plain gather {} iterations {:.2?}, worst error {:.2e}",
            transport.link_count(), s.iterations, gmres_time, worst, plain.iterations, t0.elapsed(), plain_worst
        );
        assert!(worst < 0.005, "{name}: B off by {worst}");
        assert!(s.residual < 1e-9, "{name}: GMRES stopped at residual {}", s.residual);
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
    let inputs: Vec<SurfaceInput> =
        faces.iter().enumerate().map(|(i, t)| SurfaceInput { surface: i as u32, triangles: t, is_virtual: false }).collect();
    let sets: Vec<SurfaceTriangles> = faces.iter().enumerate().map(|(i, t)| SurfaceTriangles { surface: i as u32, triangles: t }).collect();
    let tracer = Tracer::build(&sets, &[]).unwrap();
    let patches = Patches::build(&inputs, 0.5);
    let t = Transport::full(&patches, &tracer, Layer::All);
    let n = patches.patch_count();
    let s = solve(&patches, &t, &vec![DVec3::ZERO; n], &vec![DVec3::ONE; n], 1e-10, 100);
    assert!(s.radiosity.iter().all(|b| (*b - DVec3::ONE).abs().max_element() < 1e-12), "B = E when nothing reflects");
    let s = solve(&patches, &t, &vec![DVec3::splat(0.7); n], &vec![DVec3::ZERO; n], 1e-10, 100);
    assert!(s.radiosity.iter().all(|b| *b == DVec3::ZERO) && s.residual == 0.0);
}

