//! Inputs that render but are likely wrong get a warning with numbers
//! (and an error under `--strict`, writing nothing); the desk gets none.

mod common;

use common::{Desk, arlux};

fn render(desk: &Desk, strict: bool) -> (Option<i32>, String) {
    let out = desk.path("a.exr").display().to_string();
    let scene = desk.scene();
    run(
        &["render", &scene, "--variant", "box_floor_a", "-o", &out],
        strict,
    )
}

/// arlux with `args` (and `--strict`): its exit status and what it said.
fn run(args: &[&str], strict: bool) -> (Option<i32>, String) {
    let mut args = args.to_vec();
    if strict {
        args.push("--strict");
    }
    let run = arlux(&args);
    (
        run.status.code(),
        String::from_utf8_lossy(&run.stderr).into_owned(),
    )
}

#[test]
fn the_desk_renders_without_a_warning() {
    let (code, stderr) = render(&Desk::new(), true);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
}

#[test]
fn lights_ten_times_too_weak_are_reported_with_their_shortfall() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "rgb = [4.32, 4.32, 3.96]",
        "rgb = [0.432, 0.432, 0.396]",
    );
    desk.edit(
        "scene.toml",
        "rgb = [20.0, 17.0, 13.0]",
        "rgb = [2.0, 1.7, 1.3]",
    );
    let (code, stderr) = render(&desk, false);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("pinned at the clamp")
            && stderr.contains("too weak for the photo by at least"),
        "{stderr}"
    );
    std::fs::remove_file(desk.path("a.exr")).unwrap();
    let (code, stderr) = render(&desk, true);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("(--strict)"), "{stderr}");
    assert!(!desk.path("a.exr").exists(), "--strict wrote the output");
}

#[test]
fn a_clipped_photo_is_reported() {
    let desk = Desk::new();
    let mut img = arlux::image_io::read_image(&desk.path("photo.exr")).unwrap();
    // Clip at the 90th percentile of brightness: a tenth of the pixels saturate.
    let mut levels: Vec<f32> = img.pixels.iter().map(|p| p.max_element()).collect();
    levels.sort_by(f32::total_cmp);
    let clip = levels[levels.len() * 9 / 10];
    for p in &mut img.pixels {
        *p = p.min(glam::Vec3::splat(clip));
    }
    arlux::image_io::write_exr(
        &desk.path("photo.exr"),
        512,
        384,
        &[arlux::image_io::ExrLayer::Rgb("", &img)],
    )
    .unwrap();
    let (code, stderr) = render(&desk, false);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("of the photo's pixels sit at its brightest value"),
        "{stderr}"
    );
}

#[test]
fn a_camera_that_sees_little_of_the_model_is_reported() {
    let desk = Desk::new();
    // Turned to look out of the room's open side: no surface in view.
    desk.edit(
        "scene.toml",
        "look_at = [-0.45, 0.6, -1.0]",
        "look_at = [1.2, 1.2, 6.0]",
    );
    let (code, stderr) = render(&desk, false);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("the model covers 0.0% of the image"),
        "{stderr}"
    );
    std::fs::remove_file(desk.path("a.exr")).unwrap();
    let (code, stderr) = render(&desk, true);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(!desk.path("a.exr").exists(), "--strict wrote the output");
}

#[test]
fn an_object_s_material_is_read_and_its_missing_texture_refused_by_name() {
    let desk = Desk::new();
    std::fs::write(
        desk.path("geometry/box.mtl"),
        "newmtl wood\nKd 0.6 0.4 0.2\nKs 0.5 0.5 0.5\nNs 100\nmap_Kd wood.png\n",
    )
    .unwrap();
    desk.edit(
        "geometry/box.obj",
        "o box\n",
        "mtllib box.mtl\no box\nusemtl wood\n",
    );
    let run = arlux(&["info", &desk.scene()]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("wood.png"), "{stderr}");
    image::RgbImage::from_pixel(4, 4, image::Rgb([200, 120, 40]))
        .save(desk.path("geometry/wood.png"))
        .unwrap();
    let run = arlux(&["info", &desk.scene()]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr),
    );
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    // The scene's rgb overrides the base colour (and its texture); Ns
    // gives the roughness: √α with α = √(2 / 102).
    assert!(
        stdout.contains(
            "box: material 'wood': base [0.800, 0.320, 0.060], metallic 0.00, roughness 0.37"
        ),
        "{stdout}"
    );
    assert!(!stderr.contains("does not use"), "{stderr}");
}

/// `box_floor_a` with its box placed at `translate`, and `extra` appended
/// to the scene.
fn box_at(translate: &str, extra: &str) -> Desk {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "objects = { box = { translate = [0.35, 0.0, -0.25], rotate_y_deg = 20.0 } }",
        &format!("objects = {{ box = {{ translate = {translate}, rotate_y_deg = 20.0 }} }}"),
    );
    let text = std::fs::read_to_string(desk.path("scene.toml")).unwrap();
    std::fs::write(desk.path("scene.toml"), text + extra).unwrap();
    desk
}

/// Likely placement mistakes are said with numbers (errors with
/// `--strict`): a box sunk half its height into the floor, one entirely
/// under it (the camera sees none of it), two boxes through each other. A
/// box touching the floor (the desk) says nothing (the first test).
#[test]
fn objects_sunk_unseen_or_through_each_other_are_reported() {
    let sunk = box_at("[0.35, -0.15, -0.25]", "");
    let (code, stderr) = render(&sunk, false);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("'box' passes through the room's 'floor' (15.0 cm deep"),
        "{stderr}"
    );
    std::fs::remove_file(sunk.path("a.exr")).unwrap();
    let (code, stderr) = render(&sunk, true);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(!sunk.path("a.exr").exists());

    let under = box_at("[0.35, -1.0, -0.25]", "");
    let (code, stderr) = render(&under, false);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("the camera sees no pixel of 'box'"),
        "{stderr}"
    );
    assert!(!stderr.contains("passes through"), "{stderr}");

    let twins = box_at(
        "[0.35, 0.0, -0.25]",
        "\n[[virtual]]\nname = \"twin\"\nmesh = \"geometry/box.obj\"\nrgb = [0.2, 0.5, 0.8]\ntranslate = [0.45, 0.0, -0.15]\n",
    );
    let (code, stderr) = render(&twins, false);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("'box' passes through 'twin'")
            && stderr.contains("'twin' passes through 'box'"),
        "{stderr}"
    );
    assert!(!stderr.contains("the room's"), "{stderr}");
}

/// Brackets with no known reflectance leave radiance relative: `radiosity`
/// (absolute figures) warns through the same path as every warning, so
/// `--strict` refuses; a render (a ratio of the photo) only notes it.
#[test]
fn a_relative_photo_is_a_warning_that_strict_refuses() {
    let desk = Desk::new();
    std::os::unix::fs::symlink(
        std::path::Path::new(common::DESK).join("brackets"),
        desk.path("brackets"),
    )
    .unwrap();
    let text =
        std::fs::read_to_string(std::path::Path::new(common::DESK).join("scene_brackets.toml"))
            .unwrap();
    let start = text.find("[[reflectance]]").expect("a known reflectance");
    let end = start + text[start..].find("\n\n").unwrap_or(text.len() - start);
    std::fs::write(
        desk.path("b.toml"),
        format!("{}{}", &text[..start], &text[end..]),
    )
    .unwrap();
    let scene = desk.path("b.toml").display().to_string();
    let out = desk.path("m.exr").display().to_string();
    let run = arlux(&["radiosity", &scene, "-o", &out]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("warning:") && stderr.contains("radiance is relative"),
        "{stderr}"
    );
    std::fs::remove_file(desk.path("m.exr")).unwrap();
    let run = arlux(&["radiosity", &scene, "-o", &out, "--strict"]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("radiance is relative (--strict)"),
        "{stderr}"
    );
}

/// A motion whose object passes through another object at some poses is
/// said before any frame (errors with `--strict`, no folder made); the
/// desk's own motion says nothing.
#[test]
fn a_motion_through_another_object_is_reported_before_its_frames() {
    let desk = Desk::new();
    let frames = desk.path("frames");
    let (scene, out) = (desk.scene(), frames.display().to_string());
    let args = [
        "motion",
        &scene,
        "--motion",
        "box_slide",
        "--frames",
        "2..5",
        "-o",
        &out,
    ];
    let motion = |strict: bool| run(&args, strict);
    let (code, stderr) = motion(true);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
    std::fs::remove_dir_all(&frames).unwrap();
    let text = std::fs::read_to_string(desk.scene()).unwrap()
        + "\n[[virtual]]\nname = \"twin\"\nmesh = \"geometry/box.obj\"\nrgb = [0.2, 0.5, 0.8]\ntranslate = [-0.27, 0.0, 0.11]\n";
    std::fs::write(desk.scene(), text).unwrap();
    let (code, stderr) = motion(false);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("motion 'box_slide': 'box' passes through 'twin' at")
            && stderr.contains("cm deep"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&frames).unwrap();
    let (code, stderr) = motion(true);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(!frames.exists(), "--strict made the frames' folder");
}
