//! A cache of built kd-trees on disk: [`KdTree::write_to`] and
//! [`KdTree::read_from`] store and load a tree in a versioned little-endian
//! binary format, and [`load_or_build`] keeps one file per scene and build
//! configuration in a folder (`kdtrace --tree-cache DIR`).
//!
//! A file is keyed by a [`CacheKey`]: a hash of the triangles' f32 bits, their
//! count, and a hash of the build configuration's `Debug` string (so a field
//! added to [`BuildConfig`] later changes the key without further work); the
//! format version is in the file and in its name. Loading never trusts a file:
//! it rejects a wrong magic, version or key, bounds every count by the data
//! actually present before allocating more than a chunk, verifies a 64-bit
//! checksum over everything, and runs [`KdTree::check`]. Every failure is a
//! [`CacheError`], never a panic; [`load_or_build`] then rebuilds and replaces
//! the file.
//!
//! # Format, version 2 (version 1: interior nodes without the empty-child flags, the above child at bit 2)
//!
//! All numbers little-endian (kdtrace targets little-endian machines, as its
//! GPU upload does), no padding:
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 8 | magic `KDTCACHE` |
//! | 8 | 4 | format version, u32 ([`FORMAT_VERSION`]) |
//! | 12 | 4 | flags, u32, 0 |
//! | 16 | 8 | key: hash of the triangles' bytes, u64 |
//! | 24 | 8 | key: hash of the build configuration's `Debug` string, u64 |
//! | 32 | 8 | key: triangle count (input, skipped ones included), u64 |
//! | 40 | 8 | triangles in the tree (not skipped), u64 |
//! | 48 | 8 | node count `N`, u64 |
//! | 56 | 8 | primitive index count `P`, u64 |
//! | 64 | 24 | bounds: min x, y, z, max x, y, z, f32 |
//! | 88 | 8 | build time of the original build, seconds, f64 |
//! | 96 | 8 | peak scratch bytes of the original build, u64 |
//! | 104 | 8 | threads of the original build, u64 |
//! | 112 | 8 `N` | nodes ([`KdNode`], 8 bytes each) |
//! | 112 + 8 `N` | 4 `P` | primitive indices, u32 |
//! | 112 + 8 `N` + 4 `P` | 8 | checksum, u64 |
//!
//! The checksum is [`hash64`] over the three hashes of the header, the node
//! bytes and the index bytes. The other statistics are recomputed from the tree
//! on load ([`BuildStats::compute`]), so they always describe the tree loaded.

use std::fs::File;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use bytemuck::Pod;
use glam::Vec3;
use rayon::prelude::*;

use super::build::BuildProgress;
use super::config::BuildConfig;
use super::node::{mark_empty_children, KdNode, MAX_CHILD_INDEX};
use super::stats::BuildStats;
use super::tree::KdTree;
use crate::geom::Aabb;

/// The first 8 bytes of every tree cache file.
pub const MAGIC: [u8; 8] = *b"KDTCACHE";

/// The version of the file format; bumped whenever the layout or the meaning of
/// a field changes, which invalidates every older file.
pub const FORMAT_VERSION: u32 = 2;

/// Bytes before the node array.
pub const HEADER_BYTES: usize = 112;

/// Bytes of the checksum that ends a file.
const CHECKSUM_BYTES: usize = 8;

/// The largest chunk the loader allocates ahead of the data it has read: a
/// corrupt count costs at most this much memory before the file runs out.
const READ_CHUNK_BYTES: usize = 64 << 20;

/// Why a tree cache file was not used, or could not be written.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// Reading or writing failed.
    #[error("{what}: {source}")]
    Io {
        /// What was being done, with the file when there is one.
        what: String,
        /// The underlying I/O error.
        #[source]
        source: io::Error,
    },

    /// The file does not start with [`MAGIC`].
    #[error("not a kdtrace tree cache file (magic {found:02x?})")]
    BadMagic {
        /// The first bytes found.
        found: Vec<u8>,
    },

    /// The file was written in another format version.
    #[error("format version {found}, this kdtrace reads version {FORMAT_VERSION}")]
    Version {
        /// The version in the file.
        found: u32,
    },

    /// The file holds the tree of another scene or build configuration.
    #[error("built for another {what} (stored {stored:#018x}, expected {expected:#018x})")]
    KeyMismatch {
        /// `scene` (the triangles' hash), `triangle count` or `configuration`.
        what: &'static str,
        /// The value in the file.
        stored: u64,
        /// The value of the scene and configuration asked for.
        expected: u64,
    },

    /// The header holds a value no valid file can have.
    #[error("implausible header: {0}")]
    BadHeader(String),

    /// The file ends early. `expected` is the length the header declares, or
    /// the header's own length when the header itself is cut short.
    #[error("truncated: expected {expected} bytes, found {found}")]
    Truncated {
        /// Bytes the file should have.
        expected: u64,
        /// Bytes it has.
        found: u64,
    },

    /// The file goes on after the checksum.
    #[error("longer than the {expected} bytes its header declares")]
    TrailingBytes {
        /// Bytes the file should have.
        expected: u64,
    },

    /// The checksum does not match the contents.
    #[error("checksum mismatch (stored {stored:#018x}, computed {computed:#018x})")]
    Checksum {
        /// The checksum at the end of the file.
        stored: u64,
        /// The checksum of the bytes read.
        computed: u64,
    },

    /// The bounds are neither empty nor a finite box.
    #[error("bounds {0:?} are not a finite box")]
    BadBounds(Aabb),

    /// The tree fails [`KdTree::check`].
    #[error("the tree fails its check: {0}")]
    BadTree(String),
}

impl CacheError {
    fn io(what: impl Into<String>) -> impl FnOnce(io::Error) -> CacheError {
        let what = what.into();
        move |source| CacheError::Io { what, source }
    }
}

// ---------------------------------------------------------------------------
// Hashing
// ---------------------------------------------------------------------------

/// An odd 64-bit constant (2⁶⁴ / φ) for the multiplications of [`mix`].
const K: u64 = 0x9E37_79B9_7F4A_7C15;

/// Bytes hashed per task by [`hash64`].
const HASH_BLOCK: usize = 1 << 20;

/// One step of the hash: `h` absorbs the word `w`. A bijection of `h` for a
/// fixed `w` and of `w` for a fixed `h` (xor, multiplication by an odd
/// constant, xorshift), so a change to any single word always changes the
/// result.
#[inline(always)]
fn mix(h: u64, w: u64) -> u64 {
    let x = (h ^ w).wrapping_mul(K);
    x ^ (x >> 32)
}

/// MurmurHash3's 64-bit finalizer (Appleby): spreads every input bit over the output.
fn fmix64(mut h: u64) -> u64 {
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^= h >> 33;
    h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    h ^ (h >> 33)
}

/// Hashes one block as four interleaved lanes of 64-bit words (independent
/// multiplication chains, so the CPU overlaps them); the tail is zero-padded
/// and the length mixed in.
fn hash_block(seed: u64, bytes: &[u8]) -> u64 {
    const LANES: [u64; 4] =
        [0x243F_6A88_85A3_08D3, 0x1319_8A2E_0370_7344, 0xA409_3822_299F_31D0, 0x082E_FA98_EC4E_6C89];
    let mut lanes = LANES.map(|l| l ^ seed);
    let mut absorb = |block: &[u8]| {
        for (i, lane) in lanes.iter_mut().enumerate() {
            let word: [u8; 8] = block[8 * i..8 * i + 8].try_into().unwrap();
            *lane = mix(*lane, u64::from_le_bytes(word));
        }
    };
    let mut blocks = bytes.chunks_exact(32);
    for block in &mut blocks {
        absorb(block);
    }
    let rest = blocks.remainder();
    if !rest.is_empty() {
        let mut padded = [0u8; 32];
        padded[..rest.len()].copy_from_slice(rest);
        absorb(&padded);
    }
    fmix64(lanes.iter().fold(bytes.len() as u64, |h, &lane| mix(h, lane)))
}

/// A 64-bit hash of `bytes` (not cryptographic): fixed 1 MiB blocks hashed in
/// parallel with rayon, their hashes combined in order, so the value does not
/// depend on the thread count. Any change confined to one aligned 8-byte word
/// (a single bit flip, say) always changes the hash; other changes go
/// unnoticed with a probability of about 2⁻⁶⁴.
pub fn hash64(bytes: &[u8]) -> u64 {
    let hash = |(i, block): (usize, &[u8])| hash_block(i as u64, block);
    let blocks: Vec<u64> = if bytes.len() <= HASH_BLOCK {
        bytes.chunks(HASH_BLOCK).enumerate().map(hash).collect()
    } else {
        bytes.par_chunks(HASH_BLOCK).enumerate().map(hash).collect()
    };
    fmix64(blocks.iter().fold(bytes.len() as u64 ^ K, |h, &b| mix(h, b)))
}

/// The hash of several hashes, in order.
fn combine(hashes: &[u64]) -> u64 {
    fmix64(hashes.iter().fold(hashes.len() as u64, |h, &w| mix(h, w)))
}

/// What a cached tree was built from: the file of a scene and configuration is
/// used only when its key equals the key of the scene and configuration at hand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CacheKey {
    /// [`hash64`] of the triangles' bytes (their f32 bits: `-0.0` and `0.0`
    /// differ, and any one-ulp move changes the key).
    pub triangles: u64,
    /// Number of triangles, skipped ones included.
    pub triangle_count: u64,
    /// [`hash64`] of the configuration's `Debug` string, which names every
    /// field and prints every f32 exactly.
    pub config: u64,
}

impl CacheKey {
    /// The key of `triangles` built with `config`. Hashes the triangles in
    /// parallel (its cost beside a build's: docs/BUILDER.md).
    pub fn new(triangles: &[[Vec3; 3]], config: &BuildConfig) -> CacheKey {
        CacheKey {
            triangles: hash64(bytemuck::cast_slice(triangles)),
            triangle_count: triangles.len() as u64,
            config: hash64(format!("{config:?}").as_bytes()),
        }
    }

    /// The file name of this key in a cache folder: 16 hex digits of the hash of
    /// the key and [`FORMAT_VERSION`], then `.kdtree`.
    pub fn file_name(&self) -> String {
        let id = combine(&[self.triangles, self.triangle_count, self.config, FORMAT_VERSION as u64]);
        format!("{id:016x}.kdtree")
    }
}

// ---------------------------------------------------------------------------
// The header
// ---------------------------------------------------------------------------

/// The fixed-size start of a file (see the module docs for the layout).
struct Header {
    key: CacheKey,
    included: u64,
    nodes: u64,
    prims: u64,
    bounds: Aabb,
    build_seconds: f64,
    peak_scratch_bytes: u64,
    threads: u64,
}

impl Header {
    fn of(tree: &KdTree, key: &CacheKey) -> Header {
        let s = &tree.stats;
        Header {
            key: *key,
            included: s.triangles as u64,
            nodes: tree.nodes.len() as u64,
            prims: tree.prim_indices.len() as u64,
            bounds: tree.bounds,
            build_seconds: s.build_seconds,
            peak_scratch_bytes: s.peak_scratch_bytes as u64,
            threads: s.threads as u64,
        }
    }

    /// The length of the whole file this header declares (saturating: an
    /// absurd count gives an absurd length, which the data then falls short of).
    fn file_bytes(&self) -> u64 {
        let body = self.nodes.saturating_mul(8).saturating_add(self.prims.saturating_mul(4));
        body.saturating_add((HEADER_BYTES + CHECKSUM_BYTES) as u64)
    }

    fn to_bytes(&self) -> [u8; HEADER_BYTES] {
        let mut out = Vec::with_capacity(HEADER_BYTES);
        out.extend_from_slice(&MAGIC);
        for word in [FORMAT_VERSION, 0] {
            out.extend_from_slice(&word.to_le_bytes());
        }
        let key = &self.key;
        for word in [key.triangles, key.config, key.triangle_count, self.included, self.nodes, self.prims] {
            out.extend_from_slice(&word.to_le_bytes());
        }
        for coordinate in self.bounds.min.to_array().into_iter().chain(self.bounds.max.to_array()) {
            out.extend_from_slice(&coordinate.to_le_bytes());
        }
        out.extend_from_slice(&self.build_seconds.to_le_bytes());
        for word in [self.peak_scratch_bytes, self.threads] {
            out.extend_from_slice(&word.to_le_bytes());
        }
        out.try_into().expect("the header is HEADER_BYTES long")
    }

    /// Parses and validates a complete header against the expected key.
    fn parse(bytes: &[u8; HEADER_BYTES], expected: &CacheKey) -> Result<Header, CacheError> {
        let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
        let f32_at = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        if bytes[..8] != MAGIC {
            return Err(CacheError::BadMagic { found: bytes[..8].to_vec() });
        }
        if u32_at(8) != FORMAT_VERSION {
            return Err(CacheError::Version { found: u32_at(8) });
        }
        if u32_at(12) != 0 {
            return Err(CacheError::BadHeader(format!("flags {:#x}, expected 0", u32_at(12))));
        }
        let header = Header {
            key: CacheKey { triangles: u64_at(16), config: u64_at(24), triangle_count: u64_at(32) },
            included: u64_at(40),
            nodes: u64_at(48),
            prims: u64_at(56),
            bounds: Aabb::new(
                Vec3::new(f32_at(64), f32_at(68), f32_at(72)),
                Vec3::new(f32_at(76), f32_at(80), f32_at(84)),
            ),
            build_seconds: f64::from_le_bytes(bytes[88..96].try_into().unwrap()),
            peak_scratch_bytes: u64_at(96),
            threads: u64_at(104),
        };

        // Key: the triangle count first, so that a different mesh size reads as such.
        let key = &header.key;
        for (what, stored, expected) in [
            ("triangle count", key.triangle_count, expected.triangle_count),
            ("scene", key.triangles, expected.triangles),
            ("configuration", key.config, expected.config),
        ] {
            if stored != expected {
                return Err(CacheError::KeyMismatch { what, stored, expected });
            }
        }

        // Counts: bounded by what a tree can hold (2^28 nodes, leaf offsets 32
        // bits), not yet by the data present (see `read_pod_vec`).
        let bad = |message: String| Err(CacheError::BadHeader(message));
        if header.included > header.key.triangle_count {
            return bad(format!("{} triangles in the tree of {}", header.included, header.key.triangle_count));
        }
        if header.nodes == 0 || header.nodes > MAX_CHILD_INDEX as u64 + 1 {
            return bad(format!("{} nodes", header.nodes));
        }
        if header.prims > u32::MAX as u64 {
            return bad(format!("{} primitive indices", header.prims));
        }
        if !(header.build_seconds.is_finite() && header.build_seconds >= 0.0) {
            return bad(format!("build time {} s", header.build_seconds));
        }
        if usize::try_from(header.peak_scratch_bytes).is_err() || usize::try_from(header.threads).is_err() {
            return bad(format!("scratch {} bytes, {} threads", header.peak_scratch_bytes, header.threads));
        }
        let b = header.bounds;
        let finite_box = b.min.is_finite() && b.max.is_finite() && b.min.cmple(b.max).all();
        if !(finite_box || b == Aabb::EMPTY) {
            return Err(CacheError::BadBounds(b));
        }
        Ok(header)
    }
}

// ---------------------------------------------------------------------------
// Writing and reading
// ---------------------------------------------------------------------------

/// The checksum stored at the end of a file.
fn checksum(header: &[u8], nodes: &[KdNode], prims: &[u32]) -> u64 {
    combine(&[hash64(header), hash64(bytemuck::cast_slice(nodes)), hash64(bytemuck::cast_slice(prims))])
}

/// Reads until `buf` is full or the reader ends; returns the bytes read.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match r.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// Reads `count` values of `T`, allocating at most [`READ_CHUNK_BYTES`] ahead of
/// the data read so far: a corrupt count runs into the end of the file, not
/// into an allocation failure. `done` counts the file's bytes read so far and
/// `expected` is the file's declared length, for the error.
fn read_pod_vec<T: Pod>(r: &mut impl Read, count: u64, done: &mut u64, expected: u64) -> Result<Vec<T>, CacheError> {
    let size = std::mem::size_of::<T>();
    let chunk = (READ_CHUNK_BYTES / size) as u64;
    let mut values: Vec<T> = Vec::new();
    while (values.len() as u64) < count {
        let start = values.len();
        let n = chunk.min(count - start as u64) as usize;
        values.reserve_exact(n);
        values.resize(start + n, T::zeroed());
        let got = read_full(r, bytemuck::cast_slice_mut(&mut values[start..])).map_err(CacheError::io("read"))?;
        *done += got as u64;
        if got < n * size {
            return Err(CacheError::Truncated { expected, found: *done });
        }
    }
    Ok(values)
}

impl KdTree {
    /// Writes the tree in the cache format (module docs) under `key`, the key of
    /// the triangles and configuration it was built from. Writes the arrays as
    /// they are in memory (no per-element work) in a few large writes; wrap a
    /// small-write sink in a `BufWriter` yourself.
    pub fn write_to(&self, w: &mut impl Write, key: &CacheKey) -> Result<(), CacheError> {
        let header = Header::of(self, key).to_bytes();
        let sum = checksum(&header, &self.nodes, &self.prim_indices);
        let mut write = || -> io::Result<()> {
            w.write_all(&header)?;
            w.write_all(bytemuck::cast_slice(&self.nodes))?;
            w.write_all(bytemuck::cast_slice(&self.prim_indices))?;
            w.write_all(&sum.to_le_bytes())
        };
        write().map_err(CacheError::io("write"))
    }

    /// Reads a tree written by [`KdTree::write_to`], which must be the whole rest
    /// of `r` (bytes after it are an error), if it was built under `key` with
    /// `config` (the key's configuration; used to recompute the statistics).
    ///
    /// Never trusts the data: checks the magic, version and key first, reads
    /// the arrays in chunks so that a corrupt count cannot allocate far beyond
    /// the data present, verifies the checksum, the bounds and
    /// [`KdTree::check`]. Every failure is an error, never a panic. The
    /// statistics are recomputed ([`BuildStats::compute`]) except the original
    /// build's `build_seconds`, `peak_scratch_bytes` and `threads`.
    pub fn read_from(r: &mut impl Read, key: &CacheKey, config: &BuildConfig) -> Result<KdTree, CacheError> {
        debug_assert_eq!(key.config, hash64(format!("{config:?}").as_bytes()), "`config` is not the key's");
        // Header: magic and version first, so that another file reads as such.
        let mut header_bytes = [0u8; HEADER_BYTES];
        let got = read_full(r, &mut header_bytes).map_err(CacheError::io("read"))?;
        if got >= MAGIC.len() && header_bytes[..MAGIC.len()] != MAGIC {
            return Err(CacheError::BadMagic { found: header_bytes[..MAGIC.len()].to_vec() });
        }
        let version = u32::from_le_bytes(header_bytes[8..12].try_into().unwrap());
        if got >= 12 && version != FORMAT_VERSION {
            return Err(CacheError::Version { found: version });
        }
        if got < HEADER_BYTES {
            let expected = (HEADER_BYTES + CHECKSUM_BYTES) as u64;
            return Err(CacheError::Truncated { expected, found: got as u64 });
        }
        let header = Header::parse(&header_bytes, key)?;

        // Arrays and checksum.
        let expected = header.file_bytes();
        let mut done = HEADER_BYTES as u64;
        let nodes: Vec<KdNode> = read_pod_vec(r, header.nodes, &mut done, expected)?;
        let prim_indices: Vec<u32> = read_pod_vec(r, header.prims, &mut done, expected)?;
        let mut stored = [0u8; CHECKSUM_BYTES];
        let got = read_full(r, &mut stored).map_err(CacheError::io("read"))?;
        if got < CHECKSUM_BYTES {
            return Err(CacheError::Truncated { expected, found: done + got as u64 });
        }
        if read_full(r, &mut [0u8; 1]).map_err(CacheError::io("read"))? != 0 {
            return Err(CacheError::TrailingBytes { expected });
        }
        let stored = u64::from_le_bytes(stored);
        let computed = checksum(&header_bytes, &nodes, &prim_indices);
        if stored != computed {
            return Err(CacheError::Checksum { stored, computed });
        }

        // The tree itself.
        let triangle_count = header.key.triangle_count as usize;
        let mut tree = KdTree { nodes, prim_indices, bounds: header.bounds, stats: BuildStats::default() };
        tree.check(triangle_count).map_err(CacheError::BadTree)?;
        // The empty-child flags are derived, never trusted from the file.
        mark_empty_children(&mut tree.nodes);
        let included = header.included as usize;
        tree.stats = BuildStats::compute(&tree, config, included, triangle_count - included, header.build_seconds);
        tree.stats.peak_scratch_bytes = header.peak_scratch_bytes as usize;
        tree.stats.threads = header.threads as usize;
        Ok(tree)
    }
}

// ---------------------------------------------------------------------------
// The cache folder
// ---------------------------------------------------------------------------

/// What [`load_or_build`] is doing, for a progress display.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Hashing the triangles and configuration into a [`CacheKey`].
    Hashing,
    /// Reading and checking a cache file.
    Loading,
    /// Building the tree (no usable file).
    Building,
    /// Writing the new cache file.
    Storing,
}

/// How [`load_or_build`] got its tree.
#[derive(Debug)]
pub enum CacheOutcome {
    /// Loaded from `path`; `load_seconds` covers hashing, reading and checking.
    Hit {
        /// The cache file.
        path: PathBuf,
        /// Seconds from the call to the checked tree.
        load_seconds: f64,
    },
    /// No file yet: built and stored at `path`.
    Stored {
        /// The new cache file.
        path: PathBuf,
        /// Seconds spent writing it.
        store_seconds: f64,
    },
    /// The file at `path` was rejected for `reason`; built and replaced.
    Rebuilt {
        /// The replaced cache file.
        path: PathBuf,
        /// Why the old file was not used.
        reason: CacheError,
        /// Seconds spent writing the new one.
        store_seconds: f64,
    },
    /// Built, but the file could not be written (`reason`); the tree is still good.
    StoreFailed {
        /// The cache file that could not be written.
        path: PathBuf,
        /// Why an existing file was not used, if there was one.
        rejected: Option<CacheError>,
        /// Why writing failed.
        reason: CacheError,
    },
}

impl CacheOutcome {
    /// The cache file concerned.
    pub fn path(&self) -> &Path {
        match self {
            CacheOutcome::Hit { path, .. }
            | CacheOutcome::Stored { path, .. }
            | CacheOutcome::Rebuilt { path, .. }
            | CacheOutcome::StoreFailed { path, .. } => path,
        }
    }
}

/// The tree of `triangles` built with `config`: loaded from the folder `dir`
/// when it holds a good file for them ([`CacheKey::file_name`]), else built with
/// [`KdTree::build`] and stored there (the folder is created when missing).
/// A rejected file is replaced. `progress` hears each [`Stage`] as it starts;
/// a build reports to `build_progress` ([`KdTree::build_with_progress`]).
///
/// The file is written to a temporary name in `dir` and renamed into place, so
/// the final name never holds a partial file, and concurrent writers of the
/// same key leave one whole file. Failing to store is not an error: the
/// outcome says so and the built tree is returned.
pub fn load_or_build(
    dir: &Path,
    triangles: &[[Vec3; 3]],
    config: &BuildConfig,
    build_progress: Option<&BuildProgress>,
    mut progress: impl FnMut(Stage),
) -> (KdTree, CacheOutcome) {
    let start = Instant::now();
    progress(Stage::Hashing);
    let key = CacheKey::new(triangles, config);
    let path = dir.join(key.file_name());
    let rejected = match File::open(&path) {
        Ok(mut file) => {
            progress(Stage::Loading);
            match KdTree::read_from(&mut file, &key, config) {
                Ok(tree) => return (tree, CacheOutcome::Hit { path, load_seconds: start.elapsed().as_secs_f64() }),
                Err(e) => Some(e),
            }
        }
        // No file (or no folder) is a plain miss; a file that exists but cannot
        // be opened is rejected.
        Err(_) if !path.exists() => None,
        Err(source) => Some(CacheError::Io { what: "open".into(), source }),
    };
    progress(Stage::Building);
    let tree = KdTree::build_with_progress(triangles, config, build_progress);
    progress(Stage::Storing);
    let store_start = Instant::now();
    let outcome = match store(dir, &path, &tree, &key) {
        Err(reason) => CacheOutcome::StoreFailed { path, rejected, reason },
        Ok(()) => {
            let store_seconds = store_start.elapsed().as_secs_f64();
            match rejected {
                None => CacheOutcome::Stored { path, store_seconds },
                Some(reason) => CacheOutcome::Rebuilt { path, reason, store_seconds },
            }
        }
    };
    (tree, outcome)
}

/// Writes `tree` to a temporary file in `dir` and renames it to `path`; removes
/// the temporary file on failure.
fn store(dir: &Path, path: &Path, tree: &KdTree, key: &CacheKey) -> Result<(), CacheError> {
    static SERIAL: AtomicU64 = AtomicU64::new(0);
    std::fs::create_dir_all(dir).map_err(CacheError::io(format!("creating {}", dir.display())))?;
    let name = path.file_name().map_or_else(|| "tree".into(), |n| n.to_string_lossy().into_owned());
    let serial = SERIAL.fetch_add(1, Ordering::Relaxed);
    let temp = dir.join(format!(".{name}.{}-{serial}.tmp", std::process::id()));
    let result = File::create(&temp)
        .map_err(CacheError::io(format!("creating {}", temp.display())))
        .and_then(|mut file| tree.write_to(&mut file, key))
        .and_then(|()| {
            std::fs::rename(&temp, path).map_err(CacheError::io(format!(
                "renaming {} to {}",
                temp.display(),
                path.display()
            )))
        });
    if result.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small tree over a few triangles of a grid, and its key.
    fn small() -> (Vec<[Vec3; 3]>, KdTree, CacheKey) {
        let triangles: Vec<[Vec3; 3]> = (0..12)
            .map(|i| {
                let o = Vec3::new((i % 4) as f32, (i / 4) as f32, (i % 3) as f32 * 0.5);
                [o, o + Vec3::X, o + Vec3::Y]
            })
            .collect();
        let config = BuildConfig::default();
        let tree = KdTree::build(&triangles, &config);
        let key = CacheKey::new(&triangles, &config);
        (triangles, tree, key)
    }

    fn bytes_of(tree: &KdTree, key: &CacheKey) -> Vec<u8> {
        let mut bytes = Vec::new();
        tree.write_to(&mut bytes, key).unwrap();
        bytes
    }

    #[test]
    fn header_layout_matches_the_documented_offsets() {
        let (_, tree, key) = small();
        let bytes = bytes_of(&tree, &key);
        assert_eq!(bytes.len(), HEADER_BYTES + 8 * tree.nodes.len() + 4 * tree.prim_indices.len() + 8);
        assert_eq!(&bytes[..8], b"KDTCACHE");
        assert_eq!(bytes[8..12], FORMAT_VERSION.to_le_bytes());
        assert_eq!(bytes[16..24], key.triangles.to_le_bytes());
        assert_eq!(bytes[24..32], key.config.to_le_bytes());
        assert_eq!(bytes[32..40], 12u64.to_le_bytes());
        assert_eq!(bytes[48..56], (tree.nodes.len() as u64).to_le_bytes());
        assert_eq!(bytes[64..68], tree.bounds.min.x.to_le_bytes());
        assert_eq!(bytes[88..96], tree.stats.build_seconds.to_le_bytes());
        assert_eq!(bytes[HEADER_BYTES..HEADER_BYTES + 8], *bytemuck::bytes_of(&tree.nodes[0]));
    }

    #[test]
    fn hash64_detects_every_single_bit_flip_and_ignores_threads() {
        let bytes: Vec<u8> =
            (0..3 * HASH_BLOCK as u32 + 77).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect();
        let h = hash64(&bytes);
        let serial = fmix64(
            bytes
                .chunks(HASH_BLOCK)
                .enumerate()
                .fold(bytes.len() as u64 ^ K, |h, (i, b)| mix(h, hash_block(i as u64, b))),
        );
        assert_eq!(h, serial, "the parallel hash equals the serial definition");
        let mut flipped = bytes.clone();
        for bit in (0..flipped.len() * 8).step_by(104_729) {
            flipped[bit / 8] ^= 1 << (bit % 8);
            assert_ne!(hash64(&flipped), h, "bit {bit}");
            flipped[bit / 8] ^= 1 << (bit % 8);
        }
        // Short inputs: every bit of every length up to 40 bytes, and the length itself.
        for len in 0..40usize {
            let short = &bytes[..len];
            assert_ne!(hash64(short), hash64(&bytes[..len + 1]), "length {len}");
            for bit in 0..len * 8 {
                let mut f = short.to_vec();
                f[bit / 8] ^= 1 << (bit % 8);
                assert_ne!(hash64(&f), hash64(short), "length {len} bit {bit}");
            }
        }
    }

    #[test]
    fn key_and_file_name_change_with_one_ulp_and_with_the_config() {
        let (mut triangles, _, key) = small();
        let config = BuildConfig::default();
        assert_eq!(CacheKey::new(&triangles, &config), key);
        triangles[5][1].y = f32::from_bits(triangles[5][1].y.to_bits() + 1);
        let moved = CacheKey::new(&triangles, &config);
        assert_ne!(moved.triangles, key.triangles);
        assert_ne!(moved.file_name(), key.file_name());
        let other = CacheKey::new(&triangles, &BuildConfig { empty_bonus: 0.1000001, ..config });
        assert_ne!(other.config, moved.config);
        assert_eq!(key.file_name().len(), 16 + ".kdtree".len());
    }

    #[test]
    fn header_fields_out_of_range_are_rejected_before_reading_on() {
        let (_, tree, key) = small();
        let config = BuildConfig::default();
        let good = bytes_of(&tree, &key);
        let with = |at: usize, value: &[u8]| {
            let mut b = good.clone();
            b[at..at + value.len()].copy_from_slice(value);
            KdTree::read_from(&mut b.as_slice(), &key, &config).unwrap_err()
        };
        assert!(matches!(with(0, b"KDTCACHX"), CacheError::BadMagic { .. }));
        assert!(matches!(with(8, &1u32.to_le_bytes()), CacheError::Version { found: 1 }));
        assert!(matches!(with(12, &1u32.to_le_bytes()), CacheError::BadHeader(_)));
        assert!(matches!(with(16, &0u64.to_le_bytes()), CacheError::KeyMismatch { what: "scene", .. }));
        assert!(matches!(with(24, &0u64.to_le_bytes()), CacheError::KeyMismatch { what: "configuration", .. }));
        assert!(matches!(with(32, &13u64.to_le_bytes()), CacheError::KeyMismatch { what: "triangle count", .. }));
        assert!(matches!(with(40, &13u64.to_le_bytes()), CacheError::BadHeader(_)));
        assert!(matches!(with(48, &0u64.to_le_bytes()), CacheError::BadHeader(_)));
        assert!(matches!(with(48, &u64::MAX.to_le_bytes()), CacheError::BadHeader(_)));
        assert!(matches!(with(56, &(1u64 << 40).to_le_bytes()), CacheError::BadHeader(_)));
        assert!(matches!(with(64, &f32::NAN.to_le_bytes()), CacheError::BadBounds(_)));
        assert!(matches!(with(88, &(-1.0f64).to_le_bytes()), CacheError::BadHeader(_)));
        // A node count at the 28-bit limit reads into the end of the file
        // without allocating gigabytes first.
        let e = with(48, &(MAX_CHILD_INDEX as u64 + 1).to_le_bytes());
        assert!(matches!(e, CacheError::Truncated { found, .. } if found == good.len() as u64), "{e}");
    }
}
