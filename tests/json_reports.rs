//! Every command's `--json` report, and its failures, validated against
//! the schema documented in `docs/schema/` (`docs/json.md`); progress on
//! stderr is drawn when asked (`--progress always`, as on a terminal) and
//! never into a pipe by default.

mod common;

use std::path::Path;
use std::process::Command;

use serde_json::Value;

const DESK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/desk");

/// Runs arlux; returns (status, stdout, stderr).
fn arlux(args: &[&str]) -> (i32, String, String) {
    let run = Command::new(env!("CARGO_BIN_EXE_arlux"))
        .args(args)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap();
    (
        run.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&run.stdout).into_owned(),
        String::from_utf8_lossy(&run.stderr).into_owned(),
    )
}

/// Validates `report` against `docs/schema/<command>.schema.json`: a
/// report against its first branch, a failure against its second, so that
/// a mismatch names the field.
fn validate(command: &str, report: &Value) {
    let file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("docs/schema/{command}.schema.json"));
    let schema: Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    let whole = jsonschema::validator_for(&schema)
        .unwrap_or_else(|e| panic!("{} is not a valid schema: {e}", file.display()));
    let branch = usize::from(report.get("error").is_some());
    let mut part = schema["oneOf"][branch].clone();
    part["$defs"] = schema["$defs"].clone();
    let validator = jsonschema::validator_for(&part).unwrap();
    let errors: Vec<String> = validator
        .iter_errors(report)
        .map(|e| format!("{} at {}", e, e.instance_path))
        .collect();
    assert!(errors.is_empty(), "{command}: {errors:#?}\n{report:#}");
    assert!(
        whole.is_valid(report),
        "{command}: not one of the schema's branches"
    );
}

/// Runs a command with `--json` and validates what it prints.
fn report(command: &str, args: &[&str]) -> Value {
    let mut all = vec![command];
    all.extend(args);
    all.push("--json");
    let (status, stdout, stderr) = arlux(&all);
    assert_eq!(status, 0, "{all:?}: {stderr}");
    let report: Value = serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    validate(command, &report);
    report
}

#[test]
fn every_command_s_report_follows_its_documented_schema() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name).display().to_string();
    let scene = format!("{DESK}/scene.toml");
    let truth = format!("{DESK}/truth/box_floor_a.exr");
    report("info", &[&scene]);
    report("ids", &[&scene, "-o", &at("ids.png")]);
    let r = report(
        "render",
        &[&scene, "--variant", "box_floor_a", "-o", &at("r.exr")],
    );
    assert!(r["skill"]["skill"].as_f64().unwrap() > 0.8, "{r}");
    // A hierarchical link is 8 bytes (source, factor), plus each receiver's range.
    let (links, bytes) = (
        r["links"].as_u64().unwrap(),
        r["links_bytes"].as_u64().unwrap(),
    );
    assert!(links > 0 && bytes >= 8 * links && bytes < 20 * links, "{r}");
    // Every patch is an element, and a root split in two has three.
    let elements = r["elements"].as_u64().unwrap();
    let patches = r["patches"].as_u64().unwrap();
    assert!(elements >= patches && elements < 2 * patches, "{r}");
    report(
        "render",
        &[
            &scene,
            "--variant",
            "box_table",
            "-o",
            &at("t.exr"),
            "--crop",
            "0",
            "0.5",
            "0",
            "1",
        ],
    );
    report(
        "motion",
        &[
            &scene,
            "--motion",
            "box_slide",
            "--frames",
            "0..2",
            "-o",
            &at("frames"),
        ],
    );
    report("radiosity", &[&scene, "-o", &at("rad.exr")]);
    report(
        "compare",
        &[
            &at("r.exr"),
            &truth,
            "--photo",
            &format!("{DESK}/photo.exr"),
        ],
    );
    for shard in ["0/2", "1/2"] {
        let sweep = at("sweep");
        let args = [
            &scene,
            "--variant",
            "box_floor_a",
            "--quick",
            "-o",
            &sweep,
            "--shard",
            shard,
        ];
        report("sweep", &args);
    }
    let shards = [
        at("sweep/sweep.shard-0-of-2.csv"),
        at("sweep/sweep.shard-1-of-2.csv"),
    ];
    let m = report("merge", &[&shards[0], &shards[1], "-o", &at("merged.csv")]);
    assert_eq!(m["settings"], 9);
    let brackets: Vec<String> = [("ev-2", -2), ("ev+0", 0), ("ev+2", 2)]
        .iter()
        .map(|(f, ev)| format!("{DESK}/brackets/{f}.png:{ev}"))
        .collect();
    report(
        "hdr",
        &[
            "--bracket",
            &brackets[0],
            "--bracket",
            &brackets[1],
            "--bracket",
            &brackets[2],
            "-o",
            &at("h.exr"),
        ],
    );
}

#[test]
fn a_failure_with_json_is_a_json_error_naming_the_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.exr").display().to_string();
    let scene = format!("{DESK}/scene.toml");
    let (status, stdout, stderr) =
        arlux(&["render", &scene, "--variant", "nope", "-o", &out, "--json"]);
    assert_eq!(status, 2, "{stderr}");
    let report: Value = serde_json::from_str(&stdout).unwrap();
    validate("render", &report);
    assert_eq!(report["error"]["key"], "variant");
    assert!(
        report["error"]["file"]
            .as_str()
            .unwrap()
            .ends_with("scene.toml")
    );
    assert!(stderr.contains("no variant named 'nope'"), "{stderr}");

    let desk = common::Desk::new();
    desk.edit(
        "geometry/box.obj",
        "v -0.150000 0.000000 0.150000",
        "v -0.15 zero 0.15",
    );
    let (status, stdout, _) = arlux(&["info", &desk.scene(), "--json"]);
    assert_eq!(status, 2);
    let report: Value = serde_json::from_str(&stdout).unwrap();
    validate("info", &report);
    // The key of the scene that names the mesh, and the mesh's line.
    assert_eq!(report["error"]["key"], "virtual[0].mesh", "{report}");
    assert!(
        report["error"]["message"]
            .as_str()
            .unwrap()
            .contains("box.obj: line 3"),
        "{report}"
    );
}

#[test]
fn progress_is_drawn_when_asked_and_never_into_a_pipe() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name).display().to_string();
    let scene = format!("{DESK}/scene.toml");
    let motion = |out: &str, extra: &[&str]| {
        let mut args = vec!["motion", &scene, "--motion", "box_slide", "-o", out];
        args.extend(extra);
        let (status, _, stderr) = arlux(&args);
        assert_eq!(status, 0, "{stderr}");
        stderr
    };
    let shown = motion(&at("a"), &["--progress", "always"]);
    assert!(shown.contains("8/8 poses"), "{shown}");
    let piped = motion(&at("b"), &[]);
    assert!(!piped.contains("poses"), "{piped}");
    // gonio takes tens of seconds: one run, asked to draw (the pipe's
    // silence is the same code path as motion's, checked above).
    let reconstruct = format!("{DESK}/scene_reconstruct.toml");
    let (ies, plot) = (at("spot.ies"), at("spot.png"));
    let (status, stdout, stderr) = arlux(&[
        "gonio",
        &reconstruct,
        "-o",
        &ies,
        "--json",
        "--plot",
        &plot,
        "--progress",
        "always",
    ]);
    assert_eq!(status, 0, "{stderr}");
    assert!(stderr.contains("gonio: reconstruct"), "{stderr}");
    // Into a log, a line per stage: no spinner and clock redrawn each tick.
    let lines: Vec<&str> = stderr.lines().filter(|l| l.contains("gonio:")).collect();
    assert!(
        lines
            .iter()
            .all(|l| l.starts_with("gonio:") && !l.ends_with("s)")),
        "{lines:?}"
    );
    let report: Value = serde_json::from_str(&stdout).unwrap();
    validate("gonio", &report);
    // The polar plot (plotters: axes in candela, legend, colour bar).
    let png = image::open(&plot).unwrap();
    assert_eq!((png.width(), png.height()), (1100, 540));
}
