//! The texture path's preprocess in parts: what it derives from its inputs
//! ([`Setup`]), the texture-based refinement's rounds, the photo's
//! illumination model on the refined mesh, Loscos's Steps 1 and 2
//! ([`Unshadow`], [`References`]), and what each pixel keeps.

use super::*;
use crate::error::Error;
use crate::radiosity::{GatherRows, GatherRowsSettings, ObjectLinkEstimate, ObjectView};

/// Groups of the objects' leaves traced to estimate what all of them make.
const PILOT_TASKS: usize = 64;

/// Bytes counted per link and per row weight, the room's included: a
/// bound, not a measure (a weight takes 8 bytes, a link 12 and the room's
/// are held already). It kept the texture path's peak within the budget
/// when objects were linked element by element, 51 MB more peak per
/// million links.
const BYTES_PER_OBJECT_LINK: f64 = 56.0;

/// What the preprocess derives from its inputs before any work.
pub(super) struct Setup<'a> {
    pub(super) scene: &'a Scene,
    pub(super) photo: &'a Image,
    pub(super) tracer: &'a Tracer,
    pub(super) settings: &'a TextureSettings,
    pub(super) lights: Vec<LightSource>,
    /// Each light's scale in the photo.
    pub(super) photo_scales: Vec<f64>,
    pub(super) has_objects: bool,
    pub(super) patch_size: f64,
    pub(super) virtual_size: f64,
    pub(super) criteria: Criteria,
    pub(super) pixel_angle: f64,
}

impl<'a> Setup<'a> {
    pub(super) fn new(
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
    pub(super) fn refine(
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
                (self.virtual_size, None),
                &marks,
            );
        }
        (patches, marks)
    }

    /// The mesh with the inserted objects, the direct light through them
    /// and the transport with them: the room's links as given, and rows
    /// of weights gathered by rays for the room's leaves that see the
    /// objects and for the objects' leaves ([`GatherRows`]). With a memory
    /// budget, what the objects' rows will hold is first measured on a
    /// sample of their groups, and refused before they are made when it
    /// would not fit.
    pub(super) fn with_objects(
        &self,
        patches: Patches,
        direct: Vec<Vec<LightTerm>>,
        transport: Transport,
        marks: &SplitMarks,
        times: &mut StageTimes,
        stats: &mut TextureStats,
    ) -> Result<(Patches, Vec<Vec<LightTerm>>, Transport)> {
        if !self.has_objects {
            return Ok((patches, direct, transport));
        }
        let (tracer, settings) = (self.tracer, self.settings);
        let all = times.time("virtual mesh", || {
            let objects = (self.virtual_size, self.settings.coarse_objects_from);
            Patches::of_scene_refined(self.scene, true, self.patch_size, objects, marks)
        });
        let bounds = crate::objects::VirtualBounds::of(&self.scene.virtual_world_surfaces());
        let rows_settings = self.gather_rows();
        let groups = GatherRows::groups_of(&all, rows_settings.within);
        let direct = times.time("direct light with objects", || {
            // Objects with a material are shaded per pixel, lights sampled
            // there: their leaves' direct light only feeds the radiosity, and
            // close leaves facing alike share it. Clay shows its leaves' own.
            let shaded = surfaces_with_material(self.scene);
            let share = GatherRows::representatives(&all, &groups, |s| shaded.contains(&s));
            let lights = (&self.lights[..], &direct[..]);
            leaf_light_with_objects(
                &all,
                lights,
                tracer,
                (settings.light_level, &share),
                &bounds,
            )
        });
        // What the room sees of the objects in place of what they hide: its
        // own links are kept as they are.
        let mut rows = times.time("objects seen from the room", || {
            let view = ObjectView::trace(&all, patches.patch_count(), tracer, &bounds);
            GatherRows::of_view(&all, &view)
        });
        if let Some(budget) = settings.memory {
            let estimate = times.time("object links estimate", || {
                self.estimate_rows(&all, (&transport, &rows), &groups)
            });
            stats.object_links_estimate = Some(estimate);
            self.check_link_memory(&estimate, budget)?;
        }
        let objects = times.time("objects' gather rays", || {
            GatherRows::trace(&all, tracer, &groups, rows_settings.rays)
        });
        stats.object_gather_groups = objects.group_count();
        rows.append(objects);
        Ok((all, direct, transport.with_gather_rows(rows)))
    }

    /// How the objects' leaves gather their light: in groups within a
    /// quarter of the objects' patch size, as the pixel path's vertices
    /// share their final gathers.
    fn gather_rows(&self) -> GatherRowsSettings {
        GatherRowsSettings {
            rays: self.settings.object_rays,
            within: self.virtual_size / 4.0,
        }
    }

    /// What the transport will hold with the objects: the room's links,
    /// the room's rows (`room`, made) and the rows of the objects' `groups`,
    /// measured on [`PILOT_TASKS`] of them.
    fn estimate_rows(
        &self,
        all: &Patches,
        (transport, room): (&Transport, &GatherRows),
        groups: &[Vec<u32>],
    ) -> ObjectLinkEstimate {
        let rays = self.gather_rows().rays;
        let (entries, seconds) =
            GatherRows::estimate(all, self.tracer, (groups, rays), PILOT_TASKS);
        ObjectLinkEstimate {
            roots: (all.roots.iter())
                .filter(|r| all.is_virtual_element(**r))
                .count(),
            groups: groups.len(),
            sampled: PILOT_TASKS.min(groups.len()),
            links: (transport.link_count() + room.entry_count()) as f64 + entries,
            seconds,
        }
    }

    /// Refuses links that, held on top of what the process holds now,
    /// would pass `budget` bytes: the message gives the estimate and the
    /// `--memory` that would fit.
    fn check_link_memory(&self, e: &ObjectLinkEstimate, budget: u64) -> Result<()> {
        let now = crate::util::resident_bytes().unwrap_or(0);
        let need = now + (e.links * BYTES_PER_OBJECT_LINK) as u64;
        if need <= budget {
            return Ok(());
        }
        let mb = |b: u64| b.div_ceil(1_000_000);
        Err(Error::file(
            &self.scene.file,
            format!(
                "--method texture would hold about {} MB with the objects' {} triangles ({:.1} M links and weights, about {:.1} s, measured on {} of their {} groups), more than the {} MB --memory allows: give --memory {}M, or render on the pixel path (--method pda), which holds no links with the objects",
                mb(need),
                e.roots,
                e.links / 1e6,
                e.seconds,
                e.sampled,
                e.groups,
                mb(budget),
                mb(need).div_ceil(100) * 100,
            ),
        ))
    }

    /// The photo's illumination model on the refined mesh (links at the
    /// leaves for the light sources: direct light is per leaf).
    pub(super) fn real_model(&self, patches: &Patches, times: &mut StageTimes) -> RealModel {
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
        let transport = crate::model::room_links(
            self.scene,
            patches,
            tracer,
            self.settings.link_epsilon,
            self.settings.cache_links,
            times,
        );
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
pub(super) struct RealModel {
    /// Per light and leaf, through the real layer.
    pub(super) direct: Vec<Vec<LightTerm>>,
    pub(super) transport: Transport,
    /// The user's reflectances by surface.
    pub(super) known: HashMap<u32, DVec3>,
    /// The photo's lights' direct irradiance per leaf, with and without
    /// their shadows.
    pub(super) e_occluded: Vec<DVec3>,
    pub(super) e_unoccluded: Vec<DVec3>,
    pub(super) estimate: Estimate,
}

/// The photo's 99th percentile luminance over the real pixels: CIELAB's white.
pub(super) fn white_level(hits: &[Option<RealHit>], photo: &Image) -> f64 {
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
pub(super) fn user_points(scene: &Scene, base: &Patches) -> Result<Vec<(u32, u32, DVec3)>> {
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
pub(super) fn vertex_visibility(direct: &[Vec<LightTerm>], patches: &Patches) -> Vec<Vec<f64>> {
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
pub(super) struct Unshadow<'a> {
    pub(super) setup: &'a Setup<'a>,
    pub(super) patches: &'a Patches,
    pub(super) real_vis: Vec<Vec<f64>>,
    /// The photo's indirect irradiance at the vertices.
    pub(super) h_vertex: Vec<DVec3>,
    /// Step 2's correction at the vertices (empty until Step 2 has run).
    pub(super) correction_vertex: Vec<DVec3>,
}

impl Unshadow<'_> {
    /// Step 1 (Eq. 5-6) at a point: the blocked direct light added back.
    /// The photo's lights' unoccluded irradiance there is exact; their
    /// visibility is the mesh's.
    pub(super) fn step1(&self, x: DVec3, n: DVec3, at: &Location) -> DVec3 {
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

    pub(super) fn step2(&self, at: &Location) -> DVec3 {
        self.patches.interpolate(&self.correction_vertex, at)
    }

    /// Both steps at a point of root polygon `root`.
    pub(super) fn at_root_point(&self, root: u32, x: DVec3) -> DVec3 {
        let at = self.patches.locate_in_root(root, x);
        self.step1(x, self.patches.patch(at.patch as usize).normal, &at) * self.step2(&at)
    }
}

/// Steps 1 and 2 over the leaves the camera sees: the shadow-free factors
/// and ρ_final per leaf.
pub(super) fn unshadow<'a>(
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
pub(super) fn occluded_leaves(setup: &Setup, model: &RealModel, leaves: usize) -> Vec<bool> {
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
pub(super) struct References<'a> {
    pub(super) patches: &'a Patches,
    pub(super) occluded: &'a [bool],
    pub(super) seen: &'a [bool],
    pub(super) rho_inter: &'a [DVec3],
    pub(super) user_points: &'a [(u32, u32, DVec3)],
    pub(super) colour_threshold: f64,
}

impl References<'_> {
    /// The correction factor per leaf (one where no reference applies).
    pub(super) fn corrections(&self, stats: &mut TextureStats) -> Vec<DVec3> {
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
pub(super) fn index_textures(textures: HashMap<u32, Texture>) -> (Vec<Texture>, HashMap<u32, u32>) {
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
pub(super) fn pixel_points(
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
pub(super) fn display_factors(
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

/// The surface ids of the enabled objects' surfaces that have a material
/// (shaded per pixel by their BRDF; the others are diffuse clay).
fn surfaces_with_material(scene: &Scene) -> std::collections::HashSet<u32> {
    (scene.virtual_surfaces())
        .filter(|(_, o, i)| o.enabled && o.surfaces[*i].material.is_some())
        .map(|(id, ..)| id)
        .collect()
}
