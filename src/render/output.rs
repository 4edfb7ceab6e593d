//! What a render returns: the image ([`RenderOutput`]) and what it measured
//! ([`RenderStats`]), and the readback of the accumulated samples into pixels.

use glam::Vec3;

use super::plan::RenderPlan;
use crate::error::Result;
use crate::gpu::Buffer;

/// What a render measured.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    /// Camera rays (traced, or their first hits rasterized).
    pub camera_rays: u64,
    /// Reflection and bounce rays traced.
    pub secondary_rays: u64,
    /// Shadow and ambient-occlusion rays traced (any hit).
    pub shadow_rays: u64,
    /// GPU time of the trace dispatches (timestamps), when the device has them:
    /// the sum of the three below.
    pub trace_seconds: Option<f64>,
    /// GPU time of tracing the camera rays (`None` when rasterized).
    pub trace_camera_seconds: Option<f64>,
    /// GPU time of tracing the shadow and ambient-occlusion rays (any hit).
    pub trace_shadow_seconds: Option<f64>,
    /// GPU time of tracing the reflection and bounce rays.
    pub trace_secondary_seconds: Option<f64>,
    /// GPU time of the ray generation, shade and resolve dispatches.
    pub shade_seconds: Option<f64>,
    /// `shade_seconds` by kernel: ray generation, shade, resolve.
    pub pass_seconds: Option<[f64; 3]>,
    /// Wall time of pipeline creation and uploads.
    pub setup_seconds: f64,
    /// Wall time of the sample loop (submits, waits, counter readbacks).
    pub render_seconds: f64,
    /// Queue submissions.
    pub submits: u32,
    /// Rays the tracer reported invalid or incomplete (0 unless something is wrong).
    pub bad_rays: u64,
    /// GPU time of the visibility-buffer draws and their conversion to hits.
    pub raster_seconds: Option<f64>,
    /// Rasterized first hits whose ray passes just outside their triangle (edge ties).
    pub raster_edge_pixels: u64,
    /// The first hits were rasterized ([`Primary::Raster`](super::Primary::Raster)).
    pub rasterized: bool,
}

impl RenderStats {
    /// All rays: camera, secondary and shadow.
    pub fn rays(&self) -> u64 {
        self.camera_rays + self.secondary_rays + self.shadow_rays
    }

    /// The rays the tracer traced: [`RenderStats::rays`] less the camera rays
    /// when their first hits were rasterized.
    pub fn traced_rays(&self) -> u64 {
        self.rays() - if self.rasterized { self.camera_rays } else { 0 }
    }
}

/// A rendered image: linear radiance, row-major from the top-left.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Mean radiance of each pixel's samples.
    pub pixels: Vec<Vec3>,
    /// The plan it followed.
    pub plan: RenderPlan,
    /// The first hits of the first sample, row-major, when
    /// [`RenderSettings::keep_first_hits`](super::RenderSettings::keep_first_hits) asked for them.
    pub first_hits: Option<Vec<crate::geom::Hit>>,
    /// What it measured.
    pub stats: RenderStats,
    /// Pixels (row-major indices) that had a ray the tracer marked invalid or
    /// incomplete in some sample: their value lacks that ray's light.
    pub bad_pixels: Vec<usize>,
}

/// The accumulated sums the last `Frame::copy_image` read back: per pixel, the
/// mean of `samples` samples' radiance, and the pixels that had a bad ray (the
/// shade and resolve kernels count a pixel's bad rays in its sum's w).
pub(super) fn read_image(readback: &Buffer, pixel_count: u64, samples: u32) -> Result<(Vec<Vec3>, Vec<usize>)> {
    let sums: &[[f32; 4]] = bytemuck::cast_slice(readback.read(0, (pixel_count * super::abi::ACCUM_BYTES) as usize)?);
    let scale = 1.0 / samples as f32;
    let pixels = sums.iter().map(|s| Vec3::new(s[0], s[1], s[2]) * scale).collect();
    let bad_pixels = sums.iter().enumerate().filter(|(_, s)| s[3] > 0.0).map(|(i, _)| i).collect();
    Ok((pixels, bad_pixels))
}
