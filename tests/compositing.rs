//! The layers a compositor reads from `arlux render`'s EXR: the final
//! `RGBA`, `object.RGBA` (the virtual objects premultiplied by their
//! coverage), `shadow.RGB` (the photo's factor where real surfaces show),
//! `change.RGB` and the `photo`. The recipe of docs/compositing.md,
//! photo × shadow + object, rebuilds the image, in a render's EXR and in
//! each frame of a motion; both carry the camera and the run's settings.

mod common;

use arlux::image_io::read_exr_channel;

fn run(args: &[&str]) {
    let run = common::arlux(args);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

#[test]
fn photo_times_shadow_plus_object_rebuilds_the_render() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("box.exr");
    let scene = common::scene_dir("desk").join("scene.toml");
    let scene = scene.to_str().unwrap();
    run(&[
        "render",
        scene,
        "--variant",
        "box_floor_a",
        "-o",
        out.to_str().unwrap(),
    ]);
    rebuilds(&out);
    let frames = dir.path().join("frames");
    let frames_arg = frames.to_str().unwrap();
    run(&[
        "motion",
        scene,
        "--motion",
        "box_slide",
        "--frames",
        "4..5",
        "-o",
        frames_arg,
    ]);
    rebuilds(&frames.join("box_slide_004.exr"));
}

#[test]
fn a_frame_carries_its_camera_and_settings() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("box.exr");
    let scene = common::scene_dir("desk").join("scene.toml");
    run(&[
        "render",
        scene.to_str().unwrap(),
        "--variant",
        "box_table",
        "-o",
        out.to_str().unwrap(),
    ]);
    let meta = exr::meta::MetaData::read_from_file(&out, false).unwrap();
    let a = &meta.headers[0].own_attributes;
    let software = a.software_name.as_ref().unwrap().to_string();
    assert!(software.starts_with("arlux "), "{software}");
    // The desk camera at (0.7, 1.45, 2.7): its position goes to camera space's origin.
    let m = a.world_to_camera.unwrap();
    let p = [0.7f32, 1.45, 2.7, 1.0];
    for j in 0..3 {
        let v: f32 = (0..4).map(|i| p[i] * m[i * 4 + j]).sum();
        assert!(v.abs() < 1e-5, "{v}");
    }
    assert!(a.world_to_normalized_device.is_some());
    let text = match a
        .other
        .get(&exr::meta::attribute::Text::new_or_panic("arlux"))
    {
        Some(exr::meta::attribute::AttributeValue::Text(t)) => t.to_string(),
        other => panic!("no arlux attribute: {other:?}"),
    };
    let settings: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(settings["variant"], "box_table");
    assert_eq!(settings["settings"]["method"], "pda");
    assert_eq!(settings["settings"]["supersample"], 4);
}

/// The recipe rebuilds the frame in `out`, and the box shows in it.
fn rebuilds(out: &std::path::Path) {
    let channel = |name: &str| read_exr_channel(out, name).unwrap().2;
    let rgb = |layer: &str| -> [Vec<f32>; 3] {
        let prefix = if layer.is_empty() {
            String::new()
        } else {
            format!("{layer}.")
        };
        ["R", "G", "B"].map(|c| channel(&format!("{prefix}{c}")))
    };
    let (image, object, shadow, photo, change) = (
        rgb(""),
        rgb("object"),
        rgb("shadow"),
        rgb("photo"),
        rgb("change"),
    );
    let (alpha, object_alpha) = (channel("A"), channel("object.A"));
    assert_eq!(alpha, object_alpha);
    let (mut opaque, mut untouched, mut shadowed) = (0, 0, 0);
    for i in 0..alpha.len() {
        for c in 0..3 {
            let rebuilt = photo[c][i] * shadow[c][i] + object[c][i];
            let tolerance = 1e-6 * image[c][i].abs().max(1.0);
            assert!(
                (rebuilt - image[c][i]).abs() <= tolerance,
                "pixel {i}: {rebuilt} against {}",
                image[c][i]
            );
            assert!((change[c][i] - (image[c][i] - photo[c][i])).abs() <= tolerance);
        }
        if alpha[i] == 1.0 {
            opaque += 1;
            assert_eq!(shadow[0][i], 0.0, "an opaque object hides the photo");
        } else if alpha[i] == 0.0 {
            assert_eq!(object[0][i], 0.0, "no object where none shows");
            if change[0][i] == 0.0 && photo[0][i] > 0.0 {
                untouched += 1;
                assert_eq!(shadow[0][i], 1.0);
            }
            shadowed += (shadow[0][i] < 0.8) as usize;
        }
    }
    // The box covers ~1900 pixels and darkens ~300 of the floor by over 20%.
    assert!(opaque > 1000, "{opaque} opaque pixels");
    assert!(shadowed > 200, "{shadowed} shadowed pixels");
    // Few pixels keep the photo's bits: the box's indirect light reaches nearly all.
    assert!(untouched > 100, "{untouched} untouched pixels");
}

/// docs/compositing.md's `oiiotool` recipe, run as printed there, rebuilds
/// the render's RGB to 1e-6 (Debian's `openimageio-tools`, which
/// `.ci/setup` installs).
#[test]
fn the_oiiotool_recipe_rebuilds_the_rgb() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/compositing.md"))
        .unwrap();
    let start = doc
        .find("```sh\noiiotool")
        .expect("the recipe is in the page")
        + 6;
    let recipe = doc[start..start + doc[start..].find("```").unwrap()].replace("\\\n", " ");
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene_dir("desk").join("scene.toml");
    run(&[
        "render",
        scene.to_str().unwrap(),
        "--variant",
        "box_floor_a",
        "-o",
        dir.path().join("shot.exr").to_str().unwrap(),
    ]);
    let args: Vec<&str> = recipe.split_whitespace().skip(1).collect();
    let status = std::process::Command::new("oiiotool")
        .args(&args)
        .current_dir(dir.path())
        .status()
        .expect("oiiotool is installed (`bash .ci/setup`)");
    assert!(status.success());
    let shot = dir.path().join("shot.exr");
    let comp = dir.path().join("comp.exr");
    let mut worst = 0.0f32;
    for c in ["R", "G", "B"] {
        let want = read_exr_channel(&shot, c).unwrap().2;
        let got = read_exr_channel(&comp, c).unwrap().2;
        assert_eq!(want.len(), got.len());
        for (a, b) in want.iter().zip(&got) {
            worst = worst.max((a - b).abs() / a.abs().max(1.0));
        }
    }
    assert!(worst <= 1e-6, "the recipe differs from the RGB by {worst}");
}
