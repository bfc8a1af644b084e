use super::brdf::*;
use super::*;
use crate::util::rng::unit_random;

fn metal(roughness: f64) -> Lobes {
    Lobes {
        base: DVec3::ONE,
        metallic: 1.0,
        roughness,
    }
}

/// Directional albedo of the specular lobe by brute force: f·cos over a
/// fine midpoint grid of the hemisphere, independent of the sampler.
fn brute_albedo(lobes: &Lobes, mu: f64) -> DVec3 {
    let n = DVec3::Z;
    let v = DVec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
    let (k_theta, k_phi) = (1200, 600);
    let mut sum = DVec3::ZERO;
    for i in 0..k_theta {
        // Uniform in cos θ: dω = d(cos θ) dφ.
        let c = (i as f64 + 0.5) / k_theta as f64;
        let s = (1.0 - c * c).sqrt();
        for j in 0..k_phi {
            let phi = std::f64::consts::TAU * (j as f64 + 0.5) / k_phi as f64;
            let l = DVec3::new(s * phi.cos(), s * phi.sin(), c);
            let (d, sp) = lobes.eval(n, v, l);
            sum += (d + sp) * c;
        }
    }
    sum * (std::f64::consts::TAU / (k_theta * k_phi) as f64)
}

#[test]
fn white_furnace_metal_reflects_at_most_what_arrives_and_matches_single_scattering() {
    for roughness in [0.05, 0.2, 0.35, 0.5, 0.8, 1.0] {
        for mu in [0.1, 0.4, 0.7, 1.0] {
            let sampled = directional_albedo(&metal(roughness), mu, 64).x;
            assert!(sampled <= 1.0 + 1e-9, "r {roughness} μ {mu}: {sampled}");
            if roughness >= 0.35 {
                // The brute-force grid resolves the lobe from α = 0.12 up.
                let brute = brute_albedo(&metal(roughness), mu).x;
                assert!(
                    (sampled - brute).abs() <= 0.01 * brute,
                    "r {roughness} μ {mu}: sampler {sampled} against quadrature {brute}"
                );
            }
        }
    }
    // The truth's own figure: E_avg of a white metal of roughness 0.5 is 0.882.
    let e_avg = hemispherical_albedo(&metal(0.5)).x;
    assert!((e_avg - 0.882).abs() < 0.01 * 0.882, "E_avg {e_avg}");
}

#[test]
fn a_white_dielectric_matches_quadrature_and_conserves_energy_seen_from_above() {
    // glTF's mix lets the diffuse base through as (1 − F(v·h)), which is
    // not reduced enough at grazing views: a white dielectric of roughness
    // 0.5 reflects 1.13 of what arrives at n·v = 0.05. The truth renders
    // this model, so it is kept; seen from above it conserves energy.
    for roughness in [0.0, 0.3, 0.5, 1.0] {
        let l = Lobes {
            base: DVec3::ONE,
            metallic: 0.0,
            roughness,
        };
        let e = directional_albedo(&l, 1.0, 64).x;
        assert!(e <= 1.0 + 1e-9 && e > 0.95, "r {roughness}: {e}");
        if roughness >= 0.3 {
            for mu in [0.05, 0.5, 1.0] {
                let (s, b) = (directional_albedo(&l, mu, 64).x, brute_albedo(&l, mu).x);
                assert!(
                    (s - b).abs() < 0.005 * b,
                    "r {roughness} μ {mu}: {s} against {b}"
                );
            }
        }
    }
}

#[test]
fn the_brdf_is_reciprocal() {
    let mut s = 7u64;
    let dir = |s: &mut u64| {
        let (a, b) = (unit_random(s), unit_random(s));
        let z = a.max(1e-3);
        let r = (1.0 - z * z).sqrt();
        DVec3::new(
            r * (std::f64::consts::TAU * b).cos(),
            r * (std::f64::consts::TAU * b).sin(),
            z,
        )
    };
    for k in 0..200 {
        let lobes = Lobes {
            base: DVec3::new(0.9, 0.5, 0.1),
            metallic: (k % 3) as f64 / 2.0,
            roughness: (k % 7) as f64 / 6.0,
        };
        let (v, l) = (dir(&mut s), dir(&mut s));
        let (a, b) = (lobes.eval(DVec3::Z, v, l), lobes.eval(DVec3::Z, l, v));
        let (fa, fb) = (a.0 + a.1, b.0 + b.1);
        assert!(
            (fa - fb).abs().max_element() <= 1e-9 * fa.max_element().max(1.0),
            "{fa} against {fb}"
        );
    }
}

#[test]
fn no_nan_or_inf_at_roughness_zero_and_grazing_angles() {
    let n = DVec3::Z;
    for roughness in [0.0, 1e-6, 0.5, 1.0] {
        for metallic in [0.0, 1.0] {
            let lobes = Lobes {
                base: DVec3::splat(0.8),
                metallic,
                roughness,
            };
            for (vz, lz) in [
                (1e-9f64, 1e-9f64),
                (1.0, 1.0),
                (1e-12, 1.0),
                (1.0, 0.0),
                (0.0, 1.0),
            ] {
                let v = DVec3::new((1.0 - vz * vz).sqrt(), 0.0, vz);
                let l = DVec3::new(-(1.0 - lz * lz).sqrt(), 0.0, lz);
                let (d, s) = lobes.eval(n, v, l);
                assert!(d.is_finite() && s.is_finite() && d.min_element() >= 0.0);
                assert!(s.min_element() >= 0.0);
                for u in [0.0, 0.5, 0.999_999] {
                    if let Some((l, pdf, w)) = lobes.sample_specular(n, v, u, 1.0 - u) {
                        assert!(l.is_finite() && pdf.is_finite() && pdf >= 0.0);
                        assert!(w.is_finite() && w.max_element() <= 1.0 + 1e-9);
                    }
                }
            }
        }
    }
}

#[test]
fn a_textured_quad_shows_the_texel_at_its_uv_with_srgb_decoded() {
    // 2×2: top-left red, top-right green, bottom-left blue, bottom-right white (sRGB 8-bit).
    let data = [
        255, 0, 0, 0, 255, 0, //
        0, 0, 255, 128, 128, 128,
    ];
    let t = Arc::new(Texture::from_u8(2, 2, 3, &data, true).unwrap());
    let m = Material {
        base_texture: Some(t),
        ..Material::plain("q", Vec3::ONE, 0.0, 1.0)
    };
    let at = |u: f32, v: f32| m.at(Vec2::new(u, v), 0.0).lobes.base;
    assert!(
        (at(0.25, 0.25) - DVec3::X).length() < 1e-6,
        "top-left is red"
    );
    assert!((at(0.75, 0.25) - DVec3::Y).length() < 1e-6);
    assert!((at(0.25, 0.75) - DVec3::Z).length() < 1e-6);
    // 128 in sRGB is 0.2158605 linear (decoded before filtering).
    let grey = at(0.75, 0.75);
    assert!(
        (grey - DVec3::splat(0.215_860_5)).abs().max_element() < 1e-5,
        "{grey}"
    );
    // Halfway between the two top texels: the mean of their linear values.
    let mid = at(0.5, 0.25);
    assert!((mid - DVec3::new(0.5, 0.5, 0.0)).abs().max_element() < 1e-6);
    // Repeat wrapping: u + 1 is u.
    assert!((at(1.25, 0.25) - DVec3::X).length() < 1e-6);
    // A footprint wider than the texture reads its mean.
    let mean = m.at(Vec2::new(0.3, 0.6), 64.0).lobes.base;
    let expect = (DVec3::X + DVec3::Y + DVec3::Z + DVec3::splat(0.215_860_5)) / 4.0;
    assert!((mean - expect).abs().max_element() < 1e-5, "{mean}");
}

#[test]
fn an_alpha_mask_cuts_where_alpha_is_below_the_cutoff() {
    let data = [255, 255, 255, 255, 255, 255, 255, 0];
    let t = Arc::new(Texture::from_u8(2, 1, 4, &data, true).unwrap());
    let m = Material {
        base_texture: Some(t),
        alpha_cutoff: Some(0.5),
        ..Material::plain("m", Vec3::ONE, 0.0, 1.0)
    };
    assert!(m.at(Vec2::new(0.25, 0.5), 0.0).opaque);
    assert!(!m.at(Vec2::new(0.75, 0.5), 0.0).opaque);
    let blend = Material {
        alpha_cutoff: None,
        ..m
    };
    assert!(blend.at(Vec2::new(0.75, 0.5), 0.0).opaque);
}

#[test]
fn a_normal_texture_decodes_to_its_tangent_space_normal() {
    // (0.5, 0.5, 1) is the unperturbed normal; (1, 0.5, 0.5) lies along +x.
    let texel = |x: f32, y: f32, z: f32| Vec4::new(x, y, z, 1.0);
    let t = Texture::from_linear(2, 1, vec![texel(0.5, 0.5, 1.0), texel(1.0, 0.5, 0.5)]);
    let m = Material {
        normal_texture: Some((Arc::new(t), 1.0)),
        ..Material::plain("n", Vec3::ONE, 0.0, 1.0)
    };
    // Texels are kept in 16 bits: 0.5 is 0.500008, a tilt of 1.5e-5.
    let flat = m.at(Vec2::new(0.25, 0.5), 0.0).tangent_normal.unwrap();
    assert!((flat - Vec3::Z).length() < 1e-4, "{flat}");
    let lean = m.at(Vec2::new(0.75, 0.5), 0.0).tangent_normal.unwrap();
    assert!((lean - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-4, "{lean}");
}

#[test]
fn mikktspace_tangents_run_along_u_with_the_bitangent_up_the_image() {
    // A unit square facing +z with its image upright on it (v = 1 at the bottom).
    let (a, b, c, d) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y);
    let triangles = [[a, b, c], [a, c, d]];
    let uv = |p: Vec3| Vec2::new(p.x, 1.0 - p.y);
    let attributes = Attributes {
        normals: vec![[Vec3::Z; 3]; 2],
        uvs: triangles.iter().map(|t| t.map(uv)).collect(),
        tangents: Vec::new(),
    }
    .with_mikktspace(&triangles);
    assert_eq!(attributes.tangents.len(), 2);
    for t in attributes.tangents.iter().flatten() {
        assert!((t.truncate() - Vec3::X).length() < 1e-5, "{t}");
        // glTF: bitangent = normal × tangent · w, up the image (+y here).
        assert_eq!(t.w, 1.0, "{t}");
    }
}

#[test]
fn the_albedo_table_matches_the_quadrature() {
    // Affine in the base colour, bilinear in metallic and roughness
    // between the table's cells: within 0.5% of the quadrature anywhere.
    let mut state = 7u64;
    let mut worst: f64 = 0.0;
    for _ in 0..40 {
        let mut u = || unit_random(&mut state);
        let lobes = Lobes {
            base: DVec3::new(u(), u(), u()),
            metallic: u(),
            roughness: u(),
        };
        let (table, exact) = (table_albedo(&lobes), hemispherical_albedo(&lobes));
        worst = worst.max(((table - exact).abs() / exact.max(DVec3::splat(0.05))).max_element());
    }
    assert!(worst <= 0.005, "largest relative difference {worst}");
}

#[test]
fn the_diffuse_part_under_uniform_light_does_not_vanish_at_grazing_views() {
    // The mean over cosine-distributed light of 1 − F(v·h), read from a
    // table, against a fine quadrature: it stays near 0.9 at grazing views, where
    // 1 − F(n·v) goes to 0 (which darkened every glossy silhouette).
    let white = Lobes {
        base: DVec3::ONE,
        metallic: 0.0,
        roughness: 0.5,
    };
    for mu in [0.02, 0.1, 0.33, 0.7, 1.0] {
        let exact = coat_quadrature(mu, 400);
        let table = white.diffuse_mean(mu).x;
        // The BRDF's own diffuse part under uniform light: a dielectric's
        // albedo with a white base less a black one's.
        let black = Lobes {
            base: DVec3::ZERO,
            ..white
        };
        let brdf = (directional_albedo(&white, mu, 200) - directional_albedo(&black, mu, 200)).x;
        assert!(
            (brdf - exact).abs() <= 0.002 * exact,
            "n·v {mu}: the BRDF's {brdf}"
        );
        assert!(
            (table - exact).abs() <= 0.002 * exact,
            "n·v {mu}: {table} against {exact}"
        );
        assert!(table > 0.8, "n·v {mu}: {table}");
    }
    assert!(white.diffuse(0.02).x < 0.2, "1 − F(n·v) at a grazing view");
}

/// 8-bit texels decoded through the per-code tables are the texels the
/// sRGB function gives one by one (every code, every channel layout,
/// both encodings), and their mip chain is the same.
#[test]
fn eight_bit_texels_decode_as_the_srgb_function_does_one_by_one() {
    let codes: Vec<u8> = (0..=255).collect();
    for channels in 1..=4usize {
        for srgb in [false, true] {
            // 256 texels a row: each code in every channel, shifted per channel.
            let data: Vec<u8> = (0..256 * channels)
                .map(|i| codes[(i / channels + 37 * (i % channels)) % 256])
                .collect();
            let decode = |c: u8, colour: bool| {
                let x = c as f32 / 255.0;
                if srgb && colour {
                    texture::srgb_to_linear(x)
                } else {
                    x
                }
            };
            let texels: Vec<Vec4> = data
                .chunks_exact(channels)
                .map(|t| {
                    let c = |i: usize| decode(t[i], true);
                    match channels {
                        1 => Vec4::new(c(0), c(0), c(0), 1.0),
                        2 => Vec4::new(c(0), c(0), c(0), decode(t[1], false)),
                        3 => Vec4::new(c(0), c(1), c(2), 1.0),
                        _ => Vec4::new(c(0), c(1), c(2), decode(t[3], false)),
                    }
                })
                .collect();
            // Every level's every texel: the full level as the image's
            // codes read through their table, the mips made from it.
            let by_table = Texture::from_u8(16, 16, channels, &data, srgb).unwrap();
            assert_eq!(
                by_table.texels(),
                Texture::from_linear(16, 16, texels).texels(),
                "{channels} channels, sRGB {srgb}"
            );
            // Held as a byte a channel on the full level (and its table),
            // the mips' values in 16 bits each.
            let full = 256 * channels + 1024;
            let mips: usize = [64, 16, 4, 1].iter().map(|n| n * channels * 2).sum();
            assert_eq!(by_table.memory_bytes(), full + mips);
            // The mean by counting codes is the texels' mean.
            let texels = &by_table.texels()[0];
            let sum: glam::DVec4 = texels.iter().map(|t| t.as_dvec4()).sum();
            let mean = (sum / texels.len() as f64).as_vec4();
            let off = (by_table.mean() - mean).abs().max_element();
            assert!(
                off <= 1e-6 * mean.max_element(),
                "{channels} channels: mean off by {off}"
            );
        }
    }
}

#[test]
fn the_stored_albedo_table_is_the_quadratures_bit_for_bit() {
    // `ARLUX_WRITE_ALBEDO_TABLE=1 cargo test --release stored_albedo_table`
    // writes the table again (after a change to the BRDF or its quadrature).
    use super::brdf::{ALBEDO_TABLE_CELLS, ALBEDO_TABLE_FILE, albedo_cell, decode_albedo_table};
    use rayon::prelude::*;
    let side = (ALBEDO_TABLE_CELLS as f64).sqrt() as usize;
    let cells: Vec<(f64, f64)> = (0..ALBEDO_TABLE_CELLS)
        .into_par_iter()
        .map(|k| albedo_cell(k / side, k % side))
        .collect();
    if std::env::var_os("ARLUX_WRITE_ALBEDO_TABLE").is_some() {
        let bytes: Vec<u8> = (cells.iter())
            .flat_map(|(a, b)| a.to_le_bytes().into_iter().chain(b.to_le_bytes()))
            .collect();
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/src/materials/albedo_table.bin"
        );
        std::fs::write(path, bytes).unwrap();
        return;
    }
    let stored = decode_albedo_table(ALBEDO_TABLE_FILE);
    let differ = (stored.iter().zip(&cells).enumerate())
        .filter(|(_, (s, c))| s.0.to_bits() != c.0.to_bits() || s.1.to_bits() != c.1.to_bits())
        .map(|(k, _)| (k / side, k % side))
        .collect::<Vec<_>>();
    assert!(
        differ.is_empty(),
        "{} cells differ from the quadrature (metallic, roughness steps: {:?}…); \
         ARLUX_WRITE_ALBEDO_TABLE=1 writes the table again",
        differ.len(),
        &differ[..differ.len().min(4)]
    );
    // And no cell can darken a base or make light from nothing
    // (`table_albedo` clamps the sum to 1: the smoothest lobe's quadrature
    // overshoots it by 4%).
    assert!(
        (stored.iter()).all(|&(a, b)| a.is_finite() && b.is_finite() && a >= 0.0 && b >= 0.0),
        "a cell with a negative or non-finite part"
    );
}

#[test]
fn odd_and_tiny_textures_keep_their_texels_mean_and_largest_value() {
    // Odd sides keep their last texel alone in the next level; one texel
    // is its own chain. Each layout against the same texels as RGBA.
    for (w, h) in [(1u32, 1u32), (5, 3), (7, 1), (1, 6)] {
        for channels in 1..=4usize {
            let n = (w * h) as usize;
            let data: Vec<u8> = (0..n * channels).map(|i| (i * 61 % 256) as u8).collect();
            let rgba: Vec<u8> = data
                .chunks_exact(channels)
                .flat_map(|t| match channels {
                    1 => [t[0], t[0], t[0], 255],
                    2 => [t[0], t[0], t[0], t[1]],
                    3 => [t[0], t[1], t[2], 255],
                    _ => [t[0], t[1], t[2], t[3]],
                })
                .collect();
            let own = Texture::from_u8(w, h, channels, &data, true).unwrap();
            let expanded = Texture::from_u8(w, h, 4, &rgba, true).unwrap();
            assert_eq!(
                own.texels(),
                expanded.texels(),
                "{w}×{h}, {channels} channels"
            );
            assert_eq!(own.mean(), expanded.mean(), "{w}×{h}, {channels} channels");
            // The largest value among the codes held is the largest texel.
            let largest = own.texels()[0].iter().fold(Vec4::ZERO, |m, t| m.max(*t));
            assert_eq!(own.max(), largest, "{w}×{h}, {channels} channels");
            assert_eq!(expanded.max(), largest, "{w}×{h}, {channels} channels");
        }
    }
}
