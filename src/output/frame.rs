//! A frame's files written band by band ([`FrameWriter`]): the EXR with
//! every layer a compositor expects, each layer as a file of its own
//! (AOVs), the PNG, and the image kept for a comparison only when one is
//! asked for. What a band holds is written and dropped.

use std::path::PathBuf;

use glam::Vec3;

use crate::composite::Composite;
use crate::error::Result;
use crate::image_io::{ExrMeta, ExrStream, Image, PixelRect, linear_to_srgb8};

/// A layer of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameLayer {
    Image,
    Alpha,
    /// The objects alone, premultiplied.
    Object,
    /// What the change did to the real surfaces, a factor on the photo.
    Shadow,
    Change,
    Photo,
    Direct,
    Indirect,
    /// The estimated standard deviation of the image's luminance left by
    /// the rounds of per-pixel samples (0 where none ran).
    Noise,
}

/// The layers written as files of their own (`--aov`), by file name.
pub const AOV_LAYERS: [(&str, FrameLayer); 8] = [
    ("object", FrameLayer::Object),
    ("shadow", FrameLayer::Shadow),
    ("change", FrameLayer::Change),
    ("photo", FrameLayer::Photo),
    ("direct", FrameLayer::Direct),
    ("indirect", FrameLayer::Indirect),
    ("alpha", FrameLayer::Alpha),
    ("noise", FrameLayer::Noise),
];

/// A channel of a file: its name and the layer's component it holds.
#[derive(Debug, Clone, PartialEq)]
struct Channel {
    name: String,
    layer: FrameLayer,
    component: usize,
}

/// The RGB channels of `layer` named `prefix.R` … (or `R` … without a prefix).
fn rgb(prefix: &str, layer: FrameLayer) -> Vec<Channel> {
    ["R", "G", "B"]
        .iter()
        .enumerate()
        .map(|(component, c)| Channel {
            name: if prefix.is_empty() {
                c.to_string()
            } else {
                format!("{prefix}.{c}")
            },
            layer,
            component,
        })
        .collect()
}

fn alpha(name: &str) -> Channel {
    Channel {
        name: name.to_string(),
        layer: FrameLayer::Alpha,
        component: 0,
    }
}

/// The frame EXR's channels: the image and its coverage, and with
/// `layers` the objects, shadow factor, change, photo, direct and indirect.
fn frame_channels(layers: bool) -> Vec<Channel> {
    let mut out = rgb("", FrameLayer::Image);
    out.push(alpha("A"));
    if layers {
        out.extend(rgb("object", FrameLayer::Object));
        out.push(alpha("object.A"));
        for (name, layer) in &AOV_LAYERS[1..6] {
            out.extend(rgb(name, *layer));
        }
    }
    out
}

/// A layer's file of its own: `R`, `G`, `B`, `A` for the coverage, or
/// `Y` for the noise (one number per pixel).
fn aov_channels(layer: FrameLayer) -> Vec<Channel> {
    match layer {
        FrameLayer::Alpha => vec![alpha("A")],
        FrameLayer::Noise => vec![Channel {
            name: "Y".to_string(),
            layer,
            component: 0,
        }],
        _ => rgb("", layer),
    }
}

/// Each channel's samples over `rect` (rows within `c`'s), in order.
fn planes(c: &Composite, photo: &Image, rect: PixelRect, channels: &[Channel]) -> Vec<Vec<f32>> {
    use rayon::prelude::*;
    let w = c.image.width as usize;
    let (x0, x1) = (rect.x0 as usize, rect.x1 as usize);
    // The rect's part of each row of a layer held as `c`'s rows, or as the frame's.
    let local = |y: u32| (y - c.first_row) as usize * w;
    let frame = |y: u32| y as usize * photo.width as usize;
    channels
        .par_iter()
        .map(|ch| {
            let mut out = Vec::with_capacity(rect.pixel_count());
            let k = ch.component;
            for y in rect.y0..rect.y1 {
                let (l, f) = (local(y), frame(y));
                let rgb = |img: &Image, at: usize, out: &mut Vec<f32>| match img
                    .pixels
                    .get(at + x0..at + x1)
                {
                    Some(row) => out.extend(row.iter().map(|p| p[k])),
                    None => out.extend(std::iter::repeat_n(0.0, x1 - x0)),
                };
                match ch.layer {
                    FrameLayer::Image => rgb(&c.image, l, &mut out),
                    FrameLayer::Object => rgb(&c.object, l, &mut out),
                    FrameLayer::Change => rgb(&c.change, l, &mut out),
                    FrameLayer::Direct => rgb(&c.direct, l, &mut out),
                    FrameLayer::Indirect => rgb(&c.indirect, l, &mut out),
                    FrameLayer::Photo => rgb(photo, f, &mut out),
                    FrameLayer::Alpha => out.extend(&c.alpha[l + x0..l + x1]),
                    FrameLayer::Noise => match c.noise.get(l + x0..l + x1) {
                        Some(row) => out.extend(row),
                        None => out.extend(std::iter::repeat_n(0.0, x1 - x0)),
                    },
                    FrameLayer::Shadow => {
                        out.extend((x0..x1).map(|x| c.shadow_at(l + x, photo.pixels[f + x])[k]))
                    }
                }
            }
            out
        })
        .collect()
}

/// Rows handed to the files at a time (four rows of the EXR's tiles).
const PIECE_ROWS: u32 = 256;

/// The files of a frame and where each goes.
#[derive(Debug, Clone, Default)]
pub struct FrameFiles {
    pub exr: PathBuf,
    /// With its exposure, in stops.
    pub png: Option<(PathBuf, f32)>,
    /// Each layer's own file.
    pub aov: Vec<(FrameLayer, PathBuf)>,
    /// Write the layers beside the image (a motion writes its images only).
    pub layers: bool,
}

/// A frame's files being written, band by band, in row order.
pub struct FrameWriter {
    window: PixelRect,
    streams: Vec<(ExrStream, Vec<Channel>)>,
    png: Option<(PathBuf, f32, Vec<u8>)>,
}

impl FrameWriter {
    /// Starts the files of a `width` × `height` frame, cut to `meta.window`.
    pub fn start(files: &FrameFiles, width: u32, height: u32, meta: &ExrMeta) -> Result<Self> {
        let window = meta.window.unwrap_or(PixelRect::full(width, height));
        let mut streams = Vec::new();
        let mut jobs = vec![(files.exr.clone(), frame_channels(files.layers))];
        jobs.extend((files.aov.iter()).map(|(layer, path)| (path.clone(), aov_channels(*layer))));
        for (path, channels) in jobs {
            let names: Vec<String> = channels.iter().map(|c| c.name.clone()).collect();
            let stream = ExrStream::create(&path, width, height, &names, meta)?;
            // The planes go in the file's order.
            let ordered = (stream.channels().iter())
                .map(|n| channels.iter().find(|c| &c.name == n).cloned())
                .collect::<Option<Vec<_>>>()
                .expect("the stream orders the names it was given");
            streams.push((stream, ordered));
        }
        let pixels = window.pixel_count();
        Ok(FrameWriter {
            window,
            streams,
            png: (files.png.clone()).map(|(p, ev)| (p, ev, Vec::with_capacity(3 * pixels))),
        })
    }

    /// The next band, the frame's rows `rows` (of those `c` holds; the
    /// window's part of them is written), handed on 256 rows at
    /// a time: a whole frame's channel planes are never made at once.
    pub fn band(&mut self, c: &Composite, rows: (u32, u32), photo: &Image) -> Result<()> {
        let y0 = rows.0.max(self.window.y0).max(c.first_row);
        let y1 = (rows.1.min(self.window.y1)).min(c.first_row + c.image.height);
        for start in (y0..y1).step_by(PIECE_ROWS as usize) {
            self.piece(c, (start, (start + PIECE_ROWS).min(y1)), photo)?;
        }
        Ok(())
    }

    /// Rows `y0..y1` (within the window and `c`) to every file.
    fn piece(&mut self, c: &Composite, (y0, y1): (u32, u32), photo: &Image) -> Result<()> {
        let rect = PixelRect {
            y0,
            y1,
            ..self.window
        };
        for (stream, channels) in &mut self.streams {
            stream.push(y1 - y0, planes(c, photo, rect, channels))?;
        }
        if self.png.is_none() {
            return Ok(());
        }
        let image = planes(c, photo, rect, &rgb("", FrameLayer::Image));
        let rgb_at = |k: usize| Vec3::new(image[0][k], image[1][k], image[2][k]);
        if let Some((_, ev, bytes)) = &mut self.png {
            let gain = ev.exp2();
            bytes.extend(
                (0..rect.pixel_count())
                    .flat_map(|k| rgb_at(k).to_array().map(|v| linear_to_srgb8(v * gain))),
            );
        }
        Ok(())
    }

    /// The image's pixels of [`FrameWriter::band`]'s rows (the window's
    /// part), handed to `each` 16 rows at a time: what a comparison reads
    /// band by band, never a band's worth at once.
    pub fn image_rows<E>(
        &self,
        c: &Composite,
        rows: (u32, u32),
        photo: &Image,
        mut each: impl FnMut(&[Vec3]) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        let y0 = rows.0.max(self.window.y0).max(c.first_row);
        let y1 = (rows.1.min(self.window.y1)).min(c.first_row + c.image.height);
        let channels = rgb("", FrameLayer::Image);
        for start in (y0..y1).step_by(16) {
            let rect = PixelRect {
                y0: start,
                y1: (start + 16).min(y1),
                ..self.window
            };
            let [r, g, b] = &planes(c, photo, rect, &channels)[..] else {
                unreachable!("three channels asked for");
            };
            let pixels: Vec<Vec3> = (0..rect.pixel_count())
                .map(|k| Vec3::new(r[k], g[k], b[k]))
                .collect();
            each(&pixels)?;
        }
        Ok(())
    }

    /// Ends every file.
    pub fn finish(self) -> Result<()> {
        for (stream, _) in self.streams {
            stream.finish()?;
        }
        if let Some((path, _, bytes)) = self.png {
            let (w, h) = (self.window.width(), self.window.height());
            crate::image_io::write_png_rgb8(&path, w, h, bytes)?;
        }
        Ok(())
    }
}
