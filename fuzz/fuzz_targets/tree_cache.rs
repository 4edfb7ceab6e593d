//! The tree cache loader on arbitrary bytes and on mutated valid files: a tree
//! or an error, never a panic; a tree it accepts passes `KdTree::check` and,
//! when it came from a mutated file, is the unchanged original.
#![no_main]
use std::sync::OnceLock;

use glam::Vec3;
use kdtrace::kdtree::cache::CacheKey;
use kdtrace::kdtree::{BuildConfig, KdTree};
use libfuzzer_sys::fuzz_target;

/// A small scene's triangles, its tree, key and valid cache file.
struct Valid {
    triangles: Vec<[Vec3; 3]>,
    tree: KdTree,
    key: CacheKey,
    file: Vec<u8>,
}

fn valid() -> &'static Valid {
    static VALID: OnceLock<Valid> = OnceLock::new();
    VALID.get_or_init(|| {
        let triangles: Vec<[Vec3; 3]> = (0..40)
            .map(|i| {
                let o = Vec3::new((i % 5) as f32, (i / 5 % 4) as f32, (i / 20) as f32 * 0.7);
                [o, o + Vec3::new(0.9, 0.1, 0.0), o + Vec3::new(0.2, 0.8, 0.3)]
            })
            .collect();
        let config = BuildConfig::default();
        let tree = KdTree::build(&triangles, &config);
        let key = CacheKey::new(&triangles, &config);
        let mut file = Vec::new();
        tree.write_to(&mut file, &key).expect("writing to a Vec");
        Valid { triangles, tree, key, file }
    })
}

fuzz_target!(|data: &[u8]| {
    let v = valid();
    let config = BuildConfig::default();
    // First byte even: `data` is the file. Odd: `data` edits the valid file,
    // three bytes per edit (little-endian position, xor mask); a trailing
    // lone byte cuts the file at that fraction of its length.
    let Some((&mode, rest)) = data.split_first() else { return };
    let file = if mode % 2 == 0 {
        rest.to_vec()
    } else {
        let mut file = v.file.clone();
        let mut edits = rest.chunks_exact(3);
        for edit in &mut edits {
            let at = u16::from_le_bytes([edit[0], edit[1]]) as usize % file.len();
            file[at] ^= edit[2];
        }
        if let [cut] = edits.remainder() {
            file.truncate(file.len() * *cut as usize / 256);
        }
        file
    };
    if let Ok(tree) = KdTree::read_from(&mut file.as_slice(), &v.key, &config) {
        tree.check(v.triangles.len()).expect("an accepted tree passes its check");
        if mode % 2 == 1 {
            assert_eq!(file, v.file, "a changed file was accepted");
            assert_eq!(tree.nodes, v.tree.nodes);
        }
    }
});
