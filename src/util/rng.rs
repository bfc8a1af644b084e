//! Deterministic randomness keyed by what it is for (a pixel and a sample, a
//! vertex and a direction), so that every image is bit-identical whatever
//! the thread count and the order work is done in. `rand`'s generators are
//! streams: drawing from one per pixel would need a seeded generator per
//! pixel and sample, which is what a counter-based hash gives directly.

/// SplitMix64 of two words: a deterministic per-(pixel, sample) hash.
pub fn hash2(a: u64, b: u64) -> u64 {
    let mut z = a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_add(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) from a SplitMix64 stream.
pub(crate) fn unit_random(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    (hash2(*state, 0) >> 11) as f64 / (1u64 << 53) as f64
}
