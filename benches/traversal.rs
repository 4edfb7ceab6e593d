//! CPU traversal benchmark: the CPU twins of every traversal (rayon over rays),
//! and Intel Embree with `--features embree`, on the benchmark matrix's ray kinds
//! (camera, shadow, reflection, diffuse, random) — `kdtrace bench`'s matrix
//! without the Vulkan device. Each cell is judged against the exact reference on
//! a sample while it is timed; a serious error of a robust traversal fails the run.
//!
//! ```text
//! cargo bench --bench traversal                          # teapot and the Cornell box
//! cargo bench --bench traversal -- --scenes bunny,dragon_200k --size 256x192 --repeat 5
//! ```

use std::path::PathBuf;

use kdtrace::bench::matrix::expand_traversals;
use kdtrace::bench::{report, run_scene, MatrixOptions, RayKind};
use kdtrace::scene::{Camera, Scene};

fn main() {
    let mut scenes = vec!["teapot".to_string(), "cornell_box".to_string()];
    let mut options = MatrixOptions {
        width: 128,
        height: 96,
        random: 20_000,
        repeat: 3,
        reference_sample: 200,
        traversals: Vec::new(),
        orders: vec![kdtrace::trace::RayOrder::AsGiven],
        cpu_traversals: expand_traversals("all", &[1, 3, 8], &[1], &[true, false], None).expect("traversals"),
        builders: vec!["default".into()],
        kinds: RayKind::ALL.to_vec(),
        embree: cfg!(feature = "embree"),
        ray_query: false,
        seed: 1,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--scenes" => scenes = it.next().unwrap_or_default().split(',').map(String::from).collect(),
            "--repeat" => options.repeat = it.next().and_then(|s| s.parse().ok()).unwrap_or(3).max(1),
            "--size" => {
                let s = it.next().unwrap_or_default();
                let (w, h) = s.split_once('x').expect("--size WxH");
                (options.width, options.height) = (w.parse().expect("width"), h.parse().expect("height"));
            }
            // cargo bench passes --bench; ignore what we do not know.
            _ => {}
        }
    }
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes");
    println!("rayon threads: {}; camera rays {}x{}", rayon::current_num_threads(), options.width, options.height);
    let mut cells = Vec::new();
    for name in &scenes {
        let path = dir.join(format!("{name}.obj"));
        let Ok(scene) = Scene::load(&path) else {
            eprintln!("{name}: not found (tools/fetch-scenes)");
            continue;
        };
        let json = dir.join("cameras.json");
        let camera =
            Camera::from_cameras_json(&json, name).ok().flatten().unwrap_or_else(|| Camera::frame(&scene.bounds));
        cells.extend(run_scene(None, name, &scene, &camera, &options, |_| {}).expect("the CPU matrix"));
    }
    println!("\n{}", report::markdown_table(&cells));
    let serious: Vec<String> = cells
        .iter()
        .filter(|c| c.tally.serious() > 0 && c.traversal.is_some_and(|t| t.robust))
        .map(|c| format!("{} {}", c.label(), c.kind))
        .collect();
    assert!(serious.is_empty(), "serious errors of robust traversals: {serious:?}");
}
