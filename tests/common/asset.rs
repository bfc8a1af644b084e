//! A glTF asset made like a real Blender export, written by the test or
//! bench that needs it (the repository keeps no heavy binary): a closed
//! surface of revolution (a bottle, a can, a round table) of a chosen
//! triangle count and size, with base-colour, metallic-roughness and normal
//! textures of a chosen resolution, a label band, metal rims, deep grooves
//! in the normal map, and nested node scales.
//!
//! Used as `#[path = "../tests/common/asset.rs"] mod asset;` from benches.

#![allow(dead_code)] // each test binary uses its own part of this module

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// What to make.
#[derive(Debug, Clone, Copy)]
pub struct AssetSpec {
    /// Roughly this many triangles (sides and both caps).
    pub triangles: usize,
    /// Width and height of each texture, texels.
    pub texture: u32,
    /// Largest diameter, metres.
    pub width: f64,
    /// Height, metres.
    pub height: f64,
    /// Grooves in the normal map tilting the shading normal this far from
    /// the surface's (degrees; 0: a flat normal map).
    pub groove_deg: f64,
    /// Grooves round the object (each 40% of its period wide).
    pub grooves: u32,
}

impl AssetSpec {
    /// A bottle-like prop of about 80k triangles with 2k textures.
    pub fn heavy_prop() -> AssetSpec {
        AssetSpec {
            triangles: 80_000,
            texture: 2048,
            width: 0.22,
            height: 0.45,
            groove_deg: 70.0,
            grooves: 48,
        }
    }
}

/// The profile's radius at height fraction `t` (0 bottom, 1 top), as a
/// fraction of the largest: a body, a shoulder and a neck.
fn radius(t: f64) -> f64 {
    let body = 1.0 - 0.08 * (2.0 * t - 1.0).powi(2);
    let shoulder = 0.5 * (1.0 + (((t - 0.72) * 18.0).tanh()));
    body * (1.0 - 0.45 * shoulder)
}

/// Writes `dir/NAME.gltf` with `NAME.bin` and three PNG textures beside it;
/// returns the glTF's path. The object stands on y = 0, centred on x = z = 0.
pub fn write_asset(dir: &Path, name: &str, spec: &AssetSpec) -> PathBuf {
    let segments = ((spec.triangles as f64 / 2.0).sqrt().round() as usize).max(8);
    let rings = ((spec.triangles.saturating_sub(2 * segments)) / (2 * segments)).max(2);
    let (mut positions, mut normals, mut uvs) = (Vec::new(), Vec::new(), Vec::new());
    let mut indices: Vec<u32> = Vec::new();
    // Nested node scales (0.5 then 2) as Blender writes them: the mesh is
    // stored at half size under a child node scaled by 2.
    let stored = 0.5;
    for j in 0..=rings {
        let t = j as f64 / rings as f64;
        let (r, dr) = (radius(t), (radius(t + 1e-4) - radius(t - 1e-4)) / 2e-4);
        let r = r * spec.width / 2.0;
        let slope = dr * spec.width / 2.0 / spec.height;
        for i in 0..=segments {
            let a = 2.0 * PI * i as f64 / segments as f64;
            let (s, c) = a.sin_cos();
            positions.push([r * c, t * spec.height, r * s].map(|v| (v * stored) as f32));
            let n = [c, -slope, s];
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            normals.push(n.map(|v| (v / l) as f32));
            uvs.push([i as f32 / segments as f32, 1.0 - t as f32]);
        }
    }
    let row = segments as u32 + 1;
    for j in 0..rings as u32 {
        for i in 0..segments as u32 {
            let (a, b) = (j * row + i, j * row + i + 1);
            let (c, d) = (a + row, b + row);
            indices.extend([a, c, b, b, c, d]);
        }
    }
    // Caps: a fan round a centre vertex at each end, facing out.
    for (t, ny) in [(0.0, -1.0f32), (1.0, 1.0)] {
        let centre = positions.len() as u32;
        positions.push([0.0, (t * spec.height * stored) as f32, 0.0]);
        normals.push([0.0, ny, 0.0]);
        uvs.push([0.5, 0.5]);
        let r = radius(t) * spec.width / 2.0;
        for i in 0..=segments {
            let a = 2.0 * PI * i as f64 / segments as f64;
            let (s, c) = a.sin_cos();
            positions.push([r * c, t * spec.height, r * s].map(|v| (v * stored) as f32));
            normals.push([0.0, ny, 0.0]);
            uvs.push([0.5 + 0.5 * c as f32, 0.5 + 0.5 * s as f32]);
        }
        for i in 0..segments as u32 {
            let (a, b) = (centre + 1 + i, centre + 2 + i);
            match ny > 0.0 {
                true => indices.extend([centre, b, a]),
                false => indices.extend([centre, a, b]),
            }
        }
    }
    write_textures(dir, name, spec);
    write_gltf(dir, name, &positions, &normals, &uvs, &indices)
}

/// The three textures: base colour (a printed label band with text-like
/// marks between plain glass-green ends), metallic-roughness (metal rims,
/// a glossy label) and the normal map's grooves.
fn write_textures(dir: &Path, name: &str, spec: &AssetSpec) {
    let n = spec.texture;
    let label = |v: f64| (0.38..0.68).contains(&v);
    let rim = |v: f64| !(0.06..0.94).contains(&v);
    let mut base = image::RgbImage::new(n, n);
    let mut mr = image::RgbImage::new(n, n);
    let mut normal = image::RgbImage::new(n, n);
    let tilt = spec.groove_deg.to_radians();
    for y in 0..n {
        let v = (y as f64 + 0.5) / n as f64;
        for x in 0..n {
            let u = (x as f64 + 0.5) / n as f64;
            // Text-like marks: cells of a grid lit by a hash of the cell.
            let cell = ((u * 96.0) as u64) * 131 + (v * 160.0) as u64;
            let mark = label(v) && (cell.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 61) < 3;
            let colour = match (label(v), mark) {
                (true, true) => [30, 24, 20],
                (true, false) => [232, 214, 180],
                _ => [40, 110, 60],
            };
            base.put_pixel(x, y, image::Rgb(colour));
            let (rough, metal) = match (rim(v), label(v)) {
                (true, _) => (0.25, 1.0),
                (false, true) => (0.35, 0.0),
                _ => (0.6, 0.0),
            };
            mr.put_pixel(
                x,
                y,
                image::Rgb([0, (rough * 255.0) as u8, (metal * 255.0) as u8]),
            );
            // V-shaped grooves round the object (stitching, a knurl): each
            // wall tilts the normal by `tilt`, one way then the other.
            let g = (u * spec.grooves as f64).fract();
            let across = match g {
                g if g < 0.2 => -tilt,
                g if g < 0.4 => tilt,
                _ => 0.0,
            };
            let t = [across.sin(), 0.0, across.cos()];
            normal.put_pixel(
                x,
                y,
                image::Rgb(t.map(|c| ((c * 0.5 + 0.5) * 255.0).round() as u8)),
            );
        }
    }
    base.save(dir.join(format!("{name}_base.png"))).unwrap();
    mr.save(dir.join(format!("{name}_mr.png"))).unwrap();
    normal.save(dir.join(format!("{name}_normal.png"))).unwrap();
}

fn write_gltf(
    dir: &Path,
    name: &str,
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    uvs: &[[f32; 2]],
    indices: &[u32],
) -> PathBuf {
    let mut bin: Vec<u8> = Vec::new();
    for p in positions.iter().chain(normals) {
        p.iter().for_each(|c| bin.extend(c.to_le_bytes()));
    }
    uvs.iter()
        .for_each(|t| t.iter().for_each(|c| bin.extend(c.to_le_bytes())));
    indices.iter().for_each(|i| bin.extend(i.to_le_bytes()));
    std::fs::write(dir.join(format!("{name}.bin")), &bin).unwrap();
    let (lo, hi) = positions
        .iter()
        .fold(([f32::MAX; 3], [f32::MIN; 3]), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1]), lo[2].min(p[2])],
                [hi[0].max(p[0]), hi[1].max(p[1]), hi[2].max(p[2])],
            )
        });
    let (nv, ni) = (positions.len(), indices.len());
    let (p, t) = (nv * 12, nv * 8);
    let gltf = format!(
        r#"{{
  "asset": {{ "version": "2.0", "generator": "arlux test asset" }},
  "scene": 0,
  "scenes": [{{ "nodes": [0] }}],
  "nodes": [
    {{ "name": "{name}", "scale": [0.5, 0.5, 0.5], "children": [1] }},
    {{ "name": "{name}_mesh", "mesh": 0, "scale": [4.0, 4.0, 4.0] }}],
  "meshes": [{{ "name": "{name}", "primitives": [{{
    "attributes": {{ "POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2 }},
    "indices": 3, "material": 0 }}] }}],
  "materials": [{{ "name": "{name}_material",
    "pbrMetallicRoughness": {{ "baseColorTexture": {{ "index": 0 }},
      "metallicRoughnessTexture": {{ "index": 1 }} }},
    "normalTexture": {{ "index": 2 }} }}],
  "textures": [
    {{ "source": 0, "sampler": 0 }}, {{ "source": 1, "sampler": 0 }}, {{ "source": 2, "sampler": 0 }}],
  "samplers": [{{ "magFilter": 9729, "minFilter": 9987 }}],
  "images": [
    {{ "uri": "{name}_base.png" }}, {{ "uri": "{name}_mr.png" }}, {{ "uri": "{name}_normal.png" }}],
  "buffers": [{{ "uri": "{name}.bin", "byteLength": {len} }}],
  "bufferViews": [
    {{ "buffer": 0, "byteOffset": 0, "byteLength": {p} }},
    {{ "buffer": 0, "byteOffset": {p}, "byteLength": {p} }},
    {{ "buffer": 0, "byteOffset": {o2}, "byteLength": {t} }},
    {{ "buffer": 0, "byteOffset": {o3}, "byteLength": {ib} }}],
  "accessors": [
    {{ "bufferView": 0, "componentType": 5126, "count": {nv}, "type": "VEC3",
       "min": [{}, {}, {}], "max": [{}, {}, {}] }},
    {{ "bufferView": 1, "componentType": 5126, "count": {nv}, "type": "VEC3" }},
    {{ "bufferView": 2, "componentType": 5126, "count": {nv}, "type": "VEC2" }},
    {{ "bufferView": 3, "componentType": 5125, "count": {ni}, "type": "SCALAR" }}]
}}"#,
        lo[0],
        lo[1],
        lo[2],
        hi[0],
        hi[1],
        hi[2],
        len = bin.len(),
        o2 = 2 * p,
        o3 = 2 * p + t,
        ib = ni * 4,
    );
    let file = dir.join(format!("{name}.gltf"));
    std::fs::write(&file, gltf).unwrap();
    file
}

/// Writes into `dir` the lounge (its room, lights and stool, linked from
/// `scenes/lounge`, without references) with two generated assets — an
/// 80k-triangle prop (disabled) and a 2 m wide round table of 20k
/// triangles — and three motions: `prop_walk` (the prop alone along the
/// stool's path), `wide_walk` (the table moving a little) and `stool_walk`
/// (the stool beside the still table). Returns the scene file's path.
pub fn lounge_with_assets(dir: &Path) -> PathBuf {
    let lounge = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/lounge");
    let geometry = dir.join("geometry");
    std::fs::create_dir_all(&geometry).unwrap();
    for f in ["room.obj", "furniture.obj", "stool.obj"] {
        std::os::unix::fs::symlink(lounge.join("geometry").join(f), geometry.join(f)).unwrap();
    }
    std::os::unix::fs::symlink(lounge.join("photo.exr"), dir.join("photo.exr")).unwrap();
    write_asset(&geometry, "prop", &AssetSpec::heavy_prop());
    let wide = AssetSpec {
        triangles: 20_000,
        texture: 1024,
        width: 2.0,
        height: 0.45,
        groove_deg: 0.0,
        grooves: 1,
    };
    write_asset(&geometry, "wide", &wide);
    let text = std::fs::read_to_string(lounge.join("scene.toml")).unwrap();
    // The room, lights and the stool; no references (not measured here).
    let cut = text.find("[[variant]]").unwrap_or(text.len());
    let path = "[[-2.0, 0.0, 1.5], [-1.26, 0.0, 1.36], [-0.52, 0.0, 1.22], \
                [0.22, 0.0, 1.08], [0.96, 0.0, 0.94]]";
    let scene = format!(
        r#"{room}
[[virtual]]
name = "prop"
mesh = "geometry/prop.gltf"
enabled = false

[[virtual]]
name = "wide"
mesh = "geometry/wide.gltf"
translate = [-0.6, 0.0, -0.9]

[[motion]]
name = "prop_walk"
object = "prop"
hide = ["stool", "wide"]
translations = {path}

[[motion]]
name = "wide_walk"
object = "wide"
hide = ["stool"]
translations = [[-0.6, 0.0, -0.9], [-0.5, 0.0, -0.85], [-0.4, 0.0, -0.8], [-0.3, 0.0, -0.75]]

[[motion]]
name = "stool_walk"
object = "stool"
translations = {path}
"#,
        room = &text[..cut],
    );
    let file = dir.join("scene.toml");
    std::fs::write(&file, scene).unwrap();
    file
}
