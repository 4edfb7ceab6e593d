//! `kdtrace rays`: write a ray file (camera or random rays).

use std::path::PathBuf;

use anyhow::{bail, Result};

use kdtrace::scene::Scene;

use super::args::{choice, choices};
use super::common::default_camera;

#[derive(clap::Args)]
pub struct RaysArgs {
    /// OBJ scene file (its box and camera place the rays).
    pub scene: PathBuf,
    /// Ray file to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// camera: one ray per pixel of the scene's camera; random: uniform origins in the box, uniform directions.
    #[arg(long, default_value = "camera")]
    pub kind: String,
    /// Image size for camera rays.
    #[arg(long, default_value_t = 800)]
    pub width: u32,
    #[arg(long, default_value_t = 600)]
    pub height: u32,
    /// Number of random rays.
    #[arg(short = 'n', long, default_value_t = 1_000_000)]
    pub count: usize,
    /// Seed of the random rays.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Camera rays in Morton (Z) order over the image, as `kdtrace bench` traces them
    /// (neighbouring pixels in neighbouring lanes), instead of row-major.
    #[arg(long)]
    pub morton: bool,
}

/// `--kind`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum RayKind {
    Camera,
    Random,
}

/// `kdtrace rays`: writes camera or random rays for the scene.
pub fn rays(args: RaysArgs) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    let Some(kind) = choice::<RayKind>(&args.kind) else {
        bail!("unknown --kind '{}' ({})", args.kind, choices::<RayKind>());
    };
    let rays = match kind {
        RayKind::Camera => {
            if args.width == 0 || args.height == 0 || args.width > 16384 || args.height > 16384 {
                bail!("--width and --height must be in 1..=16384");
            }
            let camera = default_camera(&args.scene, &scene)?;
            if args.morton {
                kdtrace::render::camera_rays_morton(&camera, args.width, args.height).0
            } else {
                kdtrace::render::camera_rays(&camera, args.width, args.height)
            }
        }
        RayKind::Random => kdtrace::raygen::random_rays(&scene.bounds, args.count, args.seed),
    };
    kdtrace::io::write_rays(&args.output, &rays)?;
    eprintln!("{}: {} {} rays", args.output.display(), rays.len(), args.kind);
    Ok(())
}
