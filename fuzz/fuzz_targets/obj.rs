//! The OBJ parser on arbitrary bytes: a scene or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = kdtrace::scene::Scene::from_obj_bytes(std::path::Path::new("fuzz.obj"), data);
});
