use super::*;
use rand::{RngExt, SeedableRng};

/// Where [`RealPixels::may_keep`] says no pixel of a patch can keep the
/// photo, none is within its band: random corners (quads and
/// triangles) moved by up to three bands either way, pixels at random
/// weights with bands as [`CompositeInput::real_pixel`] makes them, h
/// interpolated as the composite does.
#[test]
fn a_patch_said_to_keep_nothing_has_no_pixel_within_its_band() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let (mut refused, mut kept) = (0, 0);
    for _ in 0..3000 {
        let ids = if rng.random_bool(0.3) {
            [0, 1, 2, u32::MAX]
        } else {
            [0, 1, 2, 3]
        };
        let scale = 10f64.powf(rng.random_range(-6.0..3.0));
        let without: Vec<DVec3> = (0..4)
            .map(|_| {
                DVec3::new(
                    rng.random_range(0.5..2.0),
                    rng.random_range(0.5..2.0),
                    rng.random_range(0.5..2.0),
                ) * scale
            })
            .collect();
        let direct = rng.random_range(0.0..3.0) * scale;
        let band_size = (direct + scale) * UNCHANGED_INDIRECT;
        // Sometimes every corner moves one way, sometimes either way.
        let one_way = rng.random_bool(0.5);
        let with: Vec<DVec3> = without
            .iter()
            .map(|w| {
                let m = rng.random_range(if one_way { 0.5..3.0 } else { -3.0..3.0 });
                *w + DVec3::new(m, rng.random_range(-3.0..3.0), m) * band_size
            })
            .collect();
        let pixels: Vec<(RealPixel, [f32; 4])> = (0..50)
            .map(|_| {
                let mut w = [
                    rng.random_range(0.0..1.0f64),
                    rng.random_range(0.0..1.0),
                    rng.random_range(0.0..1.0),
                    rng.random_range(0.0..1.0),
                ];
                if ids[3] == u32::MAX {
                    w[3] = 0.0;
                }
                let sum: f64 = w.iter().sum();
                let w = w.map(|x| (x / sum) as f32);
                let h_wo: DVec3 = (0..4)
                    .filter(|&i| w[i] != 0.0)
                    .map(|i| without[i] * w[i] as f64)
                    .sum();
                let band = ((h_wo + DVec3::splat(direct)) * UNCHANGED_INDIRECT).as_vec3();
                let affine = AffinePixel {
                    offset: Vec3::ZERO,
                    slope: Vec3::ONE,
                    patch: 0,
                    weights: w,
                };
                (
                    RealPixel {
                        affine,
                        keep: PhotoBand {
                            h_without: h_wo.as_vec3(),
                            band,
                        },
                    },
                    w,
                )
            })
            .collect();
        let mut known = RealPixels {
            affine: pixels.iter().map(|p| p.0.affine).collect(),
            keep: pixels.iter().map(|p| p.0.keep).collect(),
            widest_band: vec![Vec3::splat(-1.0)],
            without: patch_corners(&without, &[ids]),
            floor: DVec3::ZERO,
        };
        for (r, _) in &pixels {
            known.widen(r);
        }
        let corners = patch_corners(&with, &[ids]);
        let may = known.may_keep(&corners, &[ids])[0];
        refused += !may as usize;
        for (r, w) in &pixels {
            let holds = r.keep.holds(interpolate_single(&corners[0], *w).into());
            assert!(
                may || !holds,
                "a pixel within its band on a patch said to keep nothing"
            );
            kept += holds as usize;
        }
    }
    // Neither answer is vacuous.
    assert!(
        refused > 500 && kept > 500,
        "refused {refused} patches, {kept} pixels kept"
    );
}
