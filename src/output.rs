//! What a render produced and what it did, whichever method made it (the
//! pixel path of `render` or the texture path of `relight`).

use crate::composite::Composite;
use crate::image_io::Image;

mod frame;
pub use frame::{AOV_LAYERS, FrameFiles, FrameLayer, FrameWriter};

/// What a render produced and what it did.
pub struct RenderOutput {
    pub composite: Composite,
    /// What is likely wrong with the inputs, with numbers (the lights do
    /// not explain the photo, the photo is clipped): the render went on.
    pub warnings: Vec<String>,
    /// Stages that ran are in the timings; these were left out, with why.
    pub left_out: Vec<String>,
    pub pda_bytes: usize,
    pub pda_pixels: usize,
    pub rays: u64,
    pub patches: usize,
    pub links: usize,
    /// Elements of the mesh's hierarchy (patches and the elements above
    /// them) that links may join.
    pub elements: usize,
    /// What the links (or the form-factor matrix) take in memory.
    pub links_bytes: usize,
    /// The room's solution without the objects, kept for every pose, and
    /// the objects' change to it (see [`crate::radiosity::ObjectView`]).
    pub room_solution_bytes: usize,
    pub change_bytes: usize,
    /// The room's patch size used, metres.
    pub patch_size: f64,
    /// `--method texture`: what the preprocess did, the shadow-free texture
    /// seen from the camera, and the time of the light change alone.
    pub texture: Option<(TextureStats, Image, std::time::Duration)>,
    /// What the rounds of per-pixel samples did (None: none ran).
    pub residual: Option<crate::residual::ResidualStats>,
}

/// What the preprocess did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TextureStats {
    pub rounds: usize,
    /// Leaves split by the refinement, and splits undone (no visibility change).
    pub splits: usize,
    pub undone: usize,
    pub leaves: usize,
    pub links: usize,
    /// Seen leaves occluded from some real light, and how each was corrected.
    pub occluded: usize,
    pub by_frontier: usize,
    pub by_user_reference: usize,
    pub uncorrected: usize,
    pub texels: usize,
    pub texture_bytes: usize,
    pub patch_size: f64,
    /// What linking the objects was expected to make and take, measured on
    /// a sample of their triangles before it started (with a memory budget).
    pub object_links_estimate: Option<crate::radiosity::ObjectLinkEstimate>,
    /// Groups of the objects' leaves that gathered their light by rays.
    pub object_gather_groups: usize,
}
