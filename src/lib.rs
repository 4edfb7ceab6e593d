//! kdtrace: SAH kd-tree ray tracing on the GPU through Vulkan compute.
pub mod bench;
pub mod consts;
pub mod error;
pub mod geom;
pub mod gpu;
pub mod io;
pub mod kdtree;
pub mod raygen;
pub mod reference;
pub mod render;
pub mod scene;
pub mod sweep;
pub mod trace;

pub use error::{Error, Result};
pub use geom::{Aabb, Hit, Ray};
