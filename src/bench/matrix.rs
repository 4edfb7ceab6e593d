//! The benchmark matrix of `kdtrace bench`: per scene, builder settings ×
//! traversals (variant, short-stack size, packet width, robustness) × ray kinds
//! on the Vulkan device, the same rays through the multithreaded CPU twin and,
//! with the `embree` feature, through Intel Embree. Every cell is timed after a
//! warm-up over several repetitions and judged against the exact reference on
//! a sample of its rays, so each speed comes with its error.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use crate::bench::rays::{secondary_rays, RayKind};
use crate::error::{Error, Result};
use crate::exact::Exact;
use crate::geom::{Hit, Ray};
use crate::gpu::GpuContext;
use crate::kdtree::links::TreeLinks;
use crate::kdtree::traverse::{trace_ray, Counters, SceneRef};
use crate::kdtree::{BuildConfig, Builder, KdTree};
use crate::scene::{Camera, Scene};
use crate::stress::{exact_answers, judge_with, Tally};
use crate::trace::{RayOrder, TraceOptions, Tracer};
use crate::traversal::{Traversal, Variant};

/// The builder settings the matrix knows, by name: `sweep` is `default`'s
/// costs with the exact sweep at every node (`default` bins the large ones).
pub const BUILDERS: [(&str, BuildConfig); 4] = [
    ("default", BuildConfig::TUNED),
    ("sweep", BuildConfig { builder: Builder::Sweep, ..BuildConfig::TUNED }),
    ("pbrt-v3", BuildConfig::PBRT_V3),
    ("wald-havran", BuildConfig::WALD_HAVRAN),
];

/// The builder settings named `name` (`default`, `sweep`, `pbrt-v3`, `wald-havran`).
pub fn builder_config(name: &str) -> Result<BuildConfig> {
    BUILDERS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, c)| *c)
        .ok_or_else(|| Error::InvalidInput(format!("unknown builder '{name}' (default, sweep, pbrt-v3, wald-havran)")))
}

/// Who traced a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Backend {
    /// kdtrace's kernels on the Vulkan device (GPU timestamps).
    Gpu,
    /// kdtrace's CPU twin, rayon over rays (wall clock).
    Cpu,
    /// Intel Embree 3, `rtcIntersect1`/`rtcOccluded1`, one thread or rayon over rays (wall clock).
    Embree,
    /// The driver's ray query on the Vulkan device ([`crate::trace::Backend::RayQuery`]:
    /// its own BVH, GPU timestamps), the peer on any device with `VK_KHR_ray_query`.
    RayQuery,
}

impl Backend {
    /// The name in tables and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Gpu => "kdtrace-gpu",
            Backend::Cpu => "kdtrace-cpu",
            Backend::Embree => "embree",
            Backend::RayQuery => "vk-ray-query",
        }
    }

    /// True for the backends that run on the Vulkan device (no CPU threads).
    pub fn on_device(self) -> bool {
        matches!(self, Backend::Gpu | Backend::RayQuery)
    }
}

/// What the matrix runs.
#[derive(Clone, Debug)]
pub struct MatrixOptions {
    /// Camera rays: image size.
    pub width: u32,
    /// Camera rays: image size.
    pub height: u32,
    /// Random rays.
    pub random: usize,
    /// Timed repetitions per cell, after one warm-up; median, min and max reported.
    pub repeat: usize,
    /// Rays per cell judged against the exact reference (evenly spaced).
    pub reference_sample: usize,
    /// GPU traversals (closest-hit settings; shadow rays run them any-hit).
    pub traversals: Vec<Traversal>,
    /// The orders the kd-tree GPU cells trace each batch in (each a cell).
    pub orders: Vec<RayOrder>,
    /// CPU-twin traversals (single rays; packet width ignored).
    pub cpu_traversals: Vec<Traversal>,
    /// Builder settings, by name.
    pub builders: Vec<String>,
    /// Ray kinds.
    pub kinds: Vec<RayKind>,
    /// Run Embree too (needs the `embree` feature).
    pub embree: bool,
    /// Run the driver's ray query too (a device with `VK_KHR_ray_query`): one
    /// cell per ray kind, builder `driver-bvh`, no traversal settings or counters.
    pub ray_query: bool,
    /// Seed of the random and diffuse rays.
    pub seed: u64,
}

/// One measured cell.
#[derive(Clone, Debug)]
pub struct Cell {
    /// Scene name (file stem).
    pub scene: String,
    /// Ray kind.
    pub kind: RayKind,
    /// Who traced it.
    pub backend: Backend,
    /// CPU threads (0 for the GPU).
    pub threads: usize,
    /// Builder settings name, or Embree's (`embree-bvh`, `embree-bvh-robust`), or
    /// `driver-bvh` for the ray query.
    pub builder: String,
    /// The traversal (`None` for Embree and the ray query); `any_hit` set for shadow rays.
    pub traversal: Option<Traversal>,
    /// The order the batch was traced in (kd-tree GPU cells; `AsGiven` elsewhere).
    pub order: RayOrder,
    /// Rays traced.
    pub rays: usize,
    /// Seconds to build the acceleration structure (kd-tree, or Embree's commit,
    /// or for the ray query the sort, upload and driver's build together).
    pub build_seconds: f64,
    /// Seconds to upload the scene to the device (GPU), 0 elsewhere.
    pub upload_seconds: f64,
    /// Seconds of `Tracer::prepare` for this cell: the pipeline compile on first
    /// use (~0 when cached), plus the side-buffer upload the first time
    /// `backtrack`/`ropes` run; for the CPU twin, building the side buffers.
    pub pipeline_seconds: f64,
    /// Traversal seconds over the repetitions: median, min, max (GPU timestamps
    /// around the dispatches; CPU wall clock).
    pub trace_seconds: [f64; 3],
    /// Median seconds of the whole call: for the GPU with ray upload, submission,
    /// wait and readback.
    pub wall_seconds: f64,
    /// Mean nodes, leaves and triangle tests per ray (`None` for Embree and the ray query).
    pub counters: Option<[f64; 3]>,
    /// Verdicts on the judged sample.
    pub tally: Tally,
    /// Rays of the whole cell (not only the sample) that did not finish
    /// traversal (`PRIM_INCOMPLETE`; 0 for Embree; for the ray query, rays it
    /// cannot pass to the driver).
    pub incomplete: usize,
    /// The baseline's median trace time over this cell's (same scene and rays); > 1 is faster.
    pub speedup: f64,
}

impl Cell {
    /// Rays per second at the median trace time.
    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.trace_seconds[0]
    }

    /// Rays of the sample that do not agree with the exact reference.
    pub fn disagreeing(&self) -> usize {
        self.tally.rays - self.tally.agreeing()
    }

    /// The settings as one label: backend, traversal, packet width, robustness, builder.
    pub fn label(&self) -> String {
        let mut s = self.backend.name().to_string();
        if let Some(t) = &self.traversal {
            s += &format!(" {}", traversal_name(t));
        }
        if self.order != RayOrder::AsGiven {
            s += &format!(" {}-order", self.order.name());
        }
        if !self.backend.on_device() {
            s += &format!(" {}t", self.threads);
        }
        s += &format!(" {}", self.builder);
        s
    }
}

/// `name[:stack-size][ W<width>][/plain]`, as `--traversals` takes it.
pub fn traversal_name(t: &Traversal) -> String {
    let mut s = t.variant.name().to_string();
    if t.variant.uses_short_stack() {
        s += &format!(":{}", t.stack_size);
    }
    if t.uses_packets() {
        s += &format!(" W{}", t.packet_width);
    }
    if !t.robust {
        s += "/plain";
    }
    s
}

/// A batch of one kind, its evenly spaced sample and the exact answers there.
struct Batch {
    kind: RayKind,
    rays: Vec<Ray>,
    sample: Vec<usize>,
    exact: Vec<Exact>,
}

impl Batch {
    fn judge(&self, triangles: &[[glam::Vec3; 3]], hits: &[Hit]) -> Tally {
        let rays: Vec<Ray> = self.sample.iter().map(|&i| self.rays[i]).collect();
        let hits: Vec<Hit> = self.sample.iter().map(|&i| hits[i]).collect();
        judge_with(triangles, &rays, &hits, &self.exact, self.kind.any_hit())
    }
}

fn mean_counters(counters: &[Counters]) -> [f64; 3] {
    let n = counters.len().max(1) as f64;
    let sum = |f: fn(&Counters) -> u32| counters.iter().map(|c| f(c) as f64).sum::<f64>() / n;
    [sum(|c| c.nodes), sum(|c| c.leaves), sum(|c| c.triangles)]
}

/// Times → [median (the lower one for an even count), min, max].
fn spread(mut times: Vec<f64>) -> [f64; 3] {
    times.sort_by(f64::total_cmp);
    [times[(times.len() - 1) / 2], times[0], times[times.len() - 1]]
}

/// Runs `f` once to warm up and `repeat` times timed; returns its last result,
/// the [median, min, max] wall seconds.
fn timed<T>(repeat: usize, mut f: impl FnMut() -> Result<T>) -> Result<(T, [f64; 3])> {
    let mut last = f()?;
    let mut times = Vec::new();
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        last = f()?;
        times.push(start.elapsed().as_secs_f64());
    }
    Ok((last, spread(times)))
}

/// The rays of every kind in `options.kinds` for `scene`: camera rays in Morton
/// order, secondary rays from the camera rays' first hits (CPU twin, `stack`,
/// over `tree`), random rays; with the sample judged and its exact answers.
fn make_batches(scene: &Scene, tree: &KdTree, camera: &Camera, options: &MatrixOptions) -> Vec<Batch> {
    let camera_rays = crate::render::camera_rays_morton(camera, options.width, options.height).0;
    let needs_hits = options.kinds.iter().any(|k| k.is_secondary());
    let first_hits: Vec<Hit> = if needs_hits {
        let view = SceneRef::new(tree, &scene.triangles);
        camera_rays.par_iter().map(|r| trace_ray(&view, r, Variant::Stack).0).collect()
    } else {
        Vec::new()
    };
    options
        .kinds
        .iter()
        .map(|&kind| {
            let rays = match kind {
                RayKind::Camera => camera_rays.clone(),
                RayKind::Random => crate::raygen::random_rays(&scene.bounds, options.random, options.seed),
                RayKind::Hard => crate::stress::Category::ALL
                    .iter()
                    .flat_map(|&c| {
                        let per = crate::bench::rays::HARD_PER_CATEGORY;
                        crate::stress::stress_rays(c, &scene.triangles, tree, per, options.seed)
                    })
                    .collect(),
                _ => secondary_rays(kind, &scene.triangles, &scene.bounds, &camera_rays, &first_hits, options.seed),
            };
            let count = options.reference_sample.min(rays.len());
            let sample: Vec<usize> = (0..count).map(|i| i * rays.len() / count.max(1)).collect();
            let sampled: Vec<Ray> = sample.iter().map(|&i| rays[i]).collect();
            let exact = exact_answers(&scene.triangles, &sampled);
            Batch { kind, rays, sample, exact }
        })
        .collect()
}

/// Runs the matrix on one scene. `ctx`: the Vulkan device (`None`: CPU peers only).
/// `progress` is told what runs.
pub fn run_scene(
    ctx: Option<&Arc<GpuContext>>,
    name: &str,
    scene: &Scene,
    camera: &Camera,
    options: &MatrixOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<Cell>> {
    if options.embree && !cfg!(feature = "embree") {
        return Err(Error::InvalidInput(
            "Embree was asked for, but kdtrace was built without --features embree".into(),
        ));
    }
    if options.kinds.is_empty() || options.builders.is_empty() {
        return Err(Error::InvalidInput("the matrix needs at least one ray kind and one builder".into()));
    }
    for t in options.traversals.iter().chain(&options.cpu_traversals) {
        t.validate()?;
    }
    let configs: Vec<(String, BuildConfig)> =
        options.builders.iter().map(|b| Ok((b.clone(), builder_config(b)?))).collect::<Result<_>>()?;
    progress("rays and exact answers");
    let first_tree = KdTree::build(&scene.triangles, &configs[0].1);
    let batches = make_batches(scene, &first_tree, camera, options);
    drop(first_tree);
    let threads = rayon::current_num_threads();
    let cell = |kind: RayKind, backend: Backend, builder: &str, rays: usize| Cell {
        scene: name.to_string(),
        kind,
        backend,
        threads: if backend.on_device() { 0 } else { threads },
        builder: builder.to_string(),
        traversal: None,
        order: RayOrder::AsGiven,
        rays,
        build_seconds: 0.0,
        upload_seconds: 0.0,
        pipeline_seconds: 0.0,
        trace_seconds: [f64::NAN; 3],
        wall_seconds: f64::NAN,
        counters: None,
        tally: Tally::default(),
        incomplete: 0,
        speedup: f64::NAN,
    };
    let mut cells = Vec::new();
    let mut tracer: Option<Tracer> = None;
    for (builder, config) in &configs {
        progress(&format!("building the kd-tree ({builder})"));
        let tree = KdTree::build(&scene.triangles, config);
        let build_seconds = tree.stats.build_seconds;

        // The Vulkan device.
        if let Some(ctx) = ctx {
            let start = Instant::now();
            match tracer.as_mut() {
                Some(t) => t.replace_scene(&tree, &scene.triangles)?,
                None => tracer = Some(Tracer::new(ctx, &tree, &scene.triangles)?),
            }
            let upload_seconds = start.elapsed().as_secs_f64();
            let tracer = tracer.as_mut().expect("made above");
            for &base in &options.traversals {
                for (batch, &order) in batches
                    .iter()
                    .filter(|b| !b.rays.is_empty())
                    .flat_map(|b| options.orders.iter().map(move |o| (b, o)))
                {
                    let traversal = Traversal { any_hit: batch.kind.any_hit(), ..base };
                    progress(&format!("{builder} {} {} rays {order:?}", traversal_name(&traversal), batch.kind));
                    let plain = TraceOptions { traversal, counters: false, order };
                    let start = Instant::now();
                    tracer.prepare(&plain)?;
                    let pipeline_seconds = start.elapsed().as_secs_f64();
                    let counted = tracer.trace(&batch.rays, &TraceOptions { traversal, counters: true, order })?;
                    let mut gpu_times = Vec::new();
                    let (result, wall) = timed(options.repeat, || {
                        let r = tracer.trace(&batch.rays, &plain)?;
                        gpu_times.push(r.gpu_seconds.unwrap_or(f64::NAN));
                        Ok(r)
                    })?;
                    gpu_times.remove(0); // the warm-up
                    cells.push(Cell {
                        traversal: Some(traversal),
                        order,
                        build_seconds,
                        upload_seconds,
                        pipeline_seconds,
                        trace_seconds: spread(gpu_times),
                        wall_seconds: wall[0],
                        counters: counted.counters.as_deref().map(mean_counters),
                        tally: batch.judge(&scene.triangles, &result.hits),
                        incomplete: result.incomplete().len(),
                        ..cell(batch.kind, Backend::Gpu, builder, batch.rays.len())
                    });
                }
            }
        }

        // The CPU twin, rayon over rays.
        for &base in &options.cpu_traversals {
            let base = Traversal { packet_width: 1, subgroup_size: None, ..base };
            let start = Instant::now();
            let links = base.variant.uses_links().then(|| TreeLinks::new(&tree.nodes, tree.bounds));
            let links_seconds = start.elapsed().as_secs_f64();
            let view = SceneRef::new(&tree, &scene.triangles);
            let view = match &links {
                Some(l) => view.with_links(l),
                None => view,
            };
            for batch in batches.iter().filter(|b| !b.rays.is_empty()) {
                let traversal = Traversal { any_hit: batch.kind.any_hit(), ..base };
                progress(&format!("{builder} CPU {} {} rays", traversal_name(&traversal), batch.kind));
                let (traced, wall) = timed(options.repeat, || {
                    Ok(batch.rays.par_iter().map(|r| trace_ray(&view, r, traversal)).collect::<Vec<_>>())
                })?;
                let (hits, counters): (Vec<Hit>, Vec<Counters>) = traced.into_iter().unzip();
                cells.push(Cell {
                    traversal: Some(traversal),
                    build_seconds,
                    pipeline_seconds: links_seconds,
                    trace_seconds: wall,
                    wall_seconds: wall[0],
                    counters: Some(mean_counters(&counters)),
                    tally: batch.judge(&scene.triangles, &hits),
                    incomplete: crate::trace::incomplete_rays(&hits).len(),
                    ..cell(batch.kind, Backend::Cpu, builder, batch.rays.len())
                });
            }
        }
    }
    drop(tracer);

    // The driver's ray query: its own acceleration structure, one cell per ray kind.
    if let (Some(ctx), true) = (ctx, options.ray_query) {
        cells.extend(run_ray_query(ctx, scene, &batches, options.repeat, &mut progress, |kind, rays| {
            cell(kind, Backend::RayQuery, "driver-bvh", rays)
        })?);
    }

    #[cfg(feature = "embree")]
    if options.embree {
        cells.extend(run_embree(&scene.triangles, &batches, options.repeat, &mut progress, |kind, b, rays| {
            cell(kind, Backend::Embree, b, rays)
        })?);
    }

    set_speedups(&mut cells);
    Ok(cells)
}

/// The driver's ray query on every batch, timed as the GPU cells are (GPU
/// timestamps, median after a warm-up).
fn run_ray_query(
    ctx: &Arc<GpuContext>,
    scene: &Scene,
    batches: &[Batch],
    repeat: usize,
    progress: &mut impl FnMut(&str),
    cell: impl Fn(RayKind, usize) -> Cell,
) -> Result<Vec<Cell>> {
    progress("ray query: building the driver's acceleration structures");
    let start = Instant::now();
    let mut tracer = Tracer::ray_query(ctx, &scene.triangles)?;
    let build_seconds = start.elapsed().as_secs_f64();
    let mut cells = Vec::new();
    for batch in batches.iter().filter(|b| !b.rays.is_empty()) {
        progress(&format!("ray query {} rays", batch.kind));
        let options =
            TraceOptions::new(Traversal { any_hit: batch.kind.any_hit(), ..Traversal::closest(Variant::Stack) });
        let start = Instant::now();
        tracer.prepare(&options)?;
        let pipeline_seconds = start.elapsed().as_secs_f64();
        let mut gpu_times = Vec::new();
        let (result, wall) = timed(repeat, || {
            let r = tracer.trace(&batch.rays, &options)?;
            gpu_times.push(r.gpu_seconds.unwrap_or(f64::NAN));
            Ok(r)
        })?;
        gpu_times.remove(0); // the warm-up
        cells.push(Cell {
            build_seconds,
            pipeline_seconds,
            trace_seconds: spread(gpu_times),
            wall_seconds: wall[0],
            tally: batch.judge(&scene.triangles, &result.hits),
            incomplete: result.incomplete().len(),
            ..cell(batch.kind, batch.rays.len())
        });
    }
    Ok(cells)
}

/// Embree, robust off and on, one thread and rayon over rays.
#[cfg(feature = "embree")]
fn run_embree(
    triangles: &[[glam::Vec3; 3]],
    batches: &[Batch],
    repeat: usize,
    progress: &mut impl FnMut(&str),
    cell: impl Fn(RayKind, &str, usize) -> Cell,
) -> Result<Vec<Cell>> {
    use crate::bench::embree::EmbreeScene;
    let mut cells = Vec::new();
    for robust in [false, true] {
        let builder = if robust { "embree-bvh-robust" } else { "embree-bvh" };
        progress(&format!("Embree: building ({builder})"));
        let start = Instant::now();
        let embree = EmbreeScene::new(triangles, robust)?;
        let build_seconds = start.elapsed().as_secs_f64();
        for batch in batches.iter().filter(|b| !b.rays.is_empty()) {
            // Timed as a renderer would call it: rtcOccluded1 (only the flag, kept in
            // `prim_id`) for shadow rays, rtcIntersect1 for the others.
            let one = |r: &Ray| {
                if batch.kind.any_hit() {
                    Hit { prim_id: embree.occluded(r) as u32, ..Hit::MISS }
                } else {
                    embree.intersect(r)
                }
            };
            for threads in [1, rayon::current_num_threads()] {
                if robust && threads == 1 {
                    continue;
                }
                progress(&format!("Embree {builder} {threads}t {} rays", batch.kind));
                let (_, wall) = timed(repeat, || {
                    Ok(if threads == 1 {
                        batch.rays.iter().map(one).collect::<Vec<_>>()
                    } else {
                        batch.rays.par_iter().map(one).collect::<Vec<_>>()
                    })
                })?;
                // Judged on the sample, any-hit answers with their occluder.
                let mut hits = vec![Hit::MISS; batch.rays.len()];
                for &i in &batch.sample {
                    let r = &batch.rays[i];
                    hits[i] = if batch.kind.any_hit() { embree.any_hit_answer(r) } else { embree.intersect(r) };
                }
                cells.push(Cell {
                    threads,
                    build_seconds,
                    trace_seconds: wall,
                    wall_seconds: wall[0],
                    tally: batch.judge(triangles, &hits),
                    ..cell(batch.kind, builder, batch.rays.len())
                });
            }
        }
    }
    Ok(cells)
}

/// The baseline of each scene and ray kind, as an index into `cells`:
/// multithreaded Embree (robust off) when present, else the CPU twin's first
/// traversal on the first builder.
pub fn baselines(cells: &[Cell]) -> HashMap<(String, RayKind), usize> {
    let rank = |c: &Cell| match c.backend {
        Backend::Embree if c.builder == "embree-bvh" => 1 + c.threads,
        Backend::Cpu => 1,
        _ => 0,
    };
    let mut map: HashMap<(String, RayKind), usize> = HashMap::new();
    for (i, c) in cells.iter().enumerate() {
        let key = (c.scene.clone(), c.kind);
        let better = match map.get(&key) {
            None => rank(c) > 0,
            Some(&j) => rank(c) > rank(&cells[j]),
        };
        if better {
            map.insert(key, i);
        }
    }
    map
}

fn set_speedups(cells: &mut [Cell]) {
    let base = baselines(cells);
    let times: Vec<f64> = cells
        .iter()
        .map(|c| base.get(&(c.scene.clone(), c.kind)).map_or(f64::NAN, |&b| cells[b].trace_seconds[0]))
        .collect();
    for (c, b) in cells.iter_mut().zip(times) {
        c.speedup = b / c.trace_seconds[0];
    }
}

/// A comma-separated list of numbers (`--stack-sizes 1,3,8`).
pub fn parse_list<T: std::str::FromStr>(what: &str, list: &str) -> Result<Vec<T>> {
    let items: Vec<T> = list
        .split(',')
        .map(|s| s.trim().parse().map_err(|_| Error::InvalidInput(format!("{what}: '{s}' is not a valid value"))))
        .collect::<Result<_>>()?;
    if items.is_empty() {
        return Err(Error::InvalidInput(format!("{what}: the list is empty")));
    }
    Ok(items)
}

/// Expands a traversal list into the matrix's traversals. Items are `all` (every
/// variant) or `name[:stack-size][/plain]`. An item without `:stack-size` of a
/// short-stack variant runs every size of `stack_sizes`; one without `/plain`
/// runs every robustness level of `robust` (`true` = on); variants with packet
/// versions run every width of `packet_widths`, the others single rays.
pub fn expand_traversals(
    list: &str,
    stack_sizes: &[u32],
    packet_widths: &[u32],
    robust: &[bool],
    subgroup_size: Option<u32>,
) -> Result<Vec<Traversal>> {
    let mut out = Vec::new();
    for item in list.split(',').map(str::trim) {
        let (rest, levels) = match item.strip_suffix("/plain") {
            Some(rest) => (rest, vec![false]),
            None => (item, robust.to_vec()),
        };
        let (name, sizes) = match rest.split_once(':') {
            Some((n, s)) => {
                let size = s
                    .parse::<u32>()
                    .map_err(|_| Error::InvalidInput(format!("traversal '{item}': '{s}' is not a short-stack size")))?;
                (n, Some(vec![size]))
            }
            None => (rest, None),
        };
        let variants: Vec<Variant> = if name == "all" { Variant::ALL.to_vec() } else { vec![name.parse()?] };
        for variant in variants {
            let sizes = match (&sizes, variant.uses_short_stack()) {
                (Some(s), _) => s.clone(),
                (None, true) => stack_sizes.to_vec(),
                (None, false) => vec![3],
            };
            let widths = if variant.uses_links() { vec![1] } else { packet_widths.to_vec() };
            for &robust in &levels {
                for &stack_size in &sizes {
                    for &packet_width in &widths {
                        let t = Traversal {
                            stack_size,
                            packet_width,
                            subgroup_size,
                            robust,
                            ..Traversal::closest(variant)
                        };
                        t.validate()?;
                        if !out.contains(&t) {
                            out.push(t);
                        }
                    }
                }
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn traversal_lists_expand_over_the_axes() {
        let all = expand_traversals("all", &[1, 3], &[1, 4], &[true, false], None).unwrap();
        // stack, restart, push-down: 2 widths; the short stacks: 2 sizes × 2 widths; backtrack, ropes: 1.
        assert_eq!(all.len(), 2 * (3 * 2 + 2 * 2 * 2 + 2));
        let some = expand_traversals("stack/plain,short-stack:8,ropes", &[1, 3], &[1], &[true], None).unwrap();
        let names: Vec<String> = some.iter().map(traversal_name).collect();
        assert_eq!(names, ["stack/plain", "short-stack:8", "ropes"]);
        assert!(expand_traversals("stack:x", &[1], &[1], &[true], None).is_err());
        assert!(expand_traversals("short-stack:99", &[1], &[1], &[true], None).is_err());
        assert!(expand_traversals("nope", &[1], &[1], &[true], None).is_err());
        assert!(expand_traversals("stack", &[1], &[3], &[true], None).is_err());
        assert!(parse_list::<u32>("--stack-sizes", "1,a").is_err());
    }
}
