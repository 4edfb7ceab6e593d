//! The `kdtrace` command line: a thin layer over the library.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};

use kdtrace::gpu::{list_devices, ContextOptions, GpuContext};
use kdtrace::kdtree::traverse::{Counters, Traversal};
use kdtrace::kdtree::{BuildConfig, BuildProgress, KdTree};
use kdtrace::render::{PointLight, Primary, RenderPlan, RenderSettings};
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::{Backend, TraceOptions, TracePipelines, Tracer};

#[derive(Parser)]
#[command(name = "kdtrace", version, about = "SAH kd-tree ray tracing on the GPU through Vulkan compute")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene: shadows, mirrors, ambient occlusion, path-traced diffuse light; PNG or EXR.
    Render(RenderArgs),
    /// Trace a binary ray file and write a binary hit file.
    Trace(TraceArgs),
    /// Build the kd-tree and print its statistics.
    Stats(StatsArgs),
    /// Write a ray file: camera rays or random rays for a scene.
    Rays(RaysArgs),
    /// Compare the traversal variants: rays/s, per-ray counters, hit agreement.
    Bench(BenchArgs),
    /// Sweep packet variants × packet widths × subgroup sizes: table, CSV and PNG chart.
    Subgroups(SubgroupsArgs),
    /// Trace hard rays (or a ray file) and compare every answer with the exact reference.
    Verify(VerifyArgs),
    /// List the Vulkan devices and their subgroup properties.
    Info,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// OBJ scene file.
    scene: PathBuf,
    /// Output PNG.
    #[arg(short, long, default_value = "out.png")]
    output: PathBuf,
    #[arg(long, default_value_t = 800)]
    width: u32,
    #[arg(long, default_value_t = 600)]
    height: u32,
    /// Camera position x,y,z (default: the scene's entry in cameras.json next to it, else framing the box).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    eye: Option<Vec3>,
    /// Point looked at, x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    target: Option<Vec3>,
    /// Up vector x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    up: Option<Vec3>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    fov: Option<f32>,
    #[command(flatten)]
    traversal: TraversalArgs,
    #[command(flatten)]
    tree: TreeArgs,
    /// Print the wall time of every stage (OBJ, kd-tree, device, upload, render,
    /// write) on stderr.
    #[arg(long)]
    timings: bool,
    /// Write a per-pixel cost heatmap instead of the shaded image: nodes | triangles.
    #[arg(long)]
    heatmap: Option<String>,
    /// Samples per pixel (jittered by a seeded, Owen-scrambled Sobol sequence when > 1).
    #[arg(long, default_value_t = 1)]
    spp: u32,
    /// Seed of the sample sequence.
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Ray segments per path at most (camera ray, reflections, bounces).
    #[arg(long, default_value_t = 8)]
    max_depth: u32,
    /// Diffuse bounces (path-traced indirect light, next-event estimation toward emitters).
    #[arg(long, default_value_t = 0)]
    bounces: u32,
    /// Ambient-occlusion rays at the first diffuse hit.
    #[arg(long, default_value_t = 0)]
    ao: u32,
    /// Length of the ambient-occlusion rays (default: a tenth of the scene's diagonal).
    #[arg(long)]
    ao_radius: Option<f32>,
    /// Ambient radiance let through by ambient occlusion (default 1 without other lights, else 0.1).
    #[arg(long)]
    ambient: Option<f32>,
    /// A point light x,y,z[,intensity] (repeatable); the default intensity gives the
    /// scene's centre an irradiance of pi, so a white surface facing it looks white.
    #[arg(long, value_parser = parse_light, allow_hyphen_values = true)]
    light: Vec<(Vec3, Option<f32>)>,
    /// Radiance r,g,b of rays that leave the scene (default black, grey with the headlight).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    background: Option<Vec3>,
    /// Multiply the radiance by this before tone mapping the PNG.
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    /// Also write the linear image as OpenEXR (the output itself is EXR when it ends in .exr).
    #[arg(long)]
    exr: Option<PathBuf>,
    /// Write the output image every N samples per pixel while rendering (progressive preview).
    #[arg(long, default_value_t = 0)]
    checkpoint: u32,
    /// List what the scene and options need and what the renderer skips, then render.
    #[arg(long)]
    explain: bool,
    /// Do not skip what the scene does not need (to measure what skipping saves).
    #[arg(long)]
    no_skip: bool,
    /// Also render without skipping and with the other --primary, each on a fresh
    /// tracer (pipelines compiled anew), and print what each costs, in one run.
    #[arg(long)]
    compare: bool,
    /// First hits: trace (camera rays) or raster (a visibility buffer drawn by a graphics pipeline).
    #[arg(long, default_value = "trace")]
    primary: String,
}

#[derive(clap::Args, Clone)]
struct TraversalArgs {
    /// Traversal: stack | restart | push-down | short-stack | push-down-short-stack | backtrack | ropes.
    #[arg(long, default_value = "stack")]
    traversal: String,
    /// Short-stack entries (1..=8) for short-stack and push-down-short-stack.
    #[arg(long, default_value_t = 3)]
    stack_size: u32,
    /// Lanes per packet: 1 = single rays; 2, 4, 8, ... up to the subgroup size (subgroup ballots).
    #[arg(long, default_value_t = 1)]
    packet_width: u32,
    /// Require this subgroup size (VK_EXT_subgroup_size_control); default: the device's.
    #[arg(long)]
    subgroup_size: Option<u32>,
    /// Turn the robustness measures off: plain f32 split decisions and the f64
    /// recompute only at an edge function of 0 (to measure what they cost).
    #[arg(long)]
    plain: bool,
    /// kd-tree (kdtrace's kernels) or ray-query (the driver's own BVH and
    /// VK_KHR_ray_query, a peer: no traversal options or counters; Mesa >= 24 lavapipe or a GPU).
    #[arg(long, default_value = "kd-tree")]
    backend: Backend,
}

impl TraversalArgs {
    fn parse(&self, any_hit: bool) -> Result<Traversal> {
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

#[derive(clap::Args)]
struct VerifyArgs {
    /// OBJ scene file.
    scene: PathBuf,
    /// A ray file to verify instead of the stress categories.
    rays: Option<PathBuf>,
    #[command(flatten)]
    traversal: TraversalArgs,
    #[command(flatten)]
    tree: TreeArgs,
    /// Verify any-hit (shadow) answers instead of closest hits.
    #[arg(long)]
    any_hit: bool,
    /// Trace with the CPU twin of the traversal instead of the GPU.
    #[arg(long)]
    cpu: bool,
    /// Rays per stress category.
    #[arg(long, default_value_t = 2000)]
    count: usize,
    /// Seed of the stress rays.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scale the scene by this factor first (e.g. 1e-4 or 1e5).
    #[arg(long, default_value_t = 1.0)]
    scale: f32,
    /// Print up to this many seriously wrong rays per category.
    #[arg(long, default_value_t = 3)]
    show: usize,
    /// Also print up to `--show` disagreeing rays per category that are not serious.
    #[arg(long)]
    show_all: bool,
}

#[derive(clap::Args)]
struct SubgroupsArgs {
    /// OBJ scene file.
    scene: PathBuf,
    #[command(flatten)]
    tree: TreeArgs,
    /// Camera rays: image width and height.
    #[arg(long, default_value_t = 256)]
    width: u32,
    #[arg(long, default_value_t = 192)]
    height: u32,
    /// Random rays.
    #[arg(long, default_value_t = 50_000)]
    random: usize,
    /// Timed repetitions per cell (median reported, after a warm-up).
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// CSV output.
    #[arg(long, default_value = "subgroups.csv")]
    csv: PathBuf,
    /// PNG chart output.
    #[arg(long, default_value = "subgroups.png")]
    png: PathBuf,
}

#[derive(clap::Args)]
struct BenchArgs {
    /// OBJ scene files.
    #[arg(required = true)]
    scenes: Vec<PathBuf>,
    /// Camera rays: image width and height (full-size batches by default: small
    /// ones measure per-dispatch overheads rather than traversal).
    #[arg(long, default_value_t = 1024)]
    width: u32,
    #[arg(long, default_value_t = 768)]
    height: u32,
    /// Random rays (uniform origins in the box, uniform directions).
    #[arg(long, default_value_t = 1_000_000)]
    random: usize,
    /// Timed repetitions per cell (after one warm-up); median, min and max are reported.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Rays per cell judged against the exact reference (evenly spaced).
    #[arg(long, default_value_t = 500)]
    reference_sample: usize,
    /// GPU traversals: `all` or `name[:stack-size][/plain]`, comma-separated. Without
    /// `:stack-size` the short stacks run every --stack-sizes; without `/plain`
    /// every --robust level; packet variants every --packet-widths.
    #[arg(long, default_value = "all")]
    traversals: String,
    #[arg(long, default_value = "1,3,8")]
    stack_sizes: String,
    #[arg(long, default_value = "1")]
    packet_widths: String,
    /// Robustness levels: on, off or on,off.
    #[arg(long, default_value = "on,off")]
    robust: String,
    /// Builder settings: default, sweep (default's costs, exact sweep everywhere), pbrt-v3, wald-havran.
    #[arg(long, default_value = "default,pbrt-v3,wald-havran")]
    builders: String,
    /// Ray kinds: camera, shadow, reflection, diffuse, random, hard (the stress
    /// categories of `verify`, 64 rays each).
    #[arg(long, default_value = "camera,shadow,reflection,diffuse,random")]
    kinds: String,
    /// CPU-twin traversals (rayon over rays), same syntax as --traversals; `none` for none.
    #[arg(long, default_value = "stack")]
    cpu: String,
    /// Leave Embree out (it runs by default when built with --features embree).
    #[arg(long)]
    no_embree: bool,
    /// Device backends, comma-separated: kd-tree (the --traversals cells), ray-query
    /// (the driver's ray query, one cell per ray kind; Mesa >= 24 lavapipe or a GPU).
    #[arg(long, default_value = "kd-tree")]
    backend: String,
    /// Leave the Vulkan device out (CPU peers only).
    #[arg(long)]
    no_gpu: bool,
    /// Require this subgroup size.
    #[arg(long)]
    subgroup_size: Option<u32>,
    /// Seed of the random and diffuse rays.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// CSV output (one row per cell).
    #[arg(long, default_value = "bench.csv")]
    csv: PathBuf,
    /// Folder for the PNG charts (bench-time-error.png, bench-rays-per-second.png, bench-nodes.png).
    #[arg(long, default_value = ".")]
    plots: PathBuf,
    /// Also render images and compare them with a converged reference: each cell's
    /// render time with its RMSE and SSIM (images CSV and bench-images-time-error.png).
    #[arg(long)]
    images: bool,
    /// Image size for --images, WxH.
    #[arg(long, default_value = "128x96")]
    image_size: String,
    /// Samples per pixel of the image cells.
    #[arg(long, default_value = "1,4,16,64")]
    image_spp: String,
    /// Diffuse bounces of the image cells.
    #[arg(long, default_value = "0,1,3")]
    image_bounces: String,
    /// First hits of the image cells: trace, raster or trace,raster.
    #[arg(long, default_value = "trace,raster")]
    image_primary: String,
    /// GPU traversals of the image cells (same syntax as --traversals, no `all`).
    #[arg(long, default_value = "stack")]
    image_traversals: String,
    /// Samples per pixel and bounces of the reference image.
    #[arg(long, default_value_t = 1024)]
    reference_spp: u32,
    #[arg(long, default_value_t = 3)]
    reference_bounces: u32,
    /// CSV of the image cells.
    #[arg(long, default_value = "bench-images.csv")]
    images_csv: PathBuf,
    #[command(flatten)]
    tree: TreeArgs,
}

#[derive(clap::Args)]
struct TraceArgs {
    /// OBJ scene file.
    scene: PathBuf,
    /// Ray file: 32-byte records ox oy oz tmin dx dy dz tmax (f32, little-endian).
    rays: PathBuf,
    /// Hit file to write: 16-byte records t prim_id u v.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    traversal: TraversalArgs,
    #[command(flatten)]
    tree: TreeArgs,
    /// Any-hit (shadow-ray) mode: report the first occluder found, not the closest hit.
    #[arg(long)]
    any_hit: bool,
    /// Write per-ray counters (nodes, leaves, triangles, restarts, steps, drops) to this CSV.
    #[arg(long)]
    counters: Option<PathBuf>,
    /// Trace in a coherent order (direction octant, origin Morton code, direction cell)
    /// instead of the file's; hits and counters are still written in file order.
    #[arg(long)]
    sort: bool,
    /// Print the wall time of every stage (rays, OBJ, kd-tree, device, upload,
    /// pipelines, trace, write) on stderr.
    #[arg(long)]
    timings: bool,
}

#[derive(clap::Args)]
struct StatsArgs {
    /// OBJ scene file.
    scene: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Build this many times; report the fastest and the median build time.
    #[arg(long, default_value_t = 1)]
    repeat: u32,
    /// Builder parameters to start from: default | pbrt-v3 | wald-havran.
    #[arg(long, default_value = "default")]
    config: String,
    /// Override K_T, the cost of traversing a node.
    #[arg(long)]
    traversal_cost: Option<f32>,
    /// Override K_I, the cost of a ray/triangle test.
    #[arg(long)]
    intersection_cost: Option<f32>,
    /// Override the empty-space bonus (0 ≤ b < 1).
    #[arg(long)]
    empty_bonus: Option<f32>,
    /// Override the depth limit (default: 8 + 1.3·log2 N, capped).
    #[arg(long)]
    max_depth: Option<u32>,
    /// Clip only triangle boxes at splits, not the triangles (no "perfect splits").
    #[arg(long)]
    box_clipping: bool,
    #[command(flatten)]
    builder: BuilderArgs,
    /// Worker threads for the build (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

/// The split search of the kd-tree builder.
#[derive(clap::Args)]
struct BuilderArgs {
    /// binned: binned SAH on the large nodes, the exact sweep below (the
    /// default's); sweep: the exact SAH sweep at every node.
    #[arg(long, value_enum)]
    builder: Option<BuilderKind>,
    /// Binned builder: bins per axis [default: 64].
    #[arg(long)]
    bins: Option<u32>,
    /// Binned builder: nodes of at least this many triangles are binned [default: 4096].
    #[arg(long)]
    binned_above: Option<u32>,
}

/// The builder as `stats` prints it: `sweep` or `binned:BINS:MIN_PRIMS`.
fn builder_name(b: &kdtrace::kdtree::Builder) -> String {
    match b {
        kdtrace::kdtree::Builder::Sweep => "sweep".into(),
        kdtrace::kdtree::Builder::Binned { bins, min_prims } => format!("binned:{bins}:{min_prims}"),
    }
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
enum BuilderKind {
    Sweep,
    Binned,
}

impl BuilderArgs {
    /// `config` with the builder these options choose (its own when none).
    fn apply(&self, config: BuildConfig) -> Result<BuildConfig> {
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

#[derive(clap::Args)]
struct RaysArgs {
    /// OBJ scene file (its box and camera place the rays).
    scene: PathBuf,
    /// Ray file to write.
    #[arg(short, long)]
    output: PathBuf,
    /// camera: one ray per pixel of the scene's camera; random: uniform origins in the box, uniform directions.
    #[arg(long, default_value = "camera")]
    kind: String,
    /// Image size for camera rays.
    #[arg(long, default_value_t = 800)]
    width: u32,
    #[arg(long, default_value_t = 600)]
    height: u32,
    /// Number of random rays.
    #[arg(short = 'n', long, default_value_t = 1_000_000)]
    count: usize,
    /// Seed of the random rays.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn parse_vec3(s: &str) -> std::result::Result<Vec3, String> {
    let parts: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>().map_err(|e| format!("'{p}': {e}")))
        .collect::<std::result::Result<_, _>>()?;
    match parts.as_slice() {
        [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(format!("expected three finite numbers x,y,z, got '{s}'")),
    }
}

fn parse_light(s: &str) -> std::result::Result<(Vec3, Option<f32>), String> {
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

fn spinner(message: String) -> ProgressBar {
    let bar = ProgressBar::new_spinner().with_message(message);
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

/// Loads the scene and builds its tree (or loads it from the tree cache), with a
/// progress bar while that runs.
fn load_and_build(path: &Path, tree: &TreeArgs, stages: &mut Stages) -> Result<(Scene, KdTree)> {
    let bar = spinner(format!("loading {}", path.display()));
    let scene = Scene::load(path)?;
    stages.mark("parse and check the OBJ");
    let tree = build_tree(&bar, &scene.triangles, tree)?;
    stages.mark("kd-tree (build or cache)");
    bar.finish_and_clear();
    Ok((scene, tree))
}

/// The wall time of each stage of a command, printed on stderr with `--timings`.
struct Stages {
    enabled: bool,
    start: Instant,
    last: Instant,
    list: Vec<(&'static str, f64)>,
    notes: Vec<String>,
}

impl Stages {
    fn new(enabled: bool) -> Stages {
        let now = Instant::now();
        Stages { enabled, start: now, last: now, list: Vec::new(), notes: Vec::new() }
    }

    /// Ends the stage called `name`, which began where the previous one ended.
    fn mark(&mut self, name: &'static str) {
        let now = Instant::now();
        self.list.push((name, (now - self.last).as_secs_f64()));
        self.last = now;
    }

    /// Prints the stages and the total, when enabled.
    fn print(&self) {
        if !self.enabled {
            return;
        }
        let total = (self.last - self.start).as_secs_f64();
        eprintln!("stages (wall):");
        for (name, seconds) in &self.list {
            eprintln!("  {name:<26} {seconds:>8.3} s {:>5.1} %", 100.0 * seconds / total.max(1e-12));
        }
        eprintln!("  {:<26} {total:>8.3} s", "total");
        for note in &self.notes {
            eprintln!("  ({note})");
        }
    }

    /// A line printed after the stages (work that ran beside them).
    fn note(&mut self, line: String) {
        self.notes.push(line);
    }
}

/// `--tree-cache DIR` and the builder, shared by the subcommands that build a tree.
#[derive(clap::Args)]
struct TreeArgs {
    /// Folder of cached kd-trees: load the scene's tree from it when it holds a
    /// valid one, else build the tree and store it there (bench: --images only).
    #[arg(long, env = "KDTRACE_TREE_CACHE", value_name = "DIR")]
    tree_cache: Option<PathBuf>,
    #[command(flatten)]
    builder: BuilderArgs,
}

/// Runs `build` (which reports to the [`BuildProgress`] it is given) on another
/// thread while `bar` shows the build's stage and the fraction of the tree done.
fn with_build_bar<T: Send>(bar: &ProgressBar, message: &str, build: impl FnOnce(&BuildProgress) -> T + Send) -> T {
    use kdtrace::kdtree::BuildStage;
    let progress = BuildProgress::default();
    std::thread::scope(|scope| {
        let worker = scope.spawn(|| build(&progress));
        while !worker.is_finished() {
            let stage = match progress.stage() {
                // Not building (yet): whoever runs `build` tells the bar.
                BuildStage::Waiting | BuildStage::Finished => None,
                BuildStage::Preparing => Some("preparing".to_string()),
                BuildStage::Splitting => Some(format!("{:.0} %", 100.0 * progress.fraction())),
                BuildStage::Statistics => Some("statistics".to_string()),
            };
            if let Some(stage) = stage {
                bar.set_message(format!("{message}: {stage}"));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        worker.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

/// The kd-tree over `triangles` with the chosen builder, built or loaded from
/// the tree cache, with the stage on `bar` and one line on stderr about the
/// cache file.
fn build_tree(bar: &ProgressBar, triangles: &[[Vec3; 3]], args: &TreeArgs) -> Result<KdTree> {
    use kdtrace::kdtree::cache::{load_or_build, CacheOutcome, Stage};
    let config = args.builder.apply(BuildConfig::default())?;
    let building = format!("building kd-tree over {} triangles", triangles.len());
    let Some(dir) = &args.tree_cache else {
        return Ok(with_build_bar(bar, &building, |p| KdTree::build_with_progress(triangles, &config, Some(p))));
    };
    let (tree, outcome) = with_build_bar(bar, &building, |p| {
        load_or_build(dir, triangles, &config, Some(p), |stage| {
            bar.set_message(match stage {
                Stage::Hashing => "hashing the triangles for the tree cache".to_string(),
                Stage::Loading => format!("loading kd-tree from {}", dir.display()),
                Stage::Building => building.clone(),
                Stage::Storing => format!("storing kd-tree in {}", dir.display()),
            })
        })
    });
    let path = outcome.path().display();
    let build = tree.stats.build_seconds;
    let message = match &outcome {
        CacheOutcome::Hit { load_seconds, .. } => {
            format!("loaded kd-tree from cache {path} in {load_seconds:.3} s (build took {build:.3} s)")
        }
        CacheOutcome::Stored { store_seconds, .. } => {
            format!("built kd-tree in {build:.3} s, stored in cache {path} in {store_seconds:.3} s")
        }
        CacheOutcome::Rebuilt { reason, .. } => {
            format!("warning: tree cache {path} rejected ({reason}); rebuilt in {build:.3} s and replaced")
        }
        CacheOutcome::StoreFailed { rejected, reason, .. } => {
            let rejected = rejected.as_ref().map_or(String::new(), |r| format!("rejected ({r}), "));
            format!("warning: tree cache {path} {rejected}not stored: {reason}")
        }
    };
    bar.suspend(|| eprintln!("{message}"));
    Ok(tree)
}

fn context() -> Result<std::sync::Arc<GpuContext>> {
    GpuContext::headless(&ContextOptions::from_env()).context("creating the Vulkan device")
}

/// The device for `backends`: with the ray-query extensions enabled when one is the ray query.
fn backend_context(backends: &[Backend]) -> Result<std::sync::Arc<GpuContext>> {
    let options = ContextOptions { ray_query: backends.contains(&Backend::RayQuery), ..ContextOptions::from_env() };
    GpuContext::headless(&options).context("creating the Vulkan device")
}

fn trace_bar(len: usize) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(ProgressStyle::with_template("tracing {bar:40} {pos}/{len} rays {elapsed}").unwrap());
    bar
}

fn render(args: RenderArgs) -> Result<()> {
    if args.width == 0 || args.height == 0 || args.width > 16384 || args.height > 16384 {
        bail!("--width and --height must be in 1..=16384");
    }
    let traversal = args.traversal.parse(false)?;
    let heatmap = match args.heatmap.as_deref() {
        None => None,
        Some(h @ ("nodes" | "triangles")) => Some(h.to_string()),
        Some(other) => bail!("unknown --heatmap '{other}' (nodes, triangles)"),
    };
    let primary = match args.primary.as_str() {
        "trace" => Primary::Trace,
        "raster" => Primary::Raster,
        other => bail!("unknown --primary '{other}' (trace, raster)"),
    };
    if !(args.exposure.is_finite() && args.exposure >= 0.0) {
        bail!("--exposure must be a finite number >= 0");
    }
    let mut stages = Stages::new(args.timings);
    let (scene, tree) = load_and_build(&args.scene, &args.tree, &mut stages)?;
    let mut camera = default_camera(&args.scene, &scene)?;
    if let Some(eye) = args.eye {
        camera.eye = eye;
    }
    if let Some(target) = args.target {
        camera.target = target;
    }
    if let Some(up) = args.up {
        camera.up = up;
    }
    if let Some(fov) = args.fov {
        if !(fov > 0.0 && fov < 180.0) {
            bail!("--fov must be in (0, 180) degrees");
        }
        camera.fov_deg = fov;
    }
    if (camera.target - camera.eye).length_squared() == 0.0
        || (camera.target - camera.eye).cross(camera.up) == Vec3::ZERO
    {
        bail!("the camera is degenerate: eye equals target, or up is parallel to the view direction");
    }
    let ctx = backend_context(&[args.traversal.backend])?;
    stages.mark("Vulkan device");
    let mut tracer = Tracer::with_backend(&ctx, args.traversal.backend, &tree, &scene.triangles)?;
    stages.mark("upload the scene");
    if let Some(kind) = &heatmap {
        return render_heatmap(&args, &ctx, &mut tracer, &camera, traversal, kind);
    }

    let mut settings = RenderSettings::new(args.width, args.height);
    settings.spp = args.spp;
    settings.seed = args.seed;
    settings.max_depth = args.max_depth;
    settings.bounces = args.bounces;
    settings.ao_samples = args.ao;
    settings.ao_radius = args.ao_radius;
    settings.ambient = args.ambient;
    settings.background = args.background;
    settings.traversal = traversal;
    settings.skip_unneeded = !args.no_skip;
    settings.primary = primary;
    settings.lights = args
        .light
        .iter()
        .map(|&(position, intensity)| {
            let d2 = (scene.bounds.center() - position).length_squared().max(f32::MIN_POSITIVE);
            PointLight { position, intensity: Vec3::splat(intensity.unwrap_or(std::f32::consts::PI * d2)) }
        })
        .collect();
    if args.explain {
        for line in RenderPlan::new(&scene, &settings)?.explain() {
            eprintln!("  {line}");
        }
    }
    let render_once = |tracer: &mut Tracer, settings: &RenderSettings| {
        let bar = ProgressBar::new(u64::from(settings.spp));
        bar.set_style(ProgressStyle::with_template("rendering {bar:40} {pos}/{len} sample passes {elapsed}").unwrap());
        let out = kdtrace::render::render(tracer, &scene, &camera, settings, |done, total| {
            bar.set_length(total);
            bar.set_position(done);
        });
        bar.finish_and_clear();
        out
    };
    let is_exr = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let save = |pixels: &[Vec3]| -> Result<()> {
        if is_exr {
            kdtrace::render::save_exr(&args.output, pixels, args.width, args.height)?;
        } else {
            let image = kdtrace::render::tone_map(pixels, args.width, args.height, args.exposure);
            image.save(&args.output).with_context(|| format!("writing {}", args.output.display()))?;
        }
        Ok(())
    };
    let out = if args.checkpoint > 0 {
        let bar = ProgressBar::new(u64::from(settings.spp));
        bar.set_style(
            ProgressStyle::with_template("rendering {bar:40} {pos}/{len} sample passes {elapsed} {msg}").unwrap(),
        );
        let out = kdtrace::render::render_progressive(
            &mut tracer,
            &scene,
            &camera,
            &settings,
            args.checkpoint,
            |done, total| {
                bar.set_length(total);
                bar.set_position(done);
            },
            |samples, pixels| {
                save(pixels).map_err(|e| kdtrace::Error::InvalidInput(format!("{e:#}")))?;
                bar.set_message(format!("(wrote {} at {samples} spp)", args.output.display()));
                Ok(())
            },
        );
        bar.finish_and_clear();
        out?
    } else {
        render_once(&mut tracer, &settings)?
    };
    if args.compare {
        compare_renders(&ctx, args.traversal.backend, &tree, &scene, &settings, &out, render_once)?;
    }

    stages.mark("render (pipelines, passes)");
    let mut out = out;
    if args.explain {
        // A debug colour for pixels that lost a ray (invalid or unfinished).
        for &p in &out.bad_pixels {
            out.pixels[p] = BAD_PIXEL;
        }
    }
    save(&out.pixels)?;
    if let Some(exr) = &args.exr {
        kdtrace::render::save_exr(exr, &out.pixels, out.width, out.height)?;
    }
    stages.mark("write the image");
    let s = &out.stats;
    eprint!(
        "{}: {}x{}, {} spp on {}: {} camera + {} secondary + {} shadow rays",
        args.output.display(),
        out.width,
        out.height,
        args.spp,
        ctx.info.name,
        s.camera_rays,
        s.secondary_rays,
        s.shadow_rays
    );
    if let (Some(t), Some(sh)) = (s.trace_seconds, s.shade_seconds) {
        eprint!(
            "; GPU: trace {:.1} ms ({:.2} M rays/s), shade {:.1} ms",
            t * 1e3,
            s.traced_rays() as f64 / t.max(1e-12) / 1e6,
            sh * 1e3
        );
    }
    if s.rasterized {
        let time = s.raster_seconds.map_or(String::new(), |r| format!(" in {:.1} ms", r * 1e3));
        eprint!("; first hits rasterized{time} ({} edge ties)", s.raster_edge_pixels);
    }
    if s.trace_seconds.is_none() {
        eprint!("; no GPU times (timestamps missing or implausible on this device)");
    }
    eprintln!(
        "; setup {:.0} ms, render {:.0} ms wall, {} submits",
        s.setup_seconds * 1e3,
        s.render_seconds * 1e3,
        s.submits
    );
    stages.print();
    if s.bad_rays > 0 {
        let what = format!(
            "ray(s) of the render (invalid or unfinished; {} pixel(s) lack their light{})",
            out.bad_pixels.len(),
            if args.explain { ", painted magenta by --explain" } else { "; --explain paints them magenta" }
        );
        return Err(Unfinished::incomplete(s.bad_rays as usize, &what).into());
    }
    Ok(())
}

/// `render --compare`: the render as asked, without skipping, and with the other
/// kind of first hits, each on a fresh tracer; a table of their costs.
fn compare_renders(
    ctx: &std::sync::Arc<GpuContext>,
    backend: Backend,
    tree: &KdTree,
    scene: &Scene,
    settings: &RenderSettings,
    first: &kdtrace::render::RenderOutput,
    render_once: impl Fn(&mut Tracer, &RenderSettings) -> kdtrace::Result<kdtrace::render::RenderOutput>,
) -> Result<()> {
    let mut variants = vec![("as asked".to_string(), settings.clone())];
    if settings.skip_unneeded {
        variants.push(("--no-skip".into(), RenderSettings { skip_unneeded: false, ..settings.clone() }));
    }
    let other = match settings.primary {
        Primary::Trace => ("--primary raster", Primary::Raster),
        Primary::Raster => ("--primary trace", Primary::Trace),
    };
    variants.push((other.0.into(), RenderSettings { primary: other.1, ..settings.clone() }));
    let mean = first.pixels.iter().map(|p| f64::from(p.element_sum())).sum::<f64>() / (3 * first.pixels.len()) as f64;
    let ms = |s: Option<f64>| s.map_or("-".to_string(), |s| format!("{:.1}", s * 1e3));
    eprintln!(
        "{:<18} {:>9} {:>9} {:>9} {:>9} {:>9} {:>11} {:>8}",
        "variant", "setup ms", "loop ms", "trace ms", "shade ms", "raster ms", "rays", "RMSE"
    );
    for (name, variant) in &variants {
        // A fresh tracer, so that the variant compiles its own pipelines.
        let mut tracer = Tracer::with_backend(ctx, backend, tree, &scene.triangles)?;
        let out = render_once(&mut tracer, variant)?;
        let s = &out.stats;
        let sq =
            out.pixels.iter().zip(&first.pixels).map(|(a, b)| f64::from((*a - *b).length_squared()) / 3.0).sum::<f64>();
        let rmse = (sq / out.pixels.len() as f64).sqrt() / mean.max(f64::MIN_POSITIVE);
        eprintln!(
            "{:<18} {:>9.1} {:>9.1} {:>9} {:>9} {:>9} {:>11} {:>7.2}%",
            name,
            s.setup_seconds * 1e3,
            s.render_seconds * 1e3,
            ms(s.trace_seconds),
            ms(s.shade_seconds),
            ms(s.raster_seconds),
            s.rays(),
            rmse * 100.0
        );
    }
    eprintln!(
        "(setup: pipelines and uploads; loop: the sample loop's wall time; trace/shade/raster: GPU \
         timestamps, '-' where the device gave none; RMSE: each image against the first one, relative \
         to its mean; the first variant ran twice)"
    );
    Ok(())
}

/// `render --heatmap`: the per-pixel node visits or triangle tests of camera rays.
fn render_heatmap(
    args: &RenderArgs,
    ctx: &GpuContext,
    tracer: &mut Tracer,
    camera: &Camera,
    traversal: Traversal,
    kind: &str,
) -> Result<()> {
    // Morton order: every aligned run of 4^k rays is a square tile, so packets hold neighbours.
    let (rays, pixels) = kdtrace::render::camera_rays_morton(camera, args.width, args.height);
    let bar = trace_bar(rays.len());
    let options = TraceOptions { traversal, counters: true };
    let result = tracer.trace_with_progress(&rays, &options, |n| bar.set_position(n as u64))?;
    bar.finish_and_clear();
    let counters = result.counters.context("the tracer returned no counters")?;
    let mut values = vec![0u32; pixels.len()];
    for (c, &p) in counters.iter().zip(&pixels) {
        values[p as usize] = if kind == "nodes" { c.nodes } else { c.triangles };
    }
    let (image, max, mean) = kdtrace::render::heatmap(&values, args.width, args.height);
    eprintln!("heatmap of {kind} per ray ({}): mean {mean:.1}, max {max}", traversal.variant);
    image.save(&args.output).with_context(|| format!("writing {}", args.output.display()))?;
    eprintln!("{}: {}x{} on {}", args.output.display(), args.width, args.height, ctx.info.name);
    Ok(())
}

/// The camera from `cameras.json` beside the scene (keyed by file stem), else one framing the box.
fn default_camera(path: &Path, scene: &Scene) -> Result<Camera> {
    let json = path.parent().unwrap_or(Path::new(".")).join("cameras.json");
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    if json.exists() {
        if let Some(camera) = Camera::from_cameras_json(&json, &stem)? {
            return Ok(camera);
        }
    }
    Ok(Camera::frame(&scene.bounds))
}

fn trace(args: TraceArgs) -> Result<()> {
    let traversal = args.traversal.parse(args.any_hit)?;
    let backend = args.traversal.backend;
    let label = if backend == Backend::KdTree { traversal.variant.name() } else { backend.name() };
    let mut stages = Stages::new(args.timings);
    let rays = kdtrace::io::read_rays(&args.rays)?;
    stages.mark("read the rays");
    let options = TraceOptions { traversal, counters: args.counters.is_some() };
    // The device and the pipelines come up on another thread while the scene
    // loads and its tree builds.
    let (device, loaded) = std::thread::scope(|scope| {
        let device = scope.spawn(|| -> Result<_> {
            let start = Instant::now();
            let ctx = backend_context(&[backend])?;
            let mut pipelines = TracePipelines::new(&ctx);
            pipelines.prepare(backend, &options)?;
            Ok((ctx, pipelines, start.elapsed().as_secs_f64()))
        });
        let loaded = if backend == Backend::RayQuery {
            // The driver builds its own structure: no kd-tree needed.
            Scene::load(&args.scene).map_err(Into::into).map(|scene| {
                stages.mark("parse and check the OBJ");
                (scene, KdTree::build(&[], &BuildConfig::default()))
            })
        } else {
            load_and_build(&args.scene, &args.tree, &mut stages)
        };
        (device.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)), loaded)
    });
    let (scene, tree) = loaded?;
    let (ctx, pipelines, device_seconds) = device?;
    stages.mark("wait for the device");
    stages.note(format!("device and pipelines, beside the above: {device_seconds:.3} s"));
    let mut tracer = Tracer::with_backend(&ctx, backend, &tree, &scene.triangles)?;
    tracer.adopt_pipelines(pipelines)?;
    tracer.prepare(&options)?;
    stages.mark("upload the scene");
    let bar = trace_bar(rays.len());
    let start = Instant::now();
    let order = args.sort.then(|| kdtrace::raygen::coherent_order(&rays, &scene.bounds));
    let traced: Vec<kdtrace::Ray> = match &order {
        Some(order) => order.iter().map(|&i| rays[i as usize]).collect(),
        None => rays.clone(),
    };
    let mut result = tracer.trace_with_progress(&traced, &options, |n| bar.set_position(n as u64))?;
    let wall = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    stages.mark("trace");
    if let Some(order) = &order {
        // Back to the file's order.
        let mut hits = vec![kdtrace::Hit::MISS; rays.len()];
        for (h, &i) in result.hits.iter().zip(order) {
            hits[i as usize] = *h;
        }
        result.hits = hits;
        if let Some(counters) = result.counters.as_mut() {
            let mut unsorted = vec![Counters::default(); rays.len()];
            for (c, &i) in counters.iter().zip(order) {
                unsorted[i as usize] = *c;
            }
            *counters = unsorted;
        }
    }
    kdtrace::io::write_hits(&args.output, &result.hits)?;
    stages.mark("write the hits");
    if let (Some(path), Some(counters)) = (&args.counters, &result.counters) {
        write_counters_csv(path, counters)?;
        let n = counters.len().max(1) as f64;
        let mean = |f: fn(&Counters) -> u32| counters.iter().map(|c| f(c) as f64).sum::<f64>() / n;
        eprintln!(
            "per ray: {:.1} nodes, {:.2} leaves, {:.1} triangles, {:.2} restarts, {:.2} drops ({})",
            mean(|c| c.nodes),
            mean(|c| c.leaves),
            mean(|c| c.triangles),
            mean(|c| c.restarts),
            mean(|c| c.drops),
            path.display()
        );
    }
    let hits = result.hits.iter().filter(|h| h.is_hit()).count();
    let invalid = result.hits.iter().filter(|h| h.prim_id == kdtrace::consts::PRIM_INVALID).count();
    eprintln!(
        "{} rays, {} hits, {} invalid (NaN/zero direction or non-finite origin) on {}",
        rays.len(),
        hits,
        invalid,
        ctx.info.name
    );
    match result.gpu_seconds {
        Some(s) if s > 0.0 => eprintln!(
            "traversal ({}): {:.3} ms GPU = {:.2} M rays/s (timestamps, excluding upload; wall incl. transfers {:.3} ms)",
            label,
            s * 1e3,
            rays.len() as f64 / s / 1e6,
            wall * 1e3
        ),
        _ => eprintln!("traversal ({}): the device has no timestamps; wall incl. transfers {:.3} ms", label, wall * 1e3),
    }
    stages.print();
    match Unfinished::from_hits(&result.hits) {
        Some(u) => Err(u.into()),
        None => Ok(()),
    }
}

fn write_counters_csv(path: &Path, counters: &[Counters]) -> Result<()> {
    use std::io::Write;
    let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut out = std::io::BufWriter::new(file);
    writeln!(out, "ray,nodes,leaves,triangles,restarts,steps,drops")?;
    for (i, c) in counters.iter().enumerate() {
        writeln!(out, "{i},{},{},{},{},{},{}", c.nodes, c.leaves, c.triangles, c.restarts, c.steps, c.drops)?;
    }
    out.flush().with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// The first number of /proc/loadavg's three, as text (or why not).
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unavailable".into())
}

/// Today's date (UTC) as YYYY-MM-DD, from the system clock (Hinnant's civil-from-days).
fn today() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let z = (secs / 86_400) as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

fn bench(args: BenchArgs) -> Result<()> {
    use kdtrace::bench::matrix::{expand_traversals, parse_list};
    use kdtrace::bench::{report, MatrixOptions, RayKind};
    if args.width == 0 || args.height == 0 || args.width > 16384 || args.height > 16384 {
        bail!("--width and --height must be in 1..=16384");
    }
    if args.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let robust: Vec<bool> = args
        .robust
        .split(',')
        .map(|s| match s.trim() {
            "on" => Ok(true),
            "off" => Ok(false),
            other => bail!("--robust: '{other}' is neither on nor off"),
        })
        .collect::<Result<_>>()?;
    let stack_sizes: Vec<u32> = parse_list("--stack-sizes", &args.stack_sizes)?;
    let widths: Vec<u32> = parse_list("--packet-widths", &args.packet_widths)?;
    let traversals = expand_traversals(&args.traversals, &stack_sizes, &widths, &robust, args.subgroup_size)?;
    let cpu_traversals = match args.cpu.as_str() {
        "none" => Vec::new(),
        list => expand_traversals(list, &stack_sizes, &[1], &robust, None)?,
    };
    let backends: Vec<Backend> = args.backend.split(',').map(|s| s.trim().parse()).collect::<kdtrace::Result<_>>()?;
    let options = MatrixOptions {
        width: args.width,
        height: args.height,
        random: args.random,
        repeat: args.repeat,
        reference_sample: args.reference_sample,
        traversals: if args.no_gpu || !backends.contains(&Backend::KdTree) { Vec::new() } else { traversals },
        cpu_traversals,
        builders: args.builders.split(',').map(|s| s.trim().to_string()).collect(),
        kinds: args.kinds.split(',').map(|s| s.trim().parse()).collect::<kdtrace::Result<Vec<RayKind>>>()?,
        embree: cfg!(feature = "embree") && !args.no_embree,
        ray_query: !args.no_gpu && backends.contains(&Backend::RayQuery),
        seed: args.seed,
    };
    for b in &options.builders {
        kdtrace::bench::matrix::builder_config(b)?;
    }
    let ctx = if args.no_gpu { None } else { Some(backend_context(&backends)?) };
    let device = ctx.as_ref().map_or("no Vulkan device (--no-gpu)".to_string(), |c| c.info.to_string());
    let load_before = load_average();
    let mut cells = Vec::new();
    for path in &args.scenes {
        let bar = spinner(format!("loading {}", path.display()));
        let scene = Scene::load(path)?;
        let camera = default_camera(path, &scene)?;
        let name = path.file_stem().map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        let found = kdtrace::bench::run_scene(ctx.as_ref(), &name, &scene, &camera, &options, |what| {
            bar.set_message(format!("{name}: {what}"))
        })?;
        bar.finish_and_clear();
        cells.extend(found);
    }
    if let Some(ctx) = &ctx {
        ctx.check_validation()?;
    }
    let image_cells = match (args.images, &ctx) {
        (false, _) => Vec::new(),
        (true, None) => bail!("--images renders on the Vulkan device: drop --no-gpu"),
        (true, Some(ctx)) => bench_images(&args, ctx, &stack_sizes, &widths, &robust)?,
    };
    let command: Vec<String> = std::env::args().collect();
    println!("# kdtrace bench, {}\n", today());
    println!("- device: {device}");
    println!(
        "- CPU peers: {} rayon threads on {} cores; Embree {}",
        rayon::current_num_threads(),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        if options.embree { "3 (libembree3)" } else { "not built (--features embree)" }
    );
    println!("- load average (/proc/loadavg, 1/5/15 min): {load_before} before, {} after", load_average());
    println!("- command: `{}`", command.join(" "));
    println!(
        "- times: build = kd-tree build (or Embree commit); upload = scene to the device; pipeline = \
         `prepare` (compile on first use, ~0 when cached); trace = GPU timestamps around the \
         dispatches (CPU: wall clock), median of {} after a warm-up (min–max); call = the whole \
         `trace` call with ray upload, submission and readback\n",
        args.repeat
    );
    println!("## Summary\n\n{}", report::summary_table(&cells));
    println!("## Every cell\n\n{}", report::markdown_table(&cells));
    report::write_csv(&args.csv, &cells)?;
    let title = format!("kdtrace bench on {}", ctx.as_ref().map_or("CPU only".into(), |c| c.info.name.clone()));
    let mut plots = kdtrace::bench::plot::write_plots(&args.plots, &cells, &title)?;
    if args.images {
        use kdtrace::bench::images;
        println!(
            "## Rendered images\n\nAgainst a reference of {} spp and {} bounces per scene (scenes without \
             emitters get the shadow rays' point light); wall = the render call after a one-sample warm-up.\n\n{}",
            args.reference_spp,
            args.reference_bounces,
            images::images_table(&image_cells)
        );
        images::write_images_csv(&args.images_csv, &image_cells)?;
        let png = args.plots.join("bench-images-time-error.png");
        images::plot_images(&png, &image_cells, &format!("{title}: rendered images"))?;
        plots.push(args.images_csv.clone());
        plots.push(png);
    }
    eprintln!(
        "wrote {} and {}",
        args.csv.display(),
        plots.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
    );
    let incomplete: usize = cells.iter().map(|c| c.incomplete).sum();
    if incomplete > 0 {
        let what =
            format!("rays in {} cell(s) (column 'incomplete')", cells.iter().filter(|c| c.incomplete > 0).count());
        return Err(Unfinished::incomplete(incomplete, &what).into());
    }
    Ok(())
}

/// `bench --images`: the image cells of every scene.
fn bench_images(
    args: &BenchArgs,
    ctx: &std::sync::Arc<GpuContext>,
    stack_sizes: &[u32],
    widths: &[u32],
    robust: &[bool],
) -> Result<Vec<kdtrace::bench::images::ImageCell>> {
    use kdtrace::bench::matrix::{expand_traversals, parse_list};
    let (w, h) = args
        .image_size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .filter(|&(w, h)| (1..=4096).contains(&w) && (1..=4096).contains(&h))
        .with_context(|| format!("--image-size '{}': expected WxH, each in 1..=4096", args.image_size))?;
    let primaries = args
        .image_primary
        .split(',')
        .map(|p| match p.trim() {
            "trace" => Ok(Primary::Trace),
            "raster" => Ok(Primary::Raster),
            other => bail!("--image-primary: unknown '{other}' (trace, raster)"),
        })
        .collect::<Result<Vec<_>>>()?;
    let options = kdtrace::bench::images::ImageOptions {
        width: w,
        height: h,
        spp: parse_list("--image-spp", &args.image_spp)?,
        bounces: parse_list("--image-bounces", &args.image_bounces)?,
        primaries,
        traversals: expand_traversals(&args.image_traversals, stack_sizes, widths, robust, args.subgroup_size)?,
        reference_spp: args.reference_spp,
        reference_bounces: args.reference_bounces,
    };
    let mut cells = Vec::new();
    for path in &args.scenes {
        let (scene, tree) = load_and_build(path, &args.tree, &mut Stages::new(false))?;
        let camera = default_camera(path, &scene)?;
        let name = path.file_stem().map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        let mut tracer = Tracer::new(ctx, &tree, &scene.triangles)?;
        let bar = spinner(format!("{name}: images"));
        let (found, _) = kdtrace::bench::images::run_images(&mut tracer, &name, &scene, &camera, &options, |m| {
            bar.set_message(m.to_string())
        })?;
        bar.finish_and_clear();
        cells.extend(found);
    }
    Ok(cells)
}

fn subgroups(args: SubgroupsArgs) -> Result<()> {
    let (scene, tree) = load_and_build(&args.scene, &args.tree, &mut Stages::new(false))?;
    let ctx = context()?;
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles)?;
    let camera = default_camera(&args.scene, &scene)?;
    let batches = [
        ("camera", kdtrace::render::camera_rays_morton(&camera, args.width, args.height).0),
        ("random", kdtrace::raygen::random_rays(&scene.bounds, args.random, 1)),
    ];
    let bar = spinner("sweeping".into());
    let rows = kdtrace::sweep::run(&mut tracer, &batches, args.repeat, |what| bar.set_message(what.to_string()))?;
    bar.finish_and_clear();
    let title = format!("{} on {}", args.scene.display(), ctx.info.name);
    println!("# kdtrace subgroups {title}\n\n{}", kdtrace::sweep::markdown_table(&rows));
    kdtrace::sweep::write_csv(&args.csv, &rows)?;
    kdtrace::sweep::plot_png(&args.png, &rows, &title)?;
    eprintln!("wrote {} and {}", args.csv.display(), args.png.display());
    Ok(())
}

fn stats(args: StatsArgs) -> Result<()> {
    let mut config = match args.config.as_str() {
        "default" => BuildConfig::default(),
        "pbrt-v3" => BuildConfig::PBRT_V3,
        "wald-havran" => BuildConfig::WALD_HAVRAN,
        other => bail!("unknown --config '{other}' (default, pbrt-v3, wald-havran)"),
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
    let (fastest, median) = (times[0], times[times.len() / 2]);
    let s = &tree.stats;
    if args.json {
        println!(
            "{{\"scene\":{:?},\"triangles\":{},\"degenerate\":{},\"skipped\":{},\"nodes\":{},\"leaves\":{},\"empty_leaves\":{},\"depth_limit\":{},\"max_depth\":{},\"mean_leaf_depth\":{},\"refs_per_triangle\":{},\"mean_prims_per_leaf\":{},\"max_prims_per_leaf\":{},\"sah_cost\":{},\"build_seconds\":{},\"build_seconds_median\":{},\"builds\":{},\"threads\":{},\"node_bytes\":{},\"index_bytes\":{},\"peak_scratch_bytes\":{},\"traversal_cost\":{},\"intersection_cost\":{},\"empty_bonus\":{},\"perfect_splits\":{},\"builder\":\"{}\"}}",
            args.scene.display().to_string(),
            scene.triangles.len(),
            scene.degenerate_count,
            s.skipped_triangles,
            s.nodes,
            s.leaves,
            s.empty_leaves,
            s.depth_limit,
            s.max_depth,
            s.mean_leaf_depth,
            s.refs_per_triangle,
            s.mean_prims_per_leaf,
            s.max_prims_per_leaf,
            s.sah_cost,
            fastest,
            median,
            times.len(),
            s.threads,
            s.node_bytes,
            s.index_bytes,
            s.peak_scratch_bytes,
            config.traversal_cost,
            config.intersection_cost,
            config.empty_bonus,
            config.perfect_splits,
            builder_name(&config.builder)
        );
    } else {
        let mib = |b: usize| b as f64 / (1 << 20) as f64;
        println!("scene               {}", args.scene.display());
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
            times.len(),
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
    }
    Ok(())
}

fn rays(args: RaysArgs) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    let rays = match args.kind.as_str() {
        "camera" => {
            if args.width == 0 || args.height == 0 || args.width > 16384 || args.height > 16384 {
                bail!("--width and --height must be in 1..=16384");
            }
            kdtrace::render::camera_rays(&default_camera(&args.scene, &scene)?, args.width, args.height)
        }
        "random" => kdtrace::raygen::random_rays(&scene.bounds, args.count, args.seed),
        other => bail!("unknown --kind '{other}' (camera, random)"),
    };
    kdtrace::io::write_rays(&args.output, &rays)?;
    eprintln!("{}: {} {} rays", args.output.display(), rays.len(), args.kind);
    Ok(())
}

fn verify(args: VerifyArgs) -> Result<()> {
    use kdtrace::stress::{judge_batch, stress_rays, table_header, table_row, Category};
    let traversal = args.traversal.parse(args.any_hit)?;
    if !(args.scale.is_finite() && args.scale > 0.0) {
        bail!("--scale must be a positive finite number");
    }
    let mut scene = Scene::load(&args.scene)?;
    if args.scale != 1.0 {
        for tri in scene.triangles.iter_mut() {
            *tri = tri.map(|v| v * args.scale);
        }
    }
    let bar = spinner(format!("building kd-tree over {} triangles", scene.triangles.len()));
    let tree = build_tree(&bar, &scene.triangles, &args.tree)?;
    bar.finish_and_clear();
    let batches: Vec<(String, Vec<kdtrace::Ray>)> = match &args.rays {
        Some(path) => vec![(path.display().to_string(), kdtrace::io::read_rays(path)?)],
        None => Category::ALL
            .iter()
            .map(|&c| (c.name().to_string(), stress_rays(c, &scene.triangles, &tree, args.count, args.seed)))
            .filter(|(_, rays)| !rays.is_empty())
            .collect(),
    };
    let backend = args.traversal.backend;
    if args.cpu && backend != Backend::KdTree {
        bail!("--cpu traces with the kd-tree's CPU twin: drop --backend {backend}");
    }
    let mut tracer = if args.cpu {
        None
    } else {
        let ctx = backend_context(&[backend])?;
        Some((Tracer::with_backend(&ctx, backend, &tree, &scene.triangles)?, ctx))
    };
    let device = tracer.as_ref().map_or("the CPU twin".to_string(), |(_, ctx)| ctx.info.name.clone());
    println!(
        "# kdtrace verify {} (scale {}): {} {} on {}, against the exact reference\n",
        args.scene.display(),
        args.scale,
        if backend == Backend::KdTree { traversal.variant.name() } else { backend.name() },
        if args.any_hit { "any-hit" } else { "closest hit" },
        device
    );
    // The agreement table with each category's node visits per ray (p50, p99).
    let header = table_header();
    let (head, rule) = header.split_once('\n').unwrap_or((&header, ""));
    println!("{head} p50 nodes | p99 nodes |\n{rule}---|---|");
    let (mut total, mut serious, mut incomplete) = (0usize, 0usize, 0usize);
    let mut examples = Vec::new();
    for (label, rays) in &batches {
        let (hits, counters): (Vec<kdtrace::Hit>, Vec<Counters>) = match tracer.as_mut() {
            // The ray query has no counters: its node columns stay empty.
            Some((tracer, _)) => {
                let counted = backend == Backend::KdTree;
                let result = tracer.trace(rays, &TraceOptions { traversal, counters: counted })?;
                (result.hits, result.counters.unwrap_or_default())
            }
            None => {
                let scene_ref = kdtrace::kdtree::traverse::SceneRef::new(&tree, &scene.triangles);
                let links = traversal
                    .variant
                    .uses_links()
                    .then(|| kdtrace::kdtree::links::TreeLinks::new(&tree.nodes, tree.bounds));
                let scene_ref = match &links {
                    Some(l) => scene_ref.with_links(l),
                    None => scene_ref,
                };
                rays.iter().map(|r| kdtrace::kdtree::traverse::trace_ray(&scene_ref, r, traversal)).unzip()
            }
        };
        let tally = judge_batch(&scene.triangles, rays, &hits, args.any_hit);
        let mut nodes: Vec<u32> = counters.iter().map(|c| c.nodes).collect();
        nodes.sort_unstable();
        let quantile = |q: f64| {
            let index = ((nodes.len() as f64 - 1.0) * q).round() as usize;
            nodes.get(index).map_or("—".to_string(), u32::to_string)
        };
        println!("{} {} | {} |", table_row(label, &tally), quantile(0.5), quantile(0.99));
        total += tally.rays;
        serious += tally.serious();
        incomplete += tally.incomplete;
        examples.extend(tally.serious_examples.iter().take(args.show).map(|e| (label.clone(), *e)));
        if args.show_all {
            examples.extend(tally.other_examples.iter().take(args.show).map(|e| (label.clone(), *e)));
        }
    }
    println!("\n{total} rays, {serious} serious errors, {incomplete} incomplete");
    for (label, (ray, hit, verdict)) in examples {
        println!("- {label}: {} ray {ray:?} -> {hit:?}", verdict.name());
        // What the exact reference says, and where the tracer's triangle lies exactly.
        let exact = match kdtrace::exact::closest_exact(&scene.triangles, &ray) {
            kdtrace::exact::Exact::Hit { ties, t } => format!("triangles {ties:?} at t = {t:e}"),
            other => format!("{other:?}"),
        };
        let own = match kdtrace::exact::hit_t_exact(&scene.triangles, &ray, hit.prim_id) {
            Some(t) => format!("hit exactly at t = {t:e}"),
            None => "missed exactly".to_string(),
        };
        println!("    exact: {exact}; the tracer's triangle is {own}");
    }
    if incomplete > 0 {
        return Err(Unfinished::incomplete(incomplete, "rays").into());
    }
    if serious > 0 {
        return Err(Unfinished { code: EXIT_SERIOUS, message: format!("{serious} serious error(s)") }.into());
    }
    Ok(())
}

/// `render --explain`'s colour for pixels that lost a ray: magenta, bright enough
/// to survive tone mapping.
const BAD_PIXEL: Vec3 = Vec3::new(1e3, 0.0, 1e3);

/// Exit status of `trace`, `verify`, `bench` and `render` when some rays did not
/// finish traversal (their answers are marked PRIM_INCOMPLETE; the rest is written).
const EXIT_INCOMPLETE: u8 = 3;
/// Exit status of `verify` when it found a serious error (and every ray finished).
const EXIT_SERIOUS: u8 = 4;

/// A command that did its work but must exit non-zero (EXIT_INCOMPLETE, EXIT_SERIOUS).
#[derive(Debug)]
struct Unfinished {
    code: u8,
    message: String,
}

impl Unfinished {
    fn incomplete(count: usize, what: &str) -> Self {
        Unfinished {
            code: EXIT_INCOMPLETE,
            message: format!(
                "{count} {what} did not finish traversal (the step cap is {}); they are marked PRIM_INCOMPLETE",
                kdtrace::consts::MAX_TRAVERSAL_STEPS
            ),
        }
    }

    /// `incomplete` for the hits of a batch: how many and the first indices.
    fn from_hits(hits: &[kdtrace::Hit]) -> Option<Self> {
        let rays = kdtrace::trace::incomplete_rays(hits);
        if rays.is_empty() {
            return None;
        }
        let first: Vec<String> = rays.iter().take(10).map(|i| i.to_string()).collect();
        let more = if rays.len() > 10 { ", ..." } else { "" };
        Some(Unfinished::incomplete(rays.len(), &format!("ray(s) (first: {}{more})", first.join(", "))))
    }
}

impl std::fmt::Display for Unfinished {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Unfinished {}

fn info() -> Result<()> {
    let devices = list_devices()?;
    if devices.is_empty() {
        bail!("no Vulkan device with a compute queue");
    }
    for (i, d) in devices.iter().enumerate() {
        println!("{i}: {d}");
        println!(
            "   subgroup size {} (min {}, max {}, size control {}), maxStorageBufferRange {} B",
            d.subgroup_size,
            d.min_subgroup_size,
            d.max_subgroup_size,
            d.subgroup_size_control,
            d.max_storage_buffer_range
        );
    }
    Ok(())
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render(a),
        Command::Trace(a) => trace(a),
        Command::Stats(a) => stats(a),
        Command::Rays(a) => rays(a),
        Command::Bench(a) => bench(a),
        Command::Subgroups(a) => subgroups(a),
        Command::Verify(a) => verify(a),
        Command::Info => info(),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => match e.downcast_ref::<Unfinished>() {
            Some(u) => {
                eprintln!("kdtrace: {u}");
                std::process::ExitCode::from(u.code)
            }
            None => {
                eprintln!("Error: {e:?}");
                std::process::ExitCode::FAILURE
            }
        },
    }
}
