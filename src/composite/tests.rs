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
            seams: Vec::new(),
            scales_changed: false,
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

/// A rough model's seam one pixel off the photo's edge: the model puts
/// surface 2 at x ≥ 8, the photo shows surface 1 up to x = 8. Surface 1's
/// light doubles, surface 2's stays: the stray column takes most of its
/// change from the neighbours that look like it in the photo, and the
/// pixels off the seam keep theirs.
#[test]
fn a_seam_pixel_takes_the_change_of_the_side_it_shows_in_the_photo() {
    use crate::pda::{PatchPoint, PixelDataArray, Samples, SurfacePoint};
    let (w, h) = (16u32, 8u32);
    let n = (w * h) as usize;
    let on_two = |i: usize| i as u32 % w >= 8;
    let points: Vec<SurfacePoint> = (0..n)
        .map(|i| SurfacePoint {
            position: Vec3::ZERO,
            normal: Vec3::Z,
            surface: 1 + on_two(i) as u32,
            is_virtual: false,
            pixel_terms: false,
            clear_of_own: false,
            location: PatchPoint {
                patch: 0,
                weights: [1.0, 0.0, 0.0, 0.0],
            },
        })
        .collect();
    let mut pda = PixelDataArray::default();
    pda.width = w;
    pda.height = h;
    pda.supersample = 4;
    pda.own = crate::image_io::PixelRect::full(w, h);
    pda.rows = (0, h);
    pda.real_index = (0..n as u32).collect();
    pda.real_t = vec![1.0; n];
    pda.real = Samples {
        points,
        terms: Vec::new(),
    };
    pda.virtual_index = vec![u32::MAX; n];
    let shows_one = |i: usize| i as u32 % w <= 8;
    let mut photo = Image::new(w, h);
    for (i, p) in photo.pixels.iter_mut().enumerate() {
        *p = if shows_one(i) {
            Vec3::new(0.5, 0.4, 0.3)
        } else {
            Vec3::new(0.1, 0.15, 0.2)
        };
    }
    let mut out = Composite::empty();
    out.image = Image::new(w, h);
    for (i, v) in out.image.pixels.iter_mut().enumerate() {
        *v = photo.pixels[i] * if on_two(i) { 1.0 } else { 2.0 };
    }
    let seams = seams::seam_pixels(&pda);
    // Within two pixels of x = 7.5: columns 6 to 9.
    assert!(seams.iter().all(|&i| (6..=9).contains(&(i % w))));
    assert_eq!(seams.len(), 4 * h as usize);
    let before = out.image.clone();
    seams::smooth_seams(&pda, &photo, &seams, &|_| true, &mut out);
    let truth = |i: usize| photo.pixels[i] * if shows_one(i) { 2.0 } else { 1.0 };
    let error = |image: &Image| -> Vec<f32> {
        (0..n)
            .map(|i| ((image.pixels[i] - truth(i)).abs() / truth(i)).max_element())
            .collect()
    };
    let (was, now) = (error(&before), error(&out.image));
    for i in 0..n {
        match i as u32 % w {
            // The stray column: half its change missing, under a fifth now.
            8 => assert!(was[i] == 0.5 && now[i] < 0.2, "stray: {}", now[i]),
            // Its neighbour on the photo's side of it takes a little of its
            // change; the other side's, none.
            7 => assert!(now[i] < 0.1, "beside: {}", now[i]),
            9 => assert!(now[i] < 0.01, "other side: {}", now[i]),
            _ => assert_eq!(out.image.pixels[i], before.pixels[i]),
        }
    }
    let squared = |e: &[f32]| e.iter().map(|e| e * e).sum::<f32>();
    assert!(
        squared(&now) * 5.0 < squared(&was),
        "{} against {}",
        squared(&now),
        squared(&was)
    );
}
