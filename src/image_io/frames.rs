//! EXR frames as a compositor and a render farm take them: a data window
//! inside the display window (a crop or a tile of the frame), the camera's
//! standard attributes (`worldToCamera`, `worldToNDC`), the run's settings,
//! and tiles merged back into the whole frame.
//!
//! The `exr` crate does the encoding; this module decides what goes in.

use std::path::{Path, PathBuf};

use exr::prelude::{self as x, ReadChannels, ReadLayers, WritableImage};

use super::{ExrLayer, write_atomic};
use crate::camera::Camera;
use crate::error::{Error, Result};

/// A rectangle of pixels, columns `x0..x1` and rows `y0..y1`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PixelRect {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl PixelRect {
    /// This rectangle grown by `margin` pixels on every side, within a
    /// `width` × `height` image.
    pub fn grown(&self, margin: u32, width: u32, height: u32) -> PixelRect {
        PixelRect {
            x0: self.x0.saturating_sub(margin),
            y0: self.y0.saturating_sub(margin),
            x1: (self.x1 + margin).min(width),
            y1: (self.y1 + margin).min(height),
        }
    }

    pub fn full(width: u32, height: u32) -> PixelRect {
        PixelRect {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    pub fn contains(&self, x: u32, y: u32) -> bool {
        (self.x0..self.x1).contains(&x) && (self.y0..self.y1).contains(&y)
    }

    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }

    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }

    pub fn pixel_count(&self) -> usize {
        self.width() as usize * self.height() as usize
    }

    /// The rectangle's values of a full-frame, row-major plane.
    pub fn cut<T: Copy>(&self, plane: &[T], frame_width: u32) -> Vec<T> {
        let w = frame_width as usize;
        (self.y0..self.y1)
            .flat_map(|y| {
                let row = y as usize * w;
                plane[row + self.x0 as usize..row + self.x1 as usize]
                    .iter()
                    .copied()
            })
            .collect()
    }
}

/// A crop window as pbrt gives it: fractions of the frame's width
/// (`x0..x1`) and height (`y0..y1`, from the top).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CropWindow {
    pub x0: f64,
    pub x1: f64,
    pub y0: f64,
    pub y1: f64,
}

impl CropWindow {
    /// Each pair must satisfy 0 ≤ start < end ≤ 1.
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (axis, a, b) in [("x", self.x0, self.x1), ("y", self.y0, self.y1)] {
            if !((0.0..1.0).contains(&a) && a < b && b <= 1.0) {
                return Err(format!(
                    "{axis}0 {a} and {axis}1 {b} must satisfy 0 <= {axis}0 < {axis}1 <= 1 (fractions of the frame)"
                ));
            }
        }
        Ok(())
    }

    /// The pixels the window holds: columns ⌈w·x0⌉ to ⌈w·x1⌉ (exclusive),
    /// likewise rows, as pbrt rounds, so that windows sharing an edge tile
    /// the frame with no pixel twice or missing. `None` when it holds none.
    pub fn pixels(&self, width: u32, height: u32) -> Option<PixelRect> {
        let at = |f: f64, n: u32| ((f * n as f64).ceil() as u32).min(n);
        let r = PixelRect {
            x0: at(self.x0, width),
            x1: at(self.x1, width),
            y0: at(self.y0, height),
            y1: at(self.y1, height),
        };
        (r.x0 < r.x1 && r.y0 < r.y1).then_some(r)
    }
}

/// What an EXR carries besides its pixels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExrMeta {
    /// The pixels written (the data window); `None`: the whole frame.
    pub window: Option<PixelRect>,
    /// OpenEXR's `worldToCamera` and `worldToNDC` (row vectors multiplied
    /// on the left, as Imath does).
    pub world_to_camera: Option<[f32; 16]>,
    pub world_to_ndc: Option<[f32; 16]>,
    /// The text attribute `arlux`: the run's scene, variant and settings.
    pub arlux: Option<String>,
}

impl ExrMeta {
    /// The camera's standard attributes. Camera space is OpenEXR's (and
    /// RenderMan's): x right, y up, z along the view; NDC runs from (0, 0)
    /// at the display window's top left to (1, 1) at its bottom right.
    pub fn with_camera(mut self, camera: &Camera) -> ExrMeta {
        let (r, u, f, p) = (camera.right, camera.up, camera.forward, camera.position);
        let to_camera = [
            [r.x, u.x, f.x, 0.0],
            [r.y, u.y, f.y, 0.0],
            [r.z, u.z, f.z, 0.0],
            [-p.dot(r), -p.dot(u), -p.dot(f), 1.0],
        ];
        let (w, h) = (camera.width as f64, camera.height as f64);
        // (X, Y, Z, 1) in camera space → (x·Z, y·Z, Z, Z) with x, y in NDC.
        let projection = [
            [camera.fx / w, 0.0, 0.0, 0.0],
            [0.0, -camera.fy / h, 0.0, 0.0],
            [camera.cx / w, camera.cy / h, 1.0, 1.0],
            [0.0, 0.0, 0.0, 0.0],
        ];
        let mut to_ndc = [[0.0; 4]; 4];
        for (i, row) in to_ndc.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..4).map(|k| to_camera[i][k] * projection[k][j]).sum();
            }
        }
        let flat = |m: [[f64; 4]; 4]| {
            let mut out = [0.0f32; 16];
            for (o, v) in out.iter_mut().zip(m.iter().flatten()) {
                *o = *v as f32;
            }
            out
        };
        self.world_to_camera = Some(flat(to_camera));
        self.world_to_ndc = Some(flat(to_ndc));
        self
    }
}

/// How arlux encodes every EXR it writes (lossless, scan lines top down).
fn encoding() -> x::Encoding {
    x::Encoding {
        line_order: x::LineOrder::Increasing,
        ..x::Encoding::FAST_LOSSLESS
    }
}

/// The layer attributes `meta` asks for.
fn attributes(meta: &ExrMeta) -> x::LayerAttributes {
    let mut a = x::LayerAttributes {
        software_name: Some(text(concat!("arlux ", env!("CARGO_PKG_VERSION")))),
        world_to_camera: meta.world_to_camera,
        world_to_normalized_device: meta.world_to_ndc,
        ..x::LayerAttributes::default()
    };
    if let Some(window) = meta.window {
        a.layer_position = x::Vec2(window.x0 as i32, window.y0 as i32);
    }
    // One custom attribute only: the crate keeps them in a hash map, whose
    // order would make two writes of one frame differ in their bytes.
    if let Some(s) = &meta.arlux {
        a.other
            .insert(text("arlux"), x::AttributeValue::Text(text(s)));
    }
    a
}

/// A text attribute; OpenEXR stores text as bytes, which arlux writes as UTF-8.
fn text(s: &str) -> x::Text {
    x::Text::from_slice_unchecked(s.as_bytes())
}

/// Writes a float EXR holding every layer (full-frame planes of
/// `width`×`height`) as channels of one part, cut to `meta.window`,
/// with `meta`'s attributes, atomically.
pub fn write_exr_with(
    path: &Path,
    width: u32,
    height: u32,
    layers: &[ExrLayer],
    meta: &ExrMeta,
) -> Result<()> {
    let window = meta.window.unwrap_or(PixelRect::full(width, height));
    let cut = |plane: Vec<f32>| window.cut(&plane, width);
    let mut list: x::SmallVec<[x::AnyChannel<x::FlatSamples>; 4]> = x::SmallVec::new();
    for layer in layers {
        match layer {
            ExrLayer::Rgb(name, img) => {
                assert_eq!(
                    (img.width, img.height),
                    (width, height),
                    "layer '{name}' has the wrong size"
                );
                for (c, cname) in ["R", "G", "B"].iter().enumerate() {
                    let full = if name.is_empty() {
                        cname.to_string()
                    } else {
                        format!("{name}.{cname}")
                    };
                    let samples = cut(img.pixels.iter().map(|p| p[c]).collect());
                    list.push(x::AnyChannel::new(
                        full.as_str(),
                        x::FlatSamples::F32(samples),
                    ));
                }
            }
            ExrLayer::Channel(name, data) => {
                assert_eq!(
                    data.len(),
                    width as usize * height as usize,
                    "channel '{name}' has the wrong size"
                );
                list.push(x::AnyChannel::new(
                    *name,
                    x::FlatSamples::F32(cut(data.to_vec())),
                ));
            }
        }
    }
    write_image(path, frame_image(width, height, window, meta, list))
}

/// The single-part image arlux writes: `channels` over `window` of a
/// `width` × `height` frame, with `meta`'s attributes (its header is what
/// [`super::ExrStream`] writes too).
pub(super) fn frame_image(
    width: u32,
    height: u32,
    window: PixelRect,
    meta: &ExrMeta,
    channels: x::SmallVec<[x::AnyChannel<x::FlatSamples>; 4]>,
) -> Part {
    let layer = x::Layer::new(
        (window.width() as usize, window.height() as usize),
        attributes(meta),
        encoding(),
        x::AnyChannels::sort(channels),
    );
    let display = x::IntegerBounds::new((0, 0), (width as usize, height as usize));
    x::Image::new(x::ImageAttributes::new(display), layer)
}

fn write_image(path: &Path, image: Part) -> Result<()> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    image
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| Error::file(path, format!("could not encode EXR: {e}")))?;
    write_atomic(path, bytes.get_ref())
}

type Part = x::Image<x::Layer<x::AnyChannels<x::FlatSamples>>>;

/// Reads a single-part EXR whole: pixels, windows and attributes.
fn read_part(path: &Path) -> Result<Part> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    super::check_exr_size(path, &bytes)?;
    x::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| Error::file(path, format!("malformed EXR: {e}")))
}

/// Where a part's pixels lie in its display window.
fn window_of(path: &Path, part: &Part) -> Result<PixelRect> {
    let d = part.attributes.display_window;
    let p = part.layer_data.attributes.layer_position - d.position;
    let s = part.layer_data.size;
    let (dw, dh) = (d.size.width() as i64, d.size.height() as i64);
    let (x0, y0) = (p.x() as i64, p.y() as i64);
    let (x1, y1) = (x0 + s.width() as i64, y0 + s.height() as i64);
    if x0 < 0 || y0 < 0 || x1 > dw || y1 > dh {
        return Err(Error::file(
            path,
            format!(
                "its data window ({x0}, {y0})..({x1}, {y1}) leaves its display window (0, 0)..({dw}, {dh}): not a tile of a frame"
            ),
        ));
    }
    Ok(PixelRect {
        x0: x0 as u32,
        y0: y0 as u32,
        x1: x1 as u32,
        y1: y1 as u32,
    })
}

/// What [`merge_tiles`] assembled.
#[derive(Debug, Clone, PartialEq)]
pub struct MergedFrame {
    pub width: u32,
    pub height: u32,
    pub tiles: usize,
    pub channels: usize,
}

/// What says two tiles come from different renders: their `arlux`
/// attributes (scene, variant or motion pose, settings, version) differ,
/// or one has it and the other not. None when they agree.
fn different_renders(a: &Part, b: &Part) -> Option<String> {
    let tag = |i: &Part| {
        i.layer_data
            .attributes
            .other
            .get(&text("arlux"))
            .map(|v| match v {
                x::AttributeValue::Text(t) => {
                    serde_json::from_slice::<serde_json::Value>(t.bytes())
                        .unwrap_or(serde_json::Value::Null)
                }
                _ => serde_json::Value::Null,
            })
    };
    match (tag(a), tag(b)) {
        (None, None) => None,
        (Some(x), Some(y)) if x == y => None,
        (Some(serde_json::Value::Object(x)), Some(serde_json::Value::Object(y))) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            let differ: Vec<String> = keys
                .into_iter()
                .filter(|k| x.get(*k) != y.get(*k))
                .map(|k| {
                    let show = |v: Option<&serde_json::Value>| {
                        v.map_or("none".to_string(), |v| v.to_string())
                    };
                    format!("{k} {} against {}", show(y.get(k)), show(x.get(k)))
                })
                .collect();
            Some(differ.join("; "))
        }
        _ => Some("one was written by arlux with what it renders, the other not".to_string()),
    }
}

/// Assembles crops of one frame (`arlux render --crop`, in any order) into
/// the whole frame, written to `output` with the tiles' attributes. The
/// tiles must share their display window and channels, and cover every
/// pixel exactly once.
pub fn merge_tiles(inputs: &[PathBuf], output: &Path) -> Result<MergedFrame> {
    let Some(first_path) = inputs.first() else {
        return Err(Error::file(output, "no tiles to merge"));
    };
    let first = read_part(first_path)?;
    let display = first.attributes.display_window;
    let (w, h) = (display.size.width(), display.size.height());
    let names: Vec<x::Text> = first
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| c.name.clone())
        .collect();
    let mut planes: Vec<Vec<f32>> = vec![vec![0.0; w * h]; names.len()];
    let mut owner: Vec<u32> = vec![u32::MAX; w * h];
    for (t, path) in inputs.iter().enumerate() {
        let part = if t == 0 {
            first.clone()
        } else {
            read_part(path)?
        };
        if part.attributes.display_window != display {
            return Err(Error::file(
                path,
                format!(
                    "its display window differs from {}'s: tiles of different frames",
                    first_path.display()
                ),
            ));
        }
        if let Some(what) = different_renders(&first, &part) {
            return Err(Error::file(
                path,
                format!(
                    "a tile of another render than {}: {what}",
                    first_path.display()
                ),
            ));
        }
        let channels = &part.layer_data.channel_data.list;
        if channels.iter().map(|c| &c.name).ne(names.iter()) {
            return Err(Error::file(
                path,
                format!("its channels differ from {}'s", first_path.display()),
            ));
        }
        let r = window_of(path, &part)?;
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                let i = y as usize * w + x as usize;
                if owner[i] != u32::MAX {
                    return Err(Error::file(
                        path,
                        format!(
                            "pixel ({x}, {y}) is also in {}: tiles overlap",
                            inputs[owner[i] as usize].display()
                        ),
                    ));
                }
                owner[i] = t as u32;
            }
        }
        for (plane, c) in planes.iter_mut().zip(channels) {
            let samples: Vec<f32> = match &c.sample_data {
                x::FlatSamples::F16(v) => v.iter().map(|s| s.to_f32()).collect(),
                x::FlatSamples::F32(v) => v.clone(),
                x::FlatSamples::U32(v) => v.iter().map(|&s| s as f32).collect(),
            };
            let mut k = 0;
            for y in r.y0..r.y1 {
                for x in r.x0..r.x1 {
                    plane[y as usize * w + x as usize] = samples[k];
                    k += 1;
                }
            }
        }
    }
    if let Some(i) = owner.iter().position(|&o| o == u32::MAX) {
        let missing = owner.iter().filter(|&&o| o == u32::MAX).count();
        return Err(Error::file(
            output,
            format!(
                "the tiles leave {missing} pixels uncovered, the first at ({}, {}): give every crop of the frame",
                i % w,
                i / w
            ),
        ));
    }
    let mut attributes = first.layer_data.attributes.clone();
    attributes.layer_position = display.position;
    let list = names
        .into_iter()
        .zip(planes)
        .map(|(n, p)| x::AnyChannel::new(n, x::FlatSamples::F32(p)))
        .collect();
    let layer = x::Layer::new((w, h), attributes, encoding(), x::AnyChannels::sort(list));
    write_image(output, x::Image::new(first.attributes.clone(), layer))?;
    Ok(MergedFrame {
        width: w as u32,
        height: h as u32,
        tiles: inputs.len(),
        channels: first.layer_data.channel_data.list.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// Row vector (p, 1) times a row-major 4×4.
    fn apply(m: &[f32; 16], p: DVec3) -> [f64; 4] {
        let v = [p.x, p.y, p.z, 1.0];
        let mut out = [0.0; 4];
        for (j, o) in out.iter_mut().enumerate() {
            *o = (0..4).map(|i| v[i] * m[i * 4 + j] as f64).sum();
        }
        out
    }

    #[test]
    fn the_camera_matrices_project_as_the_camera_does() {
        let camera = Camera::new(
            512,
            384,
            DVec3::new(0.7, 1.45, 2.7),
            DVec3::new(-0.45, 0.6, -1.0),
            DVec3::Y,
            crate::camera::Projection::Intrinsics {
                fx: 480.0,
                fy: 470.0,
                cx: 250.0,
                cy: 200.0,
            },
        )
        .unwrap();
        let meta = ExrMeta::default().with_camera(&camera);
        let (to_camera, to_ndc) = (meta.world_to_camera.unwrap(), meta.world_to_ndc.unwrap());
        let at = apply(&to_camera, camera.position);
        assert!(at[..3].iter().all(|v| v.abs() < 1e-5), "{at:?}");
        let ahead = apply(&to_camera, camera.position + camera.forward * 2.0);
        assert!(
            (ahead[2] - 2.0).abs() < 1e-5 && ahead[0].abs() < 1e-5,
            "{ahead:?}"
        );
        for p in [
            DVec3::new(-0.45, 0.6, -1.0),
            DVec3::new(1.0, 0.0, -0.5),
            DVec3::new(-1.3, 2.2, 0.4),
        ] {
            let (x, y, _) = camera.project(p).unwrap();
            let h = apply(&to_ndc, p);
            let (u, v) = (h[0] / h[3], h[1] / h[3]);
            assert!((u - x / 512.0).abs() < 1e-5, "{u} against {}", x / 512.0);
            assert!((v - y / 384.0).abs() < 1e-5, "{v} against {}", y / 384.0);
        }
    }

    #[test]
    fn crop_windows_sharing_edges_tile_the_frame_once() {
        let (w, h) = (517, 389);
        let cuts = [0.0, 0.13, 0.5, 0.77, 1.0];
        let mut count = vec![0u8; w * h];
        for xs in cuts.windows(2) {
            for ys in cuts.windows(2) {
                let c = CropWindow {
                    x0: xs[0],
                    x1: xs[1],
                    y0: ys[0],
                    y1: ys[1],
                };
                let r = c.pixels(w as u32, h as u32).unwrap();
                for y in r.y0..r.y1 {
                    for x in r.x0..r.x1 {
                        count[y as usize * w + x as usize] += 1;
                    }
                }
            }
        }
        assert!(count.iter().all(|&c| c == 1));
        let bad = CropWindow {
            x0: 0.5,
            x1: 0.5,
            y0: 0.0,
            y1: 1.0,
        };
        assert!(bad.validate().unwrap_err().contains("x0 0.5 and x1 0.5"));
    }
}
