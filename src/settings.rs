//! What a user may choose for a render, with its defaults and validation in
//! one place: the command line maps its flags onto [`RenderOptions`], and
//! [`RenderOptions::resolve`] checks them and turns them into the settings
//! of the method chosen.

use std::fmt;

use crate::composite::CompositeMode;
use crate::image_io::{CropWindow, PixelRect};
use crate::model::{ModelSettings, TransportMethod};
use crate::pda::PdaSettings;
use crate::radiosity::DEFAULT_LINK_EPSILON;
use crate::relight::TextureSettings;
use crate::render::{PatchSize, RenderSettings};

/// A setting the user gave that cannot be used. Displayed with the
/// setting's name as a flag (`--supersample must lie in 1..=16, not 20`),
/// the name a user typed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SettingError {
    /// The setting's name, kebab-case (`supersample`, `patch-size`).
    pub setting: &'static str,
    /// What is wrong, after the name.
    pub message: String,
}

impl fmt::Display for SettingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "--{} {}", self.setting, self.message)
    }
}

impl std::error::Error for SettingError {}

fn fail<T>(setting: &'static str, message: impl Into<String>) -> Result<T, SettingError> {
    Err(SettingError {
        setting,
        message: message.into(),
    })
}

/// How a still is rendered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RenderMethod {
    /// Per-pixel differential rendering with the Pixel Data Array (Grosch).
    Pda,
    /// Shadow-free radiosity textures × B/D (Loscos).
    Texture,
}

/// A render's settings, resolved for the method chosen.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    Pda(RenderSettings),
    Texture(TextureSettings),
}

/// Every choice `arlux render` offers, as the user gives it: `None` is
/// "the default", which may depend on the scene (the room's patch size) or
/// on the method (the texture path's thresholds).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RenderOptions {
    pub method: RenderMethod,
    pub composite: CompositeMode,
    /// The room's largest patch edge, metres (None: from what the scene changes).
    pub patch_size: Option<f64>,
    /// Largest patch edge on virtual objects, metres.
    pub virtual_patch_size: f64,
    /// Objects of this many triangles or more take their patches on a
    /// coarse mesh of each surface (0: a patch per triangle on every object).
    pub coarse_objects_from: usize,
    /// The full form-factor matrix instead of hierarchical radiosity.
    pub full: bool,
    /// Hierarchical radiosity's link threshold.
    pub epsilon: f64,
    /// 2^min_level shadow rays per rect light everywhere.
    pub min_level: usize,
    /// 2^penumbra_level where the first rays disagree.
    pub penumbra_level: usize,
    /// n×n sub-pixels where real and virtual surfaces meet.
    pub supersample: u32,
    pub colour_threshold: Option<f64>,
    pub visibility_threshold: Option<f64>,
    pub reference_colour_threshold: Option<f64>,
    pub min_leaf_pixels: Option<f64>,
    /// Render only this window of the frame (pbrt's crop window); each of
    /// its pixels is what the whole frame gives it, bit for bit. The pixel
    /// path computes only the window; the texture path renders the frame.
    /// Not serialised: a tile's settings are the whole frame's.
    #[serde(skip)]
    pub crop: Option<CropWindow>,
    /// Keep the room's links next to the scene and read them back when the
    /// room, its mesh and ε are the same. Not serialised: the image is the
    /// same either way.
    #[serde(skip)]
    pub cache: bool,
    /// Rounds of per-pixel samples over the kept solution (0: none).
    pub samples: u32,
    /// Seconds the render may take: as many rounds as fit.
    pub time: Option<f64>,
    /// The memory a render may hold, bytes (`--memory`): the pixel path's
    /// bands are cut to fit it; the texture path refuses, before linking
    /// its objects, links that would not fit. None: not bounded. Not in the
    /// files' settings: the image is the same whatever the budget.
    #[serde(skip)]
    pub memory: Option<u64>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        let render = RenderSettings::default();
        RenderOptions {
            method: RenderMethod::Pda,
            composite: render.mode,
            patch_size: None,
            virtual_patch_size: render.virtual_patch_size,
            coarse_objects_from: render.coarse_objects_from.unwrap_or(0),
            full: false,
            epsilon: DEFAULT_LINK_EPSILON,
            min_level: render.pda.min_level,
            penumbra_level: render.pda.penumbra_level,
            supersample: render.pda.supersample,
            colour_threshold: None,
            visibility_threshold: None,
            reference_colour_threshold: None,
            min_leaf_pixels: None,
            crop: None,
            cache: true,
            samples: 0,
            time: None,
            memory: None,
        }
    }
}

fn positive(setting: &'static str, v: f64, unit: &str) -> Result<(), SettingError> {
    if v > 0.0 && v.is_finite() {
        Ok(())
    } else {
        fail(setting, format!("must be a positive number{unit}, not {v}"))
    }
}

impl RenderOptions {
    /// Checks every setting and returns the chosen method's settings. A
    /// setting of the other method, given away from its default, is an
    /// error rather than silently ignored.
    pub fn resolve(&self) -> Result<Method, SettingError> {
        if let Some(m) = self.patch_size {
            positive("patch-size", m, " of metres")?;
        }
        positive("virtual-patch-size", self.virtual_patch_size, " of metres")?;
        positive("epsilon", self.epsilon, "")?;
        let max = crate::light::MAX_GRID_LEVEL;
        if self.min_level > max || self.penumbra_level > max || self.penumbra_level < self.min_level
        {
            return fail(
                "min-level",
                format!("and --penumbra-level must satisfy min-level <= penumbra-level <= {max}"),
            );
        }
        let most = crate::residual::MAX_SAMPLES;
        if self.samples > most {
            return fail(
                "samples",
                format!("must lie in 0..={most}, not {}", self.samples),
            );
        }
        if let Some(t) = self.time {
            positive("time", t, " of seconds")?;
        }
        if !(1..=16).contains(&self.supersample) {
            return fail(
                "supersample",
                format!("must lie in 1..=16, not {}", self.supersample),
            );
        }
        let texture_only = [
            ("colour-threshold", self.colour_threshold, f64::INFINITY),
            ("visibility-threshold", self.visibility_threshold, 0.5),
            (
                "reference-colour-threshold",
                self.reference_colour_threshold,
                f64::INFINITY,
            ),
            ("min-leaf-pixels", self.min_leaf_pixels, f64::INFINITY),
        ];
        for (setting, value, hi) in texture_only {
            let Some(v) = value else { continue };
            if self.method != RenderMethod::Texture {
                return fail(setting, "applies to --method texture");
            }
            if !(v.is_finite() && v > 0.0 && v < hi) {
                return fail(setting, format!("must be a number in (0, {hi}), not {v}"));
            }
        }
        if let Some(c) = self.crop {
            c.validate().map_err(|m| SettingError {
                setting: "crop",
                message: m,
            })?;
        }
        match self.method {
            RenderMethod::Pda => Ok(Method::Pda(self.pda_settings())),
            RenderMethod::Texture => self.texture_settings().map(Method::Texture),
        }
    }

    fn pda_settings(&self) -> RenderSettings {
        RenderSettings {
            model: ModelSettings {
                patch_size: self.patch_size.unwrap_or(0.25),
                transport: if self.full {
                    TransportMethod::Full
                } else {
                    TransportMethod::Hierarchical {
                        epsilon: self.epsilon,
                    }
                },
                cache_links: self.cache,
                ..ModelSettings::default()
            },
            patch_size: self.patch_size.map_or(PatchSize::Auto, PatchSize::Metres),
            virtual_patch_size: self.virtual_patch_size,
            coarse_objects_from: (self.coarse_objects_from > 0).then_some(self.coarse_objects_from),
            pda: PdaSettings {
                min_level: self.min_level,
                penumbra_level: self.penumbra_level,
                supersample: self.supersample,
                crop: self.crop,
            },
            mode: self.composite,
            residual: crate::residual::ResidualSettings {
                samples: self.samples,
                time: self.time,
            },
            ..RenderSettings::default()
        }
    }

    fn texture_settings(&self) -> Result<TextureSettings, SettingError> {
        let d = RenderOptions::default();
        let pda_only = [
            ("full", self.full),
            ("composite", self.composite != d.composite),
            ("min-level", self.min_level != d.min_level),
            ("penumbra-level", self.penumbra_level != d.penumbra_level),
            ("supersample", self.supersample != d.supersample),
            ("samples", self.samples != d.samples),
            ("time", self.time.is_some()),
        ];
        if let Some((setting, _)) = pda_only.iter().find(|(_, given)| *given) {
            return fail(
                setting,
                "applies to --method pda (the texture path casts its shadow rays per leaf and displays T×B/D)",
            );
        }
        let t = TextureSettings::default();
        Ok(TextureSettings {
            patch_size: self.patch_size,
            link_epsilon: self.epsilon,
            colour_threshold: self.colour_threshold.unwrap_or(t.colour_threshold),
            visibility_threshold: self.visibility_threshold.unwrap_or(t.visibility_threshold),
            reference_colour_threshold: self
                .reference_colour_threshold
                .unwrap_or(t.reference_colour_threshold),
            min_leaf_pixels: self.min_leaf_pixels.unwrap_or(t.min_leaf_pixels),
            cache_links: self.cache,
            memory: self.memory,
            coarse_objects_from: (self.coarse_objects_from > 0).then_some(self.coarse_objects_from),
            ..t
        })
    }
}

impl RenderOptions {
    /// The pixels of the crop window in a `width`×`height` frame (`None`:
    /// no crop); an error when the window holds no pixel of it.
    pub fn crop_pixels(&self, width: u32, height: u32) -> Result<Option<PixelRect>, SettingError> {
        let Some(c) = self.crop else { return Ok(None) };
        match c.pixels(width, height) {
            Some(r) => Ok(Some(r)),
            None => fail(
                "crop",
                format!(
                    "{} {} {} {} holds no pixel of the {width}×{height} frame",
                    c.x0, c.x1, c.y0, c.y1
                ),
            ),
        }
    }
}

impl ModelSettings {
    /// Checks the settings of a model of the room (`arlux radiosity`).
    pub fn validate(&self) -> Result<(), SettingError> {
        positive("patch-size", self.patch_size, " of metres")?;
        if let TransportMethod::Hierarchical { epsilon } = self.transport {
            positive("epsilon", epsilon, "")?;
        }
        let max = crate::light::MAX_GRID_LEVEL;
        if self.light_level > max {
            return fail("light-level", format!("must be at most {max}"));
        }
        Ok(())
    }
}

impl crate::gonio::GonioSettings {
    /// Checks the direction table's spacing (`arlux gonio`).
    pub fn validate(&self) -> Result<(), SettingError> {
        for (setting, v) in [
            ("vertical-step", self.vertical_step_deg),
            ("horizontal-step", self.horizontal_step_deg),
        ] {
            if !(v > 0.0 && v <= 90.0) {
                return fail(setting, format!("must be in (0, 90] degrees, not {v}"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_resolve_to_the_library_defaults() {
        let Method::Pda(s) = RenderOptions::default().resolve().unwrap() else {
            panic!("pda by default")
        };
        let d = RenderSettings::default();
        assert_eq!(s.pda, d.pda);
        assert_eq!(s.mode, d.mode);
        assert_eq!(s.patch_size, PatchSize::Auto);
        assert_eq!(s.virtual_patch_size, d.virtual_patch_size);
        // The commands keep the room's links; a program using the library
        // (a bench timing refinement) asks for the cache itself.
        assert!(s.model.cache_links && !d.model.cache_links);
        let uncached = ModelSettings {
            cache_links: false,
            ..s.model
        };
        assert_eq!(uncached, d.model);
    }

    #[test]
    fn a_setting_of_the_other_method_is_refused_by_name() {
        let texture_flag = RenderOptions {
            min_leaf_pixels: Some(2.0),
            ..RenderOptions::default()
        };
        assert_eq!(
            texture_flag.resolve().unwrap_err().to_string(),
            "--min-leaf-pixels applies to --method texture"
        );
        let pda_flag = RenderOptions {
            method: RenderMethod::Texture,
            supersample: 2,
            ..RenderOptions::default()
        };
        assert_eq!(pda_flag.resolve().unwrap_err().setting, "supersample");
    }

    #[test]
    fn model_and_table_settings_are_checked() {
        let bad = ModelSettings {
            light_level: 99,
            ..ModelSettings::default()
        };
        assert_eq!(bad.validate().unwrap_err().setting, "light-level");
        assert!(ModelSettings::default().validate().is_ok());
        let table = crate::gonio::GonioSettings {
            vertical_step_deg: 0.0,
            ..Default::default()
        };
        assert_eq!(
            table.validate().unwrap_err().to_string(),
            "--vertical-step must be in (0, 90] degrees, not 0"
        );
    }

    #[test]
    fn out_of_range_values_are_refused() {
        for (o, setting) in [
            (
                RenderOptions {
                    supersample: 0,
                    ..RenderOptions::default()
                },
                "supersample",
            ),
            (
                RenderOptions {
                    patch_size: Some(f64::NAN),
                    ..RenderOptions::default()
                },
                "patch-size",
            ),
            (
                RenderOptions {
                    epsilon: -1.0,
                    ..RenderOptions::default()
                },
                "epsilon",
            ),
            (
                RenderOptions {
                    method: RenderMethod::Texture,
                    visibility_threshold: Some(0.7),
                    ..RenderOptions::default()
                },
                "visibility-threshold",
            ),
        ] {
            assert_eq!(o.resolve().unwrap_err().setting, setting);
        }
    }
}
