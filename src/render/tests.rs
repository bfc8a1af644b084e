use super::merge_sorted;

#[test]
fn merging_sorted_lists_gives_their_union_sorted_once() {
    assert_eq!(
        merge_sorted(&[1, 4, 9], &[2, 4, 10, 11]),
        vec![1, 2, 4, 9, 10, 11]
    );
    assert_eq!(merge_sorted(&[], &[3, 3, 5]), vec![3, 5]);
    assert_eq!(merge_sorted(&[7], &[]), vec![7]);
    assert!(merge_sorted(&[], &[]).is_empty());
}

/// A UV sphere of radius `r` at `centre`, `rings` × `segments` quads each
/// cut in two (fans at the poles).
fn uv_sphere(
    centre: glam::Vec3,
    r: f32,
    rings: usize,
    segments: usize,
) -> Vec<crate::geometry::Triangle> {
    let point = |i: usize, j: usize| {
        let (theta, phi) = (
            std::f32::consts::PI * i as f32 / rings as f32,
            std::f32::consts::TAU * j as f32 / segments as f32,
        );
        centre
            + r * glam::Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            )
    };
    let mut out = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (
                point(i, j),
                point(i, j + 1),
                point(i + 1, j + 1),
                point(i + 1, j),
            );
            if i > 0 {
                out.push([a, c, b]);
            }
            if i + 1 < rings {
                out.push([a, d, c]);
            }
        }
    }
    out
}

/// Each vertex of a virtual mesh with its plane's normal, as final
/// gathering takes them (all facing the camera).
fn gather_points(patches: &crate::patches::Patches) -> Vec<(u32, glam::DVec3, u32)> {
    let mut normal_of = std::collections::BTreeMap::new();
    for (k, ids) in patches.patch_vertices.iter().enumerate() {
        for &v in ids.iter().filter(|&&v| v != u32::MAX) {
            normal_of.entry(v).or_insert(patches.patch(k).normal);
        }
    }
    normal_of.into_iter().map(|(v, n)| (v, n, 12)).collect()
}

#[test]
fn a_finely_tessellated_ball_gathers_at_no_more_points_than_a_coarse_one() {
    use super::final_gather::shared_gathers;
    use glam::DVec3;
    let within = 0.01;
    let mut counts = Vec::new();
    for (rings, segments) in [(20, 40), (80, 160)] {
        let ball = uv_sphere(glam::Vec3::new(0.0, 0.6, 0.0), 0.12, rings, segments);
        let input = crate::patches::SurfaceInput {
            surface: 0,
            triangles: &ball,
            is_virtual: true,
        };
        let patches = crate::patches::Patches::build(&[input], 0.1);
        let points = gather_points(&patches);
        let shares = shared_gathers(&patches, &points, within);
        let gathering = (0..shares.len())
            .filter(|&i| shares.of(i).is_empty())
            .count();
        // A light E(x, n) known at the gathering vertices, steeper than a
        // room's indirect light (it varies by up to 4.5% across 1 cm and
        // 5°): the others take a weighted mean of the values they share,
        // so within those values' range and within 4% of their own.
        let light = |v: u32, n: DVec3| {
            let x = patches.vertices[v as usize];
            1.0 + 2.0 * x.y + 0.5 * n.y + 0.3 * n.x
        };
        let mut worst: f64 = 0.0;
        for (i, (v, n, _)) in points.iter().enumerate() {
            let taken = shares.of(i);
            for &(j, _) in taken {
                let (w, m, _) = points[j as usize];
                let d = (patches.vertices[w as usize] - patches.vertices[*v as usize]).length();
                assert!(
                    d <= within
                        && n.dot(m) >= super::final_gather::SHARE_ANGLE_DEG.to_radians().cos()
                );
            }
            if !taken.is_empty() {
                let total: f64 = taken.iter().map(|t| t.1).sum();
                let values: Vec<f64> = taken
                    .iter()
                    .map(|&(j, _)| light(points[j as usize].0, points[j as usize].1))
                    .collect();
                let shared: f64 =
                    taken.iter().zip(&values).map(|(t, e)| t.1 * e).sum::<f64>() / total;
                let (lo, hi) = values.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), e| {
                    (lo.min(*e), hi.max(*e))
                });
                assert!(shared >= lo * (1.0 - 1e-12) && shared <= hi * (1.0 + 1e-12));
                worst = worst.max((shared / light(*v, *n) - 1.0).abs());
            }
        }
        assert!(
            worst < 0.04,
            "{rings}×{segments}: shared light off by {worst}"
        );
        counts.push((points.len(), gathering));
    }
    let ((coarse_vertices, coarse), (fine_vertices, fine)) = (counts[0], counts[1]);
    assert!(fine_vertices > 10 * coarse_vertices, "{counts:?}");
    assert!(
        fine <= coarse,
        "gathers {coarse} (coarse) against {fine} (fine)"
    );
    // The coarse ball's facets are 9° apart: most of its vertices (all but
    // the poles' fans and corners shared by nearly parallel facets) keep
    // their own gathers (measured: 2,234 of 3,120; the fine ball 1,815 of 51,276).
    assert!(coarse * 3 > coarse_vertices * 2, "{counts:?}");
}
