//! The photo re-projected into each root polygon's own texture, and the
//! texels the camera does not see filled from those it does.

use super::*;

/// One root polygon's texture over the part of it the camera sees.
#[derive(Debug, Clone)]
pub(super) struct Texture {
    /// Parameter range covered: texel (i, j) is centred at
    /// (s0 + (i + ½)·ds, t0 + (j + ½)·dt).
    pub(super) s0: f64,
    pub(super) t0: f64,
    pub(super) ds: f64,
    pub(super) dt: f64,
    pub(super) nu: usize,
    pub(super) nv: usize,
    pub(super) texels: Vec<Vec3>,
}

impl Texture {
    pub(super) fn texel_of(&self, st: DVec2) -> usize {
        let i = (((st.x - self.s0) / self.ds).floor().max(0.0) as usize).min(self.nu - 1);
        let j = (((st.y - self.t0) / self.dt).floor().max(0.0) as usize).min(self.nv - 1);
        j * self.nu + i
    }
}

/// The photo re-projected into each seen root polygon, texel by texel, at
/// `texels_per_pixel` per pixel footprint (over the part of the root the
/// camera sees): a texel takes the pixel it projects into when that
/// pixel's centre sees the same polygon; each texel is then multiplied by
/// `modulation(root, x)`. A texel the photo does not show takes its
/// nearest shown texel's value.
pub(super) fn build_textures(
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
pub(super) fn fill_unknown(tex: &mut Texture, known: &mut [bool]) {
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
