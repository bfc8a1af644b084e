//! Stiff and extreme cases through the whole model (estimation, radiosity,
//! per-pixel view): no NaN or Inf leaves any stage, nothing is negative.

mod common;
use common::desk;

use glam::DVec3;

use arlux::image_io::Image;
use arlux::model::{Model, ModelSettings, ModelView, StageTimes};
use arlux::scene::{KnownReflectance, LightPosition, Scene};

fn all_finite(img: &Image) -> bool {
    img.pixels
        .iter()
        .all(|p| p.is_finite() && p.min_element() >= 0.0)
}

fn run(scene: &Scene) -> (Model, ModelView) {
    let photo = scene.load_photo().unwrap();
    let tracer = arlux::scene_tracer::build_tracer(scene).unwrap();
    let settings = ModelSettings {
        patch_size: 0.5,
        ..ModelSettings::default()
    };
    let model = Model::build(
        scene,
        &photo,
        &tracer,
        &settings,
        &mut StageTimes::default(),
    )
    .unwrap();
    let view = ModelView::render(scene, &tracer, &model, 3);
    let est = &model.estimate;
    assert!(
        est.reflectance
            .iter()
            .all(|r| r.is_finite() && r.min_element() >= 0.0 && r.max_element() <= 0.99)
    );
    assert!(
        est.solution
            .radiosity
            .iter()
            .all(|b| b.is_finite() && b.min_element() >= 0.0)
    );
    assert!(
        est.solution
            .indirect_irradiance
            .iter()
            .all(|h| h.is_finite() && h.min_element() >= 0.0)
    );
    for (name, img) in [
        ("radiance", &view.radiance),
        ("direct", &view.direct),
        ("indirect", &view.indirect),
        ("reflectance", &view.reflectance),
    ] {
        assert!(all_finite(img), "{name} has a non-finite or negative pixel");
    }
    (model, view)
}

fn bulb_at(scene: &mut Scene, p: DVec3) {
    let bulb = scene.light_index("bulb").unwrap();
    scene.lights[bulb].position = LightPosition::Known(p);
    scene.lights[bulb].scale = 1.0;
    // As a real lamp, the photographed state (and so the model) includes it.
    scene.lights[bulb].real = true;
    scene.check_light_clearance().unwrap();
}

#[test]
fn a_light_one_millimetre_above_the_floor() {
    let mut scene = desk();
    bulb_at(&mut scene, DVec3::new(-0.5, 0.001, 0.5));
    let (_, view) = run(&scene);
    // The pixel under the bulb sees the singular-but-finite peak: E ≈ I/d² = 6e6.
    let peak = view
        .direct
        .pixels
        .iter()
        .map(|p| p.x)
        .fold(0.0f32, f32::max);
    assert!(
        peak.is_finite() && peak > 1e3,
        "peak direct irradiance {peak}"
    );
}

#[test]
fn a_light_grazing_a_wall() {
    let mut scene = desk();
    // 1 mm from the left wall: its light meets the wall at grazing angles.
    bulb_at(&mut scene, DVec3::new(-1.999, 1.2, 0.0));
    run(&scene);
}

#[test]
fn zero_reflectance_of_a_known_surface() {
    let mut scene = desk();
    let floor = scene.surface_index("floor").unwrap();
    scene.reflectances.push(KnownReflectance {
        surface: floor,
        rgb: DVec3::ZERO,
    });
    let (model, _) = run(&scene);
    let floor_b: Vec<DVec3> = (0..model.patches.patch_count())
        .filter(|&k| model.patches.patch(k).surface == floor as u32)
        .map(|k| model.estimate.solution.radiosity[k])
        .collect();
    assert!(
        floor_b.iter().all(|b| *b == DVec3::ZERO),
        "a black floor reflects nothing"
    );
}

/// The texture path on the stiff cases: a virtual bulb 1 mm above the floor
/// (its forced refinement meets the singular peak), a bulb grazing a wall,
/// a known reflectance of 0.99, and a photo spanning 1e6:1. Every layer
/// stays finite and non-negative, every light change too.
#[test]
fn the_texture_path_stays_finite_on_stiff_cases() {
    use arlux::relight::{TexturePath, TextureSettings};
    let settings = TextureSettings {
        patch_size: Some(0.5),
        ..TextureSettings::default()
    };
    type Edit = Box<dyn Fn(&mut Scene, &mut Image)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "virtual bulb 1 mm above the floor",
            Box::new(|s: &mut Scene, _: &mut Image| {
                let bulb = s.light_index("bulb").unwrap();
                s.lights[bulb].position = LightPosition::Known(DVec3::new(-0.5, 0.001, 0.5));
                s.lights[bulb].scale = 1.0;
            }),
        ),
        (
            "virtual bulb grazing the left wall",
            Box::new(|s: &mut Scene, _: &mut Image| {
                let bulb = s.light_index("bulb").unwrap();
                s.lights[bulb].position = LightPosition::Known(DVec3::new(-1.999, 1.2, 0.0));
                s.lights[bulb].scale = 1.0;
            }),
        ),
        (
            "reflectance 0.99",
            Box::new(|s: &mut Scene, _: &mut Image| {
                s.reflectances[0].rgb = DVec3::splat(0.99);
            }),
        ),
        (
            "a photo spanning 1e6:1",
            Box::new(|_: &mut Scene, photo: &mut Image| {
                let w = photo.width as usize;
                for (i, p) in photo.pixels.iter_mut().enumerate() {
                    *p *= if (i % w) < w / 2 { 1e3 } else { 1e-3 };
                }
            }),
        ),
    ];
    for (name, edit) in cases {
        let mut scene = desk();
        scene.objects.iter_mut().for_each(|o| o.enabled = false);
        let mut photo = scene.load_photo().unwrap();
        edit(&mut scene, &mut photo);
        let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
        let path = TexturePath::prepare(
            &scene,
            &photo,
            &tracer,
            &settings,
            &mut StageTimes::default(),
        )
        .unwrap();
        assert!(
            all_finite(&path.unoccluded_texture()),
            "{name}: the unoccluded texture"
        );
        let n = scene.lights.len();
        for scales in [
            scene.lights.iter().map(|l| l.scale).collect::<Vec<f64>>(),
            vec![0.0; n],
            vec![1e3; n],
        ] {
            let out = path.relight(&scales, &mut StageTimes::default());
            for (layer, img) in [
                ("image", &out.image),
                ("direct", &out.direct),
                ("indirect", &out.indirect),
            ] {
                assert!(
                    all_finite(img),
                    "{name}, scales {scales:?}: {layer} has a non-finite or negative pixel"
                );
            }
            assert!(
                out.change.pixels.iter().all(|p| p.is_finite()),
                "{name}: change"
            );
        }
    }
}

/// Every light off with an object shown (a variant that used to panic once
/// the room's solution was kept): radiance is linear in the lights, so every
/// pixel the model explains goes to exactly 0 on both methods; only the
/// pixels copied from the photo (seen nowhere in the model) keep it. With
/// `--samples` the rounds add nothing either.
#[test]
fn every_light_off_renders_black_where_the_model_sees() {
    use arlux::relight::{TextureSettings, render_texture};
    use arlux::render::{RenderSettings, render};
    let mut scene = desk();
    scene.lights.iter_mut().for_each(|l| l.scale = 0.0);
    assert!(scene.objects.iter().any(|o| o.enabled));
    let photo = scene.load_photo().unwrap();
    let pda = |samples: u32| {
        let mut settings = RenderSettings::default();
        settings.residual.samples = samples;
        render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap()
    };
    let texture = render_texture(
        &scene,
        &photo,
        &TextureSettings::default(),
        &mut StageTimes::default(),
    )
    .unwrap();
    for (name, out) in [
        ("pda", pda(0)),
        ("pda, 4 rounds", pda(4)),
        ("texture", texture),
    ] {
        let img = &out.composite.image;
        assert!(all_finite(img), "{name}: a non-finite or negative pixel");
        let lit: Vec<usize> = (0..img.pixels.len())
            .filter(|&i| img.pixels[i] != glam::Vec3::ZERO)
            .collect();
        assert!(
            lit.iter().all(|&i| img.pixels[i] == photo.pixels[i]),
            "{name}: a pixel neither black nor the photo's"
        );
        assert!(
            lit.len() <= out.composite.copied,
            "{name}: {} pixels lit, {} copied from the photo",
            lit.len(),
            out.composite.copied
        );
        assert!(out.composite.copied < img.pixels.len() / 20, "{name}");
    }
}
