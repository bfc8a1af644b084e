//! An EXR written a band of rows at a time ([`ExrStream`]): a plate of
//! tens of megapixels is never held whole, as pixels or as encoded bytes.
//! The file is the one [`write_exr_with`](super::write_exr_with) writes for
//! the same pixels, byte for byte (same header, 64 × 64 RLE tiles in
//! increasing rows). A thread of its own cuts each row of tiles as its
//! rows arrive, compresses them in parallel (the `exr` crate's block
//! encoder, on rayon) and writes them, while the caller renders the next
//! band.

use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use exr::block::chunk::Chunk;
use exr::block::writer::ChunksWriter;
use exr::block::{BlockIndex, UncompressedBlock};

use exr::prelude as x;

use super::frames::{PixelRect, frame_image};
use crate::error::{Error, Result};

/// Rows of every channel, a plane per channel in [`ExrStream::channels`]' order.
struct Band {
    rows: u32,
    planes: Vec<Vec<f32>>,
}

/// An EXR file being written band by band, at a temporary name until
/// [`ExrStream::finish`] renames it into place (removed on failure, or by
/// the signal handler through [`crate::util::cleanup`]).
pub struct ExrStream {
    path: PathBuf,
    tmp: PathBuf,
    /// Channel names as the file orders them (sorted).
    channels: Vec<String>,
    width: u32,
    height: u32,
    /// Rows sent so far.
    sent: u32,
    sender: Option<SyncSender<Band>>,
    worker: Option<JoinHandle<std::result::Result<(), String>>>,
}

impl ExrStream {
    /// Starts `path`, a float EXR of `window` (a data window in a
    /// `width` × `height` display window: `meta.window`, or the whole frame)
    /// holding `channels`.
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        channels: &[String],
        meta: &super::ExrMeta,
    ) -> Result<ExrStream> {
        let window = meta.window.unwrap_or(PixelRect::full(width, height));
        let mut sorted = channels.to_vec();
        sorted.sort();
        let headers = headers(width, height, window, &sorted, meta);
        let (file, tmp) = super::fail_for_tests(path)
            .and_then(|()| super::temp_beside(path))
            .map_err(|e| Error::io(path, &e))?;
        // One band in flight: the renderer works on the next while this one is encoded.
        let (sender, receiver) = sync_channel::<Band>(1);
        let (w, count) = (window.width(), sorted.len());
        let worker = std::thread::Builder::new()
            .name("exr writer".into())
            .spawn(move || encode(file, headers, w, count, receiver))
            .map_err(|e| Error::io(path, &e))?;
        Ok(ExrStream {
            path: path.to_path_buf(),
            tmp,
            channels: sorted,
            width: window.width(),
            height: window.height(),
            sent: 0,
            sender: Some(sender),
            worker: Some(worker),
        })
    }

    /// The channel names in the order [`ExrStream::push`] takes their planes.
    pub fn channels(&self) -> &[String] {
        &self.channels
    }

    /// Rows not yet sent.
    pub fn rows_left(&self) -> u32 {
        self.height - self.sent
    }

    /// The next `rows` rows of the data window: a plane per channel of
    /// `rows` × the window's width samples, in [`ExrStream::channels`] order.
    pub fn push(&mut self, rows: u32, planes: Vec<Vec<f32>>) -> Result<()> {
        let expected = rows as usize * self.width as usize;
        assert!(
            planes.len() == self.channels.len()
                && planes.iter().all(|p| p.len() == expected)
                && rows <= self.rows_left(),
            "a band of the wrong shape for {}",
            self.path.display()
        );
        self.sent += rows;
        let sent = self
            .sender
            .as_ref()
            .is_some_and(|s| s.send(Band { rows, planes }).is_ok());
        if sent {
            Ok(())
        } else {
            // The writer stopped: its error says why.
            Err(self.stop().err().unwrap_or_else(|| {
                Error::file(&self.path, "the EXR writer stopped early".to_string())
            }))
        }
    }

    /// Ends the file once every row is sent, and renames it into place.
    pub fn finish(mut self) -> Result<()> {
        if self.sent != self.height {
            let message = format!("{} of {} rows written", self.sent, self.height);
            let _ = self.stop();
            return Err(Error::file(&self.path, message));
        }
        self.stop()?;
        let renamed = std::fs::rename(&self.tmp, &self.path);
        crate::util::cleanup::unregister(&self.tmp);
        renamed.map_err(|e| {
            let _ = std::fs::remove_file(&self.tmp);
            Error::io(&self.path, &e)
        })
    }

    /// Closes the channel and waits for the writer; on failure the temporary goes.
    fn stop(&mut self) -> Result<()> {
        self.sender = None;
        let result = match self.worker.take().map(|w| w.join()) {
            None | Some(Ok(Ok(()))) => Ok(()),
            Some(Ok(Err(e))) => Err(Error::file(&self.path, format!("could not write: {e}"))),
            Some(Err(_)) => Err(Error::file(&self.path, "the EXR writer failed".to_string())),
        };
        if result.is_err() {
            let _ = std::fs::remove_file(&self.tmp);
            crate::util::cleanup::unregister(&self.tmp);
        }
        result
    }
}

impl Drop for ExrStream {
    /// Unfinished (an error elsewhere, a panic): no partial file is left.
    fn drop(&mut self) {
        if self.worker.is_some() {
            let _ = self.stop();
            let _ = std::fs::remove_file(&self.tmp);
            crate::util::cleanup::unregister(&self.tmp);
        }
    }
}

/// The header [`write_exr_with`](super::write_exr_with) writes for these
/// channels: the crate infers it from a layer whose planes are empty.
fn headers(
    width: u32,
    height: u32,
    window: PixelRect,
    sorted: &[String],
    meta: &super::ExrMeta,
) -> exr::meta::Headers {
    let list: x::SmallVec<[x::AnyChannel<x::FlatSamples>; 4]> = sorted
        .iter()
        .map(|name| x::AnyChannel::new(name.as_str(), x::FlatSamples::F32(Vec::new())))
        .collect();
    use x::WritableImage;
    frame_image(width, height, window, meta, list)
        .write()
        .infer_meta_data()
}

/// The writer thread: each row of tiles compressed in parallel once its
/// rows have arrived, and written in order.
fn encode(
    file: std::fs::File,
    headers: exr::meta::Headers,
    width: u32,
    channels: usize,
    receiver: Receiver<Band>,
) -> std::result::Result<(), String> {
    use rayon::prelude::*;
    let blocks: Vec<(usize, BlockIndex)> =
        exr::block::enumerate_ordered_header_block_indices(&headers).collect();
    let result = exr::block::write(BufWriter::new(file), headers, true, |meta, chunks| {
        // Rows held from `written`; `rows` of them from `first` not yet written.
        let (mut held, mut written) = (vec![Vec::new(); channels], 0usize);
        let (mut first, mut rows) = (0usize, 0usize);
        let mut next = 0;
        let w = width as usize;
        for band in receiver {
            // Rows already written go now, in one move (not one per row of tiles).
            let done = first - written;
            for (plane, new) in held.iter_mut().zip(band.planes) {
                plane.drain(..done * w);
                plane.extend(new);
            }
            written = first;
            rows += band.rows as usize;
            while next < blocks.len() {
                let y = blocks[next].1.pixel_position.y();
                let end = blocks[next..]
                    .iter()
                    .position(|(_, b)| b.pixel_position.y() != y)
                    .map_or(blocks.len(), |k| next + k);
                let h = blocks[next].1.pixel_size.height();
                if y + h > first + rows {
                    break;
                }
                let compressed: Vec<exr::error::Result<(usize, Chunk)>> = blocks[next..end]
                    .par_iter()
                    .map(|(index, block)| {
                        let list = &meta.headers[block.layer].channels;
                        let data = UncompressedBlock::from_lines(list, *block, |line| {
                            let at = (line.location.position.y() - written) * w
                                + line.location.position.x();
                            let plane = &held[line.location.channel];
                            let samples = &plane[at..at + line.location.sample_count];
                            line.write_samples_from_slice(samples)
                                .expect("a line of the block's width");
                        });
                        Ok((*index, data.compress_to_chunk(&meta.headers)?))
                    })
                    .collect();
                for c in compressed {
                    let (index, chunk) = c?;
                    chunks.write_chunk(index, chunk)?;
                }
                next = end;
                let drop = (y + h - first).min(rows);
                (first, rows) = (first + drop, rows - drop);
            }
        }
        if next < blocks.len() {
            return Err(exr::error::Error::Invalid(
                "the frame ended before its last row".into(),
            ));
        }
        Ok(())
    });
    result.map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests;
