//! Per-pixel shading for [`composite_into`]: plain real pixels, edge pixels
//! (their sub-pixels averaged), virtual pixels, and an update's image alone
//! a row at a time.

use super::*;
use crate::pda::EdgePixel;

/// What shading a pixel reads: the input, and per row the columns where an
/// object or an edge may show.
pub(super) struct Shader<'a> {
    input: &'a CompositeInput<'a>,
    pda: &'a PixelDataArray,
    lights: usize,
    /// Without prepared pixels (a still image) each is prepared as it is shaded.
    floor: DVec3,
    /// Per row, the columns from the first to past the last pixel showing
    /// an object or mixing real and virtual sub-pixels (none: start ≥ end).
    /// Outside them a pixel shows a real point alone, or nothing: most
    /// pixels need neither the virtual index nor the edge list.
    spans: Vec<(u32, u32)>,
}

impl<'a> Shader<'a> {
    pub(super) fn new(input: &'a CompositeInput<'a>) -> Self {
        let pda = input.pda;
        let floor = input.known.map_or(input.floor, |k| k.floor);
        let (w, h) = (pda.width, pda.height);
        let mut spans = vec![(u32::MAX, 0u32); h as usize];
        for &p in pda
            .virtual_pixels
            .iter()
            .chain(pda.edges.iter().map(|e| &e.pixel))
        {
            let (x, y) = (p % w, (p / w) as usize);
            spans[y] = (spans[y].0.min(x), spans[y].1.max(x + 1));
        }
        Shader {
            input,
            pda,
            lights: pda.light_count,
            floor,
            spans,
        }
    }

    pub(super) fn pda(&self) -> &PixelDataArray {
        self.pda
    }

    /// The photo's pixel `i` (of the frame).
    pub(super) fn photo_at(&self, i: usize) -> Vec3 {
        self.input.photo.pixels[i]
    }

    fn in_span(&self, i: usize) -> bool {
        let w = self.pda.width as usize;
        let (x0, x1) = self.spans[i / w];
        (x0..x1).contains(&((i % w) as u32))
    }

    /// Whether pixel `i` shows no object, in whole or in part (outside
    /// the row's span: without looking it up).
    pub(super) fn shows_no_object(&self, i: usize) -> bool {
        !self.in_span(i) || (self.pda.virtual_at(i) == u32::MAX && self.edge_at(i).is_none())
    }

    /// Pixel `i`'s edge entry, if it mixes sub-pixels (edges are in pixel order).
    fn edge_at(&self, i: usize) -> Option<EdgePixel> {
        let edges = &self.pda.edges;
        self.in_span(i)
            .then(|| edges.binary_search_by_key(&(i as u32), |e| e.pixel).ok())
            .flatten()
            .map(|k| edges[k])
    }

    /// An edge pixel's shade, its virtual coverage and the objects' part of
    /// it: the mean of its sub-pixels, or, where rounds measured the shares
    /// of the pixel its parts cover, each part's mean by its share.
    fn shade_edge(&self, i: usize, e: EdgePixel) -> (Shade, f32, DVec3) {
        let (input, pda, lights) = (self.input, self.pda, self.lights);
        let photo = input.photo.pixels[i].as_dvec3();
        let empty = Shade {
            value: DVec3::ZERO,
            direct: DVec3::ZERO,
            indirect: DVec3::ZERO,
            copied: false,
            fallback: false,
            clamped: false,
        };
        // The objects' sub-pixels and the room's, summed apart.
        let (mut parts, mut counts) = ([empty, empty], [0u32; 2]);
        let edge = (pda.edges)
            .binary_search_by_key(&(i as u32), |e| e.pixel)
            .ok();
        let rounds = self.input.residual.zip(edge);
        // Rounds ran over the outlines (without rounds a residual holds the
        // shadow edges alone, and a band without one holds none).
        let refined = rounds.is_some_and(|(r, _)| !r.edge_shares.is_empty());
        // The objects' indirect light gathered at the pixel by the rounds.
        let gathered = rounds.and_then(|(r, k)| r.edge_irradiance.get(k).copied().flatten());
        // And the mean of the objects' part, their materials sampled over
        // the pixel: each object sub-pixel takes it.
        let sampled = rounds.and_then(|(r, k)| r.edge_radiance.get(k).copied().flatten());
        let shaded = |k: u32| {
            let points = self.input.shaded.map(|s| &s.edge);
            sampled.or_else(|| points.and_then(|p| p.get(k as usize).copied().flatten()))
        };
        for k in e.start..e.start + e.count {
            let p = &pda.edge_samples.points[k as usize];
            let terms = match pda.real_at(i) {
                r if p.pixel_terms && r != u32::MAX => {
                    &pda.real.terms[r as usize * lights..(r as usize + 1) * lights]
                }
                _ => &pda.edge_samples.terms[k as usize * lights..(k as usize + 1) * lights],
            };
            let s = if p.is_virtual {
                let share = 1.0 / (pda.supersample * pda.supersample) as f64;
                input.shade_virtual(
                    p,
                    terms,
                    share,
                    Rounds {
                        irradiance: gathered,
                        radiance: shaded(k),
                    },
                )
            } else {
                let direct = input.irradiance(terms, input.scales_with, true);
                // Rounds ran: the photo where the sub-pixel is.
                let at = match refined {
                    true => input.photo_at_point(i, p.position.as_dvec3()),
                    false => input.photo_at(i),
                };
                input.real_pixel(p, terms, at, self.floor).shade(
                    input.interpolate(input.indirect_with, &p.location),
                    at.0,
                    direct,
                )
            };
            let part = usize::from(!p.is_virtual);
            counts[part] += 1;
            let sum = &mut parts[part];
            sum.value += s.value;
            sum.direct += s.direct;
            sum.indirect += s.indirect;
            sum.fallback |= s.fallback;
            sum.clamped |= s.clamped;
        }
        // Sub-pixels that see no surface keep the photo's background.
        let total = (pda.supersample * pda.supersample) as f64;
        let grid = [counts[0] as f64, counts[1] as f64, total - e.count as f64].map(|c| c / total);
        let found = rounds.and_then(|(r, k)| r.edge_shares.get(k).copied().flatten());
        // The room's part as the rays shaded it, in place of the sub-pixels'.
        if let Some(room) = found.and_then(|f| f.1) {
            let n = counts[1].max(1) as f64;
            let p = &mut parts[1];
            (p.value, p.direct, p.indirect) = (room.as_dvec3(), p.direct / n, p.indirect / n);
            counts[1] = 1;
        }
        let shares = found
            .map(|f| f.0.map(f64::from))
            // A part the rays found but no sub-pixel shaded: the grid's shares.
            .filter(|f| (0..2).all(|p| counts[p] > 0 || f[p] == 0.0));
        let Some(shares) = shares else {
            // The sub-pixels' mean, summed as it always was.
            let sum = |f: &dyn Fn(&Shade) -> DVec3| (f(&parts[0]) + f(&parts[1])) / total;
            return (
                Shade {
                    value: (parts[0].value + parts[1].value + photo * (total - e.count as f64))
                        / total,
                    direct: sum(&|s| s.direct),
                    indirect: sum(&|s| s.indirect),
                    fallback: parts[0].fallback || parts[1].fallback,
                    clamped: parts[0].clamped || parts[1].clamped,
                    ..empty
                },
                grid[0] as f32,
                parts[0].value / total,
            );
        };
        let mean = |p: usize, x: DVec3| x / counts[p].max(1) as f64;
        let mix = |f: &dyn Fn(&Shade) -> DVec3| {
            mean(0, f(&parts[0])) * shares[0] + mean(1, f(&parts[1])) * shares[1]
        };
        let object = mean(0, parts[0].value) * shares[0];
        (
            Shade {
                value: mix(&|s| s.value) + photo * shares[2],
                direct: mix(&|s| s.direct),
                indirect: mix(&|s| s.indirect),
                fallback: parts[0].fallback || parts[1].fallback,
                clamped: parts[0].clamped || parts[1].clamped,
                ..empty
            },
            shares[0] as f32,
            object,
        )
    }

    /// A pixel's shade, its virtual coverage and the objects' part of it.
    fn shade(&self, i: usize) -> (Shade, f32, DVec3) {
        let (pda, lights) = (self.pda, self.lights);
        if let Some(e) = self.edge_at(i) {
            return self.shade_edge(i, e);
        }
        if pda.virtual_at(i) != u32::MAX {
            let k = pda.virtual_at(i) as usize;
            let residual = self.input.residual;
            let s = self.input.shade_virtual(
                &pda.virtual_samples.points[k],
                &pda.virtual_samples.terms[k * lights..(k + 1) * lights],
                1.0,
                Rounds {
                    irradiance: residual
                        .and_then(|r| r.object_irradiance.get(k).copied().flatten()),
                    radiance: (residual.and_then(|r| r.object_radiance.get(k).copied().flatten()))
                        .or_else(|| {
                            let shaded = self.input.shaded.map(|s| &s.whole);
                            shaded.and_then(|s| s.get(k).copied().flatten())
                        }),
                },
            );
            let object = s.value;
            return (s, 1.0, object);
        }
        let photo = self.input.photo.pixels[i].as_dvec3();
        (
            Shade {
                value: photo,
                direct: DVec3::ZERO,
                indirect: DVec3::ZERO,
                copied: true,
                fallback: false,
                clamped: false,
            },
            0.0,
            DVec3::ZERO,
        )
    }

    /// A pixel that shows a real point alone; None for any other.
    pub(super) fn plain(&self, i: usize, h_with: &[[Vec3A; 4]]) -> Option<PixelShade> {
        self.plain_with(i, h_with, None, None)
    }

    /// [`Shader::plain`] with `extra` added to the interpolated indirect
    /// light and the point's light terms replaced by `own_terms` when given.
    pub(super) fn plain_with(
        &self,
        i: usize,
        h_with: &[[Vec3A; 4]],
        extra: Option<Vec3A>,
        own_terms: Option<&[LightTerm]>,
    ) -> Option<PixelShade> {
        let (input, pda, lights) = (self.input, self.pda, self.lights);
        let photo = &input.photo.pixels;
        let k = pda.real_at(i);
        if k == u32::MAX
            || self.in_span(i) && (pda.virtual_at(i) != u32::MAX || self.edge_at(i).is_some())
        {
            return None;
        }
        let k = k as usize;
        let terms = own_terms.unwrap_or(&pda.real.terms[k * lights..(k + 1) * lights]);
        let r = match input.known {
            Some(known) if own_terms.is_none() => known.get(k),
            _ => input.real_pixel(&pda.real.points[k], terms, input.photo_at(i), self.floor),
        };
        let h = interpolate_single(&h_with[r.patch()], r.affine.weights);
        let mut s = r.layers(extra.map_or(h, |e| h + e), &photo[i]);
        if input.layers == super::Layers::All {
            s.direct = input.irradiance(terms, input.scales_with, true).as_vec3();
        }
        Some(s)
    }

    /// Any pixel [`Shader::plain`] does not take.
    pub(super) fn other(&self, i: usize) -> PixelShade {
        let (s, a, object) = self.shade(i);
        // Copied pixels keep the photo's exact bits.
        let value: Vec3 = if s.copied {
            self.input.photo.pixels[i]
        } else {
            s.value.as_vec3()
        };
        PixelShade {
            value,
            direct: s.direct.as_vec3(),
            indirect: s.indirect.as_vec3(),
            alpha: a,
            object: object.as_vec3(),
            copied: s.copied,
            fallback: s.fallback,
            clamped: s.clamped,
        }
    }

    /// An update's image alone (and the objects' own light, where the
    /// composite holds that layer): a row at a time over plain slices, the
    /// prepared real pixels shaded in place (what [`Shader::plain`] does,
    /// without a pixel's layers passed back).
    pub(super) fn image_only(
        &self,
        known: &RealPixels,
        h_with: &[[Vec3A; 4]],
        out: &mut Composite,
    ) {
        let (input, pda) = (self.input, self.pda);
        let photo = &input.photo.pixels;
        let may_keep = known.may_keep(h_with, input.patch_vertices);
        let tables = PlainTables {
            affine: &known.affine,
            bands: &known.keep,
            h_with,
            may_keep: &may_keep,
            // With an object in the room nearly no patch may keep the
            // photo: then no pixel looks its patch up.
            any_keep: may_keep.iter().any(|k| *k),
        };
        let w = (pda.width as usize).max(1);
        // Each row's part of the object layer where the composite holds it.
        let objects: Vec<Option<&mut [Vec3]>> =
            match out.object.pixels.len() == out.image.pixels.len() {
                true => out.object.pixels.chunks_mut(w).map(Some).collect(),
                false => (0..out.image.pixels.len().div_ceil(w))
                    .map(|_| None)
                    .collect(),
            };
        let rows = out
            .image
            .pixels
            .par_chunks_mut(w)
            .zip(out.alpha.par_chunks_mut(w))
            .zip(objects.into_par_iter())
            .enumerate();
        let counts = rows
            .map(|(local, ((image, alpha), mut object))| {
                // Plain pixels show no object: the layer is zero but where `other` shades.
                if let Some(o) = object.as_deref_mut() {
                    o.fill(Vec3::ZERO);
                }
                // The composite holds the rows the pixel data holds.
                let row = local + pda.rows.0 as usize;
                let at = local * w..local * w + image.len();
                let (real, virt, photo_row) = (
                    &pda.real_index[at.clone()],
                    &pda.virtual_index[at],
                    &photo[row * w..row * w + image.len()],
                );
                // Outside the columns where objects or edges may show,
                // every pixel is plain: a loop that asks nothing else.
                let (x0, x1) = match self.spans[row] {
                    (a, b) if a < b => (a as usize, b as usize),
                    _ => (image.len(), image.len()),
                };
                let mut counts = Counts::default();
                tables.run(
                    &mut image[..x0],
                    &mut alpha[..x0],
                    &real[..x0],
                    &photo_row[..x0],
                    &mut counts,
                );
                tables.run(
                    &mut image[x1..],
                    &mut alpha[x1..],
                    &real[x1..],
                    &photo_row[x1..],
                    &mut counts,
                );
                for x in x0..x1 {
                    let k = real[x];
                    if k == u32::MAX || virt[x] != u32::MAX || self.edge_at(row * w + x).is_some() {
                        let s = self.other(row * w + x);
                        image[x] = s.value;
                        alpha[x] = s.alpha;
                        if let Some(o) = object.as_deref_mut() {
                            o[x] = s.object;
                        }
                        counts.add(s.copied, s.fallback, s.clamped);
                        continue;
                    }
                    tables.pixel(
                        k as usize,
                        &photo_row[x],
                        &mut image[x],
                        &mut alpha[x],
                        &mut counts,
                    );
                }
                counts
            })
            .reduce(Counts::default, Counts::sum);
        (out.copied, out.ratio_fallbacks, out.clamped) =
            (counts.copied, counts.fallbacks, counts.clamped);
    }
}
