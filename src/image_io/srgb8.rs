//! Linear radiance to 8-bit sRGB by table: the same byte as
//! `(linear_to_srgb(c) * 255).round()` for every `f32`, without a `powf`
//! per channel (which took 3 ms of each of `serve`'s 0.2 MP frames, more
//! than the rest of what the server adds to an update). Crates that encode
//! by table (`fast-srgb8`) round within half a step of the exact value, not
//! to it: PNGs written before and after would differ in a byte here and
//! there, and the served image from the written one.

use std::sync::OnceLock;

use super::linear_to_srgb;

/// Bits of an `f32` below the bucket index: a bucket spans 2^-8 of an
/// octave, where the code rises by at most a quarter step (its steepest,
/// just below 1.0), so at most one code boundary lies in a bucket.
const SHIFT: u32 = 15;

/// The bits of 1.0, the largest value encoded (larger ones clamp).
const ONE: u32 = 0x3F80_0000;

struct Table {
    /// The code at each bucket's first value.
    first: Vec<u8>,
    /// `above[k]`: the least value whose code is more than `k`.
    above: [f32; 256],
}

fn exact(c: f32) -> u8 {
    (linear_to_srgb(c) * 255.0).round() as u8
}

fn table() -> &'static Table {
    static TABLE: OnceLock<Table> = OnceLock::new();
    TABLE.get_or_init(|| {
        let first = (0..=ONE >> SHIFT)
            .map(|b| exact(f32::from_bits(b << SHIFT)))
            .collect();
        let mut above = [f32::INFINITY; 256];
        for (k, slot) in above.iter_mut().enumerate().take(255) {
            // The least bits (of non-negative floats, ordered as their
            // values) whose code exceeds k: bisection over [0, 1.0].
            let (mut lo, mut hi) = (0u32, ONE);
            if exact(f32::from_bits(hi)) as usize <= k {
                continue;
            }
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                match exact(f32::from_bits(mid)) as usize > k {
                    true => hi = mid,
                    false => lo = mid + 1,
                }
            }
            *slot = f32::from_bits(lo);
        }
        Table { first, above }
    })
}

/// `(linear_to_srgb(c) * 255).round()` as a byte: NaN and below 0 give 0,
/// above 1 gives 255.
pub fn linear_to_srgb8(c: f32) -> u8 {
    let c = if c.is_finite() {
        c.clamp(0.0, 1.0)
    } else {
        0.0
    };
    // +0.0: a clamped -0.0 has the sign bit set.
    let bits = (c + 0.0).to_bits();
    let t = table();
    let code = t.first[(bits >> SHIFT) as usize];
    code + (c >= t.above[code as usize]) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_float_in_range_encodes_as_the_exact_rounding_does() {
        // Every 61st bit pattern of [0, 1] (and the ends), and around each
        // code's boundary.
        let mut checked = 0;
        for bits in (0..=ONE).step_by(61).chain([ONE, 1]) {
            let c = f32::from_bits(bits);
            assert_eq!(linear_to_srgb8(c), exact(c), "{c:e}");
            checked += 1;
        }
        for &b in table().above.iter().filter(|a| a.is_finite()) {
            for bits in b.to_bits().saturating_sub(3)..=b.to_bits() + 3 {
                let c = f32::from_bits(bits);
                assert_eq!(linear_to_srgb8(c), exact(c), "{c:e}");
            }
        }
        assert!(checked > 15_000_000);
    }

    #[test]
    fn out_of_range_and_non_finite_values_clamp() {
        for (c, code) in [
            (-1.0, 0),
            (-0.0, 0),
            (f32::NAN, 0),
            (f32::NEG_INFINITY, 0),
            (2.0, 255),
            (f32::INFINITY, 0),
            (f32::MAX, 255),
            (1e-30, 0),
        ] {
            assert_eq!(linear_to_srgb8(c), code, "{c}");
        }
    }
}
