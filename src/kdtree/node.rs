//! The 8-byte kd-tree node (pbrt-v3; Hapala & Havran), decoded on the GPU by
//! `glsl/shared/kdnode.glsl`; both take the tag width and the leaf tag from
//! [`NODE_TAG_BITS`] and [`NODE_LEAF`] (`#define`s there).
//!
//! - interior: `word0` = split position (f32 bits); `word1` = axis (0..2, low 2 bits)
//!   | below child is an empty leaf << 2 | above child is an empty leaf << 3
//!   | index of the above child << 4. The below child is the next node (depth-first order).
//!   The two flags let the stack traversal skip empty leaves without fetching them
//!   ([`mark_empty_children`] sets them once the tree is complete).
//! - leaf: `word1` = 3 | primitive count << 2; `word0` = offset into `prim_indices`.

use bytemuck::{Pod, Zeroable};

use crate::consts::{NODE_ABOVE_EMPTY, NODE_BELOW_EMPTY, NODE_CHILD_SHIFT, NODE_LEAF, NODE_TAG_BITS};

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

/// Largest primitive count a leaf can hold (30 bits).
pub const MAX_NODE_FIELD: u32 = (1 << (32 - NODE_TAG_BITS)) - 1;
/// Largest above-child index an interior node can hold (28 bits), so a tree has
/// at most 2^28 nodes (2 GiB of them; devices' texel buffers hold 2^27 or fewer).
pub const MAX_CHILD_INDEX: u32 = (1 << (32 - NODE_CHILD_SHIFT)) - 1;

impl KdNode {
    /// An interior node splitting `axis` at `split`; `above_child` is the index of
    /// the child with coordinates `>= split`.
    pub fn interior(axis: usize, split: f32, above_child: u32) -> Self {
        debug_assert!(axis < 3 && above_child <= MAX_CHILD_INDEX);
        KdNode { word0: split.to_bits(), word1: axis as u32 | (above_child << NODE_CHILD_SHIFT) }
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
        self.word1 >> NODE_CHILD_SHIFT
    }

    /// True for an interior node whose below child is a leaf without primitives.
    pub fn below_empty(&self) -> bool {
        !self.is_leaf() && self.word1 & NODE_BELOW_EMPTY != 0
    }

    /// True for an interior node whose above child is a leaf without primitives.
    pub fn above_empty(&self) -> bool {
        !self.is_leaf() && self.word1 & NODE_ABOVE_EMPTY != 0
    }

    /// True for a leaf without primitives.
    pub fn is_empty_leaf(&self) -> bool {
        self.is_leaf() && self.prim_count() == 0
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

/// Sets (and clears) every interior node's empty-child flags from its children.
/// Trees from the builder and from the cache get them; `nodes` must be a
/// complete tree (children in range).
pub fn mark_empty_children(nodes: &mut [KdNode]) {
    for i in 0..nodes.len() {
        let n = nodes[i];
        if n.is_leaf() {
            continue;
        }
        let below = nodes[i + 1].is_empty_leaf();
        let above = nodes[n.above_child() as usize].is_empty_leaf();
        let mut word1 = n.word1 & !(NODE_BELOW_EMPTY | NODE_ABOVE_EMPTY);
        if below {
            word1 |= NODE_BELOW_EMPTY;
        }
        if above {
            word1 |= NODE_ABOVE_EMPTY;
        }
        nodes[i].word1 = word1;
    }
}
