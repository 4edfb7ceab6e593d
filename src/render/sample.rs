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

/// The second Sobol dimension: its generator matrix is Pascal's triangle mod 2,
/// so digit r of the point is the parity of the index bits that contain r's
/// bits (Lucas); five shift-and-mask steps, then the digits' bit order. The
/// same closed form as `sobol_second` in `render.glsl`.
fn sobol_second(index: u32) -> u32 {
    let mut y = index;
    y ^= (y >> 1) & 0x5555_5555;
    y ^= (y >> 2) & 0x3333_3333;
    y ^= (y >> 4) & 0x0f0f_0f0f;
    y ^= (y >> 8) & 0x00ff_00ff;
    y ^= y >> 16;
    y.reverse_bits()
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

#[cfg(test)]
mod tests {
    /// The closed form against the definition: the XOR of the direction numbers
    /// (v_0 = 2^31, v_k = v_(k-1) ^ v_(k-1) >> 1) of the index's set bits.
    #[test]
    fn sobol_second_closed_form_equals_the_direction_numbers() {
        let by_directions = |index: u32| {
            let (mut result, mut v, mut i) = (0u32, 1u32 << 31, index);
            while i != 0 {
                if i & 1 != 0 {
                    result ^= v;
                }
                v ^= v >> 1;
                i >>= 1;
            }
            result
        };
        let mut x = 0x1234_5678u32;
        for k in 0..100_000u32 {
            x = super::hash_u32(x ^ k);
            for index in [k, x, u32::MAX - k] {
                assert_eq!(super::sobol_second(index), by_directions(index), "index {index:#x}");
            }
        }
    }
}
