//! [`Camera`]: a pinhole camera, by vertical field of view or by calibrated
//! intrinsics, with OpenCV's lens distortion (radial k1, k2, k3 and
//! tangential p1, p2) when the photo was shot through one. Gives rays
//! through any point of the image and projects world points back to pixels.
//!
//! Image coordinates are continuous pixels: (0,0) is the top-left corner of
//! the image, a pixel's centre is at (col+0.5, row+0.5), `y` grows down.

use glam::DVec3;

/// A pinhole camera. Built only through [`Camera::new`], which checks it.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub position: DVec3,
    /// Unit vectors: `forward` along the view axis, `right` and `up` spanning
    /// the image plane (up points to decreasing row).
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    /// Focal lengths and principal point, in pixels.
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Zero for a pinhole photo (an undistorted one).
    pub distortion: Distortion,
}

/// OpenCV's distortion model on normalised image coordinates (x right,
/// y down, 1 unit at the focal length): a point (x, y) at r² = x² + y²
/// is seen at (x·k + 2p1·xy + p2(r² + 2x²), y·k + p1(r² + 2y²) + 2p2·xy)
/// with k = 1 + k1·r² + k2·r⁴ + k3·r⁶.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

impl Distortion {
    pub fn is_none(&self) -> bool {
        *self == Distortion::default()
    }

    /// Whether the radial part still grows at r²: beyond, a polynomial
    /// lens model folds back onto the image and means nothing.
    pub(crate) fn is_monotonic_at(&self, r2: f64) -> bool {
        1.0 + r2 * (3.0 * self.k1 + r2 * (5.0 * self.k2 + r2 * 7.0 * self.k3)) > 0.0
    }

    /// Where the lens shows the normalised point (x, y).
    pub fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let k = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        (
            x * k + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * k + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// The normalised point the lens shows at (xd, yd): Newton's method on
    /// [`Distortion::apply`] (converges in a few steps over a photo's
    /// field; OpenCV's fixed-point iteration needs tens).
    pub(crate) fn remove(&self, xd: f64, yd: f64) -> (f64, f64) {
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let (fx, fy) = self.apply(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.abs().max(ey.abs()) < 1e-14 {
                break;
            }
            // The Jacobian by central differences (step far below a pixel).
            let h = 1e-7;
            let (ax, ay) = self.apply(x + h, y);
            let (bx, by) = self.apply(x - h, y);
            let (cx, cy) = self.apply(x, y + h);
            let (dx, dy) = self.apply(x, y - h);
            let (j00, j10) = ((ax - bx) / (2.0 * h), (ay - by) / (2.0 * h));
            let (j01, j11) = ((cx - dx) / (2.0 * h), (cy - dy) / (2.0 * h));
            let det = j00 * j11 - j01 * j10;
            if det.abs() < 1e-12 {
                break;
            }
            x -= (j11 * ex - j01 * ey) / det;
            y -= (-j10 * ex + j00 * ey) / det;
        }
        (x, y)
    }
}

/// How the projection is given in `scene.toml`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    FovY { degrees: f64 },
    Intrinsics { fx: f64, fy: f64, cx: f64, cy: f64 },
}

/// A ray: origin and unit direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: DVec3,
    pub direction: DVec3,
}

impl Camera {
    /// Builds a camera, or says which input makes it impossible (the caller
    /// attaches the key). The message names the offending quantity.
    pub fn new(
        width: u32,
        height: u32,
        position: DVec3,
        look_at: DVec3,
        up: DVec3,
        projection: Projection,
    ) -> Result<Camera, (&'static str, String)> {
        let forward = look_at - position;
        if forward.length() < 1e-9 {
            return Err(("look_at", "must differ from position".into()));
        }
        let forward = forward.normalize();
        if up.length() < 1e-12 {
            return Err(("up", "must not be zero".into()));
        }
        let right = forward.cross(up.normalize());
        if right.length() < 1e-6 {
            return Err(("up", "must not be parallel to the viewing direction".into()));
        }
        let right = right.normalize();
        let up = right.cross(forward);
        let (fx, fy, cx, cy) = match projection {
            Projection::FovY { degrees } => {
                if !(degrees > 0.0 && degrees < 180.0) {
                    return Err((
                        "fov_y_deg",
                        format!("must lie strictly between 0 and 180, found {degrees}"),
                    ));
                }
                let f = 0.5 * height as f64 / (0.5 * degrees.to_radians()).tan();
                (f, f, 0.5 * width as f64, 0.5 * height as f64)
            }
            Projection::Intrinsics { fx, fy, cx, cy } => {
                if !(fx > 0.0 && fy > 0.0) {
                    return Err((
                        "intrinsics",
                        format!("fx and fy must be positive, found fx={fx}, fy={fy}"),
                    ));
                }
                (fx, fy, cx, cy)
            }
        };
        Ok(Camera {
            width,
            height,
            position,
            forward,
            right,
            up,
            fx,
            fy,
            cx,
            cy,
            distortion: Distortion::default(),
        })
    }

    /// Whether every corner of the image comes from a point the lens maps
    /// there one to one (true for a pinhole): a polynomial model fitted to
    /// a photo can fold back before its corners, and then means nothing.
    pub(crate) fn lens_maps_the_image(&self) -> bool {
        let lens = self.distortion;
        if lens.is_none() {
            return true;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
            .iter()
            .all(|&(px, py)| {
                let (xd, yd) = ((px - self.cx) / self.fx, (py - self.cy) / self.fy);
                let (x, y) = lens.remove(xd, yd);
                let (ax, ay) = lens.apply(x, y);
                lens.is_monotonic_at(x * x + y * y) && (ax - xd).hypot(ay - yd) <= 1e-9
            })
    }

    /// This camera seeing through a lens with `distortion`.
    pub(crate) fn with_distortion(self, distortion: Distortion) -> Camera {
        Camera { distortion, ..self }
    }

    /// The same view at `scale` of the size (0 < scale ≤ 1): each side
    /// rounded to whole pixels, the intrinsics scaled with it, so that a
    /// pixel of the smaller image covers the same rays as the area of the
    /// larger one it averages.
    pub fn scaled(&self, scale: f64) -> Camera {
        let side = |n: u32| ((n as f64 * scale).round() as u32).max(1);
        let (w, h) = (side(self.width), side(self.height));
        let (sx, sy) = (w as f64 / self.width as f64, h as f64 / self.height as f64);
        Camera {
            width: w,
            height: h,
            fx: self.fx * sx,
            cx: self.cx * sx,
            fy: self.fy * sy,
            cy: self.cy * sy,
            ..*self
        }
    }

    pub(crate) fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The ray through image point (x, y) in continuous pixel coordinates.
    pub fn ray(&self, x: f64, y: f64) -> Ray {
        let d = if self.distortion.is_none() {
            self.forward + self.right * ((x - self.cx) / self.fx)
                - self.up * ((y - self.cy) / self.fy)
        } else {
            let (u, v) = self
                .distortion
                .remove((x - self.cx) / self.fx, (y - self.cy) / self.fy);
            self.forward + self.right * u - self.up * v
        };
        Ray {
            origin: self.position,
            direction: d.normalize(),
        }
    }

    /// The ray through the centre of pixel (col, row).
    pub fn pixel_ray(&self, col: u32, row: u32) -> Ray {
        self.ray(col as f64 + 0.5, row as f64 + 0.5)
    }

    /// The image of the segment a–b as a polyline: its two ends for a
    /// pinhole (a straight line stays straight), 17 points along it through
    /// a lens (which bends it). `None` when a point is behind the camera.
    pub(crate) fn project_path(&self, a: DVec3, b: DVec3) -> Option<Vec<(f64, f64)>> {
        let n = if self.distortion.is_none() { 1 } else { 16 };
        (0..=n)
            .map(|i| {
                let p = a.lerp(b, i as f64 / n as f64);
                self.project(p).map(|(x, y, _)| (x, y))
            })
            .collect()
    }

    /// Image points whose bounding box holds the image of the convex hull of
    /// `corners`: the corners themselves for a pinhole, points along every
    /// segment between two of them through a lens (whose curves may bow
    /// past the corners). `None` when a point is behind the camera.
    pub(crate) fn project_hull(&self, corners: &[DVec3]) -> Option<Vec<(f64, f64)>> {
        if self.distortion.is_none() {
            return corners
                .iter()
                .map(|c| self.project(*c).map(|(x, y, _)| (x, y)))
                .collect();
        }
        let mut out = Vec::new();
        for (i, a) in corners.iter().enumerate() {
            for b in &corners[i + 1..] {
                out.extend(self.project_path(*a, *b)?);
            }
        }
        Some(out)
    }

    /// Image coordinates of a world point and its depth along the view axis,
    /// or `None` for points at or behind the camera plane.
    pub fn project(&self, p: DVec3) -> Option<(f64, f64, f64)> {
        let d = p - self.position;
        let z = d.dot(self.forward);
        if z <= 1e-12 {
            return None;
        }
        if self.distortion.is_none() {
            let x = self.cx + self.fx * d.dot(self.right) / z;
            let y = self.cy - self.fy * d.dot(self.up) / z;
            return Some((x, y, z));
        }
        let (x, y) = (d.dot(self.right) / z, -d.dot(self.up) / z);
        if !self.distortion.is_monotonic_at(x * x + y * y) {
            // Past where the lens model folds back: it says nothing there.
            return None;
        }
        let (u, v) = self.distortion.apply(x, y);
        Some((self.cx + self.fx * u, self.cy + self.fy * v, z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn desk_like(projection: Projection) -> Camera {
        Camera::new(
            512,
            384,
            DVec3::new(0.7, 1.45, 2.7),
            DVec3::new(-0.45, 0.6, -1.0),
            DVec3::Y,
            projection,
        )
        .unwrap()
    }

    #[test]
    fn project_inverts_ray_within_1e4_pixels() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for cam in [
            desk_like(Projection::FovY { degrees: 55.0 }),
            desk_like(Projection::Intrinsics {
                fx: 610.0,
                fy: 590.0,
                cx: 250.3,
                cy: 199.7,
            }),
        ] {
            for _ in 0..1000 {
                let (x, y) = (
                    rng.random_range(-50.0..562.0),
                    rng.random_range(-50.0..434.0),
                );
                let depth = rng.random_range(0.01..100.0);
                let ray = cam.ray(x, y);
                let p = ray.origin + ray.direction * depth;
                let (px, py, _) = cam.project(p).unwrap();
                assert!(
                    (px - x).abs() < 1e-4 && (py - y).abs() < 1e-4,
                    "({x},{y}) -> ({px},{py})"
                );
            }
        }
    }

    #[test]
    fn right_of_the_axis_lands_right_of_centre_and_up_lands_up() {
        let cam = desk_like(Projection::FovY { degrees: 55.0 });
        let ahead = cam.position + cam.forward * 3.0;
        let (x, y, _) = cam.project(ahead + cam.right * 0.5).unwrap();
        assert!(x > 256.0 + 1.0 && (y - 192.0).abs() < 1e-9);
        let (x, y, _) = cam.project(ahead + DVec3::Y * 0.5).unwrap();
        assert!(y < 192.0 - 1.0 && (x - 256.0).abs() < 1.0);
        assert!(cam.project(cam.position - cam.forward).is_none());
    }

    #[test]
    fn fov_spans_the_image_height() {
        let cam = desk_like(Projection::FovY { degrees: 55.0 });
        let top = cam.ray(256.0, 0.0).direction;
        let bottom = cam.ray(256.0, 384.0).direction;
        assert!((top.angle_between(bottom).to_degrees() - 55.0).abs() < 1e-9);
    }

    #[test]
    fn degenerate_cameras_are_refused() {
        let p = DVec3::ZERO;
        let fov = Projection::FovY { degrees: 50.0 };
        assert_eq!(
            Camera::new(8, 8, p, p, DVec3::Y, fov).unwrap_err().0,
            "look_at"
        );
        assert_eq!(
            Camera::new(8, 8, p, DVec3::Y, DVec3::Y, fov).unwrap_err().0,
            "up"
        );
        assert_eq!(
            Camera::new(
                8,
                8,
                p,
                DVec3::X,
                DVec3::Y,
                Projection::FovY { degrees: 180.0 }
            )
            .unwrap_err()
            .0,
            "fov_y_deg"
        );
    }
}
