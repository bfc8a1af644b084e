//! Rendering the desk's `box_floor_a` (512×384; 4 shadow rays per rect
//! light, 16 in penumbra; 4×4 sub-pixels at the box's edges): the whole
//! render, and the Pixel Data Array alone with its ray throughput (compare
//! with the `trace` bench's occlusion rays per second, the bound).

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

use arlux::model::{Model, StageTimes};
use arlux::patches::Patches;
use arlux::pda::{PdaInput, PixelDataArray, VirtualBounds};
use arlux::render::{RenderSettings, render};
use arlux::scene::Scene;

fn bench(c: &mut Criterion) {
    let base =
        Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/desk/scene.toml")).unwrap();
    let scene = base.with_variant("box_floor_a").unwrap();
    let photo = scene.load_photo().unwrap();
    let settings = RenderSettings::default();
    let mut g = c.benchmark_group("render");
    g.sample_size(10);
    g.bench_function("box_floor_a_full_render", |b| {
        b.iter(|| render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap())
    });

    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let model = Model::build(
        &scene,
        &photo,
        &tracer,
        &settings.model,
        &mut StageTimes::default(),
    )
    .unwrap();
    let patches = Patches::of_scene_with(
        &scene,
        true,
        settings.model.patch_size,
        settings.virtual_patch_size,
    );
    let bounds = VirtualBounds::of(&scene.virtual_world_surfaces());
    let active: Vec<bool> = model
        .lights
        .iter()
        .map(|l| l.scale > 0.0 || l.photo_scale() > 0.0)
        .collect();
    let input = PdaInput {
        camera: &scene.camera,
        tracer: &tracer,
        patches: &patches,
        lights: &model.lights,
        active: &active,
        bounds: &bounds,
        settings: settings.pda,
        for_updates: false,
        band: None,
        shaded_per_pixel: &[],
    };
    let rays = PixelDataArray::build(&input).rays;
    g.throughput(Throughput::Elements(rays));
    g.bench_function("pixel_data_array", |b| {
        b.iter(|| PixelDataArray::build(&input))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
