//! A motion split over machines: each shard renders its poses (the first
//! in full, the rest by updates) and every frame equals the whole run's,
//! bit for bit, under the same name (re-running a shard rewrites the same
//! files).

mod common;

use std::path::Path;
use std::process::Command;

fn motion(out: &Path, extra: &[&str], env: &[(&str, &str)]) {
    let scene = common::scene_dir("desk").join("scene.toml");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_arlux"));
    cmd.args([
        "motion",
        scene.to_str().unwrap(),
        "--motion",
        "box_slide",
        "-o",
        out.to_str().unwrap(),
    ])
    .args(extra)
    .env_remove("SLURM_ARRAY_TASK_ID")
    .env_remove("JOB_COMPLETION_INDEX");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let run = cmd.output().unwrap();
    assert_eq!(
        run.status.code(),
        Some(0),
        "{extra:?}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
}

fn frames(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    files.sort();
    files
}

#[test]
fn motion_shards_equal_the_whole_run_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, shards, ranges) = (
        dir.path().join("whole"),
        dir.path().join("shards"),
        dir.path().join("ranges"),
    );
    motion(&whole, &[], &[]);
    motion(&shards, &["--shard", "0/3"], &[]);
    motion(
        &shards,
        &["--shard", "auto/3"],
        &[("SLURM_ARRAY_TASK_ID", "1")],
    );
    motion(
        &shards,
        &["--shard", "auto/3"],
        &[("JOB_COMPLETION_INDEX", "2")],
    );
    motion(&ranges, &["--frames", "0..5"], &[]);
    motion(&ranges, &["--frames", "5..8"], &[]);
    let expected = frames(&whole);
    assert_eq!(expected.len(), 8);
    assert_eq!(frames(&shards), expected, "shards 0/3, 1/3, 2/3");
    assert_eq!(frames(&ranges), expected, "frames 0..5 and 5..8");
}

#[test]
fn a_bad_shard_or_range_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scene = common::scene_dir("desk").join("scene.toml");
    for (args, expected) in [
        (
            vec!["--frames", "5..3"],
            "--frames 5..3: give A..B with A < B <= 8",
        ),
        (vec!["--shard", "3/3"], "--shard 3/3: i must be below n"),
        (
            vec!["--shard", "auto/2"],
            "neither SLURM_ARRAY_TASK_ID nor JOB_COMPLETION_INDEX",
        ),
        (
            vec!["--shard", "auto/4", "both"],
            "SLURM_ARRAY_TASK_ID=1 and JOB_COMPLETION_INDEX=2 disagree",
        ),
    ] {
        // "both": the two index variables set, and different.
        let both = args.last() == Some(&"both");
        let args: Vec<&str> = args.into_iter().filter(|a| *a != "both").collect();
        let env: &[(&str, &str)] = if both {
            &[("SLURM_ARRAY_TASK_ID", "1"), ("JOB_COMPLETION_INDEX", "2")]
        } else {
            &[]
        };
        let run = Command::new(env!("CARGO_BIN_EXE_arlux"))
            .args([
                "motion",
                scene.to_str().unwrap(),
                "--motion",
                "box_slide",
                "-o",
            ])
            .arg(&out)
            .args(&args)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .envs(env.iter().copied())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{stderr}");
        assert!(!out.exists(), "{args:?}: the folder was made");
    }
}

fn arlux(args: &[&str], env: &[(&str, &str)]) -> std::process::Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_arlux"));
    cmd.args(args)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().unwrap()
}

fn ok(args: &[&str], env: &[(&str, &str)]) {
    let run = arlux(args, env);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{args:?}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
}

#[test]
fn crops_of_a_frame_merged_equal_the_whole_render_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene_dir("desk").join("scene.toml");
    let scene = scene.to_str().unwrap();
    let path = |name: &str| dir.path().join(name).display().to_string();
    let render = |out: &str, crop: &[&str]| {
        let mut args = vec!["render", scene, "--variant", "box_floor_a", "-o", out];
        if !crop.is_empty() {
            args.push("--crop");
            args.extend(crop);
        }
        ok(&args, &[]);
    };
    render(&path("whole.exr"), &[]);
    // Uneven windows whose edges cross the box and its shadow (pbrt's
    // rounding gives the tiles no pixel twice and none missing), and the
    // quadrants, whose edges cross the table's seams.
    let uneven = [
        ["0", "0.37", "0", "0.61"],
        ["0.37", "1", "0", "0.61"],
        ["0", "0.71", "0.61", "1"],
        ["0.71", "1", "0.61", "1"],
    ];
    let quadrants = [
        ["0", "0.5", "0", "0.5"],
        ["0.5", "1", "0", "0.5"],
        ["0", "0.5", "0.5", "1"],
        ["0.5", "1", "0.5", "1"],
    ];
    // Thirds, rendered in bands (`--memory 64M`: 64 rows a band); and
    // edges drawn at random, printed on failure.
    let third = format!("{}", 1.0 / 3.0);
    let thirds = [
        ["0", &third, "0", "0.6666667"],
        [&third, "1", "0", "0.6666667"],
        ["0", &third, "0.6666667", "1"],
        [&third, "1", "0.6666667", "1"],
    ]
    .map(|w| w.map(String::from));
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    let (x, y) = (
        format!("{:.4}", 0.05 + 0.9 * (nanos % 10007) as f64 / 10007.0),
        format!(
            "{:.4}",
            0.05 + 0.9 * (nanos / 10007 % 10009) as f64 / 10009.0
        ),
    );
    let random = [
        ["0", &x, "0", &y],
        [&x, "1", "0", &y],
        ["0", &x, &y, "1"],
        [&x, "1", &y, "1"],
    ]
    .map(|w| w.map(String::from));
    let owned = |set: [[&str; 4]; 4]| set.map(|w| w.map(String::from));
    let sets = [
        (owned(uneven), false),
        (owned(quadrants), false),
        (thirds, true),
        (random, false),
    ];
    let mut tiles = Vec::new();
    for (set, (windows, banded)) in sets.iter().enumerate() {
        tiles.clear();
        for (i, w) in windows.iter().enumerate() {
            let tile = path(&format!("tile{set}-{i}.exr"));
            let mut crop: Vec<&str> = w.iter().map(String::as_str).collect();
            if *banded {
                crop.extend(["--memory", "64M"]);
            }
            render(&tile, &crop);
            tiles.push(tile);
        }
        let merged = path(&format!("merged{set}.exr"));
        // In any order.
        let mut args = vec!["merge", "-o", &merged];
        args.extend(tiles.iter().rev().map(String::as_str));
        ok(&args, &[]);
        let (whole, merged) = (
            arlux::image_io::read_image(Path::new(&path("whole.exr"))).unwrap(),
            arlux::image_io::read_image(Path::new(&merged)).unwrap(),
        );
        let differ: Vec<usize> = (0..whole.pixels.len())
            .filter(|&i| {
                whole.pixels[i].to_array().map(f32::to_bits)
                    != merged.pixels[i].to_array().map(f32::to_bits)
            })
            .collect();
        assert!(
            differ.is_empty(),
            "tiles {windows:?}: {} pixels differ from the whole render, the first at ({}, {})",
            differ.len(),
            differ.first().map_or(0, |i| i % 512),
            differ.first().map_or(0, |i| i / 512)
        );
        let (whole, merged_bytes) = (
            std::fs::read(path("whole.exr")).unwrap(),
            std::fs::read(path(&format!("merged{set}.exr"))).unwrap(),
        );
        assert!(
            whole == merged_bytes,
            "the merged frame's file differs from the whole render's"
        );
    }

    // Three tiles leave pixels out; a tile given twice overlaps.
    for (pieces, expected) in [
        (&tiles[..3], "pixels uncovered"),
        (&[tiles[0].clone(), tiles[0].clone()][..], "tiles overlap"),
    ] {
        let out = path("bad.exr");
        let mut args = vec!["merge", "-o", &out];
        args.extend(pieces.iter().map(String::as_str));
        let run = arlux(&args, &[]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains(expected), "{stderr}");
        assert!(!dir.path().join("bad.exr").exists());
    }
}

/// A sweep CSV's cells by column, less the timings (and the Pareto flag,
/// which the timings decide).
fn measured(csv: &str) -> Vec<Vec<(String, String)>> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            header
                .iter()
                .zip(l.split(','))
                .filter(|(h, _)| {
                    !h.starts_with("s_")
                        && !["total_seconds", "seconds_median", "seconds_max", "pareto"].contains(h)
                })
                .map(|(h, c)| (h.to_string(), c.to_string()))
                .collect()
        })
        .collect()
}

#[test]
fn sweep_shards_merged_equal_the_whole_sweep_less_timings() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene_dir("desk").join("scene.toml");
    let scene = scene.to_str().unwrap();
    let path = |name: &str| dir.path().join(name).display().to_string();
    let sweep = |out: &str, extra: &[&str], env: &[(&str, &str)]| {
        let mut args = vec![
            "sweep",
            scene,
            "--variant",
            "box_floor_a",
            "--quick",
            "-o",
            out,
        ];
        args.extend(extra);
        ok(&args, env);
    };
    sweep(&path("whole"), &[], &[]);
    sweep(&path("shards"), &["--shard", "0/3"], &[]);
    sweep(
        &path("shards"),
        &["--shard", "auto/3"],
        &[("SLURM_ARRAY_TASK_ID", "1")],
    );
    sweep(
        &path("shards"),
        &["--shard", "auto/3"],
        &[("JOB_COMPLETION_INDEX", "2")],
    );
    let shard = |i: usize| path(&format!("shards/sweep.shard-{i}-of-3.csv"));
    let merged = path("merged.csv");
    let plot = path("merged.png");
    ok(
        &[
            "merge",
            &shard(2),
            &shard(0),
            &shard(1),
            "-o",
            &merged,
            "--plot",
            &plot,
        ],
        &[],
    );
    let whole = std::fs::read_to_string(dir.path().join("whole/sweep.csv")).unwrap();
    let merged = std::fs::read_to_string(&merged).unwrap();
    let rows = measured(&whole);
    assert_eq!(rows.len(), 9, "the quick grid of a variant");
    assert_eq!(measured(&merged), rows);
    assert!(std::fs::metadata(&plot).unwrap().len() > 1000);

    // A shard missing is named.
    let out = path("part.csv");
    let run = arlux(&["merge", &shard(0), &shard(2), "-o", &out], &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("the shards leave 3 of 9 settings out, the first 3"),
        "{stderr}"
    );
}

#[test]
fn a_tile_reports_its_own_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene_dir("desk").join("scene.toml");
    let out = dir.path().join("tile.exr");
    let run = arlux(
        &[
            "render",
            scene.to_str().unwrap(),
            "--variant",
            "box_floor_a",
            "--crop",
            "0",
            "0.5",
            "0",
            "0.25",
            "-o",
            out.to_str().unwrap(),
            "--json",
        ],
        &[],
    );
    let v: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(v["pixels"], 256 * 96);
    assert!(v["copied_from_photo"].as_u64().unwrap() <= 256 * 96, "{v}");
}

#[test]
fn a_shard_beyond_the_poses_renders_nothing_and_succeeds() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scene = common::scene_dir("desk").join("scene.toml");
    // A job array of 10 tasks for the 8-pose motion: tasks 8 and 9 have no pose.
    let run = arlux(
        &[
            "motion",
            scene.to_str().unwrap(),
            "--motion",
            "box_slide",
            "--shard",
            "auto/10",
            "-o",
            out.to_str().unwrap(),
        ],
        &[("SLURM_ARRAY_TASK_ID", "9")],
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("no pose falls to this shard (8 in all)"),
        "{stderr}"
    );
    assert!(!out.exists(), "a folder was made for nothing");
}

#[test]
fn a_sweep_shard_beyond_the_grid_runs_nothing_and_succeeds() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sweep");
    let scene = common::scene_dir("desk").join("scene.toml");
    // A job array of 10 tasks for the 9 quick settings: task 9 has none.
    let run = arlux(
        &[
            "sweep",
            scene.to_str().unwrap(),
            "--variant",
            "box_floor_a",
            "--quick",
            "--shard",
            "auto/10",
            "--json",
            "-o",
            out.to_str().unwrap(),
        ],
        &[("SLURM_ARRAY_TASK_ID", "9")],
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("no setting falls to shard 9 of 10 (9 in all)"),
        "{stderr}"
    );
    let v: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(v["settings"], 0, "{v}");
    assert!(!out.exists(), "a folder was made for nothing");
}
