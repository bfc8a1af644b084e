use super::*;
use crate::trace::{SurfaceTriangles, Tracer};
use std::f64::consts::PI;

/// Form factor from a point under the corner of an X×Y rectangle at height h, parallel.
fn corner_ff(x: f64, y: f64, h: f64) -> f64 {
    let (a, b) = ((x * x + h * h).sqrt(), (y * y + h * h).sqrt());
    (x / a * (y / a).atan() + y / b * (x / b).atan()) / (2.0 * PI)
}

fn square(c: DVec3, half: f64) -> [DVec3; 4] {
    [
        c + DVec3::new(-half, 0.0, -half),
        c + DVec3::new(half, 0.0, -half),
        c + DVec3::new(half, 0.0, half),
        c + DVec3::new(-half, 0.0, half),
    ]
}

#[test]
fn point_to_polygon_form_factor_is_analytic_and_finite_when_close() {
    for h in [2.0, 1.0, 0.1, 1e-3, 1e-6] {
        let f = polygon_form_factor(DVec3::ZERO, DVec3::Y, &square(DVec3::new(0.0, h, 0.0), 0.5));
        let exact = 4.0 * corner_ff(0.5, 0.5, h);
        assert!((f - exact).abs() < 1e-9, "h {h}: {f} vs {exact}");
        assert!(f <= 1.0);
    }
    // Two-sided: the same from below, and a polygon across the tangent plane counts both parts.
    let below = polygon_form_factor(
        DVec3::ZERO,
        DVec3::NEG_Y,
        &square(DVec3::new(0.0, 1.0, 0.0), 0.5),
    );
    assert!((below - 4.0 * corner_ff(0.5, 0.5, 1.0)).abs() < 1e-12);
    let edge_on = polygon_form_factor(
        DVec3::ZERO,
        DVec3::Y,
        &[
            DVec3::new(-1.0, 0.0, 1.0),
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(1.0, 0.0, 2.0),
            DVec3::new(-1.0, 0.0, 2.0),
        ],
    );
    assert_eq!(
        edge_on, 0.0,
        "a polygon in the tangent plane is seen edge-on"
    );
}

#[test]
fn spot_falls_off_linearly_and_integrates_to_its_closed_form_power() {
    let (beam, cutoff) = (15f64.to_radians(), 30f64.to_radians());
    let spot = Distribution::Spot {
        axis: DVec3::NEG_Y,
        rgb: DVec3::new(20.0, 17.0, 13.0),
        beam,
        cutoff,
    };
    let at = |angle: f64| spot.intensity(DVec3::new(angle.sin(), -angle.cos(), 0.0)).x;
    assert_eq!(at(0.1), 20.0);
    assert!((at(22.5f64.to_radians()) - 10.0).abs() < 1e-9);
    assert_eq!(at(31f64.to_radians()), 0.0);
    // Power = 2π I [1 − (sin c − sin b)/(c − b)]; midpoint rule in θ.
    let n = 200_000;
    let mut power = 0.0;
    for i in 0..n {
        let theta = (i as f64 + 0.5) * PI / n as f64;
        power += at(theta) * theta.sin() * 2.0 * PI * PI / n as f64;
    }
    let exact = 2.0 * PI * 20.0 * (1.0 - (cutoff.sin() - beam.sin()) / (cutoff - beam));
    assert!((power - exact).abs() < 1e-3 * exact, "{power} vs {exact}");
}

fn panel(scale: f64) -> LightSource {
    let (u, v) = (DVec3::new(0.6, 0.0, 0.0), DVec3::new(0.0, 0.0, 0.6));
    LightSource {
        name: "panel".into(),
        real: true,
        scale,
        position: DVec3::new(0.0, 2.0, 0.0),
        emitter: Emitter::Rect {
            u,
            v,
            normal: u.cross(v).normalize(),
        },
        distribution: Distribution::Lambertian {
            normal: DVec3::NEG_Y,
            rgb: DVec3::splat(4.0),
        },
        grid: Some(JitteredGrid::new(0.6, 0.6, 1)),
    }
}

#[test]
fn lambertian_rect_tends_to_a_point_light_far_away_and_is_dark_behind() {
    let p = panel(1.0);
    let far = DVec3::new(0.0, -98.0, 0.0);
    let e = p.unoccluded_irradiance(far, DVec3::Y).x;
    assert!((e - 4.0 / 100.0f64.powi(2)).abs() < 1e-4 * e, "{e}");
    // At 45° off axis the intensity is I0·cos45 and the receiver cosine another cos45.
    let x = DVec3::new(70.0, 2.0 - 70.0, 0.0);
    let e = p.unoccluded_irradiance(x, DVec3::Y).x;
    let expect = 4.0 * 0.5f64.sqrt() * 0.5f64.sqrt() / (2.0 * 70.0 * 70.0);
    assert!((e - expect).abs() < 1e-4 * expect, "{e} vs {expect}");
    assert_eq!(
        p.unoccluded_irradiance(DVec3::new(0.0, 3.0, 0.0), DVec3::Y),
        DVec3::ZERO
    );
}

#[test]
fn lights_millimetres_away_and_at_grazing_angles_stay_finite() {
    let p = panel(1.0);
    let near = p.unoccluded_irradiance(DVec3::new(0.0, 1.999, 0.0), DVec3::Y);
    // At 1 mm under the middle of a Lambertian panel of radiance L: E → π L.
    let radiance = 4.0 / 0.36;
    assert!(
        near.is_finite() && (near.x - PI * radiance).abs() < 0.01 * PI * radiance,
        "{near}"
    );
    let grazing = p.unoccluded_irradiance(DVec3::new(5.0, 1.999, 0.0), DVec3::Y);
    assert!(grazing.is_finite() && grazing.x >= 0.0);
    let bulb = Distribution::Uniform(DVec3::splat(6.0));
    let e = point_contribution(DVec3::new(0.0, 1e-3, 0.0), DVec3::ZERO, DVec3::Y, |d| {
        bulb.intensity(d)
    });
    assert!(e.is_finite() && (e.x - 6.0e6).abs() < 1.0, "{e}");
    let e = point_contribution(DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0), DVec3::Y, |d| {
        bulb.intensity(d)
    });
    assert_eq!(e, DVec3::ZERO, "grazing incidence");
}

#[test]
fn the_jittered_grid_is_stratified_nested_and_deterministic() {
    let g = JitteredGrid::new(0.6, 0.3, 9);
    for level in 0..=MAX_GRID_LEVEL {
        let pts: Vec<DVec2> = g.samples(level, 42).collect();
        assert_eq!(pts.len(), 1 << level);
        assert!(
            pts.iter()
                .all(|p| p.x >= 0.0 && p.x <= 1.0 && p.y >= 0.0 && p.y <= 1.0)
        );
        assert_eq!(pts, g.samples(level, 42).collect::<Vec<_>>());
    }
    // Level 3 of a 2:1 rectangle: split u, then the 0.3×0.3 halves into 2×2: a 4×2 grid.
    let mut counts = [[0; 2]; 4];
    for p in g.samples(3, 7) {
        counts[(p.x * 4.0) as usize][(p.y * 2.0) as usize] += 1;
    }
    assert_eq!(counts, [[1; 2]; 4], "one sample per cell");
    assert_ne!(
        g.samples(4, 1).collect::<Vec<_>>(),
        g.samples(4, 2).collect::<Vec<_>>(),
        "seeds pick different points"
    );
}

#[test]
fn half_a_panel_hidden_behind_a_wall_gives_half_visibility() {
    let p = panel(1.0);
    // A wall in the plane x = 0 from the floor to 1.9 m: the receiver at x = -1 sees the x<0 half.
    let wall = vec![
        [
            glam::Vec3::new(0.0, 0.0, -5.0),
            glam::Vec3::new(0.0, 1.99, -5.0),
            glam::Vec3::new(0.0, 1.99, 5.0),
        ],
        [
            glam::Vec3::new(0.0, 0.0, -5.0),
            glam::Vec3::new(0.0, 1.99, 5.0),
            glam::Vec3::new(0.0, 0.0, 5.0),
        ],
    ];
    let tracer = Tracer::build(
        &[SurfaceTriangles {
            surface: 0,
            triangles: &wall,
            mask: None,
        }],
        &[],
    )
    .unwrap();
    let x = DVec3::new(-0.01, 0.0, 0.0);
    let d = p.direct(&tracer, Layer::All, x, DVec3::Y, 8, 3);
    assert_eq!(d.rays, 256);
    assert!((d.visibility - 0.5).abs() < 0.03, "{}", d.visibility);
    let clear = p.direct(
        &tracer,
        Layer::All,
        DVec3::new(-1.0, 1.5, 0.0),
        DVec3::Y,
        4,
        3,
    );
    assert!(clear.visibility > 0.0);
}

#[test]
fn the_polygon_factors_angle_matches_atan2_to_the_last_places() {
    let mut worst: f64 = 0.0;
    let mut state = 11u64;
    for k in 0..200_000 {
        // Wide magnitudes, both signs of x.
        let y = unit_random(&mut state) * 10f64.powi((k % 13) - 6);
        let x = (unit_random(&mut state) - 0.5) * 10f64.powi((k % 11) - 5);
        let (exact, ours) = (y.atan2(x), angle_atan2(y, x));
        worst = worst.max((ours - exact).abs() / exact.abs().max(1e-300));
    }
    assert!(worst < 4.0 * f64::EPSILON, "worst relative error {worst:e}");
    // Exact edges, and where the reduction switches branches.
    let t3 = 2.414_213_562_373_095;
    for (y, x) in [
        (0.0f64, 1.0f64),
        (0.0, -1.0),
        (1.0, 0.0),
        (0.0, 0.0),
        (1e-300, 1.0),
        (1.0, 1e-300),
        (1.0, -1e-300),
        (1.0, 1.0),
        (1.0, -1.0),
        (0.66, 1.0),
        (t3, 1.0),
        (t3, -1.0),
    ] {
        let (exact, ours) = (y.atan2(x), angle_atan2(y, x));
        assert!(
            (ours - exact).abs() <= 4.0 * f64::EPSILON * exact.abs(),
            "atan2({y}, {x}): {ours} against {exact}"
        );
    }
}

#[test]
fn the_factors_at_four_points_at_once_are_the_single_points_bit_for_bit() {
    // Points in front of, behind, beside and in the plane of a quad and a
    // triangle, with tangent planes that cut them (the clipping path), at
    // polygon corners (zero-length edges' cross products) and far off.
    let quad = square(DVec3::new(0.2, 1.0, -0.1), 0.5);
    let tri = [
        DVec3::new(-0.4, 0.3, 0.2),
        DVec3::new(0.7, 0.9, -0.3),
        DVec3::new(0.1, 1.6, 0.8),
    ];
    let mut state = 5u64;
    let mut r = |scale: f64| (unit_random(&mut state) - 0.5) * scale;
    let (mut clipped, mut compared) = (0, 0);
    for trial in 0..4000 {
        let polygon: &[DVec3] = if trial % 2 == 0 { &quad } else { &tri };
        let n = DVec3::new(r(2.0), r(2.0), r(2.0)).normalize_or(DVec3::Y);
        let scale = [0.01, 1.0, 100.0][trial % 3];
        let mut points: Vec<DVec3> = (0..1 + trial % 11)
            .map(|_| DVec3::new(r(scale), r(scale), r(scale)))
            .collect();
        if trial % 7 == 0 {
            points.push(polygon[0]);
            points.push(DVec3::new(polygon[1].x, 1.0, polygon[1].z));
        }
        for two_sided in [false, true] {
            let mut batch = vec![f64::NAN; points.len()];
            polygon_form_factors_sided(&points, n, polygon, two_sided, &mut batch);
            for (x, f) in points.iter().zip(&batch) {
                let one = polygon_form_factor_sided(*x, n, polygon, two_sided);
                assert_eq!(
                    f.to_bits(),
                    one.to_bits(),
                    "at {x} (n {n}): {f} against {one}"
                );
                let sides = polygon.iter().map(|p| (*p - *x).dot(n));
                clipped +=
                    (sides.clone().any(|s| s > 0.0) && sides.clone().any(|s| s < 0.0)) as u32;
                compared += 1;
            }
        }
    }
    // Both paths were taken.
    assert!(
        clipped > 1000 && compared - clipped > 1000,
        "{clipped} of {compared} clipped"
    );
}
