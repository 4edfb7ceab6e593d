//! `kdtrace stats`: build the kd-tree and print its statistics (text or JSON).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use kdtrace::kdtree::{BuildConfig, BuildStats, KdTree};
use kdtrace::scene::Scene;

use super::args::{builder_name, choice, choices, BuilderArgs};

#[derive(clap::Args)]
pub struct StatsArgs {
    /// OBJ scene file.
    pub scene: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also build the scene two-level (a glTF file's meshes once each, placed by
    /// their nodes; `kdtrace::twolevel`) and report what it uploads
    /// (`two_level_device_bytes`, geometries, instances).
    #[arg(long)]
    pub two_level: bool,
    /// Build this many times; report the fastest and the median build time.
    #[arg(long, default_value_t = 1)]
    pub repeat: u32,
    /// Builder parameters to start from: default | pbrt-v3 | wald-havran.
    #[arg(long, default_value = "default")]
    pub config: String,
    /// Override K_T, the cost of traversing a node.
    #[arg(long)]
    pub traversal_cost: Option<f32>,
    /// Override K_I, the cost of a ray/triangle test.
    #[arg(long)]
    pub intersection_cost: Option<f32>,
    /// Override the empty-space bonus (0 ≤ b < 1).
    #[arg(long)]
    pub empty_bonus: Option<f32>,
    /// Override the depth limit (default: 8 + 1.3·log2 N, capped).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Clip only triangle boxes at splits, not the triangles (no "perfect splits").
    #[arg(long)]
    pub box_clipping: bool,
    #[command(flatten)]
    pub builder: BuilderArgs,
    /// Worker threads for the build (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// The builder presets of `--config`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Preset {
    Default,
    PbrtV3,
    WaldHavran,
}

/// The builder parameters: the `--config` preset with the overrides applied.
fn build_config(args: &StatsArgs) -> Result<BuildConfig> {
    let Some(preset) = choice::<Preset>(&args.config) else {
        bail!("unknown --config '{}' ({})", args.config, choices::<Preset>());
    };
    let mut config = match preset {
        Preset::Default => BuildConfig::default(),
        Preset::PbrtV3 => BuildConfig::PBRT_V3,
        Preset::WaldHavran => BuildConfig::WALD_HAVRAN,
    };
    config.traversal_cost = args.traversal_cost.unwrap_or(config.traversal_cost);
    config.intersection_cost = args.intersection_cost.unwrap_or(config.intersection_cost);
    config.empty_bonus = args.empty_bonus.unwrap_or(config.empty_bonus);
    config.max_depth = args.max_depth.or(config.max_depth);
    config.perfect_splits &= !args.box_clipping;
    let config = args.builder.apply(config)?;
    if !(config.traversal_cost >= 0.0 && config.intersection_cost > 0.0 && (0.0..1.0).contains(&config.empty_bonus)) {
        bail!("costs must be finite with K_T >= 0, K_I > 0 and 0 <= empty bonus < 1");
    }
    Ok(config)
}

/// What `stats` reports: the scene, the last tree built, the build times.
struct Report<'a> {
    args: &'a StatsArgs,
    scene: &'a Scene,
    config: &'a BuildConfig,
    stats: &'a BuildStats,
    /// Build times, ascending.
    times: &'a [f64],
    /// What a tracer uploads for the scene (`kdtrace::trace::scene_device_bytes`).
    device_bytes: u64,
    /// With `--two-level`: (device bytes, geometries, instances) of the two-level scene.
    two_level: Option<(u64, usize, usize)>,
}

/// `kdtrace stats`: builds the tree `--repeat` times and prints the statistics of the last.
pub fn stats(args: StatsArgs) -> Result<()> {
    let config = build_config(&args)?;
    if args.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let scene = Scene::load(&args.scene)?;
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(threads) = args.threads {
        pool = pool.num_threads(threads);
    }
    let pool = pool.build().context("starting the build threads")?;
    let mut times = Vec::new();
    let mut tree = None;
    for _ in 0..args.repeat {
        drop(tree.take());
        let built = pool.install(|| KdTree::build(&scene.triangles, &config));
        times.push(built.stats.build_seconds);
        tree = Some(built);
    }
    let tree = tree.expect("built at least once");
    times.sort_by(f64::total_cmp);
    let device_bytes = kdtrace::trace::scene_device_bytes(&tree);
    let two_level = match args.two_level {
        true => {
            let (two, _) = pool.install(|| Scene::load_two_level(&args.scene, &config))?;
            Some((two.device_bytes(), two.geometries().len(), two.instance_count()))
        }
        false => None,
    };
    let report = Report {
        args: &args,
        scene: &scene,
        config: &config,
        stats: &tree.stats,
        times: &times,
        device_bytes,
        two_level,
    };
    if args.json {
        println!("{}", report.json());
    } else {
        report.print_text();
    }
    Ok(())
}

impl Report<'_> {
    /// The fastest and the median build time.
    fn fastest_median(&self) -> (f64, f64) {
        (self.times[0], self.times[self.times.len() / 2])
    }

    /// The report as one line of JSON.
    fn json(&self) -> JsonObject {
        let (s, config) = (self.stats, self.config);
        let (fastest, median) = self.fastest_median();
        let mut o = JsonObject::default();
        o.string("scene", &self.args.scene.display().to_string());
        o.field("triangles", self.scene.triangles.len());
        o.field("degenerate", self.scene.degenerate_count);
        o.field("skipped", s.skipped_triangles);
        o.field("nodes", s.nodes);
        o.field("leaves", s.leaves);
        o.field("empty_leaves", s.empty_leaves);
        o.field("depth_limit", s.depth_limit);
        o.field("max_depth", s.max_depth);
        o.field("mean_leaf_depth", s.mean_leaf_depth);
        o.field("refs_per_triangle", s.refs_per_triangle);
        o.field("mean_prims_per_leaf", s.mean_prims_per_leaf);
        o.field("max_prims_per_leaf", s.max_prims_per_leaf);
        o.field("sah_cost", s.sah_cost);
        o.field("build_seconds", fastest);
        o.field("build_seconds_median", median);
        o.field("builds", self.times.len());
        o.field("threads", s.threads);
        o.field("node_bytes", s.node_bytes);
        o.field("index_bytes", s.index_bytes);
        o.field("device_bytes", self.device_bytes);
        if let Some((bytes, geometries, instances)) = self.two_level {
            o.field("two_level_device_bytes", bytes);
            o.field("two_level_geometries", geometries);
            o.field("two_level_instances", instances);
        }
        o.field("peak_scratch_bytes", s.peak_scratch_bytes);
        o.field("traversal_cost", config.traversal_cost);
        o.field("intersection_cost", config.intersection_cost);
        o.field("empty_bonus", config.empty_bonus);
        o.field("perfect_splits", config.perfect_splits);
        o.string("builder", &builder_name(&config.builder));
        o
    }

    /// The report as aligned text lines.
    fn print_text(&self) {
        let (s, config, scene) = (self.stats, self.config, self.scene);
        let (fastest, median) = self.fastest_median();
        let mib = |b: usize| b as f64 / (1 << 20) as f64;
        println!("scene               {}", self.args.scene.display());
        println!(
            "triangles           {} ({} zero-area, {} left out)",
            scene.triangles.len(),
            scene.degenerate_count,
            s.skipped_triangles
        );
        println!(
            "config              K_T {} K_I {} empty bonus {} perfect splits {} builder {}",
            config.traversal_cost,
            config.intersection_cost,
            config.empty_bonus,
            config.perfect_splits,
            builder_name(&config.builder)
        );
        println!("nodes               {}", s.nodes);
        println!("leaves              {} ({} empty)", s.leaves, s.empty_leaves);
        println!(
            "depth               max {} (limit {}), mean leaf {:.2}",
            s.max_depth, s.depth_limit, s.mean_leaf_depth
        );
        println!("refs per triangle   {:.3}", s.refs_per_triangle);
        println!("prims per leaf      mean {:.2} (non-empty), max {}", s.mean_prims_per_leaf, s.max_prims_per_leaf);
        println!("SAH cost            {:.3}", s.sah_cost);
        println!(
            "build time          {:.3} s (fastest of {}, median {:.3} s) on {} threads",
            fastest,
            self.times.len(),
            median,
            s.threads
        );
        println!(
            "memory              {} B nodes + {} B indices = {:.1} MiB; build scratch peak {:.1} MiB",
            s.node_bytes,
            s.index_bytes,
            mib(s.node_bytes + s.index_bytes),
            mib(s.peak_scratch_bytes)
        );
        println!(
            "device copy         {} B ({:.1} MiB, {:.1} B per triangle): nodes, indices, a 48-byte triangle per reference",
            self.device_bytes,
            mib(self.device_bytes as usize),
            self.device_bytes as f64 / self.scene.triangles.len().max(1) as f64
        );
        if let Some((bytes, geometries, instances)) = self.two_level {
            println!(
                "two-level copy      {bytes} B ({:.1} MiB, {:.1} B per placed triangle): {geometries} geometries, {instances} instances",
                mib(bytes as usize),
                bytes as f64 / self.scene.triangles.len().max(1) as f64
            );
        }
    }
}

/// A flat JSON object written field by field, in order, on one line: numbers
/// and booleans as Rust's `Display` writes them, strings quoted and escaped as
/// Rust's `Debug` writes them (the same for the paths and names written here).
#[derive(Default)]
struct JsonObject {
    body: String,
}

impl JsonObject {
    /// Appends `"name":value`.
    fn field(&mut self, name: &str, value: impl std::fmt::Display) {
        use std::fmt::Write;
        let comma = if self.body.is_empty() { "" } else { "," };
        write!(self.body, "{comma}\"{name}\":{value}").expect("writing to a String");
    }

    /// Appends `"name":"value"`.
    fn string(&mut self, name: &str, value: &str) {
        self.field(name, format_args!("{value:?}"));
    }
}

impl std::fmt::Display for JsonObject {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{{{}}}", self.body)
    }
}
