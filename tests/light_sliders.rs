//! A session's lights scaled and switched in place ([`Session::relight`]):
//! each image is the one a full render of the new scales gives, to 1e-5
//! relative, and so is an object's move after it.

mod common;
use common::{desk, differing, relative_difference};

use arlux::image_io::Image;
use arlux::render::{Relight, RenderSettings, Session, render};
use arlux::scene::Scene;
use arlux::util::stages::StageTimes;

fn scaled(base: &Scene, panel: f64, spot: f64) -> Scene {
    let mut scene = base.clone();
    scene.lights[0].scale = panel;
    scene.lights[1].scale = spot;
    scene
}

fn scales(scene: &Scene) -> Vec<f64> {
    scene.lights.iter().map(|l| l.scale).collect()
}

/// The session's image is a full render's of `scene` within 1e-5 relative
/// (the room's solution is the sum of its lights' alone, to the solver's
/// tolerance; the rest is computed as a full render computes it).
fn assert_same(session: &Session, scene: &Scene, photo: &Image, settings: &RenderSettings) {
    let full = render(scene, photo, settings, &mut StageTimes::default()).unwrap();
    let (a, b) = (&session.composite, &full.composite);
    for (layer, x, y) in [
        ("image", &a.image, &b.image),
        ("direct", &a.direct, &b.direct),
        ("indirect", &a.indirect, &b.indirect),
    ] {
        let d = relative_difference(x, y);
        println!("{layer} at scales {:?}: {d:.2e} relative", scales(scene));
        assert!(
            d <= 1e-5,
            "{layer} differs by {d:.2e} at scales {:?}",
            scales(scene)
        );
    }
    assert!(
        a.alpha == b.alpha,
        "alpha differs at scales {:?}",
        scales(scene)
    );
}

#[test]
fn a_relit_session_equals_a_full_render_of_its_scales() {
    let base = desk().with_variant("box_floor_a").unwrap();
    let photo = base.load_photo().unwrap();
    // With rounds too: the per-pixel samples read the scales as well.
    for samples in [0, 2] {
        let mut settings = RenderSettings::default();
        settings.residual.samples = samples;
        let first = scaled(&base, 1.0, 2.0);
        let mut session =
            Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
        // Dimmed, switched off, brightened (the photo's grain then), back.
        for (panel, spot) in [(0.5, 2.0), (0.0, 1.0), (3.0, 0.25), (1.0, 2.0)] {
            let scene = scaled(&base, panel, spot);
            session.relight(&scene, &mut StageTimes::default()).unwrap();
            assert_same(&session, &scene, &photo, &settings);
        }
        // An object moved after a relight: the update keeps the new scales.
        let mut moved = scaled(&base, 0.0, 1.5);
        session.relight(&moved, &mut StageTimes::default()).unwrap();
        moved.objects[0].pose.translate.x += 0.1;
        session.update(&moved, &mut StageTimes::default()).unwrap();
        assert_same(&session, &moved, &photo, &settings);
    }
}

#[test]
fn what_a_relight_cannot_do_is_refused_and_the_session_kept() {
    let base = desk().with_variant("box_floor_a").unwrap();
    let photo = base.load_photo().unwrap();
    let settings = RenderSettings::default();
    let first = scaled(&base, 0.5, 1.0);
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    let before = session.composite.image.clone();
    let mut times = StageTimes::default();
    // The lights as photographed: a full render meshes the room coarser.
    assert_eq!(
        session.relight(&scaled(&base, 1.0, 1.0), &mut times),
        Err(Relight::PatchSize)
    );
    // The virtual bulb switched on: the pixel data holds no terms for it.
    let mut bulb = first.clone();
    bulb.lights[2].scale = 1.0;
    assert_eq!(
        session.relight(&bulb, &mut times),
        Err(Relight::LightsTraced)
    );
    let mut moved = first.clone();
    moved.objects[0].pose.translate.x += 0.1;
    assert_eq!(
        session.relight(&moved, &mut times),
        Err(Relight::NotOnlyScales)
    );
    let mut hidden = first.clone();
    hidden.objects[0].enabled = false;
    assert_eq!(
        session.relight(&hidden, &mut times),
        Err(Relight::NotOnlyScales)
    );
    assert_eq!(differing(&session.composite.image, &before), 0);
    // With the patch size given, the lights as photographed are a relight.
    let settings = RenderSettings {
        patch_size: arlux::render::PatchSize::Metres(0.5),
        ..RenderSettings::default()
    };
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    let photographed = scaled(&base, 1.0, 1.0);
    session.relight(&photographed, &mut times).unwrap();
    assert_same(&session, &photographed, &photo, &settings);
}

/// Rooms with more lights and objects whose light bounces between them:
/// the lounge's stool (three lights and a real bulb) and the materials'
/// trio of glTF objects; the room meshed at a given size so that the
/// lights as photographed are a relight too.
#[test]
fn relit_sessions_of_other_rooms_equal_their_full_renders() {
    for (scene, variant, metres) in [("lounge", "stool_a", 0.8), ("materials", "trio", 0.5)] {
        let base = common::load(scene, "scene.toml")
            .with_variant(variant)
            .unwrap();
        let photo = base.load_photo().unwrap();
        let settings = RenderSettings {
            patch_size: arlux::render::PatchSize::Metres(metres),
            ..RenderSettings::default()
        };
        let mut session =
            Session::start(&base, &photo, &settings, &mut StageTimes::default()).unwrap();
        for (panel, spot) in [(0.5, 1.5), (1.25, 0.0)] {
            let scene = scaled(&base, panel, spot);
            session.relight(&scene, &mut StageTimes::default()).unwrap();
            assert_same(&session, &scene, &photo, &settings);
        }
    }
}

/// Solved ahead ([`Session::prepare_relights`], what `arlux serve` does
/// while idle), a slider's first step solves nothing per light: it sums.
/// Its image is a full render's, and so is a move's after it. On the
/// photo's lights with the automatic patch size nothing is solved ahead:
/// a change of lights meshes the room finer and renders in full.
#[test]
fn lights_solved_ahead_make_the_first_step_a_sum() {
    let base = desk().with_variant("box_floor_a").unwrap();
    let photo = base.load_photo().unwrap();
    let settings = RenderSettings::default();
    let stages = |times: &StageTimes| -> Vec<String> {
        times.0.iter().map(|(name, _)| name.to_string()).collect()
    };
    let mut photographed =
        Session::start(&base, &photo, &settings, &mut StageTimes::default()).unwrap();
    assert!(!photographed.prepare_relights(&mut StageTimes::default()));
    let first = scaled(&base, 1.0, 2.0);
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    let mut ahead = StageTimes::default();
    assert!(session.prepare_relights(&mut ahead));
    let solved = stages(&ahead);
    assert!(
        solved.iter().any(|s| s == "solve the room per light"),
        "{solved:?}"
    );
    assert!(solved.iter().any(|s| s == "solve the change"), "{solved:?}");
    // Once: the next call finds both solved.
    assert!(!session.prepare_relights(&mut StageTimes::default()));
    let scene = scaled(&base, 0.5, 2.5);
    let mut step = StageTimes::default();
    session.relight(&scene, &mut step).unwrap();
    let done = stages(&step);
    assert!(
        done.iter().any(|s| s == "sum the change per light"),
        "{done:?}"
    );
    for solve in [
        "solve the room per light",
        "solve the change",
        "final gather on objects",
    ] {
        assert!(!done.iter().any(|s| s == solve), "{solve} ran: {done:?}");
    }
    assert_same(&session, &scene, &photo, &settings);
    let mut moved = scene.clone();
    moved.objects[0].pose.translate.x += 0.1;
    session.update(&moved, &mut StageTimes::default()).unwrap();
    assert_same(&session, &moved, &photo, &settings);
}

/// A standby (the session a change of the lights renders, made ahead)
/// makes the first change of a light a relight, after a move too, and the
/// session it replaced stands by for the lights set back as photographed;
/// each image is the full render's of the state to 1e-5 relative. What
/// neither traced (a virtual light switched on) renders in full.
#[test]
fn a_standby_makes_the_first_change_of_a_light_a_relight() {
    use arlux::interactive::{Edit, Interactive, RenderPath, Standby};
    let base = desk().with_variant("box_floor_a").unwrap();
    let photo = base.load_photo().unwrap();
    let settings = RenderSettings::default();
    let method = arlux::settings::Method::Pda(settings);
    let times = &mut StageTimes::default();
    let same_as_full = |it: &Interactive| {
        let full = render(it.scene(), &photo, &settings, &mut StageTimes::default()).unwrap();
        let d = relative_difference(it.image(), &full.composite.image);
        println!("at scales {:?}: {d:.2e} relative", scales(it.scene()));
        assert!(d <= 1e-5, "{d:.2e} at scales {:?}", scales(it.scene()));
    };
    for moved_first in [false, true] {
        let mut it = Interactive::new(base.clone(), photo.clone(), settings, times).unwrap();
        let scene = it
            .standby_scene()
            .expect("the photo's lights on the automatic size");
        it.offer_standby(Standby::start(scene, &photo, &method, times).unwrap());
        if moved_first {
            let nudge = Edit::Nudge {
                object: 0,
                right_m: 0.1,
                forward_m: 0.05,
            };
            let out = it.apply(nudge, times).unwrap();
            assert!(matches!(out.path, RenderPath::Update { .. }), "{out:?}");
        }
        let out = it
            .apply(
                Edit::Light {
                    light: 0,
                    scale: 0.5,
                },
                times,
            )
            .unwrap();
        assert!(matches!(out.path, RenderPath::Relight), "{out:?}");
        same_as_full(&it);
        // Its lights were solved ahead, at its pose or the one it moved to.
        let out = it
            .apply(
                Edit::Light {
                    light: 1,
                    scale: 2.0,
                },
                times,
            )
            .unwrap();
        assert!(matches!(out.path, RenderPath::Relight), "{out:?}");
        same_as_full(&it);
        // As photographed: the coarser session the standby replaced stands
        // by in turn, and relights (at the scales it was rendered at, and
        // moved by updates: bit for bit); changed again, the finer one does.
        let set = |it: &mut Interactive, light, scale, times: &mut StageTimes| {
            it.apply(Edit::Light { light, scale }, times).unwrap().path
        };
        set(&mut it, 1, 1.0, times);
        let path = set(&mut it, 0, 1.0, times);
        assert!(matches!(path, RenderPath::Relight), "{path:?}");
        let full = render(it.scene(), &photo, &settings, &mut StageTimes::default()).unwrap();
        assert_eq!(differing(it.image(), &full.composite.image), 0);
        let path = set(&mut it, 0, 0.25, times);
        assert!(matches!(path, RenderPath::Relight), "{path:?}");
        same_as_full(&it);
        // A virtual light switched on was never traced: in full.
        let path = set(&mut it, 2, 1.0, times);
        assert!(matches!(path, RenderPath::Full { .. }), "{path:?}");
        same_as_full(&it);
    }
}
