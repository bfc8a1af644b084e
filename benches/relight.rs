//! The texture path's light change on the desk (Loscos: 0.8 s per change):
//! one preprocess with the bulb inserted, then each light variant's scales
//! as a radiosity step on the kept mesh and links plus the display; and the
//! preprocess itself, once.

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};

use arlux::model::StageTimes;
use arlux::relight::{TexturePath, TextureSettings};
use arlux::scene::Scene;

fn bench(c: &mut Criterion) {
    let base =
        Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/scene.toml")).unwrap();
    // The bulb inserted (its forced refinement done), the box hidden: every light variant is a light change from here.
    let scene = base.with_variant("virtual_light_only").unwrap();
    let photo = scene.load_photo().unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let settings = TextureSettings::default();
    let mut g = c.benchmark_group("relight");
    g.sample_size(10);
    g.bench_function("preprocess", |b| {
        b.iter(|| {
            TexturePath::prepare(
                &scene,
                &photo,
                &tracer,
                &settings,
                &mut StageTimes::default(),
            )
            .unwrap()
        })
    });
    let path = TexturePath::prepare(
        &scene,
        &photo,
        &tracer,
        &settings,
        &mut StageTimes::default(),
    )
    .unwrap();
    for variant in ["panel_off", "spot_x2", "virtual_light_only"] {
        let scales: Vec<f64> = base
            .with_variant(variant)
            .unwrap()
            .lights
            .iter()
            .map(|l| l.scale)
            .collect();
        g.bench_function(format!("light_change_{variant}"), |b| {
            b.iter(|| path.relight(&scales, &mut StageTimes::default()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
