//! `kdtrace divergence`: the real `stack` kernel against a replay of its control
//! flow without fetches or arithmetic (src/divergence.rs), per scene and ray kind.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use kdtrace::divergence::{record, replay, simd_efficiency};
use kdtrace::trace::{TraceOptions, Tracer};

use super::args::{TraversalArgs, TreeArgs};
use super::common::{context, default_camera, load_and_build, spinner, Stages};

#[derive(clap::Args)]
pub struct DivergenceArgs {
    /// OBJ or glTF scene files.
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    #[command(flatten)]
    pub traversal: TraversalArgs,
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
    /// CSV output (one row per scene and kind).
    #[arg(long, default_value = "divergence.csv")]
    pub csv: PathBuf,
    /// PNG chart: replay and record read as shares of the real kernel's time.
    #[arg(long, default_value = "divergence.png")]
    pub png: PathBuf,
}

/// One row of the table and CSV.
struct Row {
    scene: String,
    kind: String,
    rays: usize,
    lanes: u32,
    real_s: f64,
    replay_s: f64,
    read_s: f64,
    record_bytes: u64,
    descent: f64,
    leaf: f64,
    overall: f64,
    nodes: f64,
    leaves: f64,
    triangles: f64,
}

/// `kdtrace divergence`.
pub fn divergence(args: DivergenceArgs) -> Result<()> {
    let traversal = args.traversal.parse(false)?;
    if traversal.variant != kdtrace::traversal::Variant::Stack
        || traversal.packet_width > 1
        || args.traversal.backend != kdtrace::trace::Backend::KdTree
    {
        bail!("divergence replays the single-ray stack traversal only (--traversal stack, --packet-width 1)");
    }
    let ctx = context()?;
    let lanes = ctx.info.subgroup_size;
    let mut rows = Vec::new();
    for path in &args.scenes {
        let (scene, tree) = load_and_build(path, &args.tree, &mut Stages::new(false))?;
        let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles)?;
        let options = TraceOptions::new(traversal);
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
            let bar = spinner(format!("{name}, {kind}: the real kernel"));
            let mut real = Vec::new();
            for _ in 0..=args.repeat.max(1) {
                let t = tracer.trace(&rays, &options)?.gpu_seconds.context("the device has no timestamps")?;
                real.push(t);
            }
            real.remove(0);
            real.sort_by(f64::total_cmp);
            bar.set_message(format!("{name}, {kind}: recording the control flow (CPU twin)"));
            let records = record(&tree, &scene.triangles, &rays, traversal)?;
            if records.clamped > 0 {
                eprintln!("warning: {} trip counts above 65535 were clamped in the records", records.clamped);
            }
            bar.set_message(format!("{name}, {kind}: replaying"));
            let times = replay(&ctx, &records, args.repeat)?.context("the device has no timestamps")?;
            bar.finish_and_clear();
            let e = simd_efficiency(&records, lanes as usize);
            let n = rays.len().max(1) as f64;
            rows.push(Row {
                scene: name.clone(),
                kind: kind.clone(),
                rays: rays.len(),
                lanes,
                real_s: real[real.len() / 2],
                replay_s: times.replay_s,
                read_s: times.read_s,
                record_bytes: records.bytes(),
                descent: e.descent,
                leaf: e.leaf,
                overall: e.overall,
                nodes: records.nodes as f64 / n,
                leaves: records.leaves as f64 / n,
                triangles: records.triangles as f64 / n,
            });
        }
    }
    print_table(&rows, &ctx.info.name, traversal.robust);
    write_csv(&args.csv, &rows)?;
    plot(&args.png, &rows, &format!("kdtrace divergence on {}", ctx.info.name))?;
    eprintln!("wrote {} and {}", args.csv.display(), args.png.display());
    Ok(())
}

fn print_table(rows: &[Row], device: &str, robust: bool) {
    println!("# kdtrace divergence: `stack` ({}) on {device}\n", if robust { "robust" } else { "plain" });
    println!(
        "| scene | rays | real ms | replay ms | ÷ real | records read ms | record B/ray | SIMD eff. descent | leaf | overall | nodes/ray | leaves/ray | tris/ray |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        println!(
            "| {} | {} {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1} | {:.0} % | {:.0} % | {:.0} % | {:.1} | {:.2} | {:.1} |",
            r.scene,
            r.rays,
            r.kind,
            r.real_s * 1e3,
            r.replay_s * 1e3,
            r.replay_s / r.real_s,
            r.read_s * 1e3,
            r.record_bytes as f64 / r.rays.max(1) as f64,
            100.0 * r.descent,
            100.0 * r.leaf,
            100.0 * r.overall,
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
        "scene,kind,rays,lanes,real_s,replay_s,records_read_s,record_bytes,simd_descent,simd_leaf,simd_overall,nodes_per_ray,leaves_per_ray,tris_per_ray"
    )?;
    for r in rows {
        writeln!(
            f,
            "{},{},{},{},{:.6e},{:.6e},{:.6e},{},{:.4},{:.4},{:.4},{:.3},{:.3},{:.3}",
            r.scene,
            r.kind,
            r.rays,
            r.lanes,
            r.real_s,
            r.replay_s,
            r.read_s,
            r.record_bytes,
            r.descent,
            r.leaf,
            r.overall,
            r.nodes,
            r.leaves,
            r.triangles
        )?;
    }
    Ok(())
}

/// Bars per scene and kind: the replay's and the records read's time as shares
/// of the real kernel's, beside the SIMD efficiency.
fn plot(path: &std::path::Path, rows: &[Row], title: &str) -> Result<()> {
    use plotters::prelude::*;
    kdtrace::bench::plot::ensure_font()?;
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (160 * rows.len().max(1) as u32 + 200, 480)).into_drawing_area();
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
                true => rows.get(x.round() as usize).map_or(String::new(), |r| format!("{} {}", r.scene, r.kind)),
                false => String::new(),
            })
            .y_desc("share of the real kernel's time / SIMD efficiency")
            .draw()?;
        let series = [("replay ÷ real", RED), ("records read ÷ real", BLUE), ("SIMD efficiency (overall)", GREEN)];
        for (s, (label, color)) in series.into_iter().enumerate() {
            let bars = rows.iter().enumerate().map(|(i, r)| {
                let value = match s {
                    0 => r.replay_s / r.real_s,
                    1 => r.read_s / r.real_s,
                    _ => r.overall,
                };
                let x0 = i as f64 - 0.34 + 0.23 * s as f64;
                Rectangle::new([(x0, 0.0), (x0 + 0.2, value.min(1.1))], color.filled())
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
