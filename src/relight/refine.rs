//! Texture-based refinement (Loscos §4.1, Fig. 12): the leaves' light
//! terms, their colour in CIELAB, and one round of splits.

use super::*;

/// Visibility of one light from an element: fraction of its unoccluded
/// irradiance that arrives (1 where the light does not reach it at all).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LightTerm {
    pub(super) occluded: DVec3,
    pub(super) unoccluded: DVec3,
}

impl LightTerm {
    pub(super) fn visibility(&self) -> f64 {
        let u = self.unoccluded.element_sum();
        if u > 0.0 {
            (self.occluded.element_sum() / u).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }
}

/// Mean direct light over an element's 2×2 quadrature points.
pub(super) fn element_light(
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
pub(super) fn leaf_light(
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

/// [`leaf_light`] through the room and the objects, `room` holding the
/// room's leaves' terms through the room alone (the first leaves): those
/// are taken wherever the shaft from a leaf to the light leaves out every
/// object (no ray can meet one there: the same rays, seeds and answers),
/// and only the rest are traced. An object's leaf takes the terms of the
/// leaf `share` names (its group's, see
/// [`GatherRows::representatives`](crate::radiosity::GatherRows::representatives)).
pub(super) fn leaf_light_with_objects(
    patches: &Patches,
    (lights, room): (&[LightSource], &[Vec<LightTerm>]),
    tracer: &Tracer,
    (level, share): (usize, &[u32]),
    objects: &crate::objects::VirtualBounds,
) -> Vec<Vec<LightTerm>> {
    let none = LightTerm {
        occluded: DVec3::ZERO,
        unoccluded: DVec3::ZERO,
    };
    lights
        .iter()
        .zip(room)
        .map(|(light, room)| {
            let light_box = light.bounds();
            let own: Vec<LightTerm> = (0..patches.patch_count())
                .into_par_iter()
                .map(|k| {
                    if share[k] != k as u32 {
                        return none;
                    }
                    let el = patches.patch(k);
                    if let Some(term) = room.get(k) {
                        let shaft = crate::shaft::Shaft::between_boxes(el.bounds, light_box);
                        if objects.objects.iter().all(|o| o.outside(&shaft)) {
                            return *term;
                        }
                    }
                    let seed = element_seed(patches, el);
                    let shape = patches.sample_shape(k);
                    element_light(shape, el.normal, light, tracer, Layer::All, level, seed)
                })
                .collect();
            share.iter().map(|&s| own[s as usize]).collect()
        })
        .collect()
}

/// Light terms already computed, by (element identity, light, through the objects too).
pub(super) type TermCache = HashMap<((u32, i64, i64, i64), usize, bool), LightTerm>;

/// An element's identity across rebuilds of the mesh (its root, centre and size).
pub(super) fn element_key(patches: &Patches, el: &Element) -> (u32, i64, i64, i64) {
    let c = region_centre(&el.region);
    (
        patches.root_ordinal(el.root),
        (c.x * 1e9).round() as i64,
        (c.y * 1e9).round() as i64,
        (el.shape.size() * 1e9).round() as i64,
    )
}

pub(super) fn element_seed(patches: &Patches, el: &Element) -> u64 {
    let (r, a, b, c) = element_key(patches, el);
    hash2(hash2(r as u64, a as u64), hash2(b as u64, c as u64))
}

/// Linear sRGB (relative to `white`) to CIELAB under D65.
pub(crate) fn cielab(rgb: DVec3, white: f64) -> DVec3 {
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
pub(crate) fn colour_distance(a: DVec3, b: DVec3) -> f64 {
    (a - b).length()
}

pub(super) fn luminance(c: DVec3) -> f64 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// A pixel centre's hit in the real geometry: where, on which root, how far.
#[derive(Debug, Clone, Copy)]
pub(super) struct RealHit {
    pub(super) surface: u32,
    pub(super) triangle: u32,
    pub(super) x: DVec3,
    pub(super) t: f64,
}

pub(super) fn real_hits(scene: &Scene, tracer: &Tracer) -> Vec<Option<RealHit>> {
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
pub(super) struct LeafPixels {
    pub(super) mean: Vec<DVec3>,
    pub(super) count: Vec<u32>,
    pub(super) footprint: Vec<f64>,
}

pub(super) fn leaf_pixels(
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
pub(super) fn neighbours(patches: &Patches, leaves: usize) -> Vec<Vec<u32>> {
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
pub(super) struct Criteria {
    /// Real lights on in the photo: the texture rule (their shadows are in it).
    pub(super) texture: Vec<usize>,
    /// Lights whose visibility changes what the variant shows: inserted
    /// lights, and every active light where inserted objects cast shadows.
    pub(super) forced: Vec<(usize, Layer)>,
}

/// What every round of the texture-based refinement reads.
pub(super) struct Refiner<'a> {
    pub(super) hits: &'a [Option<RealHit>],
    pub(super) photo: &'a Image,
    pub(super) pixel_angle: f64,
    /// CIELAB's white.
    pub(super) white: f64,
    pub(super) lights: &'a [LightSource],
    pub(super) criteria: &'a Criteria,
    pub(super) tracer: &'a Tracer,
    pub(super) settings: &'a TextureSettings,
}

impl Refiner<'_> {
    /// Every (light, layer) the criteria look at.
    fn wanted(&self) -> Vec<(usize, Layer)> {
        let mut wanted: Vec<(usize, Layer)> = self
            .criteria
            .texture
            .iter()
            .map(|&l| (l, Layer::Real))
            .collect();
        wanted.extend(self.criteria.forced.iter().copied());
        wanted.dedup();
        wanted
    }

    /// The light terms of `els` for each wanted (light, layer): what the
    /// cache lacks is computed in parallel, then read.
    fn terms(
        &self,
        patches: &Patches,
        wanted: &[(usize, Layer)],
        els: &[Element],
        cache: &mut TermCache,
    ) -> Vec<Vec<LightTerm>> {
        for &(l, layer) in wanted {
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
                        &self.lights[l],
                        self.tracer,
                        layer,
                        self.settings.light_level,
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
    }

    /// One round of Fig. 12 over the current leaves; returns the splits added to `marks`.
    pub(super) fn round(
        &self,
        patches: &Patches,
        cache: &mut TermCache,
        marks: &mut SplitMarks,
        stats: &mut TextureStats,
    ) -> usize {
        let n = patches.patch_count();
        let settings = self.settings;
        let lp = leaf_pixels(patches, self.hits, self.photo, self.pixel_angle);
        let seen = |k: usize| lp.count[k] > 0;
        let lab: Vec<DVec3> = lp.mean.iter().map(|c| cielab(*c, self.white)).collect();
        let wanted = self.wanted();
        let leaves: Vec<Element> = (0..n).map(|k| patches.patch(k).clone()).collect();
        let eligible: Vec<usize> = (0..n)
            .filter(|&k| {
                seen(k)
                    && !patches.is_virtual_surface(leaves[k].surface)
                    && leaves[k].shape.size() >= settings.min_leaf_pixels * lp.footprint[k]
            })
            .collect();
        let vis: Vec<Vec<f64>> = self
            .terms(patches, &wanted, &leaves, cache)
            .iter()
            .map(|t| t.iter().map(LightTerm::visibility).collect())
            .collect();
        let halves = halves(&leaves, &eligible);
        let half_terms = self.terms(patches, &wanted, &halves, cache);
        let near = neighbours(patches, n);
        let tau = settings.visibility_threshold;
        let texture_count = self.criteria.texture.len();
        let mut added = 0;
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
                let el = &leaves[k];
                marks
                    .entry(patches.root_ordinal(el.root))
                    .or_default()
                    .push((region_centre(&el.region), el.shape.size()));
                added += 1;
            } else {
                stats.undone += 1;
            }
        }
        added
    }
}

/// The two halves of each eligible leaf, in order.
fn halves(leaves: &[Element], eligible: &[usize]) -> Vec<Element> {
    eligible
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
        .collect()
}
