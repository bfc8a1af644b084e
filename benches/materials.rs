//! Objects with materials against their flat Lambertian twins, side by
//! side in one run: every `materials` variant rendered from `scene.toml`
//! (glTF PBR) and from `scene_flat.toml` (clay of the mean albedo); and an
//! update that moves the chrome ball next to one that slides the desk's box.

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};

use arlux::model::StageTimes;
use arlux::render::{RenderSettings, Session, render};
use arlux::scene::Scene;

fn scene(name: &str, file: &str) -> Scene {
    Scene::load(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes")
            .join(name)
            .join(file),
    )
    .unwrap()
}

fn renders(c: &mut Criterion) {
    let settings = RenderSettings::default();
    let (pbr, flat) = (
        scene("materials", "scene.toml"),
        scene("materials", "scene_flat.toml"),
    );
    let mut g = c.benchmark_group("materials");
    g.sample_size(10);
    for v in [
        "globe_floor",
        "chrome_floor",
        "chrome_table",
        "vase_floor",
        "ring_table",
        "trio",
        "chrome_bulb",
    ] {
        for (kind, base) in [("pbr", &pbr), ("flat", &flat)] {
            let s = base.with_variant(v).unwrap();
            let photo = s.load_photo().unwrap();
            g.bench_function(format!("{v}_{kind}"), |b| {
                b.iter_with_large_drop(|| {
                    render(&s, &photo, &settings, &mut StageTimes::default()).unwrap()
                })
            });
        }
    }
    g.finish();
}

/// Alternating between two poses on one session, as a motion runs.
fn alternating(c: &mut Criterion, name: &str, a: &Scene, b: &Scene) {
    let settings = RenderSettings::default();
    let photo = a.load_photo().unwrap();
    let mut session = Session::start(a, &photo, &settings, &mut StageTimes::default()).unwrap();
    session.prepare_updates(&mut StageTimes::default());
    session.image_only();
    let mut forth = false;
    c.bench_function(name, |bench| {
        bench.iter(|| {
            forth = !forth;
            session
                .update(if forth { b } else { a }, &mut StageTimes::default())
                .unwrap()
        })
    });
}

fn updates(c: &mut Criterion) {
    let desk = scene("desk", "scene.toml");
    let (p3, p4) = (
        desk.with_motion_pose("box_slide", 3).unwrap(),
        desk.with_motion_pose("box_slide", 4).unwrap(),
    );
    alternating(c, "material_updates/desk_box_slide_3_4", &p3, &p4);
    // The chrome ball moved by about what the box moves between poses,
    // and its flat twin the same way.
    let step = p4.objects[0].pose.translate - p3.objects[0].pose.translate;
    for (file, name) in [
        ("scene.toml", "chrome_floor_step"),
        ("scene_flat.toml", "chrome_floor_step_flat"),
    ] {
        let here = scene("materials", file)
            .with_variant("chrome_floor")
            .unwrap();
        let mut there = here.clone();
        let k = there
            .objects
            .iter()
            .position(|o| o.name == "chrome")
            .unwrap();
        there.objects[k].pose.translate += step;
        alternating(c, &format!("material_updates/{name}"), &here, &there);
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = renders, updates
}
criterion_main!(benches);
