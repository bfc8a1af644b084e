//! Ray throughput on `scenes/desk` at the camera's resolution: primary rays
//! (one per pixel centre) and occlusion rays (16 per pixel, from each pixel's
//! surface point to a 4×4 stratified grid on the panel light), each traced
//! singly and in packets of 16, on all threads. Criterion reports rays/s.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use rayon::prelude::*;

use arlux::scene::{LightShape, Scene};
use arlux::trace::{Layer, TraceRay, Tracer};

struct Setup {
    tracer: Tracer,
    primary: Vec<TraceRay>,
    shadow: Vec<TraceRay>,
}

fn setup() -> Setup {
    let scene =
        Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/scene.toml")).unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let cam = &scene.camera;
    let primary: Vec<TraceRay> = (0..cam.height)
        .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let r = cam.pixel_ray(x, y);
            TraceRay::new(r.origin.as_vec3(), r.direction.as_vec3())
        })
        .collect();
    let mut hits = vec![None; primary.len()];
    tracer.intersect_batch(&primary, Layer::All, &mut hits);

    let panel = &scene.lights[0];
    let (centre, LightShape::Rect { u, v }) =
        (panel.known_position().unwrap().as_vec3(), panel.shape)
    else {
        panic!("the desk's panel is a rect light")
    };
    let (u, v) = (u.as_vec3(), v.as_vec3());
    // Fixed jitter inside each of the 4×4 cells: a deterministic workload.
    let targets: Vec<Vec3> = (0..16)
        .map(|i| {
            let (a, b) = ((i % 4) as f32, (i / 4) as f32);
            let (ja, jb) = ((i * 7 % 11) as f32 / 11.0, (i * 5 % 13) as f32 / 13.0);
            centre + u * ((a + ja) / 4.0 - 0.5) + v * ((b + jb) / 4.0 - 0.5)
        })
        .collect();
    let mut shadow = Vec::new();
    for (ray, hit) in primary.iter().zip(&hits) {
        if let Some(h) = hit {
            let p = ray.origin + ray.direction * h.t + h.normal * 1e-4;
            shadow.extend(targets.iter().map(|&t| TraceRay::segment(p, t, 1e-4)));
        }
    }
    Setup {
        tracer,
        primary,
        shadow,
    }
}

fn bench(c: &mut Criterion) {
    let s = setup();
    let mut g = c.benchmark_group("trace");
    g.sample_size(20);

    g.throughput(Throughput::Elements(s.primary.len() as u64));
    g.bench_function("primary_single", |b| {
        b.iter(|| {
            s.primary
                .par_chunks(512)
                .map(|rs| {
                    rs.iter()
                        .filter(|r| s.tracer.intersect(r, Layer::All).is_some())
                        .count()
                })
                .sum::<usize>()
        })
    });
    g.bench_function("primary_packet16", |b| {
        b.iter(|| {
            s.primary
                .par_chunks(512)
                .map(|rs| {
                    let mut out = vec![None; rs.len()];
                    s.tracer.intersect_batch(rs, Layer::All, &mut out);
                    out.iter().filter(|h| h.is_some()).count()
                })
                .sum::<usize>()
        })
    });

    g.throughput(Throughput::Elements(s.shadow.len() as u64));
    g.bench_function("occlusion_single", |b| {
        b.iter(|| {
            s.shadow
                .par_chunks(4096)
                .map(|rs| {
                    rs.iter()
                        .filter(|r| s.tracer.occluded(r, Layer::All))
                        .count()
                })
                .sum::<usize>()
        })
    });
    g.bench_function("occlusion_packet16", |b| {
        b.iter(|| {
            s.shadow
                .par_chunks(4096)
                .map(|rs| {
                    let mut out = vec![false; rs.len()];
                    s.tracer.occluded_batch(rs, Layer::All, &mut out);
                    out.iter().filter(|&&o| o).count()
                })
                .sum::<usize>()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
