//! What to render and how: [`RenderSettings`], its point lights and the kind
//! of first hits, and their validation.

use glam::Vec3;

use crate::error::{Error, Result};
use crate::traversal::Traversal;

/// A point light (`kdtrace render --light x,y,z[,intensity]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    /// Its position.
    pub position: Vec3,
    /// Radiant intensity per channel (radiance × area per steradian): a surface
    /// facing it at distance d receives irradiance `intensity / d²`.
    pub intensity: Vec3,
}

/// What to render and how.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel (1 = one ray through each pixel centre; more are
    /// jittered by a seeded, Owen-scrambled Sobol sequence unless
    /// [`jitter`](Self::jitter) is off).
    pub spp: u32,
    /// Ray segments per path at most (camera ray included).
    pub max_depth: u32,
    /// Diffuse bounces per path (path-traced indirect light); 0 = direct light only.
    pub bounces: u32,
    /// Ambient-occlusion rays at the first diffuse hit; 0 = none.
    pub ao_samples: u32,
    /// Length of the ambient-occlusion rays (default: a tenth of the scene's diagonal).
    pub ao_radius: Option<f32>,
    /// Ambient radiance that ambient occlusion lets through (default 1 when the
    /// scene has no other light, else 0.1).
    pub ambient: Option<f32>,
    /// Point lights.
    pub lights: Vec<PointLight>,
    /// Radiance of rays that leave the scene (default 0; with neither lights,
    /// emitters, ambient occlusion nor a background the renderer uses a headlight).
    pub background: Option<Vec3>,
    /// Seed of the sample sequence.
    pub seed: u32,
    /// The traversal for closest hits (its any-hit twin traces the shadow rays).
    pub traversal: Traversal,
    /// Skip what the scene does not need (default). Off: every shading feature
    /// compiled in, every buffer and pipeline made, the headlight's shadow rays
    /// traced: what a renderer that does not inspect the scene does, to measure
    /// the saving.
    pub skip_unneeded: bool,
    /// How the camera rays' first hits are found.
    pub primary: Primary,
    /// Jitter the camera rays inside their pixel when there is more than one
    /// sample (default): the pixel value is the radiance averaged over the pixel's
    /// square (anti-aliased edges). Off: every sample passes through the pixel
    /// centre, so the pixel value is the radiance seen through that point (aliased
    /// edges, as one sample gives), and an area light's penumbra is a 2D integral
    /// over the lamp instead of a 4D one over pixel and lamp (docs/RENDERING.md,
    /// "The light sample converges at the 2D rate").
    pub jitter: bool,
    /// Samples recorded into one submission: 0 (automatic) for about 2^18 paths
    /// per submission; at most 64 either way, and 1 when the image renders in
    /// chunks or its first hits are rasterized. Each submission costs a host
    /// round trip; the images do not depend on it. Checkpoints and `save_rays`
    /// end a submission where they need the results.
    pub samples_per_submission: u32,
    /// Keep the first hits of the first sample ([`RenderOutput::first_hits`](super::RenderOutput::first_hits)).
    pub keep_first_hits: bool,
    /// Write the first sample's rays to this folder, as ray files `kdtrace
    /// trace` reads (32 bytes a ray): `camera.rays`, then per wave
    /// `shadow-K.rays` (the shadow rays of the path vertices at depth K) and
    /// `secondary-K.rays` (the rays of bounce K). To time the renderer's rays
    /// with the tracer alone. The ray queues become host-visible memory for
    /// it (slower on a discrete GPU).
    pub save_rays: Option<std::path::PathBuf>,
}

/// How the first hits are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Primary {
    /// Trace the camera rays (closest hit).
    Trace,
    /// Rasterize a visibility buffer (a graphics pipeline: triangle number per
    /// pixel), then intersect each pixel's camera ray with its triangle alone.
    /// Sub-pixel jitter is then one offset per sample for the whole image.
    Raster,
}

impl RenderSettings {
    /// One sample per pixel, direct light only, the stack traversal.
    pub fn new(width: u32, height: u32) -> Self {
        RenderSettings {
            width,
            height,
            spp: 1,
            max_depth: 8,
            bounces: 0,
            ao_samples: 0,
            ao_radius: None,
            ambient: None,
            lights: Vec::new(),
            background: None,
            seed: 0,
            traversal: Traversal::closest(crate::traversal::Variant::Stack),
            skip_unneeded: true,
            primary: Primary::Trace,
            jitter: true,
            samples_per_submission: 0,
            keep_first_hits: false,
            save_rays: None,
        }
    }

    pub(super) fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidInput(m));
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return bad(format!("image size {}x{}: width and height must be in 1..=16384", self.width, self.height));
        }
        if !(1..=1 << 20).contains(&self.spp) {
            return bad(format!("{} samples per pixel: must be in 1..=1048576", self.spp));
        }
        if !(1..=64).contains(&self.max_depth) {
            return bad(format!("max depth {}: must be in 1..=64", self.max_depth));
        }
        if self.bounces > 64 {
            return bad(format!("{} bounces: at most 64", self.bounces));
        }
        if self.ao_samples > 256 {
            return bad(format!("{} ambient-occlusion rays: at most 256", self.ao_samples));
        }
        if let Some(r) = self.ao_radius {
            if !(r.is_finite() && r > 0.0) {
                return bad(format!("ambient-occlusion radius {r}: must be finite and positive"));
            }
        }
        if let Some(a) = self.ambient {
            if !(a.is_finite() && a >= 0.0) {
                return bad(format!("ambient {a}: must be finite and not negative"));
            }
        }
        if self.lights.len() > MAX_LIGHTS as usize {
            return bad(format!("{} point lights: at most {MAX_LIGHTS}", self.lights.len()));
        }
        for l in &self.lights {
            if !l.position.is_finite() || !l.intensity.is_finite() || l.intensity.min_element() < 0.0 {
                return bad(format!(
                    "point light at {} with intensity {}: position and intensity must be finite, intensity not negative",
                    l.position, l.intensity
                ));
            }
        }
        if let Some(b) = self.background {
            if !b.is_finite() || b.min_element() < 0.0 {
                return bad(format!("background {b}: must be finite and not negative"));
            }
        }
        self.traversal.validate()
    }
}

/// Point lights one render takes at most.
pub const MAX_LIGHTS: u32 = 64;
