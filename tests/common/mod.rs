//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::Arc;

use glam::Vec3;
use kdtrace::gpu::{ContextOptions, GpuContext, Validation};
use kdtrace::Ray;

/// A headless context on the default device (lavapipe here) with the validation
/// layer on when installed — required when `CI` is set, so CI cannot skip it.
pub fn context() -> Arc<GpuContext> {
    let ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false");
    let validation = if ci { Validation::Required } else { Validation::IfAvailable };
    let options = ContextOptions { device: std::env::var("KDTRACE_DEVICE").ok(), validation };
    GpuContext::headless(&options).expect("creating a Vulkan device (run tools/setup)")
}

/// Fails the test when the validation layer reported anything.
pub fn assert_validation_clean(ctx: &GpuContext) {
    let messages = ctx.take_validation_messages();
    assert!(messages.is_empty(), "validation messages:\n{}", messages.join("\n"));
}

pub fn scene_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name)
}

/// A small seeded generator (xorshift64*), so tests need no extra crate.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }
    pub fn unit_vector(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            let l = v.length_squared();
            if l > 1e-4 && l <= 1.0 {
                return v / l.sqrt();
            }
        }
    }
}

/// Rays from random points of the box (grown by 10%) in random directions.
pub fn random_rays(rng: &mut Rng, min: Vec3, max: Vec3, count: usize) -> Vec<Ray> {
    let pad = (max - min) * 0.1;
    let (lo, hi) = (min - pad, max + pad);
    (0..count)
        .map(|_| {
            let o = Vec3::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y), rng.range(lo.z, hi.z));
            Ray::new(o, rng.unit_vector(), 0.0, f32::INFINITY)
        })
        .collect()
}
