//! One interface over both methods, as a command sees them: start a frame
//! of a scene, move its objects, read the composite. The pixel path
//! (Grosch: [`Session`]) updates a move by pixel shafts over the kept room;
//! the texture path (Loscos: [`crate::relight`]) refines its mesh around
//! the variant's objects, so a move renders the pose again, and relights
//! its kept preprocess when only the lights' scales change. `arlux motion`
//! renders through it; either way a frame is what `arlux render` of its
//! pose with the same settings gives.

use crate::composite::Composite;
use crate::error::Result;
use crate::image_io::Image;
use crate::output::RenderOutput;
use crate::relight::TextureFrame;
use crate::render::{Relight, Session, SessionMemory, UpdateStats};
use crate::scene::Scene;
use crate::settings::Method;
use crate::util::stages::StageTimes;

/// A frame being rendered by one of the methods.
pub enum Renderer {
    /// The pixel path's session.
    Pixels(Box<Session>),
    /// The texture path's last frame, and what renders the next.
    Textures(Box<Textures>),
}

/// The texture path's state: its settings, the photo, the last frame's
/// preprocess (kept for light changes) and report.
pub struct Textures {
    settings: crate::relight::TextureSettings,
    photo: Image,
    frame: Option<TextureFrame>,
    out: RenderOutput,
}

impl Textures {
    fn start(
        scene: &Scene,
        photo: &Image,
        settings: &crate::relight::TextureSettings,
        times: &mut StageTimes,
    ) -> Result<Textures> {
        let mut frame = TextureFrame::prepare(scene, photo, settings, times)?;
        Ok(Textures {
            out: frame.render(scene, times),
            frame: Some(frame),
            settings: *settings,
            photo: photo.clone(),
        })
    }
}

impl Renderer {
    /// The frame of `scene` over `photo` by `method`, kept for moves.
    pub fn start(
        scene: &Scene,
        photo: &Image,
        method: &Method,
        times: &mut StageTimes,
    ) -> Result<Renderer> {
        Ok(match method {
            Method::Pda(settings) => {
                Renderer::Pixels(Box::new(Session::start(scene, photo, settings, times)?))
            }
            Method::Texture(settings) => {
                Renderer::Textures(Box::new(Textures::start(scene, photo, settings, times)?))
            }
        })
    }

    /// The frame's composite.
    pub fn composite(&self) -> &Composite {
        match self {
            Renderer::Pixels(s) => &s.composite,
            Renderer::Textures(t) => &t.out.composite,
        }
    }

    /// Moves to `scene` (the objects moved, all else kept): the pixel
    /// path's update (its statistics), or the texture path's frame of the
    /// pose rendered again (None).
    pub fn update(&mut self, scene: &Scene, times: &mut StageTimes) -> Result<Option<UpdateStats>> {
        match self {
            Renderer::Pixels(s) => s.update(scene, times).map(Some),
            Renderer::Textures(t) => {
                // One preprocess held at a time.
                t.frame = None;
                let mut frame = TextureFrame::prepare(scene, &t.photo, &t.settings, times)?;
                t.out = frame.render(scene, times);
                t.frame = Some(frame);
                Ok(None)
            }
        }
    }

    /// New scales of the lights, all else kept, in place: the pixel path
    /// by superposition ([`Session::relight`]), the texture path by one light
    /// change over its kept preprocess (Loscos §5; the same lights on).
    /// `Err` says why not (the caller renders in full).
    pub fn relight(
        &mut self,
        scene: &Scene,
        times: &mut StageTimes,
    ) -> std::result::Result<(), Relight> {
        match self {
            Renderer::Pixels(s) => s.relight(scene, times),
            Renderer::Textures(t) => match t.frame.as_mut() {
                Some(frame) if frame.relights(scene) => {
                    t.out = frame.render(scene, times);
                    Ok(())
                }
                _ => Err(Relight::LightsTraced),
            },
        }
    }

    /// The frame with `rounds` rounds of per-pixel samples (the pixel
    /// path's [`Session::refine`]; None: none ran, or the texture path).
    pub fn refine(
        &mut self,
        rounds: u32,
        times: &mut StageTimes,
    ) -> Option<crate::residual::ResidualStats> {
        match self {
            Renderer::Pixels(s) => s.refine(rounds, times),
            Renderer::Textures(_) => None,
        }
    }

    /// Solves ahead what a light's scale change reads (the pixel path's
    /// [`Session::prepare_relights`]; the texture path relights its kept
    /// preprocess as it is). Returns whether anything was solved.
    pub fn prepare_relights(&mut self, times: &mut StageTimes) -> bool {
        match self {
            Renderer::Pixels(s) => s.prepare_relights(times),
            Renderer::Textures(_) => false,
        }
    }

    /// Builds what the pixel path's updates traverse (nothing on the texture path).
    pub fn prepare_updates(&mut self, times: &mut StageTimes) {
        if let Renderer::Pixels(s) = self {
            s.prepare_updates(times);
        }
    }

    /// From the next update on, composites hold the image and alpha only
    /// (the pixel path; the texture path writes every layer).
    pub fn image_only(&mut self) {
        self.keep_layers(crate::composite::Layers::None);
    }

    /// Which layers the pixel path's next composites fill
    /// ([`Session::keep_layers`]; the texture path writes every layer).
    pub fn keep_layers(&mut self, layers: crate::composite::Layers) {
        if let Renderer::Pixels(s) = self {
            s.keep_layers(layers);
        }
    }

    /// Bytes held for moves: the pixel path's parts, the texture path's
    /// pixels and textures as pixel data.
    pub fn memory_bytes(&self) -> SessionMemory {
        match self {
            Renderer::Pixels(s) => s.memory_bytes(),
            Renderer::Textures(t) => SessionMemory {
                pixel_data: t.out.pda_bytes,
                pixel_blocks: 0,
                room_solution: 0,
                change: 0,
            },
        }
    }

    /// The pixel path's block hierarchy, once built.
    pub fn blocks(&self) -> Option<&crate::blocks::BlockHierarchy> {
        match self {
            Renderer::Pixels(s) => s.blocks(),
            Renderer::Textures(_) => None,
        }
    }
}
