//! A material's texture: linear RGBA levels of a mip chain, sampled
//! bilinearly within a level and linearly between levels (trilinear), with
//! glTF's conventions: (0, 0) is the image's top-left corner, texel centres
//! at ((i + ½)/W, (j + ½)/H), repeat wrapping.
//!
//! Written here rather than taken from a crate: the image crates resize
//! whole images; none samples a mip chain at a point, which is all this is.

use glam::{Vec2, Vec4};
use rayon::prelude::*;

/// One mip level, `channels` values a texel (1: grey, 2: grey and alpha,
/// 3: RGB, 4: RGBA, as the image held them; a texel reads as RGBA, grey
/// in R, G and B, alpha 1 where there is none).
#[derive(Debug, Clone, PartialEq)]
struct Level {
    width: u32,
    height: u32,
    channels: u8,
    texels: Texels,
}

/// A level's values. Linear values are held in 16 bits (8 bytes an RGBA
/// texel, a quarter of f32: the smallest step an 8-bit sRGB texel makes in
/// linear light, 0.0003, is twenty of their steps). The full level of an
/// 8-bit image keeps the image's own codes (a byte a channel) and reads
/// them through a table of what each code decodes to in those 16 bits:
/// the same values, in half the memory or less (a 4096² RGB texture's
/// full level 50 MB, not 134).
#[derive(Debug, Clone, PartialEq)]
enum Texels {
    Codes {
        codes: Vec<u8>,
        /// Per code, its colour value and its alpha value.
        decoded: Box<Decoded>,
    },
    Linear(Vec<u16>),
}

/// Whether value `k` of a texel of `channels` values is its alpha (the
/// last of 2 or 4).
fn is_alpha(channels: u8, k: usize) -> bool {
    (channels == 2 || channels == 4) && k + 1 == channels as usize
}

/// A texel of `channels` values (`value(k)`) as RGBA: grey in R, G and B,
/// `opaque` where it has no alpha.
fn rgba<T: Copy>(channels: u8, value: impl Fn(usize) -> T, opaque: T) -> [T; 4] {
    match channels {
        1 => {
            let g = value(0);
            [g, g, g, opaque]
        }
        2 => {
            let g = value(0);
            [g, g, g, value(1)]
        }
        3 => [value(0), value(1), value(2), opaque],
        _ => [value(0), value(1), value(2), value(3)],
    }
}

/// How many texels of a channel hold each 8-bit code.
type CodeCounts = [u64; 256];

/// Per 8-bit code, its value as colour and as alpha (16-bit linear).
type Decoded = [[u16; 256]; 2];

impl Level {
    /// Of an image's level, per channel how many texels hold each code,
    /// and the codes' decoded values (None: a level of linear values).
    /// Counted side by side: whole counts, the same in any order and on
    /// any number of threads.
    fn code_counts(&self) -> Option<(Vec<CodeCounts>, &Decoded)> {
        let Texels::Codes { codes, decoded } = &self.texels else {
            return None;
        };
        let c = self.channels as usize;
        let add = |mut a: Vec<CodeCounts>, b: Vec<CodeCounts>| {
            for (x, y) in a.iter_mut().zip(&b) {
                x.iter_mut().zip(y).for_each(|(x, y)| *x += y);
            }
            a
        };
        let counts = (codes.par_chunks(c * 65536))
            .map(|chunk| {
                let mut counts = vec![[0u64; 256]; c];
                for texel in chunk.chunks_exact(c) {
                    for (k, &code) in texel.iter().enumerate() {
                        counts[k][code as usize] += 1;
                    }
                }
                counts
            })
            .reduce(|| vec![[0u64; 256]; c], add);
        Some((counts, decoded))
    }

    /// Each code's value in channel `k`, as a texel reads it.
    fn code_values(&self, decoded: &Decoded, k: usize) -> [f32; 256] {
        let table = &decoded[is_alpha(self.channels, k) as usize];
        std::array::from_fn(|code| f32::from(table[code]) / 65535.0)
    }

    /// The mean texel. An image's codes are counted ([`Level::code_counts`])
    /// and each code's value weighted by its count, in code order: exact
    /// products, 256 sums a channel, the same on any number of threads (a
    /// 2048² level summed texel by texel took 35 ms on one).
    fn mean(&self) -> Vec4 {
        let n = (self.width * self.height) as usize;
        let sum = match self.code_counts() {
            Some((counts, decoded)) => {
                let channel = |k: usize| -> f64 {
                    (counts[k].iter().zip(self.code_values(decoded, k)))
                        .map(|(&count, v)| count as f64 * f64::from(v))
                        .sum()
                };
                glam::DVec4::from_array(rgba(self.channels, channel, n as f64))
            }
            None => (0..n).map(|i| self.texel(i).as_dvec4()).sum(),
        };
        (sum / n as f64).as_vec4()
    }

    /// Each channel's largest texel value: of an image, the largest value
    /// among the codes it holds.
    fn max(&self) -> Vec4 {
        match self.code_counts() {
            Some((counts, decoded)) => {
                let channel = |k: usize| -> f32 {
                    (counts[k].iter().zip(self.code_values(decoded, k)))
                        .filter(|(count, _)| **count > 0)
                        .fold(0.0f32, |m, (_, v)| m.max(v))
                };
                Vec4::from_array(rgba(self.channels, channel, 1.0))
            }
            None => (0..(self.width * self.height) as usize)
                .map(|i| self.texel(i))
                .fold(Vec4::ZERO, Vec4::max),
        }
    }

    /// Texel `i` (row-major) in linear RGBA.
    fn texel(&self, i: usize) -> Vec4 {
        let c = self.channels as usize;
        let value = |k: usize| -> u16 {
            match &self.texels {
                Texels::Codes { codes, decoded } => {
                    decoded[is_alpha(self.channels, k) as usize][codes[i * c + k] as usize]
                }
                Texels::Linear(v) => v[i * c + k],
            }
        };
        unpack(rgba(self.channels, value, u16::MAX))
    }
}

fn pack(v: Vec4) -> [u16; 4] {
    (v.clamp(Vec4::ZERO, Vec4::ONE) * 65535.0 + 0.5)
        .to_array()
        .map(|c| c as u16)
}

/// `v` packed, the values of `channels` kept (see [`Level`]): grey in R,
/// alpha last.
fn pack_channels(v: Vec4, channels: u8, out: &mut Vec<u16>) {
    let p = pack(v);
    match channels {
        1 => out.push(p[0]),
        2 => out.extend([p[0], p[3]]),
        3 => out.extend([p[0], p[1], p[2]]),
        _ => out.extend(p),
    }
}

fn unpack(t: [u16; 4]) -> Vec4 {
    Vec4::from_array(t.map(f32::from)) / 65535.0
}

/// A texture ready to sample.
#[derive(Debug, Clone)]
pub struct Texture {
    levels: Vec<Level>,
    /// The full level's mean, summed once when first asked (objects from
    /// one file share their textures, and each asks: a 2048² level is 4 M
    /// texels).
    mean: std::sync::OnceLock<Vec4>,
}

/// Textures are their texels: whether the mean was asked yet does not count.
impl PartialEq for Texture {
    fn eq(&self, other: &Texture) -> bool {
        self.levels == other.levels
    }
}

/// The sRGB transfer function's inverse (IEC 61966-2-1), exact.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

impl Texture {
    /// A texture from 8-bit texels with `channels` per texel (1 to 4, in
    /// R, G, B, A order; missing ones as glTF reads them: grey, opaque).
    /// `srgb`: colour channels are sRGB-encoded and decoded here, before
    /// any filtering (alpha stays linear). None for an empty or short image.
    pub fn from_u8(
        width: u32,
        height: u32,
        channels: usize,
        data: &[u8],
        srgb: bool,
    ) -> Option<Texture> {
        let n = width as usize * height as usize;
        if n == 0 || !(1..=4).contains(&channels) || data.len() < n * channels {
            return None;
        }
        let decode = |c: u8, colour: bool| {
            let x = c as f32 / 255.0;
            if srgb && colour { srgb_to_linear(x) } else { x }
        };
        // Decoded once per code, not per texel (a 4096² texture's 50 M
        // `powf`s): each code's value as a texel packed from it holds it.
        let table = |colour: bool| -> [u16; 256] {
            std::array::from_fn(|c| pack(Vec4::splat(decode(c as u8, colour)))[0])
        };
        let level = Level {
            width,
            height,
            channels: channels as u8,
            texels: Texels::Codes {
                codes: data[..n * channels].to_vec(),
                decoded: Box::new([table(true), table(false)]),
            },
        };
        Some(Texture::from_level(level))
    }

    /// A texture from linear texels in [0, 1], row by row from the top.
    pub fn from_linear(width: u32, height: u32, texels: Vec<Vec4>) -> Texture {
        let packed = texels.into_par_iter().flat_map_iter(pack).collect();
        Texture::from_level(Level {
            width,
            height,
            channels: 4,
            texels: Texels::Linear(packed),
        })
    }

    /// A texture from its full level, its mip chain made.
    fn from_level(full: Level) -> Texture {
        let mut levels = vec![full];
        while let Some(next) = levels.last().and_then(half) {
            levels.push(next);
        }
        Texture {
            levels,
            mean: std::sync::OnceLock::new(),
        }
    }

    /// Every level's texels in linear RGBA, finest first.
    #[cfg(test)]
    pub(crate) fn texels(&self) -> Vec<Vec<Vec4>> {
        (self.levels.iter())
            .map(|l| {
                (0..(l.width * l.height) as usize)
                    .map(|i| l.texel(i))
                    .collect()
            })
            .collect()
    }

    /// Bytes the levels hold.
    pub fn memory_bytes(&self) -> usize {
        (self.levels.iter())
            .map(|l| match &l.texels {
                Texels::Codes { codes, .. } => codes.len() + 1024,
                Texels::Linear(v) => 2 * v.len(),
            })
            .sum()
    }

    /// Width and height of the full-resolution level.
    pub fn size(&self) -> (u32, u32) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// The mean of the full-resolution texels.
    pub fn mean(&self) -> Vec4 {
        *self.mean.get_or_init(|| self.levels[0].mean())
    }

    /// Each channel's largest full-resolution texel value.
    pub fn max(&self) -> Vec4 {
        self.levels[0].max()
    }

    /// The value at `uv` for a pixel footprint `texels` wide on the full
    /// level (≤ √2: bilinear on it, as glTF's LINEAR filter without
    /// mipmaps). The level is the one whose bilinear tent (variance 2^2k/6)
    /// has the variance of a box over the footprint (texels²/12):
    /// log2(texels / √2), half a level finer than the usual log2(texels),
    /// which blurs a box-filtered pixel (on `materials`' globe, the
    /// object's RMSE 0.030 against 0.012).
    pub fn sample(&self, uv: Vec2, texels: f32) -> Vec4 {
        let lod = if texels.is_finite() && texels > std::f32::consts::SQRT_2 {
            (texels * std::f32::consts::FRAC_1_SQRT_2)
                .log2()
                .min((self.levels.len() - 1) as f32)
        } else {
            0.0
        };
        let k = lod.floor() as usize;
        let t = lod - k as f32;
        let a = bilinear(&self.levels[k], uv);
        if t == 0.0 || k + 1 >= self.levels.len() {
            return a;
        }
        a.lerp(bilinear(&self.levels[k + 1], uv), t)
    }
}

/// The next mip level: 2×2 box average (an odd side keeps its last texel
/// by itself); None once both sides are 1.
fn half(l: &Level) -> Option<Level> {
    if l.width == 1 && l.height == 1 {
        return None;
    }
    let (w, h) = (l.width.div_ceil(2), l.height.div_ceil(2));
    let at =
        |x: u32, y: u32| l.texel((y.min(l.height - 1) * l.width + x.min(l.width - 1)) as usize);
    let texels: Vec<u16> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut row = Vec::with_capacity((w * l.channels as u32) as usize);
            for x in 0..w {
                let mean = (at(2 * x, 2 * y)
                    + at(2 * x + 1, 2 * y)
                    + at(2 * x, 2 * y + 1)
                    + at(2 * x + 1, 2 * y + 1))
                    * 0.25;
                pack_channels(mean, l.channels, &mut row);
            }
            row
        })
        .collect();
    Some(Level {
        width: w,
        height: h,
        channels: l.channels,
        texels: Texels::Linear(texels),
    })
}

fn bilinear(l: &Level, uv: Vec2) -> Vec4 {
    let (w, h) = (l.width as i64, l.height as i64);
    let x = uv.x as f64 * w as f64 - 0.5;
    let y = uv.y as f64 * h as f64 - 0.5;
    if !x.is_finite() || !y.is_finite() {
        return l.texel(0);
    }
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let at = |i: i64, j: i64| l.texel((j.rem_euclid(h) * w + i.rem_euclid(w)) as usize);
    let (i, j) = (x0 as i64, y0 as i64);
    let top = at(i, j).lerp(at(i + 1, j), fx);
    let bottom = at(i, j + 1).lerp(at(i + 1, j + 1), fx);
    top.lerp(bottom, fy)
}
