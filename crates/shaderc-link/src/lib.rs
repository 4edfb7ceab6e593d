//! Nothing to call: this crate exists for its build script, which adds the
//! static glslang and SPIRV-Tools libraries to the link of whatever depends on
//! it (kdtrace's build script) when the system's `libshaderc_combined.a` does
//! not contain them (Debian and Ubuntu: package `libshaderc-dev`). See `build.rs`.
//!
//! A dependent names it with `extern crate kdtrace_shaderc_link as _;` so that
//! rustc links it although nothing of it is used.
