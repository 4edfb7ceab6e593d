//! `kdtrace subgroups`: packet variants x packet widths x subgroup sizes.

use std::path::PathBuf;

use anyhow::Result;

use kdtrace::sweep::PACKET_VARIANTS;
use kdtrace::trace::Tracer;
use kdtrace::traversal::Variant;

use super::args::TreeArgs;
use super::common::{context, default_camera, load_and_build, spinner, Stages};

#[derive(clap::Args)]
pub struct SubgroupsArgs {
    /// OBJ scene file.
    pub scene: PathBuf,
    #[command(flatten)]
    pub tree: TreeArgs,
    /// Camera rays: image width and height.
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    #[arg(long, default_value_t = 192)]
    pub height: u32,
    /// Random rays.
    #[arg(long, default_value_t = 50_000)]
    pub random: usize,
    /// Traversals, comma-separated, or `all` (every variant with packets): stack |
    /// restart | push-down | short-stack | push-down-short-stack.
    #[arg(long, value_delimiter = ',', default_value = "all")]
    pub traversal: Vec<String>,
    /// Timed repetitions per cell (median reported, after a warm-up).
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// CSV output.
    #[arg(long, default_value = "subgroups.csv")]
    pub csv: PathBuf,
    /// PNG chart output.
    #[arg(long, default_value = "subgroups.png")]
    pub png: PathBuf,
}

/// `kdtrace subgroups`: the sweep over packet variants, widths and subgroup sizes.
pub fn subgroups(args: SubgroupsArgs) -> Result<()> {
    let variants: Vec<Variant> = if args.traversal.iter().any(|t| t == "all") {
        PACKET_VARIANTS.to_vec()
    } else {
        args.traversal.iter().map(|t| t.parse()).collect::<kdtrace::Result<_>>()?
    };
    kdtrace::sweep::check_variants(&variants)?;
    let (scene, tree) = load_and_build(&args.scene, &args.tree, &mut Stages::new(false))?;
    let ctx = context()?;
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles)?;
    let camera = default_camera(&args.scene, &scene)?;
    let batches = [
        ("camera", kdtrace::render::camera_rays_morton(&camera, args.width, args.height).0),
        ("random", kdtrace::raygen::random_rays(&scene.bounds, args.random, 1)),
    ];
    let bar = spinner("sweeping".into());
    let rows =
        kdtrace::sweep::run(&mut tracer, &batches, &variants, args.repeat, |what| bar.set_message(what.to_string()))?;
    bar.finish_and_clear();
    let title = format!("{} on {}", args.scene.display(), ctx.info.name);
    println!("# kdtrace subgroups {title}\n\n{}", kdtrace::sweep::markdown_table(&rows));
    kdtrace::sweep::write_csv(&args.csv, &rows)?;
    kdtrace::sweep::plot_png(&args.png, &rows, &title)?;
    eprintln!("wrote {} and {}", args.csv.display(), args.png.display());
    Ok(())
}
