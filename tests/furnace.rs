//! A furnace-like case with an analytic answer. Inside a sphere of radius
//! R and reflectance ρ lit by an isotropic point light of intensity I at
//! its centre, every point of the wall receives E = I/R² directly, and
//! (every pair of a sphere's points seeing each other with the same form
//! factor dA/4πR²) the same again and again from the wall: its radiosity
//! is uniform, B = ρE/(1 − ρ), and so is the photo of it, B/π. A white
//! box of albedo a placed in it: the face turned to the light sees the
//! light and the lit wall only (its shadow falls behind it), so its
//! radiance is a/π · (I cosθ/d² + B) at every point, up to the little the
//! box changes the wall. The face's pixels, shaded per pixel by default and
//! by rounds of `--samples`, lie within 1% of it at every count (measured:
//! +0.22%): the light arriving from a uniform wall is the same along every
//! ray, so the estimate has no variance, and no bias beyond the model's.

mod common;

use std::f64::consts::PI;
use std::path::Path;

use glam::DVec3;

use arlux::image_io::{ExrLayer, Image, write_exr};
use arlux::model::StageTimes;
use arlux::render::{RenderSettings, render};
use arlux::scene::Scene;

const R: f64 = 2.0;
const RHO: f64 = 0.5;
const I: f64 = PI;
const ALBEDO: f64 = 0.8;
/// The box (whitebox's cube: 0.22 m, its origin at the bottom's centre).
const BOX_AT: [f64; 3] = [0.8, -0.11, 0.0];
const HALF: f64 = 0.11;

/// A UV sphere of radius R about the origin, wound to face its inside, in
/// two open halves (a closed surface would be a solid, lit from outside).
fn sphere_obj(rings: usize, segments: usize) -> String {
    let mut s = String::new();
    for i in 0..=rings {
        let theta = PI * i as f64 / rings as f64;
        for j in 0..segments {
            let phi = 2.0 * PI * j as f64 / segments as f64;
            let p = DVec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ) * R;
            s += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
    }
    let at = |i: usize, j: usize| i * segments + j % segments + 1;
    for i in 0..rings {
        if i == 0 || i == rings / 2 {
            s += if i == 0 { "o top\n" } else { "o bottom\n" };
        }
        for j in 0..segments {
            let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
            // Counter-clockwise seen from inside.
            if i > 0 {
                s += &format!("f {a} {b} {c}\n");
            }
            if i + 1 < rings {
                s += &format!("f {a} {c} {d}\n");
            }
        }
    }
    s
}

fn furnace(dir: &Path) -> Scene {
    std::fs::create_dir_all(dir.join("geometry")).unwrap();
    std::fs::write(dir.join("geometry/sphere.obj"), sphere_obj(12, 24)).unwrap();
    let cube = common::scene_dir("whitebox").join("geometry/cube.obj");
    std::fs::copy(cube, dir.join("geometry/cube.obj")).unwrap();
    let (w, h) = (160, 120);
    let wall = (RHO * I / (R * R) / (1.0 - RHO) / PI) as f32;
    let photo = Image {
        width: w,
        height: h,
        pixels: vec![glam::Vec3::splat(wall); (w * h) as usize],
    };
    write_exr(&dir.join("photo.exr"), w, h, &[ExrLayer::Rgb("", &photo)]).unwrap();
    let [bx, by, bz] = BOX_AT;
    let text = format!(
        r#"name = "furnace"

[camera]
width = {w}
height = {h}
position = [-0.6, 0.2, 0.9]
look_at = [{bx}, 0.0, {bz}]
up = [0.0, 1.0, 0.0]
fov_y_deg = 40.0

[photo]
image = "photo.exr"

[[real]]
mesh = "geometry/sphere.obj"

[[reflectance]]
surface = "top"
rgb = [{RHO}, {RHO}, {RHO}]

[[reflectance]]
surface = "bottom"
rgb = [{RHO}, {RHO}, {RHO}]

[[light]]
name = "centre"
real = true
position = [0.0, 0.0, 0.0]
intensity = {{ uniform = [{I}, {I}, {I}] }}

[[virtual]]
name = "box"
mesh = "geometry/cube.obj"
rgb = [{ALBEDO}, {ALBEDO}, {ALBEDO}]
translate = [{bx}, {by}, {bz}]
"#
    );
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    Scene::load(dir.join("scene.toml")).unwrap()
}

/// Pixels well inside the box's face turned to the light (x = box − half),
/// with the analytic radiance at each.
fn lit_face(scene: &Scene) -> Vec<(usize, f64)> {
    let cam = &scene.camera;
    let x0 = BOX_AT[0] - HALF;
    let mut out = Vec::new();
    for row in 0..cam.height {
        for col in 0..cam.width {
            let ray = cam.pixel_ray(col, row);
            if ray.direction.x <= 0.0 {
                continue;
            }
            let t = (x0 - ray.origin.x) / ray.direction.x;
            let p = ray.origin + ray.direction * t;
            let (y, z) = (p.y - (BOX_AT[1] + HALF), p.z - BOX_AT[2]);
            // A pixel's width of margin from the face's edges.
            if y.abs() > HALF - 0.015 || z.abs() > HALF - 0.015 {
                continue;
            }
            let to_light = -p;
            let d2 = to_light.length_squared();
            let cos = to_light.normalize().dot(DVec3::new(-1.0, 0.0, 0.0));
            let b = RHO * I / (R * R) / (1.0 - RHO);
            let radiance = ALBEDO / PI * (I * cos / d2 + b);
            out.push(((row * cam.width + col) as usize, radiance));
        }
    }
    out
}

/// The mean relative error of the face's pixels and its pixels' RMS
/// relative error, at `samples` rounds.
fn errors(scene: &Scene, photo: &Image, face: &[(usize, f64)], samples: u32) -> (f64, f64) {
    let mut settings = RenderSettings::default();
    settings.residual.samples = samples;
    let out = render(scene, photo, &settings, &mut StageTimes::default()).unwrap();
    let rel: Vec<f64> = face
        .iter()
        .map(|&(i, expect)| (out.composite.image.pixels[i].x as f64 - expect) / expect)
        .collect();
    let mean = rel.iter().sum::<f64>() / rel.len() as f64;
    let rms = (rel.iter().map(|r| r * r).sum::<f64>() / rel.len() as f64).sqrt();
    (mean, rms)
}

#[test]
fn a_white_box_in_a_uniformly_lit_sphere_converges_to_its_analytic_radiance() {
    let dir = tempfile::tempdir().unwrap();
    let scene = furnace(dir.path());
    let photo = scene.load_photo().unwrap();
    let face = lit_face(&scene);
    assert!(face.len() > 300, "{} face pixels", face.len());
    let (mean_0, rms_0) = errors(&scene, &photo, &face, 0);
    let (mean_4, rms_4) = errors(&scene, &photo, &face, 4);
    let (mean_64, rms_64) = errors(&scene, &photo, &face, 64);
    println!(
        "relative error, mean and rms over {} pixels: default {mean_0:+.4} {rms_0:.4}; 4 rounds {mean_4:+.4} {rms_4:.4}; 64 rounds {mean_64:+.4} {rms_64:.4}",
        face.len()
    );
    // The light arriving from a uniform wall is the same along every ray:
    // the rounds' estimate has no variance here, only what the model and
    // the box's own change to the wall leave.
    for (rounds, mean, rms) in [(4, mean_4, rms_4), (64, mean_64, rms_64)] {
        assert!(
            mean.abs() < 0.01,
            "{rounds} rounds: mean relative error {mean}"
        );
        assert!(rms < 0.01, "{rounds} rounds: rms relative error {rms}");
    }
}
