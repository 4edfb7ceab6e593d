//! The shaderc crate (shaderc-sys, with its feature `prefer-static-linking`)
//! links the system's `libshaderc_combined.a`. On Debian and Ubuntu
//! (`libshaderc-dev`) that archive holds shaderc alone: glslang and SPIRV-Tools
//! are separate static libraries (`glslang-dev`, `spirv-tools`), which
//! shaderc-sys does not name, and the shared `libshaderc.so` leaves their
//! symbols undefined (`undefined reference: glslang::TProgram::…` at the link,
//! or a crash when run). This build script names them, so that a crate whose
//! build script compiles shaders with shaderc links without any Cargo
//! configuration of its own.
//!
//! It looks where shaderc-sys does (`SHADERC_LIB_DIR`, `$VULKAN_SDK/lib`, then
//! the system library directories) and does nothing when `libshaderc_combined.a`
//! is missing or already defines glslang (the Vulkan SDK's, or one built from
//! source). Of the libraries below it names those present, static, in an order
//! that satisfies single-pass linkers (each before the ones it uses).

use std::env;
use std::fs;
use std::path::{Path, PathBuf};

/// glslang's and SPIRV-Tools' static libraries, users first. Newer glslang
/// releases fold some into `glslang`; the missing ones are skipped.
const LIBS: &[&str] = &[
    "glslang",
    "SPIRV",
    "MachineIndependent",
    "HLSL",
    "GenericCodeGen",
    "OSDependent",
    "OGLCompiler",
    "glslang-default-resource-limits",
    "SPIRV-Tools-opt",
    "SPIRV-Tools",
];

/// A symbol that a `libshaderc_combined.a` with glslang inside defines
/// (`glslang::TProgram::TProgram()`).
const GLSLANG_SYMBOL: &[u8] = b"_ZN7glslang8TProgramC1Ev";

fn main() {
    println!("cargo:rerun-if-env-changed=SHADERC_LIB_DIR");
    println!("cargo:rerun-if-env-changed=VULKAN_SDK");
    let Some(dir) = search_dir() else { return };
    let combined = dir.join("libshaderc_combined.a");
    println!("cargo:rerun-if-changed={}", combined.display());
    match archive_index(&combined) {
        Some(index) if !contains(&index, GLSLANG_SYMBOL) => {}
        _ => return,
    }
    println!("cargo:rustc-link-search=native={}", dir.display());
    for lib in LIBS {
        if dir.join(format!("lib{lib}.a")).is_file() {
            // `-bundle`: named at the final link, not copied into this crate's rlib.
            println!("cargo:rustc-link-lib=static:-bundle={lib}");
        }
    }
    println!("cargo:rustc-link-lib=dylib=stdc++");
}

/// The directory in which shaderc-sys will find shaderc, or `None` off Linux.
fn search_dir() -> Option<PathBuf> {
    if let Some(dir) = env::var_os("SHADERC_LIB_DIR") {
        return Some(dir.into());
    }
    if let Some(sdk) = env::var_os("VULKAN_SDK") {
        return Some(Path::new(&sdk).join("lib"));
    }
    if env::var("CARGO_CFG_TARGET_OS").ok()? != "linux" {
        return None;
    }
    let arch = match env::var("CARGO_CFG_TARGET_ARCH").ok()?.as_str() {
        "x86" => "i386".to_owned(),
        arch => arch.to_owned(),
    };
    [format!("/usr/lib/{arch}-linux-gnu"), "/usr/lib64".into(), "/usr/lib".into()]
        .into_iter()
        .map(PathBuf::from)
        .find(|dir| dir.join("libshaderc_combined.a").is_file())
}

/// The symbol index of a System V / GNU `ar` archive (its first member, `/`),
/// or `None` when the file cannot be read or has none.
fn archive_index(path: &Path) -> Option<Vec<u8>> {
    let bytes = fs::read(path).ok()?;
    let header = bytes.strip_prefix(b"!<arch>\n")?.get(..60)?;
    if !header.starts_with(b"/ ") {
        return None;
    }
    let size: usize = std::str::from_utf8(&header[48..58]).ok()?.trim().parse().ok()?;
    bytes.get(68..68 + size).map(<[u8]>::to_vec)
}

fn contains(haystack: &[u8], needle: &[u8]) -> bool {
    haystack.windows(needle.len()).any(|w| w == needle)
}
