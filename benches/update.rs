//! Incremental updates along the desk's `box_slide`: the time of each
//! pose's update next to a full render of the same pose, and the lower
//! bound — the pixels whose visibility truly changed × rays per such pixel
//! ÷ the occlusion throughput of the `trace` bench (measured here the same
//! way, packets of 16 on all threads).

use std::path::Path;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use rayon::prelude::*;

use arlux::model::StageTimes;
use arlux::render::{RenderSettings, Session, render};
use arlux::scene::Scene;
use arlux::trace::{Layer, TraceRay};

fn bench(c: &mut Criterion) {
    let base = Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/scene.toml")).unwrap();
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
                let mut s = Session::start(&p3, &photo, &settings, &mut StageTimes::default()).unwrap();
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
            session.update(if forth { &p4 } else { &p3 }, &mut StageTimes::default()).unwrap()
        })
    });
    drop(session);
    // The rendered images are likewise dropped untimed.
    g.bench_function("box_slide_pose_4_full_render", |b| b.iter_with_large_drop(|| render(&p4, &photo, &settings, &mut StageTimes::default()).unwrap()));
    drop(start);
    g.finish();

    // The lower bound per pose: pixels whose light terms really changed
    // between poses × the rays a full render spent on such a pixel, at the
    // occlusion throughput of this machine.
    let tracer = first.build_tracer().unwrap();
    let rays: Vec<TraceRay> = (0..200_000)
        .map(|i| {
            let x = (i % 512) as f32 / 512.0 * 3.0 - 1.5;
            TraceRay::segment(glam::Vec3::new(x, 0.01, -1.0), glam::Vec3::new(-0.3, 2.58, -0.6), 1e-4)
        })
        .collect();
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
    let mut session = Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    session.prepare_updates(&mut StageTimes::default());
    for pose in 1..poses {
        let scene = base.with_motion_pose("box_slide", pose).unwrap();
        let before = session.composite.direct.clone();
        let mut times = StageTimes::default();
        let stats = session.update(&scene, &mut times).unwrap();
        let changed = before.pixels.iter().zip(&session.composite.direct.pixels).filter(|(a, b)| a != b).count();
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

criterion_group!(benches, bench);
criterion_main!(benches);
