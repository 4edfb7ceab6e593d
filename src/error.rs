//! The library's error type.

use std::path::PathBuf;

/// Everything the library can fail with. Messages say what was wrong and where.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scene file could not be read or is malformed; `line` is 1-based when known.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Scene {
        /// The file that failed.
        path: PathBuf,
        /// 1-based line number, when the error has one.
        line: Option<usize>,
        /// What was wrong.
        message: String,
    },

    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file that failed.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },

    /// A Vulkan call failed.
    #[error("Vulkan: {what} failed: {result}")]
    Vulkan {
        /// The failed call, e.g. `vkCreateInstance`.
        what: &'static str,
        /// The `VkResult` it returned.
        result: ash::vk::Result,
    },

    /// The Vulkan loader could not be loaded.
    #[error("Vulkan loader: {0}")]
    Loader(String),

    /// No usable Vulkan device, or the requested one does not exist.
    #[error("no usable Vulkan device: {0}")]
    NoDevice(String),

    /// The device lacks a feature or a limit is too small for the scene or batch.
    #[error("device limit: {0}")]
    DeviceLimit(String),

    /// GPU memory allocation failed.
    #[error("GPU allocation: {0}")]
    Allocation(#[from] gpu_allocator::AllocationError),

    /// The validation layer reported messages (tests treat any message as an error).
    #[error("Vulkan validation reported {} message(s); first: {}", .0.len(), .0.first().map(String::as_str).unwrap_or(""))]
    Validation(Vec<String>),

    /// Bad input to a library call (empty scene, bad option, malformed ray file, ...).
    #[error("{0}")]
    InvalidInput(String),
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Attaches the name of the failed Vulkan call to a `vk::Result`.
pub(crate) trait VkContext<T> {
    fn vk(self, what: &'static str) -> Result<T>;
}

impl<T> VkContext<T> for std::result::Result<T, ash::vk::Result> {
    fn vk(self, what: &'static str) -> Result<T> {
        self.map_err(|result| Error::Vulkan { what, result })
    }
}
