//! The tracer's configuration: which traversal algorithm ([`Variant`]) and how
//! the kernel runs it ([`Traversal`]: short-stack size, any-hit, packets,
//! robustness). Read by the GPU tracer ([`crate::trace`]), the renderer and the
//! CPU twins ([`crate::kdtree::traverse`], which re-exports both).

use crate::consts::MAX_SHORT_STACK;

/// The traversal algorithms (specialization constant `VARIANT` of `trace.comp`),
/// each in its own file under `glsl/traverse/` with its CPU twin in
/// [`crate::kdtree::traverse`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Variant {
    /// Full per-ray stack, front to back (pbrt-v3). The baseline.
    Stack,
    /// kd-restart (Foley & Sugerman 2005): no stack, restart at the root behind each leaf.
    Restart,
    /// kd-restart from the push-down node (Horn et al. 2007): the deepest node whose
    /// segment lay wholly in one child.
    PushDown,
    /// A short stack of `stack_size` entries that drops its oldest entry when full,
    /// with kd-restart from the root when it runs empty (Horn et al. 2007).
    ShortStack,
    /// Short stack plus push-down: the paper's best variant.
    PushDownShortStack,
    /// kd-backtrack (Foley & Sugerman 2005): climb parent links to the first
    /// ancestor whose box the ray leaves after the current leaf, then descend.
    Backtrack,
    /// Ropes (Popov et al. 2007): each leaf links its six faces to the neighbouring
    /// subtree; the ray walks from leaf to leaf without a stack.
    Ropes,
}

impl Variant {
    /// Every variant, in variant-id order (`stack` first).
    pub const ALL: [Variant; 7] = [
        Variant::Stack,
        Variant::Restart,
        Variant::PushDown,
        Variant::ShortStack,
        Variant::PushDownShortStack,
        Variant::Backtrack,
        Variant::Ropes,
    ];

    /// The value of the `VARIANT` specialization constant.
    pub fn id(self) -> u32 {
        use crate::consts::*;
        match self {
            Variant::Stack => VARIANT_STACK,
            Variant::Restart => VARIANT_RESTART,
            Variant::PushDown => VARIANT_PUSH_DOWN,
            Variant::ShortStack => VARIANT_SHORT_STACK,
            Variant::PushDownShortStack => VARIANT_PUSH_DOWN_SHORT_STACK,
            Variant::Backtrack => VARIANT_BACKTRACK,
            Variant::Ropes => VARIANT_ROPES,
        }
    }

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Stack => "stack",
            Variant::Restart => "restart",
            Variant::PushDown => "push-down",
            Variant::ShortStack => "short-stack",
            Variant::PushDownShortStack => "push-down-short-stack",
            Variant::Backtrack => "backtrack",
            Variant::Ropes => "ropes",
        }
    }

    /// True for the variants whose behaviour depends on the short-stack size.
    pub fn uses_short_stack(self) -> bool {
        matches!(self, Variant::ShortStack | Variant::PushDownShortStack)
    }

    /// True for the variants that read the side buffers of
    /// [`TreeLinks`](crate::kdtree::links::TreeLinks).
    pub fn uses_links(self) -> bool {
        matches!(self, Variant::Backtrack | Variant::Ropes)
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Variant {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        Variant::ALL.into_iter().find(|v| v.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Variant::ALL.iter().map(|v| v.name()).collect();
            crate::Error::InvalidInput(format!("unknown traversal '{s}' ({})", names.join(", ")))
        })
    }
}

/// A traversal as the kernel's specialization constants select it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Traversal {
    /// The traversal algorithm.
    pub variant: Variant,
    /// Short-stack entries, 1..=`MAX_SHORT_STACK` (used by the short-stack variants).
    pub stack_size: u32,
    /// Any-hit (shadow-ray) mode: stop at the first hit in [tmin, tmax], not the closest.
    pub any_hit: bool,
    /// Lanes per packet (Horn et al.'s packets as aligned groups of subgroup lanes):
    /// 1 = single rays; 2, 4, 8, … up to the subgroup size for `stack`, `restart`,
    /// `push-down`, `short-stack` and `push-down-short-stack` (`backtrack` and `ropes`
    /// always trace single rays). The CPU twins trace single rays; packets must give
    /// the same hits.
    pub packet_width: u32,
    /// A required subgroup size (`VK_EXT_subgroup_size_control`); `None` = the device's.
    pub subgroup_size: Option<u32>,
    /// The robustness measures (default on): conservative split decisions
    /// (Ize 2013 in spirit), and the watertight test's exact fallback whenever an
    /// edge function or the hit's distance to the ray's bounds lies within its
    /// rounding error. Off: plain f32 decisions and the exact recompute only at an
    /// edge function of exactly 0 (Woop, Benthin & Wald 2013) — to measure what
    /// the measures cost. A specialization constant: no cost when off.
    ///
    /// With it on, the restart-based variants also restart exactly (see
    /// [`Traversal::follows_stack`]); off, they restart at a t value as in the papers.
    pub robust: bool,
}

impl Traversal {
    /// Closest hit with `variant`, the paper's short stack of 3, single rays.
    pub fn closest(variant: Variant) -> Self {
        Traversal { variant, stack_size: 3, any_hit: false, packet_width: 1, subgroup_size: None, robust: true }
    }

    /// True when this traversal visits the leaves a full stack visits, in the same
    /// order and with the same segments, and so returns the stack's hits bit for
    /// bit: `restart`, `push-down` and the short stacks on single rays with
    /// `robust` on. Their restarts do not start again at a t value (which cannot
    /// order cells that meet at a vertex or edge the ray passes within a float of)
    /// but descend again to the leaf just left to find the entry a full stack would
    /// pop next. `backtrack` and `ropes` (robust) keep their own walk and switch to
    /// exact restarts where a t value could not order the cells (a plane or a
    /// second exit face within rounding of t0, a ray inside a split plane), so
    /// they are watertight but may name another member of a tie. Packets restart
    /// at a t value.
    pub fn follows_stack(&self) -> bool {
        self.robust && !self.uses_packets() && !self.variant.uses_links()
    }

    /// True when the kernel traces packets with this traversal.
    pub fn uses_packets(&self) -> bool {
        self.packet_width > 1 && !self.variant.uses_links()
    }

    /// Checks the stack size and the packet width (a power of two; the device check
    /// against the subgroup size happens when the kernel is made).
    pub fn validate(&self) -> crate::Result<()> {
        if self.stack_size == 0 || self.stack_size > MAX_SHORT_STACK {
            return Err(crate::Error::InvalidInput(format!(
                "short-stack size {} is outside 1..={MAX_SHORT_STACK}",
                self.stack_size
            )));
        }
        if !self.packet_width.is_power_of_two() || self.packet_width > 128 {
            return Err(crate::Error::InvalidInput(format!(
                "packet width {} must be a power of two in 1..=128",
                self.packet_width
            )));
        }
        if let Some(size) = self.subgroup_size {
            if !size.is_power_of_two() || size > 128 {
                return Err(crate::Error::InvalidInput(format!("subgroup size {size} must be a power of two")));
            }
        }
        Ok(())
    }
}

impl From<Variant> for Traversal {
    fn from(variant: Variant) -> Self {
        Traversal::closest(variant)
    }
}
