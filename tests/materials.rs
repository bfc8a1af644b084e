//! `scenes/materials`: glTF objects with PBR materials (a textured globe,
//! chrome, a glossy vase, a gold ring) in the desk's room, against the
//! truth of an independent path tracer using glTF's BRDF; and the same
//! objects as flat Lambertian OBJs of their mean albedo (`scene_flat.toml`),
//! all a renderer without materials could use.

mod common;
use common::load;

use arlux::compare::{compare, skill};
use arlux::image_io::{Image, read_image};
use arlux::model::StageTimes;
use arlux::render::{RenderOutput, RenderSettings, Session, render};
use arlux::scene::Scene;

const VARIANTS: [&str; 7] = [
    "globe_floor",
    "chrome_floor",
    "chrome_table",
    "vase_floor",
    "ring_table",
    "trio",
    "chrome_bulb",
];

/// A `materials` variant as posed, its photo and its truth.
fn posed_with_truth(variant: &str) -> (Scene, Image, Image) {
    let base = load("materials", "scene.toml");
    let scene = base.with_variant(variant).unwrap();
    let photo = scene.load_photo().unwrap();
    let truth = read_image(base.variant(variant).unwrap().reference.as_ref().unwrap()).unwrap();
    (scene, photo, truth)
}

fn run(base: &Scene, variant: &str) -> (RenderOutput, Image, Image) {
    let (out, photo) = common::render_default(&base.with_variant(variant).unwrap());
    let truth = read_image(base.variant(variant).unwrap().reference.as_ref().unwrap()).unwrap();
    common::assert_layers_sound(variant, &out.composite);
    (out, truth, photo)
}

#[test]
fn every_variant_against_its_truth_and_its_flat_twin() {
    let (pbr, flat) = (
        load("materials", "scene.toml"),
        load("materials", "scene_flat.toml"),
    );
    for variant in VARIANTS {
        let (out, truth, photo) = run(&pbr, variant);
        let (plain, _, _) = run(&flat, variant);
        // The objects' own pixels: the geometry is the same in both scenes.
        let object: Vec<bool> = out.composite.alpha.iter().map(|a| *a > 0.5).collect();
        let ours = compare(&out.composite.image, &truth, Some(&object)).rmse;
        let clay = compare(&plain.composite.image, &truth, Some(&object)).rmse;
        let s = skill(&out.composite.image, &truth, &photo).skill.unwrap();
        println!("{variant:<14} skill {s:.4}, objects' RMSE {ours:.4} (flat clay {clay:.4})");
        assert!(s >= 0.85, "{variant}: skill {s:.4}");
        assert!(
            ours <= 0.5 * clay,
            "{variant}: objects' RMSE {ours:.4} against flat clay's {clay:.4}"
        );
    }
}

/// Centroid of the most saturated warm band a chrome ball reflects (red
/// chroma above half its largest value, lamp highlights left out): where
/// the room's reflection lies in the ball.
fn band_centroid(image: &Image, object: &[bool]) -> (f64, f64) {
    let chroma: Vec<f64> = image
        .pixels
        .iter()
        .zip(object)
        .map(|(p, o)| {
            let p = p.as_dvec3();
            if !*o || p.max_element() >= 1.0 {
                return 0.0;
            }
            (p.x - p.y.max(p.z)) / p.element_sum().max(1e-3)
        })
        .collect();
    let top = chroma.iter().cloned().fold(0.0, f64::max);
    let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
    for (i, c) in chroma.iter().enumerate() {
        let w = (c - 0.5 * top).max(0.0);
        sx += w * (i % image.width as usize) as f64;
        sy += w * (i / image.width as usize) as f64;
        sw += w;
    }
    (sx / sw, sy / sw)
}

#[test]
fn the_chrome_ball_reflects_the_room_where_the_truth_does() {
    let (out, truth, _) = run(&load("materials", "scene.toml"), "chrome_floor");
    let object: Vec<bool> = out.composite.alpha.iter().map(|a| *a > 0.99).collect();
    let (ours, theirs) = (
        band_centroid(&out.composite.image, &object),
        band_centroid(&truth, &object),
    );
    let off = ((ours.0 - theirs.0).powi(2) + (ours.1 - theirs.1).powi(2)).sqrt();
    println!("band centroid {ours:?}, truth's {theirs:?}: {off:.2} px apart");
    // Flat clay: 3.2 px off (its chroma follows the light, not the room).
    assert!(off <= 2.0, "{off:.2} px from the truth's");
}

#[test]
fn an_update_of_a_chrome_ball_equals_a_full_render_of_its_pose() {
    let base = load("materials", "scene.toml");
    let first = base.with_variant("chrome_floor").unwrap();
    let photo = first.load_photo().unwrap();
    let mut moved = first.clone();
    let chrome = moved
        .objects
        .iter()
        .position(|o| o.name == "chrome")
        .unwrap();
    moved.objects[chrome].pose.translate += glam::DVec3::new(-0.2, 0.0, 0.15);
    // Without rounds, and with the material and the floor near the ball
    // sampled in rounds.
    for samples in [0, 2] {
        let mut settings = RenderSettings::default();
        settings.residual.samples = samples;
        let mut session =
            Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
        session.update(&moved, &mut StageTimes::default()).unwrap();
        let full = render(&moved, &photo, &settings, &mut StageTimes::default()).unwrap();
        let differing = session
            .composite
            .image
            .pixels
            .iter()
            .zip(&full.composite.image.pixels)
            .filter(|(a, b)| a.to_array().map(f32::to_bits) != b.to_array().map(f32::to_bits))
            .count();
        assert_eq!(
            differing, 0,
            "{samples} rounds: the update differs from a full render"
        );
        // And the ball moved: its pixels are not where they were.
        let before = render(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
        assert_ne!(before.composite.alpha, full.composite.alpha);
    }
}

/// The chrome ball rolls past the globe and the vase, which stand still:
/// a session reads their pixels again over the samples it kept where the
/// ball comes near none of their rays, and every update still equals a
/// full render of its pose, bit for bit.
#[test]
fn objects_standing_still_keep_their_samples_and_updates_equal_full_renders() {
    let base = load("materials", "scene.toml");
    // The spot already scaled, so that the session may scale it again.
    let mut first = base.with_variant("trio").unwrap();
    first.lights[1].scale *= 0.9;
    let photo = first.load_photo().unwrap();
    let settings = RenderSettings::default();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    let chrome = (first.objects.iter())
        .position(|o| o.name == "chrome")
        .unwrap();
    let globe = (first.objects.iter())
        .position(|o| o.name == "globe")
        .unwrap();
    let mut scene = first.clone();
    // Bit for bit a full render; after the relight within 1e-5 (the
    // room's solution is then the sum of its lights' alone).
    let differing = |session: &Session, scene: &Scene, relit: bool| {
        let full = render(scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let (a, b) = (&session.composite.image, &full.composite.image);
        match relit {
            true => (common::relative_difference(a, b) > 1e-5) as usize,
            false => common::differing(a, b),
        }
    };
    // The ball rolls; the spot is dimmed; the ball rolls on; the globe moves.
    for step in 1..=6 {
        match step {
            4 => {
                scene.lights[1].scale *= 0.5;
                session.relight(&scene, &mut StageTimes::default()).unwrap();
                assert_eq!(differing(&session, &scene, true), 0, "relit");
            }
            6 => scene.objects[globe].pose.translate.x += 0.03,
            _ => scene.objects[chrome].pose.translate += glam::DVec3::new(-0.06, 0.0, 0.05),
        }
        let stats = session.update(&scene, &mut StageTimes::default()).unwrap();
        let d = differing(&session, &scene, step >= 4);
        println!(
            "step {step}: {} points kept, {d} pixels differ",
            stats.shaded_kept
        );
        // Kept wherever the samples were drawn at these scales, of objects
        // that stood still then and now (after the relight none are): at
        // step 6 the chrome ball's and the vase's pixels, about 600.
        if step != 4 {
            assert!(stats.shaded_kept > 400, "step {step}: nothing kept");
        }
        assert_eq!(d, 0, "step {step}: the update differs from a full render");
    }
}

#[test]
fn a_tile_through_the_objects_shades_them_as_the_whole_frame_does() {
    // A reflected point's change is traced, never read from a pixel a tile
    // may not hold: the objects' pixels of a tile whose edge cuts the
    // chrome ball equal the whole frame's bit for bit, without rounds and
    // with the materials sampled over their pixels in rounds.
    let base = load("materials", "scene.toml");
    let scene = base.with_variant("trio").unwrap();
    let photo = scene.load_photo().unwrap();
    for samples in [0, 2] {
        let mut settings = RenderSettings::default();
        settings.residual.samples = samples;
        let whole = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let window = arlux::image_io::CropWindow {
            x0: 0.69,
            x1: 1.0,
            y0: 0.0,
            y1: 1.0,
        };
        settings.pda.crop = Some(window);
        let tile = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let w = scene.camera.width as usize;
        let x0 = window
            .pixels(scene.camera.width, scene.camera.height)
            .unwrap()
            .x0 as usize;
        let (mut compared, mut differing) = (0, 0);
        for (i, (a, b)) in whole
            .composite
            .object
            .pixels
            .iter()
            .zip(&tile.composite.object.pixels)
            .enumerate()
        {
            if i % w >= x0 && whole.composite.alpha[i] > 0.0 {
                compared += 1;
                differing +=
                    (a.to_array().map(f32::to_bits) != b.to_array().map(f32::to_bits)) as usize;
            }
        }
        assert!(compared > 100, "the tile holds {compared} object pixels");
        assert_eq!(
            differing, 0,
            "{samples} rounds: {differing} of {compared} object pixels differ"
        );
        // And every pixel of the tile, the floor the ball lights included.
        let bits = |p: &glam::Vec3| p.to_array().map(f32::to_bits);
        let image = (whole.composite.image.pixels.iter())
            .zip(&tile.composite.image.pixels)
            .enumerate()
            .filter(|(i, (a, b))| i % w >= x0 && bits(a) != bits(b))
            .count();
        assert_eq!(
            image, 0,
            "{samples} rounds: {image} pixels of the tile differ"
        );
    }
}

#[test]
fn the_objects_pixels_are_the_same_on_one_thread_and_on_three() {
    let scene = load("materials", "scene.toml")
        .with_variant("trio")
        .unwrap();
    let photo = scene.load_photo().unwrap();
    for samples in [0, 2] {
        let mut settings = RenderSettings::default();
        settings.residual.samples = samples;
        let images: Vec<Image> = [1, 3]
            .iter()
            .map(|&t| common::image_on_threads(&scene, &photo, &settings, t))
            .collect();
        assert!(
            images[0] == images[1],
            "{samples} rounds: thread count changed the image"
        );
    }
}

#[test]
fn rounds_sample_a_metals_lamp_highlights_over_the_pixel() {
    // The chrome ball on the table mirrors the lamps: a highlight's edge
    // crosses pixels, which the default's samples per pixel (16, 64 where
    // they spread) average coarsely. Rounds add samples of the pixel's
    // points and the lobe's directions from one Sobol sequence. Measured:
    // skill 0.965 -> 0.976, the objects' RMSE 0.017 -> 0.0098.
    let (scene, photo, truth) = posed_with_truth("chrome_table");
    let mut last: Option<(f64, f64)> = None;
    for samples in [0, 16] {
        let mut settings = RenderSettings::default();
        settings.residual.samples = samples;
        let out = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        common::assert_layers_sound("chrome_table", &out.composite);
        let object: Vec<bool> = out.composite.alpha.iter().map(|a| *a > 0.5).collect();
        let rmse = compare(&out.composite.image, &truth, Some(&object)).rmse;
        let s = skill(&out.composite.image, &truth, &photo).skill.unwrap();
        println!("{samples} rounds: skill {s:.4}, objects' RMSE {rmse:.4}");
        if let Some((s0, rmse0)) = last {
            assert!(s >= 0.972 && s >= s0 + 0.008, "skill {s:.4} after {s0:.4}");
            assert!(
                rmse <= 0.65 * rmse0,
                "objects' RMSE {rmse:.4} after {rmse0:.4}"
            );
        }
        last = Some((s, rmse));
    }
}

#[test]
fn a_textured_object_bounces_the_colours_of_its_texture() {
    // The globe's oceans face the floor beside it: the light it bounces
    // there is bluer than its texture's mean. Over the floor in its half
    // shadow, our change against the truth's per channel: with one mean
    // albedo per surface red took 0.75 of the truth's change and blue
    // 1.05; with each patch's own albedo both lie within 8% of it.
    let base = load("materials", "scene.toml");
    let (out, truth, photo) = run(&base, "globe_floor");
    let changed = arlux::compare::changed_pixels(&truth, &photo);
    let (mut ours, mut theirs) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
    for (i, a) in out.composite.alpha.iter().enumerate() {
        let (o, t, p) = (
            out.composite.image.pixels[i].as_dvec3(),
            truth.pixels[i].as_dvec3(),
            photo.pixels[i].as_dvec3(),
        );
        let relative = (t - p).element_sum() / p.element_sum().max(1e-3);
        if changed[i] && *a == 0.0 && relative > -0.5 && relative <= -0.05 {
            ours += o - p;
            theirs += t - p;
        }
    }
    let ratio = ours / theirs;
    println!("half shadow: our change / the truth's {ratio:.3}");
    assert!(
        ratio.cmpge(glam::DVec3::splat(0.85)).all() && ratio.cmple(glam::DVec3::splat(1.15)).all(),
        "{ratio:.3}"
    );
    assert!(
        (ratio.x / ratio.z - 1.0).abs() <= 0.08,
        "red against blue: {ratio:.3}"
    );
}

#[test]
fn a_chrome_balls_focused_reflection_reaches_the_floor_as_rounds_grow() {
    // The truth's floor brightens beside the chrome ball where the ball
    // reflects the lamps onto it (268 pixels by more than 0.02, 0.035 on
    // average). Without rounds the room sees the ball's diffuse radiosity
    // only (0.021 there); the rounds' rays from the floor read the ball's
    // radiance towards them, lamps reflected through its lobe (widened in
    // early rounds, its own by the last): 0.029 at 16, 0.034 at 64.
    let (scene, photo, truth) = posed_with_truth("chrome_floor");
    let w = photo.width as usize;
    let mean = |img: &Image, i: usize| {
        let (a, b) = (img.pixels[i], photo.pixels[i]);
        ((a - b).x + (a - b).y + (a - b).z) as f64 / 3.0
    };
    let mut gains = Vec::new();
    for samples in [0, 64] {
        let mut settings = RenderSettings::default();
        settings.residual.samples = samples;
        let out = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let alpha = &out.composite.alpha;
        // Floor pixels whose 3×3 neighbourhood the truth brightens by
        // more than 0.02, away from the ball's outline.
        let brightened: Vec<usize> = (w + 1..truth.pixels.len() - w - 1)
            .filter(|&i| {
                let around = [
                    i - w - 1,
                    i - w,
                    i - w + 1,
                    i - 1,
                    i,
                    i + 1,
                    i + w - 1,
                    i + w,
                    i + w + 1,
                ];
                around.iter().all(|&k| alpha[k] == 0.0)
                    && around.iter().map(|&k| mean(&truth, k)).sum::<f64>() / 9.0 > 0.02
            })
            .collect();
        assert!(brightened.len() > 100, "{} pixels", brightened.len());
        let n = brightened.len() as f64;
        let ours = brightened
            .iter()
            .map(|&i| mean(&out.composite.image, i))
            .sum::<f64>()
            / n;
        let theirs = brightened.iter().map(|&i| mean(&truth, i)).sum::<f64>() / n;
        println!(
            "{samples} rounds: {} pixels, ours {ours:.4}, truth {theirs:.4}",
            brightened.len()
        );
        gains.push(ours / theirs);
    }
    assert!(
        gains[0] < 0.7,
        "without rounds: {:.2} of the truth's",
        gains[0]
    );
    assert!(
        (0.9..=1.1).contains(&gains[1]),
        "64 rounds: {:.2} of the truth's",
        gains[1]
    );
}

#[test]
fn rounds_stay_finite_with_a_bulb_a_millimetre_from_the_floor_beside_the_chrome_ball() {
    // The virtual bulb 1 mm above the floor, a few centimetres from the
    // chrome ball: what the ball mirrors of it, and what the floor's rays
    // read of the ball, span orders of magnitude within a pixel.
    use arlux::scene::LightPosition;
    let (mut scene, photo, _) = posed_with_truth("chrome_floor");
    let bulb = scene.light_index("bulb").unwrap();
    scene.lights[bulb].position = LightPosition::Known(glam::DVec3::new(0.95, 0.001, -0.7));
    scene.lights[bulb].scale = 1.0;
    scene.check_light_clearance().unwrap();
    let mut settings = RenderSettings::default();
    settings.residual.samples = 4;
    let out = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
    // The indirect light interpolated over the floor's patches overshoots
    // below 0 here (to -5.1 on 2,576 pixels): irradiance is read clamped
    // at 0, so no layer is negative.
    assert_eq!(out.residual.map(|r| r.rounds), Some(4));
    common::assert_layers_sound("bulb by the ball", &out.composite);
    // The bulb lights the ball: its pixels are brighter than without it.
    let object = |c: &arlux::composite::Composite| -> f64 {
        (c.object.pixels.iter()).map(|p| p.x as f64).sum::<f64>()
    };
    let dark = render(
        &posed_with_truth("chrome_floor").0,
        &photo,
        &settings,
        &mut StageTimes::default(),
    )
    .unwrap();
    assert!(object(&out.composite) > object(&dark.composite));
}

#[test]
fn only_a_metal_throughout_is_shaded_without_its_vertices_light() {
    // The chrome ball's vertices gather a quarter of the rays (their light
    // reaches the image only through the room); the globe and the vase
    // have a diffuse part that reads theirs.
    let scene = load("materials", "scene.toml")
        .with_variant("trio")
        .unwrap();
    let metals = arlux::object_shading::ObjectMaterials::metal_ids(&scene);
    let shaded = arlux::object_shading::ObjectMaterials::surface_ids(&scene);
    let of = |name: &str| -> Vec<u32> {
        (scene.virtual_surfaces())
            .filter(|(_, o, _)| o.name == name)
            .map(|(id, _, _)| id)
            .collect()
    };
    assert!(!metals.is_empty() && metals.windows(2).all(|w| w[0] < w[1]));
    assert!(of("chrome").iter().all(|id| metals.contains(id)));
    for other in ["globe", "vase"] {
        assert!(of(other).iter().all(|id| !metals.contains(id)), "{other}");
        assert!(of(other).iter().all(|id| shaded.contains(id)), "{other}");
    }
    // A hidden object's surfaces are neither.
    assert!(
        of("ring")
            .iter()
            .all(|id| !shaded.contains(id) && !metals.contains(id))
    );
}
