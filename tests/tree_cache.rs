//! The kd-tree cache (`kdtrace::kdtree::cache`): round trips, every truncation
//! and bit flip of a file rejected, arbitrary and mutated files never panic,
//! keys that tell scenes and configurations apart, the cache folder's
//! miss / hit / rebuild, and `--tree-cache` on the command line.

mod common;

use std::path::PathBuf;
use std::process::Command;

use glam::Vec3;
use kdtrace::kdtree::cache::{load_or_build, CacheError, CacheKey, CacheOutcome, Stage};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::raygen::SplitMix64;
use kdtrace::scene::Scene;
use proptest::prelude::*;

use common::scene_path;

/// A point of the cube `[-10, 10)³`.
fn point(rng: &mut SplitMix64) -> Vec3 {
    Vec3::new(rng.range(-10.0, 10.0), rng.range(-10.0, 10.0), rng.range(-10.0, 10.0))
}

/// `n` random small triangles in a 20-unit cube (a few degenerate ones included).
fn soup(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|i| {
            let a = point(&mut rng);
            if i % 50 == 7 {
                return [a, a, a];
            }
            [a, a + point(&mut rng) * 0.1, a + point(&mut rng) * 0.1]
        })
        .collect()
}

fn file_of(tree: &KdTree, key: &CacheKey) -> Vec<u8> {
    let mut bytes = Vec::new();
    tree.write_to(&mut bytes, key).unwrap();
    bytes
}

fn read(bytes: &[u8], key: &CacheKey, config: &BuildConfig) -> Result<KdTree, CacheError> {
    KdTree::read_from(&mut &bytes[..], key, config)
}

/// Asserts that two trees are the same, statistics included.
fn assert_same(a: &KdTree, b: &KdTree) {
    assert_eq!(a.nodes, b.nodes);
    assert_eq!(a.prim_indices, b.prim_indices);
    assert_eq!(a.bounds, b.bounds);
    assert_eq!(a.stats, b.stats);
}

/// A small tree's file (a few hundred bytes) and what it was built from.
fn small_file() -> (Vec<[Vec3; 3]>, KdTree, CacheKey, Vec<u8>) {
    let triangles = soup(24, 3);
    let config = BuildConfig::default();
    let tree = KdTree::build(&triangles, &config);
    let key = CacheKey::new(&triangles, &config);
    let bytes = file_of(&tree, &key);
    (triangles, tree, key, bytes)
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kdtrace-tree-cache-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn round_trip_of_a_random_soup_and_the_teapot_is_equal() {
    let config = BuildConfig::default();
    let teapot = Scene::load(&scene_path("teapot.obj")).unwrap().triangles;
    for triangles in [soup(5000, 11), teapot] {
        let tree = KdTree::build(&triangles, &config);
        let key = CacheKey::new(&triangles, &config);
        let bytes = file_of(&tree, &key);
        let loaded = read(&bytes, &key, &config).unwrap();
        assert_same(&tree, &loaded);
        assert!(tree.nodes.len() > 100, "a tree worth caching: {} nodes", tree.nodes.len());
    }
}

#[test]
fn the_tree_of_no_usable_triangle_round_trips() {
    let triangles = vec![[Vec3::ONE; 3]; 3];
    let config = BuildConfig::default();
    let tree = KdTree::build(&triangles, &config);
    let key = CacheKey::new(&triangles, &config);
    assert_same(&tree, &read(&file_of(&tree, &key), &key, &config).unwrap());
}

#[test]
fn every_truncation_is_an_error() {
    let (_, _, key, bytes) = small_file();
    let config = BuildConfig::default();
    for len in 0..bytes.len() {
        match read(&bytes[..len], &key, &config) {
            Err(CacheError::Truncated { found, .. }) => assert_eq!(found, len as u64, "length {len}"),
            other => panic!("length {len} of {}: {other:?}", bytes.len()),
        }
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(read(&longer, &key, &config), Err(CacheError::TrailingBytes { .. })));
}

#[test]
fn every_single_bit_flip_is_an_error() {
    let (_, _, key, bytes) = small_file();
    let config = BuildConfig::default();
    assert!(bytes.len() > 300, "{} bytes", bytes.len());
    let mut flipped = bytes.clone();
    for bit in 0..bytes.len() * 8 {
        flipped[bit / 8] ^= 1 << (bit % 8);
        let result = read(&flipped, &key, &config);
        assert!(result.is_err(), "bit {bit} (byte {}) flipped, the file still loads", bit / 8);
        flipped[bit / 8] ^= 1 << (bit % 8);
    }
    // Every error names the problem; print one of each kind for the record.
    flipped[200] ^= 1;
    let e = read(&flipped, &key, &config).unwrap_err();
    assert!(e.to_string().starts_with("checksum mismatch (stored 0x"), "{e}");
}

#[test]
fn another_scene_or_configuration_is_told_apart() {
    let (mut triangles, _, key, bytes) = small_file();
    let config = BuildConfig::default();
    triangles[10][2].x = f32::from_bits(triangles[10][2].x.to_bits() + 1);
    let moved = CacheKey::new(&triangles, &config);
    assert_ne!(moved.file_name(), key.file_name());
    let e = read(&bytes, &moved, &config).unwrap_err();
    assert!(matches!(e, CacheError::KeyMismatch { what: "scene", .. }), "{e}");
    assert!(e.to_string().starts_with("built for another scene"), "{e}");

    let pbrt = BuildConfig::PBRT_V3;
    let other = CacheKey::new(&triangles[..], &pbrt);
    let e = read(&bytes, &CacheKey { triangles: key.triangles, ..other }, &pbrt).unwrap_err();
    assert!(matches!(e, CacheError::KeyMismatch { what: "configuration", .. }), "{e}");
    let fewer = CacheKey::new(&triangles[..23], &config);
    let e = read(&bytes, &fewer, &config).unwrap_err();
    assert!(matches!(e, CacheError::KeyMismatch { what: "triangle count", .. }), "{e}");
}

#[test]
fn load_or_build_misses_then_hits_and_rebuilds_a_corrupt_file() {
    let dir = temp_dir("folder");
    let triangles = soup(2000, 5);
    let config = BuildConfig::default();
    let built = KdTree::build(&triangles, &config);

    // Miss: built, stored; the folder is created.
    let mut stages = Vec::new();
    let (first, outcome) = load_or_build(&dir, &triangles, &config, None, |s| stages.push(s));
    assert!(matches!(outcome, CacheOutcome::Stored { .. }), "{outcome:?}");
    assert_eq!(stages, [Stage::Hashing, Stage::Building, Stage::Storing]);
    assert_eq!((first.nodes.clone(), first.prim_indices.clone()), (built.nodes.clone(), built.prim_indices.clone()));
    let path = outcome.path().to_path_buf();
    assert_eq!(path, dir.join(CacheKey::new(&triangles, &config).file_name()));
    let listing = || -> Vec<_> { std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect() };
    assert_eq!(listing().len(), 1, "no temporary file left: {:?}", listing());

    // Hit: the same tree, statistics and original build time included.
    let mut stages = Vec::new();
    let (second, outcome) = load_or_build(&dir, &triangles, &config, None, |s| stages.push(s));
    assert!(matches!(outcome, CacheOutcome::Hit { load_seconds, .. } if load_seconds >= 0.0), "{outcome:?}");
    assert_eq!(stages, [Stage::Hashing, Stage::Loading]);
    assert_same(&first, &second);

    // Corrupt: rejected with the reason, rebuilt, replaced by a good file.
    let mut bytes = std::fs::read(&path).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x10;
    std::fs::write(&path, &bytes).unwrap();
    let (third, outcome) = load_or_build(&dir, &triangles, &config, None, |_| {});
    match &outcome {
        CacheOutcome::Rebuilt { reason: CacheError::Checksum { .. }, .. } => {}
        other => panic!("expected a rebuild after a checksum mismatch: {other:?}"),
    }
    assert_eq!(third.nodes, first.nodes);
    let (fourth, outcome) = load_or_build(&dir, &triangles, &config, None, |_| {});
    assert!(matches!(outcome, CacheOutcome::Hit { .. }), "the file was replaced: {outcome:?}");
    assert_same(&third, &fourth);

    // Truncated: the same.
    std::fs::write(&path, &bytes[..middle]).unwrap();
    let (_, outcome) = load_or_build(&dir, &triangles, &config, None, |_| {});
    assert!(matches!(outcome, CacheOutcome::Rebuilt { reason: CacheError::Truncated { .. }, .. }), "{outcome:?}");
    assert_eq!(listing().len(), 1, "{:?}", listing());

    // Another configuration gets its own file.
    let (_, outcome) = load_or_build(&dir, &triangles, &BuildConfig::PBRT_V3, None, |_| {});
    assert!(matches!(outcome, CacheOutcome::Stored { .. }), "{outcome:?}");
    assert_eq!(listing().len(), 2, "{:?}", listing());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_folder_that_cannot_be_written_still_gives_the_tree() {
    let dir = temp_dir("not-a-folder");
    std::fs::write(&dir, b"a file, not a folder").unwrap();
    let triangles = soup(100, 9);
    let config = BuildConfig::default();
    let (tree, outcome) = load_or_build(&dir, &triangles, &config, None, |_| {});
    assert!(matches!(outcome, CacheOutcome::StoreFailed { rejected: None, .. }), "{outcome:?}");
    tree.check(triangles.len()).unwrap();
    std::fs::remove_file(&dir).unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// Arbitrary bytes, bare or behind a valid header, are an error, never a panic.
    #[test]
    fn arbitrary_bytes_are_rejected_without_panic(
        body in prop::collection::vec(any::<u8>(), 0..1200),
        keep_header in any::<bool>(),
    ) {
        let (_, _, key, good) = small_file();
        let mut bytes = if keep_header { good[..112].to_vec() } else { Vec::new() };
        bytes.extend_from_slice(&body);
        prop_assert!(read(&bytes, &key, &BuildConfig::default()).is_err());
    }

    /// A valid file with bytes changed, cut or appended loads only when it is
    /// unchanged, and never panics.
    #[test]
    fn mutated_files_are_rejected_without_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in prop::option::of(any::<prop::sample::Index>()),
        append in prop::collection::vec(any::<u8>(), 0..3),
    ) {
        let (_, tree, key, good) = small_file();
        let mut bytes = good.clone();
        for (at, value) in &edits {
            let i = at.index(bytes.len());
            bytes[i] = *value;
        }
        if let Some(cut) = cut {
            bytes.truncate(cut.index(bytes.len()));
        }
        bytes.extend_from_slice(&append);
        match read(&bytes, &key, &BuildConfig::default()) {
            Ok(loaded) => {
                prop_assert_eq!(&bytes, &good);
                prop_assert_eq!(&loaded.nodes, &tree.nodes);
            }
            Err(e) => prop_assert!(bytes != good, "the unchanged file was rejected: {}", e),
        }
    }
}

// ---------------------------------------------------------------------------
// The command line
// ---------------------------------------------------------------------------

fn kdtrace(args: &[&str], cache: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_kdtrace"))
        .args(args)
        .env("KDTRACE_VALIDATION", "1")
        .env("KDTRACE_TREE_CACHE", cache)
        .output()
        .unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn cli_loads_the_tree_from_the_cache_and_traces_the_same_hits() {
    let dir = temp_dir("cli");
    std::fs::create_dir_all(&dir).unwrap();
    let cache = dir.join("cache");
    let scene = scene_path("teapot.obj");
    let rays = dir.join("teapot.rays");
    let o = kdtrace(
        &["rays", scene.to_str().unwrap(), "-o", rays.to_str().unwrap(), "--kind", "random", "-n", "3000"],
        &cache,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let trace = |hits: &str, flag: bool| {
        let hits = dir.join(hits);
        let mut args = vec!["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", hits.to_str().unwrap()];
        let cache_arg = cache.to_str().unwrap().to_string();
        if flag {
            args.extend(["--tree-cache", &cache_arg]);
        }
        let o = kdtrace(&args, &dir.join("unused-env-cache"));
        assert!(o.status.success(), "{}", stderr(&o));
        (std::fs::read(hits).unwrap(), stderr(&o))
    };

    // First run builds and stores, the second loads (flag, then the variable).
    let (first, err) = trace("first.hits", true);
    assert!(!err.contains("loaded kd-tree"), "{err}");
    let files: Vec<_> = std::fs::read_dir(&cache).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let (second, err) = trace("second.hits", true);
    assert!(err.contains("loaded kd-tree from cache") && err.contains("(build took"), "{err}");
    assert_eq!(first, second, "hits from the cached tree differ");
    let o = kdtrace(
        &["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", dir.join("env.hits").to_str().unwrap()],
        &cache,
    );
    assert!(stderr(&o).contains("loaded kd-tree from cache"), "KDTRACE_TREE_CACHE: {}", stderr(&o));
    assert_eq!(std::fs::read(dir.join("env.hits")).unwrap(), first);

    // A corrupt file: a warning, a rebuild, the same hits, a good file again.
    let mut bytes = std::fs::read(&files[0]).unwrap();
    let last = bytes.len() - 20;
    bytes[last] ^= 0x01;
    std::fs::write(&files[0], &bytes).unwrap();
    let (third, err) = trace("third.hits", true);
    assert!(err.contains("warning: tree cache") && err.contains("rejected (checksum mismatch"), "{err}");
    assert_eq!(first, third);
    let (_, err) = trace("fourth.hits", true);
    assert!(err.contains("loaded kd-tree from cache"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
