//! Builder benchmark and tree-quality measurement (docs/BUILDER.md).
//!
//! For each scene and each builder configuration: the build time (best of
//! `--repeat` builds), the tree's statistics, its SAH cost under both published
//! cost models, and the measured traversal cost — nodes visited and triangles
//! tested per ray by the CPU twin of the stack traversal
//! ([`trace_ray`] with [`Variant::Stack`]) on the scene's camera rays and on
//! random rays. A sample of the rays is checked against the f64 brute-force
//! reference while it runs, so a fast but wrong tree cannot pass.
//!
//! ```text
//! cargo bench --bench builder                       # every scene, every config
//! cargo bench --bench builder -- --scenes teapot,bunny --configs default,pbrt-v3 --repeat 5
//! cargo bench --bench builder -- --build-only       # build times only (no tracing)
//! ```
//!
//! Scenes: the OBJ files in `scenes/` (bunny and dragon_200k come from
//! `tools/fetch-scenes`), plus two made here, deterministically, for the
//! ~900k-triangle goal: `dragon_x4` (every dragon triangle split in four at its
//! edge midpoints: 810,080 triangles) and `torus_900k` (a bumpy torus tessellated
//! into 900,000 triangles).

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use kdtrace::exact::tolerant::{agrees, Agreement};
use kdtrace::kdtree::stats::BuildStats;
use kdtrace::kdtree::traverse::{trace_ray, Counters, SceneRef, Variant};
use kdtrace::kdtree::{BuildConfig, Builder, KdTree};
use kdtrace::raygen::SplitMix64;
use kdtrace::render::camera_rays;
use kdtrace::scene::{Camera, Scene};
use kdtrace::Ray;
use rayon::prelude::*;

/// The configurations compared, by name. `default` is `BuildConfig::default()`
/// (`BuildConfig::TUNED`: K_T 30, K_I 20, b 0.1).
fn configs() -> Vec<(&'static str, BuildConfig)> {
    let wh = BuildConfig::WALD_HAVRAN;
    let pbrt = BuildConfig::PBRT_V3;
    vec![
        ("default", BuildConfig::default()),
        // The default costs with the exact sweep at every node (no binned top).
        ("sweep", BuildConfig { builder: Builder::Sweep, ..BuildConfig::TUNED }),
        // The default with a costlier traversal step: fewer nodes, faster builds.
        ("default-kt40", BuildConfig { traversal_cost: 40.0, ..BuildConfig::TUNED }),
        ("default-kt50", BuildConfig { traversal_cost: 50.0, ..BuildConfig::TUNED }),
        ("default-kt60", BuildConfig { traversal_cost: 60.0, ..BuildConfig::TUNED }),
        ("pbrt-v3", pbrt),
        ("wald-havran", wh),
        // In between: pbrt's termination and bonus with cheaper intersections.
        ("kt1-ki20-b0.5", BuildConfig { intersection_cost: 20.0, ..pbrt }),
        ("kt1-ki8-b0.5", BuildConfig { intersection_cost: 8.0, ..pbrt }),
        // Wald-Havran's ratio with other bonuses and leaf rules.
        ("kt15-ki20-b0.5", BuildConfig { empty_bonus: 0.5, ..wh }),
        ("kt15-ki20-b0", BuildConfig { empty_bonus: 0.0, ..wh }),
        ("kt10-ki20-b0.2", BuildConfig { traversal_cost: 10.0, ..wh }),
        ("kt20-ki20-b0.2", BuildConfig { traversal_cost: 20.0, ..wh }),
        ("kt30-ki20-b0.1-leaf4", BuildConfig { max_leaf_prims: 4, ..BuildConfig::TUNED }),
        ("kt40-ki20-b0.2", BuildConfig { traversal_cost: 40.0, ..wh }),
        ("kt60-ki20-b0.2", BuildConfig { traversal_cost: 60.0, ..wh }),
        ("kt40-ki20-b0.1", BuildConfig { traversal_cost: 40.0, empty_bonus: 0.1, ..wh }),
        ("kt30-ki20-b0.2", BuildConfig { empty_bonus: 0.2, ..BuildConfig::TUNED }),
        ("kt25-ki20-b0.15", BuildConfig { traversal_cost: 25.0, empty_bonus: 0.15, ..BuildConfig::TUNED }),
        ("kt20-ki20-b0.1", BuildConfig { traversal_cost: 20.0, empty_bonus: 0.1, ..wh }),
        ("kt20-ki20-b0.3", BuildConfig { traversal_cost: 20.0, empty_bonus: 0.3, ..wh }),
        ("kt15-ki20-b0.2-leaf0", BuildConfig { max_leaf_prims: 0, ..wh }),
        ("kt15-ki20-b0.2-boxclip", BuildConfig { perfect_splits: false, ..wh }),
        ("kt30-ki20-b0.1-boxclip", BuildConfig { perfect_splits: false, ..BuildConfig::TUNED }),
        ("pbrt-v3-boxclip", BuildConfig { perfect_splits: false, ..pbrt }),
    ]
}

struct Args {
    scenes: Vec<String>,
    configs: Vec<String>,
    repeat: usize,
    width: u32,
    height: u32,
    random: usize,
    check: usize,
    build_only: bool,
}

fn parse_args() -> Args {
    let mut a = Args {
        scenes: ["teapot", "q3_20kdm2", "bunny", "dragon_200k", "dragon_x4", "torus_900k"].map(String::from).to_vec(),
        configs: configs().iter().map(|(n, _)| n.to_string()).collect(),
        repeat: 3,
        width: 256,
        height: 192,
        random: 50_000,
        check: 64,
        build_only: false,
    };
    let mut it = std::env::args().skip(1);
    let list = |s: Option<String>| s.unwrap_or_default().split(',').map(String::from).collect::<Vec<_>>();
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--scenes" => a.scenes = list(it.next()),
            "--configs" => a.configs = list(it.next()),
            "--repeat" => a.repeat = it.next().and_then(|s| s.parse().ok()).unwrap_or(3).max(1),
            "--random" => a.random = it.next().and_then(|s| s.parse().ok()).unwrap_or(50_000),
            "--check" => a.check = it.next().and_then(|s| s.parse().ok()).unwrap_or(64),
            "--build-only" => a.build_only = true,
            "--size" => {
                let s = it.next().unwrap_or_default();
                let (w, h) = s.split_once('x').expect("--size WxH");
                (a.width, a.height) = (w.parse().unwrap(), h.parse().unwrap());
            }
            // cargo bench passes --bench; ignore what we do not know.
            _ => {}
        }
    }
    a
}

fn scenes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

/// Every triangle split in four at its edge midpoints.
fn subdivide(tris: &[[Vec3; 3]]) -> Vec<[Vec3; 3]> {
    let mut out = Vec::with_capacity(tris.len() * 4);
    for &[a, b, c] in tris {
        let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
        out.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    out
}

/// A torus (radii 1 and 0.35) with a bumpy tube, `2 · nu · nv` triangles.
fn torus(nu: usize, nv: usize) -> Vec<[Vec3; 3]> {
    let point = |i: usize, j: usize| {
        let u = (i % nu) as f32 / nu as f32 * std::f32::consts::TAU;
        let v = (j % nv) as f32 / nv as f32 * std::f32::consts::TAU;
        let r = 0.35 + 0.03 * (13.0 * u).sin() * (7.0 * v).cos() + 0.01 * (41.0 * u + 3.0 * v).sin();
        let ring = 1.0 + r * v.cos();
        Vec3::new(ring * u.cos(), r * v.sin(), ring * u.sin())
    };
    let mut out = Vec::with_capacity(2 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (point(i, j), point(i + 1, j), point(i + 1, j + 1), point(i, j + 1));
            out.push([a, b, c]);
            out.push([a, c, d]);
        }
    }
    out
}

/// The triangles and camera of a scene name, or `None` when its file is absent.
fn load(name: &str) -> Option<(Vec<[Vec3; 3]>, Option<Camera>)> {
    let dir = scenes_dir();
    let camera_of = |stem: &str| Camera::from_cameras_json(&dir.join("cameras.json"), stem).ok().flatten();
    match name {
        "dragon_x4" => {
            let (tris, _) = load("dragon_200k")?;
            Some((subdivide(&tris), camera_of("dragon_200k")))
        }
        "torus_900k" => Some((torus(1000, 450), None)),
        _ => {
            let path = dir.join(format!("{name}.obj"));
            if !Path::new(&path).exists() {
                return None;
            }
            let scene = Scene::load(&path).expect("loading the scene");
            Some((scene.triangles, camera_of(name)))
        }
    }
}

/// CPU seconds (user + system, all threads) of this process so far, from
/// `/proc/self/stat` (Linux; 10 ms resolution), or NaN.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<f64> = rest.split_whitespace().map(|f| f.parse().unwrap_or(f64::NAN)).collect();
    (fields.get(11).unwrap_or(&f64::NAN) + fields.get(12).unwrap_or(&f64::NAN)) / 100.0
}

/// Rays from random points of the scene box (grown by 10 %) in random directions.
fn random_rays(tree: &KdTree, count: usize) -> Vec<Ray> {
    let mut rng = SplitMix64(0x9E37_79B9_7F4A_7C15);
    let b = tree.bounds;
    let pad = b.extent() * 0.1;
    let (lo, size) = (b.min - pad, b.extent() + 2.0 * pad);
    (0..count)
        .map(|_| {
            let o = lo + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * size;
            let d = loop {
                let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
                if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
                    break v.normalize();
                }
            };
            Ray::new(o, d, 0.0, f32::INFINITY)
        })
        .collect()
}

/// Mean nodes, leaves and triangles per ray; checks every `stride`-th ray
/// against the f64 reference (panics on a real disagreement).
fn measure(scene: &SceneRef, rays: &[Ray], check: usize) -> [f64; 3] {
    let results: Vec<(kdtrace::Hit, Counters)> = rays.par_iter().map(|r| trace_ray(scene, r, Variant::Stack)).collect();
    let stride = (rays.len() / check.max(1)).max(1);
    let bad: Vec<String> = (0..rays.len())
        .into_par_iter()
        .step_by(stride)
        .filter_map(|i| match agrees(scene.triangles, &rays[i], &results[i].0) {
            Agreement::Disagree(why) => Some(format!("ray {i}: {why}")),
            _ => None,
        })
        .collect();
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    let n = rays.len().max(1) as f64;
    let sum = |f: fn(&Counters) -> u32| results.iter().map(|(_, c)| f(c) as f64).sum::<f64>() / n;
    [sum(|c| c.nodes), sum(|c| c.leaves), sum(|c| c.triangles)]
}

fn main() {
    let args = parse_args();
    let all = configs();
    println!(
        "rayon threads: {}; camera rays {}x{}, random rays {}; build time = best of {}",
        rayon::current_num_threads(),
        args.width,
        args.height,
        args.random,
        args.repeat
    );
    println!();
    println!(
        "| scene | tris | config | build s | cpu s | nodes | leaves (empty) | depth max/mean | refs/tri | tris/leaf | \
         SAH (own) | SAH W-H | SAH pbrt | scratch MiB | cam nodes | cam tris | cam N+T | rnd nodes | rnd tris | rnd N+T |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for name in &args.scenes {
        let Some((tris, camera)) = load(name) else {
            eprintln!("{name}: not found (tools/fetch-scenes)");
            continue;
        };
        for cname in &args.configs {
            let Some(&(_, config)) = all.iter().find(|(n, _)| n == cname) else {
                eprintln!("unknown config {cname}");
                continue;
            };
            let mut best = f64::INFINITY;
            let mut tree = None;
            let mut cpu = 0.0;
            for _ in 0..args.repeat {
                drop(tree.take());
                let (start, cpu_start) = (Instant::now(), cpu_seconds());
                let t = KdTree::build(&tris, &config);
                best = best.min(start.elapsed().as_secs_f64());
                cpu += cpu_seconds() - cpu_start;
                tree = Some(t);
            }
            let cpu = cpu / args.repeat as f64;
            let tree = tree.unwrap();
            tree.check(tris.len()).expect("a well-formed tree");
            let s = &tree.stats;
            let sah_under = |c: &BuildConfig| {
                BuildStats::compute(&tree, c, s.triangles, s.skipped_triangles, s.build_seconds).sah_cost
            };
            let (sah_wh, sah_pbrt) = (sah_under(&BuildConfig::WALD_HAVRAN), sah_under(&BuildConfig::PBRT_V3));
            let scratch = format!("{:.1}", s.peak_scratch_bytes as f64 / (1 << 20) as f64);
            let (cam, rnd) = if args.build_only {
                ([f64::NAN; 3], [f64::NAN; 3])
            } else {
                let scene = SceneRef::new(&tree, &tris);
                let camera = camera.unwrap_or_else(|| Camera::frame(&tree.bounds));
                let cam = measure(&scene, &camera_rays(&camera, args.width, args.height), args.check);
                let rnd = measure(&scene, &random_rays(&tree, args.random), args.check);
                (cam, rnd)
            };
            println!(
                "| {name} | {} | {cname} | {best:.3} | {cpu:.2} | {} | {} ({}) | {}/{:.1} | {:.2} | {:.2} | {:.1} | {:.1} | {:.1} | {scratch} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
                tris.len(),
                s.nodes,
                s.leaves,
                s.empty_leaves,
                s.max_depth,
                s.mean_leaf_depth,
                s.refs_per_triangle,
                s.mean_prims_per_leaf,
                s.sah_cost,
                sah_wh,
                sah_pbrt,
                cam[0],
                cam[2],
                cam[0] + cam[2],
                rnd[0],
                rnd[2],
                rnd[0] + rnd[2],
            );
        }
    }
}
