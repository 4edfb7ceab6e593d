//! `kdtrace divergence`: each traversal's real kernel against a replay of its
//! control flow without fetches or arithmetic and a memory-only kernel with its
//! fetches and nothing else (src/divergence.rs), per scene, ray kind, variant
//! and packet width.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use kdtrace::divergence::{record, replay, simd_efficiency};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::traversal::{Traversal, Variant};

use super::args::TreeArgs;
use super::common::{context, default_camera, load_and_build, spinner, Stages};

#[derive(clap::Args)]
pub struct DivergenceArgs {
    /// OBJ or glTF scene files.
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    /// Traversals, comma-separated, or `all`: stack | restart | push-down |
    /// short-stack | push-down-short-stack | backtrack | ropes.
    #[arg(long, value_delimiter = ',', default_value = "stack")]
    pub traversal: Vec<String>,
    /// Packet widths, comma-separated: 1 = single rays; up to the subgroup size
    /// (backtrack and ropes have no packets and run as single rays only).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    pub packet_width: Vec<u32>,
    /// Short-stack entries (1..=8) for short-stack and push-down-short-stack.
    #[arg(long, default_value_t = 3)]
    pub stack_size: u32,
    /// The plain kernels instead of the robust ones.
    #[arg(long)]
    pub plain: bool,
    #[command(flatten)]
    pub tree: TreeArgs,
    /// Ray kinds: camera (Morton order), random (uniform in the scene box).
    #[arg(long, value_delimiter = ',', default_value = "camera,random")]
    pub kinds: Vec<String>,
    /// Camera rays: image width and height.
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    #[arg(long, default_value_t = 768)]
    pub height: u32,
    /// Random rays.
    #[arg(long, default_value_t = 1_000_000)]
    pub random: usize,
    /// Timed repetitions (median, after a warm-up).
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// CSV output (one row per scene, kind, traversal and packet width).
    #[arg(long, default_value = "divergence.csv")]
    pub csv: PathBuf,
    /// PNG chart: replay, memory-only and record reads as shares of the real kernel's time.
    #[arg(long, default_value = "divergence.png")]
    pub png: PathBuf,
}

/// One row of the table and CSV.
struct Row {
    scene: String,
    kind: String,
    traversal: String,
    packet_width: u32,
    rays: usize,
    lanes: u32,
    real_s: f64,
    replay_s: f64,
    read_s: f64,
    memory_s: f64,
    memory_read_s: f64,
    record_bytes: u64,
    fetch_bytes: u64,
    descent: f64,
    leaf: f64,
    overall: f64,
    /// Packets: the share of packet steps in which a lane needed the node.
    active: f64,
    nodes: f64,
    leaves: f64,
    triangles: f64,
}

/// The traversals the arguments name, validated against the device's subgroup size.
fn traversals(args: &DivergenceArgs, subgroup: u32) -> Result<Vec<Traversal>> {
    let variants: Vec<Variant> = if args.traversal.iter().any(|t| t == "all") {
        Variant::ALL.to_vec()
    } else {
        args.traversal.iter().map(|t| t.parse()).collect::<kdtrace::Result<_>>()?
    };
    let mut out = Vec::new();
    for &width in &args.packet_width {
        for &variant in &variants {
            if width > 1 && matches!(variant, Variant::Backtrack | Variant::Ropes) {
                if variants.len() == 1 {
                    bail!("{} has no packet kernel", variant.name());
                }
                continue; // backtrack and ropes run as single rays only
            }
            if width > subgroup {
                bail!("packet width {width} is wider than the device's subgroups of {subgroup}");
            }
            let traversal = Traversal {
                variant,
                stack_size: args.stack_size,
                any_hit: false,
                packet_width: width,
                subgroup_size: None,
                robust: !args.plain,
            };
            traversal.validate()?;
            out.push(traversal);
        }
    }
    Ok(out)
}

/// `kdtrace divergence`.
pub fn divergence(args: DivergenceArgs) -> Result<()> {
    let ctx = context()?;
    let lanes = ctx.info.subgroup_size;
    let traversals = traversals(&args, lanes)?;
    let mut rows = Vec::new();
    for path in &args.scenes {
        let (scene, tree) = load_and_build(path, &args.tree, &mut Stages::new(false))?;
        let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles)?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        for kind in &args.kinds {
            let rays = match kind.as_str() {
                "camera" => {
                    let camera = default_camera(path, &scene)?;
                    kdtrace::render::camera_rays_morton(&camera, args.width, args.height).0
                }
                "random" => kdtrace::raygen::random_rays(&scene.bounds, args.random, 1),
                other => bail!("unknown ray kind '{other}' (camera, random)"),
            };
            for &traversal in &traversals {
                let label = format!("{name}, {kind}, {} W={}", traversal.variant.name(), traversal.packet_width);
                let bar = spinner(format!("{label}: the real kernel"));
                let options = TraceOptions::new(traversal);
                let mut real = Vec::new();
                for _ in 0..=args.repeat.max(1) {
                    let t = tracer.trace(&rays, &options)?.gpu_seconds.context("the device has no timestamps")?;
                    real.push(t);
                }
                real.remove(0);
                real.sort_by(f64::total_cmp);
                bar.set_message(format!("{label}: recording the control flow (CPU twin)"));
                let records = record(&tree, &scene.triangles, &rays, traversal)?;
                if records.clamped > 0 {
                    eprintln!("warning: {} trip counts above 65535 were clamped in the records", records.clamped);
                }
                bar.set_message(format!("{label}: replaying"));
                let times = replay(&ctx, &tree, &scene.triangles, &records, args.repeat)?
                    .context("the device has no timestamps")?;
                bar.finish_and_clear();
                let e = simd_efficiency(&records, lanes as usize);
                let n = rays.len().max(1) as f64;
                rows.push(Row {
                    scene: name.clone(),
                    kind: kind.clone(),
                    traversal: traversal.variant.name().to_string(),
                    packet_width: traversal.packet_width,
                    rays: rays.len(),
                    lanes,
                    real_s: real[real.len() / 2],
                    replay_s: times.replay_s,
                    read_s: times.read_s,
                    memory_s: times.memory_s,
                    memory_read_s: times.memory_read_s,
                    record_bytes: records.bytes(),
                    fetch_bytes: records.fetch_bytes(),
                    descent: e.descent,
                    leaf: e.leaf,
                    overall: e.overall,
                    active: if records.steps > 0 { records.nodes as f64 / records.steps as f64 } else { 1.0 },
                    nodes: records.nodes as f64 / n,
                    leaves: records.leaves as f64 / n,
                    triangles: records.triangles as f64 / n,
                });
            }
        }
    }
    print_table(&rows, &ctx.info.name, !args.plain);
    write_csv(&args.csv, &rows)?;
    plot(&args.png, &rows, &format!("kdtrace divergence on {}", ctx.info.name))?;
    eprintln!("wrote {} and {}", args.csv.display(), args.png.display());
    Ok(())
}

fn print_table(rows: &[Row], device: &str, robust: bool) {
    println!("# kdtrace divergence ({}) on {device}\n", if robust { "robust" } else { "plain" });
    println!(
        "| scene | rays | traversal | W | real ms | replay ms | ÷ real | read ms | memory ms | ÷ real | read ms | record B/ray | fetches B/ray | SIMD eff. descent | leaf | overall | active | nodes/ray | leaves/ray | tris/ray |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let per_ray = |b: u64| b as f64 / r.rays.max(1) as f64;
        println!(
            "| {} | {} {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} | {:.0} % | {:.0} % | {:.0} % | {:.0} % | {:.1} | {:.2} | {:.1} |",
            r.scene,
            r.rays,
            r.kind,
            r.traversal,
            r.packet_width,
            r.real_s * 1e3,
            r.replay_s * 1e3,
            r.replay_s / r.real_s,
            r.read_s * 1e3,
            r.memory_s * 1e3,
            r.memory_s / r.real_s,
            r.memory_read_s * 1e3,
            per_ray(r.record_bytes),
            per_ray(r.fetch_bytes),
            100.0 * r.descent,
            100.0 * r.leaf,
            100.0 * r.overall,
            100.0 * r.active,
            r.nodes,
            r.leaves,
            r.triangles
        );
    }
}

fn write_csv(path: &std::path::Path, rows: &[Row]) -> Result<()> {
    let mut f = std::fs::File::create(path).with_context(|| format!("writing {}", path.display()))?;
    writeln!(
        f,
        "scene,kind,traversal,packet_width,rays,lanes,real_s,replay_s,records_read_s,memory_s,fetches_read_s,record_bytes,fetch_bytes,simd_descent,simd_leaf,simd_overall,packet_active,nodes_per_ray,leaves_per_ray,tris_per_ray"
    )?;
    for r in rows {
        writeln!(
            f,
            "{},{},{},{},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{},{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{:.3}",
            r.scene,
            r.kind,
            r.traversal,
            r.packet_width,
            r.rays,
            r.lanes,
            r.real_s,
            r.replay_s,
            r.read_s,
            r.memory_s,
            r.memory_read_s,
            r.record_bytes,
            r.fetch_bytes,
            r.descent,
            r.leaf,
            r.overall,
            r.active,
            r.nodes,
            r.leaves,
            r.triangles
        )?;
    }
    Ok(())
}

/// Short label of a row's traversal and packet width on the chart's x axis.
fn short_label(r: &Row) -> String {
    let t = match r.traversal.as_str() {
        "stack" => "st",
        "restart" => "rs",
        "push-down" => "pd",
        "short-stack" => "ss",
        "push-down-short-stack" => "pss",
        "backtrack" => "bt",
        "ropes" => "rp",
        other => other,
    };
    if r.packet_width > 1 {
        format!("{t}/{}", r.packet_width)
    } else {
        t.to_string()
    }
}

/// One panel per scene and ray kind (kinds in rows, scenes in columns); in each,
/// a stacked bar per traversal and packet width: the shares of the real kernel's
/// time that the control flow (replay less its record read), the memory traffic
/// (memory-only kernel less its record read) and the rest (arithmetic) take,
/// and the overall SIMD efficiency as a black tick.
fn plot(path: &std::path::Path, rows: &[Row], title: &str) -> Result<()> {
    use plotters::prelude::*;
    kdtrace::bench::plot::ensure_font()?;
    let mut scenes: Vec<&str> = Vec::new();
    let mut kinds: Vec<&str> = Vec::new();
    for r in rows {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
        if !kinds.contains(&r.kind.as_str()) {
            kinds.push(&r.kind);
        }
    }
    let per_panel = rows.iter().filter(|r| r.scene == scenes[0] && r.kind == kinds[0]).count().max(1);
    let panel_w = (40 * per_panel as u32 + 90).max(260);
    let size = (panel_w * scenes.len().max(1) as u32, 330 * kinds.len().max(1) as u32 + 70);
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, size).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root
            .titled(&format!("{title}: share of the real kernel's time (tick: SIMD efficiency)"), ("sans-serif", 18))?;
        let (body, legend) = root.split_vertically(size.1 - 70);
        let panels = body.split_evenly((kinds.len().max(1), scenes.len().max(1)));
        let series = [("control flow (replay)", RED), ("memory (memory-only)", BLUE), ("the rest: arithmetic", GREEN)];
        for (k, kind) in kinds.iter().enumerate() {
            for (s, scene) in scenes.iter().enumerate() {
                let mine: Vec<&Row> = rows.iter().filter(|r| r.scene == *scene && r.kind == *kind).collect();
                let area = &panels[k * scenes.len() + s];
                let mut chart = ChartBuilder::on(area)
                    .caption(format!("{scene}, {kind}"), ("sans-serif", 14))
                    .margin(6)
                    .x_label_area_size(36)
                    .y_label_area_size(36)
                    .build_cartesian_2d(-0.5..mine.len().max(1) as f64 - 0.5, 0.0..1.05f64)?;
                chart
                    .configure_mesh()
                    .disable_x_mesh()
                    .x_labels(mine.len().max(1))
                    .x_label_style(("sans-serif", 10))
                    .x_label_formatter(&|x| match (x.round() - x).abs() < 1e-6 && *x >= 0.0 {
                        true => mine.get(x.round() as usize).map_or(String::new(), |r| short_label(r)),
                        false => String::new(),
                    })
                    .draw()?;
                for (i, r) in mine.iter().enumerate() {
                    let control = ((r.replay_s - r.read_s) / r.real_s).clamp(0.0, 1.0);
                    let memory = ((r.memory_s - r.memory_read_s) / r.real_s).clamp(0.0, 1.0 - control);
                    let parts = [control, memory, 1.0 - control - memory];
                    let x = i as f64;
                    let mut y = 0.0;
                    for (part, (_, color)) in parts.iter().zip(series) {
                        chart.draw_series([Rectangle::new([(x - 0.35, y), (x + 0.35, y + part)], color.filled())])?;
                        y += part;
                    }
                    let e = r.overall * r.active;
                    chart.draw_series([PathElement::new(vec![(x - 0.4, e), (x + 0.4, e)], BLACK.stroke_width(3))])?;
                }
            }
        }
        let mut x = 20;
        for (label, color) in series {
            legend.draw(&Rectangle::new([(x, 20), (x + 14, 34)], color.filled()))?;
            legend.draw(&Text::new(label, (x + 20, 20), ("sans-serif", 14)))?;
            x += 240;
        }
        legend.draw(&Text::new(
            "st stack, rs restart, pd push-down, ss short-stack, pss push-down short-stack, bt backtrack, rp ropes; /W packets",
            (20, 46),
            ("sans-serif", 12),
        ))?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))
}
