//! [`Shaft`]: the convex hull of two point sets (Haines & Wallace shaft
//! culling), as a set of planes. A conservative test says when a convex
//! occluder certainly lies outside it: then nothing it contains can block
//! light between the two ends.

use glam::DVec3;

/// A convex volume given by outward planes n·x ≤ d.
#[derive(Debug, Clone, PartialEq)]
pub struct Shaft {
    planes: Vec<(DVec3, f64)>,
    tolerance: f64,
}

impl Shaft {
    /// The convex hull of the given points (at most a few dozen: every
    /// plane through three of them that has all on one side is a face).
    pub fn hull(points: &[DVec3]) -> Shaft {
        let scale = points.iter().map(|p| p.abs().max_element()).fold(1.0, f64::max);
        let extent = points.iter().map(|p| (*p - points[0]).length()).fold(0.0, f64::max).max(1e-12);
        let tolerance = 1e-9 * scale.max(extent);
        let mut planes: Vec<(DVec3, f64)> = Vec::new();
        let n = points.len();
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    let normal = (points[j] - points[i]).cross(points[k] - points[i]);
                    let len = normal.length();
                    if len < 1e-12 * extent * extent {
                        continue;
                    }
                    let normal = normal / len;
                    let d = normal.dot(points[i]);
                    let (mut above, mut below) = (false, false);
                    for p in points {
                        let s = normal.dot(*p) - d;
                        above |= s > tolerance;
                        below |= s < -tolerance;
                    }
                    let plane = match (above, below) {
                        (true, true) => continue,
                        (false, _) => (normal, d),
                        (true, false) => (-normal, -d),
                    };
                    if !planes.iter().any(|(m, e)| (*m - plane.0).length() < 1e-9 && (e - plane.1).abs() <= tolerance) {
                        planes.push(plane);
                    }
                }
            }
        }
        Shaft { planes, tolerance }
    }

    /// Whether the convex hull of `points` certainly lies outside the shaft
    /// (or only touches its boundary): all of them on or beyond one plane.
    /// May answer false for a hull that misses the shaft (conservative).
    pub fn excludes(&self, points: &[DVec3]) -> bool {
        self.planes.iter().any(|(n, d)| points.iter().all(|p| n.dot(*p) - d >= -self.tolerance))
    }

    pub fn plane_count(&self) -> usize {
        self.planes.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(y: f64) -> Vec<DVec3> {
        vec![DVec3::new(0.0, y, 0.0), DVec3::new(1.0, y, 0.0), DVec3::new(1.0, y, 1.0), DVec3::new(0.0, y, 1.0)]
    }

    #[test]
    fn a_shaft_between_parallel_squares_is_their_box() {
        let mut pts = square(0.0);
        pts.extend(square(2.0));
        let s = Shaft::hull(&pts);
        assert_eq!(s.plane_count(), 6);
        let blocker = vec![DVec3::new(0.4, 1.0, 0.4), DVec3::new(0.6, 1.0, 0.4), DVec3::new(0.5, 1.0, 0.6)];
        assert!(!s.excludes(&blocker));
        let aside: Vec<DVec3> = blocker.iter().map(|p| *p + DVec3::new(2.0, 0.0, 0.0)).collect();
        assert!(s.excludes(&aside));
        // A wall in the plane x = 1 only touches the shaft: it cannot block.
        let wall = vec![DVec3::new(1.0, -1.0, -1.0), DVec3::new(1.0, 3.0, -1.0), DVec3::new(1.0, 3.0, 3.0)];
        assert!(s.excludes(&wall));
    }

    #[test]
    fn a_shaft_between_perpendicular_squares_is_a_prism() {
        let floor = square(0.0);
        let wall = vec![DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, 0.0, 0.0), DVec3::new(1.0, 1.0, 0.0), DVec3::new(0.0, 1.0, 0.0)];
        let mut pts = floor.clone();
        pts.extend(wall);
        let s = Shaft::hull(&pts);
        // The hull is the triangular prism under the diagonal plane y + z = 1.
        assert!(!s.excludes(&[DVec3::new(0.5, 0.2, 0.2)]));
        assert!(s.excludes(&[DVec3::new(0.5, 0.8, 0.8)]));
    }
}
