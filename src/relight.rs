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
use crate::model::StageTimes;
pub use crate::output::TextureStats;
use crate::patches::{Element, Location, Patches, Shape, SplitMarks, region_centre, split};
use crate::radiosity::{DEFAULT_LINK_EPSILON, Transport, solve_from};
use crate::scene::Scene;
use crate::trace::{Layer, Tracer};
use crate::util::rng::hash2;

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

/// What the preprocess derives from its inputs before any work.
struct Setup<'a> {
    scene: &'a Scene,
    photo: &'a Image,
    tracer: &'a Tracer,
    settings: &'a TextureSettings,
    lights: Vec<LightSource>,
    /// Each light's scale in the photo.
    photo_scales: Vec<f64>,
    has_objects: bool,
    patch_size: f64,
    virtual_size: f64,
    criteria: Criteria,
    pixel_angle: f64,
}

impl<'a> Setup<'a> {
    fn new(
        scene: &'a Scene,
        photo: &'a Image,
        tracer: &'a Tracer,
        settings: &'a TextureSettings,
    ) -> Result<Self> {
        let lights = LightSource::all(scene)?;
        let photo_scales: Vec<f64> = lights.iter().map(|l| l.photo_scale()).collect();
        let has_objects = tracer.virtual_objects.is_some();
        let patch_size = settings
            .patch_size
            .unwrap_or_else(|| crate::inputs::fine_patch_size(scene));
        let criteria = Criteria {
            texture: (0..lights.len())
                .filter(|&l| photo_scales[l] > 0.0)
                .collect(),
            forced: (0..lights.len())
                .filter(|&l| lights[l].scale > 0.0 && (photo_scales[l] == 0.0 || has_objects))
                .map(|l| (l, if has_objects { Layer::All } else { Layer::Real }))
                .collect(),
        };
        let cam = &scene.camera;
        Ok(Setup {
            scene,
            photo,
            tracer,
            settings,
            lights,
            photo_scales,
            has_objects,
            patch_size,
            virtual_size: 0.1f64.min(patch_size),
            criteria,
            pixel_angle: 1.0 / cam.fx.min(cam.fy),
        })
    }

    /// Texture-based refinement (Fig. 12), one level per round: the refined
    /// mesh and its split marks.
    fn refine(
        &self,
        base: Patches,
        hits: &[Option<RealHit>],
        stats: &mut TextureStats,
    ) -> (Patches, SplitMarks) {
        let refiner = Refiner {
            hits,
            photo: self.photo,
            pixel_angle: self.pixel_angle,
            white: white_level(hits, self.photo),
            lights: &self.lights,
            criteria: &self.criteria,
            tracer: self.tracer,
            settings: self.settings,
        };
        let mut marks = SplitMarks::new();
        let mut cache = TermCache::new();
        let mut patches = base;
        for _ in 0..self.settings.max_rounds {
            stats.rounds += 1;
            if refiner.round(&patches, &mut cache, &mut marks, stats) == 0 {
                break;
            }
            patches = Patches::of_scene_refined(
                self.scene,
                false,
                self.patch_size,
                self.virtual_size,
                &marks,
            );
        }
        (patches, marks)
    }

    /// The mesh with the inserted objects, the direct light through them
    /// and the links with them (the room's as given when there is none).
    fn with_objects(
        &self,
        patches: Patches,
        direct: Vec<Vec<LightTerm>>,
        transport: Transport,
        marks: &SplitMarks,
        times: &mut StageTimes,
    ) -> (Patches, Vec<Vec<LightTerm>>, Transport) {
        if !self.has_objects {
            return (patches, direct, transport);
        }
        let (tracer, settings) = (self.tracer, self.settings);
        let all = times.time("virtual mesh", || {
            Patches::of_scene_refined(self.scene, true, self.patch_size, self.virtual_size, marks)
        });
        let direct = times.time("direct light with objects", || {
            leaf_light(&all, &self.lights, tracer, Layer::All, settings.light_level)
        });
        let transport = times.time("form factors with objects", || {
            transport.with_objects(&all, tracer, settings.link_epsilon, true)
        });
        (all, direct, transport)
    }

    /// The photo's illumination model on the refined mesh (links at the
    /// leaves for the light sources: direct light is per leaf).
    fn real_model(&self, patches: &Patches, times: &mut StageTimes) -> RealModel {
        let (lights, tracer) = (&self.lights, self.tracer);
        let direct = times.time("direct light", || {
            leaf_light(
                patches,
                lights,
                tracer,
                Layer::Real,
                self.settings.light_level,
            )
        });
        let transport = times.time("form factors", || {
            Transport::hierarchical(patches, tracer, Layer::Real, self.settings.link_epsilon)
        });
        let measured = times.time("photo per patch", || {
            PhotoPatches::measure(&self.scene.camera, tracer, patches, self.photo)
        });
        let known: HashMap<u32, DVec3> = self
            .scene
            .reflectances
            .iter()
            .map(|k| (k.surface as u32, k.rgb))
            .collect();
        let sum_scaled = |f: &dyn Fn(&LightTerm) -> DVec3, k: usize| -> DVec3 {
            (0..lights.len())
                .filter(|&l| self.photo_scales[l] > 0.0)
                .map(|l| f(&direct[l][k]) * self.photo_scales[l])
                .sum()
        };
        let n = patches.patch_count();
        let e_occluded: Vec<DVec3> = (0..n).map(|k| sum_scaled(&|t| t.occluded, k)).collect();
        let e_unoccluded: Vec<DVec3> = (0..n).map(|k| sum_scaled(&|t| t.unoccluded, k)).collect();
        let estimate = times.time("estimate + solve", || {
            estimate_reflectances(
                patches,
                &transport,
                &e_occluded,
                &measured,
                &known,
                crate::estimate::EstimateSettings::default(),
            )
        });
        RealModel {
            direct,
            transport,
            known,
            e_occluded,
            e_unoccluded,
            estimate,
        }
    }
}

/// The photo's illumination model on the refined mesh.
struct RealModel {
    /// Per light and leaf, through the real layer.
    direct: Vec<Vec<LightTerm>>,
    transport: Transport,
    /// The user's reflectances by surface.
    known: HashMap<u32, DVec3>,
    /// The photo's lights' direct irradiance per leaf, with and without
    /// their shadows.
    e_occluded: Vec<DVec3>,
    e_unoccluded: Vec<DVec3>,
    estimate: Estimate,
}

/// The photo's 99th percentile luminance over the real pixels: CIELAB's white.
fn white_level(hits: &[Option<RealHit>], photo: &Image) -> f64 {
    let mut l: Vec<f64> = hits
        .iter()
        .zip(&photo.pixels)
        .filter(|(h, _)| h.is_some())
        .map(|(_, p)| luminance(p.as_dvec3()))
        .collect();
    l.sort_by(f64::total_cmp);
    l.get(l.len() * 99 / 100).copied().unwrap_or(1.0).max(1e-30)
}

/// The user's `[[texture_reference]]` points, checked against the mesh's
/// roots: (surface, root ordinal, point).
fn user_points(scene: &Scene, base: &Patches) -> Result<Vec<(u32, u32, DVec3)>> {
    let mut points = Vec::new();
    for (i, r) in scene.texture_references.iter().enumerate() {
        // The root polygon of that surface whose plane holds the point, inside it.
        let root = base.roots.iter().copied().find(|&root| {
            let el = &base.elements[root as usize];
            let st = base.root_params(root, r.point);
            el.surface == r.surface as u32
                && (base.root_point(root, st) - r.point).length() < 1e-3
                && crate::patches::distance_outside(&el.region, st) <= 1e-6
        });
        let Some(root) = root else {
            return Err(crate::error::Error::key(
                &scene.file,
                format!("texture_reference[{i}].point"),
                format!(
                    "{:?} does not lie on surface '{}' (within 1 mm)",
                    r.point.to_array(),
                    scene.surfaces[r.surface].name
                ),
            ));
        };
        points.push((r.surface as u32, base.root_ordinal(root), r.point));
    }
    Ok(points)
}

/// Visibility per light at the vertices (the mesh's shadows).
fn vertex_visibility(direct: &[Vec<LightTerm>], patches: &Patches) -> Vec<Vec<f64>> {
    direct
        .iter()
        .map(|l| {
            patches
                .vertex_values(
                    &l.iter()
                        .map(|t| DVec3::splat(t.visibility()))
                        .collect::<Vec<_>>(),
                )
                .iter()
                .map(|v| v.x)
                .collect()
        })
        .collect()
}

/// Loscos's Steps 1 and 2 as factors on the photo at a point of the room.
struct Unshadow<'a> {
    setup: &'a Setup<'a>,
    patches: &'a Patches,
    real_vis: Vec<Vec<f64>>,
    /// The photo's indirect irradiance at the vertices.
    h_vertex: Vec<DVec3>,
    /// Step 2's correction at the vertices (empty until Step 2 has run).
    correction_vertex: Vec<DVec3>,
}

impl Unshadow<'_> {
    /// Step 1 (Eq. 5-6) at a point: the blocked direct light added back.
    /// The photo's lights' unoccluded irradiance there is exact; their
    /// visibility is the mesh's.
    fn step1(&self, x: DVec3, n: DVec3, at: &Location) -> DVec3 {
        let (mut unocc, mut occ) = (DVec3::ZERO, DVec3::ZERO);
        for &l in &self.setup.criteria.texture {
            let e = self.setup.lights[l].unoccluded_irradiance(x, n) * self.setup.photo_scales[l];
            let v: f64 = at
                .weights
                .iter()
                .map(|&(k, w)| self.real_vis[l][k as usize] * w)
                .sum();
            unocc += e;
            occ += e * v.clamp(0.0, 1.0);
        }
        let hh = self.patches.interpolate(&self.h_vertex, at);
        let (num, den) = (unocc + hh, occ + hh);
        // Where the photo holds almost none of the light there is nothing
        // to scale back; the factor is capped where it cannot tell.
        DVec3::select(
            den.cmpgt(num * 1e-3),
            num / den.max(DVec3::splat(1e-300)),
            DVec3::ONE,
        )
        .clamp(DVec3::ONE, DVec3::splat(1e3))
    }

    fn step2(&self, at: &Location) -> DVec3 {
        self.patches.interpolate(&self.correction_vertex, at)
    }

    /// Both steps at a point of root polygon `root`.
    fn at_root_point(&self, root: u32, x: DVec3) -> DVec3 {
        let at = self.patches.locate_in_root(root, x);
        self.step1(x, self.patches.patch(at.patch as usize).normal, &at) * self.step2(&at)
    }
}

/// Steps 1 and 2 over the leaves the camera sees: the shadow-free factors
/// and ρ_final per leaf.
fn unshadow<'a>(
    setup: &'a Setup<'a>,
    patches: &'a Patches,
    model: &RealModel,
    hits: &[Option<RealHit>],
    user_points: &[(u32, u32, DVec3)],
    stats: &mut TextureStats,
) -> (Unshadow<'a>, Vec<DVec3>) {
    let real_patches = patches.patch_count();
    let h = &model.estimate.solution.indirect_irradiance;
    let mut unshadow = Unshadow {
        setup,
        patches,
        real_vis: vertex_visibility(&model.direct, patches),
        h_vertex: patches.vertex_values(h),
        correction_vertex: Vec::new(),
    };
    let photo = setup.photo;
    // Per pixel: leaf and Step 1.
    let lp = leaf_pixels(patches, hits, photo, setup.pixel_angle);
    let pixel_leaf: Vec<Option<(Location, DVec3)>> = hits
        .par_iter()
        .map(|h| {
            let h = h.as_ref()?;
            let at = patches.locate(h.surface, h.triangle, h.x)?;
            let n = patches.patch(at.patch as usize).normal;
            Some((at, unshadow.step1(h.x, n, &at)))
        })
        .collect();
    let leaf_mean = |factor: &dyn Fn(usize) -> DVec3| -> Vec<DVec3> {
        let mut sum = vec![DVec3::ZERO; real_patches];
        for (i, p) in pixel_leaf.iter().enumerate() {
            if let Some((at, _)) = p {
                sum[at.patch as usize] += photo.pixels[i].as_dvec3() * factor(i);
            }
        }
        sum.iter()
            .zip(&lp.count)
            .map(|(s, &c)| if c > 0 { *s / c as f64 } else { DVec3::ZERO })
            .collect()
    };
    let step1_of = |i: usize| pixel_leaf[i].map_or(DVec3::ONE, |p| p.1);
    let t_inter = leaf_mean(&step1_of);
    let irradiance_unoccluded: Vec<DVec3> = (0..real_patches)
        .map(|k| model.e_unoccluded[k] + h[k])
        .collect();
    let rho_of = |t: DVec3, k: usize| {
        (t * std::f64::consts::PI / irradiance_unoccluded[k].max(DVec3::splat(1e-300)))
            .clamp(DVec3::ZERO, DVec3::splat(crate::estimate::MAX_REFLECTANCE))
    };
    let rho_inter: Vec<DVec3> = (0..real_patches)
        .map(|k| {
            if lp.count[k] > 0 {
                rho_of(t_inter[k], k)
            } else {
                model.estimate.reflectance[k]
            }
        })
        .collect();
    let occluded = occluded_leaves(setup, model, real_patches);
    let seen: Vec<bool> = lp.count.iter().map(|&c| c > 0).collect();
    let references = References {
        patches,
        occluded: &occluded,
        seen: &seen,
        rho_inter: &rho_inter,
        user_points,
        colour_threshold: setup.settings.reference_colour_threshold,
    };
    let correction = references.corrections(stats);
    unshadow.correction_vertex = patches.vertex_values(&correction);

    // ρ_final from T_final.
    let t_final_leaf = leaf_mean(&|i| {
        step1_of(i)
            * pixel_leaf[i]
                .as_ref()
                .map_or(DVec3::ONE, |p| unshadow.step2(&p.0))
    });
    let rho_final: Vec<DVec3> = (0..real_patches)
        .map(|k| {
            if occluded[k] && seen[k] && !model.known.contains_key(&patches.patch(k).surface) {
                rho_of(t_final_leaf[k], k)
            } else {
                model.estimate.reflectance[k]
            }
        })
        .collect();
    (unshadow, rho_final)
}

/// Leaves in a texture light's shadow.
fn occluded_leaves(setup: &Setup, model: &RealModel, leaves: usize) -> Vec<bool> {
    let tau = setup.settings.visibility_threshold;
    (0..leaves)
        .map(|k| {
            setup.criteria.texture.iter().any(|&l| {
                model.direct[l][k].unoccluded.element_sum() > 0.0
                    && model.direct[l][k].visibility() < 1.0 - tau
            })
        })
        .collect()
}

/// Step 2 (Eq. 7-9, Fig. 15-16): reference leaves on the frontier of the
/// unoccluded ones.
struct References<'a> {
    patches: &'a Patches,
    occluded: &'a [bool],
    seen: &'a [bool],
    rho_inter: &'a [DVec3],
    user_points: &'a [(u32, u32, DVec3)],
    colour_threshold: f64,
}

impl References<'_> {
    /// The correction factor per leaf (one where no reference applies).
    fn corrections(&self, stats: &mut TextureStats) -> Vec<DVec3> {
        let (patches, leaves) = (self.patches, self.rho_inter.len());
        let near = neighbours(patches, leaves);
        let frontier: Vec<usize> = (0..leaves)
            .filter(|&k| {
                self.seen[k]
                    && !self.occluded[k]
                    && near[k].iter().any(|&n| self.occluded[n as usize])
            })
            .collect();
        let lab: Vec<DVec3> = self.rho_inter.iter().map(|r| cielab(*r, 1.0)).collect();
        let user_reference: HashMap<u32, usize> = self
            .user_points
            .iter()
            .map(|&(surface, ordinal, point)| {
                let root = patches.roots[ordinal as usize];
                (surface, patches.locate_in_root(root, point).patch as usize)
            })
            .collect();
        let mut correction = vec![DVec3::ONE; leaves];
        for k in (0..leaves).filter(|&k| self.occluded[k] && self.seen[k]) {
            stats.occluded += 1;
            let el = patches.patch(k);
            let mut best: Option<(f64, usize)> = None;
            for &n in &frontier {
                let en = patches.patch(n);
                if en.surface != el.surface
                    || colour_distance(lab[k], lab[n]) >= self.colour_threshold
                {
                    continue;
                }
                let d = (en.centre - el.centre).length();
                if best.is_none_or(|(b, _)| d < b) {
                    best = Some((d, n));
                }
            }
            let reference = match best {
                Some((_, n)) => {
                    stats.by_frontier += 1;
                    n
                }
                None => match user_reference.get(&el.surface) {
                    Some(&r) => {
                        stats.by_user_reference += 1;
                        r
                    }
                    None => {
                        stats.uncorrected += 1;
                        continue;
                    }
                },
            };
            // Eq. 8 in arlux's reflectances (ρ_corr = ρ_r), Eq. 9 as a factor.
            let c = self.rho_inter[reference] / self.rho_inter[k].max(DVec3::splat(1e-6));
            correction[k] = c.clamp(DVec3::splat(0.2), DVec3::splat(5.0));
        }
        correction
    }
}

/// The textures in root order, and each root's index among them (indexed,
/// not hashed: the display looks one up per pixel).
fn index_textures(textures: HashMap<u32, Texture>) -> (Vec<Texture>, HashMap<u32, u32>) {
    let mut by_root: Vec<(u32, Texture)> = textures.into_iter().collect();
    by_root.sort_unstable_by_key(|(root, _)| *root);
    let texture_of: HashMap<u32, u32> = by_root
        .iter()
        .enumerate()
        .map(|(i, (root, _))| (*root, i as u32))
        .collect();
    (by_root.into_iter().map(|(_, t)| t).collect(), texture_of)
}

/// What each pixel shows (through the objects too) and each light's
/// unoccluded irradiance there (pixel-major), written row by row in place.
fn pixel_points(
    setup: &Setup,
    patches: &Patches,
    textures: &[Texture],
    texture_of: &HashMap<u32, u32>,
) -> (Vec<Option<PixelPoint>>, Vec<Vec3>) {
    let (cam, lights) = (&setup.scene.camera, &setup.lights);
    let layer = if setup.has_objects {
        Layer::All
    } else {
        Layer::Real
    };
    let (w, nl) = (cam.width as usize, lights.len());
    let mut pixels: Vec<Option<PixelPoint>> = vec![None; cam.pixel_count()];
    let mut unoccluded = vec![Vec3::ZERO; cam.pixel_count() * nl];
    pixels
        .par_chunks_mut(w)
        .zip(unoccluded.par_chunks_mut(w * nl))
        .enumerate()
        .for_each(|(row, (points, irradiance))| {
            let hits = crate::surface_ids::row_hits(cam, setup.tracer, layer, row as u32);
            for (col, h) in hits.into_iter().enumerate() {
                let Some(h) = h else { continue };
                let x = cam.position + cam.pixel_ray(col as u32, row as u32).direction * h.t as f64;
                let Some(root) = patches.root_of(h.surface, h.triangle) else {
                    continue;
                };
                let at = patches.locate_in_root(root, x);
                let n = patches.patch(at.patch as usize).normal;
                for (e, light) in irradiance[col * nl..(col + 1) * nl].iter_mut().zip(lights) {
                    *e = light.unoccluded_irradiance(x, n).as_vec3();
                }
                points[col] = if h.is_virtual {
                    Some(PixelPoint::Virtual { at })
                } else {
                    texture_of.get(&root).map(|&texture| {
                        let texel = textures[texture as usize]
                            .texel_of(patches.root_params(root, x))
                            as u32;
                        PixelPoint::Real { texture, at, texel }
                    })
                };
            }
        });
    (pixels, unoccluded)
}

/// D per pixel (the photo's lights unoccluded, plus the final indirect
/// light), and the floor under which D counts as zero.
fn display_factors(
    setup: &Setup,
    patches: &Patches,
    pixels: &[Option<PixelPoint>],
    unoccluded: &[Vec3],
    h_final_vertex: &[DVec3],
) -> (Vec<Vec3>, f64) {
    let nl = setup.lights.len();
    let display: Vec<Vec3> = pixels
        .iter()
        .enumerate()
        .map(|(i, p)| match p {
            Some(PixelPoint::Real { at, .. }) => {
                let e: DVec3 = setup
                    .criteria
                    .texture
                    .iter()
                    .map(|&l| unoccluded[i * nl + l].as_dvec3() * setup.photo_scales[l])
                    .sum();
                (e + patches.interpolate(h_final_vertex, at)).as_vec3()
            }
            _ => Vec3::ZERO,
        })
        .collect();
    let d: Vec<f64> = display
        .iter()
        .zip(pixels)
        .filter(|(_, p)| matches!(p, Some(PixelPoint::Real { .. })))
        .map(|(d, _)| luminance(d.as_dvec3()))
        .collect();
    let d_floor = 1e-3 * d.iter().sum::<f64>() / d.len().max(1) as f64;
    (display, d_floor)
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

        let (patches, direct, transport) =
            setup.with_objects(patches, model.direct, model.transport, &marks, times);
        stats.links = transport.link_count();
        let rest_started = std::time::Instant::now();
        let visibility = vertex_visibility(&direct, &patches);
        let direct: Vec<Vec<DVec3>> = direct
            .iter()
            .map(|l| l.iter().map(|t| t.occluded).collect())
            .collect();
        let virtual_rgb = scene.virtual_surface_rgb();
        let mut reflectance = rho_final;
        reflectance.extend(
            (real_patches..patches.patch_count()).map(|k| virtual_rgb[&patches.patch(k).surface]),
        );
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

    /// Leaves of the mesh, the inserted objects' included.
    pub fn patch_count(&self) -> usize {
        self.patches.patch_count()
    }

    /// The scene under light scales `scales` (one per light, the scene's
    /// order): a radiosity solve on the kept mesh and links, then the display
    /// T_final × B/D (Eq. 3).
    pub fn relight(&self, scales: &[f64], times: &mut StageTimes) -> Composite {
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
        times.time("display", || {
            self.display(scales, &solution.indirect_irradiance)
        })
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
    let scene = resolved.as_ref().unwrap_or(scene);
    if tracer.virtual_objects.is_none() {
        left_out.push("virtual geometry: no virtual object".to_string());
    }
    let supersample = crate::pda::PdaSettings::default().supersample;
    let (photo, lamps) = crate::inputs::lamps_in_view(scene, photo, &tracer, supersample, times)?;
    if lamps.is_none() {
        left_out.push("lamps in view: no rect light is seen".to_string());
    }
    let path = TexturePath::prepare(scene, &photo, &tracer, settings, times)?;
    let scales: Vec<f64> = scene.lights.iter().map(|l| l.scale).collect();
    let before = times.total();
    let mut composite = path.relight(&scales, times);
    if let Some((lamps, shot)) = &lamps {
        times.time("lamps in view", || {
            lamps.apply(&mut composite, shot, &photo, &scales, &tracer)
        });
    }
    let light_change = times.total() - before;
    let unoccluded = times.time("unoccluded texture", || path.unoccluded_texture());
    let out = crate::output::RenderOutput {
        warnings: crate::inputs::input_warnings(&photo, None),
        composite,
        left_out,
        pda_bytes: path.memory_bytes(),
        pda_pixels: path.pixels.len(),
        rays: 0,
        patches: path.patch_count(),
        links: path.stats.links,
        patch_size: path.stats.patch_size,
        texture: Some((path.stats.clone(), unoccluded, light_change)),
    };
    times.time("free", || drop(path));
    Ok(out)
}

mod display;
mod refine;
mod textures;

use refine::*;
pub(crate) use refine::{cielab, colour_distance};
use textures::*;

#[cfg(test)]
mod tests;
