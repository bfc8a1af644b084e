//! Real-looking assets in the desk: a generated glTF made like a Blender
//! export (80k triangles, 2k base-colour, metallic-roughness and normal
//! textures, nested node scales), rendered by `arlux render` as a user runs
//! it: wall time and peak memory from the CLI's own `--json` report, each
//! case one process. The rows compare
//! - one object against three objects placed from the same file (the file
//!   is read once, its textures shared),
//! - one object shown while two more from other files are disabled, hidden
//!   by the variant, or not in the scene at all (what is not shown is not
//!   read);
//! - the texture path against the pixel path on one object of 8,000 and
//!   30,000 triangles, first in a fresh folder (each path makes its room's
//!   links) and again (the links read from the scene's cache).
//!
//! `cargo bench --bench assets` (about three minutes on 2 cores).

#[path = "../tests/common/asset.rs"]
mod asset;

use std::path::{Path, PathBuf};
use std::process::Command;

use asset::{AssetSpec, write_asset};

/// The desk's folder copied into `dir` (no truths), scene text replaced.
fn desk_with(dir: &Path, name: &str, objects: &str, variants: &str) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk");
    let out = dir.join(name);
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::symlink(src.join("photo.exr"), out.join("photo.exr")).unwrap();
    std::os::unix::fs::symlink(dir.join("geometry"), out.join("geometry")).unwrap();
    let text = std::fs::read_to_string(src.join("scene.toml")).unwrap();
    // The room, its lights and camera: everything before the first object.
    let room = &text[..text.find("[[virtual]]").unwrap()];
    let file = out.join("scene.toml");
    std::fs::write(&file, format!("{room}{objects}{variants}")).unwrap();
    file
}

fn object(name: &str, file: &str, at: [f64; 3], enabled: bool) -> String {
    format!(
        "[[virtual]]\nname = \"{name}\"\nmesh = \"geometry/{file}.gltf\"\ntranslate = [{}, {}, {}]\nenabled = {enabled}\n\n",
        at[0], at[1], at[2]
    )
}

/// One `arlux render` run's report.
fn render(scene: &Path, variant: Option<&str>, method: &str) -> serde_json::Value {
    let out = scene.with_file_name("out.exr");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_arlux"));
    cmd.args(["render", "--json", "--method", method, "-o"])
        .arg(&out)
        .arg(scene);
    if let Some(v) = variant {
        cmd.args(["--variant", v]);
    }
    let run = cmd.output().unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    std::fs::remove_file(&out).unwrap();
    serde_json::from_slice(&run.stdout).unwrap()
}

fn main() {
    // `cargo bench` passes its own flags; `cargo test --benches` asks for a quick pass.
    if std::env::args().any(|a| a == "--test" || a == "--list") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let geometry = dir.path().join("geometry");
    std::fs::create_dir(&geometry).unwrap();
    let spec = AssetSpec::heavy_prop();
    let desk = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/geometry");
    for room in ["room.obj", "furniture.obj"] {
        std::fs::copy(desk.join(room), geometry.join(room)).unwrap();
    }
    for name in ["prop", "other_a", "other_b"] {
        write_asset(&geometry, name, &spec);
    }
    let (a, b, c) = ([0.3, 0.0, -0.3], [-0.3, 0.0, 0.5], [-0.9, 0.75, -1.3]);
    // `cargo bench --bench assets -- methods` (or `-- instances`): one part.
    let only = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    if only.as_deref() != Some("methods") {
        instances(dir.path(), a, b, c);
    }
    if only.as_deref() != Some("instances") {
        methods(dir.path(), &geometry, a);
    }
}

/// One object beside three from one file, and beside others disabled or hidden.
fn instances(dir: &Path, a: [f64; 3], b: [f64; 3], c: [f64; 3]) {
    let spec = AssetSpec::heavy_prop();
    let prop = object("prop", "prop", a, true);
    let cases: Vec<(&str, PathBuf, Option<&str>)> = vec![
        ("one object", desk_with(dir, "one", &prop, ""), None),
        (
            "three from one file",
            desk_with(
                dir,
                "three",
                &[
                    prop.clone(),
                    object("two", "prop", b, true),
                    object("three", "prop", c, true),
                ]
                .concat(),
                "",
            ),
            None,
        ),
        (
            "one, two others disabled",
            desk_with(
                dir,
                "disabled",
                &[
                    prop.clone(),
                    object("a", "other_a", b, false),
                    object("b", "other_b", c, false),
                ]
                .concat(),
                "",
            ),
            None,
        ),
        (
            "one, a variant hiding two others",
            desk_with(
                dir,
                "hidden",
                &[
                    prop.clone(),
                    object("a", "other_a", b, true),
                    object("b", "other_b", c, true),
                ]
                .concat(),
                "[[variant]]\nname = \"alone\"\nhide = [\"a\", \"b\"]\n",
            ),
            Some("alone"),
        ),
    ];
    println!(
        "{} triangles, {}² textures per file",
        spec.triangles, spec.texture
    );
    println!("| case | wall s | peak MB | vs one object |");
    println!("| --- | --- | --- | --- |");
    let mut first: Option<(f64, f64)> = None;
    for (label, scene, variant) in cases {
        let r = render(&scene, variant, "pda");
        let (s, peak) = (
            r["seconds"].as_f64().unwrap(),
            r["peak_memory_bytes"].as_f64().unwrap_or(f64::NAN),
        );
        let (s0, p0) = *first.get_or_insert((s, peak));
        println!(
            "| {label} | {s:.2} | {:.0} | time {:.2}×, peak {:.2}× |",
            peak / 1e6,
            s / s0,
            peak / p0
        );
    }
}

/// The texture path beside the pixel path, one object of each size.
fn methods(dir: &Path, geometry: &Path, at: [f64; 3]) {
    println!(
        "| triangles | run | pixel path s / MB | texture path s / MB | texture / pixel | texture links |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    for triangles in [8_000, 30_000] {
        let name = format!("t{triangles}");
        let spec = AssetSpec {
            triangles,
            ..AssetSpec::heavy_prop()
        };
        write_asset(geometry, &name, &spec);
        let scene = desk_with(dir, &name, &object("prop", &name, at, true), "");
        let run = |method| {
            let r = render(&scene, None, method);
            let estimate = &r["texture"]["object_links_estimate"];
            (
                r["seconds"].as_f64().unwrap(),
                r["peak_memory_bytes"].as_f64().unwrap_or(f64::NAN) / 1e6,
                (r["links"].as_f64(), estimate["links"].as_f64()),
            )
        };
        // First in a fresh folder (each path makes its room's links), then
        // again with the links each kept in the scene's `.arlux-cache/`.
        for label in ["first", "again"] {
            let ((ps, pm, _), (ts, tm, (links, estimate))) = (run("pda"), run("texture"));
            println!(
                "| {triangles} | {label} | {ps:.2} / {pm:.0} | {ts:.2} / {tm:.0} | time {:.1}×, peak {:.2}× | {:.2} M, estimated {:.2} M |",
                ts / ps,
                tm / pm,
                links.unwrap_or(f64::NAN) / 1e6,
                estimate.unwrap_or(f64::NAN) / 1e6,
            );
        }
    }
}
