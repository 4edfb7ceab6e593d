//! Rendering: the wavefront renderer ([`render`]: shadows, mirrors, ambient
//! occlusion, path-traced diffuse light, all passes on the device), camera rays,
//! and (feature `image`) tone mapping, image output (PNG, linear EXR) and cost heatmaps.

mod abi;
mod consts;
#[cfg(feature = "image")]
mod images;
mod output;
mod passes;
mod plan;
mod resources;
mod sample;
mod settings;
mod structs;
mod wavefront;

use glam::Vec3;

pub use abi::RenderParams;
#[cfg(feature = "image")]
pub use images::{heatmap, load_linear, save_exr, to_image, tone_map};
pub use output::{RenderOutput, RenderStats};
pub use plan::RenderPlan;
pub use sample::ld2;
pub use settings::{PointLight, Primary, RenderSettings, MAX_LIGHTS};
pub use wavefront::{render, render_progressive};

use crate::geom::{Hit, Ray};
use crate::scene::{Camera, Scene};

/// One ray per pixel through the pixel centre, row-major from the top-left.
pub fn camera_rays(camera: &Camera, width: u32, height: u32) -> Vec<Ray> {
    let mut rays = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height {
        for x in 0..width {
            let (origin, dir) = camera.ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
            rays.push(Ray::new(origin, dir, 0.0, f32::INFINITY));
        }
    }
    rays
}

/// One ray per pixel in Morton (Z) order over the image, and the row-major pixel
/// index of each ray. Every aligned run of 4^k rays covers a 2^k × 2^k tile (and
/// 2·4^k a 2:1 one), so a packet of consecutive lanes holds neighbouring pixels.
pub fn camera_rays_morton(camera: &Camera, width: u32, height: u32) -> (Vec<Ray>, Vec<u32>) {
    let pixels = morton_pixels(width, height);
    let rays = pixels
        .iter()
        .map(|&p| {
            let (x, y) = (p % width, p / width);
            let (origin, dir) = camera.ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
            Ray::new(origin, dir, 0.0, f32::INFINITY)
        })
        .collect();
    (rays, pixels)
}

/// The row-major index of every pixel, in Morton (Z) order over the image.
pub fn morton_pixels(width: u32, height: u32) -> Vec<u32> {
    let side = width.max(height).next_power_of_two() as u64;
    let mut pixels = Vec::with_capacity(width as usize * height as usize);
    for code in 0..side * side {
        let (x, y) = morton_decode(code);
        if x < width && y < height {
            pixels.push(y * width + x);
        }
    }
    pixels
}

/// The (x, y) of a 2D Morton code (x in the even bits).
fn morton_decode(code: u64) -> (u32, u32) {
    let compact = |mut v: u64| {
        v &= 0x5555_5555_5555_5555;
        v = (v | (v >> 1)) & 0x3333_3333_3333_3333;
        v = (v | (v >> 2)) & 0x0F0F_0F0F_0F0F_0F0F;
        v = (v | (v >> 4)) & 0x00FF_00FF_00FF_00FF;
        v = (v | (v >> 8)) & 0x0000_FFFF_0000_FFFF;
        v = (v | (v >> 16)) & 0x0000_0000_FFFF_FFFF;
        v as u32
    };
    (compact(code), compact(code >> 1))
}

/// The geometric normal of triangle `prim`, facing against `dir`.
pub fn facing_normal(scene: &Scene, prim: u32, dir: Vec3) -> Vec3 {
    let [a, b, c] = scene.triangles[prim as usize];
    let n = (b - a).cross(c - a).normalize_or_zero();
    if n.dot(dir) > 0.0 {
        -n
    } else {
        n
    }
}

/// Headlight diffuse shading in linear RGB: `Kd · (0.1 + 0.9·|cos θ|) + Ke`
/// (mirrors, `illum 3` with black `Kd`, use `0.6·Ks` instead of `Kd`);
/// background a dark grey. Returns one linear colour per ray.
pub fn shade_headlight(scene: &Scene, rays: &[Ray], hits: &[Hit]) -> Vec<Vec3> {
    rays.iter()
        .zip(hits)
        .map(|(ray, hit)| {
            if !hit.is_hit() {
                return Vec3::splat(0.05);
            }
            let dir = Vec3::from(ray.dir).normalize_or_zero();
            let n = facing_normal(scene, hit.prim_id, dir);
            let m = &scene.materials[scene.material_ids[hit.prim_id as usize] as usize];
            let cos = n.dot(-dir).abs();
            // Mirrors (black Kd, bright Ks) show as a light grey until reflections exist.
            let albedo = if m.illum == 3 && m.kd.max_element() < 0.05 { 0.6 * m.ks } else { m.kd };
            albedo * (0.1 + 0.9 * cos) + m.ke.min(Vec3::ONE)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_order_covers_every_pixel_once_in_tiles() {
        let camera = Camera::frame(&crate::geom::Aabb::new(Vec3::ZERO, Vec3::ONE));
        let (rays, pixels) = camera_rays_morton(&camera, 37, 21);
        assert_eq!(rays.len(), 37 * 21);
        let mut seen = pixels.clone();
        seen.sort_unstable();
        assert!(seen.iter().copied().eq(0..37 * 21));
        // The first 16 rays form the 4x4 tile at the origin.
        let tile: Vec<(u32, u32)> = pixels[..16].iter().map(|p| (p % 37, p / 37)).collect();
        assert!(tile.iter().all(|&(x, y)| x < 4 && y < 4));
        let row_major = camera_rays(&camera, 37, 21);
        for (w, h) in [(1, 1), (1, 7), (9, 1), (64, 48), (48, 64), (100, 3)] {
            let mut p = morton_pixels(w, h);
            p.sort_unstable();
            assert!(p.iter().copied().eq(0..w * h), "{w}x{h}");
        }
        for (ray, &p) in rays.iter().zip(&pixels) {
            assert_eq!(*ray, row_major[p as usize]);
        }
    }
}
