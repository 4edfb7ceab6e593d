//! kdtrace: ray tracing of triangle scenes on the GPU with a SAH kd-tree, through
//! raw Vulkan compute ([ash] and [gpu-allocator]).
//!
//! It implements Horn, Sugerman, Houston & Hanrahan, *Interactive k-D Tree GPU
//! Raytracing* (I3D 2007) — stack, kd-restart, push-down and short-stack
//! traversals — with kd-restart and kd-backtrack of Foley & Sugerman, *KD-Tree
//! Acceleration Structures for a GPU Raytracer* (Graphics Hardware 2005), and
//! ropes of Popov et al. (2007). The tree is built on the CPU with the O(N log N)
//! SAH builder of Wald & Havran (2006) ([`kdtree::KdTree::build`]), uploaded once,
//! and traversed by a compute kernel, one ray per invocation, with the watertight
//! ray/triangle test of Woop, Benthin & Wald (2013). Every GPU traversal has a CPU
//! twin ([`kdtree::traverse`]) that tests compare against bit for bit. On devices
//! with `VK_KHR_ray_query` the driver's own BVH is a second backend behind the
//! same API ([`trace::Backend`], [`ray_query`]): the peer every traversal is
//! compared with.
//!
//! # Quick start: headless
//!
//! kdtrace creates its own instance and device ([`gpu::GpuContext::headless`]),
//! uploads the rays, submits, waits and reads the hits back (`Scene::load` needs
//! the feature `obj`, a default one; [`scene::Scene::from_triangles`] does not):
//!
//! ```no_run
//! use glam::Vec3;
//! use kdtrace::gpu::{ContextOptions, GpuContext};
//! use kdtrace::kdtree::{BuildConfig, KdTree};
//! use kdtrace::scene::Scene;
//! use kdtrace::trace::{TraceOptions, Tracer};
//! use kdtrace::Ray;
//!
//! # fn main() -> kdtrace::Result<()> {
//! let scene = Scene::load("scenes/cornell_box.obj".as_ref())?;
//! let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
//! let ctx = GpuContext::headless(&ContextOptions::from_env())?;
//! let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles)?;
//! let rays = [Ray::new(Vec3::new(278.0, 273.0, -800.0), Vec3::Z, 0.0, f32::INFINITY)];
//! let hit = tracer.trace(&rays, &TraceOptions::default())?.hits[0];
//! if hit.is_hit() {
//!     println!("triangle {} at t = {}", hit.prim_id, hit.t);
//! }
//! # Ok(())
//! # }
//! ```
//!
//! # Embedding in a Vulkan engine
//!
//! kdtrace adopts the engine's instance, device, queue and shared gpu-allocator
//! `Allocator` ([`gpu::GpuContext::adopt`]; enable [`gpu::required_features`] on
//! the device) and records its trace into the engine's command buffer, reading
//! rays from and writing hits to ranges of the engine's buffers
//! ([`trace::Tracer::record_trace`]); it never submits there. The [`trace`] module
//! docs state the barriers expected before and after, what must stay alive until
//! the command buffer completes, the scene lifecycle (build or load, upload,
//! replace, drop) and thread safety. `examples/embed.rs` is a whole engine frame:
//! its own ray generation shader, kdtrace's trace and its own shading shader in
//! one command buffer.
//!
//! ```no_run
//! # use std::sync::{Arc, Mutex};
//! # use ash::vk;
//! # use kdtrace::gpu::{AdoptDesc, BufferRange, GpuContext};
//! # use kdtrace::trace::{TraceOptions, Tracer};
//! # #[allow(clippy::too_many_arguments)]
//! # fn engine(
//! #     instance: ash::Instance, physical_device: vk::PhysicalDevice, device: ash::Device, queue_family: u32,
//! #     queue: vk::Queue, queue_lock: Arc<Mutex<()>>, allocator: Arc<Mutex<gpu_allocator::vulkan::Allocator>>,
//! #     tree: &kdtrace::kdtree::KdTree, triangles: &[[glam::Vec3; 3]], cmd: vk::CommandBuffer,
//! #     ray_buffer: vk::Buffer, hit_buffer: vk::Buffer, count: u32,
//! # ) -> kdtrace::Result<()> {
//! // At load time. SAFETY: the engine's handles, alive longer than `ctx` and the tracer.
//! let ctx = unsafe {
//!     GpuContext::adopt(AdoptDesc {
//!         instance,
//!         physical_device,
//!         device,
//!         queue_family,
//!         queue,
//!         queue_lock: Some(queue_lock), // the engine's lock around vkQueueSubmit
//!         allocator,
//!         enabled_features: kdtrace::gpu::required_features(), // as the device was created
//!         subgroup_size_control: false,
//!         ray_query: false, // or true, with the ray-query backend's extensions and features enabled
//!     })?
//! };
//! let mut tracer = Tracer::new(&ctx, tree, triangles)?; // uploads: submits and waits
//! let options = TraceOptions::default();
//! tracer.prepare(&options)?; // the pipeline (and side buffers) before the first frame
//!
//! // In a frame, after a barrier that makes the rays readable by compute shaders.
//! // SAFETY: `cmd` is recording; the buffers and `binding` live until it completes.
//! let rays = BufferRange::new(ray_buffer, 0, u64::from(count) * 32);
//! let hits = BufferRange::new(hit_buffer, 0, u64::from(count) * 16);
//! let binding = unsafe { tracer.record_trace(cmd, rays, hits, count, &options)? };
//! // Then a barrier from compute-shader writes to the hits' reader, rebind your
//! // compute state, submit, and drop `binding` once the frame's fence signalled.
//! # drop(binding);
//! # Ok(())
//! # }
//! ```
//!
//! # Rays and hits for shader authors
//!
//! Rays and hits are std430 structs, defined once as [`Ray`] and [`Hit`] (both
//! `Pod`), from which `build.rs` generates their GLSL declarations:
//!
//! | `Ray`, 32 bytes | offset | GLSL | |
//! |---|---|---|---|
//! | `origin` | 0 | `vec3` | the segment is `origin + t * dir`, `tmin <= t <= tmax` |
//! | `tmin` | 12 | `float` | |
//! | `dir` | 16 | `vec3` | need not be normalized |
//! | `tmax` | 28 | `float` | may be `+inf` |
//!
//! | `Hit`, 16 bytes | offset | GLSL | |
//! |---|---|---|---|
//! | `t` | 0 | `float` | `+inf` for a miss, NaN for an invalid or incomplete ray |
//! | `prim_id` | 4 | `uint` | triangle index, or [`consts::PRIM_MISS`], [`consts::PRIM_INVALID`], [`consts::PRIM_INCOMPLETE`] |
//! | `u` | 8 | `float` | barycentrics: the hit point is `(1-u-v)·v0 + u·v1 + v·v2` |
//! | `v` | 12 | `float` | |
//!
//! [`gpu::shaders::HEADER`] holds those declarations as a self-contained
//! `kdtrace.glsl`, with the special `prim_id`s and counter indices as `#define`s. Write it into your shader include path and
//! `#include "kdtrace.glsl"` (the build script of a crate that depends on kdtrace
//! finds it as a file in the folder `DEP_KDTRACE_INCLUDE`), then declare e.g.
//! `layout(std430, binding = 0) buffer Hits { Hit hits[]; };`.
//!
//! # Threads
//!
//! No global state. [`gpu::GpuContext`], [`gpu::Buffer`], [`trace::Tracer`] and
//! [`trace::TraceBinding`] are `Send + Sync`; several tracers may share one device
//! and be used from several threads at once (the context serialises its queue
//! submissions and command-pool use).
//!
//! [ash]: https://crates.io/crates/ash
//! [gpu-allocator]: https://crates.io/crates/gpu-allocator
#![warn(missing_docs)]

#[macro_use]
mod gpu_struct;
mod abi;
#[cfg(feature = "cli")]
pub mod bench;
/// Constants shared by Rust and GLSL (passed to every kernel as `#define`s).
pub mod consts;
pub mod divergence;
pub mod error;
#[cfg(any(feature = "exact", test))]
pub mod exact;
pub mod ff;
pub mod geom;
pub mod gpu;
pub mod io;
pub mod kdtree;
pub mod ray_query;
pub mod raygen;
pub mod render;
pub mod scene;
#[cfg(feature = "exact")]
pub mod stress;
#[cfg(feature = "cli")]
pub mod sweep;
pub mod trace;
pub mod traversal;
pub mod twolevel;

pub use error::{Error, Result};
pub use geom::{Aabb, Hit, Ray};

/// The Vulkan bindings of kdtrace's public types ([`gpu::AdoptDesc`], [`gpu::BufferRange`], …):
/// use this `ash` so that an engine's handles are the same types.
pub use ash;
/// The vector types of triangles, rays and cameras (`glam::Vec3`).
pub use glam;
/// The allocator that [`gpu::AdoptDesc`] shares with the engine
/// (`Arc<Mutex<gpu_allocator::vulkan::Allocator>>`).
pub use gpu_allocator;
