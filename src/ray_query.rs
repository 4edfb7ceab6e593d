//! The ray-query backend ([`Backend::RayQuery`](crate::trace::Backend)): the
//! driver's own acceleration structures and ray queries
//! (`VK_KHR_acceleration_structure`, `VK_KHR_ray_query`) as the peer of the
//! kd-tree kernels, behind the same [`Tracer`](crate::trace::Tracer) API and
//! `record_trace` contract: the same ray and hit buffers, the same hit records
//! (`t` in the ray's own parameter, the scene's `prim_id`, barycentrics `u`, `v`
//! weighting the second and third vertex), the same treatment of invalid rays.
//!
//! The scene goes to the driver as a triangle soup of the triangles that can be
//! hit (the kd-tree builder's [`is_skipped`] ones, degenerate or non-finite, are
//! left out), sorted by the Morton code of their centroids: the driver's BVH
//! quality depends on the order it gets (docs/ACCURACY.md). A `u32` per triangle maps
//! the driver's primitive index back to the scene's, applied by the kernel
//! (`glsl/trace_ray_query.comp`) when it writes a hit.

use std::sync::Arc;

use ash::vk;
use glam::Vec3;

use crate::consts::{RQ_BINDINGS, RQ_BINDING_SCENE, RQ_SPECS, RQ_SPEC_ANY_HIT, TRACE_WORKGROUP_SIZE};
use crate::error::{Error, Result};
use crate::geom::Aabb;
use crate::gpu::{in_order, shaders, Buffer, GpuContext, Kernel, KernelDesc, TriangleAccel};
use crate::kdtree::build::is_skipped;
use crate::trace::TraceParams;

/// A scene in the driver's acceleration structures, with the map from the
/// driver's primitive index to the scene's triangle index.
pub(crate) struct RayQueryScene {
    /// The bottom and top levels.
    pub accel: TriangleAccel,
    /// `prim_ids[i]`: the scene's index of the driver's triangle `i` (`u32`, storage buffer).
    pub prim_ids: Buffer,
    /// The box around the traced triangles.
    pub bounds: Aabb,
    /// Triangles of the scene (traced or not).
    pub triangle_count: usize,
}

impl RayQueryScene {
    /// Sorts the traceable triangles (see [`driver_order`]) and builds the driver's
    /// structures over them. Submits on the context's queue and waits.
    ///
    /// Errors: `Error::DeviceLimit` naming what the device lacks of the ray-query
    /// backend, or a limit the scene exceeds; `Error::InvalidInput` for a scene
    /// without a triangle that can be hit.
    /// Bytes on the device: the acceleration structures and the id map.
    pub fn device_bytes(&self) -> u64 {
        self.accel.device_bytes() + self.prim_ids.size
    }

    pub fn upload(ctx: &Arc<GpuContext>, triangles: &[[Vec3; 3]]) -> Result<RayQueryScene> {
        ctx.ray_query()?;
        let order = driver_order(triangles);
        if order.is_empty() {
            return Err(Error::InvalidInput("the scene has no triangles that can be hit".into()));
        }
        let limit = ctx.info.max_storage_buffer_range;
        let bytes = std::mem::size_of_val(order.as_slice()) as u64;
        if bytes > limit {
            return Err(Error::DeviceLimit(format!(
                "the scene's {} triangle indices take {bytes} bytes; {} allows {limit} per storage buffer (maxStorageBufferRange)",
                order.len(),
                ctx.info.name
            )));
        }
        let vertices: Vec<[f32; 3]> = order.iter().flat_map(|&p| triangles[p as usize].map(|v| v.to_array())).collect();
        let bounds = order.iter().fold(Aabb::EMPTY, |b, &p| triangles[p as usize].iter().fold(b, |b, &v| b.grow(v)));
        let accel = TriangleAccel::build(ctx, &vertices)?;
        let prim_ids =
            Buffer::with_data(ctx, bytemuck::cast_slice(&order), vk::BufferUsageFlags::STORAGE_BUFFER, "prim ids")?;
        Ok(RayQueryScene { accel, prim_ids, bounds, triangle_count: triangles.len() })
    }
}

/// The indices of the triangles the ray-query backend gives the driver, in the
/// order it gives them: every triangle that can be hit (not
/// [`is_skipped`]) once, sorted by the 63-bit Morton code of its centroid in
/// their common box (ties by index), so that neighbours in space are
/// neighbours in the list, as BVH builders that split lists in order want.
pub fn driver_order(triangles: &[[Vec3; 3]]) -> Vec<u32> {
    let kept: Vec<u32> = (0..triangles.len() as u32).filter(|&i| !is_skipped(&triangles[i as usize])).collect();
    let centroid = |i: u32| {
        let [a, b, c] = triangles[i as usize];
        (a + b + c) / 3.0
    };
    let bounds = kept.iter().fold(Aabb::EMPTY, |b, &i| b.grow(centroid(i)));
    let extent = bounds.extent();
    let cell = |x: f32, lo: f32, span: f32| {
        if span > 0.0 {
            (((x - lo) / span).clamp(0.0, 1.0) * ((1u32 << 21) - 1) as f32) as u64
        } else {
            0
        }
    };
    let mut keyed: Vec<(u64, u32)> = kept
        .into_iter()
        .map(|i| {
            let p = centroid(i);
            let code = spread_bits(cell(p.x, bounds.min.x, extent.x))
                | spread_bits(cell(p.y, bounds.min.y, extent.y)) << 1
                | spread_bits(cell(p.z, bounds.min.z, extent.z)) << 2;
            (code, i)
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// The 21 low bits of `x`, spread to every third bit (bit k to bit 3k).
fn spread_bits(x: u64) -> u64 {
    let mut x = x & 0x1F_FFFF;
    x = (x | x << 32) & 0x001F_0000_0000_FFFF;
    x = (x | x << 16) & 0x001F_0000_FF00_00FF;
    x = (x | x << 8) & 0x100F_00F0_0F00_F00F;
    x = (x | x << 4) & 0x10C3_0C30_C30C_30C3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// The ray-query kernel (`glsl/trace_ray_query.comp`), closest or any hit.
pub(crate) fn kernel(ctx: &Arc<GpuContext>, any_hit: bool) -> Result<Kernel> {
    ctx.ray_query()?;
    Kernel::new(
        ctx,
        &KernelDesc {
            name: "trace_ray_query",
            spirv: shaders::TRACE_RAY_QUERY,
            bindings: RQ_BINDINGS,
            push_constant_size: std::mem::size_of::<TraceParams>() as u32,
            spec_constants: &in_order::<_, { RQ_SPECS as usize }>([(RQ_SPEC_ANY_HIT, any_hit as u32)]),
            workgroup_size: TRACE_WORKGROUP_SIZE,
            acceleration_structures: &[RQ_BINDING_SCENE],
            ..Default::default()
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_bits_interleave() {
        assert_eq!(spread_bits(0b1), 0b1);
        assert_eq!(spread_bits(0b11), 0b1001);
        assert_eq!(spread_bits(0x1F_FFFF), 0x1249_2492_4924_9249);
        assert_eq!(spread_bits(1 << 20), 1 << 60);
    }

    #[test]
    fn the_order_holds_every_traceable_triangle_once_and_sorts_by_space() {
        let tri = |x: f32| [Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 0.0, 0.0), Vec3::new(x, 1.0, 0.0)];
        let degenerate = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        let non_finite = [Vec3::ZERO, Vec3::X, Vec3::new(f32::NAN, 0.0, 0.0)];
        let triangles = vec![tri(5.0), degenerate, tri(0.0), non_finite, tri(9.0), tri(2.0)];
        assert_eq!(driver_order(&triangles), vec![2, 5, 0, 4]);
        assert!(driver_order(&[degenerate]).is_empty());
    }
}
