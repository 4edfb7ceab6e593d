//! Ray batches for `kdtrace rays`, tests and benchmarks.

use glam::Vec3;

use crate::geom::{Aabb, Ray};

/// A small seeded generator (SplitMix64, Steele, Lea & Flood 2014): reproducible
/// batches without a crate. The one generator of the library, its tests and
/// benchmarks.
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

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    /// Uniform in `0..n` (`n > 0`; the modulo bias is negligible for small `n`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
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

/// An order that groups incoherent rays into coherent runs, for packet tracing:
/// sorted by direction octant, then by the 3D Morton code of the origin in
/// `bounds` (10 bits per axis), then by the direction's octahedral cell. Returns
/// the permutation: `order[i]` is the index of the ray to trace `i`-th. Invalid
/// rays sort last, in their original order.
pub fn coherent_order(rays: &[Ray], bounds: &Aabb) -> Vec<u32> {
    fn spread(v: u32) -> u64 {
        let mut x = (v & 0x3FF) as u64;
        x = (x | (x << 16)) & 0x0300_00FF;
        x = (x | (x << 8)) & 0x0300_F00F;
        x = (x | (x << 4)) & 0x030C_30C3;
        x = (x | (x << 2)) & 0x0924_9249;
        x
    }
    let extent = bounds.extent().max(Vec3::splat(f32::MIN_POSITIVE));
    let quantize = |x: f32, lo: f32, size: f32| (((x - lo) / size).clamp(0.0, 1.0) * 1023.0) as u32;
    let key = |r: &Ray| -> u64 {
        if !r.is_valid() {
            return u64::MAX;
        }
        let d = Vec3::from(r.dir);
        let octant = (d.x < 0.0) as u64 | ((d.y < 0.0) as u64) << 1 | ((d.z < 0.0) as u64) << 2;
        let o = Vec3::from(r.origin);
        let morton = spread(quantize(o.x, bounds.min.x, extent.x))
            | spread(quantize(o.y, bounds.min.y, extent.y)) << 1
            | spread(quantize(o.z, bounds.min.z, extent.z)) << 2;
        let n = d / d.abs().element_sum();
        let cell = (quantize(n.x, -1.0, 2.0) >> 7) << 3 | (quantize(n.y, -1.0, 2.0) >> 7);
        octant << 60 | morton << 6 | cell as u64
    };
    let mut order: Vec<u32> = (0..rays.len() as u32).collect();
    order.sort_by_key(|&i| (key(&rays[i as usize]), i));
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coherent_order_is_a_permutation_grouped_by_octant() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let mut rays = random_rays(&b, 1000, 3);
        rays[5].dir = [f32::NAN, 0.0, 0.0];
        let order = coherent_order(&rays, &b);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert!(sorted.iter().copied().eq(0..1000));
        assert_eq!(*order.last().unwrap(), 5, "invalid rays sort last");
        let octant = |i: u32| {
            let d = rays[i as usize].dir;
            (d[0] < 0.0) as u8 | ((d[1] < 0.0) as u8) << 1 | ((d[2] < 0.0) as u8) << 2
        };
        let changes = order[..999].windows(2).filter(|w| octant(w[0]) != octant(w[1])).count();
        assert!(changes <= 7, "octants form contiguous runs ({changes} changes)");
    }
}
