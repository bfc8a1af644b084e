//! Lambert's contour formula: the exact unoccluded form factor from a
//! point to a planar convex polygon, at one point or at several at once.

use glam::DVec3;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// The unoccluded form factor from a differential area at `x` with unit
/// normal `n` to a planar convex polygon (Lambert's formula), two-sided at
/// `x`: the parts of the polygon on either side of the tangent plane both
/// count. Finite for any x off the polygon; at most 1. Polygons have at most
/// six corners.
pub fn polygon_form_factor(x: DVec3, n: DVec3, polygon: &[DVec3]) -> f64 {
    polygon_form_factor_sided(x, n, polygon, true)
}

/// [`polygon_form_factor`], with `two_sided` false counting only the part
/// of the polygon on the side `n` points to.
pub fn polygon_form_factor_sided(x: DVec3, n: DVec3, polygon: &[DVec3], two_sided: bool) -> f64 {
    debug_assert!(polygon.len() <= 6);
    let (mut above, mut below) = (false, false);
    for p in polygon {
        let s = (*p - x).dot(n);
        above |= s > 0.0;
        below |= s < 0.0;
    }
    let mut total = 0.0;
    let mut buf = [DVec3::ZERO; 8];
    for (side, present) in [(1.0, above), (-1.0, below && two_sided)] {
        if !present {
            continue;
        }
        let clipped: &[DVec3] = if above && below {
            let k = clip_to_halfspace(polygon, x, n * side, &mut buf);
            &buf[..k]
        } else {
            polygon
        };
        if clipped.len() < 3 {
            continue;
        }
        let mut sum = 0.0;
        for k in 0..clipped.len() {
            let a = clipped[k] - x;
            let b = clipped[(k + 1) % clipped.len()] - x;
            let c = a.cross(b);
            let cl = c.length();
            if cl < 1e-300 {
                continue;
            }
            sum += angle_atan2(cl, a.dot(b)) * c.dot(n) / cl;
        }
        total += (sum / (2.0 * std::f64::consts::PI)).abs();
    }
    total.min(1.0)
}

/// Cephes' `atan` on |t| ≤ 0.66: P/Q and the bits π/2 loses in f64.
const P: [f64; 5] = [
    -8.750_608_600_031_904e-1,
    -1.615_753_718_733_365_2e1,
    -7.500_855_792_314_705e1,
    -1.228_866_684_490_136_1e2,
    -6.485_021_904_942_025e1,
];
const Q: [f64; 5] = [
    2.485_846_490_142_306_2e1,
    1.650_270_098_316_988_5e2,
    4.328_810_604_912_902_7e2,
    4.853_903_996_359_137e2,
    1.945_506_571_482_614e2,
];
const MOREBITS: f64 = 6.123_233_995_736_766e-17;
const TAN_3PI_8: f64 = 2.414_213_562_373_095;

/// atan2(y, x) for y ≥ 0: the angle in [0, π] (Cephes' `atan`, accurate
/// to about 2 units in the last place). The polygon form factors sum four
/// such angles each, and glibc's `atan2` saves and restores the rounding
/// mode on every call: it took about half of their time.
pub(super) fn angle_atan2(y: f64, x: f64) -> f64 {
    debug_assert!(y >= 0.0);
    let ax = x.abs();
    if ax == 0.0 {
        return if y == 0.0 { 0.0 } else { FRAC_PI_2 };
    }
    // atan(y / |x|), reduced to |t| ≤ 0.66.
    let (base, t, more) = if y > TAN_3PI_8 * ax {
        (FRAC_PI_2, -ax / y, MOREBITS)
    } else if y <= 0.66 * ax {
        (0.0, y / ax, 0.0)
    } else {
        (FRAC_PI_4, (y - ax) / (y + ax), 0.5 * MOREBITS)
    };
    let z = t * t;
    let p = (((P[0] * z + P[1]) * z + P[2]) * z + P[3]) * z + P[4];
    let q = ((((z + Q[0]) * z + Q[1]) * z + Q[2]) * z + Q[3]) * z + Q[4];
    let a = base + (t * (z * p / q) + t + more);
    if x < 0.0 { PI - a } else { a }
}

/// Writes into `out` the part of a convex polygon where (p − x)·m ≥ 0
/// (Sutherland-Hodgman) and returns its corner count.
fn clip_to_halfspace(polygon: &[DVec3], x: DVec3, m: DVec3, out: &mut [DVec3; 8]) -> usize {
    let mut len = 0;
    for k in 0..polygon.len() {
        let (p, q) = (polygon[k], polygon[(k + 1) % polygon.len()]);
        let (dp, dq) = ((p - x).dot(m), (q - x).dot(m));
        if dp >= 0.0 {
            out[len] = p;
            len += 1;
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            out[len] = p + (q - p) * (dp / (dp - dq));
            len += 1;
        }
    }
    len
}

/// Points [`polygon_form_factors_sided`] takes at once: four f64 fill a
/// 256-bit vector.
const LANES: usize = 4;

/// [`polygon_form_factor_sided`] at each of `points` (normal `n` for all)
/// into `out`, the same numbers bit for bit. The links' refinement
/// integrates the factor at nine points of each receiver, a third of its
/// time: the edges' sums run over four points in SIMD lanes (the same
/// operations in the same order per lane, so the same rounding), and a
/// point whose tangent plane cuts the polygon takes the clipping path alone.
pub fn polygon_form_factors_sided(
    points: &[DVec3],
    n: DVec3,
    polygon: &[DVec3],
    two_sided: bool,
    out: &mut [f64],
) {
    assert_eq!(points.len(), out.len());
    debug_assert!(polygon.len() <= 6);
    for (xs, fs) in points.chunks(LANES).zip(out.chunks_mut(LANES)) {
        // A short last chunk repeats its first point in the spare lanes.
        let mut lanes = [xs[0]; LANES];
        lanes[..xs.len()].copy_from_slice(xs);
        let sums = edge_sums(&lanes, n, polygon);
        for ((x, f), sum) in xs.iter().zip(fs).zip(sums) {
            let (mut above, mut below) = (false, false);
            for p in polygon {
                let s = (*p - *x).dot(n);
                above |= s > 0.0;
                below |= s < 0.0;
            }
            // Unclipped, either side's sum is the same edges' sum.
            *f = if above && below {
                polygon_form_factor_sided(*x, n, polygon, two_sided)
            } else if above || (below && two_sided) {
                (sum / (2.0 * PI)).abs().min(1.0)
            } else {
                0.0
            };
        }
    }
}

/// Per lane, the sum over the polygon's edges that
/// [`polygon_form_factor_sided`] takes of an unclipped polygon, written
/// out per coordinate as glam computes it (no fused multiply-adds: Rust
/// never contracts). Compiled for AVX2 too, chosen at run time
/// (`multiversion`: the binary stays portable x86-64).
#[multiversion::multiversion(targets("x86_64+avx2", "x86_64+avx"))]
fn edge_sums(xs: &[DVec3; LANES], n: DVec3, polygon: &[DVec3]) -> [f64; LANES] {
    let (px, py, pz) = (xs.map(|x| x.x), xs.map(|x| x.y), xs.map(|x| x.z));
    let mut sum = [0.0; LANES];
    for k in 0..polygon.len() {
        let (p, q) = (polygon[k], polygon[(k + 1) % polygon.len()]);
        for l in 0..LANES {
            let (ax, ay, az) = (p.x - px[l], p.y - py[l], p.z - pz[l]);
            let (bx, by, bz) = (q.x - px[l], q.y - py[l], q.z - pz[l]);
            let cx = ay * bz - by * az;
            let cy = az * bx - bz * ax;
            let cz = ax * by - bx * ay;
            let cl = ((cx * cx) + (cy * cy) + (cz * cz)).sqrt();
            let d = (ax * bx) + (ay * by) + (az * bz);
            let term = angle_atan2_branchless(cl, d) * ((cx * n.x) + (cy * n.y) + (cz * n.z)) / cl;
            // The scalar path skips such an edge; adding +0 leaves a sum
            // that is never −0 as it was.
            sum[l] += if cl < 1e-300 { 0.0 } else { term };
        }
    }
    sum
}

/// [`angle_atan2`] with its range reduction chosen by selects rather than
/// branches (so that four lanes take one path), the same value bit for bit.
#[inline(always)]
fn angle_atan2_branchless(y: f64, x: f64) -> f64 {
    let ax = x.abs();
    let big = y > TAN_3PI_8 * ax;
    let small = !big && y <= 0.66 * ax;
    let pick = |b: f64, s: f64, m: f64| {
        if big {
            b
        } else if small {
            s
        } else {
            m
        }
    };
    let (num, den) = (pick(-ax, y, y - ax), pick(y, ax, y + ax));
    let (base, more) = (
        pick(FRAC_PI_2, 0.0, FRAC_PI_4),
        pick(MOREBITS, 0.0, 0.5 * MOREBITS),
    );
    let t = num / den;
    let z = t * t;
    let p = (((P[0] * z + P[1]) * z + P[2]) * z + P[3]) * z + P[4];
    let q = ((((z + Q[0]) * z + Q[1]) * z + Q[2]) * z + Q[3]) * z + Q[4];
    let a = base + (t * (z * p / q) + t + more);
    let a = if x < 0.0 { PI - a } else { a };
    let on_axis = if y == 0.0 { 0.0 } else { FRAC_PI_2 };
    if ax == 0.0 { on_axis } else { a }
}
