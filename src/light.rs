//! [`LightSource`]: a scene light made ready for rendering: its goniometric
//! [`Distribution`] I(direction) (Grosch §2.1), its emitting shape with the
//! [`JitteredGrid`] of shadow-ray targets (Grosch §3.1), and the direct
//! irradiance it gives a surface point, split as the Pixel Data Array keeps
//! it: an unoccluded geometry term times a visibility in [0, 1].
//!
//! Also [`polygon_form_factor`], the exact unoccluded form factor from a
//! point to a polygon (Lambert's contour formula), used for Lambertian rect
//! lights here and for patch-to-patch exchange in radiosity: it stays finite
//! however close the point is.

use glam::{DVec2, DVec3};

use crate::error::{Error, Result};
use crate::ies::IesProfile;
use crate::scene::{Intensity, Light, LightPosition, LightShape, Scene};
use crate::trace::{Layer, TraceRay, Tracer};
use crate::util::rng::{hash2, unit_random};

mod lambert;
#[cfg(test)]
use lambert::angle_atan2;
pub use lambert::{polygon_form_factor, polygon_form_factor_sided, polygon_form_factors_sided};

/// Goniometric intensity I(direction) in W/sr, before the light's scale.
#[derive(Debug, Clone, PartialEq)]
pub enum Distribution {
    Uniform(DVec3),
    Lambertian {
        normal: DVec3,
        rgb: DVec3,
    },
    /// Angles in radians.
    Spot {
        axis: DVec3,
        rgb: DVec3,
        beam: f64,
        cutoff: f64,
    },
    /// `rgb` includes the file's tilt factor at this orientation.
    Ies {
        profile: Box<IesProfile>,
        axis: DVec3,
        reference: DVec3,
        rgb: DVec3,
    },
}

impl Distribution {
    /// Intensity towards unit direction `d` (pointing away from the light).
    pub fn intensity(&self, d: DVec3) -> DVec3 {
        match self {
            Distribution::Uniform(rgb) => *rgb,
            Distribution::Lambertian { normal, rgb } => *rgb * d.dot(*normal).max(0.0),
            Distribution::Spot {
                axis,
                rgb,
                beam,
                cutoff,
            } => {
                let angle = d.dot(*axis).clamp(-1.0, 1.0).acos();
                if angle <= *beam {
                    *rgb
                } else if angle >= *cutoff {
                    DVec3::ZERO
                } else {
                    *rgb * ((*cutoff - angle) / (*cutoff - *beam))
                }
            }
            Distribution::Ies {
                profile,
                axis,
                reference,
                rgb,
            } => *rgb * profile.candela_towards(d, *axis, *reference),
        }
    }
}

/// The emitting shape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Emitter {
    Point,
    /// Spans centre ± u/2 ± v/2; emits on the side of `normal` = unit u×v.
    Rect {
        u: DVec3,
        v: DVec3,
        normal: DVec3,
    },
}

/// Shadow-ray targets on a rect light (Grosch §3.1): the rectangle is
/// subdivided recursively along its longest axis; each cell of every level
/// holds precomputed random points. `n = 2^k` shadow rays take one point
/// from each of the 2^k cells of level k, so a pixel can draw more rays
/// without re-stratifying.
#[derive(Debug, Clone, PartialEq)]
pub struct JitteredGrid {
    /// Points per cell, as (s, t) ∈ [0,1]² over the rectangle, for each level.
    levels: Vec<Vec<[DVec2; POINTS_PER_CELL]>>,
}

/// Random points kept per cell: a pixel picks one of them per cell.
pub(crate) const POINTS_PER_CELL: usize = 8;
/// The finest level: 2^8 = 256 cells, the most shadow rays a pixel can ask.
pub(crate) const MAX_GRID_LEVEL: usize = 8;

impl JitteredGrid {
    /// Builds the grid for a rectangle with sides |u| and |v|, from `seed`.
    pub fn new(u_len: f64, v_len: f64, seed: u64) -> JitteredGrid {
        let mut levels = Vec::with_capacity(MAX_GRID_LEVEL + 1);
        // Cells as (s0, s1, t0, t1); each level splits every cell across its longer side.
        let mut cells = vec![(0.0, 1.0, 0.0, 1.0)];
        let mut state = seed;
        for _level in 0..=MAX_GRID_LEVEL {
            let points = cells
                .iter()
                .map(|&(s0, s1, t0, t1)| {
                    std::array::from_fn(|_| {
                        let (a, b) = (unit_random(&mut state), unit_random(&mut state));
                        DVec2::new(s0 + a * (s1 - s0), t0 + b * (t1 - t0))
                    })
                })
                .collect();
            levels.push(points);
            cells = cells
                .iter()
                .flat_map(|&(s0, s1, t0, t1)| {
                    if (s1 - s0) * u_len >= (t1 - t0) * v_len {
                        let m = 0.5 * (s0 + s1);
                        [(s0, m, t0, t1), (m, s1, t0, t1)]
                    } else {
                        let m = 0.5 * (t0 + t1);
                        [(s0, s1, t0, m), (s0, s1, m, t1)]
                    }
                })
                .collect();
        }
        JitteredGrid { levels }
    }

    /// The `2^level` sample positions (s, t) a pixel with `seed` uses.
    pub fn samples(&self, level: usize, seed: u64) -> impl Iterator<Item = DVec2> + '_ {
        let level = level.min(MAX_GRID_LEVEL);
        self.levels[level]
            .iter()
            .enumerate()
            .map(move |(cell, points)| {
                points[(hash2(seed, cell as u64) % POINTS_PER_CELL as u64) as usize]
            })
    }
}

/// A light ready for rendering.
#[derive(Debug, Clone, PartialEq)]
pub struct LightSource {
    pub name: String,
    pub real: bool,
    pub scale: f64,
    pub position: DVec3,
    pub emitter: Emitter,
    pub distribution: Distribution,
    /// Shadow-ray targets of a rect light; `None` for a point light (one ray).
    pub grid: Option<JitteredGrid>,
}

/// The direct light a point receives from one light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectLight {
    /// Unoccluded irradiance (the geometry term), before the light's scale.
    pub unoccluded: DVec3,
    /// Fraction of it that arrives, in [0, 1] (contribution-weighted over shadow rays).
    pub visibility: f64,
    /// Shadow rays cast.
    pub rays: u32,
}

/// For tests: a 0.6 m square Lambertian panel at `position`, facing down.
#[cfg(test)]
pub(crate) fn test_panel(position: DVec3) -> LightSource {
    let (u, v) = (DVec3::new(0.6, 0.0, 0.0), DVec3::new(0.0, 0.0, 0.6));
    LightSource {
        name: "panel".into(),
        real: false,
        scale: 1.0,
        position,
        emitter: Emitter::Rect {
            u,
            v,
            normal: u.cross(v).normalize(),
        },
        distribution: Distribution::Lambertian {
            normal: DVec3::NEG_Y,
            rgb: DVec3::splat(4.0),
        },
        grid: Some(JitteredGrid::new(0.6, 0.6, 1)),
    }
}

/// For tests: [`test_panel`]'s light from a point at `position`.
#[cfg(test)]
pub(crate) fn test_spot(position: DVec3) -> LightSource {
    LightSource {
        emitter: Emitter::Point,
        grid: None,
        ..test_panel(position)
    }
}

impl LightSource {
    /// The emitting shape's corners: the point itself, or the rectangle's four.
    pub fn corners(&self) -> Vec<DVec3> {
        self.rect_corners()
            .map_or_else(|| vec![self.position], |c| c.to_vec())
    }

    /// A rect light's four corners (None for a point light).
    pub(crate) fn rect_corners(&self) -> Option<[DVec3; 4]> {
        match self.emitter {
            Emitter::Point => None,
            Emitter::Rect { u, v, .. } => Some(rect_quad(self.position, u, v)),
        }
    }

    /// A ball around the emitting shape: its centre and radius.
    pub fn ball(&self) -> (DVec3, f64) {
        match self.emitter {
            Emitter::Point => (self.position, 0.0),
            Emitter::Rect { u, v, .. } => (self.position, 0.5 * (u.length() + v.length())),
        }
    }

    /// The box around the emitting shape.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        crate::geometry::bounds(self.corners())
    }

    /// Prepares light `index` of `scene`. A light whose position is to be
    /// estimated from shadows, or whose intensity is to be reconstructed,
    /// must be resolved first; here it is an error naming the key.
    pub fn from_scene(scene: &Scene, index: usize) -> Result<LightSource> {
        let l: &Light = &scene.lights[index];
        let key = |k: &str| format!("light[{index}].{k}");
        let position = match &l.position {
            LightPosition::Known(p) => *p,
            LightPosition::FromShadows(c) => {
                crate::shadows::position_from_shadows(c)
                    .map_err(|m| Error::key(&scene.file, key("position"), m))?
                    .position
            }
        };
        let emitter = match l.shape {
            LightShape::Point => Emitter::Point,
            LightShape::Rect { u, v } => Emitter::Rect {
                u,
                v,
                normal: u.cross(v).normalize(),
            },
        };
        let distribution = match &l.intensity {
            Intensity::Uniform(rgb) => Distribution::Uniform(*rgb),
            Intensity::Lambertian { normal, rgb } => Distribution::Lambertian {
                normal: *normal,
                rgb: *rgb,
            },
            Intensity::Spot {
                direction,
                rgb,
                beam_deg,
                cutoff_deg,
            } => Distribution::Spot {
                axis: *direction,
                rgb: *rgb,
                beam: beam_deg.to_radians(),
                cutoff: cutoff_deg.to_radians(),
            },
            Intensity::Ies {
                profile,
                rgb,
                direction,
                reference,
                ..
            } => {
                // LM-63 tilt: lamp output at the luminaire's tilt from its
                // photometric position (photometric zero pointing down, -y).
                let tilt = profile.tilt.as_ref().map_or(1.0, |t| {
                    t.factor(direction.angle_between(DVec3::NEG_Y).to_degrees())
                });
                Distribution::Ies {
                    profile: Box::new(profile.clone()),
                    axis: *direction,
                    reference: *reference,
                    rgb: *rgb * tilt,
                }
            }
            Intensity::Reconstruct => {
                return Err(Error::key(
                    &scene.file,
                    key("intensity"),
                    "\"reconstruct\": the goniometric must be recovered from the photo before this light can be used (arlux gonio, render and radiosity do it)",
                ));
            }
        };
        let grid = match emitter {
            Emitter::Point => None,
            Emitter::Rect { u, v, .. } => Some(JitteredGrid::new(
                u.length(),
                v.length(),
                hash2(0x5eed_11c4, index as u64),
            )),
        };
        Ok(LightSource {
            name: l.name.clone(),
            real: l.real,
            scale: l.scale,
            position,
            emitter,
            distribution,
            grid,
        })
    }

    /// All lights of a scene, on or off, in scene order.
    pub fn all(scene: &Scene) -> Result<Vec<LightSource>> {
        (0..scene.lights.len())
            .map(|i| LightSource::from_scene(scene, i))
            .collect()
    }

    pub(crate) fn is_on(&self) -> bool {
        self.scale > 0.0
    }

    /// The light's scale in the photograph: real lights as photographed
    /// (1), virtual lights off (0). Estimation and the "without" render use
    /// this, whatever scale the scene or a variant sets.
    pub fn photo_scale(&self) -> f64 {
        if self.real { 1.0 } else { 0.0 }
    }

    /// The light's colour: every distribution is this RGB times a scalar
    /// (so per-point terms can be kept as one number).
    pub fn colour(&self) -> DVec3 {
        match &self.distribution {
            Distribution::Uniform(rgb) => *rgb,
            Distribution::Lambertian { rgb, .. }
            | Distribution::Spot { rgb, .. }
            | Distribution::Ies { rgb, .. } => *rgb,
        }
    }

    /// The world point of grid sample (s, t); the centre for a point light.
    pub(crate) fn point_at(&self, st: DVec2) -> DVec3 {
        match self.emitter {
            Emitter::Point => self.position,
            Emitter::Rect { u, v, .. } => self.position + u * (st.x - 0.5) + v * (st.y - 0.5),
        }
    }

    /// Intensity of the whole light towards `d` (unit, away from the
    /// light), zero behind a rect's emitting side; before `scale`.
    pub fn intensity(&self, d: DVec3) -> DVec3 {
        if let Emitter::Rect { normal, .. } = self.emitter
            && d.dot(normal) <= 0.0
        {
            return DVec3::ZERO;
        }
        self.distribution.intensity(d)
    }

    /// Unoccluded irradiance at `x` (two-sided surface with unit normal `n`),
    /// before `scale`. Point lights: I·|cosθ|/d². Lambertian rects: exact,
    /// radiance × π × the point-to-polygon form factor. Other rects: the
    /// mean of I/N·|cosθ|/d² over the 16 cell centres of grid level 4.
    pub(crate) fn unoccluded_irradiance(&self, x: DVec3, n: DVec3) -> DVec3 {
        match self.emitter {
            Emitter::Point => {
                point_contribution(self.position, x, n, |d| self.distribution.intensity(d))
            }
            Emitter::Rect { u, v, normal } => {
                if (x - self.position).dot(normal) <= 0.0 {
                    return DVec3::ZERO;
                }
                if let Distribution::Lambertian { rgb, .. } = self.distribution {
                    let area = u.cross(v).length();
                    return rgb / area
                        * std::f64::consts::PI
                        * polygon_form_factor(x, n, &rect_quad(self.position, u, v));
                }
                let mut sum = DVec3::ZERO;
                let k = 4;
                for i in 0..k {
                    for j in 0..k {
                        let st =
                            DVec2::new((i as f64 + 0.5) / k as f64, (j as f64 + 0.5) / k as f64);
                        sum += point_contribution(self.point_at(st), x, n, |d| self.intensity(d));
                    }
                }
                sum / (k * k) as f64
            }
        }
    }

    /// Direct light at `x` with normal `n`: the unoccluded irradiance and
    /// the visibility from `2^level` shadow rays to the grid (one for a point
    /// light), blocked by geometry of `layer`. `seed` picks the grid points.
    pub fn direct(
        &self,
        tracer: &Tracer,
        layer: Layer,
        x: DVec3,
        n: DVec3,
        level: usize,
        seed: u64,
    ) -> DirectLight {
        self.direct_by(x, n, level, seed, |_, rays, blocked| match rays {
            [one] if self.grid.is_none() => blocked[0] = tracer.occluded(one, layer),
            _ => tracer.occluded_batch(rays, layer, blocked),
        })
    }

    /// [`LightSource::direct`], with `occluded(targets, rays, blocked)`
    /// saying which rays (to those points of the light) are blocked; the
    /// rays are counted as cast all the same.
    pub(crate) fn direct_by(
        &self,
        x: DVec3,
        n: DVec3,
        level: usize,
        seed: u64,
        occluded: impl FnOnce(&[DVec3], &[TraceRay], &mut [bool]),
    ) -> DirectLight {
        let unoccluded = self.unoccluded_irradiance(x, n);
        if unoccluded == DVec3::ZERO {
            return DirectLight {
                unoccluded,
                visibility: 0.0,
                rays: 0,
            };
        }
        let origin = offset_origin(x, n, self.position);
        match &self.grid {
            None => {
                let mut blocked = [false];
                occluded(
                    &[self.position],
                    &[segment(origin, self.position)],
                    &mut blocked,
                );
                DirectLight {
                    unoccluded,
                    visibility: if blocked[0] { 0.0 } else { 1.0 },
                    rays: 1,
                }
            }
            Some(grid) => {
                let targets: Vec<DVec3> = grid
                    .samples(level, seed)
                    .map(|st| self.point_at(st))
                    .collect();
                let rays: Vec<TraceRay> = targets.iter().map(|&t| segment(origin, t)).collect();
                let mut blocked = vec![false; rays.len()];
                occluded(&targets, &rays, &mut blocked);
                let visibility = self.visibility_of(x, n, &targets, &blocked);
                DirectLight {
                    unoccluded,
                    visibility,
                    rays: rays.len() as u32,
                }
            }
        }
    }
}

impl LightSource {
    /// The fraction of this light reaching `x` (normal `n`) when the rays
    /// to `targets` (points of it) are `blocked` as given: each ray
    /// weighted by its sample's contribution, so that a point near the
    /// light is not dominated by far samples.
    pub(crate) fn visibility_of(
        &self,
        x: DVec3,
        n: DVec3,
        targets: &[DVec3],
        blocked: &[bool],
    ) -> f64 {
        let (mut seen, mut total) = (0.0, 0.0);
        for (t, b) in targets.iter().zip(blocked) {
            let w = point_contribution(*t, x, n, |d| self.intensity(d)).element_sum();
            total += w;
            if !b {
                seen += w;
            }
        }
        if total > 0.0 { seen / total } else { 0.0 }
    }
}

/// The corners of the rectangle centre ± u/2 ± v/2, in order around it.
fn rect_quad(c: DVec3, u: DVec3, v: DVec3) -> [DVec3; 4] {
    [
        c - 0.5 * u - 0.5 * v,
        c + 0.5 * u - 0.5 * v,
        c + 0.5 * u + 0.5 * v,
        c - 0.5 * u + 0.5 * v,
    ]
}

/// Irradiance at `x` (normal `n`, two-sided) from a point emitter at `p`
/// with intensity function `intensity(direction from p)`: I·|cosθ|/d².
pub(crate) fn point_contribution(
    p: DVec3,
    x: DVec3,
    n: DVec3,
    intensity: impl Fn(DVec3) -> DVec3,
) -> DVec3 {
    let d = x - p;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return DVec3::ZERO;
    }
    let dir = d / dist2.sqrt();
    intensity(dir) * (dir.dot(n).abs() / dist2)
}

/// Lifts a ray origin off its surface, to the side facing `towards`, by an
/// amount that grows with the coordinates' size (f32 tracing precision).
pub fn offset_origin(x: DVec3, n: DVec3, towards: DVec3) -> DVec3 {
    let side = if (towards - x).dot(n) >= 0.0 { n } else { -n };
    x + side * origin_lift(x)
}

/// How far [`offset_origin`] lifts a ray's origin at `x`.
pub fn origin_lift(x: DVec3) -> f64 {
    1e-5 + 2e-6 * x.abs().max_element()
}

/// The tracer segment from `a` to `b`, stopping a little short of `b`.
pub fn segment(a: DVec3, b: DVec3) -> TraceRay {
    let len = (b - a).length().max(1e-12);
    let eps = (1e-5 / len).min(0.25) as f32;
    TraceRay {
        origin: a.as_vec3(),
        direction: (b - a).as_vec3(),
        tnear: 0.0,
        tfar: 1.0 - eps,
    }
}

#[cfg(test)]
mod tests;
