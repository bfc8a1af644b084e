//! [`Image`]: linear RGB float images, and their files. Reads EXR (half or
//! float, RGB/RGBA/Y in any channel order, optionally inside a layer) and
//! 8-bit PNG/JPEG (sRGB decoded to linear, turned as their EXIF
//! orientation says); writes float EXR with several
//! layers in one file, and PNG (exposure + sRGB). Every write is atomic: a
//! temporary file in the same folder, renamed over the target when complete.

use std::io::Write;
use std::path::{Path, PathBuf};

use exr::prelude::{self as x, ReadChannels, ReadLayers};
use glam::Vec3;

use crate::error::{Error, Result};

mod frames;
mod rows;
mod srgb8;
mod stream;
pub use frames::{CropWindow, ExrMeta, MergedFrame, PixelRect, merge_tiles, write_exr_with};
pub use rows::RowReader;
pub use srgb8::linear_to_srgb8;
pub use stream::ExrStream;

/// A linear RGB image, row-major from the top-left pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl Image {
    pub fn new(width: u32, height: u32) -> Image {
        Image {
            width,
            height,
            pixels: vec![Vec3::ZERO; width as usize * height as usize],
        }
    }

    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// The image at continuous pixel coordinates (x, y), bilinear between
    /// the pixels' centres, clamped at its borders.
    pub fn bilinear(&self, x: f64, y: f64) -> glam::DVec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        let (fx, fy) = (x - 0.5, y - 0.5);
        let (x0, y0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - x0, fy - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let mut out = glam::DVec3::ZERO;
        for (dx, dy, wt) in [
            (0, 0, (1.0 - tx) * (1.0 - ty)),
            (1, 0, tx * (1.0 - ty)),
            (0, 1, (1.0 - tx) * ty),
            (1, 1, tx * ty),
        ] {
            let j = (y0 + dy).clamp(0, h - 1) * w + (x0 + dx).clamp(0, w - 1);
            out += self.pixels[j as usize].as_dvec3() * wt;
        }
        out
    }

    pub fn set(&mut self, x: u32, y: u32, v: Vec3) {
        let w = self.width as usize;
        self.pixels[y as usize * w + x as usize] = v;
    }

    /// The pixels of `r`, as an image of its size.
    pub fn crop(&self, r: PixelRect) -> Image {
        Image {
            width: r.width(),
            height: r.height(),
            pixels: r.cut(&self.pixels, self.width),
        }
    }

    /// This image at `width`×`height` (no larger than it), each new pixel
    /// the mean over the area of this image it covers (a box filter with
    /// fractional overlaps): a photo's pixels are means over their area.
    pub(crate) fn area_resampled(&self, width: u32, height: u32) -> Image {
        // Per new column (row), the old columns it overlaps and by how much.
        let weights = |old: u32, new: u32| -> Vec<Vec<(usize, f32)>> {
            let step = old as f64 / new as f64;
            (0..new)
                .map(|i| {
                    let (a, b) = (i as f64 * step, (i + 1) as f64 * step);
                    (a.floor() as usize..(b.ceil() as usize).min(old as usize))
                        .map(|j| {
                            let overlap = (b.min(j as f64 + 1.0) - a.max(j as f64)).max(0.0);
                            (j, (overlap / step) as f32)
                        })
                        .collect()
                })
                .collect()
        };
        let (wx, wy) = (weights(self.width, width), weights(self.height, height));
        let mut out = Image::new(width, height);
        for (y, ry) in wy.iter().enumerate() {
            for (x, rx) in wx.iter().enumerate() {
                let mut sum = Vec3::ZERO;
                for &(j, a) in ry {
                    for &(i, b) in rx {
                        sum += self.get(i as u32, j as u32) * (a * b);
                    }
                }
                out.set(x as u32, y as u32, sum);
            }
        }
        out
    }

    /// Mean of the three channels over all pixels.
    pub fn mean(&self) -> f64 {
        let sum: f64 = self.pixels.iter().map(|p| p.as_dvec3().element_sum()).sum();
        sum / (3.0 * self.pixels.len().max(1) as f64)
    }
}

/// Reads a photograph or reference: EXR as linear radiance, PNG/JPEG as
/// sRGB-encoded 8-bit values decoded to linear. Non-finite pixels are an error.
pub fn read_image(path: &Path) -> Result<Image> {
    let img = match extension(path).as_str() {
        "exr" => read_exr_rgb(path)?,
        "png" | "jpg" | "jpeg" => read_8bit(path)?,
        other => {
            return Err(Error::file(
                path,
                format!("unsupported image type '.{other}' (use .exr, .png, .jpg)"),
            ));
        }
    };
    if let Some(i) = img.pixels.iter().position(|p| !p.is_finite()) {
        let bad = img.pixels.iter().filter(|p| !p.is_finite()).count();
        let (x, y) = (i as u32 % img.width, i as u32 / img.width);
        return Err(Error::file(
            path,
            format!("{bad} pixels are NaN or infinite (the first at x={x}, y={y})"),
        ));
    }
    Ok(img)
}

/// The exposure time an image's EXIF records (`ExposureTime`, seconds):
/// what bracketed photos differ by when their EV offsets are not given.
pub(crate) fn exif_exposure_time(path: &Path) -> Result<f64> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, &e))?;
    let exif = exif::Reader::new()
        .read_from_container(&mut std::io::BufReader::new(file))
        .map_err(|e| {
            Error::file(
                path,
                format!("no EXIF to read the exposure time from ({e})"),
            )
        })?;
    let field = exif
        .get_field(exif::Tag::ExposureTime, exif::In::PRIMARY)
        .ok_or_else(|| Error::file(path, "its EXIF records no ExposureTime"))?;
    let seconds = match &field.value {
        exif::Value::Rational(v) if !v.is_empty() => v[0].to_f64(),
        _ => f64::NAN,
    };
    if seconds.is_finite() && seconds > 0.0 {
        Ok(seconds)
    } else {
        Err(Error::file(
            path,
            format!(
                "its EXIF ExposureTime {} is not a time",
                field.display_value()
            ),
        ))
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn read_8bit(path: &Path) -> Result<Image> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    let malformed = |e: image::ImageError| Error::file(path, format!("malformed image: {e}"));
    // Phones store a photo as the sensor read it and say in its EXIF how to
    // turn it: the picture the user saw is the one the camera describes.
    let mut decoder = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| Error::io(path, &e))?
        .into_decoder()
        .map_err(malformed)?;
    let orientation = image::ImageDecoder::orientation(&mut decoder).map_err(malformed)?;
    let mut decoded = image::DynamicImage::from_decoder(decoder).map_err(malformed)?;
    decoded.apply_orientation(orientation);
    let rgb = decoded.to_rgb32f();
    let pixels = rgb
        .pixels()
        .map(|p| Vec3::from_array(p.0.map(srgb_to_linear)))
        .collect();
    Ok(Image {
        width: rgb.width(),
        height: rgb.height(),
        pixels,
    })
}

/// All channels of the first part of an EXR file, by full name, as f32.
struct ExrChannels {
    width: usize,
    height: usize,
    channels: Vec<(String, Vec<f32>)>,
}

/// Samples (pixels × channels, over every layer) above which an EXR is
/// refused before its pixels are read: a header is a few bytes, and a
/// damaged one can ask for any size (the reader then aborts the process on
/// an allocation of tens of gigabytes). 2^30 samples is 4 GB of floats, a
/// 24-megapixel photo with forty channels.
pub(crate) const MAX_EXR_SAMPLES: u64 = 1 << 30;

/// Reads the EXR's headers alone and refuses one whose layers hold more
/// than [`MAX_EXR_SAMPLES`].
fn check_exr_size(path: &Path, bytes: &[u8]) -> Result<()> {
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| Error::file(path, format!("malformed EXR: {e}")))?;
    check_exr_headers(path, &meta)
}

/// Refuses headers whose layers hold more than [`MAX_EXR_SAMPLES`].
fn check_exr_headers(path: &Path, meta: &exr::meta::MetaData) -> Result<()> {
    let mut samples: u64 = 0;
    for header in &meta.headers {
        let size = header.layer_size;
        let pixels = size.width() as u64 * size.height() as u64;
        samples = samples.saturating_add(pixels.saturating_mul(header.channels.list.len() as u64));
    }
    if samples > MAX_EXR_SAMPLES {
        return Err(Error::file(
            path,
            format!(
                "malformed EXR: its header asks for {samples} samples, more than arlux reads ({MAX_EXR_SAMPLES})"
            ),
        ));
    }
    Ok(())
}

fn read_exr_channels(path: &Path) -> Result<ExrChannels> {
    let malformed = |e: x::Error| Error::file(path, format!("malformed EXR: {e}"));
    // Read from memory so that a missing file is reported as such.
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    check_exr_size(path, &bytes)?;
    let image = x::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(malformed)?;
    let mut out: Option<ExrChannels> = None;
    for layer in &image.layer_data {
        let (w, h) = (layer.size.width(), layer.size.height());
        let prefix = layer
            .attributes
            .layer_name
            .as_ref()
            .map(|n| format!("{n}."))
            .unwrap_or_default();
        let target = out.get_or_insert(ExrChannels {
            width: w,
            height: h,
            channels: Vec::new(),
        });
        if (target.width, target.height) != (w, h) {
            continue;
        }
        for ch in &layer.channel_data.list {
            let samples: Vec<f32> = match &ch.sample_data {
                x::FlatSamples::F16(v) => v.iter().map(|s| s.to_f32()).collect(),
                x::FlatSamples::F32(v) => v.clone(),
                x::FlatSamples::U32(v) => v.iter().map(|&s| s as f32).collect(),
            };
            if samples.len() != w * h {
                return Err(Error::file(
                    path,
                    format!(
                        "channel {} is subsampled; arlux reads full-resolution channels",
                        ch.name
                    ),
                ));
            }
            target
                .channels
                .push((format!("{prefix}{}", ch.name), samples));
        }
    }
    out.ok_or_else(|| Error::file(path, "the EXR has no image layer"))
}

/// Reads one channel of an EXR file by its full name (e.g. `Y`, `direct.R`).
pub fn read_exr_channel(path: &Path, name: &str) -> Result<(u32, u32, Vec<f32>)> {
    let c = read_exr_channels(path)?;
    let names: Vec<&str> = c.channels.iter().map(|(n, _)| n.as_str()).collect();
    let found = c.channels.iter().find(|(n, _)| n == name);
    match found {
        Some((_, v)) => Ok((c.width as u32, c.height as u32, v.clone())),
        None => Err(Error::file(
            path,
            format!("no channel '{name}' (channels: {})", names.join(", ")),
        )),
    }
}

/// Reads the RGB image of an EXR file: channels R, G, B (in any order, at
/// the top level or in the first layer that has all three), or a lone Y as grey.
fn read_exr_rgb(path: &Path) -> Result<Image> {
    let c = read_exr_channels(path)?;
    let names: Vec<&str> = c.channels.iter().map(|(n, _)| n.as_str()).collect();
    let plane = |i: usize| &c.channels[i].1;
    let pixels: Vec<Vec3> = match rgb_channels(&names) {
        Some(RgbChannels::Rgb([r, g, b])) => {
            let (r, g, b) = (plane(r), plane(g), plane(b));
            (0..c.width * c.height)
                .map(|i| Vec3::new(r[i], g[i], b[i]))
                .collect()
        }
        Some(RgbChannels::Grey(y)) => plane(y).iter().map(|&v| Vec3::splat(v)).collect(),
        None => {
            return Err(Error::file(
                path,
                format!("no R, G, B channels (channels: {})", names.join(", ")),
            ));
        }
    };
    Ok(Image {
        width: c.width as u32,
        height: c.height as u32,
        pixels,
    })
}

/// Which of an EXR's channels (full names, in the file's order) make its
/// RGB image: R, G, B at the top level, else in the first layer that has
/// all three, else a lone Y as grey.
enum RgbChannels {
    Rgb([usize; 3]),
    Grey(usize),
}

fn rgb_channels(names: &[&str]) -> Option<RgbChannels> {
    let find = |name: &str| names.iter().position(|n| *n == name);
    let mut prefixes: Vec<&str> = vec![""];
    for n in names {
        if let Some(p) = n.strip_suffix("R").filter(|p| p.ends_with('.')) {
            prefixes.push(p);
        }
    }
    for p in prefixes {
        if let (Some(r), Some(g), Some(b)) = (
            find(&format!("{p}R")),
            find(&format!("{p}G")),
            find(&format!("{p}B")),
        ) {
            return Some(RgbChannels::Rgb([r, g, b]));
        }
    }
    find("Y").map(RgbChannels::Grey)
}

/// One named part of an EXR file to write.
pub enum ExrLayer<'a> {
    /// RGB channels, named `R,G,B` when the name is empty, else `name.R` etc.
    Rgb(&'a str, &'a Image),
    /// A single float channel with a full name (e.g. `A`, `Y`, `mask.Y`).
    Channel(&'a str, &'a [f32]),
}

/// Writes a float EXR holding every layer as channels of one part (the
/// multi-layer convention compositors read), atomically.
pub fn write_exr(path: &Path, width: u32, height: u32, layers: &[ExrLayer]) -> Result<()> {
    write_exr_with(path, width, height, layers, &ExrMeta::default())
}

/// Writes `img` as an 8-bit sRGB PNG after multiplying by 2^exposure_ev, atomically.
pub fn write_png(path: &Path, img: &Image, exposure_ev: f32) -> Result<()> {
    let gain = exposure_ev.exp2();
    let bytes: Vec<u8> = img
        .pixels
        .iter()
        .flat_map(|p| p.to_array().map(|c| linear_to_srgb8(c * gain)))
        .collect();
    write_png_rgb8(path, img.width, img.height, bytes)
}

/// Writes already-encoded 8-bit RGB bytes as PNG, atomically.
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, bytes: Vec<u8>) -> Result<()> {
    let buf = image::RgbImage::from_raw(width, height, bytes).expect("buffer matches its size");
    let mut out = std::io::Cursor::new(Vec::new());
    buf.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| Error::file(path, format!("could not encode PNG: {e}")))?;
    write_atomic(path, out.get_ref())
}

/// With `ARLUX_TEST_WRITE_PAUSE_MS` set, waits that long with a temporary
/// file written and not yet renamed: how the tests send a signal at that
/// moment, deterministically.
fn pause_for_tests() {
    if let Some(ms) = std::env::var("ARLUX_TEST_WRITE_PAUSE_MS")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
}

/// With `ARLUX_TEST_WRITE_FAIL` set, writing a file whose name contains
/// its value fails as a full disk would: how the tests check that a run's
/// outputs are committed together or not at all.
fn fail_for_tests(path: &Path) -> std::io::Result<()> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    match (std::env::var("ARLUX_TEST_WRITE_FAIL"), name) {
        (Ok(v), Some(n)) if !v.is_empty() && n.contains(&v) => Err(std::io::Error::new(
            std::io::ErrorKind::StorageFull,
            "no space left on the device (ARLUX_TEST_WRITE_FAIL)",
        )),
        _ => Ok(()),
    }
}

/// Writes `bytes` to `path` through a temporary file in the same folder and
/// a rename, so that `path` holds either its old content or the new, whole.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// A new temporary file beside `path` for an atomic write, registered for
/// removal on a signal: created exclusively (O_CREAT | O_EXCL, so never an
/// existing file nor the target of a planted link) under an unpredictable
/// name `.NAME.XXXXXX.tmp` (the `tempfile` crate makes both).
pub(crate) fn temp_beside(path: &Path) -> std::io::Result<(std::fs::File, PathBuf)> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map_or("out".into(), |n| n.to_string_lossy());
    let (file, tmp) = tempfile::Builder::new()
        .prefix(&format!(".{name}."))
        .suffix(".tmp")
        .tempfile_in(&dir)?
        .into_parts();
    // Kept: removed by the caller, or on a signal through the registry.
    let tmp = tmp.keep().map_err(|e| e.error)?;
    crate::util::cleanup::register(&tmp);
    Ok((file, tmp))
}

/// Writes `bytes` to a new file `path`, whole or not at all, never
/// replacing a file that is there (even one made meanwhile): the temporary
/// is hard-linked to `path`, which fails when `path` exists.
pub fn write_new(path: &Path, bytes: &[u8]) -> Result<()> {
    let (mut file, tmp) = temp_beside(path).map_err(|e| Error::io(path, &e))?;
    let written = file.write_all(bytes).and_then(|()| file.sync_all());
    drop(file);
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        crate::util::cleanup::unregister(&tmp);
        return Err(Error::io(path, &e));
    }
    let linked = std::fs::hard_link(&tmp, path);
    let _ = std::fs::remove_file(&tmp);
    crate::util::cleanup::unregister(&tmp);
    linked.map_err(|e| match e.kind() {
        std::io::ErrorKind::AlreadyExists => {
            Error::file(path, "exists: a new file is never written over one")
        }
        _ => Error::io(path, &e),
    })
}

/// [`write_atomic`], with `fill` writing the content (buffered) as it is made.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if path.file_name().is_none() {
        return Err(Error::file(path, "not a file name"));
    }
    // Empty until the temporary is made (nothing to remove before).
    let mut tmp = PathBuf::new();
    let result = (|| {
        fail_for_tests(path)?;
        let (file, made) = temp_beside(path)?;
        tmp = made;
        let mut f = std::io::BufWriter::new(file);
        fill(&mut f)?;
        let f = f.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        pause_for_tests();
        std::fs::rename(&tmp, path)
    })();
    if result.is_ok() {
        crate::util::cleanup::unregister(&tmp);
    }
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        crate::util::cleanup::unregister(&tmp);
        // Writing, "not found" means the folder: say so.
        if e.kind() == std::io::ErrorKind::NotFound && !dir.is_dir() {
            return Error::file(
                path,
                format!("cannot write: the folder {} does not exist", dir.display()),
            );
        }
        Error::io(path, &e)
    })
}

/// sRGB transfer function, encoding: linear \[0,1\] → encoded \[0,1\] (clamped).
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = if c.is_finite() {
        c.clamp(0.0, 1.0)
    } else {
        0.0
    };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB transfer function, decoding: encoded \[0,1\] → linear.
pub(crate) fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                img.set(x, y, Vec3::new(x as f32 * 0.1, y as f32 * 0.2 + 0.01, 3.5));
            }
        }
        img
    }

    #[test]
    fn area_resampling_averages_what_each_pixel_covers() {
        // 3 columns into 2: the middle one is shared half and half.
        let mut img = Image::new(3, 1);
        for (x, v) in [1.0, 4.0, 7.0].iter().enumerate() {
            img.set(x as u32, 0, Vec3::splat(*v));
        }
        let out = img.area_resampled(2, 1);
        assert!((out.get(0, 0).x - 2.0).abs() < 1e-6 && (out.get(1, 0).x - 6.0).abs() < 1e-6);
        // Any size: the mean is kept.
        let r = ramp(17, 11);
        let small = r.area_resampled(5, 4);
        assert!(
            (small.mean() - r.mean()).abs() < 1e-5 * r.mean(),
            "{} {}",
            small.mean(),
            r.mean()
        );
    }

    #[test]
    fn a_jpeg_is_turned_as_its_exif_orientation_says() {
        // 16×8, left half white: stored as the sensor read it, shown turned
        // 90° clockwise (EXIF orientation 6), so the white half is on top.
        let buf = image::RgbImage::from_fn(16, 8, |x, _| {
            image::Rgb(if x < 8 { [255; 3] } else { [0; 3] })
        });
        let mut jpeg = std::io::Cursor::new(Vec::new());
        buf.write_to(&mut jpeg, image::ImageFormat::Jpeg).unwrap();
        let jpeg = jpeg.into_inner();
        let mut exif = vec![0xFF, 0xE1, 0, 34];
        exif.extend(b"Exif\0\0II*\0\x08\0\0\0\x01\0");
        exif.extend([0x12, 0x01, 3, 0, 1, 0, 0, 0, 6, 0, 0, 0, 0, 0, 0, 0]);
        let bytes: Vec<u8> = jpeg[..2]
            .iter()
            .chain(&exif)
            .chain(&jpeg[2..])
            .copied()
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("phone.jpg");
        std::fs::write(&p, bytes).unwrap();
        let img = read_image(&p).unwrap();
        assert_eq!((img.width, img.height), (8, 16));
        assert!(
            img.get(4, 2).x > 0.9 && img.get(4, 13).x < 0.05,
            "{:?} {:?}",
            img.get(4, 2),
            img.get(4, 13)
        );
    }

    #[test]
    fn exr_round_trips_with_layers() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.exr");
        let (main, extra) = (ramp(5, 3), Image::new(5, 3));
        let alpha = vec![0.5f32; 15];
        write_exr(
            &p,
            5,
            3,
            &[
                ExrLayer::Rgb("", &main),
                ExrLayer::Rgb("direct", &extra),
                ExrLayer::Channel("A", &alpha),
            ],
        )
        .unwrap();
        assert_eq!(read_image(&p).unwrap(), main);
        assert_eq!(read_exr_channel(&p, "A").unwrap().2, alpha);
        assert_eq!(read_exr_channel(&p, "direct.G").unwrap().2, vec![0.0; 15]);
        let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(leftovers.len(), 1, "no temporary file left behind");
    }

    #[test]
    fn exr_bytes_are_the_same_every_time() {
        // Chunks are compressed in parallel; written in increasing order, the
        // file does not depend on which thread finished first.
        let dir = tempfile::tempdir().unwrap();
        let img = ramp(512, 384);
        let files: Vec<Vec<u8>> = (0..4)
            .map(|i| {
                let p = dir.path().join(format!("{i}.exr"));
                write_exr(
                    &p,
                    512,
                    384,
                    &[ExrLayer::Rgb("", &img), ExrLayer::Rgb("direct", &img)],
                )
                .unwrap();
                std::fs::read(&p).unwrap()
            })
            .collect();
        assert!(files.windows(2).all(|w| w[0] == w[1]));
    }

    #[test]
    fn png_round_trips_through_srgb_within_quantisation() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        let mut img = ramp(4, 4);
        img.pixels.iter_mut().for_each(|c| *c = c.min(Vec3::ONE));
        write_png(&p, &img, 0.0).unwrap();
        let back = read_image(&p).unwrap();
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            // One 8-bit step of sRGB is at most ~0.9% of the linear value above black.
            assert!(
                (*a - *b).abs().max_element() <= 0.01 * a.max_element() + 2e-4,
                "{a} vs {b}"
            );
        }
    }

    #[test]
    fn srgb_curves_are_inverse() {
        for i in 0..=100 {
            let c = i as f32 / 100.0;
            assert!((srgb_to_linear(linear_to_srgb(c)) - c).abs() < 1e-5);
        }
        assert_eq!(linear_to_srgb(f32::NAN), 0.0);
    }

    #[test]
    fn truncated_exr_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cut.exr");
        let good = dir.path().join("good.exr");
        write_exr(&good, 5, 3, &[ExrLayer::Rgb("", &ramp(5, 3))]).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
        let e = read_image(&p).unwrap_err();
        assert!(
            e.to_string().contains("cut.exr") && e.to_string().contains("malformed EXR"),
            "{e}"
        );
    }

    #[test]
    fn an_exr_header_asking_for_gigabytes_is_refused_not_allocated() {
        // A damaged header (found by tests/fuzz_parsers.rs) made the reader
        // allocate 32 GB and abort the process.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("huge.exr");
        write_exr(&p, 5, 3, &[ExrLayer::Rgb("", &ramp(5, 3))]).unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        let key = b"dataWindow\0box2i\0";
        let at = bytes
            .windows(key.len())
            .position(|w| w == key)
            .expect("a data window")
            + key.len()
            + 4;
        // xMax and yMax of the window: 200 000 × 200 000 pixels.
        bytes[at + 8..at + 12].copy_from_slice(&199_999i32.to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&199_999i32.to_le_bytes());
        std::fs::write(&p, &bytes).unwrap();
        let e = read_image(&p).unwrap_err().to_string();
        assert!(
            e.contains("huge.exr") && e.contains("more than arlux reads"),
            "{e}"
        );
    }
}
