//! `kdtrace verify`: trace hard rays (or a ray file) and judge every answer
//! against the exact reference.

use std::path::PathBuf;

use anyhow::{bail, Result};

use kdtrace::kdtree::traverse::Counters;
use kdtrace::scene::Scene;
use kdtrace::trace::{Backend, TraceOptions, Tracer};

use super::args::{TraversalArgs, TreeArgs};
use super::common::{build_tree, cached_context, spinner};
use super::{Unfinished, EXIT_SERIOUS};

#[derive(clap::Args)]
pub struct VerifyArgs {
    /// OBJ scene file.
    pub scene: PathBuf,
    /// A ray file to verify instead of the stress categories.
    pub rays: Option<PathBuf>,
    #[command(flatten)]
    pub traversal: TraversalArgs,
    #[command(flatten)]
    pub tree: TreeArgs,
    /// Verify any-hit (shadow) answers instead of closest hits.
    #[arg(long)]
    pub any_hit: bool,
    /// Trace with the CPU twin of the traversal instead of the GPU.
    #[arg(long)]
    pub cpu: bool,
    /// Rays per stress category.
    #[arg(long, default_value_t = 2000)]
    pub count: usize,
    /// Seed of the stress rays.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Scale the scene by this factor first (e.g. 1e-4 or 1e5).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f32,
    /// Print up to this many seriously wrong rays per category.
    #[arg(long, default_value_t = 3)]
    pub show: usize,
    /// Also print up to `--show` disagreeing rays per category that are not serious.
    #[arg(long)]
    pub show_all: bool,
}

/// `kdtrace verify`: traces the stress categories (or a ray file) and judges
/// every answer against the exact reference.
pub fn verify(args: VerifyArgs) -> Result<()> {
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
        let ctx = cached_context(&[backend])?;
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
                let result = tracer.trace(rays, &TraceOptions { counters: counted, ..TraceOptions::new(traversal) })?;
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
