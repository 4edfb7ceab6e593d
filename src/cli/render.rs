//! `kdtrace render`: an image of a scene (or a cost heatmap), with `--compare`.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};

use kdtrace::gpu::GpuContext;
use kdtrace::kdtree::KdTree;
use kdtrace::render::{PointLight, Primary, RenderPlan, RenderSettings};
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::{Backend, TraceOptions, Tracer};
use kdtrace::traversal::Traversal;

use super::args::{choice, choices, parse_light, parse_vec3, PrimaryKind, TraversalArgs, TreeArgs};
use super::common::{cached_context, default_camera, load_and_build, trace_bar, Stages};
use super::Unfinished;

#[derive(clap::Args)]
pub struct RenderArgs {
    /// OBJ scene file.
    pub scene: PathBuf,
    /// Output PNG.
    #[arg(short, long, default_value = "out.png")]
    pub output: PathBuf,
    #[arg(long, default_value_t = 800)]
    pub width: u32,
    #[arg(long, default_value_t = 600)]
    pub height: u32,
    /// Camera position x,y,z (default: the scene's entry in cameras.json next to it, else framing the box).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<Vec3>,
    /// Point looked at, x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<Vec3>,
    /// Up vector x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    pub fov: Option<f32>,
    #[command(flatten)]
    pub traversal: TraversalArgs,
    #[command(flatten)]
    pub tree: TreeArgs,
    /// Print the wall time of every stage (OBJ, kd-tree, device, upload, render,
    /// write) on stderr.
    #[arg(long)]
    pub timings: bool,
    /// Write a per-pixel cost heatmap instead of the shaded image: nodes | triangles.
    #[arg(long)]
    pub heatmap: Option<String>,
    /// Samples per pixel (jittered by a seeded, Owen-scrambled Sobol sequence when > 1,
    /// unless --no-jitter).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Seed of the sample sequence.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Send every sample through the pixel centre instead of jittering it inside the
    /// pixel: no anti-aliasing, each pixel the radiance seen through its centre.
    #[arg(long)]
    pub no_jitter: bool,
    /// Samples recorded into one GPU submission (0: automatic, about 2^18 paths per
    /// submission, at most 64 samples); the image does not depend on it.
    #[arg(long, default_value_t = 0)]
    pub samples_per_submission: u32,
    /// Ray segments per path at most (camera ray, reflections, bounces).
    #[arg(long, default_value_t = 8)]
    pub max_depth: u32,
    /// Diffuse bounces (path-traced indirect light, next-event estimation toward emitters).
    #[arg(long, default_value_t = 0)]
    pub bounces: u32,
    /// Ambient-occlusion rays at the first diffuse hit.
    #[arg(long, default_value_t = 0)]
    pub ao: u32,
    /// Length of the ambient-occlusion rays (default: a tenth of the scene's diagonal).
    #[arg(long)]
    pub ao_radius: Option<f32>,
    /// Ambient radiance let through by ambient occlusion (default 1 without other lights, else 0.1).
    #[arg(long)]
    pub ambient: Option<f32>,
    /// A point light x,y,z[,intensity] (repeatable); the default intensity gives the
    /// scene's centre an irradiance of pi, so a white surface facing it looks white.
    #[arg(long, value_parser = parse_light, allow_hyphen_values = true)]
    pub light: Vec<(Vec3, Option<f32>)>,
    /// Radiance r,g,b of rays that leave the scene (default black, grey with the headlight).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub background: Option<Vec3>,
    /// Multiply the radiance by this before tone mapping the PNG.
    #[arg(long, default_value_t = 1.0)]
    pub exposure: f32,
    /// Also write the linear image as OpenEXR (the output itself is EXR when it ends in .exr).
    #[arg(long)]
    pub exr: Option<PathBuf>,
    /// Write the output image every N samples per pixel while rendering (progressive preview).
    #[arg(long, default_value_t = 0)]
    pub checkpoint: u32,
    /// List what the scene and options need and what the renderer skips, then render.
    #[arg(long)]
    pub explain: bool,
    /// Do not skip what the scene does not need (to measure what skipping saves).
    #[arg(long)]
    pub no_skip: bool,
    /// Also render without skipping and with the other --primary, each on a fresh
    /// tracer (pipelines compiled anew), and print what each costs, in one run.
    #[arg(long)]
    pub compare: bool,
    /// `--compare`'s converged reference: samples per pixel of the image every
    /// variant's error is measured against (default: 16 × --spp, at least 64; the
    /// same settings with another seed).
    #[arg(long)]
    pub compare_reference_spp: Option<u32>,
    /// Write the first sample's rays to this folder (camera.rays, shadow-K.rays,
    /// secondary-K.rays: 32-byte ray files), to time them with `kdtrace trace`
    /// (shadow rays with --any-hit).
    #[arg(long, value_name = "DIR")]
    pub save_rays: Option<PathBuf>,
    /// First hits: trace (camera rays) or raster (a visibility buffer drawn by a graphics pipeline).
    #[arg(long, default_value = "trace")]
    pub primary: String,
}

/// `--heatmap`: what the heatmap counts per pixel.
#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
enum Heatmap {
    Nodes,
    Triangles,
}

impl Heatmap {
    fn name(self) -> &'static str {
        match self {
            Heatmap::Nodes => "nodes",
            Heatmap::Triangles => "triangles",
        }
    }
}

/// `kdtrace render`: the image (or `--heatmap`) of the scene, written as PNG or EXR.
pub fn render(args: RenderArgs) -> Result<()> {
    if args.width == 0 || args.height == 0 || args.width > 16384 || args.height > 16384 {
        bail!("--width and --height must be in 1..=16384");
    }
    let traversal = args.traversal.parse(false)?;
    let heatmap = match args.heatmap.as_deref() {
        None => None,
        Some(h) => match choice::<Heatmap>(h) {
            Some(kind) => Some(kind),
            None => bail!("unknown --heatmap '{h}' ({})", choices::<Heatmap>()),
        },
    };
    let Some(primary) = choice::<PrimaryKind>(&args.primary) else {
        bail!("unknown --primary '{}' ({})", args.primary, choices::<PrimaryKind>());
    };
    if !(args.exposure.is_finite() && args.exposure >= 0.0) {
        bail!("--exposure must be a finite number >= 0");
    }
    let mut stages = Stages::new(args.timings);
    let (scene, tree) = load_and_build(&args.scene, &args.tree, &mut stages)?;
    let camera = camera(&args, &scene)?;
    let ctx = cached_context(&[args.traversal.backend])?;
    stages.mark("Vulkan device");
    let mut tracer = Tracer::with_backend(&ctx, args.traversal.backend, &tree, &scene.triangles)?;
    stages.mark("upload the scene");
    if let Some(kind) = heatmap {
        return render_heatmap(&args, &ctx, &mut tracer, &camera, traversal, kind);
    }

    let settings = settings(&args, &scene, traversal, primary.into());
    if args.explain {
        for line in RenderPlan::new(&scene, &settings)?.explain() {
            eprintln!("  {line}");
        }
    }
    let render_once = |tracer: &mut Tracer, settings: &RenderSettings| {
        let bar = ProgressBar::new(u64::from(settings.spp));
        bar.set_style(ProgressStyle::with_template("rendering {bar:40} {pos}/{len} sample passes {elapsed}").unwrap());
        let out = kdtrace::render::render(tracer, &scene, &camera, settings, |done, total| {
            bar.set_length(total);
            bar.set_position(done);
        });
        bar.finish_and_clear();
        out
    };
    let save = |pixels: &[Vec3]| save_image(&args, pixels);
    let out = if args.checkpoint > 0 {
        let bar = ProgressBar::new(u64::from(settings.spp));
        bar.set_style(
            ProgressStyle::with_template("rendering {bar:40} {pos}/{len} sample passes {elapsed} {msg}").unwrap(),
        );
        let out = kdtrace::render::render_progressive(
            &mut tracer,
            &scene,
            &camera,
            &settings,
            args.checkpoint,
            |done, total| {
                bar.set_length(total);
                bar.set_position(done);
            },
            |samples, pixels| {
                save(pixels).map_err(|e| kdtrace::Error::InvalidInput(format!("{e:#}")))?;
                bar.set_message(format!("(wrote {} at {samples} spp)", args.output.display()));
                Ok(())
            },
        );
        bar.finish_and_clear();
        out?
    } else {
        render_once(&mut tracer, &settings)?
    };
    if args.compare {
        let reference_spp = args.compare_reference_spp.unwrap_or((settings.spp.saturating_mul(16)).max(64));
        if reference_spp == 0 {
            bail!("--compare-reference-spp must be at least 1");
        }
        compare_renders(&ctx, args.traversal.backend, &tree, &scene, &settings, &out, reference_spp, render_once)?;
    }

    stages.mark("render (pipelines, passes)");
    let mut out = out;
    if args.explain {
        // A debug colour for pixels that lost a ray (invalid or unfinished).
        for &p in &out.bad_pixels {
            out.pixels[p] = BAD_PIXEL;
        }
    }
    save(&out.pixels)?;
    if let Some(exr) = &args.exr {
        kdtrace::render::save_exr(exr, &out.pixels, out.width, out.height)?;
    }
    stages.mark("write the image");
    print_summary(&args, &ctx, &out);
    stages.print();
    let s = &out.stats;
    if s.bad_rays > 0 {
        let what = format!(
            "ray(s) of the render (invalid or unfinished; {} pixel(s) lack their light{})",
            out.bad_pixels.len(),
            if args.explain { ", painted magenta by --explain" } else { "; --explain paints them magenta" }
        );
        return Err(Unfinished::incomplete(s.bad_rays as usize, &what).into());
    }
    Ok(())
}

/// The scene's default camera with `--eye`, `--target`, `--up` and `--fov` applied.
fn camera(args: &RenderArgs, scene: &Scene) -> Result<Camera> {
    let mut camera = default_camera(&args.scene, scene)?;
    if let Some(eye) = args.eye {
        camera.eye = eye;
    }
    if let Some(target) = args.target {
        camera.target = target;
    }
    if let Some(up) = args.up {
        camera.up = up;
    }
    if let Some(fov) = args.fov {
        if !(fov > 0.0 && fov < 180.0) {
            bail!("--fov must be in (0, 180) degrees");
        }
        camera.fov_deg = fov;
    }
    if (camera.target - camera.eye).length_squared() == 0.0
        || (camera.target - camera.eye).cross(camera.up) == Vec3::ZERO
    {
        bail!("the camera is degenerate: eye equals target, or up is parallel to the view direction");
    }
    Ok(camera)
}

/// The renderer's settings from the options. A light without an intensity
/// gives the scene's centre an irradiance of pi.
fn settings(args: &RenderArgs, scene: &Scene, traversal: Traversal, primary: Primary) -> RenderSettings {
    let mut settings = RenderSettings::new(args.width, args.height);
    settings.spp = args.spp;
    settings.seed = args.seed;
    settings.jitter = !args.no_jitter;
    settings.samples_per_submission = args.samples_per_submission;
    settings.max_depth = args.max_depth;
    settings.bounces = args.bounces;
    settings.ao_samples = args.ao;
    settings.ao_radius = args.ao_radius;
    settings.ambient = args.ambient;
    settings.background = args.background;
    settings.traversal = traversal;
    settings.skip_unneeded = !args.no_skip;
    settings.primary = primary;
    settings.save_rays = args.save_rays.clone();
    settings.lights = args
        .light
        .iter()
        .map(|&(position, intensity)| {
            let d2 = (scene.bounds.center() - position).length_squared().max(f32::MIN_POSITIVE);
            PointLight { position, intensity: Vec3::splat(intensity.unwrap_or(std::f32::consts::PI * d2)) }
        })
        .collect();
    settings
}

/// Writes `pixels` to `--output`: linear EXR when it ends in `.exr`, else tone-mapped (PNG).
fn save_image(args: &RenderArgs, pixels: &[Vec3]) -> Result<()> {
    let is_exr = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if is_exr {
        kdtrace::render::save_exr(&args.output, pixels, args.width, args.height)?;
    } else {
        let image = kdtrace::render::tone_map(pixels, args.width, args.height, args.exposure);
        image.save(&args.output).with_context(|| format!("writing {}", args.output.display()))?;
    }
    Ok(())
}

/// The one line on stderr about the render: rays, GPU times, setup and wall time.
fn print_summary(args: &RenderArgs, ctx: &GpuContext, out: &kdtrace::render::RenderOutput) {
    let s = &out.stats;
    eprint!(
        "{}: {}x{}, {} spp on {}: {} camera + {} secondary + {} shadow rays",
        args.output.display(),
        out.width,
        out.height,
        args.spp,
        ctx.info.name,
        s.camera_rays,
        s.secondary_rays,
        s.shadow_rays
    );
    if let (Some(t), Some(sh)) = (s.trace_seconds, s.shade_seconds) {
        eprint!(
            "; GPU: trace {:.1} ms ({:.2} M rays/s), shade {:.1} ms",
            t * 1e3,
            s.traced_rays() as f64 / t.max(1e-12) / 1e6,
            sh * 1e3
        );
        if let Some([raygen, shade, resolve]) = s.pass_seconds {
            eprint!(" (raygen {:.1}, shade {:.1}, resolve {:.1})", raygen * 1e3, shade * 1e3, resolve * 1e3);
        }
        // Where the trace time went: camera, shadow, secondary rays.
        let part = |name: &str, seconds: Option<f64>, rays: u64| match seconds {
            Some(t) if rays > 0 => {
                format!(" {name} {:.1} ms ({:.2} M rays/s)", t * 1e3, rays as f64 / t.max(1e-12) / 1e6)
            }
            _ => String::new(),
        };
        let camera = if s.rasterized { 0 } else { s.camera_rays };
        eprint!(
            " [trace:{}{}{}]",
            part("camera", s.trace_camera_seconds, camera),
            part("shadow", s.trace_shadow_seconds, s.shadow_rays),
            part("secondary", s.trace_secondary_seconds, s.secondary_rays)
        );
    }
    if s.rasterized {
        let time = s.raster_seconds.map_or(String::new(), |r| format!(" in {:.1} ms", r * 1e3));
        eprint!("; first hits rasterized{time} ({} edge ties)", s.raster_edge_pixels);
    }
    if s.trace_seconds.is_none() {
        eprint!("; no GPU times (timestamps missing or implausible on this device)");
    }
    eprintln!(
        "; setup {:.0} ms, render {:.0} ms wall, {} submits",
        s.setup_seconds * 1e3,
        s.render_seconds * 1e3,
        s.submits
    );
}

/// `render --compare`: the render as asked, without skipping, and with the other
/// kind of first hits, each on a fresh tracer; a table of their costs and of each
/// image's error against one converged reference (the same settings at
/// `reference_spp` with another seed), so that no row's error mixes in another
/// row's noise.
#[allow(clippy::too_many_arguments)]
fn compare_renders(
    ctx: &std::sync::Arc<GpuContext>,
    backend: Backend,
    tree: &KdTree,
    scene: &Scene,
    settings: &RenderSettings,
    first: &kdtrace::render::RenderOutput,
    reference_spp: u32,
    render_once: impl Fn(&mut Tracer, &RenderSettings) -> kdtrace::Result<kdtrace::render::RenderOutput>,
) -> Result<()> {
    eprintln!("rendering the reference for --compare: {reference_spp} spp");
    let reference = {
        let mut tracer = Tracer::with_backend(ctx, backend, tree, &scene.triangles)?;
        let reference_settings = RenderSettings {
            spp: reference_spp,
            seed: settings.seed ^ 0x5eed_f00d,
            keep_first_hits: false,
            save_rays: None,
            ..settings.clone()
        };
        render_once(&mut tracer, &reference_settings)?.pixels
    };
    let rmse = |pixels: &[Vec3]| kdtrace::bench::images::relative_rmse(pixels, &reference);
    let mut variants = vec![("as asked".to_string(), settings.clone())];
    if settings.skip_unneeded {
        variants
            .push(("--no-skip".into(), RenderSettings { skip_unneeded: false, save_rays: None, ..settings.clone() }));
    }
    let other = match settings.primary {
        Primary::Trace => ("--primary raster", Primary::Raster),
        Primary::Raster => ("--primary trace", Primary::Trace),
    };
    variants.push((other.0.into(), RenderSettings { primary: other.1, save_rays: None, ..settings.clone() }));
    let ms = |s: Option<f64>| s.map_or("-".to_string(), |s| format!("{:.1}", s * 1e3));
    eprintln!(
        "{:<18} {:>9} {:>9} {:>9} {:>9} {:>9} {:>11} {:>8}",
        "variant", "setup ms", "loop ms", "trace ms", "shade ms", "raster ms", "rays", "RMSE"
    );
    let row = |name: &str, out: &kdtrace::render::RenderOutput| {
        let s = &out.stats;
        eprintln!(
            "{:<18} {:>9.1} {:>9.1} {:>9} {:>9} {:>9} {:>11} {:>7.2}%",
            name,
            s.setup_seconds * 1e3,
            s.render_seconds * 1e3,
            ms(s.trace_seconds),
            ms(s.shade_seconds),
            ms(s.raster_seconds),
            s.rays(),
            rmse(&out.pixels) * 100.0
        );
    };
    row("as asked (first)", first);
    for (name, variant) in &variants {
        // A fresh tracer, so that the variant compiles its own pipelines.
        let mut tracer = Tracer::with_backend(ctx, backend, tree, &scene.triangles)?;
        let out = render_once(&mut tracer, variant)?;
        row(name, &out);
    }
    eprintln!(
        "(setup: pipelines and uploads; loop: the sample loop's wall time; trace/shade/raster: GPU \
         timestamps, '-' where the device gave none; RMSE: each image against one reference of \
         {reference_spp} spp with another seed, relative to its mean; that reference's own noise is \
         about the RMSE at {} spp times sqrt({} / {reference_spp}); the first variant ran twice, on the \
         command's tracer and on a fresh one)",
        settings.spp, settings.spp
    );
    Ok(())
}

/// `render --heatmap`: the per-pixel node visits or triangle tests of camera rays.
fn render_heatmap(
    args: &RenderArgs,
    ctx: &GpuContext,
    tracer: &mut Tracer,
    camera: &Camera,
    traversal: Traversal,
    kind: Heatmap,
) -> Result<()> {
    // Morton order: every aligned run of 4^k rays is a square tile, so packets hold neighbours.
    let (rays, pixels) = kdtrace::render::camera_rays_morton(camera, args.width, args.height);
    let bar = trace_bar(rays.len());
    let options = TraceOptions::counted(traversal);
    let result = tracer.trace_with_progress(&rays, &options, |n| bar.set_position(n as u64))?;
    bar.finish_and_clear();
    let counters = result.counters.context("the tracer returned no counters")?;
    let mut values = vec![0u32; pixels.len()];
    for (c, &p) in counters.iter().zip(&pixels) {
        values[p as usize] = if kind == Heatmap::Nodes { c.nodes } else { c.triangles };
    }
    let (image, max, mean) = kdtrace::render::heatmap(&values, args.width, args.height);
    eprintln!("heatmap of {} per ray ({}): mean {mean:.1}, max {max}", kind.name(), traversal.variant);
    image.save(&args.output).with_context(|| format!("writing {}", args.output.display()))?;
    eprintln!("{}: {}x{} on {}", args.output.display(), args.width, args.height, ctx.info.name);
    Ok(())
}

/// `render --explain`'s colour for pixels that lost a ray: magenta, bright enough
/// to survive tone mapping.
const BAD_PIXEL: Vec3 = Vec3::new(1e3, 0.0, 1e3);
