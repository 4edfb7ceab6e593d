//! An engine-shaped program around kdtrace: the engine owns its Vulkan instance,
//! device, queue and gpu-allocator `Allocator` (the [`Engine`] of
//! examples/embed.rs) and keeps its meshes the way engines do — one interleaved
//! vertex buffer (position and normal, 24 bytes a vertex) and index buffers of
//! 32-bit (a sphere) and 16-bit (a ground quad) indices — placed by a scene graph
//! of instances with 3×4 transforms: scaled non-uniformly, rotated, mirrored, one
//! moving from frame to frame.
//!
//! Once, the meshes become kdtrace geometries read straight from the engine's
//! vertex bytes (offset, stride) and indices, each with its own kd-tree
//! ([`BottomLevel::from_geometry`]), and the scene graph their instances
//! ([`TwoLevelScene`], [`TwoLevelTracer`]). Per frame:
//!
//! 1. the scene graph's transforms go to kdtrace as [`Instance`](kdtrace::twolevel::Instance)s
//!    with the engine's ids: the top level alone is rebuilt (timed below);
//! 2. one command buffer: after the first frame, the instances' upload
//!    ([`TwoLevelTracer::record_set_instances`]: recorded, no submit of kdtrace's
//!    own; its staging buffer released once the frame has completed), the engine's
//!    ray generation shader (`glsl/examples/raygen.comp`), kdtrace's two-level
//!    trace ([`TwoLevelTracer::record_binding`]), the engine's shading
//!    (`glsl/examples/engine_shade.comp`), which takes each hit's instance id,
//!    geometry id and triangle within the mesh, reads that triangle's three vertex
//!    normals through the engine's own index and vertex buffers, interpolates them
//!    with the hit's `u, v` and shades with the instance's colour; barriers between;
//! 3. submit, wait, write `frame-N.png`.
//!
//! ```sh
//! cargo run --release --example engine -- OUT_DIR [WIDTH HEIGHT [FRAMES]]
//! ```
//!
//! `tests/embed.rs` (`engine_example_shades_instances_by_id_with_smooth_normals`)
//! runs [`run`] under the validation layer with synchronization validation and
//! checks every pixel against its own CPU shading of the same hits.

#[allow(dead_code)]
#[path = "embed.rs"]
mod embed;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use ash::vk;
use embed::abi::*;
use embed::{align_up, compute_barrier, memory_barrier, Engine, Resources};
use glam::{Affine3A, Mat3, Quat, Vec3};
use gpu_allocator::MemoryLocation;
use kdtrace::gpu::{shaders, BufferRange, Validation};
use kdtrace::kdtree::BuildConfig;
use kdtrace::scene::{Camera, Geometry, Indices};
use kdtrace::traversal::{Traversal, Variant};
use kdtrace::twolevel::{BottomLevel, GpuInstanceHit, InstanceHit, TwoLevelScene, TwoLevelTracer};
use kdtrace::Ray;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out_dir = PathBuf::from(args.first().map(String::as_str).unwrap_or("engine-frames"));
    let number = |i: usize, name: &str, default: u32| -> Result<u32> {
        args.get(i).map(|s| s.parse().with_context(|| name.to_string())).transpose().map(|v| v.unwrap_or(default))
    };
    let (width, height, frames) = (number(1, "WIDTH", 640)?, number(2, "HEIGHT", 480)?, number(3, "FRAMES", 4)?);
    let report = run(Some(&out_dir), width, height, frames, Validation::IfAvailable)?;
    for (i, frame) in report.frames.iter().enumerate() {
        eprintln!(
            "frame {i}: {} triangles in {} instances; top level {:.2} ms, upload {:.2} ms, frame {:.1} ms",
            frame.triangles,
            frame.instances.len(),
            frame.build_ms,
            frame.upload_ms,
            frame.frame_ms
        );
    }
    eprintln!("{}: {frames} frames of {width}x{height} on {}", out_dir.display(), report.device);
    Ok(())
}

/// The engine's meshes as it keeps them: one interleaved vertex buffer and one
/// buffer of index words.
pub struct Meshes {
    /// Every vertex of every mesh: position xyz, normal xyz.
    pub vertices: Vec<[f32; 6]>,
    /// Mesh 0's u32 indices, then mesh 1's u16 indices two to a word.
    pub index_words: Vec<u32>,
    /// Where each mesh sits in those buffers (indexed by geometry id).
    pub meshes: Vec<EngineMesh>,
    /// The sphere's indices (mesh 0).
    pub sphere_indices: Vec<u32>,
    /// The ground quad's indices (mesh 1).
    pub ground_indices: Vec<u16>,
}

/// Geometry id of the unit sphere (32-bit indices) and of the ground quad (16-bit).
pub const SPHERE: u32 = 0;
/// See [`SPHERE`].
pub const GROUND: u32 = 1;

impl Meshes {
    /// A unit UV sphere (smooth vertex normals; the poles' degenerate triangles
    /// left out) and a unit ground quad in the y = 0 plane.
    pub fn new() -> Meshes {
        let (rings, segments) = (16u32, 32u32);
        let mut vertices = Vec::new();
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..=segments {
                let phi = std::f32::consts::TAU * j as f32 / segments as f32;
                let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
                vertices.push([n.x, n.y, n.z, n.x, n.y, n.z]);
            }
        }
        let mut sphere_indices = Vec::new();
        for i in 0..rings {
            for j in 0..segments {
                let a = i * (segments + 1) + j;
                let b = a + segments + 1;
                if i > 0 {
                    sphere_indices.extend([a, a + 1, b]);
                }
                if i + 1 < rings {
                    sphere_indices.extend([a + 1, b + 1, b]);
                }
            }
        }
        let ground_first = vertices.len() as u32;
        for (x, z) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            vertices.push([x, 0.0, z, 0.0, 1.0, 0.0]);
        }
        let ground_indices: Vec<u16> = vec![0, 2, 1, 0, 3, 2];
        let mut index_words = sphere_indices.clone();
        let ground_word = index_words.len() as u32;
        index_words
            .extend(ground_indices.chunks(2).map(|p| u32::from(p[0]) | (u32::from(*p.get(1).unwrap_or(&0)) << 16)));
        let meshes = vec![
            EngineMesh { first_vertex: 0, first_word: 0, index_bits: 32, pad: 0 },
            EngineMesh { first_vertex: ground_first, first_word: ground_word, index_bits: 16, pad: 0 },
        ];
        Meshes { vertices, index_words, meshes, sphere_indices, ground_indices }
    }

    /// Mesh `id` as a kdtrace geometry, read from the interleaved vertex bytes.
    fn geometry(&self, id: u32) -> Result<Geometry<'_>> {
        let bytes: &[u8] = bytemuck::cast_slice(&self.vertices);
        let stride = std::mem::size_of::<[f32; 6]>();
        let first = self.meshes[id as usize].first_vertex as usize;
        let end = self.meshes.get(id as usize + 1).map_or(self.vertices.len(), |m| m.first_vertex as usize);
        let indices =
            if id == SPHERE { Indices::U32(&self.sphere_indices) } else { Indices::U16(&self.ground_indices) };
        Ok(Geometry::strided(id, bytes, first * stride, stride, end - first)?.with_indices(indices))
    }
}

impl Default for Meshes {
    fn default() -> Self {
        Meshes::new()
    }
}

/// One placement of a mesh in the engine's scene graph.
#[derive(Clone, Copy, Debug)]
pub struct Instance {
    /// The mesh (geometry id).
    pub mesh: u32,
    /// Object to world.
    pub transform: Affine3A,
    /// Its colour.
    pub color: Vec3,
}

impl Instance {
    /// The normal matrix: the inverse transpose of the linear part.
    pub fn normal_matrix(&self) -> Mat3 {
        Mat3::from(self.transform.matrix3).inverse().transpose()
    }
}

/// The instance moving in the x direction from frame to frame.
pub const MOVING: u32 = 3;

/// The scene graph at `frame`: the instance ids are the indices.
pub fn instances(frame: u32) -> Vec<Instance> {
    let place = |s: Vec3, r: Quat, t: Vec3| Affine3A::from_scale_rotation_translation(s, r, t);
    vec![
        Instance {
            mesh: GROUND,
            transform: place(Vec3::new(6.0, 1.0, 4.0), Quat::IDENTITY, Vec3::new(0.0, -1.0, 0.0)),
            color: Vec3::splat(0.7),
        },
        Instance {
            mesh: SPHERE,
            transform: place(Vec3::ONE, Quat::IDENTITY, Vec3::new(-2.2, 0.0, 0.0)),
            color: Vec3::new(0.9, 0.25, 0.2),
        },
        // Scaled non-uniformly and tilted: its normals need the inverse transpose.
        Instance {
            mesh: SPHERE,
            transform: place(Vec3::new(0.6, 1.3, 0.6), Quat::from_rotation_z(0.5), Vec3::new(0.0, 0.3, -1.0)),
            color: Vec3::new(0.3, 0.85, 0.3),
        },
        // Moving.
        Instance {
            mesh: SPHERE,
            transform: place(Vec3::splat(0.7), Quat::IDENTITY, Vec3::new(1.2 + 0.35 * frame as f32, -0.3, 0.6)),
            color: Vec3::new(0.25, 0.4, 0.95),
        },
        // Mirrored (negative determinant).
        Instance {
            mesh: SPHERE,
            transform: place(Vec3::new(-0.45, 0.45, 0.45), Quat::IDENTITY, Vec3::new(-0.7, -0.55, 1.6)),
            color: Vec3::new(0.95, 0.85, 0.2),
        },
    ]
}

/// The engine's camera.
pub fn camera() -> Camera {
    Camera { eye: Vec3::new(0.0, 1.6, 7.0), target: Vec3::new(0.0, -0.3, 0.0), up: Vec3::Y, fov_deg: 45.0 }
}

/// One frame of [`run`].
pub struct Frame {
    /// The image, as written to `frame-N.png`.
    pub image: image::RgbImage,
    /// The engine's camera rays, as its raygen shader wrote them.
    pub rays: Vec<Ray>,
    /// kdtrace's hits of those rays.
    pub hits: Vec<InstanceHit>,
    /// Triangles placed by the scene graph (each mesh's times its instances).
    pub triangles: usize,
    /// The scene graph of the frame.
    pub instances: Vec<Instance>,
    /// The meshes' trees and the top level (the first frame), or rebuilding the
    /// top level alone (CPU).
    pub build_ms: f64,
    /// `TwoLevelTracer::new` (the first frame), or recording the instances' upload
    /// with `record_set_instances` (its copies run in the frame's command buffer).
    pub upload_ms: f64,
    /// Recording, submitting and waiting for the frame's command buffer.
    pub frame_ms: f64,
}

/// What [`run`] made.
pub struct Report {
    /// Every frame.
    pub frames: Vec<Frame>,
    /// The engine's meshes.
    pub meshes: Meshes,
    /// The device's name.
    pub device: String,
}

/// Renders `frames` frames at `width` × `height` as the module docs describe,
/// writes `frame-N.png` into `out_dir` when given, and tears the engine down.
/// Any validation message (synchronization validation included, and those of
/// device destruction) is an error.
pub fn run(out_dir: Option<&Path>, width: u32, height: u32, frames: u32, validation: Validation) -> Result<Report> {
    if width == 0 || height == 0 || frames == 0 {
        bail!("the image needs at least one pixel and one frame");
    }
    let engine = Engine::new(validation, false)?;
    let meshes = Meshes::new();
    let result = render_frames(&engine, &meshes, width, height, frames);
    let messages = engine.shutdown()?;
    if !messages.is_empty() {
        bail!("validation reported {} message(s):\n{}", messages.len(), messages.join("\n"));
    }
    let (device, frames) = result?;
    if let Some(dir) = out_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (i, frame) in frames.iter().enumerate() {
            let path = dir.join(format!("frame-{i}.png"));
            frame.image.save(&path).with_context(|| format!("writing {}", path.display()))?;
        }
    }
    Ok(Report { frames, meshes, device })
}

fn render_frames(
    engine: &Engine,
    meshes: &Meshes,
    width: u32,
    height: u32,
    count: u32,
) -> Result<(String, Vec<Frame>)> {
    let ctx = engine.kdtrace_context()?;
    let traversal = Traversal::closest(Variant::Stack);
    let storage = vk::BufferUsageFlags::STORAGE_BUFFER;

    // What lives as long as the engine: the meshes and the pipelines.
    let mut statics = Resources::new(engine);
    let vertex_bytes: &[u8] = bytemuck::cast_slice(&meshes.vertices);
    let index_bytes: &[u8] = bytemuck::cast_slice(&meshes.index_words);
    let mesh_bytes: &[u8] = bytemuck::cast_slice(&meshes.meshes);
    let mut upload = |bytes: &[u8], name: &str| -> Result<BufferRange> {
        let buffer = statics.buffer(bytes.len() as u64, storage, MemoryLocation::CpuToGpu, name)?;
        statics.write(buffer, bytes)?;
        Ok(BufferRange::new(buffer, 0, bytes.len() as u64))
    };
    let vertices = upload(vertex_bytes, "vertices")?;
    let indices = upload(index_bytes, "indices")?;
    let mesh_table = upload(mesh_bytes, "meshes")?;
    let raygen = statics.pipeline(
        shaders::EXAMPLE_RAYGEN,
        ENGINE_RAYGEN_BINDINGS,
        std::mem::size_of::<CameraParams>() as u32,
    )?;
    let shade = statics.pipeline(
        shaders::EXAMPLE_ENGINE_SHADE,
        ENGINE_SCENE_BINDINGS,
        std::mem::size_of::<EngineShadeParams>() as u32,
    )?;

    let camera = camera();
    let mut kd: Option<(TwoLevelScene, TwoLevelTracer)> = None;
    let mut frames = Vec::new();
    for frame_index in 0..count {
        // 1. The scene graph to kdtrace: the meshes once (their trees, the first
        // frame), the instances with the engine's ids every frame.
        let start = Instant::now();
        let graph = instances(frame_index);
        let placements: Vec<kdtrace::twolevel::Instance> = graph
            .iter()
            .enumerate()
            .map(|(id, inst)| kdtrace::twolevel::Instance {
                geometry: inst.mesh as usize,
                transform: inst.transform,
                instance_id: id as u32,
                mask: 0xff,
            })
            .collect();
        let first = kd.is_none();
        let mut upload_ms = 0.0;
        let (scene, tracer) = match &mut kd {
            Some((scene, tracer)) => {
                scene.set_instances(&placements)?;
                (scene, tracer)
            }
            None => {
                let config = BuildConfig::default();
                let bottoms = [SPHERE, GROUND]
                    .iter()
                    .map(|&m| Ok(BottomLevel::from_geometry(&meshes.geometry(m)?, &config)?))
                    .collect::<Result<Vec<_>>>()?;
                let scene = TwoLevelScene::new(bottoms, &placements)?;
                let upload = Instant::now();
                let mut tracer = TwoLevelTracer::new(&ctx, &scene)?;
                tracer.prepare(traversal)?;
                upload_ms = upload.elapsed().as_secs_f64() * 1e3;
                let (scene, tracer) = kd.insert((scene, tracer));
                (&mut *scene, tracer)
            }
        };
        let build_ms = start.elapsed().as_secs_f64() * 1e3 - upload_ms;
        let triangles: usize = placements.iter().map(|p| scene.geometries()[p.geometry].triangles.len()).sum();

        // 2. The frame's buffers: rays and hits in one buffer (read back at the
        // end), the geometry ranges and instances of this frame, the pixels.
        let start = Instant::now();
        let mut res = Resources::new(engine);
        let pixel_count = width * height;
        let ray_bytes = u64::from(pixel_count) * std::mem::size_of::<Ray>() as u64;
        let hit_bytes = u64::from(pixel_count) * std::mem::size_of::<GpuInstanceHit>() as u64;
        let hit_offset = align_up(ray_bytes, ctx.info.min_storage_buffer_offset_alignment);
        let traced_bytes = hit_offset + hit_bytes;
        let traced = res.buffer(
            traced_bytes,
            storage | vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::GpuOnly,
            "rays+hits",
        )?;
        let readback =
            res.buffer(traced_bytes, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu, "readback")?;
        let rays = BufferRange::new(traced, 0, ray_bytes);
        let hits = BufferRange::new(traced, hit_offset, hit_bytes);
        let instance_data: Vec<EngineInstance> = graph
            .iter()
            .map(|inst| {
                let n = inst.normal_matrix();
                let row = |r: usize| [n.row(r).x, n.row(r).y, n.row(r).z, 0.0];
                EngineInstance {
                    normal_x: row(0),
                    normal_y: row(1),
                    normal_z: row(2),
                    color: [inst.color.x, inst.color.y, inst.color.z, 0.0],
                }
            })
            .collect();
        let mut per_frame = |bytes: &[u8], name: &str| -> Result<BufferRange> {
            let buffer = res.buffer(bytes.len() as u64, storage, MemoryLocation::CpuToGpu, name)?;
            res.write(buffer, bytes)?;
            Ok(BufferRange::new(buffer, 0, bytes.len() as u64))
        };
        let instance_table = per_frame(bytemuck::cast_slice(&instance_data), "instances")?;
        let pixel_bytes = u64::from(pixel_count) * 4;
        let pixel_buf = res.buffer(pixel_bytes, storage, MemoryLocation::GpuToCpu, "pixels")?;
        let pixels = BufferRange::new(pixel_buf, 0, pixel_bytes);
        let [raygen_set, shade_set] = res.descriptor_sets([raygen.set_layout, shade.set_layout])?;
        res.write_set(raygen_set, &[(ENGINE_RAYGEN_BINDING_RAYS, rays)]);
        res.write_set(
            shade_set,
            &[
                (ENGINE_SCENE_BINDING_RAYS, rays),
                (ENGINE_SCENE_BINDING_HITS, hits),
                (ENGINE_SCENE_BINDING_INSTANCES, instance_table),
                (ENGINE_SCENE_BINDING_MESHES, mesh_table),
                (ENGINE_SCENE_BINDING_VERTICES, vertices),
                (ENGINE_SCENE_BINDING_INDICES, indices),
                (ENGINE_SCENE_BINDING_PIXELS, pixels),
            ],
        );

        // 3. One command buffer: raygen → kdtrace → shade, then copies to the host.
        let device = &engine.device;
        let cmd = res.command_buffer()?;
        let camera_params = CameraParams::new(&camera, width, height);
        let shade_params = EngineShadeParams { count: pixel_count, pad: 0 };
        let groups = pixel_count.div_ceil(ENGINE_WORKGROUP);
        let compute = vk::PipelineBindPoint::COMPUTE;
        // SAFETY: both ranges lie in `traced`, which lives in `res` past the wait.
        let binding = unsafe { tracer.bind(rays, hits, traversal)? };
        // SAFETY: `cmd` is a fresh primary command buffer of the engine's device;
        // every object recorded lives in `res`, `statics`, `binding` or `tracer`
        // until the wait below has returned.
        unsafe {
            device.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default()).context("vkBeginCommandBuffer")?;
            if !first {
                // This frame's instances: their upload recorded here, its staging
                // buffer kept until this frame has completed (released after the wait).
                let start = Instant::now();
                tracer.record_set_instances(cmd, scene, u64::from(frame_index))?;
                upload_ms = start.elapsed().as_secs_f64() * 1e3;
            }
            device.cmd_bind_pipeline(cmd, compute, raygen.pipeline);
            device.cmd_bind_descriptor_sets(cmd, compute, raygen.layout, 0, &[raygen_set], &[]);
            let stages = vk::ShaderStageFlags::COMPUTE;
            device.cmd_push_constants(cmd, raygen.layout, stages, 0, bytemuck::bytes_of(&camera_params));
            device.cmd_dispatch(cmd, groups, 1, 1);
            compute_barrier(device, cmd, vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE);
            tracer.record_binding(cmd, &binding, pixel_count, 0xff)?;
            compute_barrier(device, cmd, vk::AccessFlags::SHADER_READ);
            device.cmd_bind_pipeline(cmd, compute, shade.pipeline);
            device.cmd_bind_descriptor_sets(cmd, compute, shade.layout, 0, &[shade_set], &[]);
            device.cmd_push_constants(cmd, shade.layout, stages, 0, bytemuck::bytes_of(&shade_params));
            device.cmd_dispatch(cmd, groups, 1, 1);
            // The rays and hits to the readback buffer (transfer), the pixels to the host.
            let (shader, transfer) = (vk::PipelineStageFlags::COMPUTE_SHADER, vk::PipelineStageFlags::TRANSFER);
            memory_barrier(
                device,
                cmd,
                (shader, vk::AccessFlags::SHADER_WRITE),
                (transfer, vk::AccessFlags::TRANSFER_READ),
            );
            let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: traced_bytes }];
            device.cmd_copy_buffer(cmd, traced, readback, &region);
            memory_barrier(
                device,
                cmd,
                (shader | transfer, vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE),
                (vk::PipelineStageFlags::HOST, vk::AccessFlags::HOST_READ),
            );
            device.end_command_buffer(cmd).context("vkEndCommandBuffer")?;
        }
        engine.submit_and_wait(cmd)?;
        drop(binding);
        tracer.release_retired(u64::from(frame_index));
        let frame_ms = start.elapsed().as_secs_f64() * 1e3;

        let words: &[u32] = bytemuck::cast_slice(res.read(pixel_buf)?);
        let image = image::RgbImage::from_fn(width, height, |x, y| {
            let [r, g, b, _] = words[(y * width + x) as usize].to_le_bytes();
            image::Rgb([r, g, b])
        });
        let traced_data = res.read(readback)?;
        let rays: Vec<Ray> = bytemuck::pod_collect_to_vec(&traced_data[..ray_bytes as usize]);
        let words: Vec<GpuInstanceHit> =
            bytemuck::pod_collect_to_vec(&traced_data[hit_offset as usize..traced_bytes as usize]);
        let hits = words.iter().map(InstanceHit::from).collect();
        frames.push(Frame { image, rays, hits, triangles, instances: graph, build_ms, upload_ms, frame_ms });
    }
    // kdtrace's objects go before the engine's; the engine's device outlives them.
    let device = ctx.info.name.clone();
    drop(kd);
    drop(ctx);
    drop(statics);
    Ok((device, frames))
}
