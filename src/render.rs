//! Primary-ray rendering: camera rays in, a shaded image out. Shading is a
//! headlight (a light at the eye) on the MTL diffuse colour; later passes add
//! shadows, mirrors and diffuse bounces.

use glam::Vec3;

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

/// sRGB-encodes linear colours into an 8-bit RGB image.
pub fn to_image(colors: &[Vec3], width: u32, height: u32) -> image::RgbImage {
    let encode = |c: f32| {
        let c = c.clamp(0.0, 1.0);
        let s = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
        (s * 255.0 + 0.5) as u8
    };
    image::RgbImage::from_fn(width, height, |x, y| {
        let c = colors[(y * width + x) as usize];
        image::Rgb([encode(c.x), encode(c.y), encode(c.z)])
    })
}

/// A per-pixel cost image: `values` mapped through a blue–red–yellow ramp scaled
/// to the largest value. Returns the image, the maximum and the mean.
pub fn heatmap(values: &[u32], width: u32, height: u32) -> (image::RgbImage, u32, f64) {
    let max = values.iter().copied().max().unwrap_or(0).max(1);
    let mean = values.iter().map(|&v| v as f64).sum::<f64>() / values.len().max(1) as f64;
    let ramp = |x: f32| -> [u8; 3] {
        let x = x.clamp(0.0, 1.0);
        let (r, g, b) = if x < 0.5 { (2.0 * x, 0.0, 1.0 - 2.0 * x) } else { (1.0, 2.0 * (x - 0.5), 0.0) };
        [(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]
    };
    let image = image::RgbImage::from_fn(width, height, |x, y| {
        image::Rgb(ramp(values[(y * width + x) as usize] as f32 / max as f32))
    });
    (image, max, mean)
}
