//! Radiosity solved from a transport: restarted GMRES, or a plain gather
//! for comparison.

use super::transport::*;
use crate::patches::Patches;
use glam::DVec3;

/// A solved system.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Radiosity per patch.
    pub radiosity: Vec<DVec3>,
    /// Irradiance each patch gathers from the others (the indirect light).
    pub indirect_irradiance: Vec<DVec3>,
    /// Operator applications (the largest over the three channels).
    pub iterations: usize,
    /// Final relative residual ‖b − (I − ρT)B‖ / ‖b‖ (largest channel).
    pub residual: f64,
}

/// Solves B = b + ρ ⊙ T(B) per channel by restarted GMRES, to relative
/// residual `tolerance`. For lights, b = ρ ⊙ E_direct.
pub fn solve(
    patches: &Patches,
    transport: &Transport,
    reflectance: &[DVec3],
    b: &[DVec3],
    tolerance: f64,
    max_iterations: usize,
) -> Solution {
    solve_from(
        patches,
        transport,
        reflectance,
        b,
        None,
        tolerance,
        max_iterations,
    )
}

/// [`solve`] starting from a guess (a previous solution of a nearby system).
pub(crate) fn solve_from(
    patches: &Patches,
    transport: &Transport,
    reflectance: &[DVec3],
    b: &[DVec3],
    guess: Option<&[DVec3]>,
    tolerance: f64,
    max_iterations: usize,
) -> Solution {
    let n = b.len();
    let mut radiosity = vec![DVec3::ZERO; n];
    let (mut iterations, mut residual) = (0, 0.0f64);
    for c in 0..3 {
        let rho: Vec<f64> = reflectance.iter().map(|r| r[c]).collect();
        let rhs: Vec<f64> = b.iter().map(|v| v[c]).collect();
        let apply = |x: &[f64], out: &mut [f64]| {
            transport.gather(patches, x, out);
            for ((o, x), r) in out.iter_mut().zip(x).zip(&rho) {
                *o = x - r * *o;
            }
        };
        let x0: Vec<f64> = match guess {
            Some(g) => g.iter().map(|v| v[c]).collect(),
            None => vec![0.0; n],
        };
        let (x, it, res) = gmres(apply, &rhs, x0, tolerance, max_iterations, 40);
        iterations = iterations.max(it);
        residual = residual.max(res);
        for (r, v) in radiosity.iter_mut().zip(x) {
            r[c] = v;
        }
    }
    finish(patches, transport, radiosity, iterations, residual)
}

/// The plain gather iteration B ← b + ρ ⊙ T(B) from B = b, until the
/// change is below `tolerance` (relative): the baseline GMRES is measured against.
pub fn solve_by_iteration(
    patches: &Patches,
    transport: &Transport,
    reflectance: &[DVec3],
    b: &[DVec3],
    tolerance: f64,
    max_iterations: usize,
) -> Solution {
    let mut x = b.to_vec();
    let norm = b
        .iter()
        .map(|v| v.length_squared())
        .sum::<f64>()
        .sqrt()
        .max(1e-300);
    let mut iterations = 0;
    let mut change = f64::INFINITY;
    while iterations < max_iterations && change > tolerance {
        let h = transport.gather_rgb(patches, &x);
        let next: Vec<DVec3> = b
            .iter()
            .zip(&h)
            .zip(reflectance)
            .map(|((b, h), r)| *b + *r * *h)
            .collect();
        change = next
            .iter()
            .zip(&x)
            .map(|(a, b)| (*a - *b).length_squared())
            .sum::<f64>()
            .sqrt()
            / norm;
        x = next;
        iterations += 1;
    }
    finish(patches, transport, x, iterations, change)
}

pub(super) fn finish(
    patches: &Patches,
    transport: &Transport,
    radiosity: Vec<DVec3>,
    iterations: usize,
    residual: f64,
) -> Solution {
    let indirect_irradiance = transport.gather_rgb(patches, &radiosity);
    Solution {
        radiosity,
        indirect_irradiance,
        iterations,
        residual,
    }
}

/// Restarted GMRES for A x = b from the guess `x0`. Returns (x, operator
/// applications, relative residual).
pub(super) fn gmres(
    apply: impl Fn(&[f64], &mut [f64]),
    b: &[f64],
    x0: Vec<f64>,
    tolerance: f64,
    max_iterations: usize,
    restart: usize,
) -> (Vec<f64>, usize, f64) {
    let n = b.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let bnorm = dot(b, b).sqrt();
    let mut x = x0;
    if bnorm == 0.0 || n == 0 {
        return (vec![0.0; n], 0, 0.0);
    }
    let mut iterations = 0;
    let mut ax = vec![0.0; n];
    loop {
        apply(&x, &mut ax);
        let r: Vec<f64> = b.iter().zip(&ax).map(|(b, a)| b - a).collect();
        let beta = dot(&r, &r).sqrt();
        if beta / bnorm <= tolerance || iterations >= max_iterations {
            return (x, iterations, beta / bnorm);
        }
        let mut v: Vec<Vec<f64>> = vec![r.iter().map(|r| r / beta).collect()];
        let mut h = vec![vec![0.0; restart]; restart + 1];
        let (mut cs, mut sn) = (vec![0.0; restart], vec![0.0; restart]);
        let mut g = vec![0.0; restart + 1];
        g[0] = beta;
        let mut k = 0;
        while k < restart && iterations < max_iterations {
            let mut w = vec![0.0; n];
            apply(&v[k], &mut w);
            iterations += 1;
            for (i, vi) in v.iter().enumerate() {
                h[i][k] = dot(&w, vi);
                for (wj, vj) in w.iter_mut().zip(vi) {
                    *wj -= h[i][k] * vj;
                }
            }
            h[k + 1][k] = dot(&w, &w).sqrt();
            for i in 0..k {
                let t = cs[i] * h[i][k] + sn[i] * h[i + 1][k];
                h[i + 1][k] = -sn[i] * h[i][k] + cs[i] * h[i + 1][k];
                h[i][k] = t;
            }
            let denom = h[k][k].hypot(h[k + 1][k]);
            (cs[k], sn[k]) = if denom == 0.0 {
                (1.0, 0.0)
            } else {
                (h[k][k] / denom, h[k + 1][k] / denom)
            };
            h[k][k] = denom;
            h[k + 1][k] = 0.0;
            g[k + 1] = -sn[k] * g[k];
            g[k] *= cs[k];
            let norm_w = dot(&w, &w).sqrt();
            k += 1;
            if g[k].abs() / bnorm <= tolerance || norm_w == 0.0 {
                break;
            }
            v.push(w.iter().map(|x| x / norm_w).collect());
        }
        // Back-substitution of the k×k triangle, then x += V y.
        let mut y = vec![0.0; k];
        for i in (0..k).rev() {
            let s: f64 = (i + 1..k).map(|j| h[i][j] * y[j]).sum();
            y[i] = if h[i][i] != 0.0 {
                (g[i] - s) / h[i][i]
            } else {
                0.0
            };
        }
        for (i, yi) in y.iter().enumerate() {
            for (xj, vj) in x.iter_mut().zip(&v[i]) {
                *xj += yi * vj;
            }
        }
    }
}
