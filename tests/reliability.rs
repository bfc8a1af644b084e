//! Bad or extreme input ends in a clear error (status 2, the file and the
//! key or line named) before any work, and never damages a file: outputs
//! that would overwrite an input or each other, names that do not say what
//! is written, coordinates single-precision rays cannot hold, a signal
//! mid-write. Unusual but valid input is accepted with a warning.

mod common;

use std::process::{Command, Stdio};

use common::{Desk, arlux};

/// Runs arlux, expects status 2 with every `expected` text in the message.
fn fails(args: &[&str], expected: &[&str]) {
    common::arlux_refused(args, expected);
}

/// The names in a folder, sorted.
fn listing(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let desk = Desk::new();
    let photo = desk.path("photo.exr");
    let before = std::fs::read(&photo).unwrap();
    let scene = desk.scene();
    let photo_arg = photo.to_str().unwrap();
    fails(
        &[
            "render",
            &scene,
            "--variant",
            "box_floor_a",
            "-o",
            photo_arg,
        ],
        &["photo.exr: -o: is an input of this run"],
    );
    let mesh = desk.path("geometry/box.png");
    std::fs::copy(desk.path("geometry/box.obj"), &mesh).unwrap();
    fails(
        &[
            "ids",
            &scene,
            "-o",
            desk.path("scene.toml").to_str().unwrap(),
        ],
        &["-o: the name must end in .png"],
    );
    assert_eq!(
        std::fs::read(&photo).unwrap(),
        before,
        "the photo was touched"
    );
}

#[test]
fn outputs_whose_names_do_not_say_what_is_written_are_refused() {
    let desk = Desk::new();
    let scene = desk.scene();
    let before = listing(desk.dir.path());
    let at = |name: &str| desk.path(name).display().to_string();
    let (txt, both, dir) = (at("o.txt"), at("x.exr"), at("geometry"));
    fails(
        &["render", &scene, "--variant", "box_floor_a", "-o", &txt],
        &["o.txt: -o: the name must end in .exr"],
    );
    fails(
        &[
            "render",
            &scene,
            "--variant",
            "box_floor_a",
            "-o",
            &both,
            "--png",
            &both,
        ],
        &["x.exr: --png: the name must end in .png"],
    );
    fails(
        &["render", &scene, "--variant", "box_floor_a", "-o", &dir],
        &["geometry: -o: is a folder, not a file"],
    );
    fails(
        &["gonio", &scene, "-o", &at("lamp.txt")],
        &["lamp.txt: -o: the name must end in .ies"],
    );
    assert_eq!(listing(desk.dir.path()), before, "a file was written");
}

#[test]
fn a_sweep_of_a_bad_variant_leaves_no_folder() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "reference = \"truth/box_table.exr\"\nreference_noise = 0.01045\n",
        "",
    );
    let scene = desk.scene();
    for (variant, expected) in [
        ("no_such_variant", "no_such_variant"),
        ("box_table", "variant 'box_table'.reference"),
    ] {
        let out = desk.path("sweep-out");
        fails(
            &[
                "sweep",
                &scene,
                "--variant",
                variant,
                "--quick",
                "-o",
                out.to_str().unwrap(),
            ],
            &[expected],
        );
        assert!(!out.exists(), "{variant}: the output folder was made");
    }
}

#[test]
fn coordinates_beyond_single_precision_are_refused_with_their_line() {
    let desk = Desk::new();
    desk.edit(
        "geometry/box.obj",
        "v -0.150000 0.000000 0.150000",
        "v -1e15 0.000000 0.150000",
    );
    let scene = desk.scene();
    let out = desk.path("a.exr");
    fails(
        &[
            "render",
            &scene,
            "--variant",
            "box_floor_a",
            "-o",
            out.to_str().unwrap(),
        ],
        &["box.obj: line 3: vertex coordinate", "beyond ±1000000 m"],
    );
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "translate = [0.35, 0.0, -0.25]",
        "translate = [1e15, 0.0, -0.25]",
    );
    fails(
        &["info", &desk.scene()],
        &["scene.toml: virtual[0].translate:", "beyond ±1000000 m"],
    );
    let desk = Desk::new();
    desk.edit("scene.toml", "[-0.3, 2.59, -0.6]", "[-0.3, 2.59, -6e9]");
    fails(
        &["info", &desk.scene()],
        &["scene.toml: light[0].position:", "beyond ±1000000 m"],
    );
}

#[test]
fn a_scale_or_pose_that_throws_an_object_beyond_single_precision_is_refused() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "scale = 1.0\nenabled = true",
        "scale = 1e12\nenabled = true",
    );
    fails(
        &["info", &desk.scene()],
        &[
            "scene.toml: virtual[0].scale:",
            "places 'box'",
            "beyond ±1000000 m",
        ],
    );
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "box = { translate = [-1.2, 0.0, 0.7], rotate_y_deg = -15.0 }",
        "box = { translate = [-1.2, 0.0, 0.7], scale = 1e9 }",
    );
    fails(
        &["info", &desk.scene()],
        &["scene.toml: variant[1].objects.box:", "beyond ±1000000 m"],
    );
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "[0.7571, 0.0, -0.2714]",
        "[999999.99, 0.0, -0.2714]",
    );
    fails(
        &["info", &desk.scene()],
        &[
            "scene.toml: motion[0].translations[6]:",
            "beyond ±1000000 m",
        ],
    );
}

#[test]
fn a_rect_light_with_a_zero_side_is_refused_at_that_side() {
    let desk = Desk::new();
    desk.edit("scene.toml", "u = [0.6, 0.0, 0.0]", "u = [0.0, 0.0, 0.0]");
    fails(
        &["info", &desk.scene()],
        &["light[0].shape.rect.u: must not be zero"],
    );
}

#[test]
fn an_obj_in_latin_1_is_read() {
    let desk = Desk::new();
    let path = desk.path("geometry/box.obj");
    let mut bytes = b"# Caf\xe9 \xa9 2026, \xc9diteur\n".to_vec();
    bytes.extend(std::fs::read(&path).unwrap());
    std::fs::write(&path, bytes).unwrap();
    let run = arlux(&["info", &desk.scene()]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

#[test]
fn negative_photo_pixels_are_counted_and_never_reach_the_output() {
    let desk = Desk::new();
    let mut img = arlux::image_io::read_image(&desk.path("photo.exr")).unwrap();
    for p in img.pixels.iter_mut().take(100) {
        p.x = -0.25;
    }
    arlux::image_io::write_exr(
        &desk.path("photo.exr"),
        512,
        384,
        &[arlux::image_io::ExrLayer::Rgb("", &img)],
    )
    .unwrap();
    let out = desk.path("a.exr");
    let run = arlux(&[
        "render",
        &desk.scene(),
        "--variant",
        "panel_off",
        "-o",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("100 pixels of the photo are negative"),
        "{stderr}"
    );
    let image = arlux::image_io::read_image(&out).unwrap();
    assert!(image.pixels.iter().all(|p| p.min_element() >= 0.0));
}

#[test]
fn a_signal_mid_write_leaves_no_temporary_file() {
    let desk = Desk::new();
    let out = desk.path("a.exr");
    let mut child = Command::new(env!("CARGO_BIN_EXE_arlux"))
        .args([
            "render",
            &desk.scene(),
            "--variant",
            "box_floor_a",
            "-o",
            out.to_str().unwrap(),
        ])
        .env("ARLUX_TEST_WRITE_PAUSE_MS", "20000")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The run's temporaries beside the output (the output's own, and the
    // writer's inside it), named for the output and hidden.
    let temporaries = || -> Vec<String> {
        std::fs::read_dir(desk.dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.') && n.contains("a.exr"))
            .collect()
    };
    let t0 = std::time::Instant::now();
    while temporaries().is_empty() {
        assert!(
            t0.elapsed().as_secs() < 60,
            "the temporary file never appeared"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let kill = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(128 + 15));
    assert!(
        temporaries().is_empty(),
        "temporaries left behind: {:?}",
        temporaries()
    );
    assert!(!out.exists(), "a half-written output");
}

#[test]
fn a_patch_size_that_would_exhaust_memory_is_refused_up_front() {
    let desk = Desk::new();
    let out = desk.path("m.exr");
    let scene = desk.scene();
    let out = out.to_str().unwrap();
    for args in [
        vec!["radiosity", &scene, "-o", out, "--patch-size", "0.0001"],
        vec![
            "render",
            &scene,
            "--variant",
            "box_floor_a",
            "-o",
            out,
            "--patch-size",
            "0.0001",
        ],
    ] {
        fails(
            &args,
            &[
                "scene.toml: a patch size of 0.0001 m",
                "--patch-size, at least",
            ],
        );
    }
}

#[test]
fn an_object_far_outside_the_room_and_out_of_view_costs_nothing() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "objects = { box = { translate = [0.35, 0.0, -0.25], rotate_y_deg = 20.0 } }",
        "objects = { box = { translate = [0.35, 0.0, 10000.0], rotate_y_deg = 20.0 } }",
    );
    let out = desk.path("far.exr");
    let report = common::render_box_floor_a(&desk, &out);
    assert_eq!(report["rays"], 0, "{report}");
    assert_eq!(report["links"], 0, "{report}");
    let left_out = report["left_out"].to_string();
    assert!(
        left_out.contains("outside the room and out of view"),
        "{left_out}"
    );
    // Nothing changes: the photo, bit for bit.
    let image = arlux::image_io::read_image(&out).unwrap();
    let photo = arlux::image_io::read_image(&desk.path("photo.exr")).unwrap();
    assert_eq!(image.pixels, photo.pixels);
}

#[test]
fn an_output_in_a_folder_that_cannot_be_written_is_refused_before_any_work() {
    let scene = common::scene_dir("desk").join("scene.toml");
    // /proc takes no new files, whoever runs the test (root included).
    let run = arlux(&[
        "render",
        scene.to_str().unwrap(),
        "--variant",
        "box_floor_a",
        "-o",
        "/proc/arlux-out.exr",
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("/proc/arlux-out.exr: -o: cannot write in the folder /proc"),
        "{stderr}"
    );
    assert!(run.stdout.is_empty(), "work was done before the refusal");
}

#[test]
fn a_link_planted_where_a_temporary_could_be_is_never_followed() {
    use std::os::unix::fs::symlink;
    let dir = tempfile::tempdir().unwrap();
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, b"keep me").unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    // The names this process's temporaries once had (`.NAME.tmp<PID>`,
    // `.NAME.new<PID>`), each a link to a file outside the folder.
    let pid = std::process::id();
    for name in ["a.exr", "b.png"] {
        for kind in ["tmp", "new"] {
            symlink(&victim, out.join(format!(".{name}.{kind}{pid}"))).unwrap();
            symlink(&victim, out.join(format!(".{name}.{kind}{pid}.tmp"))).unwrap();
        }
    }
    let links_before = listing(&out);
    arlux::image_io::write_atomic(&out.join("a.exr"), b"first").unwrap();
    arlux::image_io::write_new(&out.join("b.png"), b"second").unwrap();
    assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
    for (name, bytes) in [("a.exr", &b"first"[..]), ("b.png", &b"second"[..])] {
        let meta = std::fs::symlink_metadata(out.join(name)).unwrap();
        assert!(meta.file_type().is_file(), "{name} is not a plain file");
        assert_eq!(std::fs::read(out.join(name)).unwrap(), bytes);
    }
    // No temporary is left: the folder holds the links and the two outputs.
    let mut expected = links_before;
    expected.extend(["a.exr".to_string(), "b.png".to_string()]);
    expected.sort();
    assert_eq!(listing(&out), expected);
}
