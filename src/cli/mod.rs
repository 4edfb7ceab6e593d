//! The `kdtrace` command line: one module per subcommand, each a thin layer
//! over the library; [`args`] holds the options they share and [`common`] the
//! setup they share.

mod args;
mod bench;
mod common;
mod divergence;
mod info;
mod rays;
mod render;
mod stats;
mod subgroups;
mod trace;
mod verify;

use clap::{Parser, Subcommand};

use self::bench::BenchArgs;
use self::divergence::DivergenceArgs;
use self::rays::RaysArgs;
use self::render::RenderArgs;
use self::stats::StatsArgs;
use self::subgroups::SubgroupsArgs;
use self::trace::TraceArgs;
use self::verify::VerifyArgs;

#[derive(Parser)]
#[command(name = "kdtrace", version, about = "SAH kd-tree ray tracing on the GPU through Vulkan compute")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene: shadows, mirrors, ambient occlusion, path-traced diffuse light; PNG or EXR.
    Render(RenderArgs),
    /// Trace a binary ray file and write a binary hit file.
    Trace(TraceArgs),
    /// Build the kd-tree and print its statistics.
    Stats(StatsArgs),
    /// Write a ray file: camera rays or random rays for a scene.
    Rays(RaysArgs),
    /// Compare the traversal variants: rays/s, per-ray counters, hit agreement.
    Bench(BenchArgs),
    /// Sweep packet variants × packet widths × subgroup sizes: table, CSV and PNG chart.
    Subgroups(SubgroupsArgs),
    /// The real stack kernel against a replay of its control flow without fetches or arithmetic: SIMD efficiency per stage, CSV and chart.
    Divergence(DivergenceArgs),
    /// Trace hard rays (or a ray file) and compare every answer with the exact reference.
    Verify(VerifyArgs),
    /// List the Vulkan devices and their subgroup properties.
    Info,
}

/// Exit status of `trace`, `verify`, `bench` and `render` when some rays did not
/// finish traversal (their answers are marked PRIM_INCOMPLETE; the rest is written).
pub const EXIT_INCOMPLETE: u8 = 3;
/// Exit status of `verify` when it found a serious error (and every ray finished).
pub const EXIT_SERIOUS: u8 = 4;

/// A command that did its work but must exit non-zero (EXIT_INCOMPLETE, EXIT_SERIOUS).
#[derive(Debug)]
pub struct Unfinished {
    pub code: u8,
    pub message: String,
}

impl Unfinished {
    pub fn incomplete(count: usize, what: &str) -> Self {
        Unfinished {
            code: EXIT_INCOMPLETE,
            message: format!(
                "{count} {what} did not finish traversal (the step cap is {}); they are marked PRIM_INCOMPLETE",
                kdtrace::consts::MAX_TRAVERSAL_STEPS
            ),
        }
    }

    /// `incomplete` for the hits of a batch: how many and the first indices.
    pub fn from_hits(hits: &[kdtrace::Hit]) -> Option<Self> {
        let rays = kdtrace::trace::incomplete_rays(hits);
        if rays.is_empty() {
            return None;
        }
        let first: Vec<String> = rays.iter().take(10).map(|i| i.to_string()).collect();
        let more = if rays.len() > 10 { ", ..." } else { "" };
        Some(Unfinished::incomplete(rays.len(), &format!("ray(s) (first: {}{more})", first.join(", "))))
    }
}

impl std::fmt::Display for Unfinished {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Unfinished {}

/// Parses the command line, runs the subcommand and turns its result into the
/// exit status: 0, [`EXIT_INCOMPLETE`], [`EXIT_SERIOUS`], or 1 for any other error.
pub fn run() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::render(a),
        Command::Trace(a) => trace::trace(a),
        Command::Stats(a) => stats::stats(a),
        Command::Rays(a) => rays::rays(a),
        Command::Bench(a) => bench::bench(a),
        Command::Subgroups(a) => subgroups::subgroups(a),
        Command::Divergence(a) => divergence::divergence(a),
        Command::Verify(a) => verify::verify(a),
        Command::Info => info::info(),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => match e.downcast_ref::<Unfinished>() {
            Some(u) => {
                eprintln!("kdtrace: {u}");
                std::process::ExitCode::from(u.code)
            }
            None => {
                eprintln!("Error: {e:?}");
                std::process::ExitCode::FAILURE
            }
        },
    }
}
