//! The ray-file reader on arbitrary bytes: rays or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(rays) = kdtrace::io::rays_from_bytes(data) {
        assert_eq!(rays.len() * 32, data.len());
    }
});
