//! A still rendered a band of rows at a time ([`render_bands`]): the
//! room's model and radiosity once, then per band the Pixel Data Array and
//! the composite, handed to the caller (who streams them to a file) and
//! dropped. The memory a render holds is then the photo, the model and one
//! band's data, whatever the image's size; the pixels are the whole
//! frame's, bit for bit (a band's data reaches the seams filter's
//! neighbourhood past its rows, as a crop's does).

use super::*;
use crate::image_io::PixelRect;

/// Bytes a band's pixel takes while it is rendered and written, from what
/// a band holds (pixel data ~90, composite layers 68, the EXR's channel
/// planes 92 and their tiles in flight ~90; `cargo bench --bench plate`
/// measures the peaks): what [`band_rows`] divides a memory budget by.
pub const BYTES_PER_BAND_PIXEL: u64 = 340;

/// Bytes a render holds whatever its bands, per pixel of the frame: the
/// photo as read and as the stages read it (12 each), the photo's patch
/// per pixel while the model is built (4), the edge candidates (1).
pub const BYTES_PER_FRAME_PIXEL: u64 = 29;

/// Rows per band for a `width` × `height` frame under `budget` bytes:
/// what is left after the frame's share, in whole 64-row tiles (the
/// EXR's, so that a band ends where a row of tiles does), at least one.
pub fn band_rows(width: u32, height: u32, budget: u64) -> u32 {
    let frame = BYTES_PER_FRAME_PIXEL * width as u64 * height as u64;
    // The process itself, the scene and its model: ~200 MB measured on the
    // lounge (the largest example), kept aside.
    let left = budget.saturating_sub(frame + (200 << 20));
    let rows = left / (BYTES_PER_BAND_PIXEL * width.max(1) as u64);
    let tiles = (rows / 64).max(1);
    (tiles * 64).min(height.div_ceil(64) as u64 * 64) as u32
}

/// The memory a render may hold by default: half what the machine has
/// available, at most 1.5 GB (a 24-megapixel plate renders in bands of
/// 256 rows under it), at least 256 MB.
pub fn default_memory() -> u64 {
    let available = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map_or(u64::MAX, |kb| kb * 1024);
    (available / 2).clamp(256 << 20, 1_500_000_000)
}

/// Bytes from `4G`, `1.5G`, `800M`, `64K` or a plain number (decimal
/// units, as `free -h` and `--memory` elsewhere read them loosely; `Gi`,
/// `Mi`, `Ki` are binary).
pub fn parse_memory(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let scale: f64 = match unit.trim().to_ascii_lowercase().trim_end_matches('b') {
        "" => 1.0,
        "k" => 1e3,
        "m" => 1e6,
        "g" => 1e9,
        "t" => 1e12,
        "ki" => 1024.0,
        "mi" => 1024.0 * 1024.0,
        "gi" => 1024.0 * 1024.0 * 1024.0,
        u => return Err(format!("unknown unit '{u}': give e.g. 4G, 800M")),
    };
    let n: f64 = (number.trim().parse())
        .map_err(|_| format!("'{number}' is not a number: give e.g. 4G, 800M"))?;
    let bytes = n * scale;
    if !(64e6..1e15).contains(&bytes) {
        return Err("give at least 64M (and less than a petabyte)".to_string());
    }
    Ok(bytes as u64)
}

/// What takes each band: its composite and the frame's rows of it to use.
pub type BandSink<'a> = dyn FnMut(&Composite, (u32, u32)) -> Result<()> + 'a;

/// Renders `scene` over `photo` as [`render`] does, `rows` rows at a time
/// (of the crop, when one is set): `sink` takes each band in order, as a
/// composite and the band's rows of the frame that it holds (it may hold
/// more: the band's margin; its columns are the frame's). The output's
/// composite holds no pixels, only the counts over every band.
pub fn render_bands(
    scene: &Scene,
    photo: &Image,
    settings: &RenderSettings,
    rows: u32,
    times: &mut StageTimes,
    sink: &mut BandSink,
) -> Result<RenderOutput> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let image = (settings.pda.crop)
        .and_then(|c| c.pixels(w, h))
        .unwrap_or(PixelRect::full(w, h));
    let bands: Vec<(u32, u32)> = (image.y0..image.y1)
        .step_by(rows.max(1) as usize)
        .map(|y| (y, (y + rows.max(1)).min(image.y1)))
        .collect();
    let (reachable, dropped) = without_unreachable_objects(scene);
    if !reachable.as_ref().unwrap_or(scene).changes_the_photo() {
        // The photo is the image: each band is its rows.
        let mut out = render(scene, photo, settings, times)?;
        for &band in &bands {
            sink(&out.composite, band)?;
        }
        out.composite = Composite {
            copied: image.pixel_count(),
            ..Composite::empty()
        };
        return Ok(out);
    }
    let scene = reachable.as_ref().unwrap_or(scene);
    let mut session = Session::begin(scene, photo, settings, times, false, Some(bands[0]))?;
    session.run.left_out.extend(dropped);
    let mut counts = Composite::empty();
    let mut pda_bytes = 0;
    let mut per_band = StageTimes::default();
    let last_row = bands.last().map_or(0, |b| b.1);
    for (k, &(y0, y1)) in bands.iter().enumerate() {
        if k > 0 {
            // A time budget not yet spent on rounds: this band's share of
            // what is left, by its rows.
            session.run.time_share = (y1 - y0) as f64 / (last_row - y0).max(1) as f64;
            session.move_to_band((y0, y1), &mut per_band);
        }
        let timed = session.prepared.settings.residual.time.is_some();
        if let Some(stats) = session
            .run
            .residual_stats
            .filter(|s| timed && s.pixels() > 0)
        {
            // Every band runs the rounds of the first that sampled any
            // pixel: a time budget gives the frame one number of rounds,
            // as `--samples` reproduces.
            session.prepared.settings.residual = crate::residual::ResidualSettings {
                samples: stats.rounds,
                time: None,
            };
        }
        pda_bytes = pda_bytes.max(session.pose.pda.memory_bytes());
        counts = Composite::empty()
            .with_counts(&session.composite)
            .added(&counts);
        per_band.time("write bands", || sink(&session.composite, (y0, y1)))?;
    }
    times.absorb(per_band);
    let mut out = session.into_output();
    out.composite = counts;
    out.pda_bytes = pda_bytes;
    Ok(out)
}

impl Session {
    /// Moves a still to the band `rows`: its Pixel Data Array traced and
    /// composited there, the model and radiosity kept.
    fn move_to_band(&mut self, rows: (u32, u32), times: &mut StageTimes) {
        self.run.band = Some(rows);
        // The last band's data goes before the next is built.
        self.pose.pda = PixelDataArray::default();
        self.composite = Composite::empty();
        self.trace_pixels(times);
        self.recomposite(times, &[]);
    }
}

impl Composite {
    /// This composite with `other`'s counts.
    fn with_counts(self, other: &Composite) -> Composite {
        Composite {
            copied: other.copied,
            ratio_fallbacks: other.ratio_fallbacks,
            clamped: other.clamped,
            ..self
        }
    }

    /// Its counts plus `other`'s.
    fn added(self, other: &Composite) -> Composite {
        Composite {
            copied: self.copied + other.copied,
            ratio_fallbacks: self.ratio_fallbacks + other.ratio_fallbacks,
            clamped: self.clamped + other.clamped,
            ..self
        }
    }
}
