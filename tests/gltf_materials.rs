//! A glTF card written here (a quad with a texture, normals and texture
//! coordinates) in a copy of the desk: its alpha MASK cuts it where the
//! texture says, for the camera and for shadows; its colour is the
//! texel's; a file asking what arlux cannot honour is reported.

mod common;
use common::Desk;

use arlux::scene::Scene;

/// Writes `geometry/card.gltf` (+ `.bin`, `.png`): a 0.6 m square card at
/// z = -0.6 facing +z (the camera), x from -0.3 to 0.3, y from 0.8 to 1.4;
/// its texture is two texels across, left transparent red, right opaque green.
fn write_card(desk: &Desk, extra: &str, material: &str) {
    let positions: [[f32; 3]; 4] = [
        [-0.3, 1.4, -0.6],
        [0.3, 1.4, -0.6],
        [0.3, 0.8, -0.6],
        [-0.3, 0.8, -0.6],
    ];
    let normals = [[0.0f32, 0.0, 1.0]; 4];
    let uvs: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let indices: [u32; 6] = [0, 3, 2, 0, 2, 1];
    let mut bin: Vec<u8> = Vec::new();
    for p in positions.iter().chain(&normals) {
        p.iter().for_each(|c| bin.extend(c.to_le_bytes()));
    }
    for t in &uvs {
        t.iter().for_each(|c| bin.extend(c.to_le_bytes()));
    }
    indices.iter().for_each(|i| bin.extend(i.to_le_bytes()));
    std::fs::write(desk.path("geometry/card.bin"), &bin).unwrap();
    let mut img = image::RgbaImage::new(2, 1);
    img.put_pixel(0, 0, image::Rgba([255, 0, 0, 0]));
    img.put_pixel(1, 0, image::Rgba([0, 255, 0, 255]));
    img.save(desk.path("geometry/card.png")).unwrap();
    let gltf = format!(
        r#"{{
  "asset": {{ "version": "2.0" }},{extra}
  "scene": 0,
  "scenes": [{{ "nodes": [0] }}],
  "nodes": [{{ "mesh": 0, "name": "card" }}],
  "meshes": [{{ "primitives": [{{
    "attributes": {{ "POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2 }},
    "indices": 3, "material": 0 }}] }}],
  "materials": [{{ "name": "cutout",
    "pbrMetallicRoughness": {{ "baseColorTexture": {{ "index": 0 }},
      "metallicFactor": 0.0, "roughnessFactor": 1.0 }},
    "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": true{material} }}],
  "textures": [{{ "source": 0, "sampler": 0 }}],
  "samplers": [{{ "magFilter": 9729, "minFilter": 9729 }}],
  "images": [{{ "uri": "card.png" }}],
  "buffers": [{{ "uri": "card.bin", "byteLength": {} }}],
  "bufferViews": [
    {{ "buffer": 0, "byteOffset": 0, "byteLength": 48 }},
    {{ "buffer": 0, "byteOffset": 48, "byteLength": 48 }},
    {{ "buffer": 0, "byteOffset": 96, "byteLength": 32 }},
    {{ "buffer": 0, "byteOffset": 128, "byteLength": 24 }}],
  "accessors": [
    {{ "bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
       "min": [-0.3, 0.8, -0.6], "max": [0.3, 1.4, -0.6] }},
    {{ "bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3" }},
    {{ "bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2" }},
    {{ "bufferView": 3, "componentType": 5125, "count": 6, "type": "SCALAR" }}]
}}"#,
        bin.len()
    );
    std::fs::write(desk.path("geometry/card.gltf"), gltf).unwrap();
    let scene = std::fs::read_to_string(desk.path("scene.toml")).unwrap();
    std::fs::write(
        desk.path("scene.toml"),
        scene + "\n[[virtual]]\nname = \"card\"\nmesh = \"geometry/card.gltf\"\n",
    )
    .unwrap();
}

#[test]
fn an_alpha_mask_cuts_the_card_for_the_camera_and_its_shadow() {
    let desk = Desk::new();
    write_card(&desk, "", "");
    let scene = Scene::load(desk.path("scene.toml")).unwrap();
    let (out, photo) = common::render_default(&scene);
    let c = &out.composite;
    let at = |x: f64, y: f64| {
        let (px, py, _) = scene.camera.project(glam::DVec3::new(x, y, -0.6)).unwrap();
        py as usize * scene.camera.width as usize + px as usize
    };
    // The cut-away half shows the room: no coverage, the photo's colour
    // (nothing in front of that wall changed but the card's shadow, which
    // falls below it).
    let (cut, kept) = (at(-0.15, 1.1), at(0.15, 1.1));
    assert_eq!(c.alpha[cut], 0.0, "the cut-away half covers its pixel");
    let (img, ph) = (c.image.pixels[cut], photo.pixels[cut]);
    assert!(
        (img - ph).abs().max_element() <= 0.05 * ph.max_element(),
        "{img} against the photo's {ph}"
    );
    // The kept half is the card, green as its texel.
    assert_eq!(c.alpha[kept], 1.0);
    let g = c.image.pixels[kept];
    assert!(g.y > 4.0 * g.x.max(g.z), "the kept half is not green: {g}");
    // Its shadow on the room has the cut: light passes the transparent half.
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let through = |x: f32| {
        let from = glam::Vec3::new(x, 1.1, -0.5);
        let ray = arlux::trace::TraceRay::segment(from, glam::Vec3::new(x, 1.1, -0.7), 1e-5);
        tracer.occluded(&ray, arlux::trace::Layer::Virtual)
    };
    assert!(
        !through(-0.15),
        "a shadow ray is blocked by the cut-away half"
    );
    assert!(through(0.15), "a shadow ray passes the kept half");
}

#[test]
fn what_a_gltf_asks_and_arlux_cannot_honour_is_said_once_by_name() {
    let desk = Desk::new();
    write_card(
        &desk,
        r#" "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_clearcoat"],"#,
        "",
    );
    let scene = Scene::load(desk.path("scene.toml")).unwrap();
    let said: Vec<&String> = scene
        .warnings
        .iter()
        .filter(|w| w.contains("card.gltf"))
        .collect();
    assert_eq!(said.len(), 1, "{:?}", scene.warnings);
    for name in ["KHR_materials_transmission", "KHR_materials_clearcoat"] {
        assert!(said[0].contains(name), "{}", said[0]);
    }
}

#[test]
fn an_emissive_card_glows_in_its_pixels_and_lights_the_room() {
    let (plain, glowing) = (Desk::new(), Desk::new());
    write_card(&plain, "", "");
    write_card(&glowing, "", r#", "emissiveFactor": [3.0, 0.0, 0.0]"#);
    // The card's own pixel, and the floor in front of it.
    let shade = |desk: &Desk| {
        let scene = Scene::load(desk.path("scene.toml")).unwrap();
        let (out, _) = common::render_default(&scene);
        let at = |p: glam::DVec3| {
            let (px, py, _) = scene.camera.project(p).unwrap();
            out.composite.image.pixels[py as usize * scene.camera.width as usize + px as usize]
        };
        (
            at(glam::DVec3::new(0.15, 1.1, -0.6)),
            at(glam::DVec3::new(0.3, 0.0, 0.3)),
        )
    };
    let ((card, floor), (card_lit, floor_lit)) = (shade(&plain), shade(&glowing));
    // Its pixel: the emitted radiance, plus the little of its red light
    // the room sends back to it.
    let added = card_lit - card;
    assert!(
        added.x >= 3.0 && added.x < 3.0 * 1.02,
        "red added {}",
        added.x
    );
    assert!(added.y.abs() < 1e-3 && added.z.abs() < 1e-3, "{added}");
    // The floor in front of it takes its red light (a 0.36 m² source of
    // radiance 3, 1.5 m away: +0.018 measured; +0.0002, its pixel's own
    // reflections only, when the radiosity left the emission out), and
    // nothing else changes there.
    let lit = floor_lit - floor;
    assert!(
        lit.x > 0.01 && lit.x > 20.0 * lit.y.abs().max(lit.z.abs()),
        "{lit}"
    );
}

#[test]
fn a_required_extension_is_named_and_a_textured_material_said_to_come_from_its_texture() {
    let desk = Desk::new();
    write_card(
        &desk,
        r#" "extensionsUsed": ["KHR_draco_mesh_compression"], "extensionsRequired": ["KHR_draco_mesh_compression"],"#,
        "",
    );
    let message = common::arlux_refused(
        &["info", &desk.path("scene.toml").display().to_string()],
        &["card.gltf", "KHR_draco_mesh_compression", "decompress"],
    );
    assert!(!message.contains("malformed"), "{message}");

    let desk = Desk::new();
    write_card(&desk, "", "");
    desk.edit(
        "geometry/card.gltf",
        r#""metallicFactor": 0.0"#,
        r#""metallicRoughnessTexture": { "index": 0 }, "metallicFactor": 0.0"#,
    );
    let run = common::arlux_ok(&["info", &desk.path("scene.toml").display().to_string()]);
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        text.contains("metallic and roughness from texture (× 0.00, × 1.00)"),
        "{text}"
    );
}

/// An object glowing brighter than anything in the photo is said with the
/// numbers (the desk's photo peaks at 0.647: an emissive factor of 3 is
/// 4.6 times that); a plain card says nothing of the kind.
#[test]
fn an_emission_brighter_than_the_photo_is_reported() {
    let (plain, glowing) = (Desk::new(), Desk::new());
    write_card(&plain, "", "");
    write_card(&glowing, "", r#", "emissiveFactor": [3.0, 0.0, 0.0]"#);
    let warnings = |desk: &Desk| {
        let scene = Scene::load(desk.path("scene.toml")).unwrap();
        common::render_default(&scene).0.warnings
    };
    let said = warnings(&glowing);
    assert!(
        said.iter().any(|w| w.starts_with(
            "'card' emits radiance up to 3.000, 4.6x the photo's brightest pixel (0.647)"
        )),
        "{said:?}"
    );
    assert!(warnings(&plain).is_empty(), "{:?}", warnings(&plain));
}

/// `emission` scales a file's emitted light, and 0 turns it off (with its
/// texture): the glowing card's factor 3 becomes 6, or nothing, and off it
/// raises no warning.
#[test]
fn the_emission_key_scales_or_turns_off_a_file_s_glow() {
    let emissive = |desk: &Desk| {
        let scene = Scene::load(desk.path("scene.toml")).unwrap();
        let card = scene.objects.iter().find(|o| o.name == "card").unwrap();
        card.surfaces[0]
            .material
            .as_ref()
            .unwrap()
            .material
            .emissive
    };
    let (doubled, off) = (Desk::new(), Desk::new());
    for (desk, scale) in [(&doubled, "2.0"), (&off, "0")] {
        write_card(desk, "", r#", "emissiveFactor": [3.0, 0.0, 0.0]"#);
        desk.edit(
            "scene.toml",
            "mesh = \"geometry/card.gltf\"\n",
            &format!("mesh = \"geometry/card.gltf\"\nemission = {scale}\n"),
        );
    }
    assert_eq!(emissive(&doubled), glam::Vec3::new(6.0, 0.0, 0.0));
    assert_eq!(emissive(&off), glam::Vec3::ZERO);
    let scene = Scene::load(off.path("scene.toml")).unwrap();
    let out = common::render_default(&scene).0;
    assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    off.edit("scene.toml", "emission = 0", "emission = -1");
    let err = Scene::load(off.path("scene.toml")).unwrap_err().to_string();
    assert!(
        err.contains(".emission: a scale of 0 (off) or more"),
        "{err}"
    );
}

#[test]
fn objects_from_one_file_share_one_mesh_of_patches() {
    // Three globes from one glb, one of them with a roughness of its own:
    // the two alike are meshed once (a copy of the material per object
    // had meshed each again: three 80k-triangle props, three meshings).
    let src = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/materials");
    let text = std::fs::read_to_string(format!("{src}/scene.toml"))
        .unwrap()
        .replace("\"geometry/", &format!("\"{src}/geometry/"))
        .replace("\"truth/", &format!("\"{src}/truth/"))
        .replace("\"photo.exr\"", &format!("\"{src}/photo.exr\""));
    let globe = |name: &str, x: f64, extra: &str| {
        format!(
            "\n[[virtual]]\nname = \"{name}\"\nmesh = \"{src}/geometry/globe.glb\"\n\
             translate = [{x}, 0.0, -0.3]\n{extra}\n"
        )
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("scene.toml");
    let extra = [
        globe("a", -0.4, ""),
        globe("b", 0.0, ""),
        globe("c", 0.4, "roughness = 0.2"),
    ]
    .concat();
    std::fs::write(&file, text + &extra).unwrap();
    let scene = Scene::load(&file).unwrap();
    let room = arlux::patches::Patches::of_scene(&scene, false, 0.5);
    let mut meshes = arlux::patches::ObjectMeshes::new(true);
    let p = arlux::patches::Patches::of_scene_from_room(&room, &scene, 0.1, &mut meshes);
    assert_eq!(
        meshes.mesh_count(),
        2,
        "a and b share one mesh, c has its own"
    );
    // Each globe still has its patches, moved to where it stands.
    let per_globe = (p.patch_count() - room.patch_count()) / 3;
    assert!(per_globe > 0 && p.patch_count() == room.patch_count() + 3 * per_globe);
}
