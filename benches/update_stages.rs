//! Per-stage medians of an object moving back and forth between two
//! poses of a motion on one session (by default the desk's box between
//! poses 3 and 4 of `box_slide`): for A/B comparisons of an update's
//! stages (run the old and the new binary alternately; this machine's
//! timings move by ±15–30% between runs).
//!
//! `cargo bench --bench update_stages -- [UPDATES [SCENE MOTION A B]]` (a
//! report, not criterion; `cargo test --benches` runs nothing). SCENE
//! `assets` is the `update` bench's lounge with generated real-looking
//! assets (motions `prop_walk`, `wide_walk`, `stool_walk`).
//!
//! Built with `--features ray-timing`, it also gives per update the rays
//! traced by kind and the CPU time spent in Embree tracing them: the part
//! of an update no bookkeeping can remove with the rays it casts.

#[path = "../tests/common/asset.rs"]
mod asset;

use std::collections::BTreeMap;

use arlux::model::StageTimes;
use arlux::render::{RenderSettings, Session};
use arlux::scene::Scene;

fn main() -> anyhow::Result<()> {
    // `cargo bench` passes its own flags; `cargo test --benches` asks for a quick pass.
    if std::env::args().any(|a| a == "--test" || a == "--list") {
        return Ok(());
    }
    let args: Vec<String> = (std::env::args().skip(1))
        .filter(|a| !a.starts_with("--"))
        .collect();
    let updates: usize = args.first().map_or(Ok(60), |a| a.parse())?;
    let desk = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/desk/scene.toml");
    let (scene, motion, a, b) = match &args[..] {
        [_, scene, motion, a, b] => (scene.as_str(), motion.as_str(), a.parse()?, b.parse()?),
        _ => (desk, "box_slide", 3, 4),
    };
    let assets = tempfile::tempdir()?;
    let scene = match scene {
        "assets" => asset::lounge_with_assets(assets.path()),
        path => path.into(),
    };
    let base = Scene::load(&scene)?;
    let (p3, p4) = (
        base.with_motion_pose(motion, a)?,
        base.with_motion_pose(motion, b)?,
    );
    let photo = p3.load_photo()?;
    let mut session = Session::start(
        &p3,
        &photo,
        &RenderSettings::default(),
        &mut StageTimes::default(),
    )?;
    session.prepare_updates(&mut StageTimes::default());
    session.image_only();
    let (mut stages, mut totals): (BTreeMap<String, Vec<f64>>, Vec<f64>) = Default::default();
    let (mut kept, mut pixels) = (Vec::new(), Vec::new());
    let mut traced = Vec::new();
    arlux::trace::timing::take();
    let cpu_before = process_cpu_seconds();
    for i in 0..updates {
        let mut times = StageTimes::default();
        let t0 = std::time::Instant::now();
        let stats = session.update(if i % 2 == 0 { &p4 } else { &p3 }, &mut times)?;
        kept.push((
            stats.bundles_kept,
            stats.gathers_kept,
            stats.gathers_partly_kept,
            stats.shaded_kept,
        ));
        pixels.push((stats.pixels_recomputed, stats.pixels_retraced));
        totals.push(t0.elapsed().as_secs_f64() * 1e3);
        traced.extend(arlux::trace::timing::take());
        let mut per: BTreeMap<String, f64> = BTreeMap::new();
        for (stage, d) in times.0 {
            *per.entry(stage.to_string()).or_default() += d.as_secs_f64() * 1e3;
        }
        // Stages run side by side within another, marked as such.
        for (stage, d) in times.1 {
            *per.entry(format!("  | {stage}")).or_default() += d.as_secs_f64() * 1e3;
        }
        for (stage, ms) in per {
            stages.entry(stage).or_default().push(ms);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "{updates} updates, medians: wall {:.2} ms",
        median(&mut totals)
    );
    // CPU time moves less than wall time when other work shares the machine.
    if let (Some(a), Some(b)) = (cpu_before, process_cpu_seconds()) {
        println!(
            "  CPU (user + system, all threads), mean per update: {:.2} ms",
            (b - a) * 1e3 / updates.max(1) as f64
        );
    }
    kept.sort();
    let (bundles, gathers, partly, shaded) = kept[kept.len() / 2];
    println!(
        "  kept of the last pose: {bundles} bundles, {gathers} vertices' gathers ({partly} more in part), {shaded} shaded points"
    );
    pixels.sort();
    let (recomputed, retraced) = pixels[pixels.len() / 2];
    println!("  pixels: {recomputed} real ones' light recomputed, {retraced} re-traced");
    for (stage, v) in stages.iter_mut() {
        println!("  {stage:<28} {:>6.2} ms", median(v));
    }
    report_rays(&traced, median(&mut totals));
    Ok(())
}

/// Rays per update by kind and their CPU time in Embree (means over the
/// updates), against the update's wall time on this machine's cores.
fn report_rays(traced: &[arlux::trace::timing::Totals], wall_ms: f64) {
    use arlux::trace::timing::Kind;
    if traced.is_empty() {
        return;
    }
    let n = traced.len() as f64;
    let mut cpu_ms = 0.0;
    println!("  rays per update (means), and their CPU time in Embree:");
    for (k, kind) in Kind::ALL.iter().enumerate() {
        let rays = traced.iter().map(|t| t[k].0).sum::<u64>() as f64 / n;
        let ms = traced.iter().map(|t| t[k].1.as_secs_f64()).sum::<f64>() * 1e3 / n;
        cpu_ms += ms;
        println!(
            "    {:<26} {:>9.0} rays {:>8.2} ms ({:.0} ns a ray)",
            kind.name(),
            rays,
            ms,
            ms * 1e6 / rays.max(1.0)
        );
    }
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get()) as f64;
    println!(
        "    all: {cpu_ms:.2} ms of CPU, {:.2} ms on {cores} cores ({:.0}% of the update's {wall_ms:.2} ms)",
        cpu_ms / cores,
        100.0 * cpu_ms / cores / wall_ms
    );
}

/// This process's CPU time so far, user and system, over all its threads
/// (Linux: `/proc/self/stat`, in clock ticks of 1/100 s; None elsewhere).
/// Read by hand: one file and two fields, where a crate would bring a
/// binding to the whole of `libc`.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) may hold spaces: fields are counted after its ')'.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the whole line: 11 and 12 after the name.
    let ticks = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
