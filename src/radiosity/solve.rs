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
    let apply = |x: &[DVec3], out: &mut [DVec3]| {
        transport.gather_channels(patches, x, out);
        for ((o, x), r) in out.iter_mut().zip(x).zip(reflectance) {
            *o = *x - *r * *o;
        }
    };
    let (radiosity, stats) = gmres_rgb(apply, b, guess, tolerance, max_iterations, 40);
    let (iterations, residual) = largest(&stats);
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

/// The most operator applications and the largest residual over the
/// channels' solves.
pub(super) fn largest(stats: &[(usize, f64); 3]) -> (usize, f64) {
    (stats.iter()).fold((0, 0.0f64), |(i, r), s| (i.max(s.0), r.max(s.1)))
}

/// Restarted GMRES (restart length `restart`) for A x = b from the guess
/// `x0`, the three channels at once: A is applied to the three channels'
/// vectors together (`apply`: one pass over the links gathers all three).
/// Each channel runs its own GMRES, its steps the same as if it ran
/// alone; a channel that has converged is handed zeros and ignores what
/// comes back. Returns x, and per channel the operator applications and
/// relative residual.
pub(super) fn gmres_rgb(
    apply: impl Fn(&[DVec3], &mut [DVec3]),
    b: &[DVec3],
    x0: Option<&[DVec3]>,
    tolerance: f64,
    max_iterations: usize,
    restart: usize,
) -> (Vec<DVec3>, [(usize, f64); 3]) {
    let n = b.len();
    let mut solvers: [Gmres; 3] = std::array::from_fn(|c| {
        let rhs: Vec<f64> = b.iter().map(|v| v[c]).collect();
        let x0 = x0.map_or(vec![0.0; n], |g| g.iter().map(|v| v[c]).collect());
        Gmres::new(rhs, x0, tolerance, max_iterations, restart)
    });
    let (mut input, mut applied) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n]);
    while solvers.iter().any(|s| s.wanted().is_some()) {
        for (c, s) in solvers.iter().enumerate() {
            match s.wanted() {
                Some(x) => input.iter_mut().zip(x).for_each(|(i, x)| i[c] = *x),
                None => input.iter_mut().for_each(|i| i[c] = 0.0),
            }
        }
        apply(&input, &mut applied);
        for (c, s) in solvers.iter_mut().enumerate() {
            if s.wanted().is_some() {
                let column: Vec<f64> = applied.iter().map(|v| v[c]).collect();
                s.take(column);
            }
        }
    }
    let mut x = vec![DVec3::ZERO; n];
    let mut stats = [(0, 0.0); 3];
    for (c, s) in solvers.into_iter().enumerate() {
        let (xc, iterations, residual) = s.result();
        x.iter_mut().zip(xc).for_each(|(x, v)| x[c] = v);
        stats[c] = (iterations, residual);
    }
    (x, stats)
}

/// Restarted GMRES turned inside out: it names the vector it wants the
/// operator applied to ([`Gmres::wanted`]) and is handed the product
/// ([`Gmres::take`]), so that several systems can share one application.
struct Gmres {
    b: Vec<f64>,
    bnorm: f64,
    x: Vec<f64>,
    tolerance: f64,
    max_iterations: usize,
    restart: usize,
    iterations: usize,
    residual: f64,
    phase: Phase,
    /// The cycle's Krylov basis, Hessenberg matrix, Givens rotations and
    /// right-hand side.
    v: Vec<Vec<f64>>,
    h: Vec<Vec<f64>>,
    cs: Vec<f64>,
    sn: Vec<f64>,
    g: Vec<f64>,
    k: usize,
}

#[derive(Clone, Copy, PartialEq)]
enum Phase {
    /// Wants A x, for the residual that opens a cycle.
    Residual,
    /// Wants A v[k].
    Arnoldi,
    Done,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>()
}

impl Gmres {
    fn new(
        b: Vec<f64>,
        x0: Vec<f64>,
        tolerance: f64,
        max_iterations: usize,
        restart: usize,
    ) -> Gmres {
        let n = b.len();
        let bnorm = dot(&b, &b).sqrt();
        let done = bnorm == 0.0 || n == 0;
        Gmres {
            b,
            bnorm,
            x: if done { vec![0.0; n] } else { x0 },
            tolerance,
            max_iterations,
            restart,
            iterations: 0,
            residual: 0.0,
            phase: if done { Phase::Done } else { Phase::Residual },
            v: Vec::new(),
            h: Vec::new(),
            cs: Vec::new(),
            sn: Vec::new(),
            g: Vec::new(),
            k: 0,
        }
    }

    /// The vector to apply the operator to next; None once solved.
    fn wanted(&self) -> Option<&[f64]> {
        match self.phase {
            Phase::Residual => Some(&self.x),
            Phase::Arnoldi => Some(&self.v[self.k]),
            Phase::Done => None,
        }
    }

    /// The operator applied to [`Gmres::wanted`].
    fn take(&mut self, applied: Vec<f64>) {
        match self.phase {
            Phase::Residual => self.open_cycle(&applied),
            Phase::Arnoldi => self.arnoldi_step(applied),
            Phase::Done => {}
        }
    }

    /// (x, operator applications, relative residual).
    fn result(self) -> (Vec<f64>, usize, f64) {
        (self.x, self.iterations, self.residual)
    }

    fn open_cycle(&mut self, ax: &[f64]) {
        let r: Vec<f64> = self.b.iter().zip(ax).map(|(b, a)| b - a).collect();
        let beta = dot(&r, &r).sqrt();
        if beta / self.bnorm <= self.tolerance || self.iterations >= self.max_iterations {
            self.residual = beta / self.bnorm;
            self.phase = Phase::Done;
            return;
        }
        let restart = self.restart;
        self.v = vec![r.iter().map(|r| r / beta).collect()];
        self.h = vec![vec![0.0; restart]; restart + 1];
        (self.cs, self.sn) = (vec![0.0; restart], vec![0.0; restart]);
        self.g = vec![0.0; restart + 1];
        self.g[0] = beta;
        self.k = 0;
        self.phase = match restart > 0 {
            true => Phase::Arnoldi,
            false => Phase::Residual,
        };
    }

    fn arnoldi_step(&mut self, mut w: Vec<f64>) {
        let Gmres {
            v, h, cs, sn, g, ..
        } = self;
        let k = self.k;
        self.iterations += 1;
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
        self.k += 1;
        let k = self.k;
        if g[k].abs() / self.bnorm <= self.tolerance || norm_w == 0.0 {
            self.close_cycle();
            return;
        }
        v.push(w.iter().map(|x| x / norm_w).collect());
        if !(k < self.restart && self.iterations < self.max_iterations) {
            self.close_cycle();
        }
    }

    /// Back-substitution of the k×k triangle, then x += V y; the next
    /// cycle opens with the residual.
    fn close_cycle(&mut self) {
        let (k, h, g) = (self.k, &self.h, &self.g);
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
            for (xj, vj) in self.x.iter_mut().zip(&self.v[i]) {
                *xj += yi * vj;
            }
        }
        self.phase = Phase::Residual;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A = I − ρ_c T per channel: T dense, positive, rows summing to 0.95.
    fn system(n: usize) -> (Vec<Vec<f64>>, [f64; 3]) {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let t: Vec<Vec<f64>> = (0..n)
            .map(|_| {
                let row: Vec<f64> = (0..n).map(|_| next()).collect();
                let sum: f64 = row.iter().sum();
                row.iter().map(|x| x / sum * 0.95).collect()
            })
            .collect();
        (t, [0.99, 0.5, 0.0])
    }

    fn solve_rgb(t: &[Vec<f64>], rho: [f64; 3], b: &[DVec3]) -> (Vec<DVec3>, [(usize, f64); 3]) {
        let apply = |x: &[DVec3], out: &mut [DVec3]| {
            for (i, o) in out.iter_mut().enumerate() {
                let tx: DVec3 = t[i].iter().zip(x).map(|(t, x)| *x * *t).sum();
                *o = x[i] - DVec3::from(rho) * tx;
            }
        };
        gmres_rgb(apply, b, None, 1e-10, 500, 8)
    }

    #[test]
    fn each_channel_is_solved_as_if_alone_and_to_its_tolerance() {
        let n = 60;
        let (t, rho) = system(n);
        // Red stiff (ρ 0.99, restarted several times), green zero, blue
        // with nothing to reflect (solved in one step).
        let b: Vec<DVec3> = (0..n)
            .map(|i| DVec3::new(1.0 + (i % 7) as f64, 0.0, (i % 3) as f64))
            .collect();
        let (x, stats) = solve_rgb(&t, rho, &b);
        assert!(stats[0].0 > 8, "red restarts: {} steps", stats[0].0);
        assert_eq!(stats[1], (0, 0.0), "green has nothing to solve");
        assert!(stats[2].0 <= 2, "blue: {} steps", stats[2].0);
        for c in [0, 2] {
            // The residual, recomputed here, within the tolerance asked.
            let (mut r2, mut b2) = (0.0, 0.0);
            for i in 0..n {
                let tx: f64 = (0..n).map(|j| t[i][j] * x[j][c]).sum();
                r2 += (b[i][c] - (x[i][c] - rho[c] * tx)).powi(2);
                b2 += b[i][c].powi(2);
            }
            let relative = (r2 / b2).sqrt();
            assert!(relative <= 1e-9, "channel {c}: residual {relative}");
            assert!(stats[c].1 <= 1e-10, "channel {c}: reported {}", stats[c].1);
        }
        assert!(x.iter().all(|v| v.y == 0.0));
        // Red alone: the same steps, the same bits.
        let red: Vec<DVec3> = b.iter().map(|v| DVec3::new(v.x, 0.0, 0.0)).collect();
        let (alone, alone_stats) = solve_rgb(&t, rho, &red);
        assert_eq!(alone_stats[0], stats[0]);
        for (a, x) in alone.iter().zip(&x) {
            assert_eq!(a.x.to_bits(), x.x.to_bits());
        }
    }
}
