//! A light's position from its shadows (Grosch §2.4): each shadow line runs
//! from a shadow corner through the object vertex that casts it, each
//! shadow plane holds a shadow edge and the object edge that casts it; the
//! light is the point with the least sum of squared distances to all of
//! them ([`position_from_shadows`]). A set that does not pin a point down
//! (parallel lines, one plane, two planes alone) is an error saying what
//! to add.

use glam::{DMat3, DVec3};

use crate::scene::ShadowConstraints;

/// The estimated position and how well the constraints agree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowFit {
    pub position: DVec3,
    /// Root mean square distance from the position to the lines and planes, metres.
    pub residual: f64,
}

/// Smallest over largest eigenvalue of the normal matrix below which the
/// set leaves a direction free.
const CONDITION: f64 = 1e-6;

/// The least-squares point nearest to every shadow line and plane.
pub fn position_from_shadows(c: &ShadowConstraints) -> Result<ShadowFit, String> {
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    let mut lines = Vec::new();
    let mut planes = Vec::new();
    for (i, l) in c.lines.iter().enumerate() {
        let d = l.vertex - l.shadow;
        if d.length() < 1e-9 {
            return Err(format!(
                "shadow_lines[{i}]: the shadow point and the vertex coincide"
            ));
        }
        let d = d.normalize();
        // Projector onto the plane across the line: distance² = |P(x − p)|².
        let p = DMat3::IDENTITY - outer(d, d);
        a += p;
        b += p * l.shadow;
        lines.push((l.shadow, d));
    }
    for (i, pl) in c.planes.iter().enumerate() {
        let n = plane_normal(&[pl.shadow[0], pl.shadow[1], pl.edge[0], pl.edge[1]])
            .ok_or_else(|| format!("shadow_planes[{i}]: the shadow edge and the object edge lie on one line, which spans no plane"))?;
        let q = (pl.shadow[0] + pl.shadow[1] + pl.edge[0] + pl.edge[1]) / 4.0;
        a += outer(n, n);
        b += outer(n, n) * q;
        planes.push((q, n));
    }
    let (values, vectors) = symmetric_eigen(a);
    let largest = values.iter().copied().fold(0.0, f64::max);
    let smallest = values.iter().copied().fold(f64::INFINITY, f64::min);
    if largest <= 0.0 || smallest < CONDITION * largest {
        let free = vectors[values
            .iter()
            .enumerate()
            .min_by(|x, y| x.1.total_cmp(y.1))
            .map(|(k, _)| k)
            .unwrap_or(0)];
        let free_count = values
            .iter()
            .filter(|v| **v < CONDITION * largest.max(1e-300))
            .count();
        let what = match (lines.len(), planes.len()) {
            (0, 0) => "no shadow lines or planes".to_string(),
            (0, 1) => "one shadow plane fixes only the distance across it: add shadow lines, or two more planes".to_string(),
            (0, 2) => "two shadow planes meet in a line: add a third plane that crosses it, or a shadow line".to_string(),
            (1, 0) => "one shadow line leaves the light anywhere along it: add a line in another direction, or a plane".to_string(),
            (_, 0) if free_count == 1 => "the shadow lines are parallel: add one in another direction, or a shadow plane".to_string(),
            _ => "the lines and planes do not cross at a point".to_string(),
        };
        return Err(format!(
            "{what} (free direction {:.3} {:.3} {:.3})",
            free.x, free.y, free.z
        ));
    }
    let position = a.inverse() * b;
    let mut sum = 0.0;
    for (p, d) in &lines {
        let v = position - *p;
        sum += (v - *d * v.dot(*d)).length_squared();
    }
    for (q, n) in &planes {
        sum += (position - *q).dot(*n).powi(2);
    }
    let residual = (sum / (lines.len() + planes.len()) as f64).sqrt();
    Ok(ShadowFit { position, residual })
}

fn outer(u: DVec3, v: DVec3) -> DMat3 {
    DMat3::from_cols(u * v.x, u * v.y, u * v.z)
}

/// The unit normal of the plane best fitting `points` (smallest principal
/// axis), or None when they lie on a line.
fn plane_normal(points: &[DVec3]) -> Option<DVec3> {
    let centre = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let mut cov = DMat3::ZERO;
    for p in points {
        cov += outer(*p - centre, *p - centre);
    }
    let (values, vectors) = symmetric_eigen(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| values[i].total_cmp(&values[j]));
    // On a line, two principal axes have (almost) no spread.
    if values[order[1]] <= 1e-12 * values[order[2]].max(1e-300) {
        return None;
    }
    Some(vectors[order[0]].normalize())
}

/// Eigenvalues and unit eigenvectors of a symmetric 3×3 matrix (cyclic Jacobi).
// A rotation updates a row and a column of two matrices at once: indices read best.
#[allow(clippy::needless_range_loop)]
fn symmetric_eigen(m: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let mut a = m.to_cols_array_2d();
    let mut v = DMat3::IDENTITY.to_cols_array_2d();
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        if off < 1e-30 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for k in 0..3 {
                let (vkp, vkq) = (v[k][p], v[k][q]);
                v[k][p] = c * vkp - s * vkq;
                v[k][q] = s * vkp + c * vkq;
            }
        }
    }
    let values = [a[0][0], a[1][1], a[2][2]];
    let vectors = [
        DVec3::new(v[0][0], v[1][0], v[2][0]),
        DVec3::new(v[0][1], v[1][1], v[2][1]),
        DVec3::new(v[0][2], v[1][2], v[2][2]),
    ];
    (values, vectors)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{ShadowLine, ShadowPlane};

    const LIGHT: DVec3 = DVec3::new(1.5, 2.3, 1.0);

    /// The floor shadow of `vertex` cast from the light.
    fn shadow_of(vertex: DVec3) -> DVec3 {
        let d = vertex - LIGHT;
        LIGHT + d * (-LIGHT.y / d.y)
    }

    fn table_lines() -> Vec<ShadowLine> {
        [
            DVec3::new(-1.0, 0.75, -1.05),
            DVec3::new(0.2, 0.75, -1.05),
            DVec3::new(-1.0, 0.75, -1.75),
            DVec3::new(0.2, 0.75, -1.75),
        ]
        .iter()
        .map(|&vertex| ShadowLine {
            shadow: shadow_of(vertex),
            vertex,
        })
        .collect()
    }

    #[test]
    fn exact_shadow_lines_give_the_light_within_a_millimetre() {
        let fit = position_from_shadows(&ShadowConstraints {
            lines: table_lines(),
            planes: vec![],
        })
        .unwrap();
        assert!((fit.position - LIGHT).length() < 1e-3, "{}", fit.position);
        assert!(fit.residual < 1e-9);
        // Planes alone: three edges of the table top and their shadows.
        let c = [
            DVec3::new(-1.0, 0.75, -1.05),
            DVec3::new(0.2, 0.75, -1.05),
            DVec3::new(0.2, 0.75, -1.75),
            DVec3::new(-1.0, 0.75, -1.75),
        ];
        let planes: Vec<ShadowPlane> = (0..3)
            .map(|k| ShadowPlane {
                shadow: [shadow_of(c[k]), shadow_of(c[k + 1])],
                edge: [c[k], c[k + 1]],
            })
            .collect();
        let fit = position_from_shadows(&ShadowConstraints {
            lines: vec![],
            planes,
        })
        .unwrap();
        assert!((fit.position - LIGHT).length() < 1e-3, "{}", fit.position);
    }

    #[test]
    fn noisy_lines_give_the_least_squares_optimum() {
        let mut state = 17u64;
        let mut noise = || {
            DVec3::new(
                crate::util::rng::unit_random(&mut state),
                crate::util::rng::unit_random(&mut state),
                crate::util::rng::unit_random(&mut state),
            ) * 0.02
                - DVec3::splat(0.01)
        };
        let lines: Vec<ShadowLine> = table_lines()
            .iter()
            .map(|l| ShadowLine {
                shadow: l.shadow + noise(),
                vertex: l.vertex + noise(),
            })
            .collect();
        let c = ShadowConstraints {
            lines: lines.clone(),
            planes: vec![],
        };
        let fit = position_from_shadows(&c).unwrap();
        // An independent solve: gradient descent on the same sum of squares.
        let cost = |x: DVec3| {
            lines
                .iter()
                .map(|l| {
                    let d = (l.vertex - l.shadow).normalize();
                    let v = x - l.shadow;
                    (v - d * v.dot(d)).length_squared()
                })
                .sum::<f64>()
        };
        let mut x = DVec3::new(0.0, 1.0, 0.0);
        let h = 1e-6;
        for _ in 0..20000 {
            let g = DVec3::new(
                (cost(x + DVec3::X * h) - cost(x - DVec3::X * h)) / (2.0 * h),
                (cost(x + DVec3::Y * h) - cost(x - DVec3::Y * h)) / (2.0 * h),
                (cost(x + DVec3::Z * h) - cost(x - DVec3::Z * h)) / (2.0 * h),
            );
            x -= g * 0.1;
        }
        assert!(
            (x - fit.position).length() < 1e-5,
            "descent {x} vs {}",
            fit.position
        );
        println!(
            "1 cm noise on every point: light estimated {:.4} m from the truth (residual {:.4} m)",
            (fit.position - LIGHT).length(),
            fit.residual
        );
    }

    #[test]
    fn degenerate_sets_say_what_is_missing() {
        let l = table_lines();
        let one = position_from_shadows(&ShadowConstraints {
            lines: vec![l[0]],
            planes: vec![],
        })
        .unwrap_err();
        assert!(one.contains("one shadow line"), "{one}");
        let parallel = ShadowConstraints {
            lines: vec![
                ShadowLine {
                    shadow: DVec3::ZERO,
                    vertex: DVec3::Y,
                },
                ShadowLine {
                    shadow: DVec3::X,
                    vertex: DVec3::X + DVec3::Y,
                },
            ],
            planes: vec![],
        };
        assert!(
            position_from_shadows(&parallel)
                .unwrap_err()
                .contains("parallel")
        );
        let plane = ShadowPlane {
            shadow: [DVec3::ZERO, DVec3::X],
            edge: [DVec3::Y, DVec3::new(1.0, 1.0, 0.0)],
        };
        let e = position_from_shadows(&ShadowConstraints {
            lines: vec![],
            planes: vec![plane],
        })
        .unwrap_err();
        assert!(e.contains("one shadow plane"), "{e}");
        let plane2 = ShadowPlane {
            shadow: [DVec3::ZERO, DVec3::Z],
            edge: [DVec3::Y, DVec3::new(0.0, 1.0, 1.0)],
        };
        let e = position_from_shadows(&ShadowConstraints {
            lines: vec![],
            planes: vec![plane, plane2],
        })
        .unwrap_err();
        assert!(e.contains("two shadow planes"), "{e}");
        let flat = ShadowPlane {
            shadow: [DVec3::ZERO, DVec3::X],
            edge: [DVec3::X * 2.0, DVec3::X * 3.0],
        };
        assert!(
            position_from_shadows(&ShadowConstraints {
                lines: vec![],
                planes: vec![flat]
            })
            .unwrap_err()
            .contains("one line")
        );
    }
}
