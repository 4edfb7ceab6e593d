//! The pipeline cache every kdtrace pipeline is created with: the engine's, or
//! one loaded from and saved to a file.

use ash::vk;

use crate::error::{Error, Result};

use super::GpuContext;

/// A context's pipeline cache: the handle, whether kdtrace made it (and destroys
/// it), and the file it saves to when the context is dropped.
#[derive(Default)]
pub(super) struct PipelineCacheSlot {
    pub(super) handle: vk::PipelineCache,
    pub(super) owned: bool,
    pub(super) file: Option<std::path::PathBuf>,
}

impl GpuContext {
    /// The pipeline cache kdtrace creates its pipelines with (null when none was
    /// set: [`GpuContext::use_pipeline_cache`], [`GpuContext::load_pipeline_cache`]).
    pub fn pipeline_cache(&self) -> vk::PipelineCache {
        self.pipeline_cache.lock().map(|c| c.handle).unwrap_or_default()
    }

    /// Creates kdtrace's pipelines (trace, render, rasterizer) with the engine's
    /// `cache` from now on; kdtrace never destroys it. A cache made by
    /// [`GpuContext::load_pipeline_cache`] is destroyed (unsaved).
    ///
    /// # Safety
    /// `cache` must be a pipeline cache of this context's device (or null) and
    /// stay alive, externally synchronized as Vulkan requires (kdtrace uses it
    /// from whichever thread compiles a pipeline), until it is replaced or the
    /// context is dropped.
    pub unsafe fn use_pipeline_cache(&self, cache: vk::PipelineCache) {
        let mut slot = self.pipeline_cache.lock().unwrap_or_else(|p| p.into_inner());
        self.release_cache(&mut slot);
        *slot = PipelineCacheSlot { handle: cache, owned: false, file: None };
    }

    /// Creates a pipeline cache from the file `path` (a cache saved by an earlier
    /// run on the same device and driver; a missing file, or data the driver
    /// finds incompatible, gives an empty cache) and uses it for every pipeline;
    /// when the context is dropped the cache is written back to `path` (see
    /// [`GpuContext::save_pipeline_cache`]). The command line keeps one per device
    /// and driver (docs/CLI.md).
    ///
    /// Errors: `Error::Vulkan` when the cache cannot be created.
    pub fn load_pipeline_cache(&self, path: &std::path::Path) -> Result<()> {
        let data = std::fs::read(path).unwrap_or_default();
        // Only data this device wrote: its header (length 32, version one, the
        // device's vendor, device and cache UUID) is checked here, as Vulkan asks
        // callers to hand back only data vkGetPipelineCacheData returned.
        // SAFETY: the context's physical device.
        let props = unsafe { self.instance.get_physical_device_properties(self.physical_device) };
        let word = |i: usize| u32::from_le_bytes([data[4 * i], data[4 * i + 1], data[4 * i + 2], data[4 * i + 3]]);
        let ours = data.len() >= 32
            && word(0) == 32
            && word(1) == vk::PipelineCacheHeaderVersion::ONE.as_raw() as u32
            && word(2) == props.vendor_id
            && word(3) == props.device_id
            && data[16..32] == props.pipeline_cache_uuid;
        let data = if ours { data } else { Vec::new() };
        let info = vk::PipelineCacheCreateInfo::default().initial_data(&data);
        // SAFETY: a valid create-info on this context's device.
        let handle = unsafe { self.device.create_pipeline_cache(&info, None) }
            .map_err(|result| Error::Vulkan { what: "vkCreatePipelineCache", result })?;
        let mut slot = self.pipeline_cache.lock().unwrap_or_else(|p| p.into_inner());
        self.release_cache(&mut slot);
        *slot = PipelineCacheSlot { handle, owned: true, file: Some(path.to_path_buf()) };
        Ok(())
    }

    /// Writes the current pipeline cache's data to `path` (through a temporary
    /// file renamed into place, so a concurrent reader sees the old or the new
    /// file whole). Nothing to write without a cache.
    ///
    /// Errors: `Error::Vulkan` from `vkGetPipelineCacheData`, `Error::Io` from the file.
    pub fn save_pipeline_cache(&self, path: &std::path::Path) -> Result<()> {
        let slot = self.pipeline_cache.lock().unwrap_or_else(|p| p.into_inner());
        if slot.handle == vk::PipelineCache::null() {
            return Ok(());
        }
        // SAFETY: the cache is this device's; the lock keeps others from replacing it meanwhile.
        let data = unsafe { self.device.get_pipeline_cache_data(slot.handle) }
            .map_err(|result| Error::Vulkan { what: "vkGetPipelineCacheData", result })?;
        drop(slot);
        let io = |source| Error::Io { path: path.to_path_buf(), source };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        std::fs::write(&tmp, &data).map_err(|source| Error::Io { path: tmp.clone(), source })?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Saves (when it has a file) and destroys an owned cache in `slot`.
    pub(super) fn release_cache(&self, slot: &mut PipelineCacheSlot) {
        if !slot.owned || slot.handle == vk::PipelineCache::null() {
            return;
        }
        if let Some(file) = slot.file.take() {
            // SAFETY: as in save_pipeline_cache.
            let saved = unsafe { self.device.get_pipeline_cache_data(slot.handle) }
                .map_err(|result| Error::Vulkan { what: "vkGetPipelineCacheData", result })
                .and_then(|data| {
                    if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
                        let _ = std::fs::create_dir_all(dir);
                    }
                    let tmp = file.with_extension(format!("tmp{}", std::process::id()));
                    std::fs::write(&tmp, &data)
                        .and_then(|()| std::fs::rename(&tmp, &file))
                        .map_err(|source| Error::Io { path: file.clone(), source })
                });
            if let Err(e) = saved {
                eprintln!("kdtrace: the pipeline cache was not saved: {e}");
            }
        }
        // SAFETY: every pipeline created with it exists independently of it.
        unsafe { self.device.destroy_pipeline_cache(slot.handle, None) };
        slot.handle = vk::PipelineCache::null();
        slot.owned = false;
    }
}
