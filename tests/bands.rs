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
