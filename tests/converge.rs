//! Renders that converge (`--samples`): rounds of per-pixel samples over
//! the kept solution lower the error against the truth, their noise
//! estimate falls as 1/sqrt(rounds) and tells the error it leaves, and the
//! image is the same bit for bit on any thread count, in bands and tiles.

mod common;

use std::path::Path;

use arlux::image_io::{Image, read_image};
use common::{arlux_json, arlux_ok};

/// `arlux render` of desk `box_floor_a` into `out` with `extra` flags; its report.
fn render(out: &Path, extra: &[&str]) -> serde_json::Value {
    let scene = common::scene_dir("desk").join("scene.toml");
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "--variant",
        "box_floor_a",
        "--json",
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    arlux_json(&args)
}

fn skill(report: &serde_json::Value) -> f64 {
    report["skill"]["skill"].as_f64().unwrap()
}

fn bits(image: &Image) -> Vec<[u32; 3]> {
    (image.pixels.iter())
        .map(|p| p.to_array().map(f32::to_bits))
        .collect()
}

#[test]
fn more_rounds_lower_the_error_and_the_noise_as_one_over_root_rounds() {
    let dir = tempfile::tempdir().unwrap();
    let default = render(&dir.path().join("default.exr"), &[]);
    assert!(default["samples"].is_null(), "{}", default["samples"]);
    let mut last: Option<(f64, f64)> = None;
    for rounds in [2u32, 8, 32] {
        let n = rounds.to_string();
        let report = render(&dir.path().join(format!("s{n}.exr")), &["--samples", &n]);
        let s = &report["samples"];
        assert_eq!(s["rounds"], rounds, "{s}");
        let (k, noise) = (skill(&report), s["noise_rms"].as_f64().unwrap());
        assert!(noise.is_finite() && noise > 0.0, "{s}");
        if let Some((k0, noise0)) = last {
            // Four times the rays: half the noise (the rays are
            // stratified, so a little better than half is allowed).
            let ratio = noise0 / noise;
            assert!(
                (1.7..=2.6).contains(&ratio),
                "{rounds} rounds: the noise fell {ratio:.2}x from a quarter of them ({noise0:.3e} -> {noise:.3e})"
            );
            assert!(
                k >= k0 - 0.002,
                "{rounds} rounds: skill {k:.4} after {k0:.4}"
            );
        }
        last = Some((k, noise));
    }
    let (k, _) = last.unwrap();
    // The default's 0.926 (its error mostly the box's interpolated light
    // and its contact shadow); measured 0.973 at 32 rounds.
    assert!(
        k >= skill(&default) + 0.03 && k >= 0.965,
        "32 rounds: skill {k:.4}, the default {:.4}",
        skill(&default)
    );
}

#[test]
fn the_noise_layer_tells_the_error_few_rounds_leave() {
    let dir = tempfile::tempdir().unwrap();
    let aov = dir.path().join("aov");
    let few = dir.path().join("few.exr");
    let many = dir.path().join("many.exr");
    render(&few, &["--samples", "2", "--aov", aov.to_str().unwrap()]);
    render(&many, &["--samples", "64"]);
    let (few, many) = (read_image(&few).unwrap(), read_image(&many).unwrap());
    // No round's estimate leaves a pixel negative or not finite (a
    // correction below the interpolated light is clamped where it would).
    for (name, image) in [("2 rounds", &few), ("64 rounds", &many)] {
        let bad = (image.pixels.iter())
            .filter(|p| !p.is_finite() || p.min_element() < 0.0)
            .count();
        assert_eq!(bad, 0, "{name}: {bad} pixels negative or not finite");
    }
    let noise = read_image(&aov.join("noise.exr")).unwrap();
    // A one-channel layer reads back grey.
    let sd: Vec<f64> = noise.pixels.iter().map(|p| p.x as f64).collect();
    assert!(sd.iter().all(|v| v.is_finite() && *v >= 0.0));
    let sampled: Vec<usize> = (0..sd.len()).filter(|&i| sd[i] > 0.0).collect();
    assert!(sampled.len() > 10_000, "{} pixels sampled", sampled.len());
    // On the pixels sampled, the 2-round image's distance from the
    // 64-round one (whose own noise is 1/32 of the squares) is what its
    // noise layer says, to within the error of an estimate from few rays.
    let lum = |p: glam::Vec3| (0.2126 * p.x + 0.7152 * p.y + 0.0722 * p.z) as f64;
    let (mut measured, mut estimated) = (0.0, 0.0);
    for &i in &sampled {
        measured += (lum(few.pixels[i]) - lum(many.pixels[i])).powi(2);
        estimated += sd[i] * sd[i];
    }
    // And no bias: the rounds estimate what the solution misses without
    // a systematic part, so the few rounds' signed differences from the
    // many average out, within three standard errors of their mean.
    let signed: f64 = (sampled.iter())
        .map(|&i| lum(few.pixels[i]) - lum(many.pixels[i]))
        .sum::<f64>();
    let n = sampled.len() as f64;
    let standard_error = estimated.sqrt() / n;
    assert!(
        (signed / n).abs() < 3.0 * standard_error,
        "mean signed difference {:.2e} against a standard error of {standard_error:.2e}",
        signed / n
    );
    let ratio = (measured / estimated).sqrt();
    assert!(
        (0.4..=1.6).contains(&ratio),
        "measured error / estimated noise = {ratio:.3} over {} pixels",
        sampled.len()
    );
}

#[test]
fn rounds_give_the_same_image_on_any_thread_count_in_bands_and_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name);
    let whole = render(&path("whole.exr"), &["--samples", "4"]);
    assert_eq!(whole["bands"]["count"], 1);
    let banded = render(&path("bands.exr"), &["--samples", "4", "--memory", "64M"]);
    assert!(banded["bands"]["count"].as_u64().unwrap() >= 6);
    // (Their rays differ: a band also traces its neighbours' margin rows.)
    assert_eq!(whole["samples"]["rounds"], banded["samples"]["rounds"]);
    assert!(
        std::fs::read(path("whole.exr")).unwrap() == std::fs::read(path("bands.exr")).unwrap(),
        "the banded render's EXR differs from the whole one's"
    );
    // Tiles whose edges cross the box and its shadow, merged.
    let scene = common::scene_dir("desk").join("scene.toml");
    let mut tiles = Vec::new();
    for (i, w) in [
        ["0", "0.37", "0", "0.61"],
        ["0.37", "1", "0", "0.61"],
        ["0", "0.71", "0.61", "1"],
        ["0.71", "1", "0.61", "1"],
    ]
    .iter()
    .enumerate()
    {
        let tile = path(&format!("tile{i}.exr")).display().to_string();
        let mut args = vec![
            "render",
            scene.to_str().unwrap(),
            "--variant",
            "box_floor_a",
            "--samples",
            "4",
            "-o",
            &tile,
            "--crop",
        ];
        args.extend(w);
        arlux_ok(&args);
        tiles.push(tile);
    }
    let merged = path("merged.exr").display().to_string();
    let mut args = vec!["merge", "-o", &merged];
    args.extend(tiles.iter().map(String::as_str));
    arlux_ok(&args);
    let (a, b) = (
        read_image(&path("whole.exr")).unwrap(),
        read_image(Path::new(&merged)).unwrap(),
    );
    let differ = (bits(&a).iter().zip(bits(&b)))
        .filter(|(x, y)| *x != y)
        .count();
    assert_eq!(differ, 0, "{differ} pixels of the merged tiles differ");

    // One thread and two, in the library.
    let base = common::desk();
    let scene = base.with_variant("box_floor_a").unwrap();
    let photo = scene.load_photo().unwrap();
    let settings = arlux::settings::RenderOptions {
        samples: 4,
        ..Default::default()
    };
    let arlux::settings::Method::Pda(settings) = settings.resolve().unwrap() else {
        panic!("the pixel path")
    };
    let one = common::image_on_threads(&scene, &photo, &settings, 1);
    let two = common::image_on_threads(&scene, &photo, &settings, 2);
    assert!(bits(&one) == bits(&two), "1 and 2 threads differ");
    assert!(
        bits(&one) == bits(&a),
        "the library's image is not the CLI's"
    );
}

#[test]
fn a_motion_with_rounds_updates_to_the_image_a_full_render_of_the_pose_gives() {
    use arlux::model::StageTimes;
    use arlux::render::{Session, render};
    let base = common::desk();
    let first = base.with_motion_pose("box_slide", 0).unwrap();
    let photo = first.load_photo().unwrap();
    let mut settings = arlux::render::RenderSettings::default();
    settings.residual.samples = 2;
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    for pose in [1, 4] {
        let scene = base.with_motion_pose("box_slide", pose).unwrap();
        session.update(&scene, &mut StageTimes::default()).unwrap();
        let full = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let rounds = full.residual.map(|r| r.rounds);
        assert_eq!(rounds, Some(2));
        let differ = (bits(&session.composite.image).iter())
            .zip(bits(&full.composite.image))
            .filter(|(a, b)| **a != *b)
            .count();
        assert_eq!(
            differ, 0,
            "pose {pose}: {differ} pixels differ from a full render"
        );
    }
}

#[test]
fn a_time_budget_reports_its_rounds_and_samples_reproduce_them() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name);
    for (name, extra) in [("whole", &[][..]), ("bands", &["--memory", "64M"][..])] {
        let mut args = vec!["--time", "1.5"];
        args.extend(extra);
        let timed = render(&path(&format!("{name}-timed.exr")), &args);
        let rounds = timed["samples"]["rounds"].as_u64().unwrap();
        assert!(rounds >= 1, "{name}: {}", timed["samples"]);
        let n = rounds.to_string();
        let mut args = vec!["--samples", n.as_str()];
        args.extend(extra);
        let again = render(&path(&format!("{name}-samples.exr")), &args);
        assert_eq!(again["samples"]["rounds"], rounds);
        // (The files' headers differ: each records the settings it was given.)
        let read = |k: &str| bits(&read_image(&path(&format!("{name}-{k}.exr"))).unwrap());
        assert!(
            read("timed") == read("samples"),
            "{name}: --time's image is not --samples {rounds}'s"
        );
    }
}

#[test]
fn rounds_stay_finite_with_a_lamp_a_millimetre_from_the_floor_beside_the_box() {
    use arlux::scene::LightPosition;
    let base = common::desk();
    let mut scene = base.with_variant("box_floor_a").unwrap();
    // The desk's virtual bulb switched on 1 mm above the floor, 5 cm from
    // the box: its light on the floor and the box spans orders of magnitude.
    let bulb = scene.light_index("bulb").unwrap();
    scene.lights[bulb].position = LightPosition::Known(glam::DVec3::new(0.6, 0.001, -0.2));
    scene.lights[bulb].scale = 1.0;
    scene.check_light_clearance().unwrap();
    let photo = scene.load_photo().unwrap();
    let mut settings = arlux::render::RenderSettings::default();
    settings.residual.samples = 4;
    let out = arlux::render::render(
        &scene,
        &photo,
        &settings,
        &mut arlux::model::StageTimes::default(),
    )
    .unwrap();
    assert_eq!(out.residual.map(|r| r.rounds), Some(4));
    let c = &out.composite;
    for (name, image) in [
        ("image", &c.image),
        ("direct", &c.direct),
        ("indirect", &c.indirect),
    ] {
        let bad = (image.pixels.iter())
            .filter(|p| !p.is_finite() || p.min_element() < 0.0)
            .count();
        assert_eq!(bad, 0, "{name}: {bad} pixels negative or not finite");
    }
    assert!(c.noise.iter().all(|n| n.is_finite() && *n >= 0.0));
}
