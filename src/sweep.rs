//! Subgroup-size experiments: traversal variants × packet widths × the subgroup
//! sizes the device allows, each measured with GPU timestamps and counters.

use std::path::Path;

use crate::error::{Error, Result};
use crate::geom::Ray;
use crate::kdtree::traverse::Counters;
use crate::trace::{TraceOptions, Tracer};
use crate::traversal::{Traversal, Variant};

/// One cell of the sweep.
#[derive(Clone, Debug)]
pub struct SweepRow {
    /// Name of the ray batch (e.g. `camera`, `random`).
    pub rays_kind: String,
    /// The traversal measured, with its packet width and required subgroup size.
    pub traversal: Traversal,
    /// The subgroup size the pipeline ran with.
    pub subgroup_size: u32,
    /// Rays in the batch.
    pub rays: usize,
    /// Median GPU seconds over the repetitions (after a warm-up).
    pub seconds: f64,
    /// Mean node fetches per ray while the ray's lane was active.
    pub nodes_per_ray: f64,
    /// Packet steps (node fetches of the packet) per ray.
    pub steps_per_ray: f64,
    /// Active lanes per packet step ÷ packet width.
    pub simd_efficiency: f64,
    /// Active lanes per packet step ÷ subgroup size.
    pub subgroup_efficiency: f64,
}

impl SweepRow {
    /// Rays per second at the median GPU time.
    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.seconds
    }
}

/// The variants that have packet versions.
pub const PACKET_VARIANTS: [Variant; 5] =
    [Variant::Stack, Variant::Restart, Variant::PushDown, Variant::ShortStack, Variant::PushDownShortStack];

/// Subgroup sizes to sweep: every power of two the device allows when it has
/// subgroup size control, else just its fixed size (`None` = don't require one).
pub fn subgroup_sizes(tracer: &Tracer) -> Vec<Option<u32>> {
    let info = &tracer.context().info;
    if !info.subgroup_size_control || info.min_subgroup_size == info.max_subgroup_size {
        return vec![None];
    }
    let mut sizes = Vec::new();
    let mut s = info.min_subgroup_size.max(1);
    while s <= info.max_subgroup_size {
        sizes.push(Some(s));
        s *= 2;
    }
    sizes
}

/// Errors (`InvalidInput`) naming a variant without packets (backtrack, ropes).
pub fn check_variants(variants: &[Variant]) -> Result<()> {
    match variants.iter().find(|v| !PACKET_VARIANTS.contains(v)) {
        Some(v) => Err(Error::InvalidInput(format!("{} has no packet kernel to sweep", v.name()))),
        None => Ok(()),
    }
}

/// Runs the sweep over `batches` of (kind, rays) and `variants` (those with
/// packets: [`PACKET_VARIANTS`]).
pub fn run(
    tracer: &mut Tracer,
    batches: &[(&str, Vec<Ray>)],
    variants: &[Variant],
    repetitions: usize,
    mut progress: impl FnMut(&str),
) -> Result<Vec<SweepRow>> {
    check_variants(variants)?;
    let mut rows = Vec::new();
    let device_size = tracer.context().info.subgroup_size;
    for size in subgroup_sizes(tracer) {
        let lanes = size.unwrap_or(device_size);
        for (kind, rays) in batches {
            for &variant in variants {
                let mut width = 1;
                while width <= lanes {
                    let traversal =
                        Traversal { packet_width: width, subgroup_size: size, ..Traversal::closest(variant) };
                    progress(&format!("{kind} {variant} W={width} subgroup {lanes}"));
                    let counted = tracer.trace(rays, &TraceOptions::counted(traversal))?;
                    let counters = counted.counters.unwrap_or_default();
                    let options = TraceOptions::new(traversal);
                    tracer.trace(rays, &options)?;
                    let mut times: Vec<f64> = (0..repetitions.max(1))
                        .map(|_| tracer.trace(rays, &options).map(|r| r.gpu_seconds.unwrap_or(f64::NAN)))
                        .collect::<Result<_>>()?;
                    times.sort_by(f64::total_cmp);
                    let sum = |f: fn(&Counters) -> u32| counters.iter().map(|c| f(c) as f64).sum::<f64>();
                    let (active, steps) = (sum(|c| c.nodes), sum(|c| c.steps));
                    let n = rays.len().max(1) as f64;
                    rows.push(SweepRow {
                        rays_kind: kind.to_string(),
                        traversal,
                        subgroup_size: lanes,
                        rays: rays.len(),
                        seconds: times[times.len() / 2],
                        nodes_per_ray: active / n,
                        // A packet's steps are counted once per lane: divide by the width.
                        steps_per_ray: steps / n,
                        simd_efficiency: active / steps.max(1.0),
                        subgroup_efficiency: active / steps.max(1.0) * width as f64 / lanes as f64,
                    });
                    width *= 2;
                }
            }
        }
    }
    Ok(rows)
}

/// The rows as a Markdown table.
pub fn markdown_table(rows: &[SweepRow]) -> String {
    let mut out = String::from(
        "| rays | subgroup | traversal | W | M rays/s | nodes/ray | packet steps/ray | SIMD eff. (÷W) | ÷ subgroup |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {} | {} | {:.2} | {:.1} | {:.1} | {:.0}% | {:.0}% |\n",
            r.rays_kind,
            r.subgroup_size,
            r.traversal.variant,
            r.traversal.packet_width,
            r.rays_per_second() / 1e6,
            r.nodes_per_ray,
            r.steps_per_ray,
            100.0 * r.simd_efficiency,
            100.0 * r.subgroup_efficiency
        ));
    }
    out
}

/// Writes the rows as CSV.
pub fn write_csv(path: &Path, rows: &[SweepRow]) -> Result<()> {
    let mut text = String::from(
        "rays,subgroup_size,traversal,packet_width,rays_per_second,nodes_per_ray,packet_steps_per_ray,simd_efficiency,subgroup_efficiency\n",
    );
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{},{:.0},{:.3},{:.3},{:.4},{:.4}\n",
            r.rays_kind,
            r.subgroup_size,
            r.traversal.variant,
            r.traversal.packet_width,
            r.rays_per_second(),
            r.nodes_per_ray,
            r.steps_per_ray,
            r.simd_efficiency,
            r.subgroup_efficiency
        ));
    }
    std::fs::write(path, text).map_err(|source| Error::Io { path: path.into(), source })
}

/// Debian's DejaVu Sans (package fonts-dejavu-core, installed by tools/setup).
const FONT_PATHS: [&str; 2] =
    ["/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", "/usr/share/fonts/dejavu/DejaVuSans.ttf"];

/// Draws M rays/s and SIMD efficiency against packet width, one line per
/// variant, for each (rays kind, subgroup size), into a PNG.
pub fn plot_png(path: &Path, rows: &[SweepRow], title: &str) -> Result<()> {
    use plotters::prelude::*;
    let font = FONT_PATHS.iter().find_map(|p| std::fs::read(p).ok()).ok_or_else(|| {
        Error::InvalidInput(format!("no font for the chart: install fonts-dejavu-core ({})", FONT_PATHS[0]))
    })?;
    let font: &'static [u8] = Box::leak(font.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, font)
        .map_err(|_| Error::InvalidInput("the chart font could not be loaded".into()))?;

    let mut panels: Vec<(String, u32)> = Vec::new();
    for r in rows {
        let key = (r.rays_kind.clone(), r.subgroup_size);
        if !panels.contains(&key) {
            panels.push(key);
        }
    }
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        let height = 360 * panels.len().max(1) as u32 + 40;
        let root = BitMapBackend::new(path, (1200, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let (header, body) = root.split_vertically(40);
        header.titled(title, ("sans-serif", 20))?;
        let areas = body.split_evenly((panels.len().max(1), 2));
        for (p, (kind, lanes)) in panels.iter().enumerate() {
            let cells: Vec<&SweepRow> =
                rows.iter().filter(|r| &r.rays_kind == kind && r.subgroup_size == *lanes).collect();
            let max_w = cells.iter().map(|r| r.traversal.packet_width).max().unwrap_or(1);
            let max_rate = cells.iter().map(|r| r.rays_per_second() / 1e6).fold(0.0, f64::max) * 1.1;
            let x_max = (max_w as f64).log2().max(1.0);
            for (col, (label, y_max)) in [("M rays/s", max_rate.max(1e-3)), ("SIMD efficiency", 1.0)].iter().enumerate()
            {
                let mut chart = ChartBuilder::on(&areas[2 * p + col])
                    .caption(format!("{kind} rays, subgroup {lanes}: {label}"), ("sans-serif", 16))
                    .margin(10)
                    .x_label_area_size(30)
                    .y_label_area_size(50)
                    .build_cartesian_2d(0.0..x_max, 0.0..*y_max)?;
                chart
                    .configure_mesh()
                    .x_desc("packet width W (log2)")
                    .x_labels(x_max as usize + 1)
                    .x_label_formatter(&|x| format!("{}", 2f64.powf(*x).round()))
                    .draw()?;
                for (i, variant) in PACKET_VARIANTS.iter().enumerate() {
                    let color = Palette99::pick(i).to_rgba();
                    let points: Vec<(f64, f64)> = cells
                        .iter()
                        .filter(|r| r.traversal.variant == *variant)
                        .map(|r| {
                            let y = if col == 0 { r.rays_per_second() / 1e6 } else { r.simd_efficiency };
                            ((r.traversal.packet_width as f64).log2(), y)
                        })
                        .collect();
                    chart
                        .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
                        .label(variant.name())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2)));
                    chart.draw_series(points.iter().map(|&(x, y)| Circle::new((x, y), 3, color.filled())))?;
                }
                chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
            }
        }
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| Error::InvalidInput(format!("{}: drawing the chart failed: {e}", path.display())))
}
