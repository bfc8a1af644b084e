use super::*;

#[test]
fn barycentrics_rebuild_the_point() {
    let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
    let x = DVec3::new(0.2, 0.3, 0.0);
    let w = barycentrics(a, b, c, x);
    let back = a * w[0] + b * w[1] + c * w[2];
    assert!((back - x).length() < 1e-12, "{w:?}");
}

#[test]
fn the_terminator_point_rises_to_the_smooth_surface_and_only_where_it_bulges() {
    let corners = [DVec3::ZERO, DVec3::X, DVec3::Y];
    let x = DVec3::new(1.0 / 3.0, 1.0 / 3.0, 0.0);
    let w = barycentrics(corners[0], corners[1], corners[2], x);
    // Flat normals: the point stays on its triangle.
    let flat = [DVec3::Z; 3];
    assert!((terminator_safe(x, corners, flat, w) - x).length() < 1e-15);
    // Normals leaning out from the centre (a convex patch): it rises, by
    // the mean of how far x lies below each corner's tangent plane.
    let out = corners.map(|p| (p - x + DVec3::Z).normalize());
    let lifted = terminator_safe(x, corners, out, w);
    let expect: DVec3 = (0..3)
        .map(|i| -out[i] * (w[i] * (x - corners[i]).dot(out[i]).min(0.0)))
        .sum();
    assert!((lifted - x - expect).length() < 1e-12);
    assert!(lifted.z > 0.0, "{lifted}");
    // Normals leaning in (a concave patch): the point lies above every
    // tangent plane and stays.
    let inward = corners.map(|p| (x - p + DVec3::Z).normalize());
    assert!((terminator_safe(x, corners, inward, w) - x).length() < 1e-15);
}

#[test]
fn a_normal_texture_tilts_a_plane_s_shading_as_lambert_says() {
    // A plane facing +z, its tangent along +x from its texture coordinates.
    let t = [DVec3::ZERO, DVec3::X, DVec3::Y];
    let uv = [
        Vec2::new(0.0, 0.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(0.0, 1.0),
    ];
    let tangent = uv_tangent(t, uv);
    assert!((tangent.0 - DVec3::X).length() < 1e-12);
    // A texel tilting the normal 30° towards +x.
    let tilt = 30f64.to_radians();
    let tn = DVec3::new(tilt.sin(), 0.0, tilt.cos());
    let n = perturbed(DVec3::Z, tangent, tn);
    assert!((n - tn).length() < 1e-12, "{n}");
    // A matte white surface lit from 60° towards +x: the diffuse radiance
    // follows cos of the angle to the tilted normal (30°), not to the plane's (60°).
    let lobes = Lobes {
        base: DVec3::ONE,
        metallic: 0.0,
        roughness: 1.0,
    };
    let l = DVec3::new(60f64.to_radians().sin(), 0.0, 60f64.to_radians().cos());
    let v = DVec3::Z;
    let (tilted, plain) = (
        lobes.eval(n, v, l).0.x * n.dot(l),
        lobes.eval(DVec3::Z, v, l).0.x * l.z,
    );
    let ratio = tilted / plain;
    let expect = 30f64.to_radians().cos() / 60f64.to_radians().cos();
    // The diffuse part's Fresnel factor differs only through v·h, the same for both.
    assert!((ratio - expect).abs() < 1e-9, "{ratio} against {expect}");
}

#[test]
fn a_texture_s_up_is_the_bitangent_mirrored_or_not() {
    // A square facing +z with its image upright on it: v = 1 at the bottom.
    let t = [DVec3::ZERO, DVec3::X, DVec3::Y];
    let upright = [
        Vec2::new(0.0, 1.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(0.0, 0.0),
    ];
    let mirrored = [
        Vec2::new(1.0, 1.0),
        Vec2::new(0.0, 1.0),
        Vec2::new(1.0, 0.0),
    ];
    for (uv, along) in [(upright, DVec3::X), (mirrored, -DVec3::X)] {
        let (tangent, sign) = uv_tangent(t, uv);
        assert!((tangent - along).length() < 1e-12, "{tangent}");
        // The normal texture's +Y (up the image) is world +y either way.
        let up = perturbed(
            DVec3::Z,
            (tangent, sign),
            DVec3::new(0.0, 1.0, 1.0).normalize(),
        );
        assert!(up.y > 0.7 && up.x.abs() < 1e-12, "{up}");
    }
}

/// A shading normal that turns from the viewer is bent towards the
/// geometric one just enough that the view's mirror direction leaves the
/// surface at the threshold; a valid one is kept as it is.
#[test]
fn a_shading_normal_turned_from_the_viewer_is_bent_back_just_enough() {
    let ng = DVec3::Z;
    let v = DVec3::new(60f64.to_radians().sin(), 0.0, 60f64.to_radians().cos());
    let tilted = |deg: f64| DVec3::new(-deg.to_radians().sin(), 0.0, deg.to_radians().cos());
    let kept = tilted(10.0);
    assert_eq!(super::towards_the_viewer(ng, v, kept), kept);
    let n = super::towards_the_viewer(ng, v, tilted(85.0));
    assert!((n.length() - 1.0).abs() < 1e-12 && n.dot(v) > 0.0);
    let mirror = 2.0 * n.dot(v) * n - v;
    assert!((mirror.dot(ng) - 0.01).abs() < 1e-6, "{}", mirror.dot(ng));
    // In the plane of the two normals, between them.
    assert!(n.y.abs() < 1e-12 && n.x < 0.0 && n.z < 1.0);
}

#[test]
fn a_pixel_draws_more_samples_where_its_mean_is_uncertain() {
    // Sixteen samples, half black and half of luminance 1: mean 0.5,
    // sample variance 16/15 × 0.25, standard error √(1/60) = 0.1291.
    let mut sums = Sums::default();
    for j in 0..16 {
        sums.add(DVec3::splat(f64::from(j % 2)));
    }
    assert_eq!(sums.count, 16);
    assert!(sums.uncertain(16, 0.129));
    assert!(!sums.uncertain(16, 0.1292));
    // The same light in every sample leaves nothing uncertain (but
    // rounding), however bright; one sample says nothing of its spread.
    let mut flat = Sums::default();
    for _ in 0..16 {
        flat.add(DVec3::splat(40.0));
    }
    assert!(!flat.uncertain(16, 1e-6));
    assert!(!sums.uncertain(1, 0.0));
}

#[test]
fn the_photos_mean_luminance_skips_what_is_not_finite() {
    let mut photo = crate::image_io::Image::new(61, 2);
    for (i, p) in photo.pixels.iter_mut().enumerate() {
        *p = glam::Vec3::splat(if i == 61 { f32::INFINITY } else { 0.5 });
    }
    photo.pixels[0] = glam::Vec3::new(1.0, 0.0, 0.0);
    // Pixels 0 and 61 are read: 0.2126 and infinity (left out).
    assert!((mean_luminance(&photo) - 0.2126).abs() < 1e-6);
    assert_eq!(mean_luminance(&crate::image_io::Image::new(0, 0)), 0.0);
}
