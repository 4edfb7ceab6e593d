//! The dependent's build script: kdtrace hands it the folder of its GLSL header
//! (`links = "kdtrace"`), where an engine's shader compiler would look for
//! `#include "kdtrace.glsl"`.

fn main() {
    let dir = std::env::var("DEP_KDTRACE_INCLUDE").expect("DEP_KDTRACE_INCLUDE is not set");
    let header = std::path::Path::new(&dir).join("kdtrace.glsl");
    let text = std::fs::read_to_string(&header).unwrap_or_else(|e| panic!("{}: {e}", header.display()));
    for needed in ["#define PRIM_MISS", "struct Ray", "struct Hit"] {
        assert!(text.contains(needed), "{} lacks {needed:?}", header.display());
    }
    println!("cargo:rustc-env=KDTRACE_GLSL={}", header.display());
}
