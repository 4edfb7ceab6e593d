//! `kdtrace bench`: the benchmark matrix (and `--images`), as Markdown, CSV and charts.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use kdtrace::gpu::GpuContext;
use kdtrace::render::Primary;
use kdtrace::scene::Scene;
use kdtrace::trace::{Backend, Tracer};

use super::args::{choice, choices, PrimaryKind, TreeArgs};
use super::common::{backend_context, default_camera, load_and_build, spinner, Stages};
use super::Unfinished;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// OBJ scene files.
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    /// Camera rays: image width and height (full-size batches by default: small
    /// ones measure per-dispatch overheads rather than traversal).
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    #[arg(long, default_value_t = 768)]
    pub height: u32,
    /// Random rays (uniform origins in the box, uniform directions).
    #[arg(long, default_value_t = 1_000_000)]
    pub random: usize,
    /// Timed repetitions per cell (after one warm-up); median, min and max are reported.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Rays per cell judged against the exact reference (evenly spaced).
    #[arg(long, default_value_t = 500)]
    pub reference_sample: usize,
    /// GPU traversals: `all` or `name[:stack-size][/plain]`, comma-separated. Without
    /// `:stack-size` the short stacks run every --stack-sizes; without `/plain`
    /// every --robust level; packet variants every --packet-widths.
    #[arg(long, default_value = "all")]
    pub traversals: String,
    #[arg(long, default_value = "1,3,8")]
    pub stack_sizes: String,
    /// Orders the kd-tree GPU cells trace each batch in, comma-separated: as-given
    /// (the batch's order; camera rays in Morton order), coherent (sorted on the
    /// device first by direction octant and origin cell, inside the timed dispatches).
    #[arg(long, default_value = "as-given")]
    pub orders: String,
    #[arg(long, default_value = "1")]
    pub packet_widths: String,
    /// Robustness levels: on, off or on,off.
    #[arg(long, default_value = "on,off")]
    pub robust: String,
    /// Builder settings: default, sweep (default's costs, exact sweep everywhere), pbrt-v3, wald-havran.
    #[arg(long, default_value = "default,pbrt-v3,wald-havran")]
    pub builders: String,
    /// Ray kinds: camera, shadow, reflection, diffuse, random, hard (the stress
    /// categories of `verify`, 64 rays each).
    #[arg(long, default_value = "camera,shadow,reflection,diffuse,random,hard")]
    pub kinds: String,
    /// CPU-twin traversals (rayon over rays), same syntax as --traversals; `none` for none.
    #[arg(long, default_value = "stack")]
    pub cpu: String,
    /// Leave Embree out (it runs by default when built with --features embree).
    #[arg(long)]
    pub no_embree: bool,
    /// Device backends, comma-separated: kd-tree (the --traversals cells), ray-query
    /// (the driver's ray query, one cell per ray kind; Mesa >= 24 lavapipe or a GPU).
    #[arg(long, default_value = "kd-tree")]
    pub backend: String,
    /// Leave the Vulkan device out (CPU peers only).
    #[arg(long)]
    pub no_gpu: bool,
    /// Require this subgroup size.
    #[arg(long)]
    pub subgroup_size: Option<u32>,
    /// Seed of the random and diffuse rays.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// CSV output (one row per cell).
    #[arg(long, default_value = "bench.csv")]
    pub csv: PathBuf,
    /// Folder for the PNG charts (bench-time-error.png, bench-rays-per-second.png, bench-nodes.png).
    #[arg(long, default_value = ".")]
    pub plots: PathBuf,
    /// Also render images and compare them with a converged reference: each cell's
    /// render time with its RMSE and SSIM (images CSV and bench-images-time-error.png).
    #[arg(long)]
    pub images: bool,
    /// Image size for --images, WxH.
    #[arg(long, default_value = "128x96")]
    pub image_size: String,
    /// Samples per pixel of the image cells.
    #[arg(long, default_value = "1,4,16,64")]
    pub image_spp: String,
    /// Diffuse bounces of the image cells.
    #[arg(long, default_value = "0,1,3")]
    pub image_bounces: String,
    /// First hits of the image cells: trace, raster or trace,raster.
    #[arg(long, default_value = "trace,raster")]
    pub image_primary: String,
    /// GPU traversals of the image cells (same syntax as --traversals, no `all`).
    #[arg(long, default_value = "stack")]
    pub image_traversals: String,
    /// Samples per pixel and bounces of the reference image.
    #[arg(long, default_value_t = 1024)]
    pub reference_spp: u32,
    #[arg(long, default_value_t = 3)]
    pub reference_bounces: u32,
    /// CSV of the image cells.
    #[arg(long, default_value = "bench-images.csv")]
    pub images_csv: PathBuf,
    /// Ambient-occlusion rays at the first diffuse hit of the image cells and reference.
    #[arg(long, default_value_t = 0)]
    pub image_ao: u32,
    /// Errors (relative RMSE, % of the reference's mean) whose wall time the
    /// convergence table gives, from each configuration's fit over its spp sweep.
    #[arg(long, default_value = "5,2,1")]
    pub image_targets: String,
    /// Only the image cells (with --images): skip the ray matrix.
    #[arg(long)]
    pub images_only: bool,
    #[command(flatten)]
    pub tree: TreeArgs,
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

/// `kdtrace bench`: runs the matrix over every scene and writes the report, CSV and charts.
pub fn bench(args: BenchArgs) -> Result<()> {
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
        orders: args.orders.split(',').map(|s| s.trim().parse()).collect::<kdtrace::Result<_>>()?,
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
    if args.images_only && !args.images {
        bail!("--images-only needs --images");
    }
    let mut cells = Vec::new();
    for path in args.scenes.iter().filter(|_| !args.images_only) {
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
    let title = format!("kdtrace bench on {}", ctx.as_ref().map_or("CPU only".into(), |c| c.info.name.clone()));
    let mut plots = Vec::new();
    if !args.images_only {
        println!("## Summary\n\n{}", report::summary_table(&cells));
        println!("## Every cell\n\n{}", report::markdown_table(&cells));
        report::write_csv(&args.csv, &cells)?;
        plots = kdtrace::bench::plot::write_plots(&args.plots, &cells, &title)?;
        plots.insert(0, args.csv.clone());
    }
    if args.images {
        use kdtrace::bench::images;
        println!(
            "## Rendered images\n\nAgainst a reference of {} spp and {} bounces per scene (scenes without \
             emitters get the shadow rays' point light); wall = the render call after a one-sample warm-up.\n\n{}",
            args.reference_spp,
            args.reference_bounces,
            images::images_table(&image_cells)
        );
        let targets = args
            .image_targets
            .split(',')
            .map(|t| match t.trim().parse::<f64>() {
                Ok(x) if x > 0.0 && x.is_finite() => Ok(x / 100.0),
                _ => bail!("--image-targets: '{}' is not a positive percentage", t.trim()),
            })
            .collect::<Result<Vec<_>>>()?;
        println!(
            "## Convergence\n\nPer configuration, over its spp sweep: RMSE ∝ spp^-exponent (least squares on \
             the logs; off emitters: the pixels whose first hit and its 8 neighbours' are not emissive), and \
             the wall time to reach each RMSE from the fit of ln RMSE on ln wall time.\n\n{}",
            images::convergence_table(&images::convergence(&image_cells, &targets))
        );
        images::write_images_csv(&args.images_csv, &image_cells)?;
        let png = args.plots.join("bench-images-time-error.png");
        images::plot_images(&png, &image_cells, &format!("{title}: rendered images"))?;
        plots.push(args.images_csv.clone());
        plots.push(png);
    }
    eprintln!("wrote {}", plots.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "));
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
        .map(|p| match choice::<PrimaryKind>(p.trim()) {
            Some(kind) => Ok(Primary::from(kind)),
            None => bail!("--image-primary: unknown '{}' ({})", p.trim(), choices::<PrimaryKind>()),
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
        ao_samples: args.image_ao,
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
