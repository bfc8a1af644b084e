//! Full-resolution plates: `arlux render` of the desk at 23.8 megapixels
//! (its photo repeated 11 × 11 per pixel, the same field of view) and of
//! the lounge at 4 × its width and height, with the default memory budget
//! and with `--memory 1G`: wall time, peak memory and the stages; and the
//! desk once more with its variant's reference (enlarged the same way)
//! compared, as `arlux render` compares it band by band. A CLI report, not
//! criterion: each run is one process, measured as a user's (its own
//! `--json` report, peak memory from the kernel).
//!
//! `cargo bench --bench plate` (about 3 minutes on 2 cores; the scenes are
//! made in a temporary folder, ~600 MB of disk).

use std::path::{Path, PathBuf};
use std::process::Command;

use arlux::image_io::{ExrLayer, Image, read_image, write_exr};

/// `scenes/NAME` copied into `dir` with its photo enlarged `k` × `k` by
/// repeating each pixel, the camera's size likewise, references dropped
/// but `compared`'s (variant name, reference file), enlarged the same way.
fn enlarged(name: &str, k: u32, dir: &Path, compared: Option<(&str, &str)>) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name);
    let out = dir.join(name);
    copy_dir(&src, &out);
    let toml = std::fs::read_to_string(src.join("scene.toml")).unwrap();
    enlarge(&src.join("photo.exr"), k, &out.join("photo.exr"));
    if let Some((_, file)) = compared {
        std::fs::create_dir_all(out.join(file).parent().unwrap()).unwrap();
        enlarge(&src.join(file), k, &out.join(file));
    }
    let text: String = toml
        .lines()
        // The references, and what describes them (their noise, a twin).
        .filter(|l| !l.starts_with("reference"))
        .map(|l| match l.split_once(" = ") {
            Some(("width", v)) => format!("width = {}", v.parse::<u32>().unwrap() * k),
            Some(("height", v)) => format!("height = {}", v.parse::<u32>().unwrap() * k),
            Some(("name", v)) => match compared {
                Some((variant, file)) if v.trim_matches('"') == variant => {
                    format!("{l}\nreference = \"{file}\"")
                }
                _ => l.to_string(),
            },
            _ => l.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(out.join("scene.toml"), text).unwrap();
    out.join("scene.toml")
}

/// The image `from` enlarged `k` × `k` by repeating each pixel, written to `to`.
fn enlarge(from: &Path, k: u32, to: &Path) {
    let small = read_image(from).unwrap();
    let mut big = Image::new(small.width * k, small.height * k);
    for y in 0..big.height {
        for x in 0..big.width {
            big.set(x, y, small.get(x / k, y / k));
        }
    }
    write_exr(to, big.width, big.height, &[ExrLayer::Rgb("", &big)]).unwrap();
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            if e.file_name() != ".arlux-cache" && e.file_name() != "truth" {
                copy_dir(&e.path(), &target);
            }
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// One `arlux render` run's report.
fn render(scene: &Path, variant: &str, memory: Option<&str>, out: &Path) -> serde_json::Value {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_arlux"));
    cmd.args(["render", "--json", "--variant", variant, "-o"])
        .arg(out)
        .arg(scene);
    if let Some(m) = memory {
        cmd.args(["--memory", m]);
    }
    let run = cmd.output().unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&run.stdout).unwrap()
}

fn main() {
    // `cargo bench` passes its own flags; `cargo test --benches` asks for a quick pass.
    if std::env::args().any(|a| a == "--test" || a == "--list") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // (scene, enlargement, variant, its reference compared, --memory values)
    let cases = [
        ("desk", 11, "box_floor_a", None, &[None, Some("1G")][..]),
        (
            "desk",
            11,
            "box_floor_a",
            Some("truth/box_floor_a.exr"),
            &[None][..],
        ),
        ("lounge", 4, "stool_a", None, &[None, Some("1G")][..]),
    ];
    println!(
        "| scene | pixels | --memory | reference | bands × rows | wall s | peak MB | B/px | pixel data s | composite s | write s | photo per patch s | skill |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (k_case, (name, k, variant, reference, memories)) in cases.into_iter().enumerate() {
        let folder = dir.path().join(k_case.to_string());
        let scene = enlarged(name, k, &folder, reference.map(|r| (variant, r)));
        for &memory in memories {
            let out = dir.path().join(format!("{name}.exr"));
            let r = render(&scene, variant, memory, &out);
            let stage = |s: &str| {
                (r["stages"].as_array().unwrap().iter())
                    .filter(|e| e["stage"] == s)
                    .map(|e| e["seconds"].as_f64().unwrap())
                    .sum::<f64>()
            };
            let pixels = r["pixels"].as_f64().unwrap();
            let peak = r["peak_memory_bytes"].as_f64().unwrap_or(f64::NAN);
            let skill = r["skill"]["skill"].as_f64().map(|s| format!("{s:.3}"));
            println!(
                "| {name} {variant} | {:.1} MP | {} | {} | {} × {} | {:.1} | {:.0} | {:.0} | {:.1} | {:.1} | {:.1} | {:.1} | {} |",
                pixels / 1e6,
                memory.unwrap_or("default"),
                if reference.is_some() {
                    "compared"
                } else {
                    "none"
                },
                r["bands"]["count"],
                r["bands"]["rows"],
                r["seconds"].as_f64().unwrap(),
                peak / 1e6,
                peak / pixels,
                stage("pixel data array"),
                stage("composite"),
                stage("write bands") + stage("write"),
                stage("photo per patch"),
                skill.as_deref().unwrap_or("—"),
            );
            std::fs::remove_file(&out).unwrap();
        }
        std::fs::remove_dir_all(&folder).unwrap();
    }
}
