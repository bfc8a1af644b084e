//! Incremental updates along the desk's `box_slide`: the time of each
//! pose's update next to a full render of the same pose, and the lower
//! bound — the pixels whose visibility truly changed × rays per such pixel
//! ÷ the occlusion throughput of the `trace` bench (measured here the same
//! way, packets of 16 on all threads).

#[path = "../tests/common/asset.rs"]
mod asset;

use std::path::Path;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use rayon::prelude::*;

use arlux::model::StageTimes;
use arlux::render::{RenderSettings, Session, render};
use arlux::scene::Scene;
use arlux::trace::{Layer, TraceRay};

fn bench(c: &mut Criterion) {
    let base =
        Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/scene.toml")).unwrap();
    let settings = RenderSettings::default();
    let first = base.with_motion_pose("box_slide", 0).unwrap();
    let photo = first.load_photo().unwrap();
    let mut g = c.benchmark_group("update");
    g.sample_size(10);
    let poses = base.motion("box_slide").unwrap().translations.len();
    // Update from pose 3 to pose 4 (the middle of the slide), and a full render of pose 4.
    let p3 = base.with_motion_pose("box_slide", 3).unwrap();
    let p4 = base.with_motion_pose("box_slide", 4).unwrap();
    let start = Session::start(&p3, &photo, &settings, &mut StageTimes::default()).unwrap();
    g.bench_function("box_slide_pose_3_to_4_update", |b| {
        // By reference: the session is dropped untimed (freeing it is not
        // part of an update).
        b.iter_batched_ref(
            // The pixel-block hierarchy is built once with the Pixel Data
            // Array (Grosch §3.2), for every update of the motion to share.
            || {
                let mut s =
                    Session::start(&p3, &photo, &settings, &mut StageTimes::default()).unwrap();
                s.prepare_updates(&mut StageTimes::default());
                // As `arlux motion` runs: each pose's image, without the other layers.
                s.image_only();
                s
            },
            |s| s.update(&p4, &mut StageTimes::default()).unwrap(),
            criterion::BatchSize::LargeInput,
        )
    });
    // The same move back and forth on one session, as a motion runs.
    let mut session = Session::start(&p3, &photo, &settings, &mut StageTimes::default()).unwrap();
    session.prepare_updates(&mut StageTimes::default());
    session.image_only();
    let mut forth = false;
    g.bench_function("box_slide_poses_3_4_alternating_on_one_session", |b| {
        b.iter(|| {
            forth = !forth;
            session
                .update(if forth { &p4 } else { &p3 }, &mut StageTimes::default())
                .unwrap()
        })
    });
    drop(session);
    // The rendered images are likewise dropped untimed.
    full_renders(&mut g, "box_slide_pose_4", &p4, &photo, &settings, true);
    drop(start);
    g.finish();

    // The lower bound per pose: pixels whose direct light really changed
    // between poses × the rays the update cast per pixel it recomputed, at
    // the occlusion throughput of this machine.
    let tracer = arlux::scene_tracer::build_tracer(&first).unwrap();
    let rays = probe_rays(200_000);
    let t0 = Instant::now();
    let blocked: usize = rays
        .par_chunks(4096)
        .map(|r| {
            let mut out = vec![false; r.len()];
            tracer.occluded_batch(r, Layer::All, &mut out);
            out.iter().filter(|b| **b).count()
        })
        .sum();
    let throughput = rays.len() as f64 / t0.elapsed().as_secs_f64();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    session.prepare_updates(&mut StageTimes::default());
    for pose in 1..poses {
        let scene = base.with_motion_pose("box_slide", pose).unwrap();
        let before = session.composite.direct.clone();
        let mut times = StageTimes::default();
        let stats = session.update(&scene, &mut times).unwrap();
        let changed = before
            .pixels
            .iter()
            .zip(&session.composite.direct.pixels)
            .filter(|(a, b)| a != b)
            .count();
        let per_pixel = stats.rays as f64 / stats.pixels_recomputed.max(1) as f64;
        let bound = changed as f64 * per_pixel / throughput;
        println!(
            "pose {pose}: update {:.1} ms; {changed} pixels changed direct light, {} recomputed; lower bound {:.2} ms ({:.0} rays/pixel at {:.1} M rays/s; {blocked} of the probe's rays blocked)",
            times.total().as_secs_f64() * 1e3,
            stats.pixels_recomputed,
            bound * 1e3,
            per_pixel,
            throughput / 1e6
        );
    }
}

/// The occlusion probe's rays: from a line along the desk's floor to a
/// point below its light; none is blocked, so each is traced to its end.
fn probe_rays(count: usize) -> Vec<TraceRay> {
    (0..count)
        .map(|i| {
            let x = (i % 512) as f32 / 512.0 * 3.0 - 1.5;
            TraceRay::segment(
                glam::Vec3::new(x, 0.01, -1.0),
                glam::Vec3::new(-0.3, 2.58, -0.6),
                1e-4,
            )
        })
        .collect()
}

/// The update's work by part, next to the lower bound, all on one thread:
/// on more, the parts run side by side and share the cores, so their
/// times cannot be told apart. The bound counts the shadow rays of pixels
/// whose direct light changed; the update must also carry the objects'
/// indirect light (the change, solve, gather) and composite every pixel.
fn parts_on_one_thread(base: &Scene, photo: &arlux::image_io::Image, settings: &RenderSettings) {
    let (p3, p4) = (
        base.with_motion_pose("box_slide", 3).unwrap(),
        base.with_motion_pose("box_slide", 4).unwrap(),
    );
    let tracer = arlux::scene_tracer::build_tracer(&p3).unwrap();
    let rays = probe_rays(100_000);
    // Timed between the updates below, as this machine's speed drifts.
    let mut out = vec![false; rays.len()];
    let mut probe = || {
        let t0 = Instant::now();
        for (r, o) in rays.chunks(4096).zip(out.chunks_mut(4096)) {
            tracer.occluded_batch(r, Layer::All, o);
        }
        rays.len() as f64 / t0.elapsed().as_secs_f64()
    };
    // The pixels whose direct light changes from pose 3 to pose 4.
    let mut layered = Session::start(&p3, photo, settings, &mut StageTimes::default()).unwrap();
    layered.prepare_updates(&mut StageTimes::default());
    let before = layered.composite.direct.clone();
    let stats = layered.update(&p4, &mut StageTimes::default()).unwrap();
    let changed = before
        .pixels
        .iter()
        .zip(&layered.composite.direct.pixels)
        .filter(|(a, b)| a != b)
        .count();
    let rays_per_pixel = stats.rays as f64 / stats.pixels_recomputed.max(1) as f64;
    drop(layered);
    let mut session = Session::start(&p3, photo, settings, &mut StageTimes::default()).unwrap();
    session.prepare_updates(&mut StageTimes::default());
    session.image_only();
    const INDIRECT: [&str; 6] = [
        "virtual mesh",
        "direct light with objects",
        "objects seen from the room",
        "solve the change",
        "final gather on objects",
        "bounces between objects",
    ];
    const PIXELS: [&str; 3] = [
        "pixel-block traversal",
        "recompute pixels",
        "re-trace objects and edges",
    ];
    let (mut parts, mut throughputs): ([Vec<f64>; 5], Vec<f64>) = Default::default();
    for i in 0..30 {
        throughputs.push(probe());
        let mut times = StageTimes::default();
        let t0 = Instant::now();
        session
            .update(if i % 2 == 0 { &p4 } else { &p3 }, &mut times)
            .unwrap();
        let total = t0.elapsed().as_secs_f64() * 1e3;
        let sum = |names: &[&str], list: &[(&str, std::time::Duration)]| {
            list.iter()
                .filter(|(n, _)| names.contains(n))
                .map(|(_, d)| d.as_secs_f64() * 1e3)
                .sum::<f64>()
        };
        let (indirect, pixels, composite) = (
            // The change near the objects is traced after the solve, before the composite.
            sum(&INDIRECT, &times.1) + sum(&["the change near the objects"], &times.0),
            sum(&PIXELS, &times.1),
            sum(&["composite"], &times.0),
        );
        for (part, ms) in parts.iter_mut().zip([
            total,
            indirect,
            pixels,
            composite,
            total - indirect - pixels - composite,
        ]) {
            part.push(ms);
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let [total, indirect, pixels, composite, rest] = parts.map(median);
    let throughput = median(throughputs);
    let bound = changed as f64 * rays_per_pixel / throughput * 1e3;
    println!(
        "one thread, poses 3 <-> 4, medians of 30 updates and of 30 probes between them: update {total:.2} ms, {:.1}x the lower bound {bound:.2} ms ({changed} pixels changed direct light, {rays_per_pixel:.1} rays each, {:.1} M rays/s); \
         objects' indirect light {indirect:.2} ms ({:.1}x the bound), pixels' direct light and the objects' own pixels {pixels:.2} ms ({:.1}x), composite {composite:.2} ms ({:.1}x), the rest {rest:.2} ms",
        total / bound,
        throughput / 1e6,
        indirect / bound,
        pixels / bound,
        composite / bound
    );
}

fn parts(_: &mut Criterion) {
    let base =
        Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/scene.toml")).unwrap();
    let photo = base
        .with_motion_pose("box_slide", 0)
        .unwrap()
        .load_photo()
        .unwrap();
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| parts_on_one_thread(&base, &photo, &RenderSettings::default()));
}

/// `lounge`'s `stool_walk` (a 1,968-triangle stool).
fn lounge(c: &mut Criterion) {
    stool_walk(c, "scenes/lounge/scene.toml", "stool_walk");
}

/// `stool_walk` with the stool's ball subdivided (24,768 triangles).
fn dense(c: &mut Criterion) {
    stool_walk(c, "scenes/lounge/scene_dense.toml", "dense_stool_walk");
}

/// A scene's `stool_walk`: the same move back and forth on one session,
/// next to a full render of the pose, and the update's indirect part
/// (the change, solve, gather) on its own; benchmarks named after `label`.
fn stool_walk(c: &mut Criterion, scene: &str, label: &str) {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join(scene);
    walk(c, &scene, "stool_walk", label, true);
}

/// Poses 2 and 3 of `motion` in `scene`: the move back and forth on one
/// session, its indirect part, and a full render of pose 3 (with a cold
/// links cache too when `cold`).
fn walk(c: &mut Criterion, scene: &Path, motion: &str, label: &str, cold: bool) {
    let base = Scene::load(scene).unwrap();
    let settings = RenderSettings::default();
    let (p2, p3) = (
        base.with_motion_pose(motion, 2).unwrap(),
        base.with_motion_pose(motion, 3).unwrap(),
    );
    let photo = p2.load_photo().unwrap();
    let mut g = c.benchmark_group("update");
    g.sample_size(10);
    let mut session = Session::start(&p2, &photo, &settings, &mut StageTimes::default()).unwrap();
    session.prepare_updates(&mut StageTimes::default());
    session.image_only();
    let mut forth = false;
    let mut indirect = Vec::new();
    g.bench_function(
        format!("{label}_poses_2_3_alternating_on_one_session"),
        |b| {
            b.iter(|| {
                forth = !forth;
                let mut times = StageTimes::default();
                let stats = session
                    .update(if forth { &p3 } else { &p2 }, &mut times)
                    .unwrap();
                // Inside "radiosity | pixels" the indirect stages run beside the
                // pixels'; the change near the objects follows them.
                indirect.push(
                    times
                        .1
                        .iter()
                        .filter(|(n, _)| !n.contains("pixel") && !n.contains("re-trace"))
                        .map(|(_, d)| d.as_secs_f64() * 1e3)
                        .sum::<f64>()
                        + (times.0.iter())
                            .filter(|(n, _)| *n == "the change near the objects")
                            .map(|(_, d)| d.as_secs_f64() * 1e3)
                            .sum::<f64>(),
                );
                stats
            })
        },
    );
    drop(session);
    indirect.sort_by(f64::total_cmp);
    if !indirect.is_empty() {
        println!(
            "{label} update, indirect part (the change: what the room sees of the objects, solve, gather): median {:.1} ms over {} updates",
            indirect[indirect.len() / 2],
            indirect.len()
        );
    }
    full_renders(
        &mut g,
        &format!("{label}_pose_3"),
        &p3,
        &photo,
        &settings,
        cold,
    );
    g.finish();
}

/// Real-looking assets in the lounge (generated as a Blender export would
/// be: `tests/common/asset.rs`): an 80k-triangle prop with 2k textures
/// walking the stool's path, a 2 m wide round table moving a little, and
/// the stool walking while that table stands still in the room.
fn real_assets(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let file = asset::lounge_with_assets(dir.path());
    walk(c, &file, "prop_walk", "asset_80k_walk", false);
    walk(c, &file, "wide_walk", "asset_2m_walk", false);
    walk(c, &file, "stool_walk", "stool_walk_beside_2m_asset", false);
}

/// Full renders of `scene` beside its updates: with the room's links
/// refined every time (a cold cache, `settings` as given) and read from
/// the links cache (warm, filled by a first render), as `arlux render` does
/// by default.
fn full_renders(
    g: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>,
    label: &str,
    scene: &Scene,
    photo: &arlux::image_io::Image,
    settings: &RenderSettings,
    cold: bool,
) {
    if cold {
        g.bench_function(format!("{label}_full_render_cold_cache"), |b| {
            b.iter_with_large_drop(|| {
                render(scene, photo, settings, &mut StageTimes::default()).unwrap()
            })
        });
    }
    let mut warm = *settings;
    warm.model.cache_links = true;
    render(scene, photo, &warm, &mut StageTimes::default()).unwrap();
    g.bench_function(format!("{label}_full_render_warm_cache"), |b| {
        b.iter_with_large_drop(|| render(scene, photo, &warm, &mut StageTimes::default()).unwrap())
    });
}

/// A light's slider in a session whose lights already differ from the
/// photo's (`Session::relight`: the pixel data kept), on the desk's box and
/// `lounge`'s stool, beside a full render of the same scales (warm links).
fn sliders(c: &mut Criterion) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut g = c.benchmark_group("update");
    g.sample_size(10);
    for (label, file, variant, light) in [
        ("desk_light_slider", "desk/scene.toml", "box_floor_a", 1),
        ("lounge_light_slider", "lounge/scene.toml", "stool_a", 1),
    ] {
        let base = Scene::load(dir.join(file))
            .unwrap()
            .with_variant(variant)
            .unwrap();
        let photo = base.load_photo().unwrap();
        let mut settings = RenderSettings::default();
        settings.model.cache_links = true;
        let at = |scale: f64| {
            let mut s = base.clone();
            s.lights[light].scale = scale;
            s
        };
        let (low, high) = (at(1.5), at(2.0));
        let mut session =
            Session::start(&low, &photo, &settings, &mut StageTimes::default()).unwrap();
        // The layers an interactive session's views need (`serve`'s).
        session.keep_layers(arlux::composite::Layers::Object);
        // What `serve` solves while idle, then the slider's first step.
        let ahead = std::time::Instant::now();
        session.prepare_relights(&mut StageTimes::default());
        println!(
            "{label}, solved ahead in {:.1} ms",
            ahead.elapsed().as_secs_f64() * 1e3
        );
        let mut times = StageTimes::default();
        let first = std::time::Instant::now();
        session.relight(&high, &mut times).unwrap();
        println!(
            "{label}, first step {:.1} ms:",
            first.elapsed().as_secs_f64() * 1e3
        );
        for (name, d) in &times.0 {
            println!("    {name:<28} {:>7.1} ms", d.as_secs_f64() * 1e3);
        }
        let mut up = false;
        g.bench_function(format!("{label}_step"), |b| {
            b.iter(|| {
                up = !up;
                let scene = if up { &low } else { &high };
                session.relight(scene, &mut StageTimes::default()).unwrap()
            })
        });
        drop(session);
        full_renders(&mut g, label, &high, &photo, &settings, false);
    }
    g.finish();
}

criterion_group!(benches, bench, parts, lounge, dense, real_assets, sliders);
criterion_main!(benches);
