use super::*;

/// The table's node grid.
#[derive(Debug, Clone, Copy)]
pub(super) struct Grid {
    pub(super) nv: usize,
    pub(super) nh: usize,
    pub(super) dv: f64,
    pub(super) dh: f64,
}

impl Grid {
    pub(super) fn new(settings: &GonioSettings) -> Grid {
        let nv = (180.0 / settings.vertical_step_deg).round().max(2.0) as usize + 1;
        let nh = (360.0 / settings.horizontal_step_deg).round().max(4.0) as usize;
        Grid {
            nv,
            nh,
            dv: 180.0 / (nv - 1) as f64,
            dh: 360.0 / nh as f64,
        }
    }

    pub(super) fn len(&self) -> usize {
        self.nv * self.nh
    }

    pub(super) fn index(&self, hi: usize, vi: usize) -> usize {
        hi * self.nv + vi
    }

    /// The four nodes around (v, h) with bilinear weights.
    pub(super) fn corners(&self, v: f64, h: f64) -> [(usize, f64); 4] {
        let fv = (v / self.dv).clamp(0.0, (self.nv - 1) as f64);
        let vi = (fv.floor() as usize).min(self.nv - 2);
        let tv = fv - vi as f64;
        let fh = h.rem_euclid(360.0) / self.dh;
        let hi = (fh.floor() as usize) % self.nh;
        let th = fh - fh.floor();
        let hj = (hi + 1) % self.nh;
        [
            (self.index(hi, vi), (1.0 - th) * (1.0 - tv)),
            (self.index(hi, vi + 1), (1.0 - th) * tv),
            (self.index(hj, vi), th * (1.0 - tv)),
            (self.index(hj, vi + 1), th * tv),
        ]
    }

    pub(super) fn nearest(&self, v: f64, h: f64) -> usize {
        let vi = ((v / self.dv).round() as usize).min(self.nv - 1);
        let hi = ((h.rem_euclid(360.0) / self.dh).round() as usize) % self.nh;
        self.index(hi, vi)
    }

    /// Solid angle a node stands for.
    pub(super) fn solid_angle(&self, vi: usize) -> f64 {
        let rad = std::f64::consts::PI / 180.0;
        let lo = ((vi as f64 - 0.5) * self.dv).max(0.0) * rad;
        let hi = ((vi as f64 + 0.5) * self.dv).min(180.0) * rad;
        (lo.cos() - hi.cos()) * self.dh * rad
    }

    /// |∇I| per radian at each known node (mean channel), from differences
    /// with its known neighbours; 0 elsewhere.
    pub(super) fn slopes(&self, values: &[DVec3], known: &[bool]) -> Vec<f64> {
        let rad = std::f64::consts::PI / 180.0;
        let value = |k: usize| values[k].element_sum() / 3.0;
        (0..self.len())
            .map(|k| {
                if !known[k] {
                    return 0.0;
                }
                let (hi, vi) = (k / self.nv, k % self.nv);
                let mut slope: f64 = 0.0;
                let mut along = |j: usize, step: f64| {
                    if known[j] && step > 1e-9 {
                        slope = slope.max((value(j) - value(k)).abs() / step);
                    }
                };
                if vi > 0 {
                    along(self.index(hi, vi - 1), self.dv * rad);
                }
                if vi + 1 < self.nv {
                    along(self.index(hi, vi + 1), self.dv * rad);
                }
                let across = self.dh * rad * (vi as f64 * self.dv * rad).sin();
                along(self.index((hi + 1) % self.nh, vi), across);
                along(self.index((hi + self.nh - 1) % self.nh, vi), across);
                slope
            })
            .collect()
    }

    /// Angular distance (radians) from every node to the nearest node in
    /// `sources`, along the grid (Dijkstra with 8 neighbours), and which
    /// source that is.
    pub(super) fn distance_field(&self, sources: &[bool]) -> (Vec<f64>, Vec<usize>) {
        use std::cmp::Reverse;
        use std::collections::BinaryHeap;
        let rad = std::f64::consts::PI / 180.0;
        let n = self.len();
        let mut dist = vec![f64::INFINITY; n];
        let mut from = vec![usize::MAX; n];
        let mut heap = BinaryHeap::new();
        for k in 0..n {
            if sources[k] {
                dist[k] = 0.0;
                from[k] = k;
                heap.push(Reverse((0u64, k)));
            }
        }
        // Distances as integer nanoradians keep the heap's ordering total.
        let key = |d: f64| (d * 1e9) as u64;
        while let Some(Reverse((dk, k))) = heap.pop() {
            if dk > key(dist[k]) {
                continue;
            }
            let (hi, vi) = (k / self.nv, k % self.nv);
            for (dh, dv) in [
                (-1i64, 0i64),
                (1, 0),
                (0, -1),
                (0, 1),
                (-1, -1),
                (-1, 1),
                (1, -1),
                (1, 1),
            ] {
                let vj = vi as i64 + dv;
                if vj < 0 || vj >= self.nv as i64 {
                    continue;
                }
                let hj = (hi as i64 + dh).rem_euclid(self.nh as i64) as usize;
                let j = self.index(hj, vj as usize);
                let mid = (vi as f64 + 0.5 * dv as f64) * self.dv * rad;
                let a = dv as f64 * self.dv * rad;
                let b = dh as f64 * self.dh * rad * mid.sin();
                let step = (a * a + b * b).sqrt();
                let d = dist[k] + step;
                if d < dist[j] {
                    dist[j] = d;
                    from[j] = from[k];
                    heap.push(Reverse((key(d), j)));
                }
            }
        }
        (dist, from)
    }
}

/// Least-squares accumulators per node: I = Σ w·g·y / Σ w·g².
#[derive(Clone)]
pub(super) struct Fit {
    pub(super) num: Vec<DVec3>,
    pub(super) den: Vec<f64>,
    /// Σ bilinear weight: how many samples' worth constrain the node.
    pub(super) weight: Vec<f64>,
    /// Σ w·g and Σ w·(all the light the samples received, mean channel):
    /// with the fitted I, the share of the samples' light the node explains.
    pub(super) g_sum: Vec<f64>,
    pub(super) light: Vec<f64>,
}

impl Fit {
    pub(super) fn new(n: usize) -> Fit {
        Fit {
            num: vec![DVec3::ZERO; n],
            den: vec![0.0; n],
            weight: vec![0.0; n],
            g_sum: vec![0.0; n],
            light: vec![0.0; n],
        }
    }

    /// A sample: `y` = g·I by EQ1, `total` the irradiance it received from everything.
    pub(super) fn add(&mut self, grid: &Grid, s: &Sample, y: DVec3, total: DVec3) {
        for (k, w) in grid.corners(s.v, s.h) {
            if w > 0.0 {
                self.num[k] += y * (w * s.g);
                self.den[k] += w * s.g * s.g;
                self.weight[k] += w;
                self.g_sum[k] += w * s.g;
                self.light[k] += w * total.element_sum() / 3.0;
            }
        }
    }

    pub(super) fn known(&self) -> Vec<bool> {
        self.den.iter().map(|&d| d > 0.0).collect()
    }

    /// The fitted table, with a node that explains less than `min_share`
    /// of the light its samples received set to zero: there the light's
    /// part is below what the other terms are known to, so the photo says
    /// it sends (next to) nothing that way.
    pub(super) fn values_above(&self, min_share: f64) -> Vec<DVec3> {
        let values = self.values();
        (0..values.len())
            .map(|k| {
                if values[k].element_sum() / 3.0 * self.g_sum[k] >= min_share * self.light[k] {
                    values[k]
                } else {
                    DVec3::ZERO
                }
            })
            .collect()
    }

    /// Nodes constrained by at least `samples` samples' worth of weight.
    pub(super) fn well_known(&self, samples: f64) -> Vec<bool> {
        self.weight.iter().map(|&w| w >= samples).collect()
    }

    pub(super) fn values(&self) -> Vec<DVec3> {
        self.num
            .iter()
            .zip(&self.den)
            .map(|(n, &d)| {
                if d > 0.0 {
                    (*n / d).max(DVec3::ZERO)
                } else {
                    DVec3::ZERO
                }
            })
            .collect()
    }
}

/// The intensity a sample sees from the table: bilinear where its four
/// nodes are known (angle 0), else the nearest known node's carried to it
/// along the table's slope there (to first order: at a beam's edge the
/// nearest known direction is the brighter one), with the angle to it.
pub(super) fn nearby_intensity(
    grid: &Grid,
    s: &Sample,
    values: &[DVec3],
    known: &[bool],
    dist: &[f64],
    from: &[usize],
) -> Option<(DVec3, f64)> {
    let corners = grid.corners(s.v, s.h);
    if corners.iter().all(|&(k, w)| w == 0.0 || known[k]) {
        return Some((corners.iter().map(|&(k, w)| values[k] * w).sum(), 0.0));
    }
    let k = grid.nearest(s.v, s.h);
    let src = from[k];
    if src == usize::MAX {
        return None;
    }
    // First order from the source node: its gradient from known neighbours.
    let (hi, vi) = (src / grid.nv, src % grid.nv);
    let diff = |a: Option<usize>, b: Option<usize>, step: f64| -> DVec3 {
        match (a.filter(|&j| known[j]), b.filter(|&j| known[j])) {
            (Some(a), Some(b)) => (values[a] - values[b]) / (2.0 * step),
            (Some(a), None) => (values[a] - values[src]) / step,
            (None, Some(b)) => (values[src] - values[b]) / step,
            (None, None) => DVec3::ZERO,
        }
    };
    let up = (vi + 1 < grid.nv).then(|| grid.index(hi, vi + 1));
    let down = (vi > 0).then(|| grid.index(hi, vi - 1));
    let d_v = diff(up, down, grid.dv);
    let d_h = diff(
        Some(grid.index((hi + 1) % grid.nh, vi)),
        Some(grid.index((hi + grid.nh - 1) % grid.nh, vi)),
        grid.dh,
    );
    let dv = s.v - vi as f64 * grid.dv;
    let dh = (s.h - hi as f64 * grid.dh + 180.0).rem_euclid(360.0) - 180.0;
    // Falling is followed to zero; rising is not trusted beyond the source
    // (a peak may lie between), so the value stays the source's there.
    let first = values[src] + d_v * dv + d_h * dh;
    let v = first.clamp(DVec3::ZERO, values[src].max(DVec3::ZERO));
    Some((v, dist[k]))
}
