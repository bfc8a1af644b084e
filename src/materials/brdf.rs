//! The glTF 2.0 metallic-roughness BRDF (glTF 2.0 specification, Appendix
//! B): a Lambertian base under a dielectric GGX coat (F0 = 0.04) mixed with
//! a GGX metal whose F0 is the base colour, single scattering, Schlick
//! Fresnel, height-correlated Smith visibility. Sampling draws the GGX
//! distribution of visible normals (Heitz 2018), whose weight f·cos/pdf is
//! F·G2/G1 and never exceeds F.
//!
//! Vectors are in the shading frame's world coordinates: `n` the unit
//! shading normal, `v` towards the viewer, `l` towards the light, all unit.
//! The BRDF is one-sided: zero unless n·v > 0 and n·l > 0.

use glam::DVec3;

/// The smallest GGX α (= roughness²): below it a highlight is narrower
/// than any sample finds and its peak overflows f32 (glTF viewers clamp
/// the same way).
pub const MIN_ALPHA: f64 = 1e-3;

/// A material at one surface point, its textures resolved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lobes {
    /// Linear base colour.
    pub base: DVec3,
    pub metallic: f64,
    pub roughness: f64,
}

impl Lobes {
    /// GGX α.
    pub fn alpha(&self) -> f64 {
        (self.roughness * self.roughness).max(MIN_ALPHA)
    }

    /// The Fresnel factor of the specular lobe at v·h (dielectric and metal mixed).
    pub fn fresnel(&self, v_dot_h: f64) -> DVec3 {
        let fw = (1.0 - v_dot_h.abs()).clamp(0.0, 1.0).powi(5);
        let dielectric = 0.04 + 0.96 * fw;
        let metal = self.base + (DVec3::ONE - self.base) * fw;
        DVec3::splat(dielectric * (1.0 - self.metallic)) + metal * self.metallic
    }

    /// The diffuse colour at v·h: what the dielectric's coat lets through.
    pub fn diffuse(&self, v_dot_h: f64) -> DVec3 {
        let fw = (1.0 - v_dot_h.abs()).clamp(0.0, 1.0).powi(5);
        self.base * ((1.0 - self.metallic) * (1.0 - (0.04 + 0.96 * fw)))
    }

    /// The diffuse colour averaged over light arriving from the whole
    /// hemisphere (cosine-weighted) for a view at n·v = `n_dot_v`: what
    /// the diffuse part reflects of uniform (indirect) light. The coat lets
    /// through 1 − F(v·h) for each light direction's half vector, not
    /// 1 − F(n·v): at a grazing view most half vectors still lie near the
    /// view, so the diffuse part does not vanish at a silhouette.
    pub fn diffuse_mean(&self, n_dot_v: f64) -> DVec3 {
        self.base * ((1.0 - self.metallic) * coat_transmission(n_dot_v))
    }

    /// The BRDF f(v, l), split into its diffuse and specular parts.
    pub fn eval(&self, n: DVec3, v: DVec3, l: DVec3) -> (DVec3, DVec3) {
        let (nv, nl) = (n.dot(v), n.dot(l));
        if nv <= 0.0 || nl <= 0.0 {
            return (DVec3::ZERO, DVec3::ZERO);
        }
        let h = (v + l).normalize_or_zero();
        if h == DVec3::ZERO {
            return (DVec3::ZERO, DVec3::ZERO);
        }
        let vh = v.dot(h);
        let a = self.alpha();
        let spec = self.fresnel(vh) * (ggx_d(n.dot(h), a) * visibility(nv, nl, a));
        (self.diffuse(vh) / std::f64::consts::PI, spec)
    }

    /// The specular lobe's sample for uniform numbers (u1, u2): the
    /// direction l, its pdf over solid angle, and its weight
    /// f_spec·(n·l)/pdf. None when the sample leaves the hemisphere.
    pub fn sample_specular(
        &self,
        n: DVec3,
        v: DVec3,
        u1: f64,
        u2: f64,
    ) -> Option<(DVec3, f64, DVec3)> {
        let nv = n.dot(v);
        if nv <= 0.0 {
            return None;
        }
        let a = self.alpha();
        let (t, b) = frame(n);
        let local_v = DVec3::new(v.dot(t), v.dot(b), nv);
        let m = sample_vndf(local_v, a, u1, u2);
        let h = (t * m.x + b * m.y + n * m.z).normalize();
        let vh = v.dot(h);
        let l = 2.0 * vh * h - v;
        let nl = n.dot(l);
        if nl <= 0.0 || vh <= 0.0 {
            return None;
        }
        let pdf = self.specular_pdf(n, v, l);
        let weight = self.fresnel(vh) * (smith_g2(nv, nl, a) / smith_g1(nv, a));
        Some((l, pdf, weight))
    }

    /// The specular sampler's pdf of direction l (over solid angle).
    pub fn specular_pdf(&self, n: DVec3, v: DVec3, l: DVec3) -> f64 {
        let (nv, nl) = (n.dot(v), n.dot(l));
        if nv <= 0.0 || nl <= 0.0 {
            return 0.0;
        }
        let h = (v + l).normalize_or_zero();
        let a = self.alpha();
        // VNDF: G1(v)·max(0, v·h)·D(h)/(n·v), times the reflection's 1/(4 v·h).
        smith_g1(nv, a) * ggx_d(n.dot(h), a) / (4.0 * nv)
    }
}

/// The GGX (Trowbridge-Reitz) normal distribution.
pub fn ggx_d(n_dot_h: f64, a: f64) -> f64 {
    let a2 = a * a;
    let c = n_dot_h * n_dot_h * (a2 - 1.0) + 1.0;
    a2 / (std::f64::consts::PI * c * c)
}

/// Height-correlated Smith visibility G2 / (4 n·l n·v), as glTF writes it.
pub fn visibility(nv: f64, nl: f64, a: f64) -> f64 {
    let a2 = a * a;
    let gv = nl * (a2 + (1.0 - a2) * nv * nv).sqrt();
    let gl = nv * (a2 + (1.0 - a2) * nl * nl).sqrt();
    let s = gv + gl;
    if s > 0.0 { 0.5 / s } else { 0.0 }
}

fn smith_g2(nv: f64, nl: f64, a: f64) -> f64 {
    4.0 * nv * nl * visibility(nv, nl, a)
}

fn smith_g1(nv: f64, a: f64) -> f64 {
    let a2 = a * a;
    2.0 * nv / (nv + (a2 + (1.0 - a2) * nv * nv).sqrt())
}

/// A tangent frame (t, b) for unit n (Duff et al. 2017, branchless).
pub fn frame(n: DVec3) -> (DVec3, DVec3) {
    let s = 1f64.copysign(n.z);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    (
        DVec3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
        DVec3::new(b, s + n.y * n.y * a, -n.y),
    )
}

/// A visible normal of the isotropic GGX distribution α for the local view
/// direction v (z up), by Heitz 2018, "Sampling the GGX Distribution of
/// Visible Normals".
fn sample_vndf(v: DVec3, a: f64, u1: f64, u2: f64) -> DVec3 {
    let vh = DVec3::new(a * v.x, a * v.y, v.z).normalize();
    let len2 = vh.x * vh.x + vh.y * vh.y;
    let t1 = if len2 > 0.0 {
        DVec3::new(-vh.y, vh.x, 0.0) / len2.sqrt()
    } else {
        DVec3::X
    };
    let t2 = vh.cross(t1);
    let r = u1.sqrt();
    let phi = std::f64::consts::TAU * u2;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    DVec3::new(a * nh.x, a * nh.y, nh.z.max(1e-9)).normalize()
}

/// Directional albedo of the whole BRDF for a view at n·v = `mu`: the
/// fraction of uniform light it reflects, by a fixed stratified quadrature
/// (the specular lobe by its own sampler, the diffuse part by cosine cells).
pub fn directional_albedo(lobes: &Lobes, mu: f64, side: usize) -> DVec3 {
    let n = DVec3::Z;
    let mu = mu.clamp(1e-4, 1.0);
    let v = DVec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
    let mut spec = DVec3::ZERO;
    let mut diffuse = DVec3::ZERO;
    let cells = (side * side) as f64;
    for i in 0..side {
        for j in 0..side {
            let (u1, u2) = (
                (i as f64 + 0.5) / side as f64,
                (j as f64 + 0.5) / side as f64,
            );
            if let Some((_, _, w)) = lobes.sample_specular(n, v, u1, u2) {
                spec += w;
            }
            // Cosine-weighted direction: the diffuse part's weight is its colour.
            let (r, phi) = (u1.sqrt(), std::f64::consts::TAU * u2);
            let l = DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).sqrt());
            let h = (v + l).normalize();
            diffuse += lobes.diffuse(v.dot(h));
        }
    }
    (spec + diffuse) / cells
}

/// Hemispherical (bi-hemispherical) albedo: the directional albedo
/// averaged over views weighted by cosine, what a diffuse exchange of
/// light with the room sees of the material.
pub fn hemispherical_albedo(lobes: &Lobes) -> DVec3 {
    // ∫ E(μ) 2μ dμ over 16 midpoint cells of μ².
    let k = 16;
    (0..k)
        .map(|i| directional_albedo(lobes, ((i as f64 + 0.5) / k as f64).sqrt(), 24))
        .sum::<DVec3>()
        / k as f64
}

/// Cells per unit of metallic and of roughness in [`table_albedo`]'s table.
const TABLE_STEPS: usize = 64;

/// [`hemispherical_albedo`] from a table over metallic and roughness,
/// interpolated bilinearly. The albedo is affine in the base colour (the
/// Fresnel term and the diffuse part are), a + b·base per channel, so a
/// cell holds a and b (`albedo_cell`, which its test recomputes). A
/// textured object's patches read it, one material point each: an
/// 80k-triangle asset took 40 s by quadrature.
pub fn table_albedo(lobes: &Lobes) -> DVec3 {
    const S: usize = TABLE_STEPS;
    let table = albedo_table();
    let cell = |i: usize, j: usize| table[i * (S + 1) + j];
    let (m, r) = (
        lobes.metallic.clamp(0.0, 1.0) * S as f64,
        lobes.roughness.clamp(0.0, 1.0) * S as f64,
    );
    let (i, j) = ((m as usize).min(S - 1), (r as usize).min(S - 1));
    let (fm, fr) = (m - i as f64, r - j as f64);
    let mix = |p: (f64, f64), q: (f64, f64), t: f64| (p.0 + (q.0 - p.0) * t, p.1 + (q.1 - p.1) * t);
    let lo = mix(cell(i, j), cell(i, j + 1), fr);
    let hi = mix(cell(i + 1, j), cell(i + 1, j + 1), fr);
    let (a, b) = mix(lo, hi, fm);
    (DVec3::splat(a) + lobes.base.clamp(DVec3::ZERO, DVec3::ONE) * b).clamp(DVec3::ZERO, DVec3::ONE)
}

/// Cell (i, j) of [`table_albedo`]'s table, metallic i / S and roughness
/// j / S: the hemispherical albedo a of a black base and b, what a white
/// base adds (two quadratures of 9,216 samples). What the stored table
/// holds; only its test computes it.
#[cfg(test)]
pub(crate) fn albedo_cell(i: usize, j: usize) -> (f64, f64) {
    const S: usize = TABLE_STEPS;
    let at = |base: f64| {
        hemispherical_albedo(&Lobes {
            base: DVec3::splat(base),
            metallic: i as f64 / S as f64,
            roughness: j as f64 / S as f64,
        })
        .x
    };
    let a = at(0.0);
    (a, at(1.0) - a)
}

/// [`table_albedo`]'s cells, row by row of metallic, as stored in
/// `albedo_table.bin`: each cell's a and b as little-endian f64 bits.
/// Stored, not computed at first use: the whole table is 155 M BRDF
/// samples, about 10 s of CPU, and a textured object's patches read cells
/// all over it (the cells the 30k-triangle prop read took 75 ms of its
/// render). A test checks that every stored cell is what `albedo_cell`
/// computes, bit for bit, and writes the file again when asked to.
pub(crate) const ALBEDO_TABLE_FILE: &[u8] = include_bytes!("albedo_table.bin");

/// The stored table, decoded once.
fn albedo_table() -> &'static [(f64, f64)] {
    use std::sync::OnceLock;
    static TABLE: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    TABLE.get_or_init(|| decode_albedo_table(ALBEDO_TABLE_FILE))
}

/// Cells from the stored bytes.
pub(crate) fn decode_albedo_table(bytes: &[u8]) -> Vec<(f64, f64)> {
    let value = |c: &[u8]| f64::from_le_bytes(c.try_into().expect("eight bytes"));
    (bytes.chunks_exact(16))
        .map(|c| (value(&c[..8]), value(&c[8..])))
        .collect()
}

// A stored table of another size fails the build, not a render.
const _: () = assert!(ALBEDO_TABLE_FILE.len() == ALBEDO_TABLE_CELLS * 16);

/// Cells in [`table_albedo`]'s table.
pub(crate) const ALBEDO_TABLE_CELLS: usize = (TABLE_STEPS + 1) * (TABLE_STEPS + 1);

/// Views per unit of n·v in [`coat_transmission`]'s table.
const COAT_STEPS: usize = 64;

/// The cosine-weighted mean over light directions of 1 − F(v·h) for a
/// dielectric coat (F₀ = 0.04), at n·v = `mu`: a table over n·v, filled
/// once by a 48 × 48 stratified quadrature per entry, read linearly.
fn coat_transmission(mu: f64) -> f64 {
    use std::sync::OnceLock;
    static TABLE: OnceLock<Vec<f64>> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        (0..=COAT_STEPS)
            .map(|i| coat_quadrature(i as f64 / COAT_STEPS as f64, 48))
            .collect()
    });
    let x = mu.clamp(0.0, 1.0) * COAT_STEPS as f64;
    let i = (x as usize).min(COAT_STEPS - 1);
    table[i] + (table[i + 1] - table[i]) * (x - i as f64)
}

/// The mean over cosine-distributed light directions of 1 − F(v·h) (F₀ =
/// 0.04) at n·v = `mu`, by a `side` × `side` stratified quadrature.
pub(crate) fn coat_quadrature(mu: f64, side: usize) -> f64 {
    let mu = mu.max(1e-4);
    let v = DVec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
    let mut sum = 0.0;
    for a in 0..side {
        for b in 0..side {
            let (u1, u2) = (
                (a as f64 + 0.5) / side as f64,
                (b as f64 + 0.5) / side as f64,
            );
            let (r, phi) = (u1.sqrt(), std::f64::consts::TAU * u2);
            let l = DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).sqrt());
            let vh = v.dot((v + l).normalize()).abs();
            sum += 1.0 - (0.04 + 0.96 * (1.0 - vh).clamp(0.0, 1.0).powi(5));
        }
    }
    sum / (side * side) as f64
}
