//! What several subcommands share: progress bars, stage timings, the scene and
//! its tree (built or from the tree cache), the device and the default camera.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};

use kdtrace::gpu::{ContextOptions, GpuContext};
use kdtrace::kdtree::{BuildConfig, BuildProgress, KdTree};
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::Backend;

use super::args::TreeArgs;

/// A spinner showing `message`, ticking on its own.
pub fn spinner(message: String) -> ProgressBar {
    let bar = ProgressBar::new_spinner().with_message(message);
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

/// Loads the scene and builds its tree (or loads it from the tree cache), with a
/// progress bar while that runs.
pub fn load_and_build(path: &Path, tree: &TreeArgs, stages: &mut Stages) -> Result<(Scene, KdTree)> {
    let bar = spinner(format!("loading {}", path.display()));
    let scene = Scene::load(path)?;
    stages.mark("parse and check the OBJ");
    let tree = build_tree(&bar, &scene.triangles, tree)?;
    stages.mark("kd-tree (build or cache)");
    bar.finish_and_clear();
    Ok((scene, tree))
}

/// The wall time of each stage of a command, printed on stderr with `--timings`.
pub struct Stages {
    enabled: bool,
    start: Instant,
    last: Instant,
    list: Vec<(&'static str, f64)>,
    notes: Vec<String>,
}

impl Stages {
    pub fn new(enabled: bool) -> Stages {
        let now = Instant::now();
        Stages { enabled, start: now, last: now, list: Vec::new(), notes: Vec::new() }
    }

    /// Ends the stage called `name`, which began where the previous one ended.
    pub fn mark(&mut self, name: &'static str) {
        let now = Instant::now();
        self.list.push((name, (now - self.last).as_secs_f64()));
        self.last = now;
    }

    /// Prints the stages and the total, when enabled.
    pub fn print(&self) {
        if !self.enabled {
            return;
        }
        let total = (self.last - self.start).as_secs_f64();
        eprintln!("stages (wall):");
        for (name, seconds) in &self.list {
            eprintln!("  {name:<26} {seconds:>8.3} s {:>5.1} %", 100.0 * seconds / total.max(1e-12));
        }
        eprintln!("  {:<26} {total:>8.3} s", "total");
        for note in &self.notes {
            eprintln!("  ({note})");
        }
    }

    /// A line printed after the stages (work that ran beside them).
    pub fn note(&mut self, line: String) {
        self.notes.push(line);
    }
}

/// Runs `build` (which reports to the [`BuildProgress`] it is given) on another
/// thread while `bar` shows the build's stage and the fraction of the tree done.
pub fn with_build_bar<T: Send>(bar: &ProgressBar, message: &str, build: impl FnOnce(&BuildProgress) -> T + Send) -> T {
    use kdtrace::kdtree::BuildStage;
    let progress = BuildProgress::default();
    std::thread::scope(|scope| {
        let worker = scope.spawn(|| build(&progress));
        while !worker.is_finished() {
            let stage = match progress.stage() {
                // Not building (yet): whoever runs `build` tells the bar.
                BuildStage::Waiting | BuildStage::Finished => None,
                BuildStage::Preparing => Some("preparing".to_string()),
                BuildStage::Splitting => Some(format!("{:.0} %", 100.0 * progress.fraction())),
                BuildStage::Statistics => Some("statistics".to_string()),
            };
            if let Some(stage) = stage {
                bar.set_message(format!("{message}: {stage}"));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        worker.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

/// The kd-tree over `triangles` with the chosen builder, built or loaded from
/// the tree cache, with the stage on `bar` and one line on stderr about the
/// cache file.
pub fn build_tree(bar: &ProgressBar, triangles: &[[Vec3; 3]], args: &TreeArgs) -> Result<KdTree> {
    use kdtrace::kdtree::cache::{load_or_build, CacheOutcome, Stage};
    let config = args.builder.apply(BuildConfig::default())?;
    let building = format!("building kd-tree over {} triangles", triangles.len());
    let Some(dir) = &args.tree_cache else {
        return Ok(with_build_bar(bar, &building, |p| KdTree::build_with_progress(triangles, &config, Some(p))));
    };
    let (tree, outcome) = with_build_bar(bar, &building, |p| {
        load_or_build(dir, triangles, &config, Some(p), |stage| {
            bar.set_message(match stage {
                Stage::Hashing => "hashing the triangles for the tree cache".to_string(),
                Stage::Loading => format!("loading kd-tree from {}", dir.display()),
                Stage::Building => building.clone(),
                Stage::Storing => format!("storing kd-tree in {}", dir.display()),
            })
        })
    });
    let path = outcome.path().display();
    let build = tree.stats.build_seconds;
    let message = match &outcome {
        CacheOutcome::Hit { load_seconds, .. } => {
            format!("loaded kd-tree from cache {path} in {load_seconds:.3} s (build took {build:.3} s)")
        }
        CacheOutcome::Stored { store_seconds, .. } => {
            format!("built kd-tree in {build:.3} s, stored in cache {path} in {store_seconds:.3} s")
        }
        CacheOutcome::Rebuilt { reason, .. } => {
            format!("warning: tree cache {path} rejected ({reason}); rebuilt in {build:.3} s and replaced")
        }
        CacheOutcome::StoreFailed { rejected, reason, .. } => {
            let rejected = rejected.as_ref().map_or(String::new(), |r| format!("rejected ({r}), "));
            format!("warning: tree cache {path} {rejected}not stored: {reason}")
        }
    };
    bar.suspend(|| eprintln!("{message}"));
    Ok(tree)
}

/// The headless device of `ContextOptions::from_env()`.
pub fn context() -> Result<std::sync::Arc<GpuContext>> {
    GpuContext::headless(&ContextOptions::from_env()).context("creating the Vulkan device")
}

/// The device for `backends`: with the ray-query extensions enabled when one is the ray query.
pub fn backend_context(backends: &[Backend]) -> Result<std::sync::Arc<GpuContext>> {
    let options = ContextOptions { ray_query: backends.contains(&Backend::RayQuery), ..ContextOptions::from_env() };
    GpuContext::headless(&options).context("creating the Vulkan device")
}

/// [`backend_context`] with the command line's pipeline cache loaded (and saved
/// when the context is dropped): `KDTRACE_PIPELINE_CACHE` names the file, or
/// `off`; by default `$XDG_CACHE_HOME/kdtrace` (else `~/.cache/kdtrace`) holds one
/// file per device and driver. A cache that cannot be made is a warning.
pub fn cached_context(backends: &[Backend]) -> Result<std::sync::Arc<GpuContext>> {
    let ctx = backend_context(backends)?;
    if let Some(path) = pipeline_cache_path(&ctx) {
        if let Err(e) = ctx.load_pipeline_cache(&path) {
            eprintln!("warning: no pipeline cache ({}): {e}", path.display());
        }
    }
    Ok(ctx)
}

fn pipeline_cache_path(ctx: &GpuContext) -> Option<PathBuf> {
    match std::env::var_os("KDTRACE_PIPELINE_CACHE") {
        Some(v) if v == "off" || v == "0" => return None,
        Some(v) if !v.is_empty() => return Some(PathBuf::from(v)),
        _ => {}
    }
    let dir = std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").filter(|v| !v.is_empty()).map(|h| PathBuf::from(h).join(".cache")))?;
    let key: String = format!("{}-{}", ctx.info.name, ctx.info.driver)
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '.' { c } else { '_' })
        .collect();
    Some(dir.join("kdtrace").join(format!("pipelines-{key}.bin")))
}

/// A bar counting traced rays out of `len`.
pub fn trace_bar(len: usize) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(ProgressStyle::with_template("tracing {bar:40} {pos}/{len} rays {elapsed}").unwrap());
    bar
}

/// The camera from `cameras.json` beside the scene (keyed by file stem), else the
/// scene file's own (glTF), else one framing the box.
pub fn default_camera(path: &Path, scene: &Scene) -> Result<Camera> {
    let json = path.parent().unwrap_or(Path::new(".")).join("cameras.json");
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    if json.exists() {
        if let Some(camera) = Camera::from_cameras_json(&json, &stem)? {
            return Ok(camera);
        }
    }
    Ok(scene.camera.unwrap_or_else(|| Camera::frame(&scene.bounds)))
}
