use super::*;

#[test]
fn cielab_of_reference_colours() {
    let white = cielab(DVec3::ONE, 1.0);
    assert!(
        (white.x - 100.0).abs() < 0.05 && white.y.abs() < 0.05 && white.z.abs() < 0.05,
        "{white}"
    );
    // sRGB red: L 53.24, a 80.09, b 67.20.
    let red = cielab(DVec3::X, 1.0);
    assert!(
        (red - DVec3::new(53.24, 80.09, 67.20)).length() < 0.1,
        "{red}"
    );
    assert_eq!(cielab(DVec3::ZERO, 1.0), DVec3::ZERO);
    // Relative to the white given: twice as bright and a white of 2 is white.
    assert!((cielab(DVec3::splat(2.0), 2.0) - white).length() < 1e-9);
}

#[test]
fn unknown_texels_take_their_nearest_known_value() {
    let mut tex = Texture {
        s0: 0.0,
        t0: 0.0,
        ds: 0.25,
        dt: 0.5,
        nu: 4,
        nv: 2,
        texels: vec![Vec3::ZERO; 8],
    };
    let mut known = vec![false; 8];
    tex.texels[0] = Vec3::ONE;
    known[0] = true;
    tex.texels[7] = Vec3::splat(3.0);
    known[7] = true;
    fill_unknown(&mut tex, &mut known);
    assert!(known.iter().all(|&k| k));
    assert_eq!(tex.texels[1], Vec3::ONE);
    assert_eq!(tex.texels[6], Vec3::splat(3.0));
    assert_eq!(tex.texel_of(DVec2::new(0.99, 0.99)), 7);
    assert_eq!(tex.texel_of(DVec2::new(-0.1, 0.1)), 0);
}
