//! A project that depends on kdtrace (tools/check-dependent): one triangle, a
//! few rays traced on a headless device, under the validation layer when it is
//! installed. Only kdtrace's public API and its re-exported `glam`, `ash` and
//! `gpu_allocator`.

use kdtrace::glam::Vec3;
use kdtrace::gpu::{shaders, ContextOptions, GpuContext, Validation};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::{consts, Ray};

fn main() -> kdtrace::Result<()> {
    // The re-exports are the crates of kdtrace's public types.
    let _: kdtrace::ash::vk::Buffer = kdtrace::ash::vk::Buffer::null();
    let _ = kdtrace::gpu_allocator::MemoryLocation::GpuOnly;
    assert_eq!(std::fs::read_to_string(env!("KDTRACE_GLSL")).unwrap(), shaders::HEADER);

    let triangles = vec![[Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]];
    let tree = KdTree::build(&triangles, &BuildConfig::default());
    let options = ContextOptions { validation: Validation::IfAvailable, ..ContextOptions::from_env() };
    let ctx = GpuContext::headless(&options)?;
    let mut tracer = Tracer::new(&ctx, &tree, &triangles)?;
    let inf = f32::INFINITY;
    let rays = [
        Ray::new(Vec3::new(0.0, 0.0, -1.0), Vec3::Z, 0.0, inf),   // hits at t = 1
        Ray::new(Vec3::new(0.25, -0.5, 4.0), -Vec3::Z, 0.0, inf), // from behind, t = 4
        Ray::new(Vec3::new(2.0, 2.0, -1.0), Vec3::Z, 0.0, inf),   // beside it
        Ray::new(Vec3::new(0.0, 0.0, -1.0), Vec3::Z, 0.0, 0.5),   // ends before it
    ];
    let hits = tracer.trace(&rays, &TraceOptions::default())?.hits;
    let expected = [(0, 1.0), (0, 4.0), (consts::PRIM_MISS, inf), (consts::PRIM_MISS, inf)];
    for (i, (hit, &(prim, t))) in hits.iter().zip(&expected).enumerate() {
        assert_eq!((hit.prim_id, hit.t), (prim, t), "ray {i}: {hit:?}");
    }
    drop(tracer);
    ctx.check_validation()?;
    println!(
        "dependent: {} rays traced on {} (validation {})",
        rays.len(),
        ctx.info.name,
        if ctx.validation_enabled() { "on, clean" } else { "not installed" }
    );
    Ok(())
}
