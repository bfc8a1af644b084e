//! `arlux info`: Describe a scene: surfaces, triangles, lights, objects, variants, motions, the photo's range.

use std::path::PathBuf;

use anyhow::Result;
use serde_json::json;

use arlux::scene::{Intensity, LightPosition, LightShape, Photo, Scene};

use crate::common::*;
use crate::timing::*;

/// Arguments of `arlux info`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    /// Apply this variant first.
    #[arg(long)]
    pub variant: Option<String>,
    /// Print a JSON report instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let path = args.scene.as_path();
    let variant = args.variant.as_deref();
    let as_json = args.json;
    // Every object's size is reported: every mesh is read.
    let scene = stage("load", || {
        let scene = load_showing(path, arlux::scene::Showing::Everything)?;
        match variant {
            Some(v) => Ok::<_, anyhow::Error>(scene.with_variant(v)?),
            None => Ok(scene),
        }
    })?;
    let names = scene.surface_names();
    let photo = match &scene.photo {
        Photo::Image(p) => {
            let img = stage("read photo", || read_photo(&scene))?;
            json!({ "image": rel(&scene, p), "range": stage("photo range", || photo_range(&img)) })
        }
        Photo::Brackets(bs) => json!({
            "brackets": bs.iter().map(|b| json!({ "image": rel(&scene, &b.image), "ev": b.ev })).collect::<Vec<_>>(),
        }),
    };
    stage("report", || info_report(&scene, &names, photo, as_json))
}

/// A light as JSON (numbers, its kinds named) and as a line of text.
fn light_report(scene: &Scene, l: &arlux::scene::Light) -> (serde_json::Value, String) {
    let (position, position_text) = match &l.position {
        LightPosition::Known(p) => (json!(p.to_array()), fmt3(*p)),
        LightPosition::FromShadows(c) => (
            json!({ "shadow_lines": c.lines.len(), "shadow_planes": c.planes.len() }),
            format!(
                "from {} shadow lines and {} shadow planes",
                c.lines.len(),
                c.planes.len()
            ),
        ),
    };
    let (shape, shape_text) = match l.shape {
        LightShape::Point => (json!({ "kind": "point" }), "point".to_string()),
        LightShape::Rect { u, v } => (
            json!({ "kind": "rect", "u": u.to_array(), "v": v.to_array(), "u_m": u.length(), "v_m": v.length() }),
            format!("rect {:.3} x {:.3} m", u.length(), v.length()),
        ),
    };
    let (intensity, intensity_text) = match &l.intensity {
        Intensity::Uniform(rgb) => (
            json!({ "kind": "uniform", "rgb": rgb.to_array() }),
            format!("uniform {}", fmt3(*rgb)),
        ),
        Intensity::Lambertian { rgb, normal } => (
            json!({ "kind": "lambertian", "rgb": rgb.to_array(), "normal": normal.to_array() }),
            format!("lambertian {}", fmt3(*rgb)),
        ),
        Intensity::Spot {
            rgb,
            direction,
            beam_deg,
            cutoff_deg,
        } => (
            json!({ "kind": "spot", "rgb": rgb.to_array(), "direction": direction.to_array(), "beam_deg": beam_deg, "cutoff_deg": cutoff_deg }),
            format!("spot {} beam {beam_deg}° cutoff {cutoff_deg}°", fmt3(*rgb)),
        ),
        Intensity::Ies { file, rgb, .. } => (
            json!({ "kind": "ies", "file": rel(scene, file), "rgb": rgb.to_array() }),
            format!("ies {} x {}", rel(scene, file), fmt3(*rgb)),
        ),
        Intensity::Reconstruct => (
            json!({ "kind": "reconstruct" }),
            "reconstruct from the photo".to_string(),
        ),
    };
    let line = format!(
        "{:<12} {:<7} scale {:<4} at {position_text}  {shape_text}  {intensity_text}",
        l.name,
        if l.real { "real" } else { "virtual" },
        l.scale
    );
    (
        json!({ "name": l.name, "real": l.real, "scale": l.scale, "position": position, "shape": shape, "intensity": intensity }),
        line,
    )
}

fn info_report(
    scene: &Scene,
    names: &[String],
    photo: serde_json::Value,
    as_json: bool,
) -> Result<()> {
    let surfaces: Vec<_> = scene
        .surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let known = scene.reflectances.iter().find(|k| k.surface == i).map(|k| k.rgb.to_array());
            json!({ "id": i, "name": s.name, "triangles": s.triangles.len(), "mesh": rel(scene, &s.mesh), "known_reflectance": known })
        })
        .collect();
    let (lights, light_lines): (Vec<_>, Vec<_>) =
        scene.lights.iter().map(|l| light_report(scene, l)).unzip();
    let objects: Vec<_> = scene
        .objects
        .iter()
        .map(|o| {
            // Where it stands, as placed: what a user lifts, turns or scales by.
            let (lo, hi) = arlux::geometry::bounds(
                (o.surfaces.iter())
                    .flat_map(|s| s.triangles.iter().flatten())
                    .map(|&p| o.pose.apply(p).as_dvec3()),
            );
            json!({
                "name": o.name, "mesh": rel(scene, &o.mesh), "enabled": o.enabled,
                "bounds": { "min": lo.to_array(), "max": hi.to_array(), "size_m": (hi - lo).to_array() },
                // The floor area it covers, what `stand` and `serve` put down.
                "footprint": { "x": [lo.x, hi.x], "z": [lo.z, hi.z], "centre": [0.5 * (lo.x + hi.x), 0.5 * (lo.z + hi.z)], "area_m2": (hi.x - lo.x) * (hi.z - lo.z) },
                "triangles": o.surfaces.iter().map(|s| s.triangles.len()).sum::<usize>(),
                "surfaces": o.surfaces.iter().map(|s| json!({
                    "name": s.name, "rgb": s.rgb.to_array(),
                    "material": s.material.as_ref().map(|m| m.material.describe()),
                })).collect::<Vec<_>>(),
                "translate": o.pose.translate.to_array(), "rotate_deg": o.pose.euler_xyz_deg(),
                "rotation": (0..3).map(|i| o.pose.rotation.row(i).to_array()).collect::<Vec<_>>(), "scale": o.pose.scale,
            })
        })
        .collect();
    let variants: Vec<_> = scene
        .variants
        .iter()
        .map(|v| {
            json!({
                "name": v.name,
                "lights": v.lights.iter().map(|(l, s)| json!({ "light": scene.lights[*l].name, "scale": s })).collect::<Vec<_>>(),
                "moved_lights": v.light_positions.iter().map(|(l, p)| json!({ "light": scene.lights[*l].name, "position": p.to_array() })).collect::<Vec<_>>(),
                "objects": v.objects.iter().map(|(o, _)| scene.objects[*o].name.clone()).collect::<Vec<_>>(),
                "hide": v.hide_objects.iter().map(|o| scene.objects[*o].name.clone())
                    .chain(v.hide_lights.iter().map(|l| scene.lights[*l].name.clone())).collect::<Vec<_>>(),
                "reference": v.reference.as_ref().map(|r| rel(scene, r)),
            })
        })
        .collect();
    let motions: Vec<_> = scene
        .motions
        .iter()
        .map(|m| {
            json!({ "name": m.name, "object": scene.objects[m.object].name, "poses": m.translations.len(), "references": m.references.len() })
        })
        .collect();
    let c = &scene.camera;
    let report = json!({
        "name": scene.name, "file": scene.file.display().to_string(),
        "camera": { "width": c.width, "height": c.height, "position": c.position.to_array(), "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy },
        "photo": photo, "surfaces": surfaces, "triangles": scene.triangle_count(), "lights": lights,
        "virtual_objects": objects, "variants": variants, "motions": motions, "warnings": scene.warnings,
        "all_surface_names": names,
    });
    print_report(
        &InfoReport {
            report,
            light_lines,
        },
        as_json,
    )
}

/// `arlux info`'s report: the scene as JSON; its text is read from that
/// JSON (the lights from their own lines).
#[derive(serde::Serialize)]
struct InfoReport {
    #[serde(flatten)]
    report: serde_json::Value,
    #[serde(skip)]
    light_lines: Vec<String>,
}

impl Report for InfoReport {
    const COMMAND: &'static str = "info";

    fn text(&self) -> Vec<String> {
        let report = &self.report;
        let list = |key: &str| report[key].as_array().cloned().unwrap_or_default();
        let str_of = |v: &serde_json::Value| v.as_str().unwrap_or("").to_string();
        let (surfaces, objects, variants, motions) = (
            list("surfaces"),
            list("virtual_objects"),
            list("variants"),
            list("motions"),
        );
        let c = &report["camera"];
        let f2 = |v: &serde_json::Value| v.as_f64().unwrap_or(0.0);
        let mut out = vec![
            format!(
                "scene '{}' ({})",
                str_of(&report["name"]),
                str_of(&report["file"])
            ),
            format!(
                "camera: {}x{} px, fx {:.2} fy {:.2}, principal point ({:.1}, {:.1})",
                c["width"],
                c["height"],
                f2(&c["fx"]),
                f2(&c["fy"]),
                f2(&c["cx"]),
                f2(&c["cy"])
            ),
        ];
        out.push(match &report["photo"]["range"] {
            serde_json::Value::Null => format!("photo: {}", report["photo"]),
            r => format!(
                "photo: {} {}x{}, min {} max {} mean {:.5}, dynamic range {}:1",
                str_of(&report["photo"]["image"]),
                r["width"],
                r["height"],
                r["min"],
                r["max"],
                f2(&r["mean"]),
                r["dynamic_range"]
                    .as_f64()
                    .map_or("n/a".into(), |d| format!("{d:.0}")),
            ),
        });
        out.push(format!(
            "real surfaces: {} ({} triangles)",
            surfaces.len(),
            report["triangles"]
        ));
        for s in &surfaces {
            let known = s["known_reflectance"]
                .as_array()
                .map(|k| {
                    format!(
                        "  known reflectance {}",
                        serde_json::Value::Array(k.clone())
                    )
                })
                .unwrap_or_default();
            out.push(format!(
                "  {:>3} {:<16} {:>6} triangles  {}{}",
                s["id"],
                str_of(&s["name"]),
                s["triangles"],
                str_of(&s["mesh"]),
                known
            ));
        }
        out.push(format!("lights: {}", self.light_lines.len()));
        out.extend(self.light_lines.iter().map(|l| format!("  {l}")));
        out.push(format!("virtual objects: {}", objects.len()));
        out.extend(objects.iter().flat_map(object_lines));
        out.push(format!("variants: {}", variants.len()));
        for v in &variants {
            out.push(format!(
                "  {:<20} reference {}",
                str_of(&v["name"]),
                v["reference"].as_str().unwrap_or("none")
            ));
        }
        out.push(format!("motions: {}", motions.len()));
        for m in &motions {
            out.push(format!(
                "  {:<20} moves {} through {} poses ({} references)",
                str_of(&m["name"]),
                str_of(&m["object"]),
                m["poses"],
                m["references"]
            ));
        }
        out
    }
}

/// An object's lines in `info`'s text: placement, size, footprint, surfaces.
fn object_lines(o: &serde_json::Value) -> Vec<String> {
    let str_of = |v: &serde_json::Value| v.as_str().unwrap_or("").to_string();
    let mut out = Vec::new();
    out.push(format!(
        "  {:<12} {} triangles, {}, at {} rotated {}° (about x, y, z)",
        str_of(&o["name"]),
        o["triangles"],
        if o["enabled"].as_bool().unwrap_or(false) {
            "enabled"
        } else {
            "disabled"
        },
        o["translate"],
        o["rotate_deg"]
    ));
    let at = |k: &str, i: usize| o["bounds"][k][i].as_f64().unwrap_or(f64::NAN);
    out.push(format!(
        "    size {:.3} × {:.3} × {:.3} m (x, y, z) as placed; from y = {:.3} to {:.3}",
        at("size_m", 0),
        at("size_m", 1),
        at("size_m", 2),
        at("min", 1),
        at("max", 1)
    ));
    let f = |k: &str, i: usize| o["footprint"][k][i].as_f64().unwrap_or(f64::NAN);
    out.push(format!(
        "    footprint x {:.3} to {:.3}, z {:.3} to {:.3} m (centre {:.3}, {:.3}; {:.3} m²)",
        f("x", 0),
        f("x", 1),
        f("z", 0),
        f("z", 1),
        f("centre", 0),
        f("centre", 1),
        o["footprint"]["area_m2"].as_f64().unwrap_or(f64::NAN)
    ));
    for s in o["surfaces"].as_array().into_iter().flatten() {
        let material = match s["material"].as_str() {
            Some(m) => format!("material {m}"),
            None => format!("diffuse {}", s["rgb"]),
        };
        out.push(format!("    {}: {material}", str_of(&s["name"])));
    }
    out
}
