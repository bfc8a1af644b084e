/// The unknowns of [`integrate_jumps`] and what ties them: `pairs` whose
/// step is measured (with their `base` weights) and weak `links` that ask
/// for no step.
pub(super) struct JumpGraph<'a> {
    pub n: usize,
    pub pairs: &'a [(u32, u32)],
    pub base: &'a [f64],
    pub links: &'a [(u32, u32, f64)],
}

/// Reweighted rounds of [`integrate_jumps`].
const ROBUST_ROUNDS: usize = 2;

/// u with u_j − u_i ≈ target over `pairs`, and u_j ≈ u_i (with each
/// link's weight) over `links`, robustly: least squares, then rounds in
/// which a pair the solution misses by more than `noise` (the photo's own
/// step-to-step noise) counts only as much as that (Huber). A texture
/// edge's step lost at a few pixels (a checkerboard's anti-aliased corner,
/// where four tiles blend) otherwise bends the texture around it in a blob
/// several pixels wide; down-weighted, it stays a local defect.
pub(super) fn integrate_jumps(
    graph: &JumpGraph,
    targets: &[f64],
    weights: Option<&[f64]>,
    start: Option<&[f64]>,
    noise: f64,
) -> (Vec<f64>, Vec<f64>) {
    let &JumpGraph {
        n,
        pairs,
        base,
        links,
    } = graph;
    let reweigh = |x: &[f64], weights: &mut [f64]| {
        for ((w, &b), (&(i, j), &t)) in weights.iter_mut().zip(base).zip(pairs.iter().zip(targets))
        {
            let r = (x[j as usize] - x[i as usize] - t).abs();
            *w = if r > noise { b * noise / r } else { b };
        }
    };
    // Given the weights of an earlier call on these pairs (its targets
    // moved a little since), one more reweighted solve goes on from there.
    if let Some(w) = weights.filter(|w| w.len() == pairs.len()) {
        let x = solve_jumps(n, pairs, targets, w, links, start);
        let mut next = w.to_vec();
        reweigh(&x, &mut next);
        return (x, next);
    }
    let mut weights = base.to_vec();
    let mut x = solve_jumps(n, pairs, targets, &weights, links, start);
    for _ in 0..ROBUST_ROUNDS {
        reweigh(&x, &mut weights);
        x = solve_jumps(n, pairs, targets, &weights, links, Some(&x));
    }
    reweigh(&x, &mut weights);
    (x, weights)
}

/// Weighted least squares of [`integrate_jumps`]: a graph Laplacian
/// system, solved by conjugate gradients from `start` (each connected
/// piece keeps its mean, so the singular system stays consistent).
pub(super) fn solve_jumps(
    n: usize,
    pairs: &[(u32, u32)],
    targets: &[f64],
    weights: &[f64],
    links: &[(u32, u32, f64)],
    start: Option<&[f64]>,
) -> Vec<f64> {
    let mut degree = vec![0.0f64; n];
    let mut rhs = vec![0.0f64; n];
    for ((&(i, j), &t), &w) in pairs.iter().zip(targets).zip(weights) {
        degree[i as usize] += w;
        degree[j as usize] += w;
        rhs[j as usize] += w * t;
        rhs[i as usize] -= w * t;
    }
    if rhs.iter().all(|&r| r == 0.0) {
        return vec![0.0; n];
    }
    for &(i, j, w) in links {
        degree[i as usize] += w;
        degree[j as usize] += w;
    }
    let apply = |x: &[f64], out: &mut [f64]| {
        for (o, (d, xi)) in out.iter_mut().zip(degree.iter().zip(x)) {
            *o = d * xi;
        }
        for (&(i, j), &w) in pairs.iter().zip(weights) {
            let (i, j) = (i as usize, j as usize);
            out[i] -= w * x[j];
            out[j] -= w * x[i];
        }
        for &(i, j, w) in links {
            let (i, j) = (i as usize, j as usize);
            out[i] -= w * x[j];
            out[j] -= w * x[i];
        }
    };
    let precondition = |r: &[f64], z: &mut [f64]| {
        for ((zi, ri), d) in z.iter_mut().zip(r).zip(&degree) {
            *zi = if *d > 0.0 { ri / d } else { 0.0 };
        }
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let start = start.filter(|s| s.len() == n);
    let mut x = start.map_or_else(|| vec![0.0; n], |s| s.to_vec());
    let mut r = rhs.clone();
    if start.is_some() {
        let mut ax = vec![0.0; n];
        apply(&x, &mut ax);
        for (r, a) in r.iter_mut().zip(ax) {
            *r -= a;
        }
    }
    let mut z = vec![0.0; n];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let norm = dot(&rhs, &rhs).sqrt();
    let mut ap = vec![0.0; n];
    for _ in 0..2000 {
        apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        if pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for k in 0..n {
            x[k] += alpha * p[k];
            r[k] -= alpha * ap[k];
        }
        if dot(&r, &r).sqrt() <= 1e-6 * norm {
            break;
        }
        precondition(&r, &mut z);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for k in 0..n {
            p[k] = z[k] + beta * p[k];
        }
    }
    x
}
