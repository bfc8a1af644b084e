use super::*;

/// Everything the rounds of a reconstruction share: the pixel samples
/// (textures removed, mixed pixels left out, indirect light gathered from
/// the photo where it sees the hit) and the radiosity model that supplies
/// the rest of the indirect light.
pub(super) struct Evidence {
    pub(super) index: usize,
    pub(super) unit: LightSource,
    /// Every sample as photographed (texture and all, mixed ones too), with
    /// [`mixed_pixels`], [`sharp_pixels`] and [`unreadable_pixels`];
    /// `samples` are those EQ1 and EQ2 use, textures removed, mixed ones
    /// left out (once a light model reads them, only unreadable ones).
    pub(super) all: Vec<Sample>,
    pub(super) mixed: Vec<bool>,
    pub(super) sharp: Vec<bool>,
    pub(super) unreadable: Vec<bool>,
    /// The texture last found (ln per channel and sample of `all`), with
    /// its robust weights.
    pub(super) texture: Texture,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) samples: Vec<Sample>,
    pub(super) unseen_hits: Vec<u32>,
    pub(super) texture_edges: usize,
    pub(super) patches: Patches,
    pub(super) transport: Transport,
    pub(super) photo_patches: PhotoPatches,
    pub(super) known_rho: HashMap<u32, DVec3>,
    /// Direct irradiance per patch of the other (known) real lights.
    pub(super) direct_known: Vec<DVec3>,
}

impl Evidence {
    pub(super) fn gather(
        scene: &Scene,
        photo: &Image,
        tracer: &Tracer,
        settings: &GonioSettings,
    ) -> Result<Evidence> {
        let Some(index) = light_to_reconstruct(scene)? else {
            return Err(Error::key(
                &scene.file,
                "light",
                "no light has intensity = \"reconstruct\"",
            ));
        };
        if scene.reflectances.is_empty() {
            return Err(Error::key(
                &scene.file,
                format!("light[{index}].intensity"),
                "\"reconstruct\" needs at least one [[reflectance]]",
            ));
        }
        // The unknown light at unit intensity gives each sample's geometry term.
        let mut unit_scene = scene.clone();
        unit_scene.lights[index].intensity = Intensity::Uniform(DVec3::ONE);
        let unit = LightSource::from_scene(&unit_scene, index)?;
        let others: Vec<LightSource> = (0..scene.lights.len())
            .filter(|&j| j != index && scene.lights[j].real)
            .map(|j| LightSource::from_scene(scene, j))
            .collect::<Result<_>>()?;
        let patches = Patches::of_scene(scene, false, settings.patch_size);
        let cam = &scene.camera;
        let sampler = Sampler {
            photo,
            tracer,
            unit: &unit,
            others: &others,
            level: settings.light_level,
        };
        let mut samples: Vec<Sample> = (0..cam.height)
            .into_par_iter()
            .flat_map_iter(|row| sampler.row(cam, row))
            .collect();
        let mixed = mixed_pixels(&samples, cam.width, cam.height);
        let sharp = sharp_pixels(&samples, cam.width, cam.height);
        let unreadable = unreadable_pixels(&samples, cam.width, cam.height);
        // Mixed pixels too: a later texture model needs their indirect light.
        let unseen_hits = gather_from_photo(
            scene,
            tracer,
            &patches,
            photo,
            &mut samples,
            settings.gather_rays,
        );
        let all = samples;
        let (samples, texture_edges, texture) = textured(
            &all,
            &mixed,
            None,
            None,
            cam.width,
            cam.height,
            settings.texture_edge,
        );
        if !samples.iter().any(|s| s.g > 0.0) {
            return Err(Error::key(
                &scene.file,
                format!("light[{index}].position"),
                "the photo shows no surface this light can reach: nothing to reconstruct from",
            ));
        }
        let transport =
            Transport::hierarchical(&patches, tracer, Layer::Real, DEFAULT_LINK_EPSILON);
        let photo_patches = PhotoPatches::measure(cam, tracer, &patches, photo);
        let known_rho: HashMap<u32, DVec3> = scene
            .reflectances
            .iter()
            .map(|k| (k.surface as u32, k.rgb))
            .collect();
        let direct_known: Vec<DVec3> = {
            let per =
                direct_irradiance(&patches, &others, tracer, Layer::Real, settings.light_level);
            (0..patches.patch_count())
                .map(|k| per.iter().map(|p| p[k]).sum())
                .collect()
        };
        Ok(Evidence {
            index,
            unit,
            all,
            mixed,
            sharp,
            unreadable,
            texture,
            width: cam.width,
            height: cam.height,
            samples,
            unseen_hits,
            texture_edges,
            patches,
            transport,
            photo_patches,
            known_rho,
            direct_known,
        })
    }

    /// Sets each sample's indirect light: gathered from the photo, plus what
    /// its rays met unseen from the radiosity solution with `light` (the
    /// unknown light as currently known; `None`: not at all).
    pub(super) fn update_indirect(
        &mut self,
        light: Option<&LightSource>,
        tracer: &Tracer,
        settings: &GonioSettings,
    ) {
        let pi = std::f64::consts::PI;
        let direct: Vec<DVec3> = match light {
            None => self.direct_known.clone(),
            Some(light) => {
                let per = direct_irradiance(
                    &self.patches,
                    std::slice::from_ref(light),
                    tracer,
                    Layer::Real,
                    settings.light_level,
                );
                self.direct_known
                    .iter()
                    .zip(&per[0])
                    .map(|(a, b)| *a + *b)
                    .collect()
            }
        };
        let est = estimate_reflectances(
            &self.patches,
            &self.transport,
            &direct,
            &self.photo_patches,
            &self.known_rho,
            EstimateSettings::default(),
        );
        let mixed: Vec<DVec3> = (0..self.patches.patch_count())
            .map(|k| {
                if self.photo_patches.pixels[k] > 0 {
                    self.photo_patches.radiance[k] * pi
                } else {
                    est.solution.radiosity[k]
                }
            })
            .collect();
        let scale = 1.0 / settings.gather_rays as f64;
        let unseen_hits = &self.unseen_hits;
        for set in [&mut self.all, &mut self.samples] {
            set.par_iter_mut().for_each(|s| {
                let unseen: DVec3 = unseen_hits[s.unseen.0 as usize..s.unseen.1 as usize]
                    .iter()
                    .map(|&k| mixed[k as usize])
                    .sum();
                s.h_ind = s.gathered_photo + unseen * scale;
            });
        }
    }

    /// Takes the textures out again, with `distribution` as the unknown
    /// light's model across the known lights' soft shadow edges.
    pub(super) fn retexture(&mut self, distribution: &Distribution, settings: &GonioSettings) {
        let unknown: Vec<DVec3> = self
            .all
            .iter()
            .map(|s| distribution.intensity(direction_at(s.v, s.h)) * s.g)
            .collect();
        let model = PenumbraModel {
            unknown: &unknown,
            sharp: &self.sharp,
            unreadable: &self.unreadable,
        };
        // From the texture found before: most of it stays.
        (self.samples, self.texture_edges, self.texture) = textured(
            &self.all,
            &self.mixed,
            Some(&model),
            Some(&self.texture),
            self.width,
            self.height,
            settings.texture_edge,
        );
    }
}

/// What a pixel's sample reads: the unknown light at unit intensity, the
/// known lights, and the photo.
struct Sampler<'a> {
    photo: &'a Image,
    tracer: &'a Tracer,
    unit: &'a LightSource,
    others: &'a [LightSource],
    /// 2^level shadow rays towards area lights.
    level: usize,
}

impl Sampler<'_> {
    /// The samples of row `row`: each pixel whose surface some light reaches.
    fn row(&self, cam: &crate::camera::Camera, row: u32) -> Vec<Sample> {
        let (tracer, position, level) = (self.tracer, self.unit.position, self.level);
        let hits = row_hits(cam, tracer, Layer::Real, row);
        let mut out = Vec::new();
        for (col, hit) in hits.iter().enumerate() {
            let Some(hit) = hit else { continue };
            let ray = cam.pixel_ray(col as u32, row);
            let x = ray.origin + ray.direction * hit.t as f64;
            // The hit normal faces the camera: a light behind the surface does not light what the photo shows.
            let n = hit.normal.as_dvec3();
            let seed = hash2(
                (row as usize * cam.width as usize + col) as u64,
                0x0060_1110,
            );
            let g = if (position - x).dot(n) > 0.0 {
                let d = self.unit.direct(tracer, Layer::Real, x, n, level, seed);
                (d.unoccluded * d.visibility).x
            } else {
                0.0
            };
            let mut e_known = DVec3::ZERO;
            for (j, l) in self.others.iter().enumerate() {
                if (l.position - x).dot(n) > 0.0 {
                    let d = l.direct(tracer, Layer::Real, x, n, level, hash2(seed, j as u64 + 1));
                    e_known += d.unoccluded * d.visibility;
                }
            }
            let b = self.photo.get(col as u32, row).as_dvec3() * std::f64::consts::PI;
            if !b.is_finite() || (g <= 0.0 && e_known == DVec3::ZERO) {
                continue;
            }
            let (v, h) = angles((x - position).normalize_or_zero());
            let area = (hit.t as f64).powi(2) / n.dot(ray.direction).abs().max(0.05);
            out.push(Sample {
                surface: hit.surface,
                v,
                h,
                g,
                e_known,
                b,
                h_ind: DVec3::ZERO,
                pixel: row * cam.width + col as u32,
                x,
                n,
                area,
                gathered_photo: DVec3::ZERO,
                unseen: (0, 0),
            });
        }
        out
    }
}
