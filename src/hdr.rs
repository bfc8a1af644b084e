//! HDR radiance maps from 8-bit exposure brackets (Debevec & Malik 1997,
//! Loscos Appendix B): [`recover_response`] finds each channel's camera
//! response g(code) = ln(exposure) by least squares with a smoothness term
//! and a hat weight, from sample pixels chosen to cover the code range;
//! [`merge`] turns the brackets into radiance, each pixel a weighted mean
//! over the exposures that saw it well. Exposure times are t0·2^ev with t0
//! unknown, so radiance comes out up to one global factor (g(128) = 0).
//!
//! Pixels saturated in every exposure keep the darkest exposure's value and
//! pixels black in every exposure the brightest's; both are flagged.

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::error::{Error, Result};
use crate::image_io::Image;
use crate::util::cache::ContentHash;

/// One 8-bit exposure: codes per pixel and channel, and its EV offset.
#[derive(Debug, Clone, PartialEq)]
pub struct Exposure {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub codes: Vec<[u8; 3]>,
    pub ev: f64,
}

impl Exposure {
    /// Reads an 8-bit PNG/JPEG's raw codes (no sRGB decoding: the response
    /// curve is what maps codes to light).
    pub fn read(path: &Path, ev: f64) -> Result<Exposure> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
        let img = image::load_from_memory(&bytes)
            .map_err(|e| Error::file(path, format!("malformed image: {e}")))?;
        if !matches!(
            img.color(),
            image::ColorType::Rgb8
                | image::ColorType::Rgba8
                | image::ColorType::L8
                | image::ColorType::La8
        ) {
            return Err(Error::file(
                path,
                format!("brackets are 8-bit images; this one is {:?}", img.color()),
            ));
        }
        let rgb = img.to_rgb8();
        Ok(Exposure {
            path: path.to_path_buf(),
            width: rgb.width(),
            height: rgb.height(),
            codes: rgb.pixels().map(|p| p.0).collect(),
            ev,
        })
    }

    /// ln of the exposure time, t0 = 1.
    pub(crate) fn ln_time(&self) -> f64 {
        self.ev * std::f64::consts::LN_2
    }
}

/// Checks that brackets can be merged: at least two, one size, distinct EVs.
pub fn check_brackets(exposures: &[Exposure]) -> Result<()> {
    let Some(first) = exposures.first() else {
        return Err(Error::file(Path::new("brackets"), "no exposures given"));
    };
    if exposures.len() < 2 {
        return Err(Error::file(
            &first.path,
            "a single exposure: merging needs at least two different exposures",
        ));
    }
    for e in &exposures[1..] {
        if (e.width, e.height) != (first.width, first.height) {
            return Err(Error::file(
                &e.path,
                format!(
                    "is {}x{} but {} is {}x{}: brackets must be aligned shots of one size",
                    e.width,
                    e.height,
                    first.path.display(),
                    first.width,
                    first.height
                ),
            ));
        }
    }
    for (i, a) in exposures.iter().enumerate() {
        if let Some(b) = exposures[i + 1..].iter().find(|b| b.ev == a.ev) {
            return Err(Error::file(
                &b.path,
                format!(
                    "has the same EV ({}) as {}: each exposure needs its own",
                    a.ev,
                    a.path.display()
                ),
            ));
        }
    }
    Ok(())
}

/// The hat weight of Debevec & Malik: trusts mid-range codes most.
pub(crate) fn hat(z: u8) -> f64 {
    let z = z as f64;
    if z <= 127.5 { z } else { 255.0 - z }
}

/// g(code) = ln(exposure) for codes 0..=255, per channel.
pub(crate) type Response = [Vec<f64>; 3];

/// Recovers the response of each channel from `samples` pixels spread over
/// the code range of the middle exposure, with smoothness weight `lambda`.
pub fn recover_response(exposures: &[Exposure], samples: usize, lambda: f64) -> Result<Response> {
    check_brackets(exposures)?;
    let mut order: Vec<usize> = (0..exposures.len()).collect();
    order.sort_by(|&a, &b| exposures[a].ev.total_cmp(&exposures[b].ev));
    let middle = &exposures[order[order.len() / 2]];
    let n = middle.codes.len();
    let mut out: Response = [vec![], vec![], vec![]];
    for c in 0..3 {
        // Pick pixels whose middle-exposure code falls in each of `samples`
        // bins across 0..255, so that every part of the curve has data.
        let mut by_code: Vec<Vec<usize>> = vec![Vec::new(); 256];
        for i in 0..n {
            by_code[middle.codes[i][c] as usize].push(i);
        }
        let mut picked = Vec::new();
        let mut state = 0x5EED_u64 + c as u64;
        for k in 0..samples {
            let lo = k * 256 / samples;
            let hi = ((k + 1) * 256 / samples).max(lo + 1);
            let pool: Vec<usize> = (lo..hi).flat_map(|z| by_code[z].iter().copied()).collect();
            if !pool.is_empty() {
                let r = crate::util::rng::unit_random(&mut state);
                picked.push(pool[(r * pool.len() as f64) as usize % pool.len()]);
            }
        }
        out[c] = solve_response(exposures, &picked, c, lambda)?;
    }
    Ok(out)
}

/// The Debevec-Malik least-squares system for one channel, solved through
/// its normal equations (Cholesky): unknowns g(0..255) then ln E per sample.
fn solve_response(
    exposures: &[Exposure],
    pixels: &[usize],
    c: usize,
    lambda: f64,
) -> Result<Vec<f64>> {
    let m = 256 + pixels.len();
    let mut ata = vec![0.0f64; m * m];
    let mut atb = vec![0.0f64; m];
    let mut add_row = |entries: &[(usize, f64)], rhs: f64| {
        for &(i, a) in entries {
            atb[i] += a * rhs;
            for &(j, b) in entries {
                ata[i * m + j] += a * b;
            }
        }
    };
    for (k, &p) in pixels.iter().enumerate() {
        for e in exposures {
            let z = e.codes[p][c];
            let w = hat(z) + 1e-3;
            add_row(&[(z as usize, w), (256 + k, -w)], w * e.ln_time());
        }
    }
    // g(128) = 0 fixes the unknown scale; smoothness keeps g well-posed.
    add_row(&[(128, 1e3)], 0.0);
    for z in 1..255 {
        let w = lambda * (hat(z as u8) + 1.0);
        add_row(&[(z - 1, w), (z, -2.0 * w), (z + 1, w)], 0.0);
    }
    let x = cholesky_solve(&mut ata, &atb, m).ok_or_else(|| {
        Error::file(
            &exposures[0].path,
            "the brackets do not determine a response curve (too few distinct exposures or codes)",
        )
    })?;
    Ok(x[..256].to_vec())
}

/// Solves the symmetric positive definite system A x = b in place.
fn cholesky_solve(a: &mut [f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d <= 1e-300 || !d.is_finite() {
            return None;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    let mut y = b.to_vec();
    for i in 0..n {
        for k in 0..i {
            y[i] -= a[i * n + k] * y[k];
        }
        y[i] /= a[i * n + i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            y[i] -= a[k * n + i] * y[k];
        }
        y[i] /= a[i * n + i];
    }
    Some(y)
}

/// A merged radiance map.
#[derive(Debug, Clone, PartialEq)]
pub struct Merged {
    /// Radiance up to one global factor (t0 = 1, g(128) = 0).
    pub image: Image,
    /// Pixels saturated in every exposure (kept from the darkest one).
    pub saturated: Vec<bool>,
    /// Pixels black in every exposure (kept from the brightest one).
    pub black: Vec<bool>,
}

/// Merges brackets with a response: per pixel and channel, the hat-weighted
/// mean of g(Z) − ln t over the exposures.
pub fn merge(exposures: &[Exposure], response: &Response) -> Result<Merged> {
    check_brackets(exposures)?;
    let first = &exposures[0];
    let n = first.codes.len();
    let darkest = exposures
        .iter()
        .min_by(|a, b| a.ev.total_cmp(&b.ev))
        .expect("checked non-empty");
    let brightest = exposures
        .iter()
        .max_by(|a, b| a.ev.total_cmp(&b.ev))
        .expect("checked non-empty");
    let mut image = Image::new(first.width, first.height);
    let mut saturated = vec![false; n];
    let mut black = vec![false; n];
    for i in 0..n {
        let mut px = Vec3::ZERO;
        for c in 0..3 {
            let (mut num, mut den) = (0.0, 0.0);
            for e in exposures {
                let z = e.codes[i][c];
                let w = hat(z);
                num += w * (response[c][z as usize] - e.ln_time());
                den += w;
            }
            let ln_e = if den > 0.0 {
                num / den
            } else if darkest.codes[i][c] == 255 {
                saturated[i] = true;
                response[c][255] - darkest.ln_time()
            } else {
                black[i] = true;
                response[c][brightest.codes[i][c] as usize] - brightest.ln_time()
            };
            px[c] = if black[i] && brightest.codes[i][c] == 0 {
                0.0
            } else {
                ln_e.exp() as f32
            };
        }
        image.pixels[i] = px;
    }
    Ok(Merged {
        image,
        saturated,
        black,
    })
}

/// Merges a scene's brackets, through a cache next to the scene: the merge
/// is redone only when a bracket's bytes or EV change.
pub(crate) fn merge_cached(scene_dir: &Path, brackets: &[(PathBuf, f64)]) -> Result<Image> {
    let mut hash = ContentHash::default();
    let mut feed = |bytes: &[u8]| hash.feed(bytes);
    let mut exposures = Vec::with_capacity(brackets.len());
    for (path, ev) in brackets {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
        feed(&bytes);
        feed(&ev.to_le_bytes());
        exposures.push((path, *ev));
    }
    let cache = hash.entry(scene_dir, "merged", "exr");
    if cache.is_file()
        && let Ok(img) = crate::image_io::read_image(&cache)
    {
        return Ok(img);
    }
    let exposures: Vec<Exposure> = exposures
        .iter()
        .map(|(p, ev)| Exposure::read(p, *ev))
        .collect::<Result<_>>()?;
    let response = recover_response(&exposures, 64, 20.0)?;
    let merged = merge(&exposures, &response)?;
    // The cache is a convenience: failing to write it is not an error.
    if std::fs::create_dir_all(cache.parent().expect("has a parent")).is_ok() {
        let _ = crate::image_io::write_exr(
            &cache,
            merged.image.width,
            merged.image.height,
            &[crate::image_io::ExrLayer::Rgb("", &merged.image)],
        );
    }
    Ok(merged.image)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exposure(codes: Vec<[u8; 3]>, ev: f64) -> Exposure {
        Exposure {
            path: PathBuf::from(format!("ev{ev}.png")),
            width: codes.len() as u32,
            height: 1,
            codes,
            ev,
        }
    }

    #[test]
    fn pixels_saturated_or_black_everywhere_are_kept_and_flagged() {
        // A linear camera: g(z) = ln(z/128).
        let g: Vec<f64> = (0..256).map(|z| ((z.max(1)) as f64 / 128.0).ln()).collect();
        let response: Response = [g.clone(), g.clone(), g];
        let e = [
            exposure(vec![[255; 3], [0; 3], [64; 3]], -1.0),
            exposure(vec![[255; 3], [0; 3], [128; 3]], 0.0),
        ];
        let m = merge(&e, &response).unwrap();
        assert_eq!((m.saturated[0], m.black[0]), (true, false));
        assert_eq!((m.saturated[1], m.black[1]), (false, true));
        assert!(!m.saturated[2] && !m.black[2]);
        // Saturated: the darkest exposure's value, exp(g(255)) / 2^-1.
        assert!(
            (m.image.pixels[0].x - (255.0 / 128.0 * 2.0)).abs() < 1e-5,
            "{}",
            m.image.pixels[0].x
        );
        assert_eq!(m.image.pixels[1], Vec3::ZERO);
        // Both exposures agree on the third pixel: radiance 1 at t0 = 1.
        assert!((m.image.pixels[2].x - 1.0).abs() < 1e-6);
    }
}
