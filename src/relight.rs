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
use crate::estimate::{PhotoPatches, estimate_reflectances};
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

/// One root polygon's texture over the part of it the camera sees.
#[derive(Debug, Clone)]
struct Texture {
    /// Parameter range covered: texel (i, j) is centred at
    /// (s0 + (i + ½)·ds, t0 + (j + ½)·dt).
    s0: f64,
    t0: f64,
    ds: f64,
    dt: f64,
    nu: usize,
    nv: usize,
    texels: Vec<Vec3>,
}

impl Texture {
    fn texel_of(&self, st: DVec2) -> usize {
        let i = (((st.x - self.s0) / self.ds).floor().max(0.0) as usize).min(self.nu - 1);
        let j = (((st.y - self.t0) / self.dt).floor().max(0.0) as usize).min(self.nv - 1);
        j * self.nu + i
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

/// Visibility of one light from an element: fraction of its unoccluded
/// irradiance that arrives (1 where the light does not reach it at all).
#[derive(Debug, Clone, Copy, PartialEq)]
struct LightTerm {
    occluded: DVec3,
    unoccluded: DVec3,
}

impl LightTerm {
    fn visibility(&self) -> f64 {
        let u = self.unoccluded.element_sum();
        if u > 0.0 {
            (self.occluded.element_sum() / u).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }
}

/// Mean direct light over an element's 2×2 quadrature points.
fn element_light(
    shape: &Shape,
    normal: DVec3,
    light: &LightSource,
    tracer: &Tracer,
    layer: Layer,
    level: usize,
    seed: u64,
) -> LightTerm {
    let mut t = LightTerm {
        occluded: DVec3::ZERO,
        unoccluded: DVec3::ZERO,
    };
    for (i, (x, w)) in shape.quadrature(2).iter().enumerate() {
        let d = light.direct(tracer, layer, *x, normal, level, hash2(seed, i as u64));
        t.unoccluded += d.unoccluded * *w;
        t.occluded += d.unoccluded * d.visibility * *w;
    }
    t
}

/// Each light's terms per leaf, `[light][leaf]`, seeded by the leaf's
/// identity (the same leaf gets the same rays in every mesh that holds it).
fn leaf_light(
    patches: &Patches,
    lights: &[LightSource],
    tracer: &Tracer,
    layer: Layer,
    level: usize,
) -> Vec<Vec<LightTerm>> {
    lights
        .iter()
        .map(|light| {
            (0..patches.patch_count())
                .into_par_iter()
                .map(|k| {
                    let el = patches.patch(k);
                    element_light(
                        &el.shape,
                        el.normal,
                        light,
                        tracer,
                        layer,
                        level,
                        element_seed(patches, el),
                    )
                })
                .collect()
        })
        .collect()
}

/// Light terms already computed, by (element identity, light, through the objects too).
type TermCache = HashMap<((u32, i64, i64, i64), usize, bool), LightTerm>;

/// An element's identity across rebuilds of the mesh (its root, centre and size).
fn element_key(patches: &Patches, el: &Element) -> (u32, i64, i64, i64) {
    let c = region_centre(&el.region);
    (
        patches.root_ordinal(el.root),
        (c.x * 1e9).round() as i64,
        (c.y * 1e9).round() as i64,
        (el.shape.size() * 1e9).round() as i64,
    )
}

fn element_seed(patches: &Patches, el: &Element) -> u64 {
    let (r, a, b, c) = element_key(patches, el);
    hash2(hash2(r as u64, a as u64), hash2(b as u64, c as u64))
}

/// Linear sRGB (relative to `white`) to CIELAB under D65.
pub fn cielab(rgb: DVec3, white: f64) -> DVec3 {
    let c = rgb / white.max(1e-300);
    let x = (0.4124 * c.x + 0.3576 * c.y + 0.1805 * c.z) / 0.95047;
    let y = 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
    let z = (0.0193 * c.x + 0.1192 * c.y + 0.9505 * c.z) / 1.08883;
    let f = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    DVec3::new(116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz))
}

/// Eq. 4: distance of two CIELAB colours.
pub fn colour_distance(a: DVec3, b: DVec3) -> f64 {
    (a - b).length()
}

fn luminance(c: DVec3) -> f64 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// A pixel centre's hit in the real geometry: where, on which root, how far.
#[derive(Debug, Clone, Copy)]
struct RealHit {
    surface: u32,
    triangle: u32,
    x: DVec3,
    t: f64,
}

fn real_hits(scene: &Scene, tracer: &Tracer) -> Vec<Option<RealHit>> {
    let cam = &scene.camera;
    (0..cam.height)
        .into_par_iter()
        .flat_map_iter(|row| {
            crate::surface_ids::row_hits(cam, tracer, Layer::Real, row)
                .into_iter()
                .enumerate()
                .map(move |(col, h)| {
                    let h = h?;
                    let x = cam.position + cam.pixel_ray(col as u32, row).direction * h.t as f64;
                    Some(RealHit {
                        surface: h.surface,
                        triangle: h.triangle,
                        x,
                        t: h.t as f64,
                    })
                })
        })
        .collect()
}

/// Per leaf: the photo's mean over the pixels that see it, their count,
/// and the smallest pixel footprint (metres) among them.
struct LeafPixels {
    mean: Vec<DVec3>,
    count: Vec<u32>,
    footprint: Vec<f64>,
}

fn leaf_pixels(
    patches: &Patches,
    hits: &[Option<RealHit>],
    photo: &Image,
    pixel_angle: f64,
) -> LeafPixels {
    let n = patches.patch_count();
    let (mut sum, mut count, mut footprint) =
        (vec![DVec3::ZERO; n], vec![0u32; n], vec![f64::INFINITY; n]);
    for (i, h) in hits.iter().enumerate() {
        let Some(h) = h else { continue };
        let Some(at) = patches.locate(h.surface, h.triangle, h.x) else {
            continue;
        };
        let k = at.patch as usize;
        sum[k] += photo.pixels[i].as_dvec3();
        count[k] += 1;
        footprint[k] = footprint[k].min(h.t * pixel_angle);
    }
    let mean = sum
        .iter()
        .zip(&count)
        .map(|(s, &c)| if c > 0 { *s / c as f64 } else { DVec3::ZERO })
        .collect();
    LeafPixels {
        mean,
        count,
        footprint,
    }
}

/// Leaves sharing a vertex with each leaf (vertices are welded per surface
/// plane, so these lie on the same plane).
fn neighbours(patches: &Patches, leaves: usize) -> Vec<Vec<u32>> {
    let mut of_vertex: HashMap<u32, Vec<u32>> = HashMap::new();
    for k in 0..leaves {
        for &v in patches.patch_vertices[k].iter().filter(|&&v| v != u32::MAX) {
            of_vertex.entry(v).or_default().push(k as u32);
        }
    }
    (0..leaves)
        .map(|k| {
            let mut out: Vec<u32> = patches.patch_vertices[k]
                .iter()
                .filter(|&&v| v != u32::MAX)
                .flat_map(|v| of_vertex[v].iter().copied())
                .filter(|&o| o as usize != k)
                .collect();
            out.sort_unstable();
            out.dedup();
            out
        })
        .collect()
}

/// Which lights each refinement criterion looks at, through which layer.
struct Criteria {
    /// Real lights on in the photo: the texture rule (their shadows are in it).
    texture: Vec<usize>,
    /// Lights whose visibility changes what the variant shows: inserted
    /// lights, and every active light where inserted objects cast shadows.
    forced: Vec<(usize, Layer)>,
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
        let lights = LightSource::all(scene)?;
        let photo_scales: Vec<f64> = lights.iter().map(|l| l.photo_scale()).collect();
        let has_objects = tracer.virtual_objects.is_some();
        let patch_size = settings
            .patch_size
            .unwrap_or_else(|| crate::inputs::fine_patch_size(scene));
        let virtual_size = 0.1f64.min(patch_size);
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
        let pixel_angle = 1.0 / cam.fx.min(cam.fy);
        let mut stats = TextureStats {
            patch_size,
            ..Default::default()
        };

        // Texture-based refinement (Fig. 12), one level per round.
        let base = times.time("mesh", || Patches::of_scene(scene, false, patch_size));
        // The user's references, checked before any work: (surface, root ordinal, point).
        let mut user_points: Vec<(u32, u32, DVec3)> = Vec::new();
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
            user_points.push((r.surface as u32, base.root_ordinal(root), r.point));
        }
        let hits = times.time("camera rays", || real_hits(scene, tracer));
        let white = {
            let mut l: Vec<f64> = hits
                .iter()
                .zip(&photo.pixels)
                .filter(|(h, _)| h.is_some())
                .map(|(_, p)| luminance(p.as_dvec3()))
                .collect();
            l.sort_by(f64::total_cmp);
            l.get(l.len() * 99 / 100).copied().unwrap_or(1.0).max(1e-30)
        };
        let mut marks = SplitMarks::new();
        let mut cache = TermCache::new();
        let patches = times.time("texture-based refinement", || {
            let mut patches = base;
            for _ in 0..settings.max_rounds {
                stats.rounds += 1;
                let added = refine_round(
                    &patches,
                    &hits,
                    photo,
                    pixel_angle,
                    white,
                    &lights,
                    &criteria,
                    tracer,
                    settings,
                    &mut cache,
                    &mut marks,
                    &mut stats,
                );
                if added == 0 {
                    break;
                }
                patches = Patches::of_scene_refined(scene, false, patch_size, virtual_size, &marks);
            }
            patches
        });
        let real_patches = patches.patch_count();
        stats.leaves = real_patches;

        // The illumination model on the refined mesh (links at the leaves for
        // the light sources: direct light is per leaf).
        let real_direct = times.time("direct light", || {
            leaf_light(&patches, &lights, tracer, Layer::Real, settings.light_level)
        });
        let transport = times.time("form factors", || {
            Transport::hierarchical(&patches, tracer, Layer::Real, settings.link_epsilon)
        });
        let measured = times.time("photo per patch", || {
            PhotoPatches::measure(cam, tracer, &patches, photo)
        });
        let known: HashMap<u32, DVec3> = scene
            .reflectances
            .iter()
            .map(|k| (k.surface as u32, k.rgb))
            .collect();
        let sum_scaled = |f: &dyn Fn(&LightTerm) -> DVec3, k: usize| -> DVec3 {
            (0..lights.len())
                .filter(|&l| photo_scales[l] > 0.0)
                .map(|l| f(&real_direct[l][k]) * photo_scales[l])
                .sum()
        };
        let e_occluded: Vec<DVec3> = (0..real_patches)
            .map(|k| sum_scaled(&|t| t.occluded, k))
            .collect();
        let e_unoccluded: Vec<DVec3> = (0..real_patches)
            .map(|k| sum_scaled(&|t| t.unoccluded, k))
            .collect();
        let estimate = times.time("estimate + solve", || {
            estimate_reflectances(
                &patches,
                &transport,
                &e_occluded,
                &measured,
                &known,
                crate::estimate::EstimateSettings::default(),
            )
        });
        let h = &estimate.solution.indirect_irradiance;
        let solve_tolerance = crate::estimate::EstimateSettings::default().solve_tolerance;
        let steps_started = std::time::Instant::now();
        let pi = std::f64::consts::PI;

        // Visibility per light at the real vertices (the mesh's shadows).
        let vis_vertex = |direct: &[Vec<LightTerm>], p: &Patches| -> Vec<Vec<f64>> {
            direct
                .iter()
                .map(|l| {
                    p.vertex_values(
                        &l.iter()
                            .map(|t| DVec3::splat(t.visibility()))
                            .collect::<Vec<_>>(),
                    )
                    .iter()
                    .map(|v| v.x)
                    .collect()
                })
                .collect()
        };
        let real_vis = vis_vertex(&real_direct, &patches);
        let h_vertex = patches.vertex_values(h);
        // Step 1 (Eq. 5-6) at a point: the blocked direct light added back.
        // The photo's lights' unoccluded irradiance there is exact; their
        // visibility is the mesh's.
        let step1 = |x: DVec3, n: DVec3, at: &Location| -> DVec3 {
            let (mut unocc, mut occ) = (DVec3::ZERO, DVec3::ZERO);
            for &l in &criteria.texture {
                let e = lights[l].unoccluded_irradiance(x, n) * photo_scales[l];
                let v: f64 = at
                    .weights
                    .iter()
                    .map(|&(k, w)| real_vis[l][k as usize] * w)
                    .sum();
                unocc += e;
                occ += e * v.clamp(0.0, 1.0);
            }
            let hh = patches.interpolate(&h_vertex, at);
            let (num, den) = (unocc + hh, occ + hh);
            // Where the photo holds almost none of the light there is nothing
            // to scale back; the factor is capped where it cannot tell.
            DVec3::select(
                den.cmpgt(num * 1e-3),
                num / den.max(DVec3::splat(1e-300)),
                DVec3::ONE,
            )
            .clamp(DVec3::ONE, DVec3::splat(1e3))
        };

        // Per pixel: leaf and Step 1.
        let lp = leaf_pixels(&patches, &hits, photo, pixel_angle);
        let pixel_leaf: Vec<Option<(Location, DVec3)>> = hits
            .par_iter()
            .map(|h| {
                let h = h.as_ref()?;
                let at = patches.locate(h.surface, h.triangle, h.x)?;
                Some((at, step1(h.x, patches.patch(at.patch as usize).normal, &at)))
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
        let irradiance_unoccluded: Vec<DVec3> =
            (0..real_patches).map(|k| e_unoccluded[k] + h[k]).collect();
        let rho_of = |t: DVec3, k: usize| {
            (t * pi / irradiance_unoccluded[k].max(DVec3::splat(1e-300)))
                .clamp(DVec3::ZERO, DVec3::splat(crate::estimate::MAX_REFLECTANCE))
        };
        let rho_inter: Vec<DVec3> = (0..real_patches)
            .map(|k| {
                if lp.count[k] > 0 {
                    rho_of(t_inter[k], k)
                } else {
                    estimate.reflectance[k]
                }
            })
            .collect();

        // Step 2 (Eq. 7-9, Fig. 15-16): reference leaves on the frontier.
        let near = neighbours(&patches, real_patches);
        let tau = settings.visibility_threshold;
        let occluded: Vec<bool> = (0..real_patches)
            .map(|k| {
                criteria.texture.iter().any(|&l| {
                    real_direct[l][k].unoccluded.element_sum() > 0.0
                        && real_direct[l][k].visibility() < 1.0 - tau
                })
            })
            .collect();
        let seen = |k: usize| lp.count[k] > 0;
        let frontier: Vec<usize> = (0..real_patches)
            .filter(|&k| seen(k) && !occluded[k] && near[k].iter().any(|&n| occluded[n as usize]))
            .collect();
        let lab: Vec<DVec3> = rho_inter.iter().map(|r| cielab(*r, 1.0)).collect();
        let user_reference: HashMap<u32, usize> = user_points
            .iter()
            .map(|&(surface, ordinal, point)| {
                (
                    surface,
                    patches
                        .locate_in_root(patches.roots[ordinal as usize], point)
                        .patch as usize,
                )
            })
            .collect();
        let mut correction = vec![DVec3::ONE; real_patches];
        for k in (0..real_patches).filter(|&k| occluded[k] && seen(k)) {
            stats.occluded += 1;
            let el = patches.patch(k);
            let mut best: Option<(f64, usize)> = None;
            for &n in &frontier {
                let en = patches.patch(n);
                if en.surface != el.surface
                    || colour_distance(lab[k], lab[n]) >= settings.reference_colour_threshold
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
            let c = rho_inter[reference] / rho_inter[k].max(DVec3::splat(1e-6));
            correction[k] = c.clamp(DVec3::splat(0.2), DVec3::splat(5.0));
        }
        let corr_v = patches.vertex_values(&correction);
        let step2 = |at: &Location| patches.interpolate(&corr_v, at);

        // ρ_final from T_final, a radiosity step; D = ρ·(unoccluded direct + indirect).
        let t_final_leaf = leaf_mean(&|i| {
            step1_of(i) * pixel_leaf[i].as_ref().map_or(DVec3::ONE, |p| step2(&p.0))
        });
        let rho_final: Vec<DVec3> = (0..real_patches)
            .map(|k| {
                if occluded[k] && seen(k) && !known.contains_key(&patches.patch(k).surface) {
                    rho_of(t_final_leaf[k], k)
                } else {
                    estimate.reflectance[k]
                }
            })
            .collect();
        times.0.push(("steps 1 and 2", steps_started.elapsed()));
        let final_solution = times.time("solve unoccluded", || {
            let b: Vec<DVec3> = rho_final
                .iter()
                .zip(&e_occluded)
                .map(|(r, e)| *r * *e)
                .collect();
            solve_from(
                &patches,
                &transport,
                &rho_final,
                &b,
                Some(&estimate.solution.radiosity),
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
                pixel_angle,
                settings.texels_per_pixel,
                &|root, x| {
                    let at = patches.locate_in_root(root, x);
                    step1(x, patches.patch(at.patch as usize).normal, &at) * step2(&at)
                },
            )
        });
        // Indexed, not hashed: the display looks one up per pixel.
        let mut by_root: Vec<(u32, Texture)> = textures.into_iter().collect();
        by_root.sort_unstable_by_key(|(root, _)| *root);
        let texture_of: HashMap<u32, u32> = by_root
            .iter()
            .enumerate()
            .map(|(i, (root, _))| (*root, i as u32))
            .collect();
        let textures: Vec<Texture> = by_root.into_iter().map(|(_, t)| t).collect();
        stats.texels = textures.iter().map(|t| t.texels.len()).sum();
        stats.texture_bytes = stats.texels * std::mem::size_of::<Vec3>();

        // The mesh with the inserted objects, and the direct light through them.
        let (patches, direct, transport) = if has_objects {
            let all = times.time("virtual mesh", || {
                Patches::of_scene_refined(scene, true, patch_size, virtual_size, &marks)
            });
            let direct = times.time("direct light with objects", || {
                leaf_light(&all, &lights, tracer, Layer::All, settings.light_level)
            });
            let transport = times.time("form factors with objects", || {
                transport.with_objects(&all, tracer, settings.link_epsilon, true)
            });
            (all, direct, transport)
        } else {
            (patches, real_direct, transport)
        };
        stats.links = transport.link_count();
        let rest_started = std::time::Instant::now();
        let visibility = vis_vertex(&direct, &patches);
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
        // What each pixel shows (through the objects too) and each light's
        // unoccluded irradiance there, written row by row in place.
        let layer = if has_objects { Layer::All } else { Layer::Real };
        let (w, nl) = (cam.width as usize, lights.len());
        let mut pixels: Vec<Option<PixelPoint>> = vec![None; cam.pixel_count()];
        let mut unoccluded = vec![Vec3::ZERO; cam.pixel_count() * nl];
        times.time("pixel points", || {
            pixels
                .par_chunks_mut(w)
                .zip(unoccluded.par_chunks_mut(w * nl))
                .enumerate()
                .for_each(|(row, (points, irradiance))| {
                    let hits = crate::surface_ids::row_hits(cam, tracer, layer, row as u32);
                    for (col, h) in hits.into_iter().enumerate() {
                        let Some(h) = h else { continue };
                        let x = cam.position
                            + cam.pixel_ray(col as u32, row as u32).direction * h.t as f64;
                        let Some(root) = patches.root_of(h.surface, h.triangle) else {
                            continue;
                        };
                        let at = patches.locate_in_root(root, x);
                        let n = patches.patch(at.patch as usize).normal;
                        for (e, light) in
                            irradiance[col * nl..(col + 1) * nl].iter_mut().zip(&lights)
                        {
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
        });
        let display_started = std::time::Instant::now();
        // D per pixel: the photo's lights unoccluded, plus the final indirect light.
        let display: Vec<Vec3> = pixels
            .iter()
            .enumerate()
            .map(|(i, p)| match p {
                Some(PixelPoint::Real { at, .. }) => {
                    let e: DVec3 = criteria
                        .texture
                        .iter()
                        .map(|&l| unoccluded[i * nl + l].as_dvec3() * photo_scales[l])
                        .sum();
                    (e + patches.interpolate(&h_final_vertex, at)).as_vec3()
                }
                _ => Vec3::ZERO,
            })
            .collect();
        let d_floor = {
            let d: Vec<f64> = display
                .iter()
                .zip(&pixels)
                .filter(|(_, p)| matches!(p, Some(PixelPoint::Real { .. })))
                .map(|(d, _)| luminance(d.as_dvec3()))
                .collect();
            1e-3 * d.iter().sum::<f64>() / d.len().max(1) as f64
        };
        times.0.push(("display factors", display_started.elapsed()));
        Ok(TexturePath {
            patches,
            lights,
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

    /// Per pixel B/D: each light's exact unoccluded irradiance times the
    /// mesh's visibility, plus the mesh's indirect light, over D.
    fn display(&self, scales: &[f64], indirect: &[DVec3]) -> Composite {
        let p = &self.patches;
        let h_v = p.vertex_values(indirect);
        let pi = std::f64::consts::PI;
        let photo = &self.photo;
        let nl = self.lights.len();
        let (w, h) = (photo.width, photo.height);
        let mut out = Composite {
            image: Image::new(w, h),
            direct: Image::new(w, h),
            indirect: Image::new(w, h),
            change: Image::new(w, h),
            alpha: vec![0.0; (w * h) as usize],
            copied: 0,
            ratio_fallbacks: 0,
            clamped: 0,
        };
        out.fill(photo, |i| {
            let Some(px) = &self.pixels[i] else {
                return PixelShade {
                    value: photo.pixels[i],
                    direct: Vec3::ZERO,
                    indirect: Vec3::ZERO,
                    alpha: 0.0,
                    copied: true,
                    fallback: false,
                    clamped: false,
                };
            };
            let (at, texture) = match px {
                PixelPoint::Real { at, texture, texel } => (
                    at,
                    Some(self.textures[*texture as usize].texels[*texel as usize]),
                ),
                PixelPoint::Virtual { at } => (at, None),
            };
            let mut e = DVec3::ZERO;
            for (l, &s) in scales.iter().enumerate() {
                if s > 0.0 {
                    let v: f64 = at
                        .weights
                        .iter()
                        .map(|&(k, w)| self.visibility[l][k as usize] * w)
                        .sum();
                    e += self.unoccluded[i * nl + l].as_dvec3() * (s * v.clamp(0.0, 1.0));
                }
            }
            let hh = p.interpolate(&h_v, at);
            let rho = self.reflectance[at.patch as usize];
            let mut fallback = false;
            let value = match texture {
                Some(t) => {
                    let d = self.display[i].as_dvec3();
                    if luminance(d) > self.d_floor && d.min_element() > 0.0 {
                        t.as_dvec3() * (e + hh) / d
                    } else {
                        // D ≈ 0: the photo saw this surface unlit; only the model knows it.
                        fallback = true;
                        rho * (e + hh) / pi
                    }
                }
                None => rho * (e + hh) / pi,
            };
            let value = if value.is_finite() {
                value.max(DVec3::ZERO)
            } else {
                DVec3::ZERO
            }
            .as_vec3();
            let alpha = if texture.is_some() { 0.0 } else { 1.0 };
            PixelShade {
                value,
                direct: e.as_vec3(),
                indirect: hh.as_vec3(),
                alpha,
                copied: false,
                fallback,
                clamped: false,
            }
        });
        out
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

/// One round of Fig. 12 over the current leaves; returns the splits added to `marks`.
#[allow(clippy::too_many_arguments)]
fn refine_round(
    patches: &Patches,
    hits: &[Option<RealHit>],
    photo: &Image,
    pixel_angle: f64,
    white: f64,
    lights: &[LightSource],
    criteria: &Criteria,
    tracer: &Tracer,
    settings: &TextureSettings,
    cache: &mut TermCache,
    marks: &mut SplitMarks,
    stats: &mut TextureStats,
) -> usize {
    let n = patches.patch_count();
    let lp = leaf_pixels(patches, hits, photo, pixel_angle);
    let seen = |k: usize| lp.count[k] > 0;
    let lab: Vec<DVec3> = lp.mean.iter().map(|c| cielab(*c, white)).collect();
    // Every (light, layer) the criteria look at.
    let mut wanted: Vec<(usize, Layer)> =
        criteria.texture.iter().map(|&l| (l, Layer::Real)).collect();
    wanted.extend(criteria.forced.iter().copied());
    wanted.dedup();
    let terms = |els: &[Element], cache: &mut HashMap<_, LightTerm>| -> Vec<Vec<LightTerm>> {
        // Compute what the cache lacks in parallel, then read.
        for &(l, layer) in &wanted {
            let all = layer == Layer::All;
            let missing: Vec<&Element> = els
                .iter()
                .filter(|el| !cache.contains_key(&(element_key(patches, el), l, all)))
                .collect();
            let computed: Vec<LightTerm> = missing
                .par_iter()
                .map(|el| {
                    element_light(
                        &el.shape,
                        el.normal,
                        &lights[l],
                        tracer,
                        layer,
                        settings.light_level,
                        element_seed(patches, el),
                    )
                })
                .collect();
            for (el, t) in missing.iter().zip(computed) {
                cache.insert((element_key(patches, el), l, all), t);
            }
        }
        els.iter()
            .map(|el| {
                wanted
                    .iter()
                    .map(|&(l, layer)| cache[&(element_key(patches, el), l, layer == Layer::All)])
                    .collect()
            })
            .collect()
    };
    let leaves: Vec<Element> = (0..n).map(|k| patches.patch(k).clone()).collect();
    let eligible: Vec<usize> = (0..n)
        .filter(|&k| {
            seen(k)
                && !patches.is_virtual_surface(leaves[k].surface)
                && leaves[k].shape.size() >= settings.min_leaf_pixels * lp.footprint[k]
        })
        .collect();
    let vis: Vec<Vec<f64>> = terms(&leaves, cache)
        .iter()
        .map(|t| t.iter().map(LightTerm::visibility).collect())
        .collect();
    let halves: Vec<Element> = eligible
        .iter()
        .flat_map(|&k| {
            let el = &leaves[k];
            split(el.shape, el.region).map(|(shape, region)| Element {
                bounds: shape.bounds(),
                size: shape.size(),
                area: shape.area(),
                centre: shape.centre(),
                shape,
                region,
                children: None,
                patch: None,
                parent: None,
                ..el.clone()
            })
        })
        .collect();
    let half_terms = terms(&halves, cache);
    let near = neighbours(patches, n);
    let tau = settings.visibility_threshold;
    let texture_count = criteria.texture.len();
    let mut added = 0;
    let mut mark = |k: usize, marks: &mut SplitMarks| {
        let el = &leaves[k];
        marks
            .entry(patches.root_ordinal(el.root))
            .or_default()
            .push((region_centre(&el.region), el.shape.size()));
        added += 1;
    };
    for (i, &k) in eligible.iter().enumerate() {
        let (a, b) = (&half_terms[2 * i], &half_terms[2 * i + 1]);
        // Fig. 12: colour against visibility, with each neighbour.
        let partial = vis[k].iter().any(|&v| v > tau && v < 1.0 - tau);
        let mut split_it = partial;
        for &m in &near[k] {
            let m = m as usize;
            if split_it || !seen(m) {
                continue;
            }
            let similar_colour = colour_distance(lab[k], lab[m]) < settings.colour_threshold;
            let differ = |range: std::ops::Range<usize>| {
                range
                    .into_iter()
                    .any(|j| (vis[k][j] - vis[m][j]).abs() >= tau)
            };
            let texture_vis_differs = differ(0..texture_count);
            // Inserted lights and objects: visibility alone decides.
            let forced_differs = differ(texture_count..wanted.len());
            split_it = (similar_colour && texture_vis_differs)
                || (!similar_colour && !texture_vis_differs && texture_count > 0)
                || forced_differs;
        }
        if !split_it {
            continue;
        }
        // Undone when the halves see every light as the leaf does.
        let changes = (0..wanted.len()).any(|j| {
            (a[j].visibility() - vis[k][j]).abs() >= tau
                || (b[j].visibility() - vis[k][j]).abs() >= tau
        });
        if changes {
            stats.splits += 1;
            mark(k, marks);
        } else {
            stats.undone += 1;
        }
    }
    added
}

/// The photo re-projected into each seen root polygon, texel by texel, at
/// `texels_per_pixel` per pixel footprint (over the part of the root the
/// camera sees): a texel takes the pixel it projects into when that
/// pixel's centre sees the same polygon; each texel is then multiplied by
/// `modulation(root, x)`. A texel the photo does not show takes its
/// nearest shown texel's value.
fn build_textures(
    scene: &Scene,
    patches: &Patches,
    hits: &[Option<RealHit>],
    photo: &Image,
    pixel_angle: f64,
    texels_per_pixel: f64,
    modulation: &(dyn Fn(u32, DVec3) -> DVec3 + Sync),
) -> HashMap<u32, Texture> {
    let cam = &scene.camera;
    // Per root: seen parameter range and nearest footprint.
    let mut range: HashMap<u32, (DVec2, DVec2, f64)> = HashMap::new();
    for h in hits.iter().flatten() {
        let Some(root) = patches.root_of(h.surface, h.triangle) else {
            continue;
        };
        let st = patches.root_params(root, h.x);
        let e = range.entry(root).or_insert((st, st, f64::INFINITY));
        e.0 = e.0.min(st);
        e.1 = e.1.max(st);
        e.2 = e.2.min(h.t * pixel_angle);
    }
    const MAX_SIDE: usize = 4096;
    let mut roots: Vec<u32> = range.keys().copied().collect();
    roots.sort_unstable();
    roots
        .par_iter()
        .map(|&root| {
            let (lo, hi, footprint) = range[&root];
            let (u, v) = match patches.elements[root as usize].shape {
                Shape::Quad { u, v, .. } => (u, v),
                Shape::Tri([a, b, c]) => (b - a, c - a),
            };
            let texel = footprint / texels_per_pixel.max(1e-3);
            let (ds, dt) = (texel / u.length(), texel / v.length());
            let (s0, t0) = ((lo.x - 2.0 * ds).max(0.0), (lo.y - 2.0 * dt).max(0.0));
            let (s1, t1) = ((hi.x + 2.0 * ds).min(1.0), (hi.y + 2.0 * dt).min(1.0));
            let nu = (((s1 - s0) / ds).ceil() as usize).clamp(1, MAX_SIDE);
            let nv = (((t1 - t0) / dt).ceil() as usize).clamp(1, MAX_SIDE);
            let (ds, dt) = ((s1 - s0) / nu as f64, (t1 - t0) / nv as f64);
            let mut tex = Texture {
                s0,
                t0,
                ds,
                dt,
                nu,
                nv,
                texels: vec![Vec3::ZERO; nu * nv],
            };
            let mut known = vec![false; nu * nv];
            let centre = |k: usize| {
                DVec2::new(
                    s0 + ((k % nu) as f64 + 0.5) * ds,
                    t0 + ((k / nu) as f64 + 0.5) * dt,
                )
            };
            tex.texels
                .par_iter_mut()
                .zip(known.par_iter_mut())
                .enumerate()
                .for_each(|(k, (texel, known))| {
                    let x = patches.root_point(root, centre(k));
                    let Some((px, py, _)) = cam.project(x) else {
                        return;
                    };
                    if px < 0.0 || py < 0.0 || px >= cam.width as f64 || py >= cam.height as f64 {
                        return;
                    }
                    let (col, row) = (px as u32, py as u32);
                    // Seen: the photo's pixel there shows this polygon (its centre's ray meets it).
                    if hits[(row * cam.width + col) as usize]
                        .is_some_and(|h| patches.root_of(h.surface, h.triangle) == Some(root))
                    {
                        *texel = photo.get(col, row);
                        *known = true;
                    }
                });
            fill_unknown(&mut tex, &mut known);
            tex.texels
                .par_iter_mut()
                .enumerate()
                .for_each(|(k, texel)| {
                    let m = modulation(root, patches.root_point(root, centre(k)));
                    *texel = (texel.as_dvec3() * m).as_vec3();
                });
            (root, tex)
        })
        .collect()
}

/// Gives unknown texels the value of their nearest known texel (4-connected
/// steps, breadth first from every known texel at once: linear time).
fn fill_unknown(tex: &mut Texture, known: &mut [bool]) {
    let (nu, nv) = (tex.nu, tex.nv);
    let mut queue: std::collections::VecDeque<usize> = (0..nu * nv).filter(|&k| known[k]).collect();
    while let Some(k) = queue.pop_front() {
        let (i, j) = (k % nu, k / nu);
        let around = [
            (i > 0).then(|| k - 1),
            (i + 1 < nu).then(|| k + 1),
            (j > 0).then(|| k - nu),
            (j + 1 < nv).then(|| k + nu),
        ];
        for n in around.into_iter().flatten() {
            if !known[n] {
                known[n] = true;
                tex.texels[n] = tex.texels[k];
                queue.push_back(n);
            }
        }
    }
}

#[cfg(test)]
mod tests;
