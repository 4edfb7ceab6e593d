//! examples/engine.rs, an engine-shaped program (its own instance, device and
//! allocator; an interleaved vertex buffer with u32 and u16 index buffers;
//! instances scaled, rotated, mirrored and one moving), run under the validation
//! layer with synchronization validation: no message, and every pixel of every
//! frame equals this file's own CPU shading of the same two-level hits — their
//! instance id, geometry id and triangle, normals read from the engine's unpacked
//! index arrays and interpolated with the hit's `u, v` — so the GPU shader's
//! reading of `GpuInstanceHit`, its u16 unpacking, the vertex stride and the
//! barycentric convention are all checked; the instances move by recorded
//! updates of the top level (`record_set_instances`).

mod common;

#[allow(dead_code)]
#[path = "../examples/engine.rs"]
mod engine;

use std::path::PathBuf;

use glam::Vec3;
use kdtrace::consts::{PRIM_INCOMPLETE, PRIM_INVALID, PRIM_MISS};

fn srgb(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.0031308 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// The engine's shading of `frame`, on the CPU.
fn cpu_shade(meshes: &engine::Meshes, frame: &engine::Frame, width: u32, height: u32) -> image::RgbImage {
    image::RgbImage::from_fn(width, height, |x, y| {
        let i = (y * width + x) as usize;
        let (ray, hit) = (frame.rays[i], frame.hits[i]);
        let color = match hit.prim_index {
            PRIM_INCOMPLETE => Vec3::new(1.0, 0.0, 1.0),
            PRIM_MISS | PRIM_INVALID => Vec3::splat(0.05),
            t => {
                let mesh = meshes.meshes[hit.geometry_id as usize];
                let t = t as usize;
                let index = |k: usize| match hit.geometry_id {
                    engine::SPHERE => meshes.sphere_indices[3 * t + k] as usize,
                    _ => usize::from(meshes.ground_indices[3 * t + k]),
                };
                let normal = |k: usize| {
                    let v = meshes.vertices[mesh.first_vertex as usize + index(k)];
                    Vec3::new(v[3], v[4], v[5])
                };
                let n = (1.0 - hit.u - hit.v) * normal(0) + hit.u * normal(1) + hit.v * normal(2);
                let inst = frame.instances[hit.instance_id as usize];
                assert_eq!(hit.geometry_id, inst.mesh, "the hit names its instance's mesh");
                let world = inst.normal_matrix() * n;
                let cos = world.normalize().dot(Vec3::from(ray.dir).normalize()).abs();
                inst.color * (0.15 + 0.85 * cos)
            }
        };
        image::Rgb([srgb(color.x), srgb(color.y), srgb(color.z)])
    })
}

#[test]
fn engine_example_shades_instances_by_id_with_smooth_normals() {
    let (width, height, frames) = (96u32, 72u32, 3u32);
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("engine");
    // `run` fails on any validation message (synchronization validation is on
    // where the layer offers it), those of device destruction included.
    let report = engine::run(Some(&out), width, height, frames, common::validation()).expect("the engine example");
    assert_eq!(report.frames.len(), frames as usize);
    let mut moving_x = Vec::new();
    for (f, frame) in report.frames.iter().enumerate() {
        let written = image::open(out.join(format!("frame-{f}.png"))).expect("the frame's PNG").to_rgb8();
        assert_eq!(written, frame.image, "frame {f}: the PNG holds the rendered frame");
        let expected = cpu_shade(&report.meshes, frame, width, height);
        let worst = frame
            .image
            .pixels()
            .zip(expected.pixels())
            .map(|(a, b)| (0..3).map(|c| a.0[c].abs_diff(b.0[c])).max().unwrap())
            .max()
            .unwrap();
        if worst > 2 {
            expected.save(out.join(format!("frame-{f}-expected.png"))).unwrap();
            panic!("frame {f}: a pixel differs from the CPU shading by {worst}; see {}", out.display());
        }
        // Pixels per instance, and the moving instance's mean x.
        let mut pixels = vec![0usize; frame.instances.len()];
        let mut sum_x = 0.0;
        for (i, hit) in frame.hits.iter().enumerate() {
            if hit.is_hit() {
                pixels[hit.instance_id as usize] += 1;
                if hit.instance_id == engine::MOVING {
                    sum_x += (i as u32 % width) as f64;
                }
            }
        }
        assert!(pixels.iter().all(|&n| n > 20), "frame {f}: every instance is in view: {pixels:?}");
        assert_eq!(frame.hits.iter().filter(|h| h.prim_index == PRIM_INCOMPLETE).count(), 0);
        moving_x.push(sum_x / pixels[engine::MOVING as usize] as f64);
    }
    assert!(
        moving_x.windows(2).all(|w| w[1] > w[0] + 2.0),
        "the moving instance moves right from frame to frame: mean x {moving_x:?}"
    );
}
