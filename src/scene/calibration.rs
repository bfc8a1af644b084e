//! Cameras solved by other tools, read as arlux's pinhole camera: a COLMAP
//! sparse model (text or binary; Schönberger & Frahm 2016) and an fSpy
//! project (single-photo calibration from vanishing points).
//!
//! Both formats are small and fixed, and no maintained Rust crate reads
//! them (searched: COLMAP readers live in Python and C++), so they are read
//! here: COLMAP's `cameras` and `images` files, and fSpy's 16-byte header
//! and JSON state.

use std::path::Path;

use glam::{DMat3, DQuat, DVec3};

use super::fields::Fields;
use super::loader::{Loader, MAX_SIDE};
use crate::camera::{Camera, Distortion, Projection};
use crate::error::{Error, Result};

/// The camera another tool solved, from `file`: the image's size, the
/// position, the view and image-up directions, and pinhole intrinsics
/// `[fx, fy, cx, cy]` in pixels (principal point in arlux's convention: the
/// top-left pixel's centre at (0.5, 0.5)).
fn solved(
    file: &Path,
    (width, height): (u32, u32),
    position: DVec3,
    forward: DVec3,
    up: DVec3,
    [fx, fy, cx, cy]: [f64; 4],
) -> Result<Camera> {
    let projection = Projection::Intrinsics { fx, fy, cx, cy };
    Camera::new(width, height, position, position + forward, up, projection)
        .map_err(|(_, msg)| Error::file(file, format!("its camera: {msg}")))
}

impl Loader<'_> {
    /// `[camera]` with its lens (`distortion`) and `scale`: the camera to
    /// render with, and the photo's size (the camera's before its scale).
    pub(super) fn camera_with_lens(&self, c: &Fields) -> Result<(Camera, (u32, u32))> {
        let scale = c.opt_f64("scale")?.unwrap_or(1.0);
        if !(scale > 0.0 && scale <= 1.0) {
            return Err(c.error(
                "scale",
                format!(
                    "must lie in (0, 1]: the share of the photo's size to render at, not {scale}"
                ),
            ));
        }
        let lens = match c.opt_table("distortion")? {
            None => None,
            Some(d) => {
                let k = |key: &'static str| -> Result<f64> { Ok(d.opt_f64(key)?.unwrap_or(0.0)) };
                let lens = crate::camera::Distortion {
                    k1: k("k1")?,
                    k2: k("k2")?,
                    p1: k("p1")?,
                    p2: k("p2")?,
                    k3: k("k3")?,
                };
                d.finish()?;
                Some(lens)
            }
        };
        let mut full = self.camera(c)?;
        if let Some(lens) = lens {
            if !full.distortion.is_none() {
                return Err(c.error(
                    "distortion",
                    "the COLMAP camera model gives the lens already: leave distortion out",
                ));
            }
            full = full.with_distortion(lens);
        }
        // Whichever gave the lens (the scene or a COLMAP model).
        if !full.lens_maps_the_image() {
            let key = if c.has("colmap") {
                "colmap"
            } else {
                "distortion"
            };
            return Err(c.error(
                key,
                "the lens folds the image back on itself before its corners: not a lens (check the signs)",
            ));
        }
        let photo_size = (full.width, full.height);
        let camera = if scale < 1.0 {
            full.scaled(scale)
        } else {
            full
        };
        Ok((camera, photo_size))
    }
    /// A camera another tool solved: `colmap = { dir, image }` or `fspy = FILE`.
    pub(super) fn solved_camera(&self, c: &Fields) -> Result<Camera> {
        let (key, camera) = match c.opt_table("colmap")? {
            Some(t) if c.has("fspy") => return Err(t.table_error("give colmap or fspy, not both")),
            Some(t) => {
                let dir = self.dir.join(t.req_str("dir")?);
                if !dir.is_dir() {
                    return Err(t.error("dir", format!("folder not found: {}", dir.display())));
                }
                let image = t.req_str("image")?;
                t.finish()?;
                let solved = from_colmap(&dir, image)
                    .map_err(|e| e.within(self.file, c.key_path("colmap")))?;
                ("colmap", solved)
            }
            None => {
                let path = self.existing_path(c, "fspy", c.req_str("fspy")?)?;
                let solved =
                    from_fspy(&path).map_err(|e| e.within(self.file, c.key_path("fspy")))?;
                ("fspy", solved)
            }
        };
        for k in ["position", "look_at", "up", "fov_y_deg", "intrinsics"] {
            if c.has(k) {
                return Err(c.error(k, format!("the camera comes from {key}: leave {k} out")));
            }
        }
        for (k, solved_size) in [("width", camera.width), ("height", camera.height)] {
            if solved_size > MAX_SIDE {
                return Err(c.error(
                    key,
                    format!("its image is {solved_size} pixels {k}, more than arlux supports ({MAX_SIDE})"),
                ));
            }
            if c.has(k) && c.req_count(k)? != solved_size {
                return Err(c.error(
                    k,
                    format!(
                        "{} differs from the {key} camera's {solved_size} pixels",
                        c.req_count(k)?
                    ),
                ));
            }
        }
        c.finish()?;
        Ok(camera)
    }
}

/// COLMAP's camera models: (id, name, parameter count, parameters that
/// are focal lengths and principal point, whether it is a fisheye).
const MODELS: [(i32, &str, usize, bool); 11] = [
    (0, "SIMPLE_PINHOLE", 3, false),
    (1, "PINHOLE", 4, false),
    (2, "SIMPLE_RADIAL", 4, false),
    (3, "RADIAL", 5, false),
    (4, "OPENCV", 8, false),
    (5, "OPENCV_FISHEYE", 8, true),
    (6, "FULL_OPENCV", 12, false),
    (7, "FOV", 5, false),
    (8, "SIMPLE_RADIAL_FISHEYE", 4, true),
    (9, "RADIAL_FISHEYE", 5, true),
    (10, "THIN_PRISM_FISHEYE", 12, true),
];

/// One COLMAP camera: model name, size, parameters.
struct ColmapCamera {
    model: &'static str,
    width: u64,
    height: u64,
    params: Vec<f64>,
}

impl ColmapCamera {
    /// fx, fy, cx, cy and the lens distortion in OpenCV's terms; an error
    /// for a model outside them (a fisheye, FOV, or FULL_OPENCV's rational
    /// terms).
    fn intrinsics(&self, file: &Path) -> Result<((f64, f64, f64, f64), Distortion)> {
        let &(_, name, _, fisheye) = MODELS
            .iter()
            .find(|m| m.1 == self.model)
            .expect("models come from MODELS");
        let p = &self.params;
        let (intrinsics, distortion) = match name {
            "SIMPLE_PINHOLE"
            | "SIMPLE_RADIAL"
            | "RADIAL"
            | "SIMPLE_RADIAL_FISHEYE"
            | "RADIAL_FISHEYE" => ((p[0], p[0], p[1], p[2]), &p[3..]),
            _ => ((p[0], p[1], p[2], p[3]), &p[4..]),
        };
        let d = |i: usize| distortion.get(i).copied().unwrap_or(0.0);
        let lens = match name {
            "SIMPLE_RADIAL" | "RADIAL" => Some(Distortion {
                k1: d(0),
                k2: d(1),
                ..Distortion::default()
            }),
            "OPENCV" => Some(Distortion {
                k1: d(0),
                k2: d(1),
                p1: d(2),
                p2: d(3),
                k3: 0.0,
            }),
            "FULL_OPENCV" if distortion[5..].iter().all(|&k| k == 0.0) => Some(Distortion {
                k1: d(0),
                k2: d(1),
                p1: d(2),
                p2: d(3),
                k3: d(4),
            }),
            _ if !fisheye && distortion.iter().all(|&k| k == 0.0) => Some(Distortion::default()),
            _ => None,
        };
        match lens {
            Some(lens) => Ok((intrinsics, lens)),
            None => Err(Error::file(
                file,
                format!(
                    "camera model {name} with parameters {distortion:?}: arlux models OpenCV's lens (k1, k2, p1, p2, k3); undistort the photos first (`colmap image_undistorter`) and give the undistorted model"
                ),
            )),
        }
    }
}

/// The camera of `image` in the COLMAP sparse model in `dir` (`cameras.txt`
/// and `images.txt`, or `cameras.bin` and `images.bin`).
pub fn from_colmap(dir: &Path, image: &str) -> Result<Camera> {
    let text = dir.join("images.txt").is_file();
    let (images_file, cameras_file) = if text {
        (dir.join("images.txt"), dir.join("cameras.txt"))
    } else {
        (dir.join("images.bin"), dir.join("cameras.bin"))
    };
    let read = |p: &Path| std::fs::read(p).map_err(|e| Error::io(p, &e));
    let (images, cameras) = (read(&images_file)?, read(&cameras_file)?);
    let (pose, camera_id) = if text {
        colmap_text_image(&images_file, &String::from_utf8_lossy(&images), image)?
    } else {
        colmap_binary_image(&images_file, &images, image)?
    };
    let camera = if text {
        colmap_text_camera(&cameras_file, &String::from_utf8_lossy(&cameras), camera_id)?
    } else {
        colmap_binary_camera(&cameras_file, &cameras, camera_id)?
    };
    let ((fx, fy, cx, cy), distortion) = camera.intrinsics(&cameras_file)?;
    let (q, t) = pose;
    if !(q.is_finite() && t.is_finite() && q.length() > 0.5) {
        return Err(Error::file(
            &images_file,
            format!("image '{image}': its pose is not a rotation"),
        ));
    }
    // COLMAP maps world to camera: x_cam = R x + t, camera x right, y down,
    // z along the view; the centre is −Rᵀt.
    let r = DMat3::from_quat(q.normalize());
    let rt = r.transpose();
    let too_big = |n: u64| n == 0 || n > u32::MAX as u64;
    if too_big(camera.width) || too_big(camera.height) {
        return Err(Error::file(
            &cameras_file,
            format!(
                "camera {camera_id}: size {}x{}",
                camera.width, camera.height
            ),
        ));
    }
    let size = (camera.width as u32, camera.height as u32);
    let (position, forward, up) = (-(rt * t), rt * DVec3::Z, -(rt * DVec3::Y));
    Ok(
        solved(&cameras_file, size, position, forward, up, [fx, fy, cx, cy])?
            .with_distortion(distortion),
    )
}

type Pose = (DQuat, DVec3);

fn colmap_text_image(file: &Path, text: &str, image: &str) -> Result<(Pose, i64)> {
    // Two lines per image, the second (its points) possibly empty: only the
    // comments at the top are skipped.
    let lines: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .skip_while(|(_, l)| l.starts_with('#'))
        .collect();
    for &(n, line) in lines.iter().step_by(2) {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 10 || f[9..].join(" ") != image {
            continue;
        }
        let num = |i: usize| -> Result<f64> {
            f[i].parse()
                .map_err(|_| Error::line(file, n + 1, format!("'{}' is not a number", f[i])))
        };
        let q = DQuat::from_xyzw(num(2)?, num(3)?, num(4)?, num(1)?);
        let t = DVec3::new(num(5)?, num(6)?, num(7)?);
        let camera = f[8]
            .parse()
            .map_err(|_| Error::line(file, n + 1, format!("camera id '{}'", f[8])))?;
        return Ok(((q, t), camera));
    }
    Err(no_image(file, image))
}

fn no_image(file: &Path, image: &str) -> Error {
    Error::file(file, format!("no image named '{image}' in the model"))
}

fn colmap_text_camera(file: &Path, text: &str, id: i64) -> Result<ColmapCamera> {
    for (n, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if line.starts_with('#') || f.len() < 4 || f[0].parse::<i64>().ok() != Some(id) {
            continue;
        }
        let at = |m: String| Error::line(file, n + 1, m);
        let &(_, model, count, _) = MODELS
            .iter()
            .find(|m| m.1 == f[1])
            .ok_or_else(|| at(format!("unknown camera model '{}'", f[1])))?;
        let size = |i: usize| {
            f[i].parse::<u64>()
                .map_err(|_| at(format!("size '{}'", f[i])))
        };
        let params = f[4..]
            .iter()
            .map(|v| {
                v.parse::<f64>()
                    .map_err(|_| at(format!("'{v}' is not a number")))
            })
            .collect::<Result<Vec<f64>>>()?;
        if params.len() != count || params.iter().any(|p| !p.is_finite()) {
            return Err(at(format!("{model} takes {count} finite parameters")));
        }
        return Ok(ColmapCamera {
            model,
            width: size(2)?,
            height: size(3)?,
            params,
        });
    }
    Err(Error::file(file, format!("no camera {id}")))
}

/// Little-endian reads from a binary model, each failing as "cut short".
struct Bytes<'a> {
    file: &'a Path,
    data: &'a [u8],
    at: usize,
}

impl Bytes<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N]> {
        let end = self.at.checked_add(N).filter(|&e| e <= self.data.len());
        let end =
            end.ok_or_else(|| Error::file(self.file, "cut short: not a whole COLMAP model"))?;
        let out = self.data[self.at..end].try_into().expect("N bytes");
        self.at = end;
        Ok(out)
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take()?))
    }
    fn i32(&mut self) -> Result<i32> {
        Ok(i32::from_le_bytes(self.take()?))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.take()?))
    }
    /// A count of items of `size` bytes each, refused when the file cannot hold them.
    fn count(&mut self, size: usize) -> Result<usize> {
        let n = self.u64()?;
        if n > ((self.data.len() - self.at) / size.max(1)) as u64 {
            return Err(Error::file(
                self.file,
                format!("cut short: it counts {n} items that the file cannot hold"),
            ));
        }
        Ok(n as usize)
    }
}

fn colmap_binary_image(file: &Path, data: &[u8], image: &str) -> Result<(Pose, i64)> {
    let mut b = Bytes { file, data, at: 0 };
    for _ in 0..b.count(64)? {
        b.i32()?;
        let q = [b.f64()?, b.f64()?, b.f64()?, b.f64()?];
        let t = DVec3::new(b.f64()?, b.f64()?, b.f64()?);
        let camera = b.i32()?;
        let name_end = data[b.at..]
            .iter()
            .position(|&c| c == 0)
            .ok_or_else(|| Error::file(file, "an image name without its end"))?;
        let name = String::from_utf8_lossy(&data[b.at..b.at + name_end]).into_owned();
        b.at += name_end + 1;
        let points = b.count(24)?;
        b.at += points * 24;
        if name == image {
            return Ok(((DQuat::from_xyzw(q[1], q[2], q[3], q[0]), t), camera as i64));
        }
    }
    Err(no_image(file, image))
}

fn colmap_binary_camera(file: &Path, data: &[u8], id: i64) -> Result<ColmapCamera> {
    let mut b = Bytes { file, data, at: 0 };
    for _ in 0..b.count(24)? {
        let this = b.i32()? as i64;
        let model_id = b.i32()?;
        let &(_, model, count, _) = MODELS
            .iter()
            .find(|m| m.0 == model_id)
            .ok_or_else(|| Error::file(file, format!("unknown camera model {model_id}")))?;
        let (width, height) = (b.u64()?, b.u64()?);
        let params = (0..count).map(|_| b.f64()).collect::<Result<Vec<f64>>>()?;
        if this == id {
            if params.iter().any(|p| !p.is_finite()) {
                return Err(Error::file(
                    file,
                    format!("camera {id}: a parameter is not finite"),
                ));
            }
            return Ok(ColmapCamera {
                model,
                width,
                height,
                params,
            });
        }
    }
    Err(Error::file(file, format!("no camera {id}")))
}

/// The camera of an fSpy project file (`.fspy`: "fspy", version 1, the
/// sizes of its JSON state and image, then both).
pub fn from_fspy(path: &Path) -> Result<Camera> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    let word = |i: usize| {
        data.get(4 * i..4 * i + 4)
            .map(|w| u32::from_le_bytes(w.try_into().expect("4")))
    };
    if word(0) != Some(u32::from_le_bytes(*b"fspy")) {
        return Err(Error::file(
            path,
            "not an fSpy project (it does not start with 'fspy')",
        ));
    }
    if word(1) != Some(1) {
        return Err(Error::file(
            path,
            format!("fSpy project version {:?}: arlux reads version 1", word(1)),
        ));
    }
    let size = word(2).unwrap_or(0) as usize;
    let state = data
        .get(16..16 + size)
        .ok_or_else(|| Error::file(path, "cut short: the state is longer than the file"))?;
    let state: serde_json::Value = serde_json::from_slice(state)
        .map_err(|e| Error::file(path, format!("its state is not JSON: {e}")))?;
    fspy_camera(path, &state["cameraParameters"])
}

fn fspy_camera(path: &Path, p: &serde_json::Value) -> Result<Camera> {
    if p.is_null() {
        return Err(Error::file(
            path,
            "the project has no solved camera (cameraParameters is null): finish the calibration in fSpy",
        ));
    }
    let bad = |what: &str| {
        Error::file(
            path,
            format!("cameraParameters.{what} is missing or not a number"),
        )
    };
    let num = |v: &serde_json::Value, what: &str| {
        v.as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| bad(what))
    };
    let (w, h) = (
        num(&p["imageWidth"], "imageWidth")?,
        num(&p["imageHeight"], "imageHeight")?,
    );
    let (hfov, vfov) = (
        num(&p["horizontalFieldOfView"], "horizontalFieldOfView")?,
        num(&p["verticalFieldOfView"], "verticalFieldOfView")?,
    );
    let rows = &p["cameraTransform"]["rows"];
    let m = |i: usize, j: usize| num(&rows[i][j], "cameraTransform");
    let column = |j: usize| -> Result<DVec3> { Ok(DVec3::new(m(0, j)?, m(1, j)?, m(2, j)?)) };
    // Camera to world, the camera looking along its −z with +y up (as in Blender).
    let (up, back, position) = (column(1)?, column(2)?, column(3)?);
    let ok = |v: f64| v > 0.0 && v < std::f64::consts::PI;
    if !(w >= 1.0 && h >= 1.0 && ok(hfov) && ok(vfov)) || up.length() < 1e-9 || back.length() < 1e-9
    {
        return Err(Error::file(
            path,
            "its camera is degenerate (image size, field of view or transform)",
        ));
    }
    // The principal point in fSpy's image plane: ±1 across the longer side, y up, 0 at the centre.
    let half = 0.5 * w.max(h);
    let (px, py) = (
        num(&p["principalPoint"]["x"], "principalPoint")?,
        num(&p["principalPoint"]["y"], "principalPoint")?,
    );
    let intrinsics = [
        0.5 * w / (0.5 * hfov).tan(),
        0.5 * h / (0.5 * vfov).tan(),
        0.5 * w + px * half,
        0.5 * h - py * half,
    ];
    solved(path, (w as u32, h as u32), position, -back, up, intrinsics)
}
