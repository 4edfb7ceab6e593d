//! The benchmark matrix of `kdtrace bench` (issue #8): scenes × builder settings
//! × traversals (variant, short-stack size, packet width, robustness) × ray kinds
//! (camera, shadow, reflection, diffuse bounce, random), on the Vulkan device and
//! through the multithreaded CPU twin and, with the `embree` feature, Intel
//! Embree 3 — every cell timed after a warm-up and judged against the exact
//! reference on a sample of its rays, so each speed comes with its error.
//! Outputs: a Markdown table, CSV and PNG charts ([`report`], [`plot`]).
//! With `--images`, rendered images against a converged reference ([`images`]).

#[cfg(feature = "embree")]
pub mod embree;
pub mod images;
pub mod matrix;
pub mod plot;
pub mod rays;
pub mod report;

pub use matrix::{run_scene, Backend, Cell, MatrixOptions};
pub use rays::RayKind;
