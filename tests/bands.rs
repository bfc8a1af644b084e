//! A still rendered in bands of rows under a memory budget (`--memory`)
//! is the whole render, byte for byte: its EXR (every layer), its PNG and
//! its report's counts and figures.

mod common;

use std::path::Path;

use common::arlux;

/// `arlux render` of `variant` with `extra` flags, into `dir/NAME.{exr,png}`; its report.
fn render(scene: &str, variant: &str, dir: &Path, name: &str, extra: &[&str]) -> serde_json::Value {
    let (exr, png) = (
        dir.join(format!("{name}.exr")),
        dir.join(format!("{name}.png")),
    );
    let mut args = vec![
        "render",
        scene,
        "--variant",
        variant,
        "--json",
        "-o",
        exr.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
    ];
    args.extend(extra);
    let run = arlux(&args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&run.stdout).unwrap()
}

#[test]
fn bands_render_the_whole_frame_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    // An object and its shadow across band edges (desk); a brightened
    // light with the photo's grain and lamps in view (lounge).
    for (name, variant) in [("desk", "box_floor_a"), ("lounge", "panel_2_x2")] {
        let scene = common::scene_dir(name).join("scene.toml");
        let scene = scene.to_str().unwrap();
        let whole = render(scene, variant, dir.path(), "whole", &[]);
        let bands = render(scene, variant, dir.path(), "bands", &["--memory", "64M"]);
        assert_eq!(whole["bands"]["count"], 1, "{whole}");
        let count = bands["bands"]["count"].as_u64().unwrap();
        assert!(count >= 6, "{name}: {} bands", count);
        for ext in ["exr", "png"] {
            let read = |n: &str| std::fs::read(dir.path().join(format!("{n}.{ext}"))).unwrap();
            assert!(
                read("whole") == read("bands"),
                "{name} {variant}: the {ext} files differ"
            );
        }
        for key in [
            "copied_from_photo",
            "ratio_fallbacks",
            "clamped",
            "pixels",
            "skill",
            "comparison",
        ] {
            assert_eq!(whole[key], bands[key], "{name} {variant}: {key}");
        }
    }
}

#[test]
fn a_bad_memory_budget_is_refused_naming_the_flag() {
    let scene = common::scene_dir("desk").join("scene.toml");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.exr");
    for bad in ["lots", "2X", "10M", "-1G", "nan"] {
        let flag = format!("--memory={bad}");
        let message = common::arlux_refused(
            &[
                "render",
                scene.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                &flag,
            ],
            &["--memory"],
        );
        assert!(message.contains(bad), "{message}");
        assert!(!out.exists());
    }
}

#[test]
fn a_tiles_figures_are_those_of_its_own_pixels_against_the_reference() {
    use arlux::compare::{compare, skill};
    use arlux::image_io::{PixelRect, read_image};
    let dir = tempfile::tempdir().unwrap();
    let folder = common::scene_dir("desk");
    let scene = folder.join("scene.toml");
    // Across the box and its shadow, in bands of a few rows.
    let extra = ["--memory", "64M", "--crop", "0.3", "0.8", "0.45", "0.85"];
    let report = render(
        scene.to_str().unwrap(),
        "box_floor_a",
        dir.path(),
        "tile",
        &extra,
    );
    let at = |k: &str| report["crop"][k].as_u64().unwrap() as u32;
    let rect = PixelRect {
        x0: at("x0"),
        x1: at("x1"),
        y0: at("y0"),
        y1: at("y1"),
    };
    let image = read_image(&dir.path().join("tile.exr")).unwrap();
    let truth = read_image(&folder.join("truth/box_floor_a.exr"))
        .unwrap()
        .crop(rect);
    let photo = read_image(&folder.join("photo.exr")).unwrap().crop(rect);
    let image = if (image.width, image.height) == (rect.width(), rect.height()) {
        image
    } else {
        image.crop(rect)
    };
    let expect = (compare(&image, &truth, None), skill(&image, &truth, &photo));
    assert!(expect.1.changed_pixels > 1000, "{:?}", expect.1);
    // Both sides through JSON text: serde_json's parser may round a float's
    // last bit differently from the value it printed.
    let parsed = |text: String| serde_json::from_str::<serde_json::Value>(&text).unwrap();
    let comparison = parsed(serde_json::to_string(&expect.0).unwrap());
    assert_eq!(report["comparison"], comparison);
    assert_eq!(
        report["skill"],
        parsed(serde_json::to_string(&expect.1).unwrap())
    );
}
