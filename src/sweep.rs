//! Error against run time: renders a variant (or a motion) over a grid of
//! quality settings, measures each against the reference, and marks the
//! Pareto front (no other setting both faster and closer).

use std::time::Instant;

use crate::compare::{Comparison, Skill, compare, skill};
use crate::error::{Error, Result};
use crate::image_io::{Image, read_image};
use crate::model::TransportMethod;
use crate::pda::PdaSettings;
use crate::render::{PatchSize, RenderSettings, render};
use crate::renderer::Renderer;
use crate::scene::Scene;
use crate::util::stages::StageTimes;

mod peer;
mod plot;
mod table;
pub use peer::{Peer, read_peer};
pub use plot::plot;
pub use table::{SweepTable, merge_tables};

/// Which renderer a grid point uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SweepMethod {
    /// Per-pixel differential rendering (Grosch): every setting applies.
    Pda,
    /// The texture path (Loscos) with its smallest leaf in pixel footprints;
    /// patch size and ε apply, shadow rays and supersampling do not.
    Texture { min_leaf_pixels: f64 },
    /// Another renderer's image read from a peer's CSV (`--peer`): no
    /// setting applies.
    Peer,
}

/// One point of the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepSettings {
    pub method: SweepMethod,
    /// 2^min_level shadow rays everywhere, 2^penumbra_level in penumbra.
    pub min_level: usize,
    pub penumbra_level: usize,
    pub supersample: u32,
    /// None: the automatic patch size.
    pub patch_size: Option<f64>,
    /// The virtual objects' patch size, metres.
    pub virtual_patch_size: f64,
    /// Hierarchical radiosity's link threshold (the solve tolerance's knob).
    pub epsilon: f64,
    /// Rounds of per-pixel samples over the kept solution (`--samples`;
    /// the pixel path's).
    pub samples: u32,
}

impl SweepSettings {
    /// The texture path's settings at this point.
    pub(crate) fn texture_settings(&self) -> Option<crate::relight::TextureSettings> {
        match self.method {
            SweepMethod::Pda | SweepMethod::Peer => None,
            SweepMethod::Texture { min_leaf_pixels } => Some(crate::relight::TextureSettings {
                patch_size: self.patch_size,
                link_epsilon: self.epsilon,
                min_leaf_pixels,
                ..Default::default()
            }),
        }
    }

    pub(crate) fn render_settings(&self) -> RenderSettings {
        let d = RenderSettings::default();
        RenderSettings {
            model: crate::model::ModelSettings {
                transport: TransportMethod::Hierarchical {
                    epsilon: self.epsilon,
                },
                ..d.model
            },
            patch_size: self.patch_size.map_or(PatchSize::Auto, PatchSize::Metres),
            virtual_patch_size: self.virtual_patch_size,
            pda: PdaSettings {
                min_level: self.min_level,
                penumbra_level: self.penumbra_level,
                supersample: self.supersample,
                crop: None,
            },
            residual: crate::residual::ResidualSettings {
                samples: self.samples,
                time: None,
            },
            ..d
        }
    }

    /// The renderer's defaults as a grid point.
    pub fn defaults() -> SweepSettings {
        let d = RenderSettings::default();
        let epsilon = match d.model.transport {
            TransportMethod::Hierarchical { epsilon } => epsilon,
            TransportMethod::Full => crate::radiosity::DEFAULT_LINK_EPSILON,
        };
        SweepSettings {
            method: SweepMethod::Pda,
            min_level: d.pda.min_level,
            penumbra_level: d.pda.penumbra_level,
            supersample: d.pda.supersample,
            patch_size: match d.patch_size {
                PatchSize::Auto => None,
                PatchSize::Metres(m) => Some(m),
            },
            virtual_patch_size: d.virtual_patch_size,
            epsilon,
            samples: d.residual.samples,
        }
    }
}

/// The rounds of per-pixel samples the grid tries at the default settings:
/// `quick`, two; otherwise doublings from 1 to 64 (the curve that keeps
/// falling as time grows).
fn sample_counts(quick: bool) -> Vec<u32> {
    if quick {
        vec![4, 16]
    } else {
        (0..7).map(|k| 1 << k).collect()
    }
}

/// The grid: `quick` is six settings from cheapest to dearest and the
/// defaults with 4 and 16 rounds of per-pixel samples (a smoke check);
/// otherwise the defaults with 1 to 64 rounds (7 settings), and shadow rays 1…256 × supersampling 1…4 × three patch
/// sizes (auto, 0.5 m, 0.25 m: the room's fine mesh) × two radiosity
/// thresholds (120 settings), and at the default rays and supersampling
/// the objects' mesh twice as fine and twice as coarse as the default
/// (8 more: it sets how finely their indirect light and the room's
/// change near them are resolved). With `texture`, the texture path joins: its
/// defaults in the quick grid, otherwise smallest leaves of 1.5, 3 and 6
/// pixels × the automatic and 0.5 m starting mesh.
pub fn grid(quick: bool, texture: bool) -> Vec<SweepSettings> {
    let d = SweepSettings::defaults();
    let texture_default = crate::relight::TextureSettings::default();
    if quick {
        let mut out: Vec<SweepSettings> = [
            (0, 0, 1),
            (0, 2, 1),
            (1, 3, 2),
            (2, 4, 4),
            (3, 5, 3),
            (4, 6, 4),
        ]
        .into_iter()
        .map(|(min_level, penumbra_level, supersample)| SweepSettings {
            min_level,
            penumbra_level,
            supersample,
            ..d
        })
        .collect();
        out.extend(
            sample_counts(true)
                .into_iter()
                .map(|samples| SweepSettings { samples, ..d }),
        );
        if texture {
            out.push(SweepSettings {
                method: SweepMethod::Texture {
                    min_leaf_pixels: texture_default.min_leaf_pixels,
                },
                supersample: 1,
                ..d
            });
        }
        return out;
    }
    let mut out: Vec<SweepSettings> = (sample_counts(false).into_iter())
        .map(|samples| SweepSettings { samples, ..d })
        .collect();
    for (min_level, penumbra_level) in [(0, 0), (0, 2), (1, 4), (2, 4), (4, 8)] {
        for supersample in 1..=4 {
            for patch_size in [None, Some(0.5), Some(0.25)] {
                for epsilon in [0.008, d.epsilon] {
                    out.push(SweepSettings {
                        method: SweepMethod::Pda,
                        min_level,
                        penumbra_level,
                        supersample,
                        patch_size,
                        epsilon,
                        ..d
                    });
                }
            }
        }
    }
    for virtual_patch_size in [0.5 * d.virtual_patch_size, 2.0 * d.virtual_patch_size] {
        for patch_size in [None, Some(0.5)] {
            for epsilon in [0.008, d.epsilon] {
                out.push(SweepSettings {
                    virtual_patch_size,
                    patch_size,
                    epsilon,
                    ..d
                });
            }
        }
    }
    if texture {
        for min_leaf_pixels in [1.5, 3.0, 6.0] {
            for patch_size in [None, Some(0.5)] {
                out.push(SweepSettings {
                    method: SweepMethod::Texture { min_leaf_pixels },
                    supersample: 1,
                    patch_size,
                    ..d
                });
            }
        }
    }
    out
}

/// One measured setting.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRow {
    /// The setting's place in the whole grid (a shard runs a part of it).
    pub index: usize,
    pub settings: SweepSettings,
    /// A peer's label (`--peer LABEL=FILE.csv`); None for arlux's rows.
    pub peer: Option<String>,
    /// Seconds per stage, summed over the run (a motion: over all poses).
    pub stages: Vec<(String, f64)>,
    pub seconds: f64,
    /// The median and the slowest of the `repeats` runs (the spread a
    /// shared machine gives; equal to `seconds` for one run).
    pub seconds_median: f64,
    pub seconds_max: f64,
    /// Against the reference (a motion: the mean over its poses with one).
    pub rmse: f64,
    /// None where a reference is black (relative error undefined) or an
    /// image equals its reference (PSNR infinite).
    pub relative_rmse: Option<f64>,
    pub psnr_srgb_db: Option<f64>,
    /// Images compared.
    pub compared: usize,
    /// Where the change is ([`crate::compare::skill`], as `compare --photo`
    /// computes it; a motion: the mean over its poses): the skill (None
    /// where no pose changes anything), the RMSE over the pixels the change
    /// touches and their number.
    pub skill: Option<f64>,
    pub rmse_changed: f64,
    pub n_changed: usize,
    /// The best skill the reference's own noise allows
    /// ([`crate::compare::skill_floor`]; None: the scene declares none).
    pub skill_floor: Option<f64>,
    pub pareto: bool,
}

impl SweepRow {
    /// The error the front and the plot use: 1 − skill where the change
    /// is, or the whole frame's RMSE when nothing changed.
    pub fn error(&self) -> f64 {
        self.skill.map_or(self.rmse, |s| 1.0 - s)
    }
}

/// What to render at each setting.
pub enum Target<'a> {
    Variant { name: &'a str },
    Motion { name: &'a str },
}

/// The references a sweep of `target` measures against, each read and
/// checked; an error naming the key when the variant or motion is missing,
/// has none, or one cannot be read or is not the camera's size.
pub fn reference_files(scene: &Scene, target: &Target) -> Result<Vec<std::path::PathBuf>> {
    match target {
        Target::Variant { name } => {
            let v = scene.variant(name)?;
            let Some(r) = &v.reference else {
                return Err(Error::key(
                    &scene.file,
                    format!("variant '{name}'.reference"),
                    "a sweep measures error: the variant needs a reference",
                ));
            };
            scene.check_reference(&format!("variant '{name}'.reference"), r)?;
            Ok(vec![r.clone()])
        }
        Target::Motion { name } => {
            let m = scene.motion(name)?;
            if m.references.is_empty() {
                return Err(Error::key(
                    &scene.file,
                    format!("motion '{name}'.references"),
                    "a sweep measures error: the motion needs references",
                ));
            }
            for (i, r) in m.references.iter().enumerate() {
                scene.check_reference(&format!("motion '{name}'.references[{i}]"), r)?;
            }
            Ok(m.references.clone())
        }
    }
}

/// Renders `target` of `scene` at the settings `share` of `grid` (each
/// `repeats` times, keeping the fastest), calling `progress` after each.
pub fn run(
    scene: &Scene,
    target: &Target,
    grid: &[SweepSettings],
    share: std::ops::Range<usize>,
    repeats: usize,
    mut progress: impl FnMut(usize, &SweepRow),
) -> Result<Vec<SweepRow>> {
    let grid = &grid[share.clone()];
    let photo = scene.load_photo()?;
    let files = reference_files(scene, target)?;
    let references: Vec<Image> = files
        .iter()
        .map(|r| scene.fit_size(read_image(r)?, "reference", r))
        .collect::<Result<_>>()?;
    let floor = skill_floor(scene, target, &references, &photo)?;
    // One untimed render first: the thread pool and the page cache warm up
    // there, not in whichever setting happens to come first.
    if let Some(first) = grid.first() {
        let warm = match target {
            Target::Variant { name } => scene.with_variant(name)?,
            Target::Motion { name } => scene.with_motion_pose(name, 0)?,
        };
        render(
            &warm,
            &photo,
            &first.render_settings(),
            &mut StageTimes::default(),
        )?;
    }
    let mut rows = Vec::with_capacity(grid.len());
    for (i, s) in grid.iter().enumerate() {
        // The fastest of `repeats` runs: these machines are shared, and a
        // single run's time is off by tens of milliseconds. Rendering is
        // deterministic, so the error is the same every time.
        let mut best: Option<(f64, StageTimes)> = None;
        let mut runs: Vec<f64> = Vec::new();
        let mut comparisons: Vec<Comparison> = Vec::new();
        let mut skills: Vec<Skill> = Vec::new();
        for _ in 0..repeats.max(1) {
            let mut times = StageTimes::default();
            let t0 = Instant::now();
            let images = render_target(scene, target, &photo, s, references.len(), &mut times)?;
            let seconds = t0.elapsed().as_secs_f64();
            if comparisons.is_empty() {
                comparisons = images
                    .iter()
                    .zip(&references)
                    .map(|(img, r)| compare(img, r, None))
                    .collect();
                skills = (images.iter().zip(&references))
                    .map(|(img, r)| skill(img, r, &photo))
                    .collect();
            }
            runs.push(seconds);
            if best.as_ref().is_none_or(|b| seconds < b.0) {
                best = Some((seconds, times));
            }
        }
        let (seconds, times) = best.expect("at least one run");
        runs.sort_by(f64::total_cmp);
        let seconds_median = median(&runs);
        let seconds_max = runs.last().copied().unwrap_or(seconds);
        let n = comparisons.len() as f64;
        let mut stages: Vec<(String, f64)> = Vec::new();
        for (name, d) in &times.0 {
            match stages.iter_mut().find(|(n, _)| n == name) {
                Some(s) => s.1 += d.as_secs_f64(),
                None => stages.push((name.to_string(), d.as_secs_f64())),
            }
        }
        let row = SweepRow {
            index: share.start + i,
            settings: *s,
            peer: None,
            stages,
            seconds,
            seconds_median,
            seconds_max,
            rmse: comparisons.iter().map(|c| c.rmse).sum::<f64>() / n,
            relative_rmse: comparisons
                .iter()
                .map(|c| c.relative_rmse)
                .sum::<Option<f64>>()
                .map(|s| s / n),
            psnr_srgb_db: comparisons
                .iter()
                .map(|c| c.psnr_srgb_db)
                .sum::<Option<f64>>()
                .map(|s| s / n),
            compared: comparisons.len(),
            skill: (skills.iter())
                .filter_map(|s| s.skill)
                .fold(None, |a: Option<(f64, f64)>, s| {
                    Some(a.map_or((s, 1.0), |(t, k)| (t + s, k + 1.0)))
                })
                .map(|(t, k)| t / k),
            rmse_changed: skills.iter().map(|s| s.rmse_changed).sum::<f64>() / n,
            n_changed: (skills.iter().map(|s| s.changed_pixels).sum::<usize>() as f64 / n).round()
                as usize,
            skill_floor: floor,
            pareto: false,
        };
        progress(i, &row);
        rows.push(row);
    }
    mark_pareto(&mut rows);
    Ok(rows)
}

/// One run of a setting: the variant's image, or a motion's frames that
/// have references (as `arlux motion` renders them).
fn render_target(
    scene: &Scene,
    target: &Target,
    photo: &Image,
    s: &SweepSettings,
    references: usize,
    times: &mut StageTimes,
) -> Result<Vec<Image>> {
    let settings = s.render_settings();
    let mut images: Vec<Image> = Vec::new();
    match target {
        Target::Variant { name } => {
            let effective = scene.with_variant(name)?;
            let out = match s.texture_settings() {
                Some(t) => crate::relight::render_texture(&effective, photo, &t, times)?,
                None => render(&effective, photo, &settings, times)?,
            };
            images.push(out.composite.image);
        }
        Target::Motion { name } => {
            // As `arlux motion` renders it: the pixel path updates
            // each pose, the texture path prepares each again.
            let method = match s.texture_settings() {
                Some(t) => crate::settings::Method::Texture(t),
                None => crate::settings::Method::Pda(settings),
            };
            let m = scene.motion(name)?;
            let first = scene.with_motion_pose(name, 0)?;
            let mut frame = Renderer::start(&first, photo, &method, times)?;
            images.push(frame.composite().image.clone());
            for pose in 1..m.translations.len() {
                let posed = scene.with_motion_pose(name, pose)?;
                frame.update(&posed, times)?;
                if pose < references {
                    images.push(frame.composite().image.clone());
                }
            }
        }
    }
    Ok(images)
}

/// The median of sorted `values` (0 for none).
fn median(values: &[f64]) -> f64 {
    match values.len() {
        0 => 0.0,
        n if n % 2 == 1 => values[n / 2],
        n => 0.5 * (values[n / 2 - 1] + values[n / 2]),
    }
}

/// The best skill `target`'s references allow, from the noise the scene
/// declares for them (a motion: the mean over its poses); None without one.
pub fn skill_floor(
    scene: &Scene,
    target: &Target,
    references: &[Image],
    photo: &Image,
) -> Result<Option<f64>> {
    use crate::scene::ReferenceNoise;
    let noise = match target {
        Target::Variant { name } => match &scene.variant(name)?.reference_noise {
            None => return Ok(None),
            Some(ReferenceNoise::Declared(n)) => *n,
            Some(ReferenceNoise::Twin(t)) => {
                let twin = scene.read_reference(&format!("variant '{name}'.reference_twin"), t)?;
                crate::compare::twin_noise(&references[0], &twin)
            }
        },
        Target::Motion { name } => match scene.motion(name)?.reference_noise {
            None => return Ok(None),
            Some(n) => n,
        },
    };
    let floors: Vec<f64> = (references.iter())
        .filter_map(|r| crate::compare::skill_floor(r, photo, noise))
        .collect();
    Ok((!floors.is_empty()).then(|| floors.iter().sum::<f64>() / floors.len() as f64))
}

/// Marks arlux's rows that no other of its rows beats on both time and
/// error (a peer's rows are drawn beside the front, not on it).
pub(crate) fn mark_pareto(rows: &mut [SweepRow]) {
    let mut order: Vec<usize> = (0..rows.len())
        .filter(|&i| rows[i].peer.is_none())
        .collect();
    order.sort_by(|&a, &b| {
        rows[a]
            .seconds
            .total_cmp(&rows[b].seconds)
            .then(rows[a].error().total_cmp(&rows[b].error()))
    });
    let mut best = f64::INFINITY;
    for i in order {
        rows[i].pareto = rows[i].error() < best;
        if rows[i].pareto {
            best = rows[i].error();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_full_grid_varies_the_objects_mesh_at_the_default_quality() {
        let d = SweepSettings::defaults();
        let full = grid(false, false);
        assert_eq!(full.len(), 135);
        let sampled: Vec<u32> = (full.iter())
            .filter(|s| s.samples > 0)
            .map(|s| s.samples)
            .collect();
        assert_eq!(sampled, [1, 2, 4, 8, 16, 32, 64]);
        let other: Vec<&SweepSettings> = full
            .iter()
            .filter(|s| s.virtual_patch_size != d.virtual_patch_size)
            .collect();
        assert_eq!(other.len(), 8);
        for s in other {
            assert_eq!(
                (s.min_level, s.penumbra_level, s.supersample),
                (d.min_level, d.penumbra_level, d.supersample)
            );
            assert!(
                s.virtual_patch_size == 0.5 * d.virtual_patch_size
                    || s.virtual_patch_size == 2.0 * d.virtual_patch_size
            );
            // The setting reaches the renderer.
            assert_eq!(s.render_settings().virtual_patch_size, s.virtual_patch_size);
        }
    }
}
