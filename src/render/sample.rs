//! The host twin of the renderer's sample sequence (`ld2` of `render.glsl`).

fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

fn owen_scramble(x: u32, seed: u32) -> u32 {
    let mut x = x.reverse_bits().wrapping_add(seed);
    for m in [0x6c50_b47c_u32, 0xb82f_1e52, 0xc7af_e638, 0x8d22_f6e6] {
        x ^= x.wrapping_mul(m);
    }
    x.reverse_bits()
}

fn sobol_second(index: u32) -> u32 {
    let (mut result, mut v, mut i) = (0u32, 1u32 << 31, index);
    while i != 0 {
        if i & 1 != 0 {
            result ^= v;
        }
        v ^= v >> 1;
        i >>= 1;
    }
    result
}

/// The host twin of `ld2` in `render.glsl` (same construction): the point of
/// the scrambled 2D Sobol set for (`pixel`, `sample`, dimension `pair`, `seed`).
/// Used for the one jitter per sample of rasterized first hits, which the host
/// passes to both the projection and the camera rays.
pub fn ld2(pixel: u32, sample: u32, pair: u32, seed: u32) -> [f32; 2] {
    let h = hash_u32(pixel.wrapping_mul(0x9e37_79b9) ^ hash_u32(pair.wrapping_mul(0x85eb_ca6b) ^ hash_u32(seed)));
    let i = owen_scramble(sample, h);
    let x = owen_scramble(i.reverse_bits(), hash_u32(h ^ 0x68bc_21eb));
    let y = owen_scramble(sobol_second(i), hash_u32(h ^ 0x02e5_be93));
    [(x >> 8) as f32 / 16_777_216.0, (y >> 8) as f32 / 16_777_216.0]
}
