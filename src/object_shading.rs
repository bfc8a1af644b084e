//! Per-pixel shading of virtual objects that have a material
//! ([`crate::materials`]): the compositor asks [`ObjectShading::radiance`]
//! for each virtual point it shows, and shades points without one as
//! diffuse clay, as before.
//!
//! At a point: the shading normal interpolated from the vertex normals (a
//! normal texture on top), the material at its texture coordinate filtered
//! over the pixel's footprint, then
//! - direct light from every light through the BRDF: point lights by one
//!   shadow ray; rect lights sampled by area and by the BRDF's specular
//!   lobe, combined by multiple importance sampling (balance heuristic);
//! - the room reflected in the object: directions drawn from the specular
//!   lobe; a ray that meets a real surface takes what the photo shows
//!   there where the camera sees that point, times the change the objects
//!   and lights make there (with / without, as the compositor's ratio),
//!   the model's radiosity elsewhere; one that meets another object takes
//!   its diffuse radiosity; one that meets a lamp's emitting shape takes
//!   its radiance;
//! - the diffuse part's indirect light from the radiosity solution's
//!   gathered irradiance at the object's vertices.
//!
//! Shadow rays leave from the point moved onto the surface the vertex
//! normals describe (Hanika 2021, "Hacking the shadow terminator"), so a
//! low-poly object's lit side is not darkened by its own facets.
//! Samples are seeded by the point's position: images are bit-identical
//! whatever the thread count and the order pixels are shaded in.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3};

use crate::camera::Camera;
use crate::geometry::Triangle;
use crate::image_io::Image;
use crate::light::LightSource;
use crate::materials::{Attributes, Lobes, Material};
use crate::patches::Patches;
use crate::pda::SurfacePoint;
use crate::scene::Scene;
use crate::trace::{Hit, Layer, TraceRay, Tracer};
use crate::util::rng::hash2;

pub mod kept;
mod paths;
mod rounds;
pub(crate) use paths::Reading;
pub(crate) use rounds::{Footprint, Lamps};

/// A virtual surface with a material, placed in the world: its triangles
/// and vertex normals stay in the object's frame, shared with the scene
/// (and every object of the same file), and are placed as a point asks
/// for them — a world copy per object cost 5.8 MB for 80k triangles.
#[derive(Debug, Clone)]
pub struct PlacedSurface {
    material: Arc<Material>,
    triangles: Arc<[Triangle]>,
    pose: crate::scene::Pose,
    attributes: Arc<Attributes>,
}

impl PlacedSurface {
    /// Triangle `k` in the world.
    fn triangle(&self, k: usize) -> Option<Triangle> {
        let t = self.triangles.get(k)?;
        Some(t.map(|p| self.pose.apply(p)))
    }

    /// Triangle `k`'s vertex normals in the world (None: flat shading).
    fn normals(&self, k: usize) -> Option<[Vec3; 3]> {
        let ns = self.attributes.normals.get(k)?;
        let rotation = self.pose.rotation;
        Some(ns.map(|n| (rotation * n.as_dvec3()).normalize_or_zero().as_vec3()))
    }
}

/// The enabled objects' surfaces that have a material, by surface id.
#[derive(Debug, Clone, Default)]
pub struct ObjectMaterials {
    surfaces: HashMap<u32, PlacedSurface>,
}

impl ObjectMaterials {
    /// The scene's objects as posed now (none: no object has a material).
    pub fn of(scene: &Scene) -> ObjectMaterials {
        let mut surfaces = HashMap::new();
        for (id, o, i) in scene.virtual_surfaces().filter(|(_, o, _)| o.enabled) {
            let Some(m) = &o.surfaces[i].material else {
                continue;
            };
            surfaces.insert(
                id,
                PlacedSurface {
                    material: m.material.clone(),
                    triangles: o.surfaces[i].triangles.clone(),
                    pose: o.pose,
                    attributes: m.attributes.clone(),
                },
            );
        }
        ObjectMaterials { surfaces }
    }

    /// The ids of the enabled objects' surfaces that have a material,
    /// sorted: those [`ObjectMaterials::of`] shades, without placing them.
    pub fn surface_ids(scene: &Scene) -> Vec<u32> {
        material_ids(scene, |_| true)
    }

    /// The ids of the enabled objects' surfaces whose material is a metal
    /// throughout (metallic 1, no texture to lower it), sorted: their
    /// pixels have no diffuse part, and read no light gathered at their
    /// vertices.
    pub fn metal_ids(scene: &Scene) -> Vec<u32> {
        material_ids(scene, |m| {
            m.material.metallic >= 1.0 && m.material.metallic_roughness_texture.is_none()
        })
    }

    pub fn is_empty(&self) -> bool {
        self.surfaces.is_empty()
    }

    /// Whether surface `surface` has a material.
    pub fn has(&self, surface: u32) -> bool {
        self.surfaces.contains_key(&surface)
    }
}

/// The sorted ids of the enabled objects' surfaces whose material `keep` takes.
fn material_ids(
    scene: &Scene,
    keep: impl Fn(&crate::materials::SurfaceMaterial) -> bool,
) -> Vec<u32> {
    let mut ids: Vec<u32> = (scene.virtual_surfaces())
        .filter(|(_, o, i)| o.enabled && o.surfaces[*i].material.as_ref().is_some_and(&keep))
        .map(|(id, _, _)| id)
        .collect();
    ids.sort_unstable();
    ids
}

/// Sample counts per shaded point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadingSettings {
    /// Most specular-lobe rays a pixel draws (at the roughness that needs
    /// the most; fewer for smoother and rougher lobes, and dielectrics).
    /// 24: on `materials`, 16 to 64 give the same error against the truth
    /// (within 0.001 of the objects' RMSE: the truth's own noise); 16
    /// against 256 differ by 0.045 on a chrome ball's pixels, nearly all
    /// in its highlights.
    pub specular_rays: u32,
    /// Points sampled on each rect light, and the fewest samples a pixel
    /// draws. 32 gained `globe_floor` 0.0009 and cost a large textured
    /// object's update 1.2–1.3× (`docs/design/materials.md`).
    pub light_samples: u32,
    /// How many times its first samples a pixel draws again where they
    /// leave its mean uncertain (0: never).
    pub extra_samples: u32,
    /// The standard error of a pixel's mean (of its luminance) above which
    /// it draws the extra samples, as a fraction of the photo's mean
    /// luminance. Measured against the scene rather than the pixel: a
    /// pixel's squared error counts whatever its brightness, and a dark
    /// pixel's relative error is large where its absolute one is not.
    /// 0.25: on `materials` (see `docs/design/materials.md`) a chrome
    /// ball's update costs two thirds of four times the samples, with
    /// its skill as high; 0.1 of the pixel's own mean cost half again and
    /// gained nothing on the dielectrics.
    pub tolerance: f64,
}

impl Default for ShadingSettings {
    fn default() -> Self {
        ShadingSettings {
            specular_rays: 24,
            light_samples: 16,
            extra_samples: 3,
            tolerance: 0.25,
        }
    }
}

/// What shading the objects' pixels reads.
pub struct ObjectShading<'a> {
    pub materials: &'a ObjectMaterials,
    pub tracer: &'a Tracer,
    pub camera: &'a Camera,
    /// The photo as the stages read it (real radiance where the camera sees a point).
    pub photo: &'a Image,
    pub lights: &'a [LightSource],
    pub scales_with: &'a [f64],
    pub scales_without: &'a [f64],
    /// The augmented scene's patches (real and virtual).
    pub patches: &'a Patches,
    /// Indirect irradiance per vertex with and without the change.
    pub indirect_with: &'a [DVec3],
    pub indirect_without: &'a [DVec3],
    /// Reflectance per patch of the augmented model.
    pub reflectance: &'a [DVec3],
    pub settings: ShadingSettings,
    /// The photo's mean luminance ([`mean_luminance`]), which
    /// [`ShadingSettings::tolerance`] is a fraction of.
    pub brightness: f64,
}

/// The mean luminance of `photo`, over every 61st pixel (a 24-megapixel
/// plate reads 400,000 of them: under a millisecond a composite).
pub fn mean_luminance(photo: &crate::image_io::Image) -> f64 {
    let (sum, count) = (photo.pixels.iter().step_by(61))
        .map(|p| p.as_dvec3().dot(DVec3::new(0.2126, 0.7152, 0.0722)))
        .filter(|y| y.is_finite())
        .fold((0.0, 0usize), |(s, c), y| (s + y.max(0.0), c + 1));
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// A shading point: where, its frames and its material.
struct Point {
    x: DVec3,
    /// Origin for rays leaving the surface (terminator-safe).
    shadow_origin: DVec3,
    /// Geometric normal facing the viewer, and the shading normal.
    ng: DVec3,
    n: DVec3,
    v: DVec3,
    lobes: Lobes,
    emissive: DVec3,
    /// The vertices the point's indirect light is interpolated from, with
    /// their weights (None: not located; the pixel's are taken).
    location: Option<[(u32, f64); 4]>,
}

/// What a camera ray meets first.
// Returned by value once per camera ray and matched at once: boxing the
// shaded point would allocate per sample.
#[allow(clippy::large_enum_variant)]
enum Seen {
    /// A surface with a material, here.
    Shaded(Point),
    /// A point an alpha mask cuts away.
    Masked,
    /// An object without a material.
    Clay,
}

/// What every sample of a pixel shares.
struct PixelSamples {
    /// The pixel's point, and its seed and Sobol key.
    x: DVec3,
    seed: u64,
    key: u32,
    /// Half the side of the part of the pixel the samples spread over, in pixels.
    half: f64,
    /// The point's place in the image.
    at: Option<(f64, f64, f64)>,
    rects: Vec<paths::Rect>,
    /// Samples per side of the footprint a sample's texture lookup covers.
    side: u32,
    /// What the camera sees through the pixel's centre: a sample whose own
    /// ray meets no material takes it.
    centre: Point,
    /// The pixel's point's vertices and weights, for a sample not located.
    location: [(u32, f64); 4],
}

/// A pixel's samples summed apart: what rays fixed, what reads the
/// solution, the diffuse part's factors (see [`kept`], which sums them
/// alike); and the first and second moments of the fixed part's
/// luminance, which decide whether more are drawn.
#[derive(Default)]
struct Sums {
    base: DVec3,
    reads: DVec3,
    diffuse: DVec3,
    /// The diffuse factors on the vertices each sample's point reads.
    weights: kept::DiffuseWeights,
    count: u32,
    moments: [f64; 2],
}

impl Sums {
    fn add(&mut self, fixed: DVec3) {
        let y = fixed.dot(DVec3::new(0.2126, 0.7152, 0.0722));
        self.count += 1;
        self.moments[0] += y;
        self.moments[1] += y * y;
    }

    /// Whether the standard error of the first `n` samples' mean exceeds `tolerance`.
    fn uncertain(&self, n: u32, tolerance: f64) -> bool {
        if n < 2 {
            return false;
        }
        let k = n as f64;
        let mean = self.moments[0] / k;
        let variance = ((self.moments[1] - self.moments[0] * mean) / (k - 1.0)).max(0.0);
        (variance / k).sqrt() > tolerance
    }
}

/// Sample `j` a pixel draws: the pixel's seed and the sample's point of
/// its Sobol sequence.
#[derive(Clone, Copy)]
struct Sample {
    j: u32,
    seed: u64,
    sobol: rounds::Sobol,
}

impl ObjectShading<'_> {
    /// The radiance towards the camera of virtual point `p`, or None when
    /// its surface has no material (shaded as diffuse clay). `share`: the
    /// fraction of its pixel the point stands for (a whole pixel, or an
    /// edge's sub-pixel). The samples spread over that part of the pixel,
    /// each at its own point of the surface: a highlight or a texture
    /// smaller than a pixel is averaged over it, as a camera's pixel does.
    pub fn radiance(&self, p: &SurfacePoint, share: f64) -> Option<DVec3> {
        self.radiance_with(p, share, None)
    }

    /// [`ObjectShading::radiance`] with the diffuse part's indirect
    /// irradiance `h` given (gathered at the pixel, [`crate::residual`])
    /// instead of interpolated from the vertices.
    pub fn radiance_with(&self, p: &SurfacePoint, share: f64, h: Option<DVec3>) -> Option<DVec3> {
        self.shade_point(p, share, h, None)
    }

    /// [`ObjectShading::radiance_with`], each sample's parts kept in
    /// `record` when one is given ([`kept`]).
    ///
    /// A pixel draws the samples its material needs
    /// ([`ObjectShading::sample_count`]), then as many again three times
    /// over where their spread says its mean is still uncertain
    /// ([`ShadingSettings::tolerance`]): a chrome ball's highlights and
    /// the sharp reflections of lamps take the extra samples, its smooth
    /// reflections of walls do not (Owen-scrambled Sobol points are
    /// stratified at every power of two, so the extension continues the
    /// same sequence).
    pub(crate) fn shade_point(
        &self,
        p: &SurfacePoint,
        share: f64,
        h: Option<DVec3>,
        record: Option<&mut kept::Record>,
    ) -> Option<DVec3> {
        self.materials.surfaces.get(&p.surface)?;
        let x = p.position.as_dvec3();
        let seed = hash2(
            hash2(p.position.x.to_bits() as u64, p.position.y.to_bits() as u64),
            p.position.z.to_bits() as u64,
        );
        let to = x - self.camera.position;
        let centre = match self.seen(to.normalize_or_zero(), to.length() * 1.001 + 1e-4, 1.0) {
            Some(Seen::Shaded(point)) => point,
            // Clay has no samples to keep, nor has what an alpha mask's cut shows.
            Some(Seen::Clay) => return None,
            // Cut away by an alpha mask, or the sample's own ray now misses it.
            _ => return Some(self.behind(x, to.normalize_or_zero(), seed)),
        };
        let n = self.sample_count(&centre.lobes, share);
        let corners = self.patches.patch_vertices.get(p.location.patch as usize);
        let mut location = [(u32::MAX, 0.0); 4];
        for (slot, (&v, w)) in location
            .iter_mut()
            .zip(corners.into_iter().flatten().zip(p.location.weights))
        {
            *slot = (v, f64::from(w));
        }
        let pixel = PixelSamples {
            x,
            seed,
            key: hash2(seed, 0xA11A5) as u32,
            half: 0.5 * share.sqrt(),
            at: self.camera.project(x),
            rects: self.rects(),
            side: (n as f64).sqrt().ceil() as u32,
            centre,
            location,
        };
        let mut kept = kept::Record {
            keepable: record.is_some(),
            view: ((x + (x - self.camera.position) * 1e-3).as_vec3(), 0.0),
            ..Default::default()
        };
        let mut sums = Sums::default();
        self.draw(&pixel, 0..n, &mut sums, &mut kept);
        let more = n * self.settings.extra_samples;
        // A sub-pixel's error weighs in its pixel's by its share, and its
        // pixel's other sub-pixels add theirs: the pixel's standard error
        // is √share of its sub-pixels' (independent, alike), so a
        // sub-pixel is held to the bound over √share.
        let tolerance = self.settings.tolerance * self.brightness / share.sqrt();
        if more > 0 && sums.uncertain(n, tolerance) {
            self.draw(&pixel, n..n + more, &mut sums, &mut kept);
        }
        // The indirect light gathered at the pixel (rounds), or read at
        // each sample's point.
        let diffuse = match h {
            Some(h) => sums.diffuse * h.max(DVec3::ZERO),
            None => sums.weights.light(self.indirect_with),
        };
        if let Some(r) = record {
            (kept.base, kept.diffuse) = (sums.base, sums.weights);
            *r = kept;
        }
        Some(kept::total(sums.base, sums.reads, diffuse, sums.count))
    }

    /// Draws samples `range` of `pixel` into `sums`, keeping each one's
    /// lobe ray in `kept` when it may be kept.
    fn draw(
        &self,
        pixel: &PixelSamples,
        range: std::ops::Range<u32>,
        sums: &mut Sums,
        kept: &mut kept::Record,
    ) {
        let (x, eye, half) = (pixel.x, self.camera.position, pixel.half);
        // The point of the pixel and the lobe's direction as four
        // dimensions of one Owen-scrambled Sobol point: each stratified,
        // and independent of the other (on one shared grid, a pixel's left
        // part took the lobe's low directions only).
        let points: Vec<[f64; 4]> = (range.clone())
            .map(|j| sobol_burley::sample_4d(j, 0, pixel.key).map(f64::from))
            .collect();
        // The pixel's camera rays, traced together: they are coherent, and
        // Embree's packets trace them at a fraction of one ray at a time.
        let subs = match pixel.at {
            Some((px, py, _)) => {
                let directions: Vec<DVec3> = (points.iter())
                    .map(|&[dx, dy, ..]| {
                        let (sx, sy) = (px + (2.0 * dx - 1.0) * half, py + (2.0 * dy - 1.0) * half);
                        self.camera.ray(sx, sy).direction
                    })
                    .collect();
                let seen = self.seen_all(&directions, 1.0 / pixel.side as f64);
                (seen.into_iter().zip(&directions))
                    .map(|((seen, t), d)| {
                        let point = match seen {
                            Some(Seen::Shaded(point)) => Some(point),
                            _ => None,
                        };
                        (point, eye + d * t.min(1e4))
                    })
                    .collect()
            }
            None => range.clone().map(|_| (None, x)).collect::<Vec<_>>(),
        };
        for (j, ([_, _, u1, u2], (sub, end))) in range.zip(points.into_iter().zip(subs)) {
            let point = sub.as_ref().unwrap_or(&pixel.centre);
            let sobol = rounds::Sobol::new(j, pixel.key, [u1, u2]);
            let sample = Sample {
                j,
                seed: pixel.seed,
                sobol,
            };
            let (own, (reflected, y), d) = self.sample_parts(point, &pixel.rects, sample);
            // What decides whether more samples are drawn is what the rays
            // fixed: a kept sample replayed over a new solution draws as
            // many as shading it anew would.
            let mut fixed = own;
            sums.base += own;
            sums.diffuse += d;
            if d != DVec3::ZERO {
                (sums.weights).add(d, point.location.unwrap_or(pixel.location));
            }
            let read = match reflected {
                paths::Reflected::Fixed(v) => {
                    sums.base += v;
                    fixed += v;
                    None
                }
                paths::Reflected::Read(m) => {
                    sums.reads += m.radiance(self);
                    fixed += m.fixed();
                    Some(m)
                }
            };
            sums.add(fixed);
            if kept.keepable {
                kept.sees(eye, x, end);
                let spread = (point.shadow_origin - x).length() as f32;
                kept.spread = kept.spread.max(spread * (1.0 + 1e-6));
                kept.lobes.push((y.as_vec3(), read));
            }
        }
    }

    /// What the camera sees along unit `d` (up to `far`) among the objects
    /// with materials; `scale`: the pixel footprint's fraction a sample covers.
    fn seen(&self, d: DVec3, far: f64, scale: f64) -> Option<Seen> {
        self.seen_far(d, far, scale).0
    }

    /// [`ObjectShading::seen`], and how far the ray went (infinity: it met nothing).
    fn seen_far(&self, d: DVec3, far: f64, scale: f64) -> (Option<Seen>, f64) {
        let ray = self.camera_ray(d, far);
        let hit = self.tracer.intersect(&ray, Layer::All);
        self.seen_at(hit, d, scale)
    }

    /// [`ObjectShading::seen_far`] of each of unit directions `ds`, unbounded.
    fn seen_all(&self, ds: &[DVec3], scale: f64) -> Vec<(Option<Seen>, f64)> {
        let rays: Vec<TraceRay> = ds
            .iter()
            .map(|&d| self.camera_ray(d, f64::INFINITY))
            .collect();
        let mut hits = vec![None; rays.len()];
        self.tracer.intersect_batch(&rays, Layer::All, &mut hits);
        (hits.into_iter().zip(ds))
            .map(|(hit, &d)| self.seen_at(hit, d, scale))
            .collect()
    }

    /// The camera's ray along unit `d`, up to `far`.
    fn camera_ray(&self, d: DVec3, far: f64) -> TraceRay {
        TraceRay {
            origin: self.camera.position.as_vec3(),
            direction: d.as_vec3(),
            tnear: 0.0,
            tfar: far.min(f32::MAX as f64) as f32,
        }
    }

    /// What the camera sees along unit `d` where the ray met `hit`.
    fn seen_at(&self, hit: Option<Hit>, d: DVec3, scale: f64) -> (Option<Seen>, f64) {
        let Some(hit) = hit else {
            return (None, f64::INFINITY);
        };
        let t = hit.t as f64;
        if !hit.is_virtual {
            return (None, t);
        }
        let Some(s) = self.materials.surfaces.get(&hit.surface) else {
            return (Some(Seen::Clay), t);
        };
        let x = self.camera.position + d * t;
        // Located for its diffuse part's light; a metal has none.
        let point = self
            .point(s, hit.triangle, x, d, t * scale)
            .map(|mut point| {
                if point.lobes.metallic < 1.0 {
                    point.location =
                        (self.patches.locate(hit.surface, hit.triangle, x)).map(|l| l.weights);
                }
                point
            });
        (Some(point.map_or(Seen::Masked, Seen::Shaded)), t)
    }

    /// Everything shading needs at `x`, on `triangle` of `surface` (the
    /// geometric normal of the sample when the triangle is unknown). None
    /// where an alpha mask cuts the surface away: the caller then shades
    /// what lies behind.
    fn point(
        &self,
        s: &PlacedSurface,
        triangle: u32,
        x: DVec3,
        d: DVec3,
        dist: f64,
    ) -> Option<Point> {
        let v = -d;
        let t = s.triangle(triangle as usize);
        let Some(t) = t else {
            let m = s.material.at(Vec2::ZERO, 1.0);
            return Some(Point {
                x,
                shadow_origin: x,
                ng: v,
                n: v,
                v,
                lobes: m.lobes,
                emissive: m.emissive,
                location: None,
            });
        };
        let k = triangle as usize;
        let [a, b, c] = t.map(|p| p.as_dvec3());
        let mut ng = crate::geometry::normal(&t);
        let w = barycentrics(a, b, c, x);
        let front = ng.dot(v) > 0.0;
        if !front {
            ng = -ng;
        }
        let (n, shadow_origin) = match s.normals(k) {
            Some(ns) => {
                let ns = ns.map(|n| n.as_dvec3());
                let n = (ns[0] * w[0] + ns[1] * w[1] + ns[2] * w[2]).normalize_or(ng);
                (n, terminator_safe(x, [a, b, c], ns, w))
            }
            None => (ng, x),
        };
        let uv = s.attributes.uvs.get(k).map_or(Vec2::ZERO, |uv| {
            uv[0] * w[0] as f32 + uv[1] * w[1] as f32 + uv[2] * w[2] as f32
        });
        let footprint = s.attributes.uvs.get(k).map_or(0.0, |uv| {
            let world = (b - a).cross(c - a).length();
            let tex = (uv[1] - uv[0]).perp_dot(uv[2] - uv[0]).abs() as f64;
            let across = dist / (self.camera.fx * ng.dot(v).abs().max(0.05).sqrt());
            (across * (tex / world.max(1e-30)).sqrt()) as f32
        });
        let m = s.material.at(uv, footprint);
        if !m.opaque {
            return None;
        }
        let mut n = n;
        if let (Some(tn), Some(uvs)) = (m.tangent_normal, s.attributes.uvs.get(k)) {
            let tangent = s
                .attributes
                .tangents
                .get(k)
                .map(|tg| {
                    let t = tg[0] * w[0] as f32 + tg[1] * w[1] as f32 + tg[2] * w[2] as f32;
                    (
                        (s.pose.rotation * t.truncate().as_dvec3()),
                        t.w.signum() as f64,
                    )
                })
                .filter(|(t, _)| t.length_squared() > 1e-12)
                .unwrap_or_else(|| uv_tangent([a, b, c], *uvs));
            n = perturbed(n, tangent, tn.as_dvec3());
        }
        if s.material.double_sided && n.dot(v) < 0.0 {
            n = -n;
        }
        if front || s.material.double_sided {
            n = towards_the_viewer(ng, v, n);
        }
        Some(Point {
            x,
            shadow_origin,
            ng,
            n,
            v,
            lobes: m.lobes,
            emissive: m.emissive,
            location: None,
        })
    }
}

/// The shading normal `n`, bent towards the geometric normal `ng` (facing
/// the viewer `v`) as little as it takes for the view's mirror direction to
/// leave the surface. A normal map's groove or an interpolated normal near
/// a silhouette can turn `n` from the viewer on a face the camera sees;
/// shaded as it is, such a point reflects nothing and its pixel goes black
/// (production renderers bend it the same way: Cycles' "ensure valid
/// reflection"). Found by bisection along the blend of `n` and `ng`, which
/// is valid at `ng` itself; 24 halvings put it within 1e-7 of the boundary.
fn towards_the_viewer(ng: DVec3, v: DVec3, n: DVec3) -> DVec3 {
    let facing = ng.dot(v);
    if facing <= 0.0 {
        return n;
    }
    // Mirror directions may always be as shallow as the view, not shallower.
    let threshold = (0.9 * facing).min(0.01);
    let valid = |n: DVec3| n.dot(v) > 0.0 && (2.0 * n.dot(v) * n - v).dot(ng) >= threshold;
    if valid(n) {
        return n;
    }
    let blend = |a: f64| n.lerp(ng, a).normalize_or(ng);
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..24 {
        let mid = 0.5 * (lo + hi);
        match valid(blend(mid)) {
            true => hi = mid,
            false => lo = mid,
        }
    }
    blend(hi)
}

/// Barycentric weights of `x` (in the plane of a, b, c) for a, b, c,
/// clamped into the triangle.
fn barycentrics(a: DVec3, b: DVec3, c: DVec3, x: DVec3) -> [f64; 3] {
    let [_, u, v] = crate::geometry::barycentric(a, b, c, x);
    if u.is_nan() || v.is_nan() {
        return [1.0, 0.0, 0.0];
    }
    let u = u.clamp(0.0, 1.0);
    let v = v.clamp(0.0, 1.0 - u);
    [1.0 - u - v, u, v]
}

/// Hanika's shadow-terminator point: `x` moved off its flat triangle to
/// where the tangent planes at the corners put the smooth surface.
fn terminator_safe(x: DVec3, corners: [DVec3; 3], normals: [DVec3; 3], w: [f64; 3]) -> DVec3 {
    let mut out = x;
    for i in 0..3 {
        let below = (x - corners[i]).dot(normals[i]).min(0.0);
        out -= normals[i] * (w[i] * below);
    }
    out
}

/// A triangle's tangent from its texture coordinates (u increasing), and
/// the sign of its bitangent, which points up the image (glTF's +Y of a
/// normal texture: v decreasing): where the file has no tangents and
/// MikkTSpace had no normals and coordinates to work from.
fn uv_tangent(t: [DVec3; 3], uv: [Vec2; 3]) -> (DVec3, f64) {
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let up = |a: Vec2, b: Vec2| glam::DVec2::new((b.x - a.x) as f64, (a.y - b.y) as f64);
    let (d1, d2) = (up(uv[0], uv[1]), up(uv[0], uv[2]));
    let det = d1.x * d2.y - d2.x * d1.y;
    if det.abs() < 1e-20 {
        return (e1.normalize_or_zero(), 1.0);
    }
    let tangent = (e1 * d2.y - e2 * d1.y) / det;
    let bitangent = (e2 * d1.x - e1 * d2.x) / det;
    let sign = if tangent.cross(bitangent).dot(e1.cross(e2)) < 0.0 {
        -1.0
    } else {
        1.0
    };
    (tangent.normalize_or_zero(), sign)
}

/// Normal `n` tilted by tangent-space normal `tn` in the frame of
/// `tangent` (Gram-Schmidt against n) and its bitangent sign.
fn perturbed(n: DVec3, (tangent, sign): (DVec3, f64), tn: DVec3) -> DVec3 {
    let t = (tangent - n * n.dot(tangent)).normalize_or_zero();
    if t == DVec3::ZERO {
        return n;
    }
    let b = n.cross(t) * sign;
    (t * tn.x + b * tn.y + n * tn.z).normalize_or(n)
}

#[cfg(test)]
mod tests;
