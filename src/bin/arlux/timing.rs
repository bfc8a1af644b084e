//! One timing mechanism for every command: stages of this run, reported by `--timings`.

use serde_json::json;

/// Stages timed anywhere in this run, in order, for `--timings`.
pub(crate) static STAGES: std::sync::Mutex<Vec<(String, std::time::Duration)>> =
    std::sync::Mutex::new(Vec::new());

/// Runs `f` as the stage `name` of this run.
pub(crate) fn stage<T>(name: &str, f: impl FnOnce() -> T) -> T {
    arlux::util::stages::started(name);
    let t0 = std::time::Instant::now();
    let out = f();
    STAGES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((name.to_string(), t0.elapsed()));
    out
}

/// Marks a stage that ran side by side within another: listed, not summed.
pub(crate) const SIDE_BY_SIDE: &str = "  | ";

/// Adds a library call's stage times to this run's.
pub(crate) fn keep(times: &arlux::model::StageTimes) {
    let mut stages = STAGES.lock().unwrap_or_else(|e| e.into_inner());
    stages.extend(times.0.iter().map(|(n, d)| (n.to_string(), *d)));
    stages.extend(
        times
            .1
            .iter()
            .map(|(n, d)| (format!("{SIDE_BY_SIDE}{n}"), *d)),
    );
}

/// Peak resident memory of this process (Linux: VmHWM), bytes.
pub(crate) fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The `--timings` report: every stage, what no stage covers, and peak memory.
pub(crate) fn report_timings(wall: std::time::Duration) {
    let stages = STAGES.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let mut merged: Vec<(String, f64)> = Vec::new();
    for (name, d) in stages {
        match merged.iter_mut().find(|(n, _)| *n == name) {
            Some(m) => m.1 += d.as_secs_f64(),
            None => merged.push((name, d.as_secs_f64())),
        }
    }
    let sum: f64 = merged
        .iter()
        .filter(|m| !m.0.starts_with(SIDE_BY_SIDE))
        .map(|m| m.1)
        .sum();
    let wall = wall.as_secs_f64();
    eprintln!("timings:");
    for (name, secs) in &merged {
        eprintln!("  {name:<32} {:>10.1} ms", secs * 1e3);
    }
    eprintln!(
        "  {:<32} {:>10.1} ms",
        "(outside stages)",
        (wall - sum).max(0.0) * 1e3
    );
    eprintln!(
        "  {:<32} {:>10.1} ms  (stages: {:.1}% of it)",
        "wall",
        wall * 1e3,
        100.0 * sum / wall.max(1e-12)
    );
    match peak_memory() {
        Some(b) => eprintln!("  peak memory {:.1} MB", b as f64 / 1e6),
        None => eprintln!("  peak memory: not known on this system"),
    }
}

/// A library call's stages for a `--json` report: each name once, in
/// first-run order, with its summed seconds and how often it ran; stages
/// that ran side by side within another are marked so (not summed into
/// the total).
pub(crate) fn stages_json(times: &arlux::model::StageTimes) -> serde_json::Value {
    let mut merged: Vec<(&str, f64, usize, bool)> = Vec::new();
    let all = times
        .0
        .iter()
        .map(|s| (s, false))
        .chain(times.1.iter().map(|s| (s, true)));
    for ((name, d), side) in all {
        match merged.iter_mut().find(|m| m.0 == *name && m.3 == side) {
            Some(m) => {
                m.1 += d.as_secs_f64();
                m.2 += 1;
            }
            None => merged.push((name, d.as_secs_f64(), 1, side)),
        }
    }
    merged
        .into_iter()
        .map(|(stage, seconds, runs, side_by_side)| {
            json!({ "stage": stage, "seconds": seconds, "runs": runs, "side_by_side": side_by_side })
        })
        .collect()
}
