//! An editing session over a render: a front end (`arlux serve`) places,
//! turns, scales, shows and hides the scene's virtual objects and scales
//! its lights, one [`Edit`] at a time, and gets the augmented photo back
//! after each, by the cheapest path that gives the image a full render of
//! that state gives.
//!
//! The state is held as the `[[variant]]` table it would be saved as, and
//! every image is rendered from that table read back by the scene loader:
//! what the session shows and what `arlux render --variant` renders of the
//! saved file are the same scene, bit for bit. The module knows nothing of
//! HTTP; it takes edits and returns plain data.

use glam::{DMat3, DQuat, DVec3};

use crate::error::Result;
use crate::image_io::Image;
use crate::render::RenderSettings;
use crate::renderer::Renderer;
use crate::scene::Scene;
use crate::settings::Method;
use crate::util::stages::StageTimes;

mod assets;
mod display;
mod lights;
mod placement;
mod save;
mod standby;

use lights::LightEdit;

pub use assets::{MESH_EXTENSIONS, list_assets};
pub use display::{Frame, View};
pub use placement::{LIGHT_HEIGHT_M, Room};
pub use standby::Standby;

/// One change a user makes. Objects and lights are indices into the
/// scene's `objects` and `lights`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Edit {
    /// Stand the object on the surface seen at image point (x, y)
    /// (continuous pixel coordinates): its footprint's centre on the point.
    Place {
        object: usize,
        x: f64,
        y: f64,
    },
    /// The object's heading about the vertical, degrees (counter-clockwise seen from above).
    Turn {
        object: usize,
        yaw_deg: f64,
    },
    /// The object's uniform scale.
    Scale {
        object: usize,
        scale: f64,
    },
    Enable {
        object: usize,
        enabled: bool,
    },
    /// Slide the object along the floor by `right_m` metres to the image's
    /// right and `forward_m` away from the camera (the camera's axes laid
    /// flat), at most a metre each way.
    Nudge {
        object: usize,
        right_m: f64,
        forward_m: f64,
    },
    /// A light's scale: 0 switches it off; for a virtual light, its intensity.
    Light {
        light: usize,
        scale: f64,
    },
    /// A virtual light placed `height_m` off the real surface seen at image
    /// point (x, y), along its normal (switched on at scale 1 if it was off).
    PlaceLight {
        light: usize,
        x: f64,
        y: f64,
        height_m: f64,
    },
    /// Back to the state before the last step (a drag's moves are one step).
    Undo,
    /// The step the last undo took back, again.
    Redo,
}

/// The user's edits of objects and lights: what one undo step restores.
type Snapshot = (Vec<ObjectEdit>, Vec<LightEdit>);

/// Undo steps kept, at most (the oldest go first).
const UNDO_STEPS: usize = 1000;

/// An edit that is not made, with the request field it is about.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    pub field: &'static str,
    pub message: String,
}

impl Refusal {
    fn new(field: &'static str, message: impl Into<String>) -> Self {
        Refusal {
            field,
            message: message.into(),
        }
    }
}

/// A light's scale the session accepts: the page's slider covers 0–4 for a
/// real light; a virtual light's intensity may go further.
pub const MAX_LIGHT_SCALE: f64 = 16.0;
/// The range of an object's scale.
pub const SCALE_RANGE: (f64, f64) = (0.05, 20.0);

/// How the image after an edit was made.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum RenderPath {
    /// Nothing changed: the image stays.
    Unchanged,
    /// The state is the photo's (no object, lights as shot): the photo.
    Photo,
    /// Pixel shafts: only what the objects' old and new places can change.
    Update {
        pixels_recomputed: usize,
        pixels_retraced: u64,
        rays: u64,
    },
    /// The lights' scales changed: the kept pixel data recombined, the room's
    /// solution and the objects' change solved again at the new scales.
    Relight,
    /// A full render of the pixel path (lights or the set of objects changed).
    Full { reason: String },
}

/// What an edit did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Outcome {
    /// Raised by every edit that changes the image.
    pub version: u64,
    pub path: RenderPath,
    /// Wall time of the render or update, milliseconds.
    pub millis: f64,
}

/// Per object, what the user changed (None: as the scene has it).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct ObjectEdit {
    translate: Option<DVec3>,
    yaw_deg: Option<f64>,
    scale: Option<f64>,
    enabled: Option<bool>,
}

/// The image of the current state, and what can update it.
enum Rendered {
    Photo,
    Frame(Box<Renderer>),
}

/// An editing session (see the module's documentation).
pub struct Interactive {
    base: Scene,
    photo: Image,
    method: Method,
    objects: Vec<ObjectEdit>,
    lights: Vec<LightEdit>,
    /// The effective scene of the state, as rendered.
    scene: Scene,
    rendered: Rendered,
    room: Room,
    version: u64,
    /// Rounds of per-pixel samples the image was last refined with
    /// ([`Interactive::refine`]; 0 after every change), and their report.
    refined: (u32, Option<crate::residual::ResidualStats>),
    /// Whether an idle moment should solve ahead for a light's slider
    /// ([`Interactive::prepare_relights`]): after a full render or a
    /// relight, not after a move (a drag's next move would wait for it).
    relights_ahead: bool,
    /// The session on the other mesh, taken when the lights cross between
    /// the photo's and changed ones.
    standby: Option<Standby>,
    /// States to go back to (newest last), and to go forward to again.
    undo: Vec<Snapshot>,
    redo: Vec<Snapshot>,
    /// The object the last step placed: a drag's next move continues it.
    placing: Option<usize>,
    /// The other objects' geometry the last placement was checked against.
    others: Option<crate::placement::Others>,
    /// The scene file's text as loaded (the session's own text also holds
    /// the objects added since).
    file_text: String,
}

impl Interactive {
    /// Renders the scene as loaded (its base state): the preprocess
    /// (estimation, radiosity, links) runs here.
    pub fn new(
        base: Scene,
        photo: Image,
        settings: RenderSettings,
        times: &mut StageTimes,
    ) -> Result<Interactive> {
        Interactive::with_method(base, photo, Method::Pda(settings), times)
    }

    /// [`Interactive::new`] by either method: the texture path renders
    /// every change in full (as `arlux render --method texture` of the state).
    pub fn with_method(
        base: Scene,
        photo: Image,
        method: Method,
        times: &mut StageTimes,
    ) -> Result<Interactive> {
        let room = Room::new(&base)?;
        let mut s = Interactive {
            objects: vec![ObjectEdit::default(); base.objects.len()],
            lights: vec![LightEdit::default(); base.lights.len()],
            scene: base.clone(),
            rendered: Rendered::Photo,
            base,
            photo,
            method,
            room,
            version: 0,
            refined: (0, None),
            relights_ahead: false,
            standby: None,
            undo: Vec::new(),
            redo: Vec::new(),
            placing: None,
            others: None,
            file_text: String::new(),
        };
        s.file_text = s.base.source.clone();
        let scene = s.state_scene()?;
        s.render_full(scene, "the first image".into(), times)?;
        Ok(s)
    }

    pub fn base(&self) -> &Scene {
        &self.base
    }

    /// The effective scene of the current state.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn photo(&self) -> &Image {
        &self.photo
    }

    pub fn version(&self) -> u64 {
        self.version
    }

    /// The rounds the image was last refined with (0: none since the last
    /// change) and what they did (None: nothing to sample).
    pub fn refined(&self) -> (u32, Option<crate::residual::ResidualStats>) {
        self.refined
    }

    /// The current state's image with `rounds` rounds of per-pixel samples:
    /// what `arlux render --samples rounds` gives of the saved state. The
    /// next change starts again from the session's setting. Returns the
    /// rounds' report (None where the state shows the photo).
    pub fn refine(
        &mut self,
        rounds: u32,
        times: &mut StageTimes,
    ) -> Option<crate::residual::ResidualStats> {
        let Rendered::Frame(session) = &mut self.rendered else {
            self.refined = (rounds, None);
            return None;
        };
        self.refined = (rounds, session.refine(rounds, times));
        self.refined.1
    }

    /// Solves ahead, once per state that asks for it, what a light's
    /// scale change would solve on its first step (each light's solution
    /// of the room and of the objects' change): the server calls it while
    /// no edit waits. Returns whether anything was solved.
    pub fn prepare_relights(&mut self, times: &mut StageTimes) -> bool {
        match (&mut self.rendered, std::mem::take(&mut self.relights_ahead)) {
            (Rendered::Frame(renderer), true) => renderer.prepare_relights(times),
            _ => false,
        }
    }

    /// `write` given the state's composite with every layer (direct,
    /// indirect, change and the objects'), composited again where the
    /// session's updates keep fewer: the image as shown, its rounds
    /// included. None while the state is the photo's.
    pub fn with_every_layer<R>(
        &mut self,
        times: &mut StageTimes,
        write: impl FnOnce(&crate::composite::Composite) -> R,
    ) -> Option<R> {
        use crate::composite::Layers;
        let rounds = self.refined.0;
        let Rendered::Frame(renderer) = &mut self.rendered else {
            return None;
        };
        let c = renderer.composite();
        if c.direct.pixels.len() != c.image.pixels.len() {
            renderer.keep_layers(Layers::All);
            renderer.refine(rounds, times);
            renderer.keep_layers(Layers::Object);
        }
        Some(write(renderer.composite()))
    }

    /// The render's composite (None while the state is the photo's).
    pub fn composite(&self) -> Option<&crate::composite::Composite> {
        match &self.rendered {
            Rendered::Photo => None,
            Rendered::Frame(s) => Some(s.composite()),
        }
    }

    /// The augmented photo, linear.
    pub fn image(&self) -> &Image {
        self.composite().map_or(&self.photo, |c| &c.image)
    }

    /// Makes `edit` and renders its state; a refused edit changes nothing.
    /// Each edit that changes the state is one undo step.
    pub fn apply(
        &mut self,
        edit: Edit,
        times: &mut StageTimes,
    ) -> std::result::Result<Outcome, Refusal> {
        self.step(edit, false, times)
    }

    /// [`Interactive::apply`] of a drag's move: a move of the object the
    /// last step placed belongs to that step (one undo takes the whole
    /// drag back).
    pub fn apply_drag(
        &mut self,
        edit: Edit,
        times: &mut StageTimes,
    ) -> std::result::Result<Outcome, Refusal> {
        self.step(edit, true, times)
    }

    /// Steps that undo and redo can take now.
    pub fn history(&self) -> (usize, usize) {
        (self.undo.len(), self.redo.len())
    }

    fn step(
        &mut self,
        edit: Edit,
        drag: bool,
        times: &mut StageTimes,
    ) -> std::result::Result<Outcome, Refusal> {
        let before: Snapshot = (self.objects.clone(), self.lights.clone());
        let placed = match edit {
            Edit::Undo => return self.travel(false, times),
            Edit::Redo => return self.travel(true, times),
            Edit::Place { object, .. } => Some(object),
            _ => None,
        };
        let outcome = self.change(edit, times)?;
        let continues = drag && placed.is_some() && placed == self.placing;
        if !continues && before != (self.objects.clone(), self.lights.clone()) {
            if self.undo.len() == UNDO_STEPS {
                self.undo.remove(0);
            }
            self.undo.push(before);
            self.redo.clear();
        }
        self.placing = placed;
        Ok(outcome)
    }

    /// Back to the last undo step's state (`forward`: the last redo's),
    /// rendered; the state left goes on the other list.
    fn travel(
        &mut self,
        forward: bool,
        times: &mut StageTimes,
    ) -> std::result::Result<Outcome, Refusal> {
        let (field, what) = match forward {
            true => ("redo", "nothing to redo"),
            false => ("undo", "nothing to undo"),
        };
        let list = if forward {
            &mut self.redo
        } else {
            &mut self.undo
        };
        let Some(target) = list.pop() else {
            return Err(Refusal::new(field, what));
        };
        let left: Snapshot = (self.objects.clone(), self.lights.clone());
        (self.objects, self.lights) = target.clone();
        // A state from before an object was added: the object as added (hidden).
        self.objects
            .resize(self.base.objects.len(), ObjectEdit::default());
        let rendered = self
            .state_scene()
            .and_then(|scene| self.render(scene, times))
            .map_err(|e| Refusal::new("state", e.to_string()));
        match rendered {
            Ok(outcome) => {
                let other = if forward {
                    &mut self.undo
                } else {
                    &mut self.redo
                };
                other.push(left);
                self.placing = None;
                Ok(outcome)
            }
            Err(r) => {
                (self.objects, self.lights) = left;
                let list = if forward {
                    &mut self.redo
                } else {
                    &mut self.undo
                };
                list.push(target);
                Err(r)
            }
        }
    }

    /// Makes `edit` (not undo or redo) and renders its state.
    fn change(
        &mut self,
        edit: Edit,
        times: &mut StageTimes,
    ) -> std::result::Result<Outcome, Refusal> {
        let (objects, lights) = (self.objects.clone(), self.lights.clone());
        let (object, field) = match edit {
            Edit::Place { object, .. } => (Some(object), "x"),
            Edit::Turn { object, .. } => (Some(object), "yaw_deg"),
            Edit::Scale { object, .. } => (Some(object), "scale"),
            Edit::Enable { object, .. } => (Some(object), "enabled"),
            Edit::Nudge { object, .. } => (Some(object), "nudge"),
            Edit::Light { .. } => (None, "scale"),
            Edit::PlaceLight { .. } => (None, "height_m"),
            // Taken by `step` before; no state of its own to change here.
            Edit::Undo | Edit::Redo => (None, "edit"),
        };
        let result = self.edit(edit).and_then(|()| {
            let scene = self
                .state_scene()
                .map_err(|e| Refusal::new(field, e.message))?;
            if let Some(k) = object.filter(|&o| scene.objects[o].enabled) {
                let o = &scene.objects[k];
                self.room
                    .check_place(o)
                    .map_err(|m| Refusal::new(field, m))?;
                let through = crate::placement::Others::passed_through(&mut self.others, &scene, k)
                    .map_err(|e| Refusal::new("state", e.to_string()))?;
                if let Some((other, depth)) = through {
                    return Err(Refusal::new(
                        field,
                        format!(
                            "'{}' would pass through '{other}' ({:.1} cm deep)",
                            o.name,
                            100.0 * depth
                        ),
                    ));
                }
            }
            self.render(scene, times)
                .map_err(|e| Refusal::new("state", e.to_string()))
        });
        if result.is_err() {
            (self.objects, self.lights) = (objects, lights);
        }
        result
    }

    /// Records `edit` in the state, after checking its values.
    fn edit(&mut self, edit: Edit) -> std::result::Result<(), Refusal> {
        let object = |o: usize| {
            (o < self.base.objects.len())
                .then_some(o)
                .ok_or_else(|| Refusal::new("object", format!("no virtual object {o}")))
        };
        let finite = |field: &'static str, v: f64| {
            v.is_finite()
                .then_some(v)
                .ok_or_else(|| Refusal::new(field, "must be a finite number"))
        };
        match edit {
            Edit::Place { object: o, x, y } => {
                let o = object(o)?;
                // An object being added is not in the state's scene yet.
                let pose = self
                    .scene
                    .objects
                    .get(o)
                    .unwrap_or(&self.base.objects[o])
                    .pose;
                let translate = self.room.standing_place(
                    &self.base.camera,
                    &self.base.objects[o],
                    &pose,
                    (x, y),
                )?;
                self.objects[o].translate = Some(translate);
                self.objects[o].enabled = Some(true);
            }
            Edit::Turn { object: o, yaw_deg } => {
                let o = object(o)?;
                let yaw = finite("yaw_deg", yaw_deg)?;
                if yaw.abs() > 3600.0 {
                    return Err(Refusal::new("yaw_deg", "must lie within ±3600 degrees"));
                }
                self.objects[o].yaw_deg = Some(yaw);
            }
            Edit::Scale { object: o, scale } => {
                let o = object(o)?;
                let s = finite("scale", scale)?;
                let (lo, hi) = SCALE_RANGE;
                if !(lo..=hi).contains(&s) {
                    return Err(Refusal::new("scale", format!("must lie in {lo}..={hi}")));
                }
                self.objects[o].scale = Some(s);
            }
            Edit::Enable { object: o, enabled } => {
                let o = object(o)?;
                self.objects[o].enabled = Some(enabled);
            }
            Edit::Nudge {
                object: o,
                right_m,
                forward_m,
            } => {
                let o = object(o)?;
                let (r, f) = (finite("nudge", right_m)?, finite("nudge", forward_m)?);
                if r.abs() > 1.0 || f.abs() > 1.0 {
                    return Err(Refusal::new("nudge", "at most a metre each way"));
                }
                let flat = |v: DVec3| DVec3::new(v.x, 0.0, v.z).normalize_or_zero();
                let camera = &self.base.camera;
                let t = self.scene.objects[o].pose.translate;
                self.objects[o].translate =
                    Some(t + flat(camera.right) * r + flat(camera.forward) * f);
                self.objects[o].enabled = Some(true);
            }
            Edit::Light { light, scale } => {
                let l = self.light(light)?;
                self.lights[l].scale = Some(lights::checked_scale(scale)?);
            }
            Edit::PlaceLight {
                light,
                x,
                y,
                height_m,
            } => {
                let l = self.light(light)?;
                lights::movable(&self.base.lights[l])?;
                let at = self.room.light_place(&self.base.camera, (x, y), height_m)?;
                self.lights[l].position = Some(at);
                if self.scene.lights[l].scale == 0.0 {
                    self.lights[l].scale = Some(1.0);
                }
            }
            Edit::Undo | Edit::Redo => {
                return Err(Refusal::new("edit", "undo and redo are steps, not changes"));
            }
        }
        Ok(())
    }

    /// `light` as an index of the scene's lights.
    fn light(&self, light: usize) -> std::result::Result<usize, Refusal> {
        (light < self.base.lights.len())
            .then_some(light)
            .ok_or_else(|| Refusal::new("light", format!("no light {light}")))
    }

    /// The state as the `[[variant]]` table named `name` it is saved as.
    pub fn variant_table(&self, name: &str) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("name".into(), name.into());
        let mut lights = toml::Table::new();
        for (l, e) in self.base.lights.iter().zip(&self.lights) {
            if let Some(value) = lights::variant_value(l, e) {
                lights.insert(l.name.clone(), value);
            }
        }
        let (mut objects, mut hide) = (toml::Table::new(), toml::value::Array::new());
        for (o, e) in self.base.objects.iter().zip(&self.objects) {
            let enabled = e.enabled.unwrap_or(o.enabled);
            if !enabled {
                if o.enabled {
                    hide.push(o.name.clone().into());
                }
                continue;
            }
            let mut pose = toml::Table::new();
            if let Some(p) = e.translate {
                pose.insert("translate".into(), vec3(p));
            }
            if let Some(yaw) = e.yaw_deg {
                rotation_keys(&mut pose, o.pose.rotation, yaw);
            }
            if let Some(s) = e.scale {
                pose.insert("scale".into(), s.into());
            }
            if !pose.is_empty() || !o.enabled {
                objects.insert(o.name.clone(), pose.into());
            }
        }
        for (key, table) in [("lights", lights), ("objects", objects)] {
            if !table.is_empty() {
                t.insert(key.into(), table.into());
            }
        }
        if !hide.is_empty() {
            t.insert("hide".into(), hide.into());
        }
        t
    }

    /// The effective scene of the state, read back from its variant table.
    fn state_scene(&self) -> Result<Scene> {
        let variant = self.base.parse_variant(&self.variant_table("session"))?;
        self.base.with_given_variant(&variant)
    }

    /// Renders `scene` by the cheapest exact path.
    fn render(&mut self, scene: Scene, times: &mut StageTimes) -> Result<Outcome> {
        let start = std::time::Instant::now();
        let scales = |s: &Scene| s.lights.iter().map(|l| l.scale).collect::<Vec<_>>();
        let places = |s: &Scene| (s.lights.iter().map(|l| l.known_position())).collect::<Vec<_>>();
        let moved = places(&scene) != places(&self.scene);
        let enabled = |s: &Scene| s.objects.iter().map(|o| o.enabled).collect::<Vec<_>>();
        let same_lights = scales(&scene) == scales(&self.scene) && !moved;
        let same_shown = enabled(&scene) == enabled(&self.scene);
        let same_poses =
            (self.scene.objects.iter().zip(&scene.objects)).all(|(a, b)| a.pose == b.pose);
        if same_lights && same_shown && same_poses {
            return Ok(self.outcome(RenderPath::Unchanged, start));
        }
        // Every composite rewrites every pixel: the next image shows the
        // session's own rounds again.
        self.refined = (0, None);
        let path = if !scene.changes_the_photo() {
            self.rendered = Rendered::Photo;
            self.scene = scene;
            RenderPath::Photo
        } else if let (Rendered::Frame(session), true) =
            (&mut self.rendered, same_lights && same_shown)
        {
            let stats = session.update(&scene, times)?;
            self.scene = scene;
            self.relights_ahead = false;
            match stats {
                Some(stats) => RenderPath::Update {
                    pixels_recomputed: stats.pixels_recomputed,
                    pixels_retraced: stats.pixels_retraced,
                    rays: stats.rays,
                },
                None => RenderPath::Full {
                    reason: "the texture path renders every move in full".into(),
                },
            }
        } else if let (Rendered::Frame(session), true) =
            (&mut self.rendered, same_shown && same_poses && !moved)
        {
            match session.relight(&scene, times) {
                Ok(()) => {
                    self.scene = scene;
                    self.relights_ahead = true;
                    RenderPath::Relight
                }
                Err(why) => {
                    let reason = format!("the lights changed ({})", why.describe());
                    match why {
                        crate::render::Relight::PatchSize => {
                            self.render_by_standby(scene, reason, times)?
                        }
                        _ => self.render_full(scene, reason, times)?,
                    }
                }
            }
        } else {
            let reason = if moved {
                "a light moved"
            } else if !same_lights {
                "the lights changed"
            } else {
                "the set of objects shown changed"
            };
            self.render_full(scene, reason.into(), times)?
        };
        self.version += 1;
        Ok(self.outcome(path, start))
    }

    fn render_full(
        &mut self,
        scene: Scene,
        reason: String,
        times: &mut StageTimes,
    ) -> Result<RenderPath> {
        self.rendered = if scene.changes_the_photo() {
            let mut renderer = Renderer::start(&scene, &self.photo, &self.method, times)?;
            // What the views show: the image, the objects' coverage and
            // their own light (the shadow-catcher factor); every layer only
            // when saved ([`Interactive::with_every_layer`]).
            renderer.keep_layers(crate::composite::Layers::Object);
            Rendered::Frame(Box::new(renderer))
        } else {
            Rendered::Photo
        };
        self.relights_ahead = true;
        self.scene = scene;
        Ok(RenderPath::Full { reason })
    }

    fn outcome(&self, path: RenderPath, start: std::time::Instant) -> Outcome {
        Outcome {
            version: self.version,
            path,
            millis: start.elapsed().as_secs_f64() * 1e3,
        }
    }

    /// The rectangle of the image the object's box covers as placed (pixel
    /// coordinates x0, y0, x1, y1, clipped to the frame): what the page
    /// outlines for the selected object. None where the box is out of the
    /// frame or reaches behind the camera.
    pub fn screen_box(&self, object: usize) -> Option<[f64; 4]> {
        let camera = &self.base.camera;
        let rect = crate::placement::screen_rect(camera, self.scene.objects.get(object)?)?;
        let (w, h) = (camera.width as f64, camera.height as f64);
        let clipped = [
            rect[0].max(0.0),
            rect[1].max(0.0),
            rect[2].min(w),
            rect[3].min(h),
        ];
        (clipped[0] < clipped[2] && clipped[1] < clipped[3]).then_some(clipped)
    }

    /// The object's state as the page shows it: enabled, where it stands,
    /// its heading and scale.
    pub fn object_state(&self, object: usize) -> (bool, DVec3, f64, f64) {
        let o = &self.scene.objects[object];
        let yaw = self.objects[object]
            .yaw_deg
            .unwrap_or_else(|| heading_deg(o.pose.rotation));
        (o.enabled, o.pose.translate, yaw, o.pose.scale)
    }

    /// The room the edits are checked against.
    pub fn room(&self) -> &Room {
        &self.room
    }
}

fn vec3(v: DVec3) -> toml::Value {
    toml::Value::Array(v.to_array().iter().map(|&c| c.into()).collect())
}

/// The heading of a rotation about the vertical: the angle of its x axis
/// seen from above, counter-clockwise (`rotate_y_deg`'s sense).
fn heading_deg(r: DMat3) -> f64 {
    let x = r.col(0);
    (-x.z).atan2(x.x).to_degrees()
}

/// The keys that turn an object whose base rotation is `base` to heading
/// `yaw`: `rotate_y_deg` when the base turns about the vertical only,
/// else a quaternion of the base turned about the vertical.
fn rotation_keys(pose: &mut toml::Table, base: DMat3, yaw: f64) {
    let upright = (base.col(1) - DVec3::Y).length() < 1e-12;
    if upright {
        pose.insert("rotate_y_deg".into(), yaw.into());
        return;
    }
    let turn = DMat3::from_rotation_y((yaw - heading_deg(base)).to_radians());
    let q = DQuat::from_mat3(&(turn * base)).normalize();
    pose.insert(
        "quaternion".into(),
        toml::Value::Array([q.w, q.x, q.y, q.z].iter().map(|&c| c.into()).collect()),
    );
}
