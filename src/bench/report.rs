//! The matrix's outputs: the full Markdown table, a short summary, and CSV.

use std::fmt::Write as _;
use std::path::Path;

use crate::bench::matrix::{baselines, Backend, Cell};
use crate::error::{Error, Result};
use crate::exact::Verdict;
use crate::traversal::Variant;

/// The verdicts that disagree, with their counts, e.g. `neighbour 2, grazing miss 1`.
pub fn classes(cell: &Cell) -> String {
    let parts: Vec<String> = Verdict::ALL
        .iter()
        .zip(&cell.tally.counts)
        .filter(|(v, n)| !v.agrees() && **n > 0)
        .map(|(v, n)| format!("{} {n}", v.name()))
        .collect();
    if parts.is_empty() {
        "—".into()
    } else {
        parts.join(", ")
    }
}

fn ms(s: f64) -> f64 {
    s * 1e3
}

/// Every cell as a Markdown table, grouped by scene and ray kind.
pub fn markdown_table(cells: &[Cell]) -> String {
    let base = baselines(cells);
    let mut out = String::from(
        "| scene | rays | settings | build ms | upload ms | pipeline ms | trace ms (min–max) | call ms | M rays/s | × baseline | nodes/ray | leaves/ray | tris/ray | disagree | classes | serious | incomplete |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (i, c) in cells.iter().enumerate() {
        let counters = match c.counters {
            Some([n, l, t]) => format!("{n:.1} | {l:.2} | {t:.1}"),
            None => "— | — | —".into(),
        };
        let is_base = base.get(&(c.scene.clone(), c.kind)) == Some(&i);
        let _ = writeln!(
            out,
            "| {} | {} {} | {}{} | {:.1} | {:.1} | {:.1} | {:.2} ({:.2}–{:.2}) | {:.2} | {:.2} | {} | {} | {}/{} ({:.2}%) | {} | {} | {} |",
            c.scene,
            c.rays,
            c.kind,
            c.label(),
            if is_base { " **(baseline)**" } else { "" },
            ms(c.build_seconds),
            ms(c.upload_seconds),
            ms(c.pipeline_seconds),
            ms(c.trace_seconds[0]),
            ms(c.trace_seconds[1]),
            ms(c.trace_seconds[2]),
            ms(c.wall_seconds),
            c.rays_per_second() / 1e6,
            ratio(c.speedup),
            counters,
            c.disagreeing(),
            c.tally.rays,
            100.0 * c.disagreeing() as f64 / c.tally.rays.max(1) as f64,
            classes(c),
            c.tally.serious(),
            c.incomplete
        );
    }
    out
}

/// One row per scene and ray kind: the GPU `stack` (first builder, robust, single
/// rays), the fastest GPU cell without serious errors, the CPU twin, Embree and
/// the driver's ray query in M rays/s, and the GPU `stack` against the baseline.
pub fn summary_table(cells: &[Cell]) -> String {
    let mut out = String::from(
        "| scene | rays | GPU stack M rays/s | fastest GPU without serious errors | CPU twin M rays/s | Embree M rays/s | ray query M rays/s | GPU stack × baseline | serious errors (all cells) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut keys: Vec<(String, crate::bench::rays::RayKind)> = Vec::new();
    for c in cells {
        let key = (c.scene.clone(), c.kind);
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let rate = |c: Option<&Cell>| c.map_or("—".to_string(), |c| format!("{:.2}", c.rays_per_second() / 1e6));
    for (scene, kind) in keys {
        let group: Vec<&Cell> = cells.iter().filter(|c| c.scene == scene && c.kind == kind).collect();
        let first_builder = group.first().map(|c| c.builder.clone()).unwrap_or_default();
        let stack = group.iter().copied().find(|c| {
            c.backend == Backend::Gpu
                && c.builder == first_builder
                && c.traversal.is_some_and(|t| t.variant == Variant::Stack && t.robust && !t.uses_packets())
        });
        let fastest = group
            .iter()
            .copied()
            .filter(|c| c.backend == Backend::Gpu && c.tally.serious() == 0)
            .max_by(|a, b| a.rays_per_second().total_cmp(&b.rays_per_second()));
        let cpu = group.iter().copied().find(|c| c.backend == Backend::Cpu);
        let embree = group
            .iter()
            .copied()
            .filter(|c| c.backend == Backend::Embree && c.builder == "embree-bvh")
            .max_by_key(|c| c.threads);
        let ray_query = group.iter().copied().find(|c| c.backend == Backend::RayQuery);
        let serious: usize = group.iter().map(|c| c.tally.serious()).sum();
        let _ = writeln!(
            out,
            "| {scene} | {} {kind} | {} | {} | {} | {} | {} | {} | {serious} |",
            group.first().map_or(0, |c| c.rays),
            rate(stack),
            fastest.map_or("—".into(), |c| format!("{:.2} ({})", c.rays_per_second() / 1e6, c.label())),
            rate(cpu),
            rate(embree),
            rate(ray_query),
            stack.map_or("—".into(), |c| ratio(c.speedup)),
        );
    }
    out
}

/// A speed ratio to two decimals, or "—" when there is no baseline to divide by.
fn ratio(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.2}")
    } else {
        "—".into()
    }
}

fn snake(name: &str) -> String {
    name.to_lowercase().replace(' ', "_")
}

/// Every cell as CSV, one row per cell, with every verdict's count.
pub fn write_csv(path: &Path, cells: &[Cell]) -> Result<()> {
    let mut text = String::from(
        "scene,kind,backend,threads,builder,traversal,variant,stack_size,packet_width,robust,any_hit,order,rays,build_s,upload_s,pipeline_s,trace_s_median,trace_s_min,trace_s_max,call_s_median,rays_per_second,speedup_vs_baseline,nodes_per_ray,leaves_per_ray,triangles_per_ray,sample,agree,disagree_rate,serious,incomplete",
    );
    for v in Verdict::ALL {
        text += &format!(",{}", snake(v.name()));
    }
    text.push('\n');
    for c in cells {
        let t = c.traversal;
        let (n, l, tr) = match c.counters {
            Some([n, l, t]) => (format!("{n:.4}"), format!("{l:.4}"), format!("{t:.4}")),
            None => (String::new(), String::new(), String::new()),
        };
        let _ = write!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6e},{:.6e},{:.6e},{:.6e},{:.0},{:.4},{n},{l},{tr},{},{},{:.6},{},{}",
            c.scene,
            c.kind,
            c.backend.name(),
            c.threads,
            c.builder,
            t.map_or(String::new(), |t| crate::bench::matrix::traversal_name(&t)),
            t.map_or(String::new(), |t| t.variant.name().to_string()),
            t.map_or(String::new(), |t| t.stack_size.to_string()),
            t.map_or(String::new(), |t| t.packet_width.to_string()),
            t.map_or(String::new(), |t| t.robust.to_string()),
            c.kind.any_hit(),
            c.order.name(),
            c.rays,
            c.build_seconds,
            c.upload_seconds,
            c.pipeline_seconds,
            c.trace_seconds[0],
            c.trace_seconds[1],
            c.trace_seconds[2],
            c.wall_seconds,
            c.rays_per_second(),
            c.speedup,
            c.tally.rays,
            c.tally.agreeing(),
            c.disagreeing() as f64 / c.tally.rays.max(1) as f64,
            c.tally.serious(),
            c.incomplete,
        );
        for n in c.tally.counts {
            let _ = write!(text, ",{n}");
        }
        text.push('\n');
    }
    std::fs::write(path, text).map_err(|source| Error::Io { path: path.into(), source })
}
