//! Radiosity on `scenes/desk` by mesh size: building the light transport
//! (form factors with visibility; hierarchical and, for coarse meshes, the
//! full matrix) and solving it with the desk's lights and reflectances.

use std::path::Path;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::DVec3;

use arlux::light::LightSource;

fn photo_scales(lights: &[LightSource]) -> Vec<f64> {
    lights.iter().map(|l| l.photo_scale()).collect()
}
use arlux::patches::Patches;
use arlux::radiosity::{DEFAULT_LINK_EPSILON, Transport, direct_irradiance, solve, total_direct};
use arlux::scene::Scene;
use arlux::trace::Layer;

fn bench(c: &mut Criterion) {
    let scene =
        Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/scene.toml")).unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let lights = LightSource::all(&scene).unwrap();
    let mut g = c.benchmark_group("radiosity");
    g.sample_size(10);
    for size in [1.0, 0.5, 0.25] {
        let patches = Patches::of_scene(&scene, false, size);
        let n = patches.patch_count();
        let id = format!("{size}m_{n}patches");
        g.bench_with_input(
            BenchmarkId::new("transport_hierarchical", &id),
            &patches,
            |b, p| {
                b.iter(|| Transport::hierarchical(p, &tracer, Layer::Real, DEFAULT_LINK_EPSILON))
            },
        );
        if size >= 0.5 {
            g.bench_with_input(BenchmarkId::new("transport_full", &id), &patches, |b, p| {
                b.iter(|| Transport::full(p, &tracer, Layer::Real))
            });
        }
        let transport =
            Transport::hierarchical(&patches, &tracer, Layer::Real, DEFAULT_LINK_EPSILON);
        let e = total_direct(
            patches.patch_count(),
            &photo_scales(&lights),
            &direct_irradiance(&patches, &lights, &tracer, Layer::Real, 4),
        );
        let rho = vec![DVec3::splat(0.6); n];
        let emission: Vec<DVec3> = rho.iter().zip(&e).map(|(r, e)| *r * *e).collect();
        g.bench_with_input(
            BenchmarkId::new("solve_hierarchical", &id),
            &patches,
            |b, p| b.iter(|| solve(p, &transport, &rho, &emission, 1e-7, 500)),
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
