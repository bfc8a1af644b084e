//! Renders that converge: what the kept solution misses, estimated per
//! pixel by Monte Carlo in rounds, on the pixels the change touches.
//!
//! The composite's interpolated light is the control variate (Lafortune &
//! Willems 1995; Rousselle, Jarosz & Novák 2016): it is exact where the
//! patches are finer than the change, and what it misses is smooth at the
//! scale of the objects. Each round adds rays at every pixel the objects
//! change, so that every extra second buys accuracy:
//! - an object's own pixels gather their indirect irradiance at the pixel
//!   (cosine-distributed rays; a ray that meets a real surface takes the
//!   photo where the camera sees that point, changed as the compositor
//!   changes it, the model's radiosity elsewhere; one that meets an object
//!   its diffuse radiosity) instead of interpolating it from the vertices;
//! - real pixels near the objects trace the objects' change at their own
//!   point (rays into the objects' bounding cones, each reading what it
//!   meets of the objects less the room it hides, as the near grid does at
//!   its points): the near grid's per-pixel limit.
//!
//! Directions come from Owen-scrambled Sobol sequences keyed by the
//! frame's pixel index, and round `r` takes their points `r·n..(r+1)·n`:
//! the image is bit-identical whatever the thread count and in bands and
//! tiles. Each pixel keeps the variance of its rays' contributions, which
//! gives the noise layer and the frame's estimated remaining noise.
//! Further bounces keep the kept solution's ΔB (smooth, already cheap).

use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::object_shading::{Lamps, ObjectShading};
use crate::pda::PixelDataArray;
use crate::radiosity::ChangeSampler;

mod edges;
mod objects;
mod room;
mod shadows;

/// How many rounds a render runs.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct ResidualSettings {
    /// Rounds of samples (0 with no time: the kept solution alone, as before).
    pub samples: u32,
    /// Seconds the whole render may take: rounds run while the next one fits
    /// (at most `samples` of them when that is not 0).
    pub time: Option<f64>,
}

impl ResidualSettings {
    /// Whether any round may run.
    pub fn enabled(&self) -> bool {
        self.samples > 0 || self.time.is_some_and(|t| t > 0.0)
    }
}

/// The share of `--time` kept for what follows the rounds.
const TIME_RESERVE: f64 = 0.05;

/// Most rounds a render runs: the Sobol sequences' indices stay below 2^16
/// (a round takes at most 64 points of each).
pub const MAX_SAMPLES: u32 = 1024;

/// What the rounds found, per pixel.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PixelResidual {
    /// Per virtual sample of the pixel data (plain object pixels), the
    /// indirect irradiance gathered there (None: not gathered).
    pub object_irradiance: Vec<Option<DVec3>>,
    /// Per virtual sample, the radiance of its material sampled over its
    /// pixel (None: clay, or not sampled).
    pub object_radiance: Vec<Option<DVec3>>,
    /// Per real point of the pixel data, the correction to its
    /// interpolated indirect irradiance (None: the near grid's, or none).
    pub room_correction: Vec<Option<Vec3>>,
    /// Real points an object's shadow edge crosses, sorted: per light whose
    /// edge it is, the visible fraction through all geometry averaged over
    /// the pixel's footprint.
    pub shadow: Vec<(u32, Vec<(u8, f32)>)>,
    /// Per outline pixel of the pixel data (as its `edges`), the shares of
    /// it the objects, the room and nothing cover, and the room's part's
    /// mean radiance (None: no ray met the room).
    pub edge_shares: Vec<Option<([f32; 3], Option<Vec3>)>>,
    /// Per outline pixel, the objects' indirect irradiance gathered at its
    /// first sub-pixel on an object (None: none is).
    pub edge_irradiance: Vec<Option<DVec3>>,
    /// Per outline pixel, the mean radiance of the objects' part of it,
    /// their materials sampled over the pixel (None: clay, or not sampled).
    pub edge_radiance: Vec<Option<DVec3>>,
    /// Per pixel held (as the pixel data's per-pixel arrays), the estimated
    /// standard deviation of its radiance (0 where nothing was sampled).
    pub noise: Vec<f32>,
    pub stats: ResidualStats,
}

/// A residual's report.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct ResidualStats {
    pub rounds: u32,
    pub rays: u64,
    pub seconds: f64,
    /// Pixels sampled: objects' and real ones near them.
    pub object_pixels: usize,
    pub room_pixels: usize,
    pub shadow_pixels: usize,
    pub edge_pixels: usize,
    /// Root mean square of the sampled pixels' estimated noise (radiance),
    /// and that over their mean value.
    pub noise_rms: f64,
    pub noise_relative: f64,
}

impl ResidualStats {
    /// These and `other`'s, over the pixels of both (a still's bands).
    pub fn and(&self, other: &ResidualStats) -> ResidualStats {
        let (a, b) = (self.pixels() as f64, other.pixels() as f64);
        let mean = |x: f64, y: f64| (x * a + y * b) / (a + b).max(1.0);
        let squares = mean(self.noise_rms.powi(2), other.noise_rms.powi(2));
        let values = mean(
            self.noise_rms / self.noise_relative.max(1e-30),
            other.noise_rms / other.noise_relative.max(1e-30),
        );
        ResidualStats {
            rounds: self.rounds.max(other.rounds),
            rays: self.rays + other.rays,
            seconds: self.seconds + other.seconds,
            object_pixels: self.object_pixels + other.object_pixels,
            room_pixels: self.room_pixels + other.room_pixels,
            shadow_pixels: self.shadow_pixels + other.shadow_pixels,
            edge_pixels: self.edge_pixels + other.edge_pixels,
            noise_rms: squares.sqrt(),
            noise_relative: if values > 0.0 {
                squares.sqrt() / values
            } else {
                0.0
            },
        }
    }

    /// Pixels sampled.
    pub fn pixels(&self) -> usize {
        self.object_pixels + self.room_pixels + self.shadow_pixels + self.edge_pixels
    }
}

/// What the rounds read.
pub struct ResidualInput<'a> {
    pub pda: &'a PixelDataArray,
    /// The augmented scene as the objects' shading reads it.
    pub shading: &'a ObjectShading<'a>,
    /// The objects' change towards the room's points (None: no object).
    pub room: Option<&'a ChangeSampler<'a>>,
    /// The room's change per vertex the composite interpolates (what the
    /// per-pixel change corrects), numbered as the shading's patches' vertices.
    pub coarse: &'a [DVec3],
    pub settings: ResidualSettings,
    /// When the render began (for `settings.time`).
    pub started: Instant,
}

/// A pixel's running sums over its rays.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    sum: DVec3,
    /// Sum of the squared luminance of each ray's contribution.
    squares: f64,
    rays: u32,
}

impl Sums {
    fn add(&mut self, x: DVec3) {
        self.sum += x;
        self.squares += luminance(x) * luminance(x);
        self.rays += 1;
    }

    fn mean(&self) -> DVec3 {
        self.sum / self.rays.max(1) as f64
    }

    /// The standard deviation of the mean's luminance: the rays' sample
    /// variance over their number (for stratified rays an upper bound).
    fn deviation(&self) -> f64 {
        let n = self.rays as f64;
        if n < 2.0 {
            return 0.0;
        }
        let m = luminance(self.mean());
        ((self.squares / n - m * m).max(0.0) / (n - 1.0)).sqrt()
    }
}

/// A camera ray through a jittered point of a pixel, for one sub-sample of
/// a round.
struct SubPixel {
    /// Its index in the pixel's sequence (round × per round + j).
    index: u32,
    /// The point in the image it passes through.
    at: (f64, f64),
    ray: crate::camera::Ray,
    traced: crate::trace::TraceRay,
}

/// Round `round`'s `per_round` camera rays through `pixel`: Owen-scrambled
/// Sobol points of the pixel keyed by `key`, round `r` taking points
/// `r·n..(r+1)·n`.
fn subpixels(
    input: &ResidualInput,
    pixel: u32,
    key: u64,
    round: u32,
    per_round: u32,
) -> impl Iterator<Item = SubPixel> {
    let camera = input.shading.camera;
    let width = input.pda.width;
    let (col, row) = ((pixel % width) as f64, (pixel / width) as f64);
    (0..per_round).map(move |j| {
        let index = round * per_round + j;
        let [u1, u2, _, _] = sobol_burley::sample_4d(index, 0, key as u32).map(f64::from);
        let at = (col + u1, row + u2);
        let ray = camera.ray(at.0, at.1);
        let traced = crate::trace::TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3());
        SubPixel {
            index,
            at,
            ray,
            traced,
        }
    })
}

fn luminance(x: DVec3) -> f64 {
    x.dot(DVec3::new(0.2126, 0.7152, 0.0722))
}

/// Runs up to `most` rounds over every kind of task (fewer where the time
/// budget ends them), then the shadow edges' own rounds up to the least
/// every render takes; returns the rounds run and the rays traced.
fn run_rounds(
    input: &ResidualInput,
    (objects, room, shadows, edges): (
        &mut [objects::Task],
        &mut [room::Task],
        &mut [shadows::Task],
        &mut [edges::Task],
    ),
    most: u32,
) -> (u32, u64) {
    let (mut rounds, mut rays) = (0, 0u64);
    // The rect lights a sample may meet, listed once for every pixel.
    let lamps = input.shading.lamps();
    while rounds < most {
        let round = Instant::now();
        rays += (objects.par_iter_mut())
            .map(|t| objects::sample(input, t, (rounds, &lamps)))
            .sum::<u64>();
        rays += (room.par_iter_mut())
            .map(|t| room::sample(input, t, (rounds, &lamps)))
            .sum::<u64>();
        rays += (shadows.par_iter_mut())
            .map(|t| shadows::sample(input, t, rounds))
            .sum::<u64>();
        rays += (edges.par_iter_mut())
            .map(|t| edges::sample(input, t, (rounds, &lamps)))
            .sum::<u64>();
        rounds += 1;
        if let Some(limit) = input.settings.time {
            // The next round costs about what this one did; what follows
            // the rounds (the composite, writing) is kept a twentieth.
            let next = input.started.elapsed().as_secs_f64() + round.elapsed().as_secs_f64();
            if next > limit * (1.0 - TIME_RESERVE) {
                break;
            }
        }
    }
    // The shadow edges' own rounds, continuing their sequence.
    for round in rounds..shadows::LEAST_ROUNDS {
        rays += (shadows.par_iter_mut())
            .map(|t| shadows::sample(input, t, round))
            .sum::<u64>();
    }
    (rounds, rays)
}

/// Runs the rounds the settings ask for. Without rounds, the pixels a
/// point light's hard shadow edge crosses are still averaged over their
/// footprint, at 16 points each (None: no rounds and no such pixel).
pub fn estimate(input: &ResidualInput) -> Option<PixelResidual> {
    let settings = input.settings;
    let enabled = settings.enabled();
    let began = Instant::now();
    let mut shadows = shadows::tasks(input);
    if !enabled && shadows.is_empty() {
        return None;
    }
    let (mut objects, mut room, mut edges) = match enabled {
        true => (
            objects::tasks(input),
            room::tasks(input),
            edges::tasks(input),
        ),
        false => Default::default(),
    };
    let nothing = objects.is_empty() && room.is_empty() && shadows.is_empty() && edges.is_empty();
    let most = match settings.samples {
        // No pixel to sample: no round (a time budget would run them all).
        _ if nothing || !enabled => 0,
        0 => MAX_SAMPLES,
        n => n.min(MAX_SAMPLES),
    };
    let (rounds, rays) = run_rounds(
        input,
        (&mut objects, &mut room, &mut shadows, &mut edges),
        most,
    );
    // Without rounds only the shadow edges hold anything (read with `get`).
    let per = |n: usize| if enabled { n } else { 0 };
    let (points, samples, edge_count) = (
        per(input.pda.real.points.len()),
        per(input.pda.virtual_samples.points.len()),
        per(input.pda.edges.len()),
    );
    let mut out = PixelResidual {
        object_irradiance: vec![None; samples],
        object_radiance: vec![None; samples],
        room_correction: vec![None; points],
        shadow: Vec::new(),
        edge_shares: vec![None; edge_count],
        edge_irradiance: vec![None; edge_count],
        edge_radiance: vec![None; edge_count],
        noise: vec![0.0; per(input.pda.real_index.len())],
        stats: ResidualStats {
            rounds,
            rays,
            object_pixels: objects.len(),
            room_pixels: room.len(),
            shadow_pixels: shadows.len(),
            edge_pixels: edges.len(),
            ..ResidualStats::default()
        },
    };
    let first = input.pda.first_pixel();
    let (mut squares, mut values) = (0.0, 0.0);
    for t in &objects {
        let objects::Found {
            irradiance: h,
            radiance,
            noise,
            value,
        } = objects::result(input, t);
        match t.source {
            objects::Source::Plain(k) => {
                out.object_irradiance[k as usize] = Some(h);
                out.object_radiance[k as usize] = radiance;
            }
            objects::Source::Edge(e, _) => {
                out.edge_irradiance[e as usize] = Some(h);
                out.edge_radiance[e as usize] = radiance;
            }
        }
        out.noise[t.pixel as usize - first] = noise as f32;
        (squares, values) = (squares + noise * noise, values + value);
    }
    for t in &room {
        let (c, noise) = room::result(input, t);
        out.room_correction[t.point as usize] = Some(c.as_vec3());
        out.noise[t.pixel as usize - first] = noise as f32;
        squares += noise * noise;
        values += luminance(input.shading.photo.pixels[t.pixel as usize].as_dvec3());
    }
    // A pixel both near an object and on its shadow's edge: the noises add.
    let mut noise = std::mem::take(&mut out.noise);
    for t in &shadows {
        let (v, n) = shadows::result(input, t);
        if let Some(v) = v {
            out.shadow.push((t.point, v));
        }
        if let Some(slot) = noise.get_mut(t.pixel as usize - first) {
            let before = *slot as f64;
            *slot = (before * before + n * n).sqrt() as f32;
        }
        squares += n * n;
        values += luminance(input.shading.photo.pixels[t.pixel as usize].as_dvec3());
    }
    for t in &edges {
        let edges::Shares {
            shares,
            room,
            deviation,
        } = edges::result(input, t);
        out.edge_shares[t.edge as usize] = Some((shares, room));
        // The shares' noise times the contrast of the pixel's parts, taken
        // as the photo's value there.
        let value = luminance(input.shading.photo.pixels[t.pixel as usize].as_dvec3());
        let n = deviation * value;
        let slot = &mut noise[t.pixel as usize - first];
        *slot = (*slot as f64).hypot(n) as f32;
        squares += n * n;
        values += value;
    }
    out.noise = noise;
    out.shadow.sort_unstable_by_key(|s| s.0);
    let count = out.stats.pixels().max(1) as f64;
    out.stats.noise_rms = (squares / count).sqrt();
    out.stats.noise_relative = out.stats.noise_rms / (values / count).max(1e-12);
    out.stats.seconds = began.elapsed().as_secs_f64();
    Some(out)
}
