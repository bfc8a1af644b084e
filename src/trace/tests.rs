use super::*;
use std::sync::Arc;

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
    let tracer = wall_and_blocker(false);
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

/// A real wall (surface 0) behind a virtual blocker (surface 1), the
/// blocker cut away below x = 0 when `masked`.
fn wall_and_blocker(masked: bool) -> Tracer {
    let (wall, blocker) = (quad(2.0, 10.0), quad(1.0, 0.5));
    Tracer::build(
        &[SurfaceTriangles {
            surface: 0,
            triangles: &wall,
            mask: None,
        }],
        &[SurfaceTriangles {
            surface: 1,
            triangles: &blocker,
            mask: masked.then(|| cut_below_x0(&blocker)),
        }],
    )
    .unwrap()
}

/// A mask cutting away the points of `triangles` (in the frame the mask
/// reads) with x < 0, as a texture's alpha would from the barycentrics.
fn cut_below_x0(triangles: &[Triangle]) -> Mask {
    let corners = triangles.to_vec();
    std::sync::Arc::new(move |k: u32, u: f32, v: f32| {
        let t = &corners[k as usize];
        (t[0] * (1.0 - u - v) + t[1] * u + t[2] * v).x >= 0.0
    })
}

/// Rays along +z across x: every query meets the masked blocker, surface
/// 1, where `present` says it is, and the wall behind it, surface 0,
/// elsewhere.
fn assert_cut_where(tracer: &Tracer, present: impl Fn(f32) -> bool) {
    let rays: Vec<TraceRay> = (0..37)
        .map(|i| TraceRay::new(Vec3::new(-0.49 + i as f32 * 0.027, 0.1, 0.0), Vec3::Z))
        .collect();
    let mut hits = vec![None; rays.len()];
    tracer.intersect_batch(&rays, Layer::All, &mut hits);
    let mut occ = vec![false; rays.len()];
    tracer.occluded_batch(&rays, Layer::Virtual, &mut occ);
    for (i, r) in rays.iter().enumerate() {
        let present = present(r.origin.x);
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

#[test]
fn a_masked_surface_lets_rays_through_where_it_is_cut_away_in_every_query() {
    let tracer = wall_and_blocker(true);
    assert_cut_where(&tracer, |x| x >= 0.0);
}

/// The same through an instance turned half round about z: its mask reads
/// the object's own barycentrics, so it cuts the world's x > 0 away.
#[test]
fn an_instanced_masked_surface_lets_rays_through_where_it_is_cut_away() {
    let (wall, blocker) = (quad(2.0, 10.0), quad(0.0, 0.5));
    let object = ObjectInstance {
        surfaces: vec![SurfaceTriangles {
            surface: 0,
            triangles: &blocker,
            mask: Some(cut_below_x0(&blocker)),
        }],
        first_surface: 1,
        rotation: glam::DMat3::from_rotation_z(std::f64::consts::PI),
        scale: 1.0,
        translate: glam::DVec3::new(0.0, 0.0, 1.0),
    };
    let real = [SurfaceTriangles {
        surface: 0,
        triangles: &wall,
        mask: None,
    }];
    let tracer = Tracer::build_with_objects(&real, &[], &[object]).unwrap();
    assert_cut_where(&tracer, |x| x <= 0.0);
}

/// A tilted, asymmetric mesh of two surfaces (so a wrong rotation, scale or
/// surface number shows).
fn object_mesh() -> (Vec<Triangle>, Vec<Triangle>) {
    let a = vec![[
        Vec3::new(-0.3, 0.0, -0.2),
        Vec3::new(0.4, 0.1, -0.2),
        Vec3::new(0.0, 0.5, 0.3),
    ]];
    let b = vec![[
        Vec3::new(-0.3, 0.0, 0.2),
        Vec3::new(0.3, -0.2, 0.25),
        Vec3::new(0.1, 0.4, 0.35),
    ]];
    (a, b)
}

#[test]
fn instanced_objects_hit_as_their_world_triangles_do_and_share_one_scene() {
    let (a, b) = object_mesh();
    let poses = [
        (
            glam::DMat3::from_rotation_y(0.7),
            1.5,
            glam::DVec3::new(0.2, 0.1, 2.0),
        ),
        (
            glam::DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 0.4),
            0.8,
            glam::DVec3::new(-0.4, 0.3, 3.0),
        ),
    ];
    let instance = |first: u32, (rotation, scale, translate)| ObjectInstance {
        surfaces: [&a, &b]
            .iter()
            .enumerate()
            .map(|(k, t)| SurfaceTriangles {
                surface: k as u32,
                triangles: t,
                mask: None,
            })
            .collect(),
        first_surface: first,
        rotation,
        scale,
        translate,
    };
    let objects = [instance(5, poses[0]), instance(7, poses[1])];
    // Beside them, a wall given in the world's frame, as small objects are.
    let wall = quad(6.0, 10.0);
    let wall_set = || SurfaceTriangles {
        surface: 20,
        triangles: &wall,
        mask: None,
    };
    let instanced = Tracer::build_with_objects(&[], &[wall_set()], &objects).unwrap();
    // The same objects as world triangles, placed in double precision.
    let world: Vec<(u32, Vec<Triangle>)> = (objects.iter())
        .flat_map(|o| {
            [&a, &b].into_iter().enumerate().map(move |(k, t)| {
                let at = |p: Vec3| (o.translate + o.rotation * (p.as_dvec3() * o.scale)).as_vec3();
                (
                    o.first_surface + k as u32,
                    t.iter().map(|t| t.map(at)).collect(),
                )
            })
        })
        .collect();
    let sets: Vec<SurfaceTriangles> = (world.iter())
        .map(|(s, t)| SurfaceTriangles {
            surface: *s,
            triangles: t,
            mask: None,
        })
        .chain([wall_set()])
        .collect();
    let plain = Tracer::build(&[], &sets).unwrap();
    let mut hits = 0;
    for i in 0..40 {
        for j in 0..40 {
            let d = Vec3::new(-0.8 + i as f32 * 0.04, -0.6 + j as f32 * 0.04, 1.0).normalize();
            let ray = TraceRay::new(Vec3::ZERO, d);
            let (x, y) = (
                instanced.intersect(&ray, Layer::Virtual),
                plain.intersect(&ray, Layer::Virtual),
            );
            let (Some(x), Some(y)) = (x, y) else {
                // Only a ray grazing an edge may hit one and miss the other.
                continue;
            };
            hits += 1;
            assert_eq!((x.surface, x.triangle), (y.surface, y.triangle));
            assert!((x.t - y.t).abs() < 1e-5 * y.t, "t {} against {}", x.t, y.t);
            assert!(
                (x.normal - y.normal).length() < 1e-5,
                "{} against {}",
                x.normal,
                y.normal
            );
            assert!((x.u - y.u).abs() < 1e-4 && (x.v - y.v).abs() < 1e-4);
            assert!(x.is_virtual);
        }
    }
    assert!(hits > 1000, "{hits} hits");
    // One scene for the two objects of one mesh, kept by a move.
    assert_eq!(instanced.object_scenes.kept.len(), 1);
    let before = Arc::clone(&instanced.object_scenes.kept[0].1);
    let mut moved = instanced;
    let shifted = [instance(5, poses[1]), instance(7, poses[0])];
    moved.place_objects(&[wall_set()], &shifted).unwrap();
    assert!(Arc::ptr_eq(&before, &moved.object_scenes.kept[0].1));
    assert_eq!(moved.virtual_objects.as_ref().unwrap().triangle_count(), 6);
}
