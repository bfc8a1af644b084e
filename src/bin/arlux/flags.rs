//! The render flags every command that renders takes alike (`render`,
//! `motion`): the method, the composite, the radiosity's and the pixel data's
//! settings, the links cache and the rounds of per-pixel samples. Mapped
//! onto the library's [`RenderOptions`], where their defaults and checks live.

use arlux::composite::CompositeMode;
use arlux::settings::{RenderMethod, RenderOptions};

/// The render flags (see the module's documentation).
#[derive(clap::Args, Debug, Clone)]
pub struct RenderFlags {
    /// Rendering method: pda (per-pixel differential rendering, Grosch)
    /// or texture (shadow-free textures × B/D, Loscos).
    #[arg(long, value_enum, default_value_t = RenderOptions::default().method)]
    pub method: RenderMethod,
    /// Texture path: CIELAB distance under which two leaves have similar colour (default 10).
    #[arg(long)]
    pub colour_threshold: Option<f64>,
    /// Texture path: visibility difference (0..0.5) under which two leaves see a light alike (default 0.2).
    #[arg(long)]
    pub visibility_threshold: Option<f64>,
    /// Texture path: CIELAB distance under which a frontier leaf may be a reference (default 10).
    #[arg(long)]
    pub reference_colour_threshold: Option<f64>,
    /// Texture path: the smallest leaf, in pixel footprints (default 3).
    #[arg(long)]
    pub min_leaf_pixels: Option<f64>,
    /// How real pixels take the change: ratio (photo × L_with/L_without) or additive.
    #[arg(long, value_enum, default_value_t = RenderOptions::default().composite)]
    pub composite: CompositeMode,
    /// The room's largest patch edge, metres (default: from what the
    /// scene changes: the room's diagonal / 24 for light changes, / 6 for
    /// added objects only).
    #[arg(long)]
    pub patch_size: Option<f64>,
    /// Largest patch edge on virtual objects, metres.
    #[arg(long, default_value_t = RenderOptions::default().virtual_patch_size)]
    pub virtual_patch_size: f64,
    /// Objects of this many triangles or more take their patches on a
    /// coarse mesh of their shape, cells a quarter of --virtual-patch-size
    /// wide (0: a patch per triangle on every object).
    #[arg(long, default_value_t = RenderOptions::default().coarse_objects_from)]
    pub coarse_objects_from: usize,
    /// Every patch against every other (the form-factor oracle) instead
    /// of hierarchical radiosity; pixel path only.
    #[arg(long)]
    pub full: bool,
    /// Hierarchical radiosity's link threshold (both methods).
    #[arg(long, default_value_t = RenderOptions::default().epsilon)]
    pub epsilon: f64,
    /// 2^level shadow rays per rect light everywhere, 2^penumbra_level in penumbra.
    #[arg(long, default_value_t = RenderOptions::default().min_level)]
    pub min_level: usize,
    #[arg(long, default_value_t = RenderOptions::default().penumbra_level)]
    pub penumbra_level: usize,
    /// n×n sub-pixels where real and virtual surfaces meet.
    #[arg(long, default_value_t = RenderOptions::default().supersample)]
    pub supersample: u32,
    /// Refine the room's links and find its automatic patch size again
    /// rather than read them from `.arlux-cache/` next to the scene (nor
    /// keep them there).
    #[arg(long)]
    pub no_cache: bool,
    /// Rounds of per-pixel samples over the radiosity solution, where the
    /// objects change the image: each round lowers the noise by sqrt(r/(r+1))
    /// (0: the solution alone; pixel path only).
    #[arg(long, default_value_t = RenderOptions::default().samples)]
    pub samples: u32,
}

impl RenderFlags {
    /// Sets these flags' settings in `options`.
    pub fn apply(&self, options: &mut RenderOptions) {
        options.method = self.method;
        options.colour_threshold = self.colour_threshold;
        options.visibility_threshold = self.visibility_threshold;
        options.reference_colour_threshold = self.reference_colour_threshold;
        options.min_leaf_pixels = self.min_leaf_pixels;
        options.composite = self.composite;
        options.patch_size = self.patch_size;
        options.virtual_patch_size = self.virtual_patch_size;
        options.coarse_objects_from = self.coarse_objects_from;
        options.full = self.full;
        options.epsilon = self.epsilon;
        options.min_level = self.min_level;
        options.penumbra_level = self.penumbra_level;
        options.supersample = self.supersample;
        options.cache = !self.no_cache;
        options.samples = self.samples;
    }
}
