//! Real assets as users bring them (a generated glTF made like a Blender
//! export: textures, a normal map, nested node scales) inserted into the
//! desk.

mod common;
use common::Desk;
use common::asset::{AssetSpec, write_asset};

use std::sync::Arc;

use arlux::scene::Scene;

/// A smaller prop than the benches' (tests stay quick), same kind.
fn prop() -> AssetSpec {
    AssetSpec {
        triangles: 8_000,
        texture: 256,
        ..AssetSpec::heavy_prop()
    }
}

/// `[[virtual]]` tables placing `geometry/NAME.gltf` at each of `at`.
fn place(desk: &Desk, name: &str, at: &[[f64; 3]]) {
    let mut text = std::fs::read_to_string(desk.path("scene.toml")).unwrap();
    for (i, p) in at.iter().enumerate() {
        text += &format!(
            "\n[[virtual]]\nname = \"{name}_{i}\"\nmesh = \"geometry/{name}.gltf\"\ntranslate = [{}, {}, {}]\n",
            p[0], p[1], p[2]
        );
    }
    std::fs::write(desk.path("scene.toml"), text).unwrap();
}

/// Three objects from one file: the file is read once, and its triangles,
/// every texture and the normal map's tangent frames are one copy shared by
/// the three and by a variant's copy of the scene.
#[test]
fn objects_from_one_file_share_one_copy_of_it() {
    let desk = Desk::new();
    write_asset(&desk.path("geometry"), "prop", &prop());
    place(
        &desk,
        "prop",
        &[[0.3, 0.0, -0.3], [-0.2, 0.0, 0.4], [-0.9, 0.75, -1.3]],
    );
    let scene = Scene::load(desk.path("scene.toml")).unwrap();
    let props: Vec<_> = (scene.objects.iter())
        .filter(|o| o.name.starts_with("prop_"))
        .collect();
    assert_eq!(props.len(), 3);
    let material = |o: &arlux::scene::VirtualObject| o.surfaces[0].material.clone().unwrap();
    let first = material(props[0]);
    let texture = |m: &arlux::materials::SurfaceMaterial| {
        m.material
            .base_texture
            .clone()
            .expect("a base colour texture")
    };
    let normal =
        |m: &arlux::materials::SurfaceMaterial| m.material.normal_texture.clone().unwrap().0;
    for o in &props[1..] {
        let m = material(o);
        assert!(
            Arc::ptr_eq(&texture(&first), &texture(&m)),
            "{}: a second base texture",
            o.name
        );
        assert!(
            Arc::ptr_eq(&normal(&first), &normal(&m)),
            "{}: a second normal map",
            o.name
        );
        assert!(
            Arc::ptr_eq(&first.attributes, &m.attributes),
            "{}: second attributes",
            o.name
        );
        assert!(
            Arc::ptr_eq(&props[0].surfaces[0].triangles, &o.surfaces[0].triangles),
            "{}: a second copy of the triangles",
            o.name
        );
    }
    let copy = scene.clone();
    assert!(Arc::ptr_eq(
        &scene.objects[0].surfaces[0].triangles,
        &copy.objects[0].surfaces[0].triangles
    ));
    // Placed where asked, at the size made: nested node scales applied once.
    let size = props[0].surfaces[0]
        .triangles
        .iter()
        .flat_map(|t| t.iter())
        .fold(0.0f32, |h, p| h.max(p.y));
    assert!((size - 0.45).abs() < 1e-4, "height {size}");
}

/// The prop standing on the desk's floor, rendered with the defaults: every
/// layer finite and non-negative (but `change`, which is signed), and none
/// of the prop's pixels black: the normal map's V-grooves tilt shading
/// normals 85°, away from the camera on the prop's flanks (269 of its 4,084
/// pixels were exactly 0 when such normals reflected nothing).
#[test]
fn a_normal_mapped_prop_has_no_black_pixels_and_no_negative_layer() {
    let desk = Desk::new();
    let spec = AssetSpec {
        width: 0.5,
        height: 0.7,
        groove_deg: 85.0,
        grooves: 10,
        ..prop()
    };
    write_asset(&desk.path("geometry"), "prop", &spec);
    place(&desk, "prop", &[[0.2, 0.0, -0.4]]);
    let mut scene = Scene::load(desk.path("scene.toml")).unwrap();
    scene
        .objects
        .iter_mut()
        .for_each(|o| o.enabled = o.name == "prop_0");
    let (out, _) = common::render_default(&scene);
    let c = &out.composite;
    for (name, img) in [
        ("image", &c.image),
        ("direct", &c.direct),
        ("indirect", &c.indirect),
        ("object", &c.object),
    ] {
        let bad = (img.pixels.iter())
            .filter(|p| !p.is_finite() || p.min_element() < 0.0)
            .count();
        assert_eq!(bad, 0, "{name}: {bad} pixels non-finite or negative");
    }
    let lum = |p: glam::Vec3| p.dot(glam::Vec3::splat(1.0 / 3.0));
    let object: Vec<usize> = (0..c.alpha.len()).filter(|&i| c.alpha[i] >= 1.0).collect();
    let black = (object.iter())
        .filter(|&&i| lum(c.image.pixels[i]) <= 0.0)
        .count();
    assert!(
        object.len() > 2000,
        "the prop covers {} pixels",
        object.len()
    );
    assert_eq!(
        black,
        0,
        "{black} of the prop's {} pixels are black",
        object.len()
    );
}

/// A render reads the meshes of only what it shows: a disabled object, or
/// one its variant hides, is left unread (its file is not opened past a
/// check that it exists), and showing an unread object is an error.
#[test]
fn only_the_objects_shown_are_read() {
    use arlux::scene::Showing;
    let desk = Desk::new();
    write_asset(&desk.path("geometry"), "prop", &prop());
    place(&desk, "prop", &[[0.3, 0.0, -0.3]]);
    let text = std::fs::read_to_string(desk.path("scene.toml")).unwrap();
    let text = text.replace(
        "mesh = \"geometry/prop.gltf\"\n",
        "mesh = \"geometry/prop.gltf\"\nenabled = false\n",
    ) + "\n[[variant]]\nname = \"with_prop\"\nobjects = { prop_0 = {} }\nhide = [\"box\"]\n";
    std::fs::write(desk.path("scene.toml"), text).unwrap();
    let read = |s: &Scene, name: &str| s.objects.iter().find(|o| o.name == name).unwrap().mesh_read;

    let base = Scene::load_showing(desk.path("scene.toml"), Showing::Base).unwrap();
    assert!(read(&base, "box") && !read(&base, "prop_0"));
    let err = base.with_variant("with_prop").unwrap_err().to_string();
    assert!(err.contains("'prop_0', whose mesh was not read"), "{err}");
    let hidden =
        Scene::load_showing(desk.path("scene.toml"), Showing::Variant("box_floor_a")).unwrap();
    assert!(!read(&hidden, "prop_0"));
    let shown =
        Scene::load_showing(desk.path("scene.toml"), Showing::Variant("with_prop")).unwrap();
    assert!(read(&shown, "prop_0") && !read(&shown, "box"));
    let scene = shown.with_variant("with_prop").unwrap();
    assert!(
        scene
            .objects
            .iter()
            .all(|o| o.enabled == (o.name == "prop_0"))
    );
    // Everything (a session, `info`) reads every mesh.
    let all = Scene::load(desk.path("scene.toml")).unwrap();
    assert!(
        all.objects
            .iter()
            .all(|o| o.mesh_read && !o.surfaces.is_empty())
    );
}

/// The bounds of an object's triangles as placed.
fn placed_bounds(scene: &Scene, name: &str) -> (glam::DVec3, glam::DVec3) {
    let o = scene.objects.iter().find(|o| o.name == name).unwrap();
    let points = (0..o.surfaces.len())
        .flat_map(|i| {
            o.surfaces[i]
                .triangles
                .iter()
                .map(|t| t.map(|p| o.pose.apply(p)))
        })
        .flatten()
        .map(|p| p.as_dvec3());
    arlux::geometry::bounds(points)
}

/// `up = "z"` turns a file's Z-up frame into the scene's Y-up one: the
/// prop (made Y-up, 0.45 m tall) read as Z-up lies along −z, and its
/// normals turn with it (still pointing out of the solid).
#[test]
fn up_z_turns_a_z_up_file_upright() {
    let desk = Desk::new();
    write_asset(&desk.path("geometry"), "prop", &prop());
    place(&desk, "prop", &[[0.0, 0.0, 0.0]]);
    desk.edit(
        "scene.toml",
        "mesh = \"geometry/prop.gltf\"\n",
        "mesh = \"geometry/prop.gltf\"\nup = \"z\"\n",
    );
    let scene = Scene::load(desk.path("scene.toml")).unwrap();
    let (lo, hi) = placed_bounds(&scene, "prop_0");
    assert!((lo.z + 0.45).abs() < 1e-4 && hi.z.abs() < 1e-4, "{lo} {hi}");
    assert!(
        (hi.y - lo.y - 0.22).abs() < 0.01 && (lo.y + hi.y).abs() < 1e-4,
        "{lo} {hi}"
    );
    let o = scene.objects.iter().find(|o| o.name == "prop_0").unwrap();
    let s = &o.surfaces[0];
    let normals = &s.material.as_ref().unwrap().attributes.normals;
    let outward = (s.triangles.iter().zip(normals.iter()))
        .filter(|(t, n)| {
            let c = (t[0] + t[1] + t[2]) / 3.0;
            // The body's side: away from its axis (now the z axis).
            let radial = glam::Vec3::new(c.x, c.y, 0.0);
            radial.length() < 0.05 || n[0].dot(radial) > 0.0 || n[0].z.abs() > 0.9
        })
        .count();
    assert_eq!(
        outward,
        s.triangles.len(),
        "normals not turned with the mesh"
    );
    let err = {
        desk.edit("scene.toml", "up = \"z\"", "up = \"x\"");
        Scene::load(desk.path("scene.toml"))
            .unwrap_err()
            .to_string()
    };
    assert!(
        err.contains("virtual[1].up: \"y\" or \"z\", not \"x\""),
        "{err}"
    );
}

/// `stand = "below"` rests the object on the highest real surface under
/// its footprint, wherever the scene or a variant puts it: floating above
/// the floor or sunk into it, it stands on the floor (y = 0); above the
/// table, on its top; nothing below is an error naming the object.
#[test]
fn stand_below_rests_an_object_on_the_surface_under_it() {
    let desk = Desk::new();
    write_asset(&desk.path("geometry"), "prop", &prop());
    place(&desk, "prop", &[[0.3, 0.4, -0.3]]);
    desk.edit(
        "scene.toml",
        "mesh = \"geometry/prop.gltf\"\n",
        "mesh = \"geometry/prop.gltf\"\nstand = \"below\"\n",
    );
    let text = std::fs::read_to_string(desk.path("scene.toml")).unwrap()
        + "\n[[variant]]\nname = \"sunk\"\nobjects = { prop_0 = { translate = [0.3, -0.1, -0.3] } }\n"
        + "\n[[variant]]\nname = \"on_table\"\nobjects = { prop_0 = { translate = [-0.35, 1.3, -1.4] } }\n"
        + "\n[[variant]]\nname = \"outside\"\nobjects = { prop_0 = { translate = [3.0, 0.0, 0.0] } }\n";
    std::fs::write(desk.path("scene.toml"), text).unwrap();
    let scene = Scene::load(desk.path("scene.toml")).unwrap();
    let floor = |s: &Scene| placed_bounds(s, "prop_0").0.y;
    assert!(floor(&scene).abs() < 1e-6, "floating: {}", floor(&scene));
    let sunk = scene.with_variant("sunk").unwrap();
    assert!(floor(&sunk).abs() < 1e-6, "sunk: {}", floor(&sunk));
    let table_top = (scene.surfaces.iter())
        .find(|s| s.name == "table_top")
        .unwrap()
        .triangles
        .iter()
        .flatten()
        .map(|p| p.y)
        .fold(f32::MIN, f32::max) as f64;
    let on_table = scene.with_variant("on_table").unwrap();
    assert!(
        (floor(&on_table) - table_top).abs() < 1e-6,
        "{} against the top at {table_top}",
        floor(&on_table)
    );
    let err = scene.with_variant("outside").unwrap_err().to_string();
    assert!(
        err.contains("virtual 'prop_0'.stand: no real surface lies below its footprint"),
        "{err}"
    );
}

/// A motion may start from a variant and hide objects: its poses show what
/// the variant shows, less what it hides, with the moving object placed
/// (and a motion run reads only those meshes).
#[test]
fn a_motion_starts_from_a_variant_and_hides() {
    use arlux::scene::Showing;
    let desk = Desk::new();
    write_asset(&desk.path("geometry"), "prop", &prop());
    place(&desk, "prop", &[[0.3, 0.0, -0.3]]);
    desk.edit(
        "scene.toml",
        "mesh = \"geometry/prop.gltf\"\n",
        "mesh = \"geometry/prop.gltf\"\nenabled = false\n",
    );
    let text = std::fs::read_to_string(desk.path("scene.toml")).unwrap()
        + "\n[[motion]]\nname = \"roll\"\nobject = \"prop_0\"\nvariant = \"spot_x2\"\nhide = [\"box\", \"bulb\"]\n"
        + "translations = [[0.3, 0.0, -0.3], [0.1, 0.0, -0.1]]\n"
        + "\n[[motion]]\nname = \"lit_slide\"\nobject = \"box\"\nvariant = \"spot_x2\"\n"
        + "translations = [[0.3, 0.0, -0.3]]\n";
    std::fs::write(desk.path("scene.toml"), text).unwrap();
    let scene = Scene::load_showing(desk.path("scene.toml"), Showing::Motion("roll")).unwrap();
    let read = |name: &str| {
        scene
            .objects
            .iter()
            .find(|o| o.name == name)
            .unwrap()
            .mesh_read
    };
    assert!(read("prop_0") && !read("box"));
    let pose = scene.with_motion_pose("roll", 1).unwrap();
    let spot_x2 = scene.with_variant("spot_x2").unwrap();
    for (l, v) in pose.lights.iter().zip(&spot_x2.lights) {
        let expected = if l.name == "bulb" { 0.0 } else { v.scale };
        assert_eq!(l.scale, expected, "{}", l.name);
    }
    let shown: Vec<&str> = (pose.objects.iter())
        .filter(|o| o.enabled)
        .map(|o| o.name.as_str())
        .collect();
    assert_eq!(shown, ["prop_0"]);
    let prop = pose.objects.iter().find(|o| o.name == "prop_0").unwrap();
    assert_eq!(prop.pose.translate, glam::DVec3::new(0.1, 0.0, -0.1));
    // A variant hiding the moving object (spot_x2 hides the box) still
    // shows it in the motion.
    let lit = Scene::load_showing(desk.path("scene.toml"), Showing::Motion("lit_slide")).unwrap();
    let pose = lit.with_motion_pose("lit_slide", 0).unwrap();
    assert!(
        pose.objects
            .iter()
            .find(|o| o.name == "box")
            .unwrap()
            .enabled
    );
    // Hiding the object that moves is refused, naming the key.
    desk.edit(
        "scene.toml",
        "hide = [\"box\", \"bulb\"]",
        "hide = [\"prop_0\"]",
    );
    let err = Scene::load(desk.path("scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("motion[1].hide: hides 'prop_0', which this motion moves"),
        "{err}"
    );
}

/// The texture path measures what linking a prop's triangles makes on a
/// sample of them before it starts; where that would pass `--memory` it
/// refuses before linking, naming the flag and the budget that would fit,
/// and that budget renders.
#[test]
fn the_texture_path_refuses_links_that_would_not_fit_and_says_what_would() {
    let desk = Desk::new();
    let spec = AssetSpec {
        triangles: 3_000,
        ..prop()
    };
    write_asset(&desk.path("geometry"), "prop", &spec);
    place(&desk, "prop", &[[0.3, 0.0, -0.3]]);
    let out = desk.path("t.exr");
    let run = |memory: &str| {
        common::arlux(&[
            "render",
            &desk.scene(),
            "--method",
            "texture",
            "--json",
            "-o",
            out.to_str().unwrap(),
            "--memory",
            memory,
        ])
    };
    let refused = run("120M");
    let message = String::from_utf8_lossy(&refused.stderr).to_string();
    assert_eq!(refused.status.code(), Some(2), "{message}");
    assert!(
        message.contains("120 MB --memory allows")
            && message.contains("--method pda")
            && message.contains("triangles"),
        "{message}"
    );
    assert!(!out.exists(), "a refused render wrote its image");
    let fits = message
        .split("give --memory ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .map(|t| t.trim_end_matches(','))
        .expect("a budget that fits")
        .to_string();
    let ok = run(&fits);
    assert!(
        ok.status.success(),
        "--memory {fits}: {}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&ok.stdout).unwrap();
    let estimate = &report["texture"]["object_links_estimate"];
    let (expected, made) = (
        estimate["links"].as_f64().unwrap(),
        report["links"].as_f64().unwrap(),
    );
    // The estimate counts the room's links too, copied into the transport.
    assert!(
        (expected / made - 1.0).abs() < 0.25,
        "{expected} against {made}"
    );
    let peak = report["peak_memory_bytes"].as_f64().unwrap();
    let budget: f64 = fits.trim_end_matches('M').parse::<f64>().unwrap() * 1e6;
    assert!(
        peak <= budget,
        "peak {peak} over the budget {budget} it was given"
    );
}

/// A prop large enough to be traced as instances of one scene: hits of
/// the scene's camera rays are the world triangles' (to float rounding),
/// and an update that moves one of two copies gives the image a full
/// render of the pose gives, bit for bit.
#[test]
fn large_objects_traced_as_instances_hit_as_their_triangles_and_update_as_renders_do() {
    use arlux::model::StageTimes;
    use arlux::render::{RenderSettings, Session, render};
    use arlux::trace::{Layer, SurfaceTriangles, TraceRay, Tracer};
    let desk = Desk::new();
    let spec = AssetSpec {
        triangles: 10_000,
        texture: 64,
        ..AssetSpec::heavy_prop()
    };
    write_asset(&desk.path("geometry"), "prop", &spec);
    place(&desk, "prop", &[[0.3, 0.0, -0.3], [-0.2, 0.0, 0.4]]);
    // Turned and scaled: an instance's normal and hit are the object's
    // frame's turned into the world's.
    desk.edit(
        "scene.toml",
        "name = \"prop_0\"\n",
        "name = \"prop_0\"\nrotate = [20.0, 35.0, -10.0]\nscale = 1.3\n",
    );
    let text = std::fs::read_to_string(desk.path("scene.toml")).unwrap()
        + "\n[[motion]]\nname = \"walk\"\nobject = \"prop_0\"\n"
        + "translations = [[0.3, 0.0, -0.3], [0.12, 0.0, -0.18], [0.0, 0.0, 0.05]]\n";
    std::fs::write(desk.path("scene.toml"), text).unwrap();
    let base = Scene::load(desk.path("scene.toml")).unwrap();
    let first = base.with_motion_pose("walk", 0).unwrap();
    let prop = (first.objects.iter()).find(|o| o.name == "prop_0").unwrap();
    let triangles: usize = prop.surfaces.iter().map(|s| s.triangles.len()).sum();
    assert!(
        triangles >= arlux::scene_tracer::INSTANCE_TRIANGLES,
        "{triangles}"
    );

    // The tracer against the same objects given as world triangles.
    let traced = arlux::scene_tracer::build_tracer(&first).unwrap();
    let virt = first.virtual_world_surfaces();
    let set = |surface: u32, triangles| SurfaceTriangles {
        surface,
        triangles,
        mask: None,
    };
    let real: Vec<_> = (first.surfaces.iter().enumerate())
        .map(|(i, s)| set(i as u32, &s.triangles))
        .collect();
    let world: Vec<_> = virt.iter().map(|(id, t)| set(*id, t)).collect();
    let plain = Tracer::build(&real, &world).unwrap();
    let camera = &first.camera;
    let (mut props, mut apart) = (0, 0);
    for y in (0..camera.height).step_by(3) {
        for x in (0..camera.width).step_by(3) {
            let r = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
            let ray = TraceRay::new(r.origin.as_vec3(), r.direction.as_vec3());
            let (a, b) = (
                traced.intersect(&ray, Layer::All),
                plain.intersect(&ray, Layer::All),
            );
            let (Some(a), Some(b)) = (a, b) else {
                assert!(a.is_none() && b.is_none(), "({x}, {y}): one hit, one miss");
                continue;
            };
            if (a.surface, a.triangle) != (b.surface, b.triangle) {
                // A ray along an edge between two triangles may take either.
                apart += 1;
                continue;
            }
            props += usize::from(a.is_virtual && a.surface >= first.surfaces.len() as u32);
            assert!(
                (a.t - b.t).abs() <= 1e-5 * b.t,
                "({x}, {y}): t {} against {}",
                a.t,
                b.t
            );
            assert!((a.normal - b.normal).length() < 1e-4, "({x}, {y})");
        }
    }
    assert!(props > 300, "{props} hits on the objects");
    assert!(apart * 100 < props, "{apart} hits on other triangles");

    let settings = RenderSettings::default();
    let photo = first.load_photo().unwrap();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    for pose in 1..3 {
        let scene = base.with_motion_pose("walk", pose).unwrap();
        session.update(&scene, &mut StageTimes::default()).unwrap();
        let full = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let d = common::differing(&session.composite.image, &full.composite.image);
        assert_eq!(d, 0, "pose {pose}: the update differs from a full render");
    }
}
