//! The 8-byte kd-tree node (pbrt-v3; Hapala & Havran), decoded on the GPU by
//! `glsl/shared/kdnode.glsl`; both take the tag width and the leaf tag from
//! [`NODE_TAG_BITS`] and [`NODE_LEAF`] (`#define`s there).
//!
//! - interior: `word0` = split position (f32 bits); `word1` = axis (0..2, low 2 bits)
//!   | index of the above child << 2. The below child is the next node (depth-first order).
//! - leaf: `word1` = 3 | primitive count << 2; `word0` = offset into `prim_indices`.

use bytemuck::{Pod, Zeroable};

use crate::consts::{NODE_LEAF, NODE_TAG_BITS};

/// The low bits of `word1` that hold the axis or the leaf tag.
const TAG_MASK: u32 = (1 << NODE_TAG_BITS) - 1;

/// One kd-tree node, 8 bytes, as uploaded to the GPU.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Pod, Zeroable)]
pub struct KdNode {
    /// Interior: split position (f32 bits). Leaf: offset into `prim_indices`.
    pub word0: u32,
    /// Low 2 bits: axis (0..=2) or 3 for a leaf; upper 30 bits: above-child index
    /// (interior) or primitive count (leaf).
    pub word1: u32,
}

/// Largest child index or primitive count a node can hold (30 bits).
pub const MAX_NODE_FIELD: u32 = (1 << (32 - NODE_TAG_BITS)) - 1;

impl KdNode {
    /// An interior node splitting `axis` at `split`; `above_child` is the index of
    /// the child with coordinates `>= split`.
    pub fn interior(axis: usize, split: f32, above_child: u32) -> Self {
        debug_assert!(axis < 3 && above_child <= MAX_NODE_FIELD);
        KdNode { word0: split.to_bits(), word1: axis as u32 | (above_child << NODE_TAG_BITS) }
    }

    /// A leaf holding `count` primitives at `prim_indices[offset..offset + count]`.
    pub fn leaf(offset: u32, count: u32) -> Self {
        debug_assert!(count <= MAX_NODE_FIELD);
        KdNode { word0: offset, word1: NODE_LEAF | (count << NODE_TAG_BITS) }
    }

    /// True for a leaf (low 2 bits of `word1` are 3).
    pub fn is_leaf(&self) -> bool {
        self.word1 & TAG_MASK == NODE_LEAF
    }

    /// Split axis of an interior node (0 = x, 1 = y, 2 = z).
    pub fn axis(&self) -> usize {
        (self.word1 & TAG_MASK) as usize
    }

    /// Split position of an interior node, world units along [`KdNode::axis`].
    pub fn split(&self) -> f32 {
        f32::from_bits(self.word0)
    }

    /// Index of the child with coordinates `>= split` (interior nodes only); the
    /// below child is the next node.
    pub fn above_child(&self) -> u32 {
        self.word1 >> NODE_TAG_BITS
    }

    /// Number of primitives of a leaf (leaves only; 0 for an empty leaf).
    pub fn prim_count(&self) -> u32 {
        self.word1 >> NODE_TAG_BITS
    }

    /// Index of a leaf's first entry in `prim_indices` (leaves only).
    pub fn prim_offset(&self) -> u32 {
        self.word0
    }
}
