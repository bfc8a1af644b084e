//! Refuse, never drop: inputs a run will read are checked before any of
//! its work, a mesh is read whole or refused naming the element, and a run's
//! outputs are committed together or not at all. Each case: exit status 2,
//! the message naming the file and the key or element, no render stage
//! run, and the output folder as it was (names, inodes and bytes).

mod common;

use std::os::unix::fs::MetadataExt as _;
use std::path::Path;
use std::process::Output;

use common::{Desk, arlux};

/// Every file under `dir` with its inode and bytes, sorted by name.
fn snapshot(dir: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let mut out = Vec::new();
    if !dir.exists() {
        return out;
    }
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        let m = e.metadata().unwrap();
        let bytes = if m.is_file() {
            std::fs::read(e.path()).unwrap()
        } else {
            Vec::new()
        };
        out.push((e.file_name().to_string_lossy().into_owned(), m.ino(), bytes));
    }
    out.sort();
    out
}

/// The run failed with status 2 naming every `expected` text, before any
/// render stage (the `--timings` report names none).
fn refused_before_work(out: &Output, expected: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    for e in expected {
        assert!(stderr.contains(e), "'{e}' not in: {stderr}");
    }
    for stage in [
        "tracer",
        "pixel data array",
        "composite",
        "write",
        "form factors",
    ] {
        assert!(
            !stderr.lines().any(|l| l.trim_start().starts_with(stage)),
            "the stage '{stage}' ran before the refusal: {stderr}"
        );
    }
}

/// Bad references: the wrong size, cut short, not an image at all.
fn bad_references(desk: &Desk) -> Vec<(&'static str, String)> {
    let small = desk.path("small.exr");
    let img = arlux::image_io::Image::new(64, 48);
    arlux::image_io::write_exr(&small, 64, 48, &[arlux::image_io::ExrLayer::Rgb("", &img)])
        .unwrap();
    let whole = std::fs::read(common::scene_dir("desk").join("truth/box_floor_a.exr")).unwrap();
    std::fs::write(desk.path("cut.exr"), &whole[..whole.len() / 2]).unwrap();
    std::fs::write(desk.path("text.exr"), "not an image").unwrap();
    vec![
        ("small.exr", "64x48".to_string()),
        ("cut.exr", "cut.exr".to_string()),
        ("text.exr", "text.exr".to_string()),
    ]
}

#[test]
fn a_bad_reference_stops_render_before_any_work_and_keeps_the_output() {
    let desk = Desk::new();
    let out_dir = desk.path("out");
    std::fs::create_dir(&out_dir).unwrap();
    let out = out_dir.join("a.exr");
    std::fs::write(&out, "an earlier render").unwrap();
    let mut reference = "truth/box_floor_a.exr".to_string();
    for (file, named) in bad_references(&desk) {
        desk.edit(
            "scene.toml",
            &format!("reference = \"{reference}\""),
            &format!("reference = \"{file}\""),
        );
        reference = file.to_string();
        for method in ["pda", "texture"] {
            let before = snapshot(&out_dir);
            let run = arlux(&[
                "render",
                &desk.scene(),
                "--variant",
                "box_floor_a",
                "--method",
                method,
                "-o",
                out.to_str().unwrap(),
                "--png",
                out_dir.join("a.png").to_str().unwrap(),
                "--timings",
            ]);
            refused_before_work(&run, &[file, &named]);
            assert_eq!(
                snapshot(&out_dir),
                before,
                "{file}, {method}: the output folder changed"
            );
        }
    }
}

/// A reference missing for one variant stops only what compares against
/// it: another variant renders (with a warning naming the missing file),
/// that variant's render is refused before any work, naming its key.
#[test]
fn a_missing_reference_stops_only_its_own_variant() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "reference = \"truth/box_table.exr\"",
        "reference = \"truth/gone.exr\"",
    );
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
        stderr.contains("variant 'box_table'.reference: file not found") && out.is_file(),
        "{stderr}"
    );
    let run = arlux(&[
        "render",
        &desk.scene(),
        "--variant",
        "box_table",
        "-o",
        desk.path("b.exr").to_str().unwrap(),
        "--timings",
    ]);
    refused_before_work(
        &run,
        &["variant 'box_table'.reference: file not found", "gone.exr"],
    );
    assert!(!desk.path("b.exr").exists());
}

#[test]
fn a_bad_reference_of_a_later_pose_stops_motion_before_its_first_frame() {
    let desk = Desk::new();
    bad_references(&desk);
    desk.edit("scene.toml", "\"truth/box_slide_5.exr\"", "\"small.exr\"");
    let out_dir = desk.path("frames");
    let run = arlux(&[
        "motion",
        &desk.scene(),
        "--motion",
        "box_slide",
        "-o",
        out_dir.to_str().unwrap(),
        "--timings",
    ]);
    refused_before_work(&run, &["small.exr", "references[5]", "64x48"]);
    assert!(!out_dir.exists(), "the frames' folder was made");
}

/// A one-triangle glTF whose POSITION accessor claims `count` vertices
/// from byte `offset` of a 36-byte bufferView.
///
/// A second primitive of the same mesh reads its triangle whole: a reader
/// that skips the bad one keeps the surface, and the drop goes unseen.
fn gltf_triangle(count: usize, offset: usize) -> String {
    let mut v: serde_json::Value = serde_json::from_str(&gltf_primitive(count, offset, 4)).unwrap();
    let mut good = v["accessors"][0].clone();
    (good["count"], good["byteOffset"]) = (3.into(), 0.into());
    v["accessors"].as_array_mut().unwrap().push(good);
    let second = serde_json::json!({ "attributes": { "POSITION": 1 } });
    v["meshes"][0]["primitives"]
        .as_array_mut()
        .unwrap()
        .push(second);
    v.to_string()
}

/// [`gltf_triangle`] as a primitive of glTF mode `mode` (4 triangles,
/// 5 a strip, 6 a fan, 1 lines).
fn gltf_primitive(count: usize, offset: usize, mode: u32) -> String {
    let floats: [f32; 9] = [0.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 0.3, 0.0];
    let bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_le_bytes()).collect();
    let b64 = {
        const T: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut s = String::new();
        for c in bytes.chunks(3) {
            let n = (c[0] as u32) << 16 | (c[1] as u32) << 8 | c[2] as u32;
            for k in 0..4 {
                s.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            }
        }
        s
    };
    serde_json::json!({
        "asset": { "version": "2.0" },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "name": "card" }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": 0 }, "mode": mode }] }],
        "buffers": [{ "byteLength": 36, "uri": format!("data:application/octet-stream;base64,{b64}") }],
        "bufferViews": [{ "buffer": 0, "byteLength": 36 }],
        "accessors": [{
            "bufferView": 0, "byteOffset": offset, "componentType": 5126, "count": count,
            "type": "VEC3", "min": [0.0, 0.0, 0.0], "max": [0.3, 0.3, 0.0]
        }]
    })
    .to_string()
}

/// The desk with its box's mesh replaced by `file` holding `text`.
fn desk_with_object_mesh(file: &str, text: &str) -> Desk {
    let desk = Desk::new();
    std::fs::write(desk.path(file), text).unwrap();
    desk.edit(
        "scene.toml",
        "mesh = \"geometry/box.obj\"",
        &format!("mesh = \"{file}\""),
    );
    desk
}

#[test]
fn a_gltf_accessor_past_its_buffer_view_is_refused_naming_it() {
    // The well-formed triangle reads.
    let good = desk_with_object_mesh("card.gltf", &gltf_triangle(3, 0));
    common::arlux_ok(&["info", &good.scene()]);
    for (count, offset, words) in [
        (
            4,
            0,
            "accessor 0 claims 4 elements from byte 0 of bufferView 0, past its 36 bytes",
        ),
        (3, 40, "accessor 0 claims 3 elements from byte 40"),
    ] {
        let desk = desk_with_object_mesh("card.gltf", &gltf_triangle(count, offset));
        let out_dir = desk.path("out");
        std::fs::create_dir(&out_dir).unwrap();
        let before = snapshot(&out_dir);
        let scene = desk.scene();
        for command in ["info", "render"] {
            let mut args = vec![command, scene.as_str()];
            let out = out_dir.join("a.exr");
            let out = out.to_str().unwrap();
            if command == "render" {
                args.extend(["--variant", "box_floor_a", "-o", out, "--timings"]);
            }
            let run = arlux(&args);
            refused_before_work(&run, &["card.gltf", "mesh 'card'", "POSITION", words]);
        }
        assert_eq!(snapshot(&out_dir), before);
    }
}

#[test]
fn a_ply_face_of_two_vertices_is_refused_naming_it() {
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n0.3 0 0\n0 0.3 0\n3 0 1 2\n2 0 1\n";
    let desk = desk_with_object_mesh("card.ply", ply);
    let run = arlux(&["info", &desk.scene()]);
    refused_before_work(&run, &["card.ply", "face 1 has 2 vertices"]);
}

#[test]
fn tiles_of_two_variants_are_not_merged_into_one_frame() {
    let desk = Desk::new();
    let scene = desk.scene();
    let (left, right) = (desk.path("left.exr"), desk.path("right.exr"));
    for (variant, crop, out) in [
        ("box_floor_a", ["0", "0.5", "0", "1"], &left),
        ("box_floor_b", ["0.5", "1", "0", "1"], &right),
    ] {
        let mut args = vec![
            "render",
            scene.as_str(),
            "--variant",
            variant,
            "-o",
            out.to_str().unwrap(),
            "--crop",
        ];
        args.extend(crop);
        common::arlux_ok(&args);
    }
    let merged = desk.path("frame.exr");
    let run = arlux(&[
        "merge",
        left.to_str().unwrap(),
        right.to_str().unwrap(),
        "-o",
        merged.to_str().unwrap(),
    ]);
    refused_before_work(
        &run,
        &[
            "right.exr",
            "left.exr",
            "variant \"box_floor_b\" against \"box_floor_a\"",
        ],
    );
    assert!(!merged.exists(), "a frame was written");
}

#[test]
fn a_render_whose_png_cannot_be_written_leaves_nothing_it_wrote() {
    let desk = Desk::new();
    let out_dir = desk.path("out");
    std::fs::create_dir(&out_dir).unwrap();
    std::fs::write(out_dir.join("a.exr"), "an earlier render").unwrap();
    let (exr, png, aov) = (
        out_dir.join("a.exr"),
        out_dir.join("a.png"),
        out_dir.join("aov"),
    );
    let args = [
        "render",
        &desk.scene(),
        "--variant",
        "box_floor_a",
        "-o",
        exr.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
        "--aov",
        aov.to_str().unwrap(),
    ];
    let before = snapshot(&out_dir);
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_arlux"))
        .args(args)
        .env("ARLUX_TEST_WRITE_FAIL", "a.png")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("a.png") && stderr.contains("no space left"),
        "{stderr}"
    );
    assert_eq!(
        snapshot(&out_dir),
        before,
        "the EXR, the AOV folder or a temporary was left"
    );
    // Written whole when nothing fails: every layer of the frame as its own file.
    common::arlux_ok(&args);
    let mut written: Vec<String> = std::fs::read_dir(&aov)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    assert_eq!(
        written,
        [
            "alpha", "change", "direct", "indirect", "object", "photo", "shadow"
        ]
        .map(|n| format!("{n}.exr"))
    );
    assert!(png.exists());
}

#[test]
fn a_sweep_with_an_unreadable_reference_makes_no_folder() {
    let desk = Desk::new();
    bad_references(&desk);
    desk.edit(
        "scene.toml",
        "reference = \"truth/box_table.exr\"",
        "reference = \"cut.exr\"",
    );
    let out = desk.path("sweep-out");
    let run = arlux(&[
        "sweep",
        &desk.scene(),
        "--variant",
        "box_table",
        "--quick",
        "-o",
        out.to_str().unwrap(),
        "--timings",
    ]);
    refused_before_work(&run, &["cut.exr"]);
    assert!(!out.exists(), "the sweep's folder was made");
}

#[test]
fn arguments_the_parser_refuses_give_the_json_error_with_json() {
    let scene = common::scene_dir("desk").join("scene.toml");
    let scene = scene.to_str().unwrap();
    let out = std::env::temp_dir().join("arlux-never-written");
    let out = out.to_str().unwrap();
    for (command, args, words) in [
        (
            "render",
            vec![
                "render", scene, "--crop", "0", "1", "0", "-o", "x.exr", "--json",
            ],
            "--crop",
        ),
        (
            "motion",
            vec![
                "motion",
                scene,
                "--motion",
                "box_slide",
                "--frames",
                "0..2",
                "--shard",
                "1/2",
                "-o",
                out,
                "--json",
            ],
            "--shard",
        ),
        (
            "render",
            vec!["render", scene, "--no-such-flag", "-o", "x.exr", "--json"],
            "--no-such-flag",
        ),
    ] {
        let run = arlux(&args);
        assert_eq!(run.status.code(), Some(2));
        let v: serde_json::Value = serde_json::from_slice(&run.stdout)
            .unwrap_or_else(|e| panic!("{args:?}: stdout is not one JSON object ({e})"));
        assert_eq!(v["command"], command);
        let message = v["error"]["message"].as_str().unwrap();
        assert!(message.contains(words), "{message}");
        let file = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(format!("docs/schema/{command}.schema.json"));
        let schema: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
        assert!(
            jsonschema::validator_for(&schema).unwrap().is_valid(&v),
            "{v}"
        );
        assert!(
            !String::from_utf8_lossy(&run.stderr).is_empty(),
            "the message is on stderr too"
        );
    }
}

#[test]
fn gltf_strips_and_fans_are_read_and_lines_reported() {
    let dir = tempfile::tempdir().unwrap();
    for (mode, triangles) in [(4, 1), (5, 1), (6, 1)] {
        let file = dir.path().join(format!("mode{mode}.gltf"));
        std::fs::write(&file, gltf_primitive(3, 0, mode)).unwrap();
        let mesh = arlux::geometry::load_mesh(&file).unwrap();
        let n: usize = mesh.surfaces.iter().map(|s| s.triangles.len()).sum();
        assert_eq!(n, triangles, "mode {mode}");
    }
    let file = dir.path().join("lines.gltf");
    std::fs::write(&file, gltf_primitive(3, 0, 1)).unwrap();
    let said = match arlux::geometry::load_mesh(&file) {
        Ok(mesh) => mesh.unsupported.join("; "),
        Err(e) => e.to_string(),
    };
    assert!(
        said.contains("no triangles to read: it has primitives of mode Lines"),
        "{said}"
    );
}

#[test]
fn a_plate_with_a_reference_of_the_wrong_size_is_refused_before_any_work() {
    // A 24-megapixel camera (the desk's view, 11 × its size) whose variant
    // names the 512 × 384 truth: refused before the photo is even read.
    let desk = Desk::new();
    desk.edit("scene.toml", "width = 512", "width = 5632");
    desk.edit("scene.toml", "height = 384", "height = 4224");
    let out = desk.path("plate.exr");
    let run = arlux(&[
        "render",
        &desk.scene(),
        "--variant",
        "box_floor_a",
        "-o",
        out.to_str().unwrap(),
        "--timings",
    ]);
    refused_before_work(&run, &["truth/box_floor_a.exr", "512x384", "5632x4224"]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!stderr.contains("read photo"), "{stderr}");
    assert!(!out.exists());
}

#[test]
fn a_reference_noise_out_of_range_or_without_a_reference_is_refused_naming_the_key() {
    for (old, new, expected) in [
        (
            "reference_noise = 0.01045\n",
            "reference_noise = 1.5\n",
            "a relative RMSE in [0, 1)",
        ),
        (
            "reference = \"truth/box_floor_a.exr\"\nreference_noise = 0.01045\n",
            "reference_noise = 0.01045\n",
            "describes a reference",
        ),
        (
            "reference_noise = 0.01045\n",
            "reference_noise = 0.01045\nreference_twin = \"truth/box_floor_b.exr\"\n",
            "not both",
        ),
    ] {
        let desk = Desk::new();
        desk.edit("scene.toml", old, new);
        let message = common::arlux_refused(&["info", &desk.scene()], &[expected, "scene.toml"]);
        assert!(message.contains("reference_"), "{message}");
    }
}

#[test]
fn an_unknown_key_of_an_object_lists_every_placement_key() {
    let desk = Desk::new();
    desk.edit(
        "scene.toml",
        "rotate_y_deg = 20.0\n",
        "rotate_y_deg = 20.0\nrotat = [0, 1, 0]\n",
    );
    common::arlux_refused(
        &["info", &desk.scene()],
        &[
            "virtual[0].rotat: unknown key",
            "matrix",
            "quaternion",
            "rotate,",
            "rotate_y_deg",
        ],
    );
}
