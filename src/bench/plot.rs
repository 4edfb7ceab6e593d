//! The matrix's PNG charts (plotters, bitmap backend): time against error with
//! the Pareto front, rays/s per setting and node visits per setting, one panel
//! per scene; every point is labelled with its settings.

use std::path::{Path, PathBuf};

use plotters::coord::ranged1d::SegmentValue;
use plotters::prelude::*;

use crate::bench::matrix::{Backend, Cell};
use crate::bench::rays::RayKind;
use crate::error::{Error, Result};

/// A time (log scale) against error chart.
pub(crate) type TimeErrorChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::combinators::LogCoord<f64>, plotters::coord::types::RangedCoordf64>,
>;

/// A panel of time (x, log scale) against error (y) for the `(time, error)`
/// points: x spans their times, never less than a factor of 2, widened by the
/// factor `margin` each way; y runs from 0 to 15 % above the largest error.
pub(crate) fn time_error_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, plotters::coord::Shift>,
    caption: String,
    points: &[(f64, f64)],
    margin: f64,
) -> std::result::Result<TimeErrorChart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let x_max = points.iter().map(|p| p.0).fold(0.0, f64::max).max(1e-3) * margin;
    let x_min = points.iter().map(|p| p.0).fold(f64::INFINITY, f64::min).min(x_max / 2.0) / margin;
    let y_max = points.iter().map(|p| p.1).fold(0.0, f64::max).max(0.1) * 1.15;
    ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(15)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d((x_min..x_max).log_scale(), 0.0..y_max)
}

/// Debian's DejaVu Sans (package fonts-dejavu-core, installed by tools/setup).
const FONT_PATHS: [&str; 2] =
    ["/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", "/usr/share/fonts/dejavu/DejaVuSans.ttf"];

/// The Pareto front of (time, error) points: sorted by time, each point more
/// accurate than every faster one.
pub fn pareto_front(mut points: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    points.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut best = f64::INFINITY;
    points.retain(|p| {
        let keep = p.1 < best;
        best = best.min(p.1);
        keep
    });
    points
}

/// Registers the charts' font once per process.
pub fn ensure_font() -> Result<()> {
    static DONE: std::sync::OnceLock<std::result::Result<(), String>> = std::sync::OnceLock::new();
    DONE.get_or_init(|| register_font().map_err(|e| e.to_string())).clone().map_err(Error::InvalidInput)
}

fn register_font() -> Result<()> {
    let font = FONT_PATHS.iter().find_map(|p| std::fs::read(p).ok()).ok_or_else(|| {
        Error::InvalidInput(format!("no font for the charts: install fonts-dejavu-core ({})", FONT_PATHS[0]))
    })?;
    let font: &'static [u8] = Box::leak(font.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, font)
        .map_err(|_| Error::InvalidInput("the chart font could not be loaded".into()))
}

/// The scenes in the order they first appear.
fn scenes(cells: &[Cell]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for c in cells {
        if !out.contains(&c.scene) {
            out.push(c.scene.clone());
        }
    }
    out
}

/// The settings labels of a scene's cells, in first-appearance order.
fn labels(cells: &[&Cell]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for c in cells {
        let l = c.label();
        if !out.contains(&l) {
            out.push(l);
        }
    }
    out
}

fn backend_color(b: Backend) -> RGBColor {
    match b {
        Backend::Gpu => RGBColor(31, 119, 180),
        Backend::Cpu => RGBColor(44, 160, 44),
        Backend::Embree => RGBColor(214, 39, 40),
        Backend::RayQuery => RGBColor(148, 103, 189),
    }
}

fn kind_color(k: RayKind) -> RGBAColor {
    Palette99::pick(RayKind::ALL.iter().position(|&x| x == k).unwrap_or(0)).to_rgba()
}

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

fn wrap(path: &Path, r: DrawResult) -> Result<()> {
    r.map_err(|e| Error::InvalidInput(format!("{}: drawing the chart failed: {e}", path.display())))
}

/// Who traced a point of the time-vs-error chart, and with which arithmetic.
#[derive(Clone, Copy, PartialEq)]
enum Family {
    GpuRobust,
    GpuPlain,
    Cpu,
    Embree,
    RayQuery,
}

impl Family {
    const ALL: [Family; 5] = [Family::GpuRobust, Family::GpuPlain, Family::Cpu, Family::Embree, Family::RayQuery];

    fn of(c: &Cell) -> Family {
        match c.backend {
            Backend::Gpu if c.traversal.map_or(true, |t| t.robust) => Family::GpuRobust,
            Backend::Gpu => Family::GpuPlain,
            Backend::Cpu => Family::Cpu,
            Backend::Embree => Family::Embree,
            Backend::RayQuery => Family::RayQuery,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Family::GpuRobust => "kdtrace GPU, robust (default)",
            Family::GpuPlain => "kdtrace GPU, --plain",
            Family::Cpu => "kdtrace CPU twin",
            Family::Embree => "Embree",
            Family::RayQuery => "driver's ray query",
        }
    }

    fn color(self) -> RGBColor {
        match self {
            Family::GpuRobust => backend_color(Backend::Gpu),
            Family::GpuPlain => RGBColor(255, 127, 14),
            Family::Cpu => backend_color(Backend::Cpu),
            Family::Embree => backend_color(Backend::Embree),
            Family::RayQuery => backend_color(Backend::RayQuery),
        }
    }
}

/// One panel per scene and ray kind (rows and columns), one point per setting:
/// nanoseconds per ray against the disagreement with the exact reference (% of
/// the judged sample), coloured by who traced it (robust and plain GPU kernels
/// apart); the Pareto front (no other point both faster and more accurate)
/// joined by a line, and only its points labelled. Include the `hard` ray kind
/// to see what the robustness measures buy.
pub fn time_vs_error(path: &Path, cells: &[Cell], title: &str) -> Result<()> {
    let scenes = scenes(cells);
    let kinds: Vec<RayKind> = RayKind::ALL.into_iter().filter(|k| cells.iter().any(|c| c.kind == *k)).collect();
    let panels: Vec<(&String, RayKind)> = scenes.iter().flat_map(|s| kinds.iter().map(move |&k| (s, k))).collect();
    let (rows, columns) = (scenes.len().max(1), kinds.len().max(1));
    let draw = || -> DrawResult {
        let width = if columns > 1 { 480 * columns as u32 } else { 1000 };
        let root = BitMapBackend::new(path, (width, 290 * rows as u32 + 40)).into_drawing_area();
        root.fill(&WHITE)?;
        let (header, body) = root.split_vertically(40);
        header.titled(title, ("sans-serif", 20))?;
        for (i, (area, (scene, kind))) in body.split_evenly((rows, columns)).iter().zip(&panels).enumerate() {
            let group: Vec<&Cell> = cells.iter().filter(|c| &c.scene == *scene && c.kind == *kind).collect();
            let points: Vec<(String, Family, f64, f64)> = labels(&group)
                .into_iter()
                .map(|label| {
                    let mine: Vec<&&Cell> = group.iter().filter(|c| c.label() == label).collect();
                    let seconds: f64 = mine.iter().map(|c| c.trace_seconds[0]).sum();
                    let rays: usize = mine.iter().map(|c| c.rays).sum();
                    let sample: usize = mine.iter().map(|c| c.tally.rays).sum();
                    let wrong: usize = mine.iter().map(|c| c.disagreeing()).sum();
                    let error = 100.0 * wrong as f64 / sample.max(1) as f64;
                    (label, Family::of(mine[0]), 1e9 * seconds / rays.max(1) as f64, error)
                })
                .collect();
            let time_error: Vec<(f64, f64)> = points.iter().map(|p| (p.2, p.3)).collect();
            let mut chart = time_error_chart(area, format!("{scene}, {kind} rays: time vs error"), &time_error, 1.5)?;
            chart
                .configure_mesh()
                .light_line_style(WHITE) // no minor grid: a lighter, smaller PNG
                .x_labels(4)
                .y_labels(6)
                .x_desc("trace ns per ray (median, log scale)")
                .y_desc("rays disagreeing with the exact reference, %")
                .draw()?;
            let front = pareto_front(points.iter().map(|p| (p.2, p.3)).collect());
            chart
                .draw_series(LineSeries::new(front.clone(), BLACK.stroke_width(1)))?
                .label("Pareto front (labelled)")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(1)));
            for family in Family::ALL {
                let color = family.color();
                let mine: Vec<&(String, Family, f64, f64)> = points.iter().filter(|p| p.1 == family).collect();
                if mine.is_empty() {
                    continue;
                }
                chart
                    .draw_series(mine.iter().map(|p| Circle::new((p.2, p.3), 4, color.filled())))?
                    .label(family.name())
                    .legend(move |(x, y)| Circle::new((x + 8, y), 4, color.filled()));
            }
            // Labels on the front only, staggered so that equal errors stay readable.
            let on_front: Vec<&(String, Family, f64, f64)> =
                points.iter().filter(|p| front.iter().any(|f| f.0 == p.2 && f.1 == p.3)).collect();
            chart.draw_series(on_front.iter().enumerate().map(|(i, p)| {
                let font = ("sans-serif", 11).into_font().color(&p.1.color());
                EmptyElement::at((p.2, p.3)) + Text::new(p.0.clone(), (4, -8 - 12 * (i as i32 % 3)), font)
            }))?;
            // The legend once, in the first panel (the same in every one).
            if i == 0 {
                chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
            }
        }
        root.present()?;
        Ok(())
    };
    wrap(path, draw())
}

/// A dot chart per scene: one row per setting, one dot per ray kind at `value(cell)`.
fn dot_chart(
    path: &Path,
    cells: &[Cell],
    title: &str,
    x_desc: &str,
    value: impl Fn(&Cell) -> Option<f64>,
) -> Result<()> {
    let scenes = scenes(cells);
    let panels: Vec<(String, Vec<&Cell>, Vec<String>)> = scenes
        .iter()
        .map(|s| {
            let group: Vec<&Cell> = cells.iter().filter(|c| &c.scene == s && value(c).is_some()).collect();
            let rows = labels(&group);
            (s.clone(), group, rows)
        })
        .collect();
    let heights: Vec<u32> = panels.iter().map(|p| 18 * p.2.len().max(1) as u32 + 90).collect();
    let draw = || -> DrawResult {
        let total: u32 = heights.iter().sum::<u32>() + 40;
        let root = BitMapBackend::new(path, (1200, total)).into_drawing_area();
        root.fill(&WHITE)?;
        let (header, mut body) = root.split_vertically(40);
        header.titled(title, ("sans-serif", 20))?;
        for ((scene, group, rows), h) in panels.iter().zip(&heights) {
            let (area, rest) = body.split_vertically(*h);
            body = rest;
            let x_max = group.iter().filter_map(|c| value(c)).fold(0.0, f64::max).max(1e-3) * 1.1;
            let n = rows.len().max(1) as u32;
            let mut chart = ChartBuilder::on(&area)
                .caption(scene, ("sans-serif", 16))
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(330)
                .build_cartesian_2d(0.0..x_max, (0u32..n).into_segmented())?;
            let rows_for_labels = rows.clone();
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_labels(n as usize)
                .y_label_formatter(&move |v| match v {
                    SegmentValue::CenterOf(i) => rows_for_labels.get(*i as usize).cloned().unwrap_or_default(),
                    _ => String::new(),
                })
                .draw()?;
            for kind in RayKind::ALL {
                let color = kind_color(kind);
                let dots: Vec<(f64, u32)> = group
                    .iter()
                    .filter(|c| c.kind == kind)
                    .filter_map(|c| Some((value(c)?, rows.iter().position(|r| *r == c.label())? as u32)))
                    .collect();
                if dots.is_empty() {
                    continue;
                }
                chart
                    .draw_series(
                        dots.iter().map(|&(x, i)| Circle::new((x, SegmentValue::CenterOf(i)), 4, color.filled())),
                    )?
                    .label(kind.name())
                    .legend(move |(x, y)| Circle::new((x + 8, y), 4, color.filled()));
            }
            chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
        }
        root.present()?;
        Ok(())
    };
    wrap(path, draw())
}

/// The three charts in `dir`, named `bench-time-error.png`, `bench-rays-per-second.png`
/// and `bench-nodes.png`; returns their paths.
pub fn write_plots(dir: &Path, cells: &[Cell], title: &str) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.into(), source })?;
    ensure_font()?;
    let paths: Vec<PathBuf> =
        ["bench-time-error.png", "bench-rays-per-second.png", "bench-nodes.png"].iter().map(|n| dir.join(n)).collect();
    time_vs_error(&paths[0], cells, title)?;
    dot_chart(&paths[1], cells, title, "M rays/s (median)", |c| Some(c.rays_per_second() / 1e6))?;
    dot_chart(&paths[2], cells, title, "nodes visited per ray", |c| c.counters.map(|[n, _, _]| n))?;
    Ok(paths)
}
