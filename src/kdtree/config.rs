//! The parameters of the SAH builder ([`BuildConfig`]) and its split search
//! ([`Builder`]).

use crate::consts::MAX_TREE_DEPTH;

/// Parameters of the SAH builder.
///
/// The SAH cost of splitting a node `V` into `B` (below) and `A` (above) is
/// `K_T + K_I · (1 − b) · (A(B)/A(V) · n_B + A(A)/A(V) · n_A)`, where `A(·)` is a
/// surface area, `n` a triangle count and `b` the empty bonus when one side has
/// no triangle (pbrt-v3's form; Wald & Havran scale `K_T` by `λ = 1 − b` too);
/// the cost of a leaf is `K_I · n`. Only the ratio `K_T / K_I`, `b` and the
/// termination rules shape the tree.
///
/// Published defaults: pbrt-v3 uses `K_I = 80, K_T = 1, b = 0.5`, stops
/// splitting at one triangle and tolerates a few splits costlier than a leaf;
/// Wald & Havran 2006 use `K_T = 15, K_I = 20, λ = 0.8` (`b = 0.2`) and stop at
/// the first split costlier than a leaf. [`Default`] was chosen by measuring
/// node visits and triangle tests per ray on the shared scenes: see
/// docs/BUILDER.md for the table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildConfig {
    /// `K_T`, the cost of traversing one interior node. Higher values (relative
    /// to `intersection_cost`) give shallower trees with fuller leaves: fewer
    /// node visits, more triangle tests. pbrt-v3: 1; Wald & Havran 2006: 15.
    pub traversal_cost: f32,
    /// `K_I`, the cost of one ray/triangle test. Higher values (relative to
    /// `traversal_cost`) split more eagerly: deeper trees, smaller leaves, more
    /// references per triangle and more memory. pbrt-v3: 80; Wald & Havran 2006: 20.
    pub intersection_cost: f32,
    /// Fraction `b` in `[0, 1)` taken off the intersection part of the cost when
    /// one side of a split holds no triangle: favours cutting off empty space,
    /// which rays then skip for one node visit. Larger values carve more empty
    /// leaves (more nodes; with a low `K_T / K_I`, stacks of thin empty slabs
    /// down to the depth limit). pbrt-v3: 0.5; Wald & Havran 2006: 0.2 (`λ = 0.8`).
    pub empty_bonus: f32,
    /// Deepest leaf (root = depth 0). `None` = pbrt-v3's `round(8 + 1.3 · ⌊log2 N⌋)`
    /// for `N` triangles. Either way capped at [`MAX_TREE_DEPTH`], which sizes the
    /// GPU traversal stack. A deeper limit lets the SAH isolate small details in
    /// dense regions; a shallower one bounds memory and the build time when
    /// triangles overlap heavily (every split then duplicates references).
    pub max_depth: Option<u32>,
    /// A node with at most this many triangles becomes a leaf without trying to
    /// split it (a node with none always does). pbrt-v3: 1; 0 leaves termination
    /// to the SAH alone, as Wald & Havran 2006 do (a lone triangle may then still
    /// get empty space cut off around it). Larger values build faster, smaller
    /// trees with fuller leaves.
    pub max_leaf_prims: u32,
    /// Splits costlier than a leaf that one path of the tree may take, in the
    /// hope that a later split pays off, before the builder makes a leaf
    /// (pbrt-v3's "bad refines": 2, it gives up at the third; with bad refines
    /// allowed, pbrt-v3 also makes a leaf when the best split costs more than
    /// four times the leaf with fewer than 16 triangles). 0 is Wald & Havran's
    /// automatic termination: a leaf as soon as the best split costs more.
    pub max_bad_refines: u32,
    /// "Perfect splits" (Havran 2000; Wald & Havran 2006 §4.3): clip every
    /// triangle that straddles a split plane to each child's box and use the
    /// box of the clipped polygon. `false` clips only the triangle's box (as
    /// pbrt-v3 does), which keeps triangles in cells they do not touch: more
    /// references, larger leaves, more triangle tests per ray.
    pub perfect_splits: bool,
    /// How the split of each node is chosen: the exact sweep everywhere, or
    /// binned SAH on the large nodes at the top and the sweep below.
    pub builder: Builder,
}

/// The split search of the SAH builder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Builder {
    /// Wald & Havran 2006's exact O(N log N) sweep at every node: the SAH's
    /// minimum over every face of every (clipped) triangle box.
    Sweep,
    /// Binned SAH (Shevtsov, Soupikov & Kapustin 2007) on nodes of at least
    /// `min_prims` triangles, `bins` equally spaced planes per axis; the exact
    /// sweep on smaller nodes. Faster: the large nodes keep no sorted event
    /// lists. See docs/BUILDER.md for the quality it costs.
    Binned {
        /// Planes per axis plus one (at least 2).
        bins: u32,
        /// Nodes with at least this many triangles are binned.
        min_prims: u32,
    },
}

impl Builder {
    /// The binned builder with the measured defaults (docs/BUILDER.md).
    pub const BINNED: Builder =
        Builder::Binned { bins: Builder::DEFAULT_BINS, min_prims: Builder::DEFAULT_BINNED_ABOVE };
    /// Bins per axis of [`Builder::BINNED`].
    pub const DEFAULT_BINS: u32 = 64;
    /// Nodes of at least this many triangles are binned by [`Builder::BINNED`].
    pub const DEFAULT_BINNED_ABOVE: u32 = 4096;
}

impl BuildConfig {
    /// pbrt-v3's parameters (`KdTreeAccel`): `K_I = 80, K_T = 1, b = 0.5`, one
    /// triangle per leaf, two bad refines (with perfect splits, which pbrt lacks).
    pub const PBRT_V3: BuildConfig = BuildConfig {
        traversal_cost: 1.0,
        intersection_cost: 80.0,
        empty_bonus: 0.5,
        max_depth: None,
        max_leaf_prims: 1,
        max_bad_refines: 2,
        perfect_splits: true,
        builder: Builder::Sweep,
    };

    /// The default, chosen by measurement (docs/BUILDER.md has the numbers and
    /// the commands): Wald & Havran's termination with a costlier traversal
    /// step and a smaller empty bonus, `K_T = 30, K_I = 20, b = 0.1`. The node
    /// visits plus triangle tests per ray are nearly flat between Wald &
    /// Havran's `K_T` and about twice it (pbrt-v3's costs are well above); of
    /// the configurations on that plateau this one has the fewest nodes, so it
    /// builds fastest and takes least memory. Its splits are binned on the
    /// nodes of 4096 triangles or more ([`Builder::BINNED`]), which builds
    /// faster at the same node visits plus triangle tests per ray within the
    /// bound docs/BUILDER.md checks; set `builder` to [`Builder::Sweep`] for the
    /// exact sweep everywhere.
    pub const TUNED: BuildConfig = BuildConfig {
        traversal_cost: 30.0,
        intersection_cost: 20.0,
        empty_bonus: 0.1,
        max_depth: None,
        max_leaf_prims: 1,
        max_bad_refines: 0,
        perfect_splits: true,
        builder: Builder::BINNED,
    };

    /// Wald & Havran 2006's costs: `K_T = 15, K_I = 20, λ = 0.8` (`b = 0.2`),
    /// automatic termination, perfect splits; pbrt-v3's depth limit and one
    /// triangle per leaf at least.
    pub const WALD_HAVRAN: BuildConfig = BuildConfig {
        traversal_cost: 15.0,
        intersection_cost: 20.0,
        empty_bonus: 0.2,
        max_depth: None,
        max_leaf_prims: 1,
        max_bad_refines: 0,
        perfect_splits: true,
        builder: Builder::Sweep,
    };

    /// The depth limit for `triangles` triangles: `max_depth`, or pbrt-v3's
    /// `round(8 + 1.3 · ⌊log2 N⌋)`, never more than [`MAX_TREE_DEPTH`].
    pub fn depth_limit(&self, triangles: usize) -> u32 {
        let auto = || {
            let log2 = if triangles > 1 { triangles.ilog2() } else { 0 };
            (8.0 + 1.3 * log2 as f64).round() as u32
        };
        self.max_depth.unwrap_or_else(auto).min(MAX_TREE_DEPTH)
    }
}

impl Default for BuildConfig {
    /// The measured choice, [`BuildConfig::TUNED`] (docs/BUILDER.md).
    fn default() -> Self {
        BuildConfig::TUNED
    }
}
