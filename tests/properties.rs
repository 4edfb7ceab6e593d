//! Property tests (proptest) on the CPU: random triangle soups and rays through
//! the builder and the CPU twins, judged by the exact reference; and the OBJ
//! loader and the ray-file reader on arbitrary input. No panic, no hang, no
//! serious error. (The GPU runs the same traversals bit for bit: tests/gpu_trace.rs.)

use glam::Vec3;
use kdtrace::exact::{closest_exact, judge};
use kdtrace::kdtree::links::TreeLinks;
use kdtrace::kdtree::traverse::{trace_ray, SceneRef, Traversal, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::scene::Scene;
use kdtrace::Ray;
use proptest::prelude::*;

/// A coordinate: mostly on a coarse grid (shared vertices, edges, coplanar and
/// axis-aligned triangles, split planes through vertices), sometimes anywhere.
fn coord() -> impl Strategy<Value = f32> {
    prop_oneof![3 => (-8i32..=8).prop_map(|i| i as f32 * 0.5), 1 => -4.0f32..4.0]
}

fn point() -> impl Strategy<Value = Vec3> {
    (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn soup() -> impl Strategy<Value = Vec<[Vec3; 3]>> {
    prop::collection::vec((point(), point(), point()).prop_map(|(a, b, c)| [a, b, c]), 1..40)
}

/// Rays from anywhere, aimed at a vertex, an edge point or anywhere.
fn rays(tris: &[[Vec3; 3]]) -> impl Strategy<Value = Vec<Ray>> {
    let tris = tris.to_vec();
    prop::collection::vec((point(), 0usize..1000, 0usize..3, 0u8..3, -3.0f32..3.0), 1..24).prop_map(move |items| {
        items
            .into_iter()
            .map(|(origin, t, k, kind, s)| {
                let tri = tris[t % tris.len()];
                let target = match kind {
                    0 => tri[k],
                    1 => tri[k] + 0.5 * (tri[(k + 1) % 3] - tri[k]),
                    _ => Vec3::splat(s),
                };
                let dir = if target == origin { Vec3::X } else { target - origin };
                Ray::new(origin, dir, 0.0, f32::INFINITY)
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Builds a valid tree, and every CPU twin answers every ray without a
    /// serious error against the exact reference.
    #[test]
    fn soups_build_and_trace_without_serious_errors((tris, rays) in soup().prop_flat_map(|t| {
        let r = rays(&t);
        (Just(t), r)
    })) {
        let tree = KdTree::build(&tris, &BuildConfig::default());
        prop_assert!(tree.check(tris.len()).is_ok(), "{:?}", tree.check(tris.len()));
        let links = TreeLinks::new(&tree.nodes, tree.bounds);
        let scene = SceneRef::new(&tree, &tris).with_links(&links);
        for ray in &rays {
            let exact = closest_exact(&tris, ray);
            for variant in [Variant::Stack, Variant::Restart, Variant::PushDownShortStack, Variant::Ropes] {
                let (hit, _) = trace_ray(&scene, ray, Traversal::closest(variant));
                let (verdict, _) = judge(&tris, ray, &hit, &exact);
                prop_assert!(!verdict.is_serious(), "{variant:?}: {ray:?} -> {hit:?}: {verdict:?}, exact {exact:?}");
            }
        }
    }

    /// Arbitrary ray-file bytes: an error or rays, never a panic.
    #[test]
    fn ray_files_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        match kdtrace::io::rays_from_bytes(&bytes) {
            Ok(rays) => prop_assert_eq!(rays.len() * 32, bytes.len()),
            Err(_) => prop_assert!(bytes.len() % 32 != 0),
        }
    }

    /// Arbitrary OBJ-like text: a scene or an error, never a panic.
    #[test]
    fn obj_text_never_panics(lines in prop::collection::vec(prop_oneof![
        (coord(), coord(), coord()).prop_map(|(x, y, z)| format!("v {x} {y} {z}")),
        (-5i32..8, -5i32..8, -5i32..8).prop_map(|(a, b, c)| format!("f {a} {b} {c}")),
        "[ -~]{0,20}".prop_map(|s| s),
        Just("v nan 0 0".to_string()),
        Just("v 1e39 0 0".to_string()),
        Just("f 1/2/3 4//5".to_string()),
        Just("mtllib missing.mtl".to_string()),
    ], 0..30)) {
        let path = std::env::temp_dir().join(format!("kdtrace-prop-{}.obj", std::process::id()));
        std::fs::write(&path, lines.join("\n")).unwrap();
        let _ = Scene::load(&path);
        std::fs::remove_file(&path).ok();
    }
}
