//! The texture path (`--method texture`, Loscos et al. 2000) on `scenes/desk`:
//! the photo reprojected with nothing changed, the light variants against
//! their truth next to the pixel path, real shadows of a switched-off lamp
//! gone, and D ≈ 0.

mod common;
use common::desk;

use arlux::compare::compare;
use arlux::image_io::{Image, read_image};
use arlux::light::LightSource;
use arlux::model::StageTimes;
use arlux::output::RenderOutput;
use arlux::relight::{TexturePath, TextureSettings, render_texture};
use arlux::render::{RenderSettings, render};
use arlux::scene::Scene;
use arlux::trace::Layer;

fn luminance(p: glam::Vec3) -> f64 {
    (0.2126 * p.x + 0.7152 * p.y + 0.0722 * p.z) as f64
}

#[test]
fn nothing_changed_reprojects_the_photo() {
    let mut scene = desk();
    scene.objects.iter_mut().for_each(|o| o.enabled = false);
    let photo = scene.load_photo().unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let mut times = StageTimes::default();
    let path = TexturePath::prepare(
        &scene,
        &photo,
        &tracer,
        &TextureSettings::default(),
        &mut times,
    )
    .unwrap();
    let scales: Vec<f64> = path.lights().iter().map(|l| l.photo_scale()).collect();
    let out = path.relight(&scales, &mut times);
    let c = compare(&out.image, &photo, None);
    // Pixels no real shadow touches come back as the photo (Steps 1 and 2
    // and B/D are all 1 there); in and near the shadows the reprojection
    // is the mesh's shadow against the photo's.
    let exact = out
        .image
        .pixels
        .iter()
        .zip(&photo.pixels)
        .filter(|(a, b)| (**a - **b).abs().max_element() <= 1e-4 * b.max_element().max(1e-6))
        .count();
    let share = exact as f64 / photo.pixels.len() as f64;
    println!(
        "reprojection with nothing changed: RMSE {:.5} (relative {:.4}); {:.1}% of pixels equal the photo to 1e-4",
        c.rmse,
        c.relative_rmse.unwrap(),
        100.0 * share
    );
    assert!(c.rmse < 0.0026, "RMSE {}", c.rmse);
    assert!(share > 0.75, "{share}");
    assert_eq!(out.ratio_fallbacks, 0);
}

/// `scene` rendered by the texture path and by the pixel path, at their defaults.
fn both_methods(scene: &Scene, photo: &Image) -> (RenderOutput, RenderOutput) {
    let mut times = StageTimes::default();
    let texture = render_texture(scene, photo, &TextureSettings::default(), &mut times).unwrap();
    let pda = render(
        scene,
        photo,
        &RenderSettings::default(),
        &mut StageTimes::default(),
    )
    .unwrap();
    (texture, pda)
}

/// RMSE of both methods on one light variant.
fn both(base: &Scene, variant: &str) -> (f64, f64, f64, Image, Image, Image) {
    let scene = base.with_variant(variant).unwrap();
    let photo = scene.load_photo().unwrap();
    let truth = read_image(base.variant(variant).unwrap().reference.as_ref().unwrap()).unwrap();
    let (texture, pda) = both_methods(&scene, &photo);
    let (_, _, change) = texture.texture.as_ref().unwrap();
    let change = change.as_secs_f64();
    common::assert_layers_sound(&format!("{variant}, texture"), &texture.composite);
    common::assert_layers_sound(&format!("{variant}, pda"), &pda.composite);
    let (t, p) = (
        compare(&texture.composite.image, &truth, None).rmse,
        compare(&pda.composite.image, &truth, None).rmse,
    );
    println!("| {variant} | {t:.5} | {p:.5} | {change:.3} s |");
    (
        t,
        p,
        change,
        texture.composite.image,
        pda.composite.image,
        truth,
    )
}

#[test]
fn variants_both_methods_against_truth() {
    let base = desk();
    println!("| variant | texture RMSE | pda RMSE | light change (texture) |");
    // box_floor_a: both methods take every variant, an inserted object too.
    for (variant, texture_bound, pda_bound) in [
        ("panel_off", 0.0030, 0.0025),
        ("spot_x2", 0.0055, 0.0040),
        ("virtual_light_only", 0.0085, 0.0075),
        ("box_floor_a", 0.0055, 0.0045),
    ] {
        let (t, p, ..) = both(&base, variant);
        assert!(t < texture_bound, "{variant}: texture RMSE {t}");
        assert!(p < pda_bound, "{variant}: pda RMSE {p}");
    }
}

/// Real shadows of the switched-off panel disappear: across the panel's
/// former shadow boundary (pixels the panel lit beside pixels in its shadow,
/// where the panel gave 30% of the light or more), the brightness ratio
/// inside/outside of the output is within 10% of the truth's; the photo's
/// is not (the shadow is there).
#[test]
fn shadows_of_a_switched_off_lamp_disappear() {
    let base = desk();
    let scene = base.with_variant("panel_off").unwrap();
    let photo = scene.load_photo().unwrap();
    let truth = read_image(
        base.variant("panel_off")
            .unwrap()
            .reference
            .as_ref()
            .unwrap(),
    )
    .unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let lights = LightSource::all(&scene).unwrap();
    let (panel, spot) = (
        lights.iter().position(|l| l.name == "panel").unwrap(),
        lights.iter().position(|l| l.name == "spot").unwrap(),
    );
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    // Per pixel: surface, panel visibility (64 rays), spot visibility, and
    // the panel's share of the direct light had it not been blocked.
    let points: Vec<Option<(u32, f64, f64, f64)>> = (0..w * h)
        .map(|i| {
            let ray = cam.pixel_ray((i % w) as u32, (i / w) as u32);
            let hit = tracer.intersect(
                &arlux::trace::TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3()),
                Layer::Real,
            )?;
            let x = ray.origin + ray.direction * hit.t as f64;
            let n = hit.normal.as_dvec3();
            let dp = lights[panel].direct(&tracer, Layer::Real, x, n, 6, i as u64);
            // Facing away is not a shadow.
            if dp.unoccluded.element_sum() <= 0.0 {
                return None;
            }
            let ds = lights[spot].direct(&tracer, Layer::Real, x, n, 0, i as u64);
            let (ep, es) = (
                dp.unoccluded.element_sum(),
                ds.unoccluded.element_sum() * ds.visibility,
            );
            Some((hit.surface, dp.visibility, ds.visibility, ep / (ep + es)))
        })
        .collect();
    let pairs = shadow_pairs(&points, w, h);
    assert!(
        pairs.len() > 300,
        "{} pairs across the panel's shadow boundary",
        pairs.len()
    );
    let ratio = |img: &Image| {
        let (a, b) = pairs.iter().fold((0.0, 0.0), |(a, b), &(p, q)| {
            (a + luminance(img.pixels[p]), b + luminance(img.pixels[q]))
        });
        a / b
    };
    let (texture, pda) = both_methods(&scene, &photo);
    let (rt, rp, rd, rtruth) = (
        ratio(&texture.composite.image),
        ratio(&photo),
        ratio(&pda.composite.image),
        ratio(&truth),
    );
    println!(
        "{} pixel pairs across the panel's former shadow boundary; inside/outside: truth {rtruth:.3}, texture {rt:.3} ({:+.1}%), pda {rd:.3} ({:+.1}%), photo {rp:.3} ({:+.1}%)",
        pairs.len(),
        100.0 * (rt / rtruth - 1.0),
        100.0 * (rd / rtruth - 1.0),
        100.0 * (rp / rtruth - 1.0)
    );
    assert!(
        (rt / rtruth - 1.0).abs() < 0.10,
        "texture: {rt} against {rtruth}"
    );
    assert!(
        (rd / rtruth - 1.0).abs() < 0.10,
        "pda: {rd} against {rtruth}"
    );
    assert!(
        (rp / rtruth - 1.0).abs() > 0.10,
        "the photo's shadow must be visible for this test to mean anything: {rp} against {rtruth}"
    );
}

/// Pairs: a pixel in the panel's shadow and the nearest pixel of the same
/// surface within 8 pixels that the panel lights, along a row or column,
/// the spot's visibility alike, the panel 30% of the light or more.
fn shadow_pairs(
    points: &[Option<(u32, f64, f64, f64)>],
    w: usize,
    h: usize,
) -> Vec<(usize, usize)> {
    let mut pairs = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let Some((s, vp, vs, _)) = points[y * w + x] else {
                continue;
            };
            if vp > 0.3 {
                continue;
            }
            for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                for step in 1..=8 {
                    let (qx, qy) = (x as i64 + dx * step, y as i64 + dy * step);
                    if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                        break;
                    }
                    let q = qy as usize * w + qx as usize;
                    match points[q] {
                        Some((qs, qp, qv, share))
                            if qs == s && qp > 0.7 && (qv - vs).abs() < 0.01 && share > 0.3 =>
                        {
                            pairs.push((y * w + x, q));
                            break;
                        }
                        _ => {}
                    }
                }
            }
        }
    }
    pairs
}

/// D ≈ 0: where the photo's lights gave no light (here: none of the
/// desk's lamps counts as photographed), the display cannot divide by D;
/// those pixels show the radiosity, finite, and are counted.
#[test]
fn d_near_zero_falls_back_to_radiosity() {
    let base = desk();
    let mut scene = base.with_variant("virtual_light_only").unwrap();
    for l in scene.lights.iter_mut() {
        l.real = false;
    }
    let photo = scene.load_photo().unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let mut times = StageTimes::default();
    let path = TexturePath::prepare(
        &scene,
        &photo,
        &tracer,
        &TextureSettings::default(),
        &mut times,
    )
    .unwrap();
    let scales: Vec<f64> = scene.lights.iter().map(|l| l.scale).collect();
    let out = path.relight(&scales, &mut times);
    let real = out.image.pixels.len() - out.copied;
    println!(
        "{} of {real} pixels on real surfaces fell back to B/π",
        out.ratio_fallbacks
    );
    assert_eq!(out.ratio_fallbacks, real);
    assert!(
        out.image
            .pixels
            .iter()
            .all(|p| p.is_finite() && p.min_element() >= 0.0)
    );
    // The bulb's light shows where it reaches.
    let lit = out
        .image
        .pixels
        .iter()
        .zip(&out.direct.pixels)
        .filter(|(p, e)| e.max_element() > 0.1 && p.min_element() > 0.0)
        .count();
    assert!(lit > 50_000, "{lit}");
}

/// Loscos's interactive use: one preprocess (the bulb inserted, so its
/// forced refinement is done), then every light variant is a light change
/// on the kept mesh and links, as accurate as its own preprocess.
#[test]
fn one_preprocess_serves_every_light_change() {
    let base = desk();
    let scene = base.with_variant("virtual_light_only").unwrap();
    let photo = scene.load_photo().unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let path = TexturePath::prepare(
        &scene,
        &photo,
        &tracer,
        &TextureSettings::default(),
        &mut StageTimes::default(),
    )
    .unwrap();
    for (variant, bound) in [
        ("panel_off", 0.0030),
        ("spot_x2", 0.0055),
        ("virtual_light_only", 0.0085),
    ] {
        let scales: Vec<f64> = base
            .with_variant(variant)
            .unwrap()
            .lights
            .iter()
            .map(|l| l.scale)
            .collect();
        let out = path.relight(&scales, &mut StageTimes::default());
        let truth = read_image(base.variant(variant).unwrap().reference.as_ref().unwrap()).unwrap();
        let e = compare(&out.image, &truth, None).rmse;
        println!("{variant} from the shared preprocess: RMSE {e:.5}");
        assert!(e < bound, "{variant}: {e}");
    }
}

/// `[[texture_reference]]`: where no frontier leaf of similar colour is
/// found (here: none may match, the colour threshold at 0), a surface's
/// shadowed leaves take the user's reference; without one they keep Step 1.
/// A point off its surface is an error naming the key.
#[test]
fn a_user_reference_serves_where_no_frontier_leaf_matches() {
    use arlux::scene::TextureReference;
    let base = desk();
    let mut scene = base.with_variant("panel_off").unwrap();
    let photo = scene.load_photo().unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let floor = scene
        .surfaces
        .iter()
        .position(|s| s.name == "floor")
        .unwrap();
    let point = glam::DVec3::new(0.6, 0.0, 0.2);
    for light in LightSource::all(&scene).unwrap().iter().filter(|l| l.real) {
        let d = light.direct(&tracer, Layer::Real, point, glam::DVec3::Y, 6, 1);
        assert!(
            d.unoccluded.element_sum() > 0.0 && d.visibility == 1.0,
            "{} must light the reference fully",
            light.name
        );
    }
    let settings = TextureSettings {
        reference_colour_threshold: 0.0,
        ..Default::default()
    };
    let without = TexturePath::prepare(
        &scene,
        &photo,
        &tracer,
        &settings,
        &mut StageTimes::default(),
    )
    .unwrap()
    .stats;
    assert_eq!((without.by_frontier, without.by_user_reference), (0, 0));
    assert_eq!(without.uncorrected, without.occluded);
    scene.texture_references.push(TextureReference {
        surface: floor,
        point,
    });
    let with = TexturePath::prepare(
        &scene,
        &photo,
        &tracer,
        &settings,
        &mut StageTimes::default(),
    )
    .unwrap()
    .stats;
    println!(
        "occluded seen leaves {}: {} from the floor's reference, {} uncorrected",
        with.occluded, with.by_user_reference, with.uncorrected
    );
    assert!(with.by_user_reference > 50, "{with:?}");
    assert_eq!(with.by_user_reference + with.uncorrected, with.occluded);
    scene.texture_references[0].point = glam::DVec3::new(0.6, 0.5, 0.2);
    let err = TexturePath::prepare(
        &scene,
        &photo,
        &tracer,
        &settings,
        &mut StageTimes::default(),
    )
    .err()
    .expect("a point off the floor");
    assert!(
        err.to_string().contains(
            "texture_reference[0].point: [0.6, 0.5, 0.2] does not lie on surface 'floor'"
        ),
        "{err}"
    );
}

/// An object's outline on the texture path is mixed by the pixel's share
/// of it, as on the pixel path: along the box's outline (pixels the pixel
/// path covers by 5-95%) the two methods' coverage (alpha) agrees, and the
/// texture path's image there lies between the object and the room.
#[test]
fn object_outlines_are_mixed_by_coverage_as_on_the_pixel_path() {
    let base = desk();
    let scene = base.with_variant("box_floor_a").unwrap();
    let photo = scene.load_photo().unwrap();
    let (texture, pda) = both_methods(&scene, &photo);
    let (t, p) = (&texture.composite.alpha, &pda.composite.alpha);
    let edge: Vec<usize> = (0..p.len())
        .filter(|&i| p[i] > 0.05 && p[i] < 0.95)
        .collect();
    assert!(edge.len() > 50, "{} outline pixels", edge.len());
    let mean_gap = edge
        .iter()
        .map(|&i| (t[i] - p[i]).abs() as f64)
        .sum::<f64>()
        / edge.len() as f64;
    let mixed = edge.iter().filter(|&&i| t[i] > 0.0 && t[i] < 1.0).count();
    assert!(
        mean_gap < 0.05,
        "mean |alpha texture - alpha pda| {mean_gap}"
    );
    assert!(
        mixed * 10 >= edge.len() * 9,
        "{mixed} of {} mixed",
        edge.len()
    );
    common::assert_layers_sound("box_floor_a, texture", &texture.composite);
}
