//! The editing session behind `arlux serve`: an object stood where a
//! click sees the floor, slid, the lights changed; what it shows equals
//! the full render of the variant it saves, bit for bit; bad edits are
//! refused and change nothing.

mod common;
use common::Desk;

use arlux::interactive::{Edit, Interactive, RenderPath};
use arlux::model::StageTimes;
use arlux::render::RenderSettings;
use arlux::scene::Scene;
use glam::DVec3;

fn session(desk: &Desk) -> Interactive {
    let scene = Scene::load(desk.scene()).unwrap();
    let photo = scene.read_photo().unwrap().0;
    Interactive::new(
        scene,
        photo,
        RenderSettings::default(),
        &mut StageTimes::default(),
    )
    .unwrap()
}

/// The image point where the camera sees `p`.
fn pixel_of(it: &Interactive, p: DVec3) -> (f64, f64) {
    let (x, y, _) = it.base().camera.project(p).unwrap();
    (x, y)
}

/// The centre of the object's lowest extent, in the world.
fn footprint_centre(it: &Interactive, object: usize) -> DVec3 {
    let o = &it.scene().objects[object];
    let points = o
        .surfaces
        .iter()
        .flat_map(|s| s.triangles.iter().flatten())
        .map(|&p| o.pose.apply(p).as_dvec3());
    let (lo, hi) = arlux::geometry::bounds(points);
    DVec3::new(0.5 * (lo.x + hi.x), lo.y, 0.5 * (lo.z + hi.z))
}

/// Stands object 0 where image point `p` sees the floor.
fn place(
    it: &mut Interactive,
    p: (f64, f64),
    times: &mut StageTimes,
) -> arlux::interactive::Outcome {
    let edit = Edit::Place {
        object: 0,
        x: p.0,
        y: p.1,
    };
    it.apply(edit, times).unwrap()
}

/// Sets light `light`'s scale.
fn light(
    it: &mut Interactive,
    light: usize,
    scale: f64,
    times: &mut StageTimes,
) -> arlux::interactive::Outcome {
    it.apply(Edit::Light { light, scale }, times).unwrap()
}

fn bits(a: &arlux::image_io::Image) -> Vec<[u32; 3]> {
    a.pixels
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect()
}

#[test]
fn what_the_session_shows_is_the_render_of_the_variant_it_saves() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    // Stand the box where a click sees the floor: its footprint's centre
    // projects onto the click.
    let click = pixel_of(&it, DVec3::new(-0.6, 0.0, 0.6));
    let out = it
        .apply(
            Edit::Place {
                object: 0,
                x: click.0,
                y: click.1,
            },
            times,
        )
        .unwrap();
    assert!(matches!(out.path, RenderPath::Update { .. }), "{out:?}");
    let (x, y) = pixel_of(&it, footprint_centre(&it, 0));
    let off = ((x - click.0).powi(2) + (y - click.1).powi(2)).sqrt();
    assert!(
        off < 1.0,
        "the footprint's centre is {off:.2} px from the click"
    );
    // Slide it, turn it, switch the panel off, slide again.
    for k in 1..=5 {
        let p = pixel_of(
            &it,
            DVec3::new(-0.6 + 0.1 * k as f64, 0.0, 0.6 - 0.05 * k as f64),
        );
        let out = place(&mut it, p, times);
        assert!(matches!(out.path, RenderPath::Update { .. }), "{out:?}");
    }
    it.apply(
        Edit::Turn {
            object: 0,
            yaw_deg: 35.0,
        },
        times,
    )
    .unwrap();
    let out = light(&mut it, 0, 0.0, times);
    assert!(matches!(out.path, RenderPath::Full { .. }), "{out:?}");
    // The lights changed already: a slider now recombines the kept pixels.
    let out = light(&mut it, 1, 1.5, times);
    assert_eq!(out.path, RenderPath::Relight);
    let p = pixel_of(&it, DVec3::new(0.2, 0.0, 0.1));
    let out = place(&mut it, p, times);
    assert!(matches!(out.path, RenderPath::Update { .. }), "{out:?}");

    let name = it.next_variant_name();
    let file = it.save_variant(&name).unwrap();
    let saved = Scene::load(&file).unwrap().with_variant(&name).unwrap();
    let (full, _) = common::render_default(&saved);
    // A slider sums the room's solution per light: the solver's tolerance
    // apart (bit for bit without a slider: the other tests here).
    let d = common::relative_difference(it.image(), &full.composite.image);
    assert!(
        d <= 1e-5,
        "the saved variant's render differs by {d:.2e} relative"
    );
    // The scene file is kept as it was, and a saved file is never replaced.
    let original = std::fs::read_to_string(common::scene_dir("desk").join("scene.toml")).unwrap();
    assert_eq!(std::fs::read_to_string(desk.scene()).unwrap(), original);
    assert!(
        std::fs::read_to_string(&file)
            .unwrap()
            .starts_with(original.trim_end())
    );
    assert!(it.save_variant(&name).is_err());
    assert_ne!(it.next_variant_name(), name);
}

/// After its first image a session composites the image, the objects'
/// coverage and their own light alone (what its views show): the shadow
/// view and the layers it saves still equal a full render's, bit for bit.
#[test]
fn the_shadow_view_and_saved_layers_of_an_updated_session_are_a_full_render_s() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    for k in 0..3 {
        let p = pixel_of(&it, DVec3::new(-0.5 + 0.15 * k as f64, 0.0, 0.5));
        let out = place(&mut it, p, times);
        assert!(matches!(out.path, RenderPath::Update { .. }), "{out:?}");
    }
    let name = it.next_variant_name();
    let file = it.save_variant(&name).unwrap();
    let saved = Scene::load(&file).unwrap().with_variant(&name).unwrap();
    check_views_and_layers(&mut it, &saved);
    // The next move composites the views' layers alone again.
    let p = pixel_of(&it, DVec3::new(0.1, 0.0, 0.5));
    place(&mut it, p, times);
    assert!(it.composite().unwrap().direct.pixels.is_empty());
}

/// The same with a glTF chrome ball, whose pixels are shaded per pixel
/// through its BRDF (the composite's other path).
#[test]
fn a_material_object_s_shadow_view_and_saved_layers_are_a_full_render_s() {
    let scene = common::load("materials", "scene.toml");
    let photo = scene.read_photo().unwrap().0;
    let times = &mut StageTimes::default();
    let mut it = Interactive::new(scene, photo, RenderSettings::default(), times).unwrap();
    let chrome = it.base().objects.iter().position(|o| o.name == "chrome");
    let chrome = chrome.expect("the materials scene has a chrome ball");
    for (k, x) in [0.4, 0.5].into_iter().enumerate() {
        let p = pixel_of(&it, DVec3::new(x, 0.0, -0.5));
        let edit = Edit::Place {
            object: chrome,
            x: p.0,
            y: p.1,
        };
        let out = it.apply(edit, times).unwrap();
        // The first shows the ball (a new set of objects), the next moves it.
        assert_eq!(
            matches!(out.path, RenderPath::Update { .. }),
            k > 0,
            "{out:?}"
        );
    }
    let state = it.scene().clone();
    check_views_and_layers(&mut it, &state);
}

/// `it`'s shadow view and every layer it saves are those of the full
/// render of `scene`, bit for bit; the session holds the views' layers alone.
fn check_views_and_layers(it: &mut Interactive, scene: &Scene) {
    let c = it.composite().unwrap();
    assert!(c.direct.pixels.is_empty() && c.object.pixels.len() == c.image.pixels.len());
    let (full, _) = common::render_default(scene);
    let photo = it.photo().clone();
    let shadow = full.composite.shadow(&photo);
    assert!(
        shadow.pixels.iter().any(|s| s.x < 0.9),
        "the object casts a shadow"
    );
    assert!(full.composite.object.pixels.iter().any(|o| o.x > 0.0));
    assert_eq!(bits(&it.frame().shadow), bits(&shadow));
    let f = &full.composite;
    it.with_every_layer(&mut StageTimes::default(), |c| {
        for (name, a, b) in [
            ("image", &c.image, &f.image),
            ("direct", &c.direct, &f.direct),
            ("indirect", &c.indirect, &f.indirect),
            ("change", &c.change, &f.change),
            ("object", &c.object, &f.object),
        ] {
            assert!(bits(a) == bits(b), "the {name} layer differs");
        }
        assert!(c.alpha == f.alpha);
    })
    .unwrap();
}

#[test]
fn bad_edits_are_refused_naming_the_field_and_change_nothing() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    let before = bits(it.image());
    let version = it.version();
    let wall = pixel_of(&it, DVec3::new(-0.5, 1.5, -2.0 + 1e-3));
    let wall_hit = it.room().pick(&it.base().camera, wall.0, wall.1).unwrap();
    assert!(
        wall_hit.1.y.abs() < 0.1,
        "a wall is seen at {wall:?}: {wall_hit:?}"
    );
    let cases = [
        (
            Edit::Place {
                object: 0,
                x: wall.0,
                y: wall.1,
            },
            "x",
            "floor-like",
        ),
        (
            Edit::Place {
                object: 0,
                x: f64::NAN,
                y: 10.0,
            },
            "x",
            "pixel",
        ),
        (
            Edit::Place {
                object: 0,
                x: 10.0,
                y: 1e300,
            },
            "y",
            "pixel",
        ),
        (
            Edit::Place {
                object: 9,
                x: 10.0,
                y: 10.0,
            },
            "object",
            "no virtual object",
        ),
        (
            Edit::Scale {
                object: 0,
                scale: 1e9,
            },
            "scale",
            "must lie",
        ),
        (
            Edit::Scale {
                object: 0,
                scale: 12.0,
            },
            "scale",
            "box",
        ),
        (
            Edit::Turn {
                object: 0,
                yaw_deg: f64::INFINITY,
            },
            "yaw_deg",
            "finite",
        ),
        (
            Edit::Light {
                light: 7,
                scale: 1.0,
            },
            "light",
            "no light",
        ),
        (
            Edit::Light {
                light: 0,
                scale: -1.0,
            },
            "scale",
            "must lie",
        ),
        (
            Edit::Light {
                light: 0,
                scale: -0.0,
            },
            "scale",
            "must lie",
        ),
    ];
    for (edit, field, words) in cases {
        let r = it.apply(edit, times).unwrap_err();
        assert_eq!(r.field, field, "{edit:?}: {r:?}");
        assert!(r.message.contains(words), "{edit:?}: {}", r.message);
    }
    // Pushed against the back wall: the box cuts into it.
    let near = pixel_of(&it, DVec3::new(-0.5, 0.0, -1.86));
    let r = it
        .apply(
            Edit::Place {
                object: 0,
                x: near.0,
                y: near.1,
            },
            times,
        )
        .unwrap_err();
    assert!(r.message.contains("cut into 'back_wall'"), "{}", r.message);
    assert_eq!(it.version(), version);
    assert_eq!(bits(it.image()), before);
    // A name `arlux render --variant NAME` would read as a flag.
    let e = it.save_variant("-v").unwrap_err().to_string();
    assert!(e.contains("not starting with '-'"), "{e}");
}

#[test]
fn a_refined_state_is_the_render_of_its_variant_with_as_many_rounds() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    let p = pixel_of(&it, DVec3::new(0.2, 0.0, 0.1));
    place(&mut it, p, times);
    let stats = it.refine(4, times).expect("the box's pixels are sampled");
    assert_eq!((stats.rounds, it.refined().0), (4, 4));
    let name = it.next_variant_name();
    let file = it.save_variant(&name).unwrap();
    let saved = Scene::load(&file).unwrap().with_variant(&name).unwrap();
    let photo = saved.load_photo().unwrap();
    let mut settings = RenderSettings::default();
    settings.residual.samples = 4;
    let full = arlux::render::render(&saved, &photo, &settings, times).unwrap();
    let same = |a: &arlux::image_io::Image, b: &arlux::image_io::Image| {
        (bits(a).iter().zip(bits(b)))
            .filter(|(x, y)| **x != *y)
            .count()
    };
    assert_eq!(same(&full.composite.image, it.image()), 0);
    // The next edit shows the session's own image again: an update, as
    // without refining.
    let p = pixel_of(&it, DVec3::new(0.0, 0.0, 0.3));
    let out = place(&mut it, p, times);
    assert!(matches!(out.path, RenderPath::Update { .. }), "{out:?}");
    assert_eq!(it.refined().0, 0);
    let name = it.next_variant_name();
    let file = it.save_variant(&name).unwrap();
    let saved = Scene::load(&file).unwrap().with_variant(&name).unwrap();
    let (plain, _) = common::render_default(&saved);
    assert_eq!(same(&plain.composite.image, it.image()), 0);
}

#[test]
fn a_save_after_the_scene_file_was_edited_renders_what_the_session_shows() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    let p = pixel_of(&it, DVec3::new(-0.3, 0.0, 0.4));
    place(&mut it, p, times);
    assert!(!it.file_changed());
    // The box's colour changed in the file while serving.
    desk.edit(
        "scene.toml",
        "rgb = [0.8, 0.32, 0.06]",
        "rgb = [0.1, 0.5, 0.9]",
    );
    assert!(it.file_changed());
    let name = it.next_variant_name();
    let file = it.save_variant(&name).unwrap();
    let saved = Scene::load(&file).unwrap().with_variant(&name).unwrap();
    assert_eq!(
        saved.objects[0].surfaces[0].rgb.to_array(),
        [0.8, 0.32, 0.06]
    );
    let (full, _) = common::render_default(&saved);
    let differ = (bits(&full.composite.image).iter())
        .zip(bits(it.image()))
        .filter(|(a, b)| **a != *b)
        .count();
    assert_eq!(
        differ, 0,
        "{differ} pixels differ from what the session shows"
    );
}

/// Objects are checked against each other as against the room: the box
/// stood where a second box already stands is refused, naming it, and
/// nothing changes; beside it, it stands.
#[test]
fn an_object_placed_into_another_is_refused_naming_it() {
    let desk = Desk::new();
    let text = std::fs::read_to_string(desk.scene()).unwrap()
        + "\n[[virtual]]\nname = \"twin\"\nmesh = \"geometry/box.obj\"\nrgb = [0.2, 0.5, 0.8]\ntranslate = [-0.8, 0.0, 0.6]\n";
    std::fs::write(desk.scene(), text).unwrap();
    let mut it = session(&desk);
    let mut times = StageTimes::default();
    let before = it.version();
    let onto = pixel_of(&it, DVec3::new(-0.8, 0.0, 0.6));
    let refused = it
        .apply(
            Edit::Place {
                object: 0,
                x: onto.0,
                y: onto.1,
            },
            &mut times,
        )
        .unwrap_err();
    assert_eq!(refused.field, "x");
    assert!(
        refused.message.contains("'box' would pass through 'twin'"),
        "{}",
        refused.message
    );
    assert_eq!(it.version(), before, "a refused place changed the state");
    let beside = pixel_of(&it, DVec3::new(0.2, 0.0, 0.6));
    place(&mut it, beside, &mut times);
    assert!(it.version() > before);
}

/// Arrow-key nudges slide the object along the floor, along the camera's
/// right and forward laid flat; more than a metre, or into a wall, is
/// refused.
#[test]
fn a_nudge_slides_the_object_along_the_floor_as_the_camera_sees_it() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let mut times = StageTimes::default();
    let before = it.scene().objects[0].pose.translate;
    it.apply(
        Edit::Nudge {
            object: 0,
            right_m: 0.2,
            forward_m: -0.1,
        },
        &mut times,
    )
    .unwrap();
    let after = it.scene().objects[0].pose.translate;
    let camera = &it.base().camera;
    let flat = |v: DVec3| DVec3::new(v.x, 0.0, v.z).normalize();
    let moved = after - before;
    assert!(moved.y.abs() < 1e-12, "{moved}");
    assert!(
        (moved.dot(flat(camera.right)) - 0.2).abs() < 1e-9,
        "{moved}"
    );
    assert!(
        (moved.dot(flat(camera.forward)) + 0.1).abs() < 1e-9,
        "{moved}"
    );
    let far = it.apply(
        Edit::Nudge {
            object: 0,
            right_m: 1.5,
            forward_m: 0.0,
        },
        &mut times,
    );
    assert_eq!(far.unwrap_err().field, "nudge");
    // Towards the back wall until it would cut in.
    let version = it.version();
    let mut refused = None;
    for _ in 0..20 {
        if let Err(r) = it.apply(
            Edit::Nudge {
                object: 0,
                right_m: 0.0,
                forward_m: 0.5,
            },
            &mut times,
        ) {
            refused = Some(r);
            break;
        }
    }
    let r = refused.expect("the wall stops it");
    assert!(
        r.message.contains("would cut into") || r.message.contains("outside the room"),
        "{}",
        r.message
    );
    assert!(it.version() > version);
}

/// `arlux serve --method texture`: the session renders each move by the
/// texture path in full and relights a scale over its kept preprocess, and
/// shows what `arlux render --method texture` gives of the variant it
/// saves, bit for bit.
#[test]
fn a_texture_path_session_shows_the_texture_render_of_its_saved_state() {
    let desk = Desk::new();
    let scene = Scene::load(desk.scene()).unwrap();
    let photo = scene.read_photo().unwrap().0;
    let options = arlux::settings::RenderOptions {
        method: arlux::settings::RenderMethod::Texture,
        ..Default::default()
    };
    let method = options.resolve().unwrap();
    let arlux::settings::Method::Texture(settings) = method else {
        panic!("not the texture path: {method:?}");
    };
    let times = &mut StageTimes::default();
    let mut it = Interactive::with_method(scene, photo.clone(), method, times).unwrap();
    let p = pixel_of(&it, DVec3::new(0.2, 0.0, 0.1));
    let out = place(&mut it, p, times);
    assert!(matches!(out.path, RenderPath::Full { .. }), "{out:?}");
    let out = light(&mut it, 1, 1.5, times);
    // A scale, the same lights on: one light change over the kept preprocess.
    assert_eq!(out.path, RenderPath::Relight);
    println!(
        "texture path: a light's scale relit in {:.1} ms",
        out.millis
    );
    check_saved(&mut it, &photo, &settings);
    // A light switched off: the preprocess reads which are on.
    let out = light(&mut it, 0, 0.0, times);
    assert!(matches!(out.path, RenderPath::Full { .. }), "{out:?}");
    // No rounds on the texture path: nothing to refine.
    assert!(it.refine(4, times).is_none());
    check_saved(&mut it, &photo, &settings);
}

/// The texture path's render of the variant `it` saves equals its image.
fn check_saved(
    it: &mut Interactive,
    photo: &arlux::image_io::Image,
    settings: &arlux::relight::TextureSettings,
) {
    let name = it.next_variant_name();
    let file = it.save_variant(&name).unwrap();
    let saved = Scene::load(&file).unwrap().with_variant(&name).unwrap();
    let times = &mut StageTimes::default();
    let full = arlux::relight::render_texture(&saved, photo, settings, times).unwrap();
    assert!(
        bits(it.image()) == bits(&full.composite.image),
        "the session differs from the texture path's render of its saved variant"
    );
}

/// A virtual light placed by a click: it goes the height asked above the
/// floor seen there, switched on; the image is the full render of the
/// variant the session saves (which writes its position), bit for bit; a
/// real light, a height the room has no space for, or no number are
/// refused; undo takes the light back.
#[test]
fn a_virtual_light_placed_by_a_click_renders_as_the_variant_it_saves() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    let bulb = it.base().lights.iter().position(|l| !l.real).unwrap();
    assert_eq!(
        it.scene().lights[bulb].scale,
        0.0,
        "the desk's bulb starts off"
    );
    let place_light = |it: &mut Interactive, light: usize, at: DVec3, height_m: f64| {
        let (x, y) = pixel_of(it, at);
        let edit = Edit::PlaceLight {
            light,
            x,
            y,
            height_m,
        };
        it.apply(edit, &mut StageTimes::default())
    };
    let out = place_light(&mut it, bulb, DVec3::new(0.3, 0.0, 0.2), 1.2).unwrap();
    assert!(
        matches!(&out.path, RenderPath::Full { reason } if reason.contains("light")),
        "{out:?}"
    );
    let l = &it.scene().lights[bulb];
    assert_eq!(l.scale, 1.0, "placing a light that is off switches it on");
    let p = l.known_position().unwrap();
    assert!(
        (p - DVec3::new(0.3, 1.2, 0.2)).length() < 2e-3,
        "the bulb is at {p}, not 1.2 m above the floor point clicked"
    );
    let first = bits(it.image());
    // Moved again, a little further.
    let out = place_light(&mut it, bulb, DVec3::new(-0.4, 0.0, 0.5), 0.8).unwrap();
    assert!(matches!(out.path, RenderPath::Full { .. }), "{out:?}");
    assert_ne!(
        bits(it.image()),
        first,
        "the light moved: the image changes"
    );

    let name = it.next_variant_name();
    let file = it.save_variant(&name).unwrap();
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(
        text.contains("position"),
        "the saved variant moves the bulb:\n{text}"
    );
    let saved = Scene::load(&file).unwrap().with_variant(&name).unwrap();
    let (full, _) = common::render_default(&saved);
    assert_eq!(
        bits(it.image()),
        bits(&full.composite.image),
        "the session's image is not the saved variant's render"
    );

    // Refused, changing nothing: a real light, no room above, no number.
    let version = it.version();
    let panel = it.base().lights.iter().position(|l| l.real).unwrap();
    let r = place_light(&mut it, panel, DVec3::new(0.3, 0.0, 0.2), 1.0).unwrap_err();
    assert!(r.message.contains("real light"), "{r:?}");
    let r = place_light(&mut it, bulb, DVec3::new(0.3, 0.0, 0.2), 4.9).unwrap_err();
    assert_eq!(r.field, "height_m");
    assert!(r.message.contains("is free"), "{r:?}");
    let r = place_light(&mut it, bulb, DVec3::new(0.3, 0.0, 0.2), f64::NAN).unwrap_err();
    assert_eq!(r.field, "height_m");
    assert_eq!(it.version(), version);

    // Undo: the light back where the first click put it, the same image.
    it.apply(Edit::Undo, times).unwrap();
    assert_eq!(bits(it.image()), first);
}

/// A folder of meshes for `--assets`: the desk's box as an OBJ without
/// materials, the materials scene's globe as a glTF, and files that are not
/// meshes (which the listing leaves out).
fn asset_folder() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let scenes = common::scene_dir("desk").parent().unwrap().to_path_buf();
    std::fs::copy(
        scenes.join("desk/geometry/box.obj"),
        dir.path().join("crate.obj"),
    )
    .unwrap();
    std::fs::copy(
        scenes.join("materials/geometry/globe.glb"),
        dir.path().join("globe.glb"),
    )
    .unwrap();
    std::fs::write(dir.path().join("notes.txt"), "not a mesh").unwrap();
    std::fs::create_dir(dir.path().join("more.obj")).unwrap();
    dir
}

/// Objects added from a folder: listed by name, each stood where a click
/// sees the floor, named after its file (made unique), a mesh without
/// materials in clay; the session's image is the render of the variant it
/// saves (which carries the added objects), bit for bit; a place that is
/// not floor-like is refused and adds nothing; undo hides the object again.
#[test]
fn objects_added_from_an_asset_folder_render_as_the_variant_saved() {
    let assets = asset_folder();
    let listed = arlux::interactive::list_assets(assets.path()).unwrap();
    let names: Vec<&str> = listed.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["crate.obj", "globe.glb"]);
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    let objects = it.base().objects.len();
    let click = pixel_of(&it, DVec3::new(0.4, 0.0, 0.3));
    let (out, name) = it.add_object(&listed[0].1, click, times).unwrap();
    assert_eq!(name, "crate");
    assert!(matches!(out.path, RenderPath::Full { .. }), "{out:?}");
    assert_eq!(it.scene().objects.len(), objects + 1);
    let (x, y) = pixel_of(&it, footprint_centre(&it, objects));
    assert!(((x - click.0).powi(2) + (y - click.1).powi(2)).sqrt() < 1.0);
    let one = bits(it.image());
    let click = pixel_of(&it, DVec3::new(-0.5, 0.0, 0.6));
    let (_, name) = it.add_object(&listed[0].1, click, times).unwrap();
    assert_eq!(name, "crate-2", "a second copy takes a name of its own");
    let click = pixel_of(&it, DVec3::new(-0.9, 0.0, 0.2));
    let (_, globe) = it.add_object(&listed[1].1, click, times).unwrap();
    assert_eq!(globe, "globe");
    assert!(
        it.scene().objects[objects + 2].surfaces[0]
            .material
            .is_some(),
        "the glTF's material"
    );

    let variant = it.next_variant_name();
    let file = it.save_variant(&variant).unwrap();
    let saved = Scene::load(&file).unwrap().with_variant(&variant).unwrap();
    assert_eq!(saved.objects.len(), objects + 3);
    let (full, _) = common::render_default(&saved);
    assert_eq!(
        bits(it.image()),
        bits(&full.composite.image),
        "the saved variant renders otherwise"
    );
    assert!(
        !it.file_changed(),
        "adding objects does not count as the file changing"
    );

    // A wall is no place to stand: refused, nothing added.
    let version = it.version();
    let wall = pixel_of(&it, DVec3::new(0.0, 1.2, -1.6));
    let r = it.add_object(&listed[0].1, wall, times).unwrap_err();
    assert!(r.message.contains("not floor-like"), "{r:?}");
    assert_eq!(
        (it.version(), it.base().objects.len()),
        (version, objects + 3)
    );

    // Undo twice: the globe, then the second crate, hidden again.
    it.apply(Edit::Undo, times).unwrap();
    it.apply(Edit::Undo, times).unwrap();
    assert!(!it.scene().objects[objects + 1].enabled);
    assert_eq!(
        bits(it.image()),
        one,
        "undo gives back the image with one crate"
    );
}

/// What the server solves ahead for a slider while idle
/// ([`Interactive::prepare_relights`]): nothing on the photo's lights (a
/// change of lights renders in full, on a finer mesh), each light's part
/// once after that full render, so that the next step only sums, and
/// nothing after a move (a drag's next move would wait for it).
#[test]
fn a_slider_s_parts_are_solved_ahead_after_a_light_change_not_after_a_move() {
    let desk = Desk::new();
    let mut it = session(&desk);
    let times = &mut StageTimes::default();
    assert!(!it.prepare_relights(times));
    let out = light(&mut it, 0, 0.5, times);
    assert!(matches!(out.path, RenderPath::Full { .. }), "{out:?}");
    assert!(it.prepare_relights(times));
    assert!(!it.prepare_relights(times));
    let mut step = StageTimes::default();
    let out = light(&mut it, 0, 0.75, &mut step);
    assert!(matches!(out.path, RenderPath::Relight), "{out:?}");
    let stages: Vec<&str> = step.0.iter().map(|(s, _)| *s).collect();
    assert!(
        !stages.contains(&"solve the room per light") && !stages.contains(&"solve the change"),
        "{stages:?}"
    );
    let p = pixel_of(&it, DVec3::new(-0.5, 0.0, 0.5));
    let out = place(&mut it, p, times);
    assert!(matches!(out.path, RenderPath::Update { .. }), "{out:?}");
    assert!(!it.prepare_relights(times));
}
