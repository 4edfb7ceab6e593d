//! The options several subcommands share (traversal, builder, tree cache) and
//! the parsers of option values.

use std::path::PathBuf;

use anyhow::{bail, Result};
use glam::Vec3;

use kdtrace::kdtree::BuildConfig;
use kdtrace::trace::Backend;
use kdtrace::traversal::Traversal;

// The traversal and the backend, shared by `render`, `trace` and `verify`.
#[derive(clap::Args, Clone)]
pub struct TraversalArgs {
    /// Traversal: stack | restart | push-down | short-stack | push-down-short-stack | backtrack | ropes.
    #[arg(long, default_value = "stack")]
    pub traversal: String,
    /// Short-stack entries (1..=8) for short-stack and push-down-short-stack.
    #[arg(long, default_value_t = 3)]
    pub stack_size: u32,
    /// Lanes per packet: 1 = single rays; 2, 4, 8, ... up to the subgroup size (subgroup ballots).
    #[arg(long, default_value_t = 1)]
    pub packet_width: u32,
    /// Require this subgroup size (VK_EXT_subgroup_size_control); default: the device's.
    #[arg(long)]
    pub subgroup_size: Option<u32>,
    /// Turn the robustness measures off: plain f32 split decisions and the exact
    /// recompute only at an edge function of 0 (to measure what they cost).
    #[arg(long)]
    pub plain: bool,
    /// kd-tree (kdtrace's kernels) or ray-query (the driver's own BVH and
    /// VK_KHR_ray_query, a peer: no traversal options or counters; Mesa >= 24 lavapipe or a GPU).
    #[arg(long, default_value = "kd-tree")]
    pub backend: Backend,
}

impl TraversalArgs {
    /// The traversal these options name (closest hit, or any hit when `any_hit`), validated.
    pub fn parse(&self, any_hit: bool) -> Result<Traversal> {
        let traversal = Traversal {
            variant: self.traversal.parse()?,
            stack_size: self.stack_size,
            any_hit,
            packet_width: self.packet_width,
            subgroup_size: self.subgroup_size,
            robust: !self.plain,
        };
        traversal.validate()?;
        Ok(traversal)
    }
}

/// `--tree-cache DIR` and the builder, shared by the subcommands that build a tree.
#[derive(clap::Args)]
pub struct TreeArgs {
    /// Folder of cached kd-trees: load the scene's tree from it when it holds a
    /// valid one, else build the tree and store it there (bench: --images only).
    #[arg(long, env = "KDTRACE_TREE_CACHE", value_name = "DIR")]
    pub tree_cache: Option<PathBuf>,
    #[command(flatten)]
    pub builder: BuilderArgs,
}

/// The split search of the kd-tree builder.
#[derive(clap::Args)]
pub struct BuilderArgs {
    /// binned: binned SAH on the large nodes, the exact sweep below (the
    /// default's); sweep: the exact SAH sweep at every node.
    #[arg(long, value_enum)]
    pub builder: Option<BuilderKind>,
    /// Binned builder: bins per axis [default: 64].
    #[arg(long)]
    pub bins: Option<u32>,
    /// Binned builder: nodes of at least this many triangles are binned [default: 4096].
    #[arg(long)]
    pub binned_above: Option<u32>,
}

/// The builder as `stats` prints it: `sweep` or `binned:BINS:MIN_PRIMS`.
pub fn builder_name(b: &kdtrace::kdtree::Builder) -> String {
    match b {
        kdtrace::kdtree::Builder::Sweep => "sweep".into(),
        kdtrace::kdtree::Builder::Binned { bins, min_prims } => format!("binned:{bins}:{min_prims}"),
    }
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
pub enum BuilderKind {
    Sweep,
    Binned,
}

impl BuilderArgs {
    /// `config` with the builder these options choose (its own when none).
    pub fn apply(&self, config: BuildConfig) -> Result<BuildConfig> {
        use kdtrace::kdtree::Builder;
        let binned = match (self.builder, config.builder) {
            (Some(BuilderKind::Sweep), _) | (None, Builder::Sweep) => {
                if self.bins.is_some() || self.binned_above.is_some() {
                    bail!("--bins and --binned-above apply to the binned builder (--builder binned)");
                }
                return Ok(BuildConfig { builder: Builder::Sweep, ..config });
            }
            (_, Builder::Binned { bins, min_prims }) => (bins, min_prims),
            (Some(BuilderKind::Binned), Builder::Sweep) => (Builder::DEFAULT_BINS, Builder::DEFAULT_BINNED_ABOVE),
        };
        let bins = self.bins.unwrap_or(binned.0);
        if bins < 2 {
            bail!("--bins must be at least 2");
        }
        let min_prims = self.binned_above.unwrap_or(binned.1);
        Ok(BuildConfig { builder: Builder::Binned { bins, min_prims }, ..config })
    }
}

/// `x,y,z`: three finite numbers.
pub fn parse_vec3(s: &str) -> std::result::Result<Vec3, String> {
    let parts: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>().map_err(|e| format!("'{p}': {e}")))
        .collect::<std::result::Result<_, _>>()?;
    match parts.as_slice() {
        [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(format!("expected three finite numbers x,y,z, got '{s}'")),
    }
}

/// `x,y,z[,intensity]`: a position and an optional intensity (finite, >= 0).
pub fn parse_light(s: &str) -> std::result::Result<(Vec3, Option<f32>), String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 && parts.len() != 4 {
        return Err(format!("expected x,y,z or x,y,z,intensity, got '{s}'"));
    }
    let position = parse_vec3(&parts[..3].join(","))?;
    let intensity = match parts.get(3) {
        None => None,
        Some(p) => match p.trim().parse::<f32>() {
            Ok(i) if i.is_finite() && i >= 0.0 => Some(i),
            _ => return Err(format!("intensity '{p}' must be a finite number >= 0")),
        },
    };
    Ok((position, intensity))
}

/// The value of `T` named `value` (exactly, as clap would accept it), for the
/// options that are read as text and checked when the subcommand runs.
pub fn choice<T: clap::ValueEnum>(value: &str) -> Option<T> {
    T::from_str(value, false).ok()
}

/// The names of `T`'s values, comma-separated, for error messages.
pub fn choices<T: clap::ValueEnum>() -> String {
    let names: Vec<String> =
        T::value_variants().iter().filter_map(|v| v.to_possible_value()).map(|v| v.get_name().to_string()).collect();
    names.join(", ")
}

/// First hits, as `--primary` and `--image-primary` name them.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum PrimaryKind {
    Trace,
    Raster,
}

impl From<PrimaryKind> for kdtrace::render::Primary {
    fn from(kind: PrimaryKind) -> Self {
        match kind {
            PrimaryKind::Trace => kdtrace::render::Primary::Trace,
            PrimaryKind::Raster => kdtrace::render::Primary::Raster,
        }
    }
}
