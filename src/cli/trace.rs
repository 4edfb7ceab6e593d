//! `kdtrace trace`: a ray file in, a hit file (and per-ray counters) out.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};

use kdtrace::kdtree::traverse::Counters;
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::scene::Scene;
use kdtrace::trace::{Backend, RayOrder, TraceOptions, TracePipelines, Tracer};
use kdtrace::traversal::Traversal;
use kdtrace::twolevel::TwoLevelTracer;

use super::args::{TraversalArgs, TreeArgs};
use super::common::{cached_context, load_and_build, trace_bar, Stages};
use super::Unfinished;

#[derive(clap::Args)]
pub struct TraceArgs {
    /// OBJ scene file.
    pub scene: PathBuf,
    /// Ray file: 32-byte records ox oy oz tmin dx dy dz tmax (f32, little-endian).
    pub rays: PathBuf,
    /// Hit file to write: 16-byte records t prim_id u v.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub traversal: TraversalArgs,
    #[command(flatten)]
    pub tree: TreeArgs,
    /// Any-hit (shadow-ray) mode: report the first occluder found, not the closest hit.
    #[arg(long)]
    pub any_hit: bool,
    /// Write per-ray counters (nodes, leaves, triangles, restarts, steps, drops) to this CSV.
    #[arg(long)]
    pub counters: Option<PathBuf>,
    /// Trace in a coherent order (direction octant, origin Morton code, direction cell)
    /// instead of the file's; hits and counters are still written in file order.
    #[arg(long)]
    pub sort: bool,
    /// Sort the rays on the device before tracing (`RayOrder::Coherent`: direction
    /// octant, then origin cell; inside the timed dispatches); hits and counters are
    /// still written in file order. kd-tree backend only.
    #[arg(long)]
    pub device_order: bool,
    /// Print the wall time of every stage (rays, OBJ, kd-tree, device, upload,
    /// pipelines, trace, write) on stderr.
    #[arg(long)]
    pub timings: bool,
    /// Trace two-level (`kdtrace::twolevel`): a glTF file's meshes each once with
    /// their own kd-tree, placed by their nodes (an OBJ file: one instance).
    /// Hits keep the scene-order `prim_id` of the flattened scene. Variants
    /// stack, restart, push-down and the short stacks, single rays; no counters,
    /// --sort or --device-order; kd-tree backend.
    #[arg(long)]
    pub two_level: bool,
}

/// `kdtrace trace`: traces the ray file and writes the hits (file order), with
/// the device and its pipelines coming up while the scene loads.
pub fn trace(args: TraceArgs) -> Result<()> {
    let traversal = args.traversal.parse(args.any_hit)?;
    let backend = args.traversal.backend;
    let label = if backend == Backend::KdTree { traversal.variant.name() } else { backend.name() };
    let mut stages = Stages::new(args.timings);
    let rays = kdtrace::io::read_rays(&args.rays)?;
    stages.mark("read the rays");
    if args.two_level {
        return trace_two_level(&args, traversal, &rays, stages);
    }
    let order = if args.device_order { RayOrder::Coherent } else { RayOrder::AsGiven };
    let options = TraceOptions { traversal, counters: args.counters.is_some(), order };
    // The device and the pipelines come up on another thread while the scene
    // loads and its tree builds.
    let (device, loaded) = std::thread::scope(|scope| {
        let device = scope.spawn(|| -> Result<_> {
            let start = Instant::now();
            let ctx = cached_context(&[backend])?;
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
    if let Some(n) = result.careful_rays {
        print_careful(n, rays.len());
    }
    stages.print();
    match Unfinished::from_hits(&result.hits) {
        Some(u) => Err(u.into()),
        None => Ok(()),
    }
}

/// The careful pass's share of the rays.
fn print_careful(listed: u64, rays: usize) {
    eprintln!(
        "careful pass: {listed} of {rays} rays ({:.2} %) traced again by the robust careful pass",
        100.0 * listed as f64 / rays.max(1) as f64
    );
}

/// `kdtrace trace --two-level`.
fn trace_two_level(args: &TraceArgs, traversal: Traversal, rays: &[kdtrace::Ray], mut stages: Stages) -> Result<()> {
    if args.counters.is_some() || args.sort || args.device_order || args.traversal.backend != Backend::KdTree {
        anyhow::bail!("--two-level traces with the kd-tree backend, without --counters, --sort or --device-order");
    }
    let config = args.tree.builder.apply(BuildConfig::default())?;
    let (scene, ranges) = Scene::load_two_level(&args.scene, &config)?;
    stages.mark("load the scene and build its trees");
    let ctx = cached_context(&[Backend::KdTree])?;
    let mut tracer = TwoLevelTracer::new(&ctx, &scene)?;
    tracer.prepare(traversal)?;
    stages.mark("upload the scene and compile");
    let result = tracer.trace_stats(rays, 0xff, traversal)?;
    stages.mark("trace");
    // Back to the flattened scene's numbering.
    let hits: Vec<kdtrace::Hit> = result
        .hits
        .iter()
        .map(|h| {
            let prim_id = match ranges.get(h.instance_index as usize) {
                Some(r) if h.is_hit() => r.first_prim + h.prim_index,
                _ => h.prim_index,
            };
            kdtrace::Hit { t: h.t, prim_id, u: h.u, v: h.v }
        })
        .collect();
    kdtrace::io::write_hits(&args.output, &hits)?;
    stages.mark("write the hits");
    let hit_count = hits.iter().filter(|h| h.is_hit()).count();
    eprintln!(
        "{} rays, {hit_count} hits on {}: {} geometries, {} instances, {:.2} MiB on the device",
        rays.len(),
        ctx.info.name,
        scene.geometries().len(),
        scene.instance_count(),
        tracer.device_bytes() as f64 / (1 << 20) as f64
    );
    if let Some(s) = result.gpu_seconds.filter(|&s| s > 0.0) {
        eprintln!(
            "two-level traversal ({}): {:.3} ms GPU = {:.2} M rays/s",
            traversal.variant.name(),
            s * 1e3,
            rays.len() as f64 / s / 1e6
        );
    }
    if let Some(n) = result.careful_rays {
        print_careful(n, rays.len());
    }
    stages.print();
    match Unfinished::from_hits(&hits) {
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
