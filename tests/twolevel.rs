//! Two-level scenes (kdtrace::twolevel) on the largest shared scenes: instances
//! of dragon_200k and the bunny (rotated, non-uniformly scaled, mirrored,
//! translated 1e6 away, two overlapping), rays aimed at edges and vertices from
//! near and from 1e9 scene sizes away, judged against the exact reference on
//! each instance's object ray. Under CI a missing scene fails.

mod common;

use glam::{Affine3A, Mat3, Quat, Vec3};
use kdtrace::kdtree::traverse::{Traversal, Variant};
use kdtrace::kdtree::BuildConfig;
use kdtrace::scene::Scene;
use kdtrace::twolevel::{BottomLevel, Instance, TwoLevelScene};
use kdtrace::Ray;
use rayon::prelude::*;

#[test]
fn instanced_big_scenes_are_exact_for_their_object_rays() {
    let (Some(dragon), Some(bunny)) = (common::fetched_scene("dragon_200k.obj"), common::fetched_scene("bunny.obj"))
    else {
        return;
    };
    let config = BuildConfig::default();
    let geometries: Vec<BottomLevel> = [dragon, bunny]
        .iter()
        .enumerate()
        .map(|(id, path)| BottomLevel::new(id as u32, Scene::load(path).unwrap().triangles, &config))
        .collect();
    let size = geometries.iter().map(|g| g.tree.bounds.extent().max_element()).fold(0.0, f32::max);
    let mut rng = common::Rng(17);
    let rotation =
        |rng: &mut common::Rng| Quat::from_axis_angle(rng.unit_vector(), rng.range(0.0, std::f32::consts::TAU));
    let at = |i: f32| Vec3::new(2.0 * size * i, 0.0, 0.0);
    let transforms = [
        Affine3A::from_rotation_translation(rotation(&mut rng), at(0.0)),
        Affine3A::from_scale_rotation_translation(Vec3::new(0.3, 2.0, 1.0), rotation(&mut rng), at(1.0)),
        Affine3A::from_mat3_translation(Mat3::from_diagonal(Vec3::new(-1.0, 1.0, 1.0)), at(2.0)),
        Affine3A::from_rotation_translation(rotation(&mut rng), at(3.0) + Vec3::splat(1e6)),
        Affine3A::from_translation(at(4.0)),
        Affine3A::from_translation(at(4.0)), // overlapping: every hit there an exact tie
    ];
    let instances: Vec<Instance> = transforms
        .iter()
        .enumerate()
        .map(|(i, &transform)| Instance { geometry: i % 2, transform, instance_id: i as u32, mask: 0xff })
        .collect();
    let scene = TwoLevelScene::new(geometries, &instances).unwrap();
    let mut rays = Vec::new();
    for k in 0..60 {
        let inst = &instances[k % instances.len()];
        let tris = &scene.geometries()[inst.geometry].triangles;
        let [v0, v1, _] = tris[rng.below(tris.len())];
        let target =
            inst.transform.transform_point3(if k % 2 == 0 { v0 + (v1 - v0) * rng.range(0.0, 1.0) } else { v1 });
        let distance = if k % 3 == 0 { 1e9 } else { rng.range(0.2, 2.0) };
        let origin = target + rng.unit_vector() * size * distance;
        rays.push(Ray::new(origin, target - origin, 0.0, f32::INFINITY));
    }
    for (variant, any_hit) in [(Variant::Stack, false), (Variant::ShortStack, false), (Variant::Stack, true)] {
        let traversal = Traversal { any_hit, ..Traversal::closest(variant) };
        // (agrees, serious, hit) per ray; the exact reference in parallel.
        let verdicts: Vec<(bool, bool, bool)> = rays
            .par_iter()
            .map(|ray| {
                let hit = scene.trace(ray, 0xff, traversal);
                let v = if any_hit { scene.verdict_any(ray, &hit) } else { scene.verdict(ray, &hit) };
                (v.agrees(), v.is_serious(), hit.is_hit())
            })
            .collect();
        let count = |f: fn(&(bool, bool, bool)) -> bool| verdicts.iter().filter(|v| f(v)).count();
        let (agree, serious, hits) = (count(|v| v.0), count(|v| v.1), count(|v| v.2));
        eprintln!("{variant:?} any-hit {any_hit}: {agree}/{} agree, {hits} hits, {serious} serious", rays.len());
        assert!(agree * 1000 >= 995 * rays.len() && serious == 0, "{variant:?}: {agree} agree, {serious} serious");
        assert!(hits * 2 > rays.len(), "aimed rays should mostly hit ({hits})");
    }
}
