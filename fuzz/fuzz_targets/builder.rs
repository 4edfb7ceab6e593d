//! The builder on arbitrary triangles (every f32 bit pattern, NaN and inf
//! included): it terminates with a tree that passes its own check, and the
//! stack traversal of a few rays through it finishes.
#![no_main]
use glam::Vec3;
use kdtrace::kdtree::traverse::{trace_ray, SceneRef, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::Ray;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let floats: Vec<f32> = data.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    let tris: Vec<[Vec3; 3]> = floats
        .chunks_exact(9)
        .take(2000)
        .map(|f| [Vec3::new(f[0], f[1], f[2]), Vec3::new(f[3], f[4], f[5]), Vec3::new(f[6], f[7], f[8])])
        .collect();
    if tris.is_empty() {
        return;
    }
    let tree = KdTree::build(&tris, &BuildConfig::default());
    tree.check(tris.len()).expect("the builder's tree passes its check");
    let scene = SceneRef::new(&tree, &tris);
    for t in tris.iter().take(8) {
        let ray = Ray::new(Vec3::ZERO, t[0] - Vec3::splat(0.5), 0.0, f32::INFINITY);
        let (hit, _) = trace_ray(&scene, &ray, Variant::Stack);
        assert_ne!(hit.prim_id, kdtrace::consts::PRIM_INCOMPLETE, "traversal did not finish");
    }
});
