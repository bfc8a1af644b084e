use super::*;

fn quad(z: f32, half: f32) -> Vec<Triangle> {
    let (a, b, c, d) = (
        Vec3::new(-half, -half, z),
        Vec3::new(half, -half, z),
        Vec3::new(half, half, z),
        Vec3::new(-half, half, z),
    );
    vec![[a, b, c], [a, c, d]]
}

#[test]
fn closest_hit_reports_surface_triangle_barycentrics_and_facing_normal() {
    let (near, far) = (quad(1.0, 1.0), quad(2.0, 1.0));
    let g = Geometry::build(
        &[
            SurfaceTriangles {
                surface: 7,
                triangles: &far,
                mask: None,
            },
            SurfaceTriangles {
                surface: 3,
                triangles: &near,
                mask: None,
            },
        ],
        false,
    )
    .unwrap();
    let ray = TraceRay::new(Vec3::new(0.5, -0.25, 0.0), Vec3::Z);
    let h = g.intersect(&ray).unwrap();
    assert_eq!((h.surface, h.triangle), (3, 0));
    assert!((h.t - 1.0).abs() < 1e-6);
    assert!(
        (h.normal - Vec3::NEG_Z).length() < 1e-6,
        "faces the origin: {}",
        h.normal
    );
    let t = &near[0];
    let p = t[0] * (1.0 - h.u - h.v) + t[1] * h.u + t[2] * h.v;
    assert!((p - Vec3::new(0.5, -0.25, 1.0)).length() < 1e-5);
    assert!(
        g.intersect(&TraceRay::new(Vec3::new(3.0, 0.0, 0.0), Vec3::Z))
            .is_none()
    );
}

#[test]
fn batches_agree_with_single_rays_and_layers_stay_apart() {
    let (wall, blocker) = (quad(2.0, 10.0), quad(1.0, 0.5));
    let tracer = Tracer::build(
        &[SurfaceTriangles {
            surface: 0,
            triangles: &wall,
            mask: None,
        }],
        &[SurfaceTriangles {
            surface: 1,
            triangles: &blocker,
            mask: None,
        }],
    )
    .unwrap();
    let rays: Vec<TraceRay> = (0..37)
        .map(|i| TraceRay::new(Vec3::new(-1.0 + i as f32 * 0.055, 0.1, 0.0), Vec3::Z))
        .collect();
    for layer in [Layer::Real, Layer::Virtual, Layer::All] {
        let mut hits = vec![None; rays.len()];
        tracer.intersect_batch(&rays, layer, &mut hits);
        let mut occ = vec![false; rays.len()];
        tracer.occluded_batch(&rays, layer, &mut occ);
        for (i, r) in rays.iter().enumerate() {
            assert_eq!(hits[i], tracer.intersect(r, layer), "ray {i} {layer:?}");
            assert_eq!(occ[i], tracer.occluded(r, layer), "ray {i} {layer:?}");
            let inside = r.origin.x.abs() < 0.5;
            let expect = match layer {
                Layer::Real => Some(0),
                Layer::Virtual => inside.then_some(1),
                Layer::All => Some(if inside { 1 } else { 0 }),
            };
            assert_eq!(hits[i].map(|h| h.surface), expect, "ray {i} {layer:?}");
        }
    }
    // A segment that stops before the wall is not blocked by it.
    let short = TraceRay::segment(Vec3::new(3.0, 0.0, 0.0), Vec3::new(3.0, 0.0, 1.9), 1e-4);
    assert!(!tracer.occluded(&short, Layer::All));
}

#[test]
fn queries_from_rayon_threads_agree() {
    use rayon::prelude::*;
    let wall = quad(2.0, 1.0);
    let g = Geometry::build(
        &[SurfaceTriangles {
            surface: 0,
            triangles: &wall,
            mask: None,
        }],
        false,
    )
    .unwrap();
    let hits: Vec<bool> = (0..10_000)
        .into_par_iter()
        .map(|i| {
            g.occluded(&TraceRay::new(
                Vec3::new(i as f32 * 2e-4 + 1e-5, 0.0, 0.0),
                Vec3::Z,
            ))
        })
        .collect();
    assert_eq!(hits.iter().filter(|&&h| h).count(), 5000);
}

#[test]
fn a_masked_surface_lets_rays_through_where_it_is_cut_away_in_every_query() {
    // The blocker's points with x < 0 are cut away (world x from the
    // barycentrics, as a texture's alpha would be read from them).
    let (wall, blocker) = (quad(2.0, 10.0), quad(1.0, 0.5));
    let corners = blocker.clone();
    let mask: Mask = std::sync::Arc::new(move |k: u32, u: f32, v: f32| {
        let t = &corners[k as usize];
        (t[0] * (1.0 - u - v) + t[1] * u + t[2] * v).x >= 0.0
    });
    let tracer = Tracer::build(
        &[SurfaceTriangles {
            surface: 0,
            triangles: &wall,
            mask: None,
        }],
        &[SurfaceTriangles {
            surface: 1,
            triangles: &blocker,
            mask: Some(mask),
        }],
    )
    .unwrap();
    let rays: Vec<TraceRay> = (0..37)
        .map(|i| TraceRay::new(Vec3::new(-0.49 + i as f32 * 0.027, 0.1, 0.0), Vec3::Z))
        .collect();
    let mut hits = vec![None; rays.len()];
    tracer.intersect_batch(&rays, Layer::All, &mut hits);
    let mut occ = vec![false; rays.len()];
    tracer.occluded_batch(&rays, Layer::Virtual, &mut occ);
    for (i, r) in rays.iter().enumerate() {
        let present = r.origin.x >= 0.0;
        let expect = if present { 1 } else { 0 };
        assert_eq!(hits[i].map(|h| h.surface), Some(expect), "ray {i}");
        assert_eq!(
            tracer.intersect(r, Layer::All).map(|h| h.surface),
            Some(expect)
        );
        assert_eq!(occ[i], present, "ray {i}");
        assert_eq!(tracer.occluded(r, Layer::Virtual), present, "ray {i}");
    }
}
