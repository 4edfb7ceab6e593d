//! Tests of two-level scenes (src/twolevel.rs): the contract against the exact
//! reference on instanced scenes, front faces, masks, updates and errors.

use glam::{Mat3, Quat};

use super::*;
use crate::kdtree::traverse::Variant;
use crate::kdtree::BuildConfig;

/// A closed, bumpy sphere of shared vertices: edges and vertices everywhere.
pub(super) fn sphere(rings: usize, segments: usize) -> Vec<[Vec3; 3]> {
    let p = |i: usize, j: usize| {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        let phi = std::f32::consts::TAU * (j % segments) as f32 / segments as f32;
        let r = 1.0 + 0.1 * ((3 * i + 5 * j) % 7) as f32 / 7.0;
        Vec3::new(r * theta.sin() * phi.cos(), r * theta.cos(), r * theta.sin() * phi.sin())
    };
    let mut tris = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            if i > 0 {
                tris.push([a, c, d]);
            }
            if i + 1 < rings {
                tris.push([a, b, c]);
            }
        }
    }
    tris
}

fn bottom(id: u32, triangles: Vec<[Vec3; 3]>) -> BottomLevel {
    BottomLevel::new(id, triangles, &BuildConfig::default())
}

pub(super) struct Rng(pub(super) u64);

impl Rng {
    pub(super) fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
    pub(super) fn unit(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.next(), self.next(), self.next()) * 2.0 - Vec3::ONE;
            if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }
}

/// The categories of placements the contract must hold through.
fn placements(category: &str, rng: &mut Rng) -> Vec<Instance> {
    let rotation = |rng: &mut Rng| Quat::from_axis_angle(rng.unit(), std::f32::consts::TAU * rng.next());
    let at = |i: usize| Vec3::new(3.0 * (i % 4) as f32, 3.0 * (i / 4) as f32, 0.0);
    (0..8)
        .map(|i| {
            let transform = match category {
                "rotated" => Affine3A::from_rotation_translation(rotation(rng), at(i)),
                "scaled" => Affine3A::from_scale_rotation_translation(
                    Vec3::new(0.2 + rng.next(), 1.0 + 4.0 * rng.next(), 0.05 + rng.next()),
                    rotation(rng),
                    at(i),
                ),
                "mirrored" => Affine3A::from_mat3_translation(
                    Mat3::from_quat(rotation(rng)) * Mat3::from_diagonal(Vec3::new(-1.0, 1.0, 1.0)),
                    at(i),
                ),
                "far" => Affine3A::from_rotation_translation(rotation(rng), at(i) + Vec3::new(3.0e6, -1.0e6, 2.0e6)),
                // Pairs placed at the same spot: every hit is an exact tie of two instances.
                "overlapping" => Affine3A::from_rotation_translation(Quat::IDENTITY, at(i / 2) * 0.5),
                other => panic!("no category {other}"),
            };
            Instance { geometry: i % 2, transform, instance_id: 100 + i as u32, mask: 0xff }
        })
        .collect()
}

/// Rays aimed at triangle edges and vertices of random instances (hard), and
/// random rays through the scene box.
fn rays(scene: &TwoLevelScene, instances: &[Instance], rng: &mut Rng, count: usize) -> Vec<Ray> {
    let world = scene.placed.iter().fold(Aabb::EMPTY, |b, p| b.union(p.world_box));
    let size = world.extent().max_element();
    (0..count)
        .map(|k| {
            let inst = &instances[(rng.next() * instances.len() as f32) as usize % instances.len()];
            let tris = &scene.geometries[inst.geometry].triangles;
            let [v0, v1, v2] = tris[(rng.next() * tris.len() as f32) as usize % tris.len()];
            let target_obj = match k % 3 {
                0 => v0 + (v1 - v0) * rng.next(), // an edge
                1 => v1,                          // a vertex
                _ => (v0 + v1 + v2) / 3.0,
            };
            let target = inst.transform.transform_point3(target_obj);
            let origin = if k % 5 == 4 {
                world.min + (world.max - world.min) * Vec3::new(rng.next(), rng.next(), rng.next())
            } else {
                target + rng.unit() * size * (0.2 + rng.next())
            };
            Ray::new(origin, target - origin, 0.0, f32::INFINITY)
        })
        .collect()
}

/// Every placement category, every robust variant, closest hit: ≥ 99.5 %
/// agreement with the exact answers of the object rays, nothing serious.
#[test]
fn instanced_hits_are_exact_for_their_object_rays() {
    let geometries = vec![bottom(7, sphere(10, 16)), bottom(9, sphere(6, 9))];
    let mut scene = TwoLevelScene::new(geometries, &[]).unwrap();
    let mut rng = Rng(3);
    for category in ["rotated", "scaled", "mirrored", "far", "overlapping"] {
        let instances = placements(category, &mut rng);
        scene.set_instances(&instances).unwrap();
        let rays = rays(&scene, &instances, &mut rng, 300);
        for variant in Variant::ALL {
            let traversal = Traversal::closest(variant);
            let (mut agree, mut serious, mut hits) = (0, 0, 0);
            for ray in &rays {
                let hit = scene.trace(ray, 0xff, traversal);
                hits += usize::from(hit.is_hit());
                let v = scene.verdict(ray, &hit);
                agree += usize::from(v.agrees());
                if v.is_serious() {
                    serious += 1;
                    eprintln!("{category} {variant:?}: {} on {ray:?}: {hit:?}", v.name());
                }
            }
            // Self-check: the verdict catches a lost hit and a farther instance.
            let ray = rays.iter().find(|r| scene.trace(r, 0xff, traversal).is_hit()).unwrap();
            assert!(scene.verdict(ray, &InstanceHit::MISS).is_serious());
            let share = agree as f64 / rays.len() as f64;
            eprintln!("{category} {variant:?}: {:.1} % agree, {hits} hits, {serious} serious", 100.0 * share);
            assert!(
                share >= 0.995 && serious == 0,
                "{category} {variant:?}: {agree}/{} agree, {serious} serious",
                rays.len()
            );
            assert!(hits > rays.len() / 2, "{category}: the aimed rays should mostly hit ({hits})");
        }
    }
}

/// Origins 1e4 to 1e12 scene sizes away, aimed at edges and vertices: the same
/// floors (the top level's culling must keep every instance whose f32 object ray
/// may enter its geometry's box, however large the origin).
#[test]
fn instanced_hits_hold_for_far_origins() {
    let geometries = vec![bottom(7, sphere(10, 16)), bottom(9, sphere(6, 9))];
    let mut scene = TwoLevelScene::new(geometries, &[]).unwrap();
    let mut rng = Rng(13);
    for category in ["rotated", "scaled", "mirrored"] {
        let instances = placements(category, &mut rng);
        scene.set_instances(&instances).unwrap();
        let size = scene.placed.iter().fold(Aabb::EMPTY, |b, p| b.union(p.world_box)).extent().max_element();
        for distance in [1e4f32, 1e8, 1e12] {
            let mut rays = rays(&scene, &instances, &mut rng, 200);
            for ray in rays.iter_mut() {
                let target = Vec3::from(ray.origin) + Vec3::from(ray.dir);
                let origin = target - Vec3::from(ray.dir).normalize() * size * distance;
                *ray = Ray::new(origin, target - origin, 0.0, f32::INFINITY);
            }
            let traversal = Traversal::closest(Variant::Stack);
            let (mut agree, mut serious, mut hits) = (0, 0, 0);
            for ray in &rays {
                let hit = scene.trace(ray, 0xff, traversal);
                hits += usize::from(hit.is_hit());
                let v = scene.verdict(ray, &hit);
                agree += usize::from(v.agrees());
                serious += usize::from(v.is_serious());
            }
            eprintln!("{category} at {distance:e} sizes: {agree}/{} agree, {hits} hits, {serious} serious", rays.len());
            assert!(
                agree * 1000 >= 995 * rays.len() && serious == 0,
                "{category} at {distance:e}: {agree} agree, {serious} serious"
            );
            assert!(hits > 0, "{category} at {distance:e}: no hits");
        }
    }
}

/// Shadow-ray segments ending before, at and after aimed targets (t = 1 at the
/// target), any hit, every category: the same floors.
#[test]
fn instanced_any_hits_are_exact_for_their_object_rays() {
    let geometries = vec![bottom(7, sphere(10, 16)), bottom(9, sphere(6, 9))];
    let mut scene = TwoLevelScene::new(geometries, &[]).unwrap();
    let mut rng = Rng(5);
    for category in ["rotated", "scaled", "mirrored", "far", "overlapping"] {
        let instances = placements(category, &mut rng);
        scene.set_instances(&instances).unwrap();
        let mut rays = rays(&scene, &instances, &mut rng, 300);
        for (k, ray) in rays.iter_mut().enumerate() {
            ray.tmax = [0.5, 0.999, 1.0, 1.001, 2.0][k % 5];
        }
        for variant in Variant::ALL {
            let traversal = Traversal { any_hit: true, ..Traversal::closest(variant) };
            let (mut agree, mut serious, mut hits) = (0, 0, 0);
            for ray in &rays {
                let hit = scene.trace(ray, 0xff, traversal);
                hits += usize::from(hit.is_hit());
                let v = scene.verdict_any(ray, &hit);
                agree += usize::from(v.agrees());
                serious += usize::from(v.is_serious());
            }
            let share = agree as f64 / rays.len() as f64;
            eprintln!(
                "{category} {variant:?} any hit: {:.1} % agree, {hits} occluded, {serious} serious",
                100.0 * share
            );
            assert!(
                share >= 0.995 && serious == 0,
                "{category} {variant:?}: {agree}/{} agree, {serious} serious",
                rays.len()
            );
            assert!(hits > rays.len() / 5 && hits < rays.len(), "{category}: {hits} occluded of {}", rays.len());
        }
    }
}

/// An engine's indexed, interleaved mesh goes in as it is held: the same
/// triangles as the flattened scene's, under the geometry's id.
#[test]
fn bottom_levels_take_engine_geometry() {
    use crate::scene::{Geometry, Indices, Scene};
    // Interleaved vertices: position then a normal, 24 bytes each; u16 indices.
    let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE];
    let bytes: Vec<u8> =
        positions.iter().flat_map(|p| [p.to_array(), [0.0, 0.0, 1.0]].concat()).flat_map(f32::to_le_bytes).collect();
    let indices: [u16; 6] = [0, 1, 2, 2, 1, 3];
    let g = Geometry::strided(42, &bytes, 0, 24, 4).unwrap().with_indices(Indices::U16(&indices));
    let b = BottomLevel::from_geometry(&g, &BuildConfig::default()).unwrap();
    assert_eq!(b.id, 42);
    assert_eq!(b.triangles, Scene::from_geometries(&[g], vec![]).unwrap().triangles);
    let bad = [0u16, 1, 9];
    let e = BottomLevel::from_geometry(&g.with_indices(Indices::U16(&bad)), &BuildConfig::default());
    assert!(matches!(e, Err(Error::InvalidInput(m)) if m.contains("vertex 9")));
}

/// One instance with the identity transform traces exactly as its geometry alone.
#[test]
fn an_identity_instance_is_the_single_level_trace() {
    let tris = sphere(8, 12);
    let single = KdTree::build(&tris, &BuildConfig::default());
    let scene = TwoLevelScene::new(
        vec![bottom(1, tris.clone())],
        &[Instance { geometry: 0, transform: Affine3A::IDENTITY, instance_id: 5, mask: 1 }],
    )
    .unwrap();
    let mut rng = Rng(8);
    let view = SceneRef::new(&single, &tris);
    // Random rays, then rays with -0.0 components (the object ray is the world
    // ray itself, bit for bit).
    let signed_zeros = (0..16).map(|k: u32| {
        let z = |bit: u32| if k & bit != 0 { -0.0 } else { 0.0 };
        Ray::new(Vec3::new(z(1), z(2), -3.0), Vec3::new(z(4), z(8), 1.0), 0.0, f32::INFINITY)
    });
    let random: Vec<Ray> = (0..500)
        .map(|_| {
            let origin = rng.unit() * 3.0;
            Ray::new(origin, rng.unit() - origin * 0.3, 0.0, f32::INFINITY)
        })
        .collect();
    for ray in random.into_iter().chain(signed_zeros) {
        let object = scene.object_ray(0, &ray);
        assert_eq!(bytemuck::bytes_of(&object), bytemuck::bytes_of(&ray));
        let (h, _) = trace_ray(&view, &ray, Traversal::closest(Variant::Stack));
        let i = scene.trace(&ray, 1, Traversal::closest(Variant::Stack));
        assert_eq!(
            (i.t.to_bits(), i.prim_index, i.u.to_bits(), i.v.to_bits()),
            (h.t.to_bits(), h.prim_id, h.u.to_bits(), h.v.to_bits())
        );
        if i.is_hit() {
            assert_eq!((i.instance_id, i.geometry_id, i.instance_index), (5, 1, 0));
        }
    }
}

/// Front faces are decided in object space: a mirroring instance does not flip them.
#[test]
fn front_faces_follow_object_space_winding_and_masks_hide_instances() {
    // Seen from -z looking along +z, clockwise in a left-handed frame: front.
    let tri = vec![[Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0), Vec3::new(1.0, 0.0, 0.0)]];
    let mirror =
        Affine3A::from_mat3_translation(Mat3::from_diagonal(Vec3::new(-1.0, 1.0, 1.0)), Vec3::new(5.0, 0.0, 0.0));
    let instances = [
        Instance { geometry: 0, transform: Affine3A::IDENTITY, instance_id: 1, mask: 0b01 },
        Instance { geometry: 0, transform: mirror, instance_id: 2, mask: 0b10 },
    ];
    let scene = TwoLevelScene::new(vec![bottom(0, tri)], &instances).unwrap();
    let closest = Traversal::closest(Variant::Stack);
    let toward = |x: f32, z: f32, dz: f32| Ray::new(Vec3::new(x, 0.25, z), Vec3::new(0.0, 0.0, dz), 0.0, f32::INFINITY);
    let front = scene.trace(&toward(0.25, -1.0, 1.0), 0xff, closest);
    assert!(front.is_hit() && front.front_face && front.instance_id == 1, "{front:?}");
    let back = scene.trace(&toward(0.25, 1.0, -1.0), 0xff, closest);
    assert!(back.is_hit() && !back.front_face, "{back:?}");
    // The mirrored copy (x in [4, 5]) keeps the object-space facing.
    let mirrored = scene.trace(&toward(4.75, -1.0, 1.0), 0xff, closest);
    assert!(mirrored.is_hit() && mirrored.front_face && mirrored.instance_id == 2, "{mirrored:?}");
    // Masks: instance 2 is hidden from rays of mask 0b01, instance 1 from 0b10.
    assert!(!scene.trace(&toward(4.75, -1.0, 1.0), 0b01, closest).is_hit());
    assert!(!scene.trace(&toward(0.25, -1.0, 1.0), 0b10, closest).is_hit());
    assert!(scene
        .trace(&toward(0.25, -1.0, 1.0), 0b11, Traversal { any_hit: true, ..Traversal::closest(Variant::Stack) })
        .is_hit());
}

#[test]
fn bad_instances_are_clear_errors_and_leave_the_scene_unchanged() {
    let mut scene = TwoLevelScene::new(vec![bottom(0, sphere(4, 6))], &[]).unwrap();
    let ok = Instance { geometry: 0, transform: Affine3A::IDENTITY, instance_id: 1, mask: 1 };
    scene.set_instances(&[ok]).unwrap();
    let mut message = |inst: Instance| match scene.set_instances(&[ok, inst]) {
        Err(Error::InvalidInput(m)) => m,
        other => panic!("expected an error, got {:?}", other.map(|_| ())),
    };
    assert!(message(Instance { geometry: 3, ..ok }).contains("geometry index 3"));
    let flat = Affine3A::from_mat3(Mat3::from_diagonal(Vec3::new(1.0, 0.0, 1.0)));
    assert!(message(Instance { transform: flat, ..ok }).contains("not invertible"));
    let nan = Affine3A::from_translation(Vec3::new(f32::NAN, 0.0, 0.0));
    assert!(message(Instance { transform: nan, ..ok }).contains("not finite"));
    let huge = Affine3A::from_scale(Vec3::splat(3e38));
    assert!(message(Instance { transform: huge, ..ok }).contains("overflows"));
    assert_eq!(scene.instance_count(), 1, "the scene is unchanged");
    // A geometry without triangles is placed and never hit.
    let empty = TwoLevelScene::new(vec![bottom(5, Vec::new())], &[ok]).unwrap();
    let probe = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 0.0, f32::INFINITY);
    assert_eq!(empty.trace(&probe, 1, Traversal::closest(Variant::Stack)).prim_index, PRIM_MISS);
    // A tree that does not fit its triangles.
    let mut wrong = bottom(4, sphere(4, 6));
    wrong.triangles.truncate(3);
    match TwoLevelScene::new(vec![wrong], &[ok]) {
        Err(Error::InvalidInput(m)) => assert!(m.contains("geometry 0 (id 4)"), "{m}"),
        other => panic!("expected an error, got {:?}", other.map(|_| ())),
    }
    // Empty scenes and invalid rays.
    scene.set_instances(&[]).unwrap();
    let ray = Ray::new(Vec3::ZERO, Vec3::X, 0.0, 1.0);
    assert_eq!(scene.trace(&ray, 1, Traversal::closest(Variant::Stack)).prim_index, PRIM_MISS);
    scene.set_instances(&[ok]).unwrap();
    let nan_ray = Ray::new(Vec3::ZERO, Vec3::ZERO, 0.0, 1.0);
    assert_eq!(scene.trace(&nan_ray, 1, Traversal::closest(Variant::Stack)).prim_index, crate::consts::PRIM_INVALID);
}

/// Top-level rebuild time for 10, 1,000 and 100,000 instances (a measurement,
/// not a test: `cargo test --release --lib top_level_rebuild -- --ignored --nocapture`).
#[test]
#[ignore]
fn top_level_rebuild_times() {
    let mut scene = TwoLevelScene::new(vec![bottom(0, sphere(8, 12))], &[]).unwrap();
    let mut rng = Rng(1);
    for n in [10usize, 1000, 100_000] {
        let instances: Vec<Instance> = (0..n)
            .map(|i| Instance {
                geometry: 0,
                transform: Affine3A::from_rotation_translation(
                    Quat::from_axis_angle(rng.unit(), rng.next() * 6.0),
                    Vec3::new(rng.next(), rng.next(), rng.next()) * (n as f32).cbrt() * 4.0,
                ),
                instance_id: i as u32,
                mask: 0xff,
            })
            .collect();
        let mut times = Vec::new();
        for _ in 0..5 {
            let start = std::time::Instant::now();
            scene.set_instances(&instances).unwrap();
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        eprintln!(
            "{n} instances: top-level rebuild {:.3} ms (median of 5), {} nodes",
            times[2],
            scene.top_level_nodes()
        );
    }
}

/// Placements of one geometry id share a tree; the ranges are those of the
/// flattened scene, so that `first_prim + prim_index` is its `prim_id`.
#[test]
fn geometries_placed_twice_share_one_tree_and_keep_the_flat_numbering() {
    use crate::scene::{Geometry, Scene};
    let ball = sphere(6, 9);
    let cube: Vec<Vec3> = sphere(3, 4).into_iter().flatten().collect();
    let ball_points: Vec<Vec3> = ball.iter().flatten().copied().collect();
    let moved = Affine3A::from_scale_rotation_translation(Vec3::splat(0.5), Quat::from_rotation_z(0.3), Vec3::X * 4.0);
    let geometries = [
        Geometry::new(5, &ball_points).with_instance_id(10),
        Geometry::new(6, &cube).with_instance_id(11).with_transform(Affine3A::from_translation(Vec3::Y * 4.0)),
        Geometry::new(5, &ball_points).with_instance_id(12).with_transform(moved),
    ];
    let (scene, ranges) = TwoLevelScene::from_geometries(&geometries, &BuildConfig::default()).unwrap();
    let flat = Scene::from_geometries(&geometries, Vec::new()).unwrap();
    assert_eq!(scene.geometries().len(), 2);
    assert_eq!(scene.instance_count(), 3);
    assert_eq!(ranges, flat.geometries);
    // A ray at the moved ball's centre: its hit, renumbered, is the flattened scene's triangle.
    let ray = Ray::new(Vec3::new(4.0, 0.0, -5.0), Vec3::Z, 0.0, f32::INFINITY);
    let hit = scene.trace(&ray, 0xff, Traversal::closest(Variant::Stack));
    assert_eq!(hit.instance_id, 12);
    let prim_id = ranges[hit.instance_index as usize].first_prim + hit.prim_index;
    let at = flat.locate(prim_id).unwrap();
    assert_eq!((at.instance_id, at.geometry_id, at.prim_index), (12, 5, hit.prim_index));
}
