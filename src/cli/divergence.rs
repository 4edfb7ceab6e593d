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

/// Bars per row: the replay's, the memory-only kernel's and the records read's time as shares
/// of the real kernel's, beside the SIMD efficiency.
fn plot(path: &std::path::Path, rows: &[Row], title: &str) -> Result<()> {
    use plotters::prelude::*;
    kdtrace::bench::plot::ensure_font()?;
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (200 * rows.len().max(1) as u32 + 200, 520)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(-0.5..rows.len().max(1) as f64 - 0.5, 0.0..1.1f64)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(rows.len().max(1))
            .x_label_formatter(&|x| match (x.round() - x).abs() < 1e-6 && *x >= 0.0 {
                true => rows.get(x.round() as usize).map_or(String::new(), |r| {
                    let w = if r.packet_width > 1 { format!(" W{}", r.packet_width) } else { String::new() };
                    format!("{} {} {}{w}", r.scene, r.kind, r.traversal)
                }),
                false => String::new(),
            })
            .y_desc("share of the real kernel's time / SIMD efficiency")
            .draw()?;
        let series = [
            ("replay ÷ real", RED),
            ("memory-only ÷ real", MAGENTA),
            ("records read ÷ real", BLUE),
            ("SIMD efficiency (overall)", GREEN),
        ];
        for (s, (label, color)) in series.into_iter().enumerate() {
            let bars = rows.iter().enumerate().map(|(i, r)| {
                let value = match s {
                    0 => r.replay_s / r.real_s,
                    1 => r.memory_s / r.real_s,
                    2 => r.read_s / r.real_s,
                    _ => r.overall,
                };
                let x0 = i as f64 - 0.38 + 0.19 * s as f64;
                Rectangle::new([(x0, 0.0), (x0 + 0.17, value.min(1.1))], color.filled())
            });
            chart
                .draw_series(bars)?
                .label(label)
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], color.filled()));
        }
        chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))
}
