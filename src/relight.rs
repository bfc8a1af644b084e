//! The radiosity-texture path (Loscos, Drettakis & Robert 2000): relighting
//! the real scene by modulating shadow-free textures with B/D.
//!
//! Preprocess ([`TexturePath::prepare`]), once per scene and set of
//! inserted lights and objects:
//! 1. **Texture-based refinement** (§4.1, Fig. 12): the room's mesh is split
//!    where a leaf and its neighbours disagree — similar CIELAB colour (Eq. 4)
//!    but different visibility of a real light, different colour but similar
//!    visibility, or partial visibility — and a split is undone when its two
//!    halves see every light as the leaf did. Lights and objects the user
//!    inserts force the same refinement on their own visibility (§4.5).
//! 2. **Textures**: the photo re-projected into each root polygon's own
//!    parameters, two texels per pixel footprint (fixed viewpoint).
//! 3. **Unoccluded illumination textures**: Step 1 adds the blocked direct
//!    light (Eq. 5-6); Step 2 corrects each occluded leaf from a reference
//!    leaf of similar colour on the frontier of unoccluded leaves (Eq. 7-9,
//!    Fig. 16, its reference being the frontier leaf n), or from the
//!    `[[texture_reference]]` the user gave for the surface.
//! 4. D = ρ_final·(unoccluded direct + indirect), B_final by a radiosity step.
//!
//! A light change ([`TexturePath::relight`]) is a radiosity solve on the kept
//! mesh and links plus the display T_final × B/D (Eq. 3), in floating point:
//! no multi-pass, no clamping at 1. Where D ≈ 0 (the photo's lights did not
//! reach the surface, so its texture holds no information) the pixel shows
//! the radiosity B/π instead, counted.
//!
//! arlux's reflectances divide by the irradiance (EQ2), where Loscos's Eq. 1
//! only scales the texture's brightness; Eq. 7-8's form-factor ratio is what
//! turns one into the other, so here Eq. 8 reads ρ_corr = ρ_r and Eq. 9
//! T_final = (ρ_r / ρ_inter) · T_inter, which is Eq. 7 with the light
//! sources' (and the indirect light's) irradiance as the weights.

use std::collections::HashMap;

use glam::{DVec2, DVec3, Vec3};
use rayon::prelude::*;

use crate::composite::{Composite, PixelShade};
use crate::error::Result;
use crate::estimate::{Estimate, PhotoPatches, estimate_reflectances};
use crate::image_io::Image;
use crate::light::LightSource;
pub use crate::output::TextureStats;
use crate::patches::{Element, Location, Patches, Shape, SplitMarks, region_centre, split};
use crate::radiosity::{DEFAULT_LINK_EPSILON, Transport, solve_from};
use crate::scene::Scene;
use crate::trace::{Layer, Tracer};
use crate::util::rng::hash2;
use crate::util::stages::StageTimes;

/// Settings of the texture path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TextureSettings {
    /// The starting mesh's largest patch edge, metres (None: the room's
    /// diagonal / 24, as light variants use on the pixel path).
    pub patch_size: Option<f64>,
    /// CIELAB distance (Eq. 4) under which two leaves have similar colour.
    pub colour_threshold: f64,
    /// Difference of visibility (attenuation, 0..1) under which two leaves
    /// see a light alike; also the margin of VISIBLE (≥ 1 − it) and
    /// OCCLUDED (≤ it).
    pub visibility_threshold: f64,
    /// CIELAB distance under which a frontier leaf may be a reference.
    pub reference_colour_threshold: f64,
    /// The smallest leaf, in pixel footprints at its nearest seen point.
    pub min_leaf_pixels: f64,
    /// Texels per pixel footprint (2 makes the photo → texture → pixel
    /// round trip exact; see `texels_per_pixel_two_round_trips_exactly`).
    pub texels_per_pixel: f64,
    pub max_rounds: usize,
    /// 2^level shadow rays per quadrature point towards rect lights.
    pub light_level: usize,
    pub link_epsilon: f64,
    /// Keep the room's links in `.arlux-cache/` (see
    /// [`crate::model::ModelSettings::cache_links`]).
    pub cache_links: bool,
    /// The memory the preprocess may hold, bytes: linking the objects is
    /// refused before it starts when its estimate (measured on a sample of
    /// the objects' triangles) would pass it. None: not checked.
    pub memory: Option<u64>,
    /// Rays each group of the objects' leaves gathers its light with (as
    /// the pixel path's final gather, `RenderSettings::gather_rays`).
    pub object_rays: u32,
    /// Objects of this many triangles or more take their leaves on a
    /// coarse mesh of their shape (as the pixel path's
    /// `RenderSettings::coarse_objects_from`; None: a leaf per triangle).
    pub coarse_objects_from: Option<usize>,
}

impl Default for TextureSettings {
    fn default() -> Self {
        TextureSettings {
            patch_size: None,
            colour_threshold: 10.0,
            visibility_threshold: 0.2,
            reference_colour_threshold: 10.0,
            min_leaf_pixels: 3.0,
            texels_per_pixel: 2.0,
            max_rounds: 16,
            light_level: 4,
            link_epsilon: DEFAULT_LINK_EPSILON,
            cache_links: false,
            memory: None,
            object_rays: 576,
            coarse_objects_from: Some(crate::scene_tracer::INSTANCE_TRIANGLES),
        }
    }
}

/// What the camera sees at a pixel centre.
#[derive(Debug, Clone, Copy)]
enum PixelPoint {
    /// `texture` indexes [`TexturePath::textures`].
    Real {
        texture: u32,
        at: Location,
        texel: u32,
    },
    Virtual {
        at: Location,
    },
}

/// The preprocessed scene: mesh, links, shadow-free textures, D.
pub struct TexturePath {
    patches: Patches,
    lights: Vec<LightSource>,
    /// Direct irradiance per light and leaf before scales, through every
    /// layer the scene has (virtual objects shadow the room).
    direct: Vec<Vec<DVec3>>,
    transport: Transport,
    reflectance: Vec<DVec3>,
    /// B_final: the solve's starting guess after a change.
    radiosity_final: Vec<DVec3>,
    /// Visibility per light at each vertex (through the objects too).
    visibility: Vec<Vec<f64>>,
    /// D per pixel: irradiance of the photo's lights unoccluded plus the
    /// indirect light of the unoccluded solution (D = ρ·this; ρ cancels).
    display: Vec<Vec3>,
    /// Each light's unoccluded irradiance per pixel (pixel-major).
    unoccluded: Vec<Vec3>,
    d_floor: f64,
    /// One per root polygon the camera sees, in root order.
    textures: Vec<Texture>,
    pixels: Vec<Option<PixelPoint>>,
    photo: Image,
    solve_tolerance: f64,
    pub stats: TextureStats,
}

impl TexturePath {
    /// Preprocesses `scene` (a variant or the scene itself: its inserted
    /// lights and objects take part in the refinement) over `photo`.
    pub fn prepare(
        scene: &Scene,
        photo: &Image,
        tracer: &Tracer,
        settings: &TextureSettings,
        times: &mut StageTimes,
    ) -> Result<TexturePath> {
        let setup = Setup::new(scene, photo, tracer, settings)?;
        let patch_size = setup.patch_size;
        let mut stats = TextureStats {
            patch_size,
            ..Default::default()
        };
        let base = times.time("mesh", || Patches::of_scene(scene, false, patch_size));
        // The user's references, checked before any work.
        let user_points = user_points(scene, &base)?;
        let hits = times.time("camera rays", || real_hits(scene, tracer));
        let (patches, marks) = times.time("texture-based refinement", || {
            setup.refine(base, &hits, &mut stats)
        });
        let real_patches = patches.patch_count();
        stats.leaves = real_patches;
        let model = setup.real_model(&patches, times);
        let solve_tolerance = crate::estimate::EstimateSettings::default().solve_tolerance;

        let steps_started = std::time::Instant::now();
        let (unshadow, rho_final) =
            unshadow(&setup, &patches, &model, &hits, &user_points, &mut stats);
        times.0.push(("steps 1 and 2", steps_started.elapsed()));
        // B_final by a radiosity step.
        let final_solution = times.time("solve unoccluded", || {
            let b: Vec<DVec3> = rho_final
                .iter()
                .zip(&model.e_occluded)
                .map(|(r, e)| *r * *e)
                .collect();
            solve_from(
                &patches,
                &model.transport,
                &rho_final,
                &b,
                Some(&model.estimate.solution.radiosity),
                solve_tolerance,
                500,
            )
        });

        // The textures: photo re-projected, then Steps 1 and 2 applied per texel.
        let textures = times.time("textures", || {
            build_textures(
                scene,
                &patches,
                &hits,
                photo,
                setup.pixel_angle,
                settings.texels_per_pixel,
                &|root, x| unshadow.at_root_point(root, x),
            )
        });
        let (textures, texture_of) = index_textures(textures);
        stats.texels = textures.iter().map(|t| t.texels.len()).sum();
        stats.texture_bytes = stats.texels * std::mem::size_of::<Vec3>();

        let (patches, direct, transport) = setup.with_objects(
            patches,
            model.direct,
            model.transport,
            &marks,
            times,
            &mut stats,
        )?;
        stats.links = transport.link_count();
        let rest_started = std::time::Instant::now();
        let visibility = vertex_visibility(&direct, &patches);
        let direct: Vec<Vec<DVec3>> = direct
            .iter()
            .map(|l| l.iter().map(|t| t.occluded).collect())
            .collect();
        let mut reflectance = rho_final;
        reflectance.extend(crate::radiosity::object_reflectances(
            scene,
            &patches,
            real_patches,
        ));
        let mut radiosity_final = final_solution.radiosity;
        radiosity_final.resize(patches.patch_count(), DVec3::ZERO);
        let mut h_final = final_solution.indirect_irradiance;
        h_final.resize(patches.patch_count(), DVec3::ZERO);
        let h_final_vertex = patches.vertex_values(&h_final);
        times
            .0
            .push(("reflectances and links", rest_started.elapsed()));

        let (pixels, unoccluded) = times.time("pixel points", || {
            pixel_points(&setup, &patches, &textures, &texture_of)
        });
        let display_started = std::time::Instant::now();
        let (display, d_floor) =
            display_factors(&setup, &patches, &pixels, &unoccluded, &h_final_vertex);
        times.0.push(("display factors", display_started.elapsed()));
        Ok(TexturePath {
            lights: setup.lights,
            patches,
            direct,
            visibility,
            transport,
            reflectance,
            radiosity_final,
            display,
            unoccluded,
            d_floor,
            textures,
            pixels,
            photo: photo.clone(),
            solve_tolerance,
            stats,
        })
    }

    /// The lights, in the scene's order (their `scale` as the scene gave it).
    pub fn lights(&self) -> &[LightSource] {
        &self.lights
    }

    /// The unoccluded illumination texture seen from the camera (Loscos
    /// Fig. 17(c)); the photo where no real surface is seen.
    pub fn unoccluded_texture(&self) -> Image {
        let mut out = self.photo.clone();
        for (o, p) in out.pixels.iter_mut().zip(&self.pixels) {
            if let Some(PixelPoint::Real { texture, texel, .. }) = p {
                *o = self.textures[*texture as usize].texels[*texel as usize];
            }
        }
        out
    }

    /// Bytes of the textures and of what is kept per pixel (its point, D,
    /// each light's unoccluded irradiance).
    pub fn memory_bytes(&self) -> usize {
        self.stats.texture_bytes
            + self.pixels.len() * std::mem::size_of::<Option<PixelPoint>>()
            + (self.display.len() + self.unoccluded.len()) * std::mem::size_of::<Vec3>()
    }

    /// What the kept links take in memory.
    pub fn links_bytes(&self) -> usize {
        self.transport.memory_bytes()
    }

    /// Leaves of the mesh, the inserted objects' included.
    pub fn patch_count(&self) -> usize {
        self.patches.patch_count()
    }

    /// The scene under light scales `scales` (one per light, the scene's
    /// order): a radiosity solve on the kept mesh and links, then the display
    /// T_final × B/D (Eq. 3).
    pub fn relight(&self, scales: &[f64], times: &mut StageTimes) -> Composite {
        self.relight_with_objects(scales, None, times)
    }

    /// [`TexturePath::relight`], the pixels of objects with materials then
    /// shaded by their BRDF (`objects`: the scene as posed and its tracer).
    pub fn relight_with_objects(
        &self,
        scales: &[f64],
        objects: Option<(&Scene, &Tracer)>,
        times: &mut StageTimes,
    ) -> Composite {
        let n = self.patches.patch_count();
        let mut e = vec![DVec3::ZERO; n];
        for (l, &s) in scales.iter().enumerate() {
            if s > 0.0 {
                for (e, d) in e.iter_mut().zip(&self.direct[l]) {
                    *e += *d * s;
                }
            }
        }
        let solution = times.time("radiosity step", || {
            let b: Vec<DVec3> = self
                .reflectance
                .iter()
                .zip(&e)
                .map(|(r, e)| *r * *e)
                .collect();
            solve_from(
                &self.patches,
                &self.transport,
                &self.reflectance,
                &b,
                Some(&self.radiosity_final),
                self.solve_tolerance,
                500,
            )
        });
        let mut out = times.time("display", || {
            self.display(scales, &solution.indirect_irradiance)
        });
        if let Some((scene, tracer)) = objects {
            times.time("objects' materials", || {
                self.shade_objects(
                    &mut out,
                    scene,
                    tracer,
                    scales,
                    &solution.indirect_irradiance,
                )
            });
            times.time("objects' outlines", || {
                self.antialias_edges(&mut out, &scene.camera, tracer)
            });
        }
        out
    }
}

/// The texture path's frame of a variant: its preprocess and what its
/// light changes read, kept so that new scales relight it in place.
pub struct TextureFrame {
    /// The scene as prepared (a light to reconstruct replaced by what was recovered).
    scene: Scene,
    tracer: Tracer,
    /// The photo as the stages read it (lamps in view filled).
    photo: Image,
    lamps: Option<(crate::lamps::LampPixels, Image)>,
    path: TexturePath,
    left_out: Vec<String>,
}

impl TextureFrame {
    /// The preprocess for `scene` (a variant: its inserted lights and
    /// objects refine the mesh).
    pub fn prepare(
        scene: &Scene,
        photo: &Image,
        settings: &TextureSettings,
        times: &mut StageTimes,
    ) -> Result<TextureFrame> {
        let tracer = times.time("tracer", || crate::scene_tracer::build_tracer(scene))?;
        let mut left_out = Vec::new();
        let (resolved, photo) = crate::inputs::resolve_inputs(
            scene,
            photo,
            &tracer,
            &crate::model::ModelSettings::default(),
            times,
            &mut left_out,
        )?;
        let scene = resolved.unwrap_or_else(|| scene.clone());
        if tracer.virtual_objects.is_none() {
            left_out.push("virtual geometry: no virtual object".to_string());
        }
        let supersample = crate::pda::PdaSettings::default().supersample;
        let (photo, lamps) =
            crate::inputs::lamps_in_view(&scene, photo, &tracer, supersample, times)?;
        if lamps.is_none() {
            left_out.push("lamps in view: no rect light is seen".to_string());
        }
        let path = TexturePath::prepare(&scene, &photo, &tracer, settings, times)?;
        Ok(TextureFrame {
            scene,
            tracer,
            photo,
            lamps,
            path,
            left_out,
        })
    }

    /// Whether `scene` is this frame's but for its lights' scales, with the
    /// same lights on: the preprocess reads which lights are on, not their
    /// scales, so a relight of it is the frame a preprocess of `scene` gives.
    pub fn relights(&self, scene: &Scene) -> bool {
        let kept = &self.scene;
        // Each light but for its scale, with the same on or off.
        let same_light = |a: &crate::scene::Light, b: &crate::scene::Light| {
            (a.scale > 0.0) == (b.scale > 0.0)
                && crate::scene::Light {
                    scale: b.scale,
                    ..a.clone()
                } == *b
        };
        scene.camera == kept.camera
            && scene.lights.len() == kept.lights.len()
            && (scene.lights.iter().zip(&kept.lights)).all(|(a, b)| same_light(a, b))
            && scene.objects.len() == kept.objects.len()
            && (scene.objects.iter().zip(&kept.objects))
                .all(|(a, b)| a.enabled == b.enabled && a.pose == b.pose)
    }

    /// The frame at the scene's scales: one light change (Loscos §5), with
    /// the lamps in view at their scales; its report.
    pub fn render(&mut self, scene: &Scene, times: &mut StageTimes) -> crate::output::RenderOutput {
        for (kept, given) in self.scene.lights.iter_mut().zip(&scene.lights) {
            kept.scale = given.scale;
        }
        let (scene, path, tracer, photo) = (&self.scene, &self.path, &self.tracer, &self.photo);
        let scales: Vec<f64> = scene.lights.iter().map(|l| l.scale).collect();
        let before = times.total();
        let mut composite = path.relight_with_objects(&scales, Some((scene, tracer)), times);
        if let Some((lamps, shot)) = &self.lamps {
            times.time("lamps in view", || {
                lamps.apply(&mut composite, shot, photo, &scales, tracer)
            });
        }
        let light_change = times.total() - before;
        let unoccluded = times.time("unoccluded texture", || path.unoccluded_texture());
        let mut warnings = crate::inputs::input_warnings(photo, None);
        warnings.extend(times.time("placement checks", || {
            crate::placement::warnings(scene, photo, tracer)
        }));
        crate::output::RenderOutput {
            warnings,
            composite,
            left_out: self.left_out.clone(),
            pda_bytes: path.memory_bytes(),
            pda_pixels: path.pixels.len(),
            rays: 0,
            patches: path.patch_count(),
            links: path.stats.links,
            elements: path.patches.elements.len(),
            links_bytes: path.links_bytes(),
            room_solution_bytes: 0,
            change_bytes: 0,
            patch_size: path.stats.patch_size,
            texture: Some((path.stats.clone(), unoccluded, light_change)),
            residual: None,
        }
    }
}

/// `arlux render --method texture`: the preprocess for `scene` (a variant:
/// its inserted lights and objects refine the mesh), then one light change
/// to the variant's scales.
pub fn render_texture(
    scene: &Scene,
    photo: &Image,
    settings: &TextureSettings,
    times: &mut StageTimes,
) -> Result<crate::output::RenderOutput> {
    let mut frame = TextureFrame::prepare(scene, photo, settings, times)?;
    let out = frame.render(scene, times);
    times.time("free", || drop(frame));
    Ok(out)
}

mod display;
mod edges;
mod objects;
mod preprocess;
mod refine;
mod textures;

use preprocess::*;
use refine::*;
pub(crate) use refine::{cielab, colour_distance};
use textures::*;

#[cfg(test)]
mod tests;
