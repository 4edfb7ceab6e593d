//! Ray batches for `kdtrace rays`, tests and benchmarks.

use glam::Vec3;

use crate::geom::{Aabb, Ray};

/// A small seeded generator (SplitMix64): reproducible batches without a crate.
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 uniformly distributed bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A uniformly distributed unit vector.
    pub fn unit_vector(&mut self) -> Vec3 {
        let z = 2.0 * self.next_f32() - 1.0;
        let phi = std::f32::consts::TAU * self.next_f32();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// `count` rays from uniform points of `bounds` in uniform directions, `[0, inf)`.
pub fn random_rays(bounds: &Aabb, count: usize, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64(seed);
    let extent = bounds.extent();
    (0..count)
        .map(|_| {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            Ray::new(bounds.min + p * extent, rng.unit_vector(), 0.0, f32::INFINITY)
        })
        .collect()
}
