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
    ] {
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
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{stderr}");
        assert!(!out.exists(), "{args:?}: the folder was made");
    }
}
