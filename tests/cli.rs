//! The `arlux` binary on good and bad input: bad input exits with status 2
//! and a message naming the file and the key, and leaves no output file
//! behind (nor touches an existing one).

mod common;

use common::{DESK, Desk, arlux};

/// Runs `arlux ids` into a file that already holds good bytes, expects
/// failure with `expected` in the message, and the old file untouched.
fn ids_fails(desk: &Desk, expected: &[&str]) {
    let out = desk.path("out.png");
    std::fs::write(&out, b"a good image").unwrap();
    let exr = desk.path("ids.exr");
    let run = arlux(&[
        "ids",
        &desk.scene(),
        "-o",
        out.to_str().unwrap(),
        "--exr",
        exr.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "stderr: {stderr}");
    for e in expected {
        assert!(stderr.contains(e), "expected '{e}' in: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(
        std::fs::read(&out).unwrap(),
        b"a good image",
        "the old output was touched"
    );
    assert!(!exr.exists(), "an output was written");
    let leftovers: Vec<_> = std::fs::read_dir(desk.dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

#[test]
fn info_and_ids_work_on_the_desk() {
    let run = arlux(&["info", &format!("{DESK}/scene.toml")]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("real surfaces: 6 (68 triangles)") && stdout.contains("motions: 1"),
        "{stdout}"
    );
    assert!(stdout.contains("dynamic range"), "{stdout}");

    let run = arlux(&["info", &format!("{DESK}/scene.toml"), "--json"]);
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(report["lights"].as_array().unwrap().len(), 3);
    assert_eq!(report["photo"]["range"]["width"], 512);
    // The box (a 0.3 m cube standing on its origin) turned 20° about y:
    // 0.3 (cos 20° + sin 20°) wide in x and z, 0.3 tall, from the floor up.
    let b = &report["virtual_objects"][0]["bounds"];
    let wide = 0.3 * (20f64.to_radians().cos() + 20f64.to_radians().sin());
    let size: Vec<f64> = (0..3).map(|i| b["size_m"][i].as_f64().unwrap()).collect();
    for (got, want) in size.iter().zip([wide, 0.3, wide]) {
        assert!((got - want).abs() < 1e-5, "size {size:?}, expected {want}");
    }
    assert!(b["min"][1].as_f64().unwrap().abs() < 1e-6, "{b}");
    assert!(stdout.contains("size 0.385 × 0.300 × 0.385 m"), "{stdout}");
    let f = &report["virtual_objects"][0]["footprint"];
    let area = f["area_m2"].as_f64().unwrap();
    assert!((area - wide * wide).abs() < 1e-6, "{f}");
    let centre = |i: usize| f["centre"][i].as_f64().unwrap();
    assert!(
        (centre(0) - 0.35).abs() < 1e-6 && (centre(1) + 0.25).abs() < 1e-6,
        "{f}"
    );

    let desk = Desk::new();
    let out = desk.path("ids.png");
    let run = arlux(&["ids", &desk.scene(), "-o", out.to_str().unwrap()]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let png = image::open(&out).unwrap();
    assert_eq!((png.width(), png.height()), (1024, 384));
}

#[test]
fn compare_reports_the_known_error_of_the_unchanged_photo() {
    // The issue states: leaving the photo unchanged scores RMSE 0.0265 on box_floor_a.
    let run = arlux(&[
        "compare",
        &format!("{DESK}/photo.exr"),
        &format!("{DESK}/truth/box_floor_a.exr"),
        "--json",
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let c: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let rmse = c["comparison"]["rmse"].as_f64().unwrap();
    assert!((rmse - 0.0265).abs() < 0.00005, "rmse {rmse}");
    assert_eq!(c["comparison"]["pixels"], 512 * 384);

    let run = arlux(&[
        "compare",
        &format!("{DESK}/photo.exr"),
        &format!("{DESK}/photo.exr"),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("rmse           0.000000") && stdout.contains("inf (identical)"),
        "{stdout}"
    );
}

#[test]
fn compare_refuses_mismatched_sizes_and_masks() {
    let desk = Desk::new();
    let small = desk.path("small.exr");
    let img = arlux::image_io::Image::new(4, 4);
    arlux::image_io::write_exr(&small, 4, 4, &[arlux::image_io::ExrLayer::Rgb("", &img)]).unwrap();
    let run = arlux(&[
        "compare",
        small.to_str().unwrap(),
        &format!("{DESK}/photo.exr"),
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("small.exr: is 4x4 but"));
    let run = arlux(&[
        "compare",
        &format!("{DESK}/photo.exr"),
        &format!("{DESK}/photo.exr"),
        "--mask",
        "nomask.png",
    ]);
    assert!(String::from_utf8_lossy(&run.stderr).contains("nomask.png: file not found"));
}

#[test]
fn a_missing_scene_file_is_named() {
    let run = arlux(&["info", "no/such/scene.toml"]);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("no/such/scene.toml: file not found"));
}

#[test]
fn malformed_toml_is_refused() {
    let desk = Desk::new();
    desk.edit("scene.toml", "[camera]", "[camera");
    ids_fails(&desk, &["scene.toml: line 3: malformed TOML"]);
}

#[test]
fn nan_in_the_scene_is_refused() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "position = [-0.3, 2.59, -0.6]",
        "position = [-0.3, nan, -0.6]",
    );
    ids_fails(&desk, &["scene.toml: light[0].position: must be finite"]);
}

#[test]
fn malformed_obj_is_refused_with_its_line() {
    let desk = Desk::new();
    desk.edit("geometry/room.obj", "f 5 6 8", "f 5 6 80");
    ids_fails(
        &desk,
        &[
            "scene.toml: real[1].mesh:",
            "room.obj: line 14: face: '80' refers to vertex 80",
        ],
    );
}

#[test]
fn an_obj_of_degenerate_triangles_is_refused() {
    let desk = Desk::new();
    std::fs::write(
        desk.path("geometry/box.obj"),
        "o box\nv 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n",
    )
    .unwrap();
    ids_fails(
        &desk,
        &[
            "scene.toml: virtual[0].mesh:",
            "box.obj: no usable triangles (2 degenerate",
        ],
    );
}

#[test]
fn malformed_exr_photo_is_refused() {
    let desk = Desk::new();
    let bytes = std::fs::read(desk.path("photo.exr")).unwrap();
    std::fs::write(desk.path("photo.exr"), &bytes[..bytes.len() / 3]).unwrap();
    ids_fails(
        &desk,
        &["scene.toml: photo.image:", "photo.exr: malformed EXR"],
    );
}

#[test]
fn a_photo_of_the_wrong_size_is_refused_not_resampled() {
    let desk = Desk::new();
    desk.edit("scene.toml", "width = 512", "width = 511");
    ids_fails(
        &desk,
        &[
            "scene.toml: photo.image:",
            "photo.exr is 512x384 but the camera is 511x384",
        ],
    );
}

#[test]
fn a_photo_with_nan_pixels_is_refused() {
    let desk = Desk::new();
    let mut img = arlux::image_io::read_image(&desk.path("photo.exr")).unwrap();
    img.pixels[1000].y = f32::NAN;
    arlux::image_io::write_exr(
        &desk.path("photo.exr"),
        512,
        384,
        &[arlux::image_io::ExrLayer::Rgb("", &img)],
    )
    .unwrap();
    ids_fails(
        &desk,
        &[
            "scene.toml: photo.image:",
            "1 pixels are NaN or infinite (the first at x=488, y=1)",
        ],
    );
}

#[test]
fn a_camera_that_sees_nothing_is_refused() {
    let desk = Desk::new();
    // The room is open towards +z: looking that way sees no surface.
    desk.edit(
        "scene.toml",
        "look_at = [-0.45, 0.6, -1.0]",
        "look_at = [0.7, 1.45, 5.0]",
    );
    ids_fails(&desk, &["scene.toml: camera: the camera sees no surface"]);
}

#[test]
fn a_light_inside_a_wall_is_refused() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "position = [1.5, 2.3, 1.0]",
        "position = [1.5, 2.3, -2.0]",
    );
    ids_fails(
        &desk,
        &["scene.toml: light[1].position: light 'spot' lies on surface 'back_wall'"],
    );
}

#[test]
fn malformed_ies_is_refused_with_its_line() {
    let desk = Desk::new();
    std::fs::write(
        desk.path("lamp.ies"),
        "IESNA:LM-63-2002\n[TEST]1\nTILT=NONE\n1 -1 1 3 1 1 2 0 0 0\n1 1 0\n0 45 90\n0\n10 20 3O\n",
    )
    .unwrap();
    desk.edit(
        "scene.toml",
        "intensity = { uniform = [6.0, 5.5, 5.0] }",
        "intensity = { ies = \"lamp.ies\", rgb = [1.0, 1.0, 1.0], direction = [0.0, -1.0, 0.0], reference = [1.0, 0.0, 0.0] }",
    );
    ids_fails(
        &desk,
        &[
            "scene.toml: light[2].intensity.ies:",
            "lamp.ies: line 8: candela value 3 of 3: '3O' is not a number",
        ],
    );
}

#[test]
fn an_output_in_a_missing_folder_is_refused_before_any_work() {
    let scene = format!("{DESK}/scene.toml");
    for args in [
        vec![
            "render",
            scene.as_str(),
            "--variant",
            "box_floor_a",
            "-o",
            "/nonexistent-arlux/a.exr",
        ],
        vec![
            "render",
            scene.as_str(),
            "--variant",
            "box_floor_a",
            "-o",
            "a.exr",
            "--png",
            "/nonexistent-arlux/a.png",
        ],
        vec![
            "radiosity",
            scene.as_str(),
            "-o",
            "/nonexistent-arlux/m.exr",
        ],
        vec!["ids", scene.as_str(), "-o", "/nonexistent-arlux/ids.png"],
    ] {
        let run = arlux(&args);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("/nonexistent-arlux") && stderr.contains("does not exist"),
            "{stderr}"
        );
        // Refused up front: nothing was rendered or reported.
        assert!(
            run.stdout.is_empty(),
            "{args:?} printed {}",
            String::from_utf8_lossy(&run.stdout)
        );
    }
    assert!(!std::path::Path::new("a.exr").exists(), "nothing written");
}
