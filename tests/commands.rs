//! The `arlux` commands end to end on the desk: what each writes and
//! reports, and their timings.

mod common;

use common::{DESK, Desk, arlux, arlux_json, stage_names};
use std::process::Command;

#[test]
fn radiosity_re_renders_the_photo_from_the_model() {
    let desk = Desk::new();
    let out = desk.path("model.exr");
    let mesh = desk.path("mesh.png");
    let report = arlux_json(&[
        "radiosity",
        &desk.scene(),
        "-o",
        out.to_str().unwrap(),
        "--mesh",
        mesh.to_str().unwrap(),
        "--patch-size",
        "0.5",
        "--json",
    ]);
    // Measured 0.0120 at 0.5 m patches (0.0096 at 0.25 m): the model explains the photo.
    let rmse = report["comparison"]["rmse"].as_f64().unwrap();
    assert!(rmse < 0.013, "model RMSE against the photo {rmse}");
    assert_eq!(report["clamped_patches"], 0);
    for layer in ["R", "direct.R", "indirect.G", "reflectance.B"] {
        let (w, h, v) = arlux::image_io::read_exr_channel(&out, layer).unwrap();
        assert_eq!((w, h), (512, 384));
        assert!(v.iter().all(|x| x.is_finite() && *x >= 0.0), "{layer}");
    }
    assert!(mesh.exists());
}

#[test]
fn render_writes_layers_and_aovs_and_reports_the_error() {
    let desk = Desk::new();
    let out = desk.path("box.exr");
    let aov = desk.path("aov");
    let png = desk.path("box.png");
    let report = arlux_json(&[
        "render",
        &desk.scene(),
        "--variant",
        "box_table",
        "-o",
        out.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
        "--aov",
        aov.to_str().unwrap(),
        "--patch-size",
        "0.5",
        "--json",
    ]);
    // Measured 0.00244 at 0.5 m patches.
    let rmse = report["comparison"]["rmse"].as_f64().unwrap();
    assert!(rmse < 0.003, "{rmse}");
    let stages = stage_names(&report);
    assert!(
        stages.iter().any(|s| s == "pixel data array")
            && stages.iter().any(|s| s == "objects seen from the room"),
        "{stages:?}"
    );
    for layer in ["R", "direct.G", "indirect.B", "change.R", "A"] {
        let (_, _, v) = arlux::image_io::read_exr_channel(&out, layer).unwrap();
        assert!(v.iter().all(|x| x.is_finite()), "{layer}");
    }
    let (_, _, alpha) = arlux::image_io::read_exr_channel(&out, "A").unwrap();
    assert!(
        alpha.contains(&1.0) && alpha.iter().any(|a| *a > 0.0 && *a < 1.0),
        "covered and edge pixels"
    );
    for f in ["direct.exr", "indirect.exr", "change.exr", "alpha.exr"] {
        assert!(aov.join(f).exists(), "{f}");
    }
    assert!(png.exists());

    common::arlux_refused(
        &[
            "render",
            &desk.scene(),
            "--variant",
            "nope",
            "-o",
            desk.path("nope.exr").to_str().unwrap(),
        ],
        &["no variant named 'nope'"],
    );
    assert!(!desk.path("nope.exr").exists());
}

#[test]
fn render_method_texture_writes_the_shadow_free_texture() {
    let desk = Desk::new();
    let out = desk.path("p.exr");
    let aov = desk.path("aov");
    let report = arlux_json(&[
        "render",
        &desk.scene(),
        "--variant",
        "panel_off",
        "--method",
        "texture",
        "-o",
        out.to_str().unwrap(),
        "--aov",
        aov.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["method"], "texture");
    assert!(report["rays"].is_null());
    // Measured 0.00236.
    let rmse = report["comparison"]["rmse"].as_f64().unwrap();
    assert!(rmse < 0.003, "{rmse}");
    let t = &report["texture"];
    assert!(
        t["light_change_seconds"].as_f64().unwrap() > 0.0
            && t["splits"].as_u64().unwrap() > 0
            && t["texels"].as_u64().unwrap() > 100_000,
        "{t}"
    );
    // The shadow-free texture is the photo with shadows lifted: brighter on
    // the whole, and almost nowhere darker (Step 2 may pull back where Step 1 overshot).
    let texture = arlux::image_io::read_image(&aov.join("unoccluded_texture.exr")).unwrap();
    let photo =
        arlux::image_io::read_image(std::path::Path::new(&format!("{DESK}/photo.exr"))).unwrap();
    let darker = texture
        .pixels
        .iter()
        .zip(&photo.pixels)
        .filter(|(t, p)| !t.cmpge(**p * 0.999).all())
        .count();
    assert!(
        darker < photo.pixels.len() / 50,
        "{darker} pixels darker than the photo"
    );
    assert!(
        texture.mean() > photo.mean() * 1.005,
        "{} against {}",
        texture.mean(),
        photo.mean()
    );

    // Its thresholds are flags, checked, and for the texture path only;
    // the pixel path's own flags are refused on it, not ignored.
    let scene = desk.scene();
    let b = desk.path("b.exr");
    let refused = |flags: &[&str], expected: &str| {
        let mut args = vec!["render", &scene, "--variant", "panel_off"];
        args.extend_from_slice(flags);
        args.extend(["-o", b.to_str().unwrap()]);
        common::arlux_refused(&args, &[expected]);
    };
    refused(
        &["--method", "texture", "--visibility-threshold", "0.7"],
        "--visibility-threshold must be a number in (0, 0.5), not 0.7",
    );
    refused(
        &["--min-leaf-pixels", "2"],
        "--min-leaf-pixels applies to --method texture",
    );
    refused(
        &["--method", "texture", "--supersample", "3"],
        "--supersample applies to --method pda",
    );
    assert!(!desk.path("b.exr").exists());
}

#[test]
fn rendering_a_light_change_leaves_out_the_virtual_stages() {
    let desk = Desk::new();
    let out = desk.path("off.exr");
    let report = arlux_json(&[
        "render",
        &desk.scene(),
        "--variant",
        "panel_off",
        "-o",
        out.to_str().unwrap(),
        "--patch-size",
        "0.5",
        "--json",
    ]);
    let stages = stage_names(&report);
    assert!(
        !stages
            .iter()
            .any(|s| s == "objects seen from the room" || s == "virtual mesh"),
        "{stages:?}"
    );
    assert!(
        report["left_out"]
            .as_array()
            .unwrap()
            .iter()
            .any(|l| l.as_str().unwrap().contains("no virtual object"))
    );
    assert!(report["comparison"]["rmse"].as_f64().unwrap() < 0.0025);
}

#[test]
fn hdr_merges_brackets_and_refuses_bad_ones() {
    let desk = Desk::new();
    let out = desk.path("merged.exr");
    let csv = desk.path("response.csv");
    let b = |name: &str, ev: &str| format!("{DESK}/brackets/{name}.png:{ev}");
    let run = arlux(&[
        "hdr",
        "--bracket",
        &b("ev-2", "-2"),
        "--bracket",
        &b("ev+0", "0"),
        "--bracket",
        &b("ev+2", "2"),
        "-o",
        out.to_str().unwrap(),
        "--response",
        csv.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert_eq!(arlux::image_io::read_image(&out).unwrap().width, 512);
    assert_eq!(std::fs::read_to_string(&csv).unwrap().lines().count(), 257);
    common::arlux_refused(
        &[
            "hdr",
            "--bracket",
            &b("ev+0", "0"),
            "-o",
            desk.path("one.exr").to_str().unwrap(),
        ],
        &["a single exposure"],
    );
    let same = arlux(&[
        "hdr",
        "--bracket",
        &b("ev+0", "0"),
        "--bracket",
        &b("ev+1", "0"),
        "-o",
        desk.path("same.exr").to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&same.stderr).contains("same EV"));
    let small = desk.path("small.png");
    image::RgbImage::new(8, 8).save(&small).unwrap();
    let misaligned = arlux(&[
        "hdr",
        "--bracket",
        &b("ev+0", "0"),
        "--bracket",
        &format!("{}:1", small.display()),
        "-o",
        desk.path("mis.exr").to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&misaligned.stderr).contains("must be aligned"));
    assert!(
        !desk.path("one.exr").exists()
            && !desk.path("same.exr").exists()
            && !desk.path("mis.exr").exists()
    );
}

#[test]
fn a_light_placed_by_its_shadows_renders_like_the_given_one() {
    // The spot's shadow lines through the table top's corners onto the floor.
    let light = [1.5f64, 2.3, 1.0];
    let corners: [[f64; 3]; 4] = [
        [-1.0, 0.75, -1.05],
        [0.2, 0.75, -1.05],
        [-1.0, 0.75, -1.75],
        [0.2, 0.75, -1.75],
    ];
    let lines: Vec<String> = corners
        .iter()
        .map(|v| {
            let t = -light[1] / (v[1] - light[1]);
            let s: Vec<f64> = (0..3).map(|k| light[k] + (v[k] - light[k]) * t).collect();
            format!(
                "{{ shadow = [{}, {}, {}], vertex = [{}, {}, {}] }}",
                s[0], s[1], s[2], v[0], v[1], v[2]
            )
        })
        .collect();
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "position = [1.5, 2.3, 1.0]",
        &format!("position = {{ shadow_lines = [{}] }}", lines.join(", ")),
    );
    let report = arlux_json(&[
        "render",
        &desk.scene(),
        "--variant",
        "box_table",
        "-o",
        desk.path("s.exr").to_str().unwrap(),
        "--json",
    ]);
    assert!(report["comparison"]["rmse"].as_f64().unwrap() < 0.003);

    // Two parallel lines only: an error saying what is missing, naming the key.
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "position = [1.5, 2.3, 1.0]",
        "position = { shadow_lines = [{ shadow = [0, 0, 0], vertex = [0, 1, 0] }, { shadow = [1, 0, 0], vertex = [1, 1, 0] }] }",
    );
    common::arlux_refused(
        &[
            "render",
            &desk.scene(),
            "--variant",
            "box_table",
            "-o",
            desk.path("p.exr").to_str().unwrap(),
        ],
        &["light[1].position", "parallel"],
    );
    assert!(!desk.path("p.exr").exists());
}

#[test]
fn a_closed_pipe_is_not_a_failure() {
    let desk = Desk::new();
    let mut child = Command::new(env!("CARGO_BIN_EXE_arlux"))
        .args([
            "motion",
            &desk.scene(),
            "--motion",
            "box_slide",
            "-o",
            desk.path("m").to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The reader goes away before the first line is written.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && !stderr.contains("panicked"),
        "{:?} {stderr}",
        out.status
    );
}

#[test]
fn radiosity_recovers_a_light_marked_reconstruct_first() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.exr");
    let run = arlux(&[
        "radiosity",
        &format!("{DESK}/scene_reconstruct.toml"),
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // No progress drawn into a pipe, whatever the command runs through.
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!stderr.contains("radiosity:"), "{stderr}");
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    // The model with the recovered spot explains the photo about as well as with the true one (0.0096).
    let rmse = report["comparison"]["rmse"].as_f64().unwrap();
    assert!(rmse < 0.012, "model against the photo {rmse}");
}

/// A motion takes the render flags as `render` does: its first frame with
/// `--patch-size`, `--min-level`, `--penumbra-level` and `--samples` is the
/// render of a variant posing the box there with the same flags, bit for bit.
#[test]
fn a_motion_takes_the_render_flags() {
    let desk = Desk::new();
    let scene = desk.scene();
    let text = std::fs::read_to_string(&scene).unwrap()
        + "\n[[variant]]\nname = \"slide_0\"\nobjects = { box = { translate = [-1.3, 0.0, 0.5] } }\n";
    std::fs::write(&scene, text).unwrap();
    let flags = [
        "--patch-size",
        "0.5",
        "--min-level",
        "3",
        "--penumbra-level",
        "5",
        "--samples",
        "2",
    ];
    let frames = desk.path("m");
    let mut motion = vec![
        "motion",
        &scene,
        "--motion",
        "box_slide",
        "--frames",
        "0..1",
    ];
    let out = frames.to_str().unwrap().to_string();
    motion.extend(["-o", &out]);
    motion.extend(flags);
    common::arlux_ok(&motion);
    let still = desk.path("still.exr");
    let mut render = vec![
        "render",
        &scene,
        "--variant",
        "slide_0",
        "-o",
        still.to_str().unwrap(),
    ];
    render.extend(flags);
    common::arlux_ok(&render);
    let a = arlux::image_io::read_image(&frames.join("box_slide_000.exr")).unwrap();
    let b = arlux::image_io::read_image(&still).unwrap();
    assert!(
        a.pixels == b.pixels,
        "the motion's frame differs from the render with the same flags"
    );
    // And the flags matter: the default first frame differs.
    let plain = desk.path("plain");
    common::arlux_ok(&[
        "motion",
        &scene,
        "--motion",
        "box_slide",
        "--frames",
        "0..1",
        "-o",
        plain.to_str().unwrap(),
    ]);
    let c = arlux::image_io::read_image(&plain.join("box_slide_000.exr")).unwrap();
    assert!(a.pixels != c.pixels);
}

/// A motion takes `--method texture` as `render` does: each frame is the
/// texture path's render of a variant posing the box there, bit for bit,
/// and the report says every pose was rendered in full.
#[test]
fn a_motion_renders_by_the_texture_path_as_render_does() {
    let desk = Desk::new();
    let scene = desk.scene();
    let text = std::fs::read_to_string(&scene).unwrap()
        + "\n[[variant]]\nname = \"slide_1\"\nobjects = { box = { translate = [-0.9571, 0.0, 0.3714] } }\n";
    std::fs::write(&scene, text).unwrap();
    let frames = desk.path("m");
    let report = common::arlux_json(&[
        "motion",
        &scene,
        "--motion",
        "box_slide",
        "--frames",
        "0..2",
        "--method",
        "texture",
        "--json",
        "-o",
        frames.to_str().unwrap(),
    ]);
    let poses = report["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 2);
    assert!(poses.iter().all(|p| p["full_render"] == true), "{report}");
    let still = desk.path("still.exr");
    common::arlux_ok(&[
        "render",
        &scene,
        "--variant",
        "slide_1",
        "--method",
        "texture",
        "-o",
        still.to_str().unwrap(),
    ]);
    let a = arlux::image_io::read_image(&frames.join("box_slide_001.exr")).unwrap();
    let b = arlux::image_io::read_image(&still).unwrap();
    assert!(
        a.pixels == b.pixels,
        "the motion's frame differs from the texture path's render of its pose"
    );
    // The pixel path's frame of the same pose is another image.
    let pixels = desk.path("pixels.exr");
    common::arlux_ok(&[
        "render",
        &scene,
        "--variant",
        "slide_1",
        "-o",
        pixels.to_str().unwrap(),
    ]);
    let c = arlux::image_io::read_image(&pixels).unwrap();
    assert!(a.pixels != c.pixels, "the method was not the texture path");
}
