//! [`RowReader`]: an image's rows, top to bottom, read from its file as
//! they are asked for. A 24-megapixel reference compared band by band as
//! a render writes its bands is never held whole (285 MB of RGB floats).
//!
//! EXR files are read chunk by chunk through the `exr` crate's block
//! reader (scan-line blocks or tiles, any compression, half or float);
//! every other file, and an EXR the block reader cannot serve in rows
//! (deep data, subsampled channels, its RGB spread over several parts), is
//! read whole by [`read_image`] and handed out from memory. Either way the
//! pixels are those [`read_image`] gives.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use exr::block::UncompressedBlock;
use exr::block::reader::FilteredChunksReader;
use exr::meta::MetaData;
use exr::meta::attribute::SampleType;
use exr::prelude::f16;
use glam::Vec3;

use super::{Image, RgbChannels, read_image, rgb_channels};
use crate::error::{Error, Result};

/// An image's rows in order, from its file or from memory.
pub struct RowReader {
    pub width: u32,
    pub height: u32,
    source: Source,
    /// The next row [`RowReader::rows`] gives.
    next: u32,
}

enum Source {
    Whole(Image),
    Exr(Box<ExrRows>),
}

/// An EXR part's RGB (or Y) channels, decoded a block at a time.
struct ExrRows {
    path: PathBuf,
    meta: MetaData,
    chunks: FilteredChunksReader<BufReader<File>>,
    part: usize,
    /// The part's channel indices for R, G, B (thrice Y's for grey).
    channels: [usize; 3],
    /// How many different channels those are (1 or 3).
    distinct: usize,
    /// Rows decoded and not yet handed out, with how many samples of those
    /// channels the blocks read so far filled (tiles fill a row piece by piece).
    pending: BTreeMap<u32, (Vec<Vec3>, usize)>,
}

impl RowReader {
    /// Opens `path` for reading its rows. Refuses what [`read_image`]
    /// refuses (a missing file, an unknown type, a malformed or oversized
    /// EXR); a non-finite pixel is refused when its row is read.
    pub fn open(path: &Path) -> Result<RowReader> {
        let is_exr = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if is_exr && let Some(rows) = ExrRows::open(path)? {
            let size = rows.meta.headers[rows.part].layer_size;
            return Ok(RowReader {
                width: size.width() as u32,
                height: size.height() as u32,
                source: Source::Exr(Box::new(rows)),
                next: 0,
            });
        }
        Ok(RowReader::from_image(read_image(path)?))
    }

    /// Rows handed out from an image already read (one resampled to the
    /// camera, or made in memory).
    pub fn from_image(image: Image) -> RowReader {
        RowReader {
            width: image.width,
            height: image.height,
            source: Source::Whole(image),
            next: 0,
        }
    }

    /// Whether the rows come from the file as they are asked for.
    pub fn is_streamed(&self) -> bool {
        matches!(self.source, Source::Exr(_))
    }

    /// The next `n` rows (fewer at the bottom), row-major.
    pub fn rows(&mut self, n: u32) -> Result<Vec<Vec3>> {
        let end = (self.next + n).min(self.height);
        let w = self.width as usize;
        let out = match &mut self.source {
            Source::Whole(image) => image.pixels[self.next as usize * w..end as usize * w].to_vec(),
            Source::Exr(exr) => {
                let mut out = Vec::with_capacity((end - self.next) as usize * w);
                for y in self.next..end {
                    out.extend(exr.row(y, w)?);
                }
                out
            }
        };
        // A whole read refused its non-finite pixels already.
        if let (Source::Exr(exr), Some(i)) = (&self.source, out.iter().position(|p| !p.is_finite()))
        {
            let (x, y) = (i % w, self.next as usize + i / w);
            return Err(Error::file(
                &exr.path,
                format!("pixel x={x}, y={y} is NaN or infinite"),
            ));
        }
        self.next = end;
        Ok(out)
    }
}

impl ExrRows {
    /// The block reader over the part that holds the image's RGB, or
    /// `None` where only a whole read serves the file.
    fn open(path: &Path) -> Result<Option<ExrRows>> {
        let malformed = |e: exr::error::Error| Error::file(path, format!("malformed EXR: {e}"));
        let file = File::open(path).map_err(|e| Error::io(path, &e))?;
        let reader = exr::block::read(BufReader::new(file), false).map_err(malformed)?;
        let meta = reader.meta_data().clone();
        super::check_exr_headers(path, &meta)?;
        let Some((part, channels)) = choose_channels(&meta) else {
            return Ok(None);
        };
        let chunks = reader
            .filter_chunks(false, |_, tile, block| {
                block.layer == part && tile.level_index == exr::math::Vec2(0, 0)
            })
            .map_err(malformed)?;
        Ok(Some(ExrRows {
            path: path.to_path_buf(),
            meta,
            chunks,
            part,
            channels,
            distinct: if channels[0] == channels[1] { 1 } else { 3 },
            pending: BTreeMap::new(),
        }))
    }

    /// Row `y` (each row asked for once, in order), reading blocks until it is whole.
    fn row(&mut self, y: u32, width: usize) -> Result<Vec<Vec3>> {
        loop {
            let whole = width * self.distinct;
            if self
                .pending
                .get(&y)
                .is_some_and(|(_, filled)| *filled == whole)
            {
                return Ok(self
                    .pending
                    .remove(&y)
                    .map(|(row, _)| row)
                    .unwrap_or_default());
            }
            let path = self.path.clone();
            let malformed =
                |e: exr::error::Error| Error::file(&path, format!("malformed EXR: {e}"));
            let Some(chunk) = self.chunks.next() else {
                return Err(Error::file(
                    &self.path,
                    format!("malformed EXR: row {y} is missing"),
                ));
            };
            let block =
                UncompressedBlock::decompress_chunk(chunk.map_err(malformed)?, &self.meta, false)
                    .map_err(malformed)?;
            self.take(&block, width).map_err(malformed)?;
        }
    }

    /// Spreads a decoded block's lines of the chosen channels over `pending`.
    fn take(&mut self, block: &UncompressedBlock, width: usize) -> exr::error::UnitResult {
        let header = &self.meta.headers[self.part];
        for line in block.lines(&header.channels) {
            let at = line.location;
            if !self.channels.contains(&at.channel) {
                continue;
            }
            let values: Vec<f32> = match header.channels.list[at.channel].sample_type {
                SampleType::F16 => line
                    .read_samples::<f16>()
                    .map(|v| v.map(f16::to_f32))
                    .collect::<exr::error::Result<_>>(),
                SampleType::F32 => line
                    .read_samples::<f32>()
                    .collect::<exr::error::Result<_>>(),
                SampleType::U32 => line
                    .read_samples::<u32>()
                    .map(|v| v.map(|v| v as f32))
                    .collect::<exr::error::Result<_>>(),
            }?;
            let (row, filled) = self
                .pending
                .entry(at.position.y() as u32)
                .or_insert_with(|| (vec![Vec3::ZERO; width], 0));
            let x0 = at.position.x();
            for (slot, &k) in self.channels.iter().enumerate() {
                // A grey image's one line fills all three slots.
                if k == at.channel {
                    for (p, v) in row[x0.min(width)..].iter_mut().zip(&values) {
                        p[slot] = *v;
                    }
                }
            }
            *filled += at.sample_count;
        }
        Ok(())
    }
}

/// The part and its channels that [`read_image`] takes the RGB from, when
/// they all lie in one part of full resolution, scan lines or tiles.
fn choose_channels(meta: &MetaData) -> Option<(usize, [usize; 3])> {
    let first = meta.headers.first()?;
    // The whole read's channel list: every part of the first part's size.
    let mut names = Vec::new();
    let mut at = Vec::new();
    for (p, header) in meta.headers.iter().enumerate() {
        if header.deep || header.layer_size != first.layer_size {
            continue;
        }
        let prefix = (header.own_attributes.layer_name.as_ref())
            .map(|n| format!("{n}."))
            .unwrap_or_default();
        for (c, ch) in header.channels.list.iter().enumerate() {
            names.push(format!("{prefix}{}", ch.name));
            at.push((p, c, ch.sampling == exr::math::Vec2(1, 1)));
        }
    }
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let picked = match rgb_channels(&names)? {
        RgbChannels::Rgb(rgb) => rgb,
        RgbChannels::Grey(y) => [y; 3],
    };
    let parts = picked.map(|i| at[i]);
    let part = parts[0].0;
    let one_part = parts.iter().all(|&(p, _, full)| p == part && full);
    one_part.then(|| (part, parts.map(|(_, c, _)| c)))
}

#[cfg(test)]
mod tests {
    use exr::prelude as x;
    use x::{Vec2, f16};

    use super::*;
    use crate::image_io::{ExrLayer, write_exr, write_png};

    fn pattern(w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            let v = (i * 7919 % 1013) as f32 / 97.0;
            *p = Vec3::new(v, 0.5 * v + 0.25, 3.0 - 0.1 * v);
        }
        img
    }

    /// Every row of `path` read `step` rows at a time equals the whole read.
    fn rows_equal_the_whole_read(path: &Path, step: u32, streamed: bool) {
        let whole = read_image(path).unwrap();
        let mut rows = RowReader::open(path).unwrap();
        assert_eq!((rows.width, rows.height), (whole.width, whole.height));
        assert_eq!(rows.is_streamed(), streamed, "{}", path.display());
        let mut read = Vec::new();
        while read.len() < whole.pixels.len() {
            read.extend(rows.rows(step).unwrap());
        }
        assert!(read == whole.pixels, "{} by {step}", path.display());
        assert!(rows.rows(step).unwrap().is_empty());
    }

    #[test]
    fn tiled_float_exr_rows_are_the_whole_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.exr");
        let img = pattern(150, 139);
        write_exr(&path, img.width, img.height, &[ExrLayer::Rgb("", &img)]).unwrap();
        for step in [1, 7, 64, 200] {
            rows_equal_the_whole_read(&path, step, true);
        }
    }

    #[test]
    fn half_scan_line_exr_in_a_layer_and_grey_rows_are_the_whole_read() {
        let dir = tempfile::tempdir().unwrap();
        let img = pattern(61, 45);
        let at = |p: Vec2<usize>| img.get(p.x() as u32, p.y() as u32);
        // RGB in a layer named "beauty", as half, in zip blocks of 16 rows.
        let layer = x::Layer::new(
            (61, 45),
            x::LayerAttributes::named("beauty"),
            x::Encoding::SMALL_LOSSLESS,
            x::SpecificChannels::rgb(|p: Vec2<usize>| {
                let v = at(p);
                (f16::from_f32(v.x), f16::from_f32(v.y), f16::from_f32(v.z))
            }),
        );
        let path = dir.path().join("layer.exr");
        x::WritableImage::write(&x::Image::from_layer(layer))
            .to_file(&path)
            .unwrap();
        for step in [1, 5, 45] {
            rows_equal_the_whole_read(&path, step, true);
        }
        let grey = dir.path().join("grey.exr");
        let y = x::AnyChannels::sort(x::SmallVec::from_vec(vec![x::AnyChannel::new(
            "Y",
            x::FlatSamples::F32((0..61 * 45).map(|i| img.pixels[i].x).collect()),
        )]));
        x::WritableImage::write(&x::Image::from_channels((61, 45), y))
            .to_file(&grey)
            .unwrap();
        rows_equal_the_whole_read(&grey, 4, true);
    }

    #[test]
    fn png_rows_come_from_the_whole_read_and_a_nan_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("p.png");
        write_png(&png, &pattern(20, 9), -4.0).unwrap();
        rows_equal_the_whole_read(&png, 4, false);
        let mut img = pattern(20, 9);
        img.pixels[20 * 6 + 3] = Vec3::new(0.0, f32::NAN, 0.0);
        let exr = dir.path().join("nan.exr");
        write_exr(&exr, 20, 9, &[ExrLayer::Rgb("", &img)]).unwrap();
        let mut rows = RowReader::open(&exr).unwrap();
        rows.rows(5).unwrap();
        let e = rows.rows(5).unwrap_err().to_string();
        assert!(e.contains("nan.exr") && e.contains("x=3, y=6"), "{e}");
    }

    #[test]
    fn a_missing_file_is_refused_naming_it() {
        let e = RowReader::open(Path::new("/nonexistent/truth.exr"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("/nonexistent/truth.exr"), "{e}");
    }
}
