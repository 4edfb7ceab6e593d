//! `kdtrace info`: the Vulkan devices and their subgroup properties.

use anyhow::{bail, Result};

use kdtrace::gpu::list_devices;

/// `kdtrace info`: one line per Vulkan device and its subgroup properties.
pub fn info() -> Result<()> {
    let devices = list_devices()?;
    if devices.is_empty() {
        bail!("no Vulkan device with a compute queue");
    }
    for (i, d) in devices.iter().enumerate() {
        println!("{i}: {d}");
        println!(
            "   subgroup size {} (min {}, max {}, size control {}), maxStorageBufferRange {} B",
            d.subgroup_size,
            d.min_subgroup_size,
            d.max_subgroup_size,
            d.subgroup_size_control,
            d.max_storage_buffer_range
        );
    }
    Ok(())
}
