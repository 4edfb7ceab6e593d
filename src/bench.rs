//! Variant comparison: times each traversal with GPU timestamps, collects its
//! per-ray counters and checks its hits against the `stack` baseline and the
//! float64 reference, so every speed figure comes with its error.

use crate::geom::{Hit, Ray};
use crate::kdtree::traverse::{Counters, Traversal};
use crate::reference::{agrees, Agreement};
use crate::scene::Scene;
use crate::trace::{TraceOptions, Tracer};
use crate::Result;

/// One measured traversal on one batch of rays.
#[derive(Clone, Debug)]
pub struct BenchRow {
    /// The traversal measured.
    pub traversal: Traversal,
    /// Rays in the batch.
    pub rays: usize,
    /// Median GPU seconds over the timed repetitions (after one warm-up).
    pub seconds_median: f64,
    /// Fastest timed repetition, GPU seconds.
    pub seconds_min: f64,
    /// Slowest timed repetition, GPU seconds.
    pub seconds_max: f64,
    /// Mean node fetches per ray ([`Counters::nodes`]).
    pub nodes: f64,
    /// Mean leaves visited per ray ([`Counters::leaves`]).
    pub leaves: f64,
    /// Mean ray/triangle tests per ray ([`Counters::triangles`]).
    pub triangles: f64,
    /// Mean restarts, backtracks or rope hops per ray ([`Counters::restarts`]).
    pub restarts: f64,
    /// Mean short-stack drops per ray ([`Counters::drops`]).
    pub drops: f64,
    /// Rays whose hit differs from the first traversal's (prim_id, or t beyond 1e-6 relative).
    pub differ_from_baseline: usize,
    /// Rays of the reference sample that disagree with the float64 reference, and the sample size.
    pub reference_errors: usize,
    /// Rays checked against the float64 reference (0 for any-hit traversals).
    pub reference_sample: usize,
}

impl BenchRow {
    /// Rays per second at the median GPU time.
    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.seconds_median
    }
}

fn mean(counters: &[Counters], f: impl Fn(&Counters) -> u32) -> f64 {
    counters.iter().map(|c| f(c) as f64).sum::<f64>() / counters.len().max(1) as f64
}

fn same_hit(a: &Hit, b: &Hit) -> bool {
    a.prim_id == b.prim_id && (a.t == b.t || ((a.t - b.t).abs() <= 1e-6 * a.t.abs().max(b.t.abs())))
}

/// Times and checks each traversal in `traversals` on `rays`. The first one is the
/// baseline for `differ_from_baseline`; `reference_sample` rays (evenly spaced) are
/// checked against the float64 brute force.
pub fn compare_traversals(
    tracer: &mut Tracer,
    scene: &Scene,
    rays: &[Ray],
    traversals: &[Traversal],
    repetitions: usize,
    reference_sample: usize,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRow>> {
    let mut rows = Vec::new();
    let mut baseline: Option<Vec<Hit>> = None;
    let stride = (rays.len() / reference_sample.max(1)).max(1);
    for &traversal in traversals {
        progress(&format!("{} (counters)", traversal.variant));
        let counted = tracer.trace(rays, &TraceOptions { traversal, counters: true })?;
        let counters = counted.counters.unwrap_or_default();
        progress(&format!("{} (timing)", traversal.variant));
        let options = TraceOptions { traversal, counters: false };
        tracer.trace(rays, &options)?; // warm-up: pipeline compile, caches
        let mut times = Vec::new();
        let mut hits = Vec::new();
        for _ in 0..repetitions.max(1) {
            let result = tracer.trace(rays, &options)?;
            times.push(result.gpu_seconds.unwrap_or(f64::NAN));
            hits = result.hits;
        }
        times.sort_by(f64::total_cmp);
        let differ = match &baseline {
            Some(base) => base.iter().zip(&hits).filter(|(a, b)| !same_hit(a, b)).count(),
            None => 0,
        };
        let mut reference_errors = 0;
        let mut sample = 0;
        if !traversal.any_hit {
            for i in (0..rays.len()).step_by(stride).take(reference_sample) {
                sample += 1;
                if let Agreement::Disagree(_) = agrees(&scene.triangles, &rays[i], &hits[i]) {
                    reference_errors += 1;
                }
            }
        }
        rows.push(BenchRow {
            traversal,
            rays: rays.len(),
            seconds_median: times[times.len() / 2],
            seconds_min: times[0],
            seconds_max: times[times.len() - 1],
            nodes: mean(&counters, |c| c.nodes),
            leaves: mean(&counters, |c| c.leaves),
            triangles: mean(&counters, |c| c.triangles),
            restarts: mean(&counters, |c| c.restarts),
            drops: mean(&counters, |c| c.drops),
            differ_from_baseline: differ,
            reference_errors,
            reference_sample: sample,
        });
        if baseline.is_none() {
            baseline = Some(hits);
        }
    }
    Ok(rows)
}

/// The rows as a Markdown table; node visits relative to the first row.
pub fn markdown_table(rows: &[BenchRow]) -> String {
    let mut out = String::from(
        "| traversal | M rays/s | ms (min–max) | nodes/ray | vs first | leaves/ray | tris/ray | restarts/ray | drops/ray | hits ≠ first | float64 errors |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let base_nodes = rows.first().map(|r| r.nodes).unwrap_or(1.0);
    for r in rows {
        let mut name = if r.traversal.variant.uses_short_stack() {
            format!("{}({})", r.traversal.variant, r.traversal.stack_size)
        } else {
            r.traversal.variant.to_string()
        };
        if !r.traversal.robust {
            name += " plain";
        }
        out.push_str(&format!(
            "| {}{} | {:.2} | {:.1} ({:.1}–{:.1}) | {:.1} | {:+.1}% | {:.2} | {:.1} | {:.2} | {:.2} | {} | {}/{} |\n",
            name,
            if r.traversal.any_hit { " any-hit" } else { "" },
            r.rays_per_second() / 1e6,
            r.seconds_median * 1e3,
            r.seconds_min * 1e3,
            r.seconds_max * 1e3,
            r.nodes,
            (r.nodes / base_nodes - 1.0) * 100.0,
            r.leaves,
            r.triangles,
            r.restarts,
            r.drops,
            r.differ_from_baseline,
            r.reference_errors,
            r.reference_sample
        ));
    }
    out
}
