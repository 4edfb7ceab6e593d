//! Images of renders (feature `image`): tone mapping, sRGB PNG and linear
//! OpenEXR files, and cost heatmaps.

use std::path::Path;

use glam::Vec3;

/// Tone maps linear radiance for display: scaled by `exposure`, then clamped to
/// [0, 1] and sRGB-encoded (see [`to_image`]).
pub fn tone_map(colors: &[Vec3], width: u32, height: u32, exposure: f32) -> image::RgbImage {
    let scaled: Vec<Vec3> = colors.iter().map(|c| *c * exposure).collect();
    to_image(&scaled, width, height)
}

/// Writes linear radiance as a 32-bit float RGB OpenEXR file.
pub fn save_exr(path: &Path, colors: &[Vec3], width: u32, height: u32) -> crate::Result<()> {
    let data: Vec<f32> = colors.iter().flat_map(|c| c.to_array()).collect();
    let image = image::Rgb32FImage::from_raw(width, height, data)
        .ok_or_else(|| crate::Error::InvalidInput(format!("{} colours for a {width}x{height} image", colors.len())))?;
    image.save(path).map_err(|e| crate::Error::InvalidInput(format!("writing {}: {e}", path.display())))
}

/// Reads a float RGB image (OpenEXR, or any format the `image` crate reads) as
/// linear colours, with its width and height.
pub fn load_linear(path: &Path) -> crate::Result<(Vec<Vec3>, u32, u32)> {
    let image = image::open(path)
        .map_err(|e| crate::Error::InvalidInput(format!("reading {}: {e}", path.display())))?
        .into_rgb32f();
    let (w, h) = image.dimensions();
    Ok((image.pixels().map(|p| Vec3::new(p[0], p[1], p[2])).collect(), w, h))
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
