//! A second session, made ahead on the mesh a change of the lights renders
//! with, so that the first change of a light is a sum of its lights'
//! solutions rather than a full render.
//!
//! With the automatic patch size, the photo's lights render on a coarse
//! mesh and changed lights on a finer one (`docs/design/relighting.md`):
//! the first change of a light leaves the session's mesh and renders in
//! full (lounge: 1.1 s with its links cached, 8.5 s without). A standby
//! is that finer session, started on the state with one real light
//! doubled (the same lights traced, the mesh a change gives) and its
//! lights solved ahead. At the first change of a light the session takes
//! it: moved to the objects' poses of the moment where they differ (an
//! update), then relit to the new scales. The image is the full render's
//! of the new state, as a relight's is (to 1e-5 relative). The session it
//! replaces stands by in turn, for the lights set back as photographed
//! (bit for bit: a relight to the scales a session holds does nothing),
//! and so on each time the lights cross between the two meshes.

use super::{Interactive, RenderPath, Rendered};
use crate::error::Result;
use crate::image_io::Image;
use crate::render::{PatchSize, lights_change};
use crate::renderer::Renderer;
use crate::scene::Scene;
use crate::settings::Method;
use crate::util::stages::StageTimes;

/// A session on the other mesh: the finer one made ahead, its lights
/// solved, or the one it replaced (see the module).
pub struct Standby {
    renderer: Box<Renderer>,
    /// The scene it holds: the state it was made for (a light doubled) or
    /// the one it last showed.
    scene: Scene,
}

impl Standby {
    /// The scene a standby for `state` renders: `state` with its first
    /// real light that is on doubled. None where a change of lights keeps
    /// the mesh: a patch size given, the texture path (which relights on
    /// its own mesh), lights already changed, or no real light on.
    pub fn scene_for(state: &Scene, method: &Method) -> Option<Scene> {
        if !Standby::wanted_for(state, method) {
            return None;
        }
        let mut scene = state.clone();
        let light = (scene.lights.iter_mut()).find(|l| l.real && l.scale > 0.0)?;
        light.scale *= 2.0;
        Some(scene)
    }

    /// Whether a change of `state`'s lights would leave its mesh: the
    /// pixel path on the automatic patch size, on the photo's lights.
    fn wanted_for(state: &Scene, method: &Method) -> bool {
        matches!(method, Method::Pda(s) if s.patch_size == PatchSize::Auto)
            && !lights_change(&state.lights)
    }

    /// Renders `scene` (from [`Standby::scene_for`]) and solves each of
    /// its lights ahead. The room's links of the finer mesh are refined
    /// here where the links cache does not hold them.
    pub fn start(
        scene: Scene,
        photo: &Image,
        method: &Method,
        times: &mut StageTimes,
    ) -> Result<Standby> {
        let mut renderer = Renderer::start(&scene, photo, method, times)?;
        renderer.prepare_relights(times);
        renderer.keep_layers(crate::composite::Layers::Object);
        Ok(Standby {
            renderer: Box::new(renderer),
            scene,
        })
    }

    /// Whether `target` shows the objects the standby shows, under the same
    /// lights (their scales aside): what an update and a relight can give.
    fn shows_as(&self, target: &Scene) -> bool {
        let shown = |s: &Scene| s.objects.iter().map(|o| o.enabled).collect::<Vec<_>>();
        let unscaled = |l: &crate::scene::Light| crate::scene::Light {
            scale: 0.0,
            ..l.clone()
        };
        shown(target) == shown(&self.scene)
            && target.lights.len() == self.scene.lights.len()
            && (target.lights.iter().zip(&self.scene.lights))
                .all(|(a, b)| unscaled(a) == unscaled(b))
    }

    /// The standby moved to `target`'s objects and relit to its lights,
    /// or None where its relight refuses them (a light switched on that
    /// it never traced, scales another mesh renders).
    fn take_to(mut self, target: &Scene, times: &mut StageTimes) -> Option<Box<Renderer>> {
        let same_poses =
            (self.scene.objects.iter().zip(&target.objects)).all(|(a, b)| a.pose == b.pose);
        if !same_poses {
            let mut moved = target.clone();
            moved.lights.clone_from(&self.scene.lights);
            self.renderer.update(&moved, times).ok()?;
        }
        self.renderer.relight(target, times).ok()?;
        Some(self.renderer)
    }
}

impl Interactive {
    /// `scene`, whose scales the session's own mesh does not render, from
    /// the standby where it can give it (a relight), else a full render.
    /// The session it replaces stands by in turn: lights set back as
    /// photographed relight on it, and changed again on the finer one.
    pub(super) fn render_by_standby(
        &mut self,
        scene: Scene,
        reason: String,
        times: &mut StageTimes,
    ) -> Result<RenderPath> {
        let standby = match self.standby.take() {
            Some(s) if s.shows_as(&scene) => s,
            kept => {
                self.standby = kept;
                return self.render_full(scene, reason, times);
            }
        };
        let Some(renderer) = standby.take_to(&scene, times) else {
            return self.render_full(scene, reason, times);
        };
        let last = std::mem::replace(&mut self.scene, scene);
        if let Rendered::Frame(session) =
            std::mem::replace(&mut self.rendered, Rendered::Frame(renderer))
        {
            self.standby = Some(Standby {
                renderer: session,
                scene: last,
            });
        }
        self.relights_ahead = true;
        Ok(RenderPath::Relight)
    }

    /// The scene a standby for this state renders (see [`Standby`]): None
    /// where a change of lights would keep the session's mesh, where the
    /// state shows the photo itself, and where two sessions' pixel data
    /// would not fit in the memory a render may hold
    /// ([`crate::render::default_memory`]): a 24-megapixel plate's is 2.2 GB.
    pub fn standby_scene(&self) -> Option<Scene> {
        let Rendered::Frame(renderer) = &self.rendered else {
            return None;
        };
        let m = renderer.memory_bytes();
        let held = m.pixel_data + m.pixel_blocks + m.room_solution + m.change;
        let photo = self.photo.pixels.len() * std::mem::size_of::<glam::Vec3>();
        if (2 * held + photo) as u64 > crate::render::default_memory() {
            return None;
        }
        Standby::scene_for(&self.scene, &self.method)
    }

    /// Whether a standby could still serve this state's next change of
    /// lights (the session is on the photo's lights, the automatic patch
    /// size): asked after every edit, so it clones nothing.
    pub fn standby_wanted(&self) -> bool {
        Standby::wanted_for(&self.scene, &self.method)
    }

    /// Holds `standby` for the first change of a light that leaves the
    /// session's mesh.
    pub fn offer_standby(&mut self, standby: Standby) {
        self.standby = Some(standby);
    }
}
