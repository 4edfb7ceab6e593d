//! The `kdtrace` binary end to end: render, rays, trace, stats and bad input
//! (`bench` is in tests/bench.rs).

mod common;

use std::path::PathBuf;
use std::process::Command;

use common::scene_path;

fn kdtrace(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_kdtrace")).args(args).env("KDTRACE_VALIDATION", "1").output().unwrap()
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kdtrace-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn render_writes_a_png_of_the_cornell_box() {
    let out = temp("cornell.png");
    let scene = scene_path("cornell_box.obj");
    let o = kdtrace(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "160",
        "--height",
        "120",
        "--spp",
        "4",
        "--exposure",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("validation:"), "{}", stderr(&o));
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (160, 120));
    // The left wall is red and the right wall green (Kd of the MTL).
    let left = img.get_pixel(25, 60);
    let right = img.get_pixel(135, 60);
    assert!(left[0] > left[1] + 40 && left[0] > left[2] + 40, "left wall {left:?}");
    // Under the warm light (Ke 17, 12, 4) the green wall looks olive.
    assert!(right[1] > right[0] + 20 && right[1] > right[2] + 40, "right wall {right:?}");
}

#[test]
fn rays_then_trace_writes_one_hit_per_ray() {
    let scene = scene_path("teapot.obj");
    let rays = temp("teapot.rays");
    let hits = temp("teapot.hits");
    let o = kdtrace(&["rays", scene.to_str().unwrap(), "-o", rays.to_str().unwrap(), "--kind", "random", "-n", "5000"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::metadata(&rays).unwrap().len(), 5000 * 32);
    for traversal in ["stack", "restart"] {
        let o = kdtrace(&[
            "trace",
            scene.to_str().unwrap(),
            rays.to_str().unwrap(),
            "-o",
            hits.to_str().unwrap(),
            "--traversal",
            traversal,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains("M rays/s"), "{}", stderr(&o));
        let hits = kdtrace::io::read_hits(&hits).unwrap();
        assert_eq!(hits.len(), 5000);
        assert!(hits.iter().filter(|h| h.is_hit()).count() > 500);
    }
    // The command line keeps a pipeline cache (KDTRACE_PIPELINE_CACHE names it).
    let cache = temp("pipelines.bin");
    let _ = std::fs::remove_file(&cache);
    let o = Command::new(env!("CARGO_BIN_EXE_kdtrace"))
        .args(["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", hits.to_str().unwrap()])
        .env("KDTRACE_VALIDATION", "1")
        .env("KDTRACE_PIPELINE_CACHE", &cache)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(&cache).expect("the pipeline cache file");
    assert!(bytes.len() >= 32 && bytes[..4] == 32u32.to_le_bytes(), "a Vulkan pipeline cache header");
}

#[test]
fn malformed_inputs_fail_with_a_message_naming_them() {
    let scene = scene_path("teapot.obj");
    let bad_rays = temp("bad.rays");
    std::fs::write(&bad_rays, [0u8; 33]).unwrap();
    let o = kdtrace(&["trace", scene.to_str().unwrap(), bad_rays.to_str().unwrap(), "-o", "/dev/null"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("bad.rays") && stderr(&o).contains("multiple of the 32-byte"), "{}", stderr(&o));

    let bad_obj = temp("bad.obj");
    std::fs::write(&bad_obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n").unwrap();
    let o = kdtrace(&["render", bad_obj.to_str().unwrap(), "-o", temp("x.png").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("bad.obj:4"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));

    let o = kdtrace(&["render", scene.to_str().unwrap(), "--traversal", "sideways"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("unknown traversal"), "{}", stderr(&o));
}

#[test]
fn stats_prints_json() {
    let scene = scene_path("cornell_box.obj");
    let o = kdtrace(&["stats", scene.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("\"triangles\":38"), "{text}");
    assert!(text.contains("\"nodes\":"), "{text}");
}

#[test]
fn counters_csv_heatmap_and_any_hit() {
    let scene = scene_path("teapot.obj");
    let rays = temp("teapot-cam.rays");
    let hits = temp("teapot-cam.hits");
    let csv = temp("teapot.csv");
    let o =
        kdtrace(&["rays", scene.to_str().unwrap(), "-o", rays.to_str().unwrap(), "--width", "64", "--height", "48"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = kdtrace(&[
        "trace",
        scene.to_str().unwrap(),
        rays.to_str().unwrap(),
        "-o",
        hits.to_str().unwrap(),
        "--traversal",
        "short-stack",
        "--stack-size",
        "2",
        "--counters",
        csv.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("ray,nodes,leaves,triangles,restarts,steps,drops"));
    let rows: Vec<Vec<u32>> = lines.map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 64 * 48);
    assert!(rows.iter().all(|r| r[5] >= r[2] && r[1] >= r[2]), "steps and nodes count every leaf");
    assert!(rows.iter().any(|r| r[1] == 0), "rays that miss the scene box visit no node");
    assert!(rows.iter().any(|r| r[3] > 0 && r[6] > 0), "some rays test triangles and drop stack entries");

    let closest = kdtrace::io::read_hits(&hits).unwrap();
    let sorted_hits = temp("teapot-sorted.hits");
    // Sorted on the CPU before the upload, or on the device: hits in file order either way.
    for order in ["--sort", "--device-order"] {
        let o = kdtrace(&[
            "trace",
            scene.to_str().unwrap(),
            rays.to_str().unwrap(),
            "-o",
            sorted_hits.to_str().unwrap(),
            "--traversal",
            "short-stack",
            "--stack-size",
            "2",
            order,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(kdtrace::io::read_hits(&sorted_hits).unwrap(), closest, "{order} writes hits in file order");
    }
    let o = kdtrace(&[
        "trace",
        scene.to_str().unwrap(),
        rays.to_str().unwrap(),
        "-o",
        "/dev/null",
        "--backend",
        "ray-query",
        "--device-order",
    ]);
    // (Without the driver's ray query, the error names the missing extension instead.)
    let e = stderr(&o);
    assert!(!o.status.success() && (e.contains("kd-tree backend") || e.contains("VK_KHR_ray_query")), "{e}");
    let o =
        kdtrace(&["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", hits.to_str().unwrap(), "--any-hit"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let any = kdtrace::io::read_hits(&hits).unwrap();
    assert_eq!(closest.len(), any.len());
    assert!(
        closest.iter().zip(&any).all(|(c, a)| c.is_hit() == a.is_hit()),
        "any-hit finds a hit exactly when one exists"
    );

    let o =
        kdtrace(&["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", "/dev/null", "--stack-size", "9"]);
    assert!(!o.status.success() && stderr(&o).contains("1..=8"), "{}", stderr(&o));

    let png = temp("heat.png");
    let o = kdtrace(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--width",
        "80",
        "--height",
        "60",
        "--heatmap",
        "nodes",
        "--traversal",
        "restart",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("heatmap of nodes"), "{}", stderr(&o));
    assert_eq!(image::open(&png).unwrap().to_rgb8().dimensions(), (80, 60));
}

#[test]
fn render_explains_what_it_skips_and_writes_exr() {
    let scene = scene_path("teapot.obj");
    let out = temp("teapot.png");
    let o = kdtrace(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "48",
        "--explain",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stderr(&o);
    for line in
        ["emitters: no triangle has a Ke", "mirrors: no illum-3", "any-hit pipeline is not compiled", "headlight"]
    {
        assert!(text.contains(line), "--explain lacks '{line}':\n{text}");
    }
    assert!(text.contains("0 shadow rays"), "{text}");

    // Cornell box with every pass: lights, AO, bounces, EXR output.
    let scene = scene_path("cornell_box.obj");
    let exr = temp("cornell.exr");
    let o = kdtrace(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        exr.to_str().unwrap(),
        "--width",
        "40",
        "--height",
        "30",
        "--spp",
        "2",
        "--bounces",
        "1",
        "--ao",
        "2",
        "--light",
        "278,400,200",
        "--explain",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stderr(&o);
    assert!(text.contains("next-event estimation toward them on") && text.contains("reflection rays on"), "{text}");
    let (pixels, w, h) = kdtrace::render::load_linear(&exr).unwrap();
    assert_eq!((w, h), (40, 30));
    assert!(pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    assert!(pixels.iter().any(|p| p.max_element() > 1.0), "the light's pixels should exceed 1 in a linear EXR");
}

#[test]
fn render_no_jitter_and_samples_per_submission() {
    let scene = scene_path("teapot.obj");
    let out = temp("teapot-centres.png");
    let args = ["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--width", "32", "--height", "24"];
    let o = kdtrace(&[&args[..], &["--spp", "2", "--no-jitter", "--explain"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 per pixel, all through the pixel centres"), "{}", stderr(&o));
    let o = kdtrace(&[&args[..], &["--spp", "2", "--explain", "--samples-per-submission", "1"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 per pixel, jittered"), "{}", stderr(&o));
    assert!(stderr(&o).contains(", 2 submits"), "{}", stderr(&o));
}

#[test]
fn render_compare_measures_every_variant_against_one_converged_reference() {
    let scene = scene_path("cornell_box.obj");
    let out = temp("cornell-compare.png");
    let o = kdtrace(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "48",
        "--height",
        "36",
        "--spp",
        "4",
        "--compare",
        "--compare-reference-spp",
        "128",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stderr(&o);
    assert!(!text.contains("validation:"), "{text}");
    assert!(text.contains("rendering the reference for --compare: 128 spp"), "{text}");
    // The RMSE column (the last) of each variant's row.
    let rmse = |name: &str| -> f64 {
        let line = text.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("no row '{name}':\n{text}"));
        line.split_whitespace().last().unwrap().trim_end_matches('%').parse().unwrap()
    };
    let first = rmse("as asked (first)");
    let again = rmse("as asked  ");
    let no_skip = rmse("--no-skip");
    let raster = rmse("--primary raster");
    // The same samples give the same image, so the same error; the 4-spp images
    // are noisy against the reference, not equal to it.
    assert_eq!(first, again, "{text}");
    assert_eq!(first, no_skip, "{text}");
    // (At 48×36 the lamp's anti-aliased edge pixels dominate: about 190 %.)
    assert!(first.is_finite() && first > 0.5, "{text}");
    // Rasterized first hits (one jitter per sample for the whole image) render
    // another 4-spp estimate of the same picture: an error of the same order.
    assert!(raster.is_finite() && raster > 0.25 * first && raster < 4.0 * first, "{text}");
}

#[test]
fn render_and_stats_read_gltf_with_its_camera() {
    let (json, bin) = common::gltf_json(r#"{"byteLength": 60}"#, 3);
    let scene = temp("quads.glb");
    std::fs::write(&scene, common::glb(&json, &bin)).unwrap();
    let out = temp("quads.png");
    let o =
        kdtrace(&["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--width", "40", "--height", "30"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("validation:"), "{}", stderr(&o));
    // The file's camera at (0, 0, 10) looks down -z at the unit quad of node 0
    // (emissive: Ke (4, 2, 1)), which covers the pixels right of and above the
    // centre; with a camera framing the whole scene the quad would be elsewhere.
    let img = image::open(&out).unwrap().to_rgb8();
    let lamp = img.get_pixel(22, 13);
    assert!(lamp[0] > 200, "pixel (22, 13) should see the lamp quad: {lamp:?}");
    let sky = img.get_pixel(5, 25);
    assert!(sky[0] < 50, "pixel (5, 25) should see nothing: {sky:?}");
    let o = kdtrace(&["stats", scene.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("\"triangles\":6,"), "{}", String::from_utf8_lossy(&o.stdout));
}

/// `trace --two-level` on a glTF file whose mesh two nodes place (one rotated,
/// scaled and moved) and a child's strip mesh: 2 geometries, 3 instances, and
/// the hits in the flattened scene's numbering, equal to the flattened trace's
/// but where the flattened vertices' rounding decides an edge.
#[test]
fn trace_two_level_keeps_the_scene_numbering() {
    let (json, bin) = common::gltf_json(r#"{"byteLength": 60}"#, 3);
    let scene = temp("instanced.glb");
    std::fs::write(&scene, common::glb(&json, &bin)).unwrap();
    let rays = temp("instanced.rays");
    let o =
        kdtrace(&["rays", scene.to_str().unwrap(), "-o", rays.to_str().unwrap(), "--width", "96", "--height", "72"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (flat, two) = (temp("instanced-flat.hits"), temp("instanced-two.hits"));
    let o = kdtrace(&["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", flat.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let args = ["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", two.to_str().unwrap(), "--two-level"];
    let o = kdtrace(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 geometries, 3 instances"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("validation:"), "{}", stderr(&o));
    let (flat, two) = (kdtrace::io::read_hits(&flat).unwrap(), kdtrace::io::read_hits(&two).unwrap());
    assert_eq!(flat.len(), two.len());
    let same = flat.iter().zip(&two).filter(|(a, b)| a.prim_id == b.prim_id).count();
    let prims: std::collections::BTreeSet<u32> = two.iter().filter(|h| h.is_hit()).map(|h| h.prim_id).collect();
    assert!(same * 100 >= 99 * flat.len(), "{same} of {} rays hit the same triangle", flat.len());
    assert!(prims.len() >= 2 && prims.iter().all(|&p| p < 6), "{prims:?}");
    let o = kdtrace(&["stats", scene.to_str().unwrap(), "--json", "--two-level"]);
    let json = String::from_utf8_lossy(&o.stdout);
    assert!(json.contains("\"two_level_geometries\":2,\"two_level_instances\":3"), "{json}");
    // Refused combinations say why.
    let o = kdtrace(&[&args[..], &["--counters", "c.csv"]].concat());
    assert!(!o.status.success() && stderr(&o).contains("--two-level"), "{}", stderr(&o));
    let o = kdtrace(&[&args[..], &["--traversal", "ropes"]].concat());
    assert!(!o.status.success() && stderr(&o).contains("no two-level kernel"), "{}", stderr(&o));
}

#[test]
fn render_rejects_bad_options_with_a_message() {
    let scene = scene_path("teapot.obj");
    let out = temp("bad.png");
    for (args, message) in [
        (vec!["--spp", "0"], "samples per pixel"),
        (vec!["--light", "1,2"], "x,y,z"),
        (vec!["--light", "1,2,3,-4"], "intensity"),
        (vec!["--max-depth", "0"], "max depth"),
        (vec!["--ao-radius", "0", "--ao", "2"], "radius"),
        (vec!["--primary", "rasterize"], "unknown --primary"),
        (vec!["--background", "1,nan,0"], "finite"),
    ] {
        let mut all =
            vec!["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--width", "8", "--height", "8"];
        all.extend(&args);
        let o = kdtrace(&all);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(stderr(&o).contains(message), "{args:?}: expected '{message}' in:\n{}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    }
}

/// Nothing lost (issue 17): a ray that cannot finish traversal (here a leaf of
/// 70,000 copies of one triangle, beyond lavapipe 22.x's loop budget) is written
/// as PRIM_INCOMPLETE with NaN t, the other rays' hits are written too, and
/// `trace` says how many and exits with status 3. On a device without the loop
/// cut-off both rays finish and it exits 0.
#[test]
fn trace_writes_every_hit_and_exits_3_when_rays_did_not_finish() {
    use std::fmt::Write;
    let mut obj = String::from("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 1\nv 6 5 1\nv 5 6 1\n");
    for _ in 0..70_000 {
        obj.push_str("f 1 2 3\n");
    }
    writeln!(obj, "f 4 5 6").unwrap();
    let scene = temp("stacked.obj");
    std::fs::write(&scene, obj).unwrap();
    let rays = temp("stacked.rays");
    let hits = temp("stacked.hits");
    kdtrace::io::write_rays(
        &rays,
        &[
            kdtrace::Ray::new(glam::Vec3::new(0.25, 0.25, -1.0), glam::Vec3::Z, 0.0, f32::INFINITY),
            kdtrace::Ray::new(glam::Vec3::new(5.25, 5.25, -1.0), glam::Vec3::Z, 0.0, f32::INFINITY),
        ],
    )
    .unwrap();
    let o = kdtrace(&["trace", scene.to_str().unwrap(), rays.to_str().unwrap(), "-o", hits.to_str().unwrap()]);
    let written = kdtrace::io::read_hits(&hits).unwrap();
    assert_eq!(written.len(), 2, "every ray gets a record: {}", stderr(&o));
    // The lone triangle's hit is kept whatever happened to the other ray.
    assert_eq!(written[1].prim_id, 70_000, "{}", stderr(&o));
    assert_eq!(written[1].t, 2.0);
    if written[0].prim_id == kdtrace::consts::PRIM_INCOMPLETE {
        assert!(written[0].t.is_nan());
        assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
        assert!(stderr(&o).contains("1 ray(s) (first: 0) did not finish traversal"), "{}", stderr(&o));
    } else {
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(written[0].is_hit());
    }
}

/// `render` keeps the image when rays did not finish: it counts them, exits 3,
/// and `--explain` paints their pixels magenta (lavapipe 22.x, whose loop
/// budget the 70,000-triangle leaf exceeds; elsewhere it renders and exits 0).
#[test]
fn render_counts_unfinished_rays_and_explain_paints_them() {
    let mut obj = String::from("v -1 -1 0\nv 1 -1 0\nv -1 1 0\n");
    for _ in 0..70_000 {
        obj.push_str("f 1 2 3\n");
    }
    let scene = temp("stacked-render.obj");
    std::fs::write(&scene, obj).unwrap();
    let out = temp("stacked.png");
    let args = ["--width", "16", "--height", "16", "--eye", "-0.5,-0.5,-3", "--target", "-0.5,-0.5,0", "--fov", "10"];
    let mut all = vec!["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--explain"];
    all.extend(args);
    let o = kdtrace(&all);
    let img = image::open(&out).unwrap().to_rgb8();
    let magenta = img.pixels().filter(|p| p[0] > 200 && p[1] < 50 && p[2] > 200).count();
    match o.status.code() {
        Some(3) => {
            assert!(stderr(&o).contains("did not finish traversal"), "{}", stderr(&o));
            assert!(magenta > 0, "no pixel painted: {}", stderr(&o));
        }
        Some(0) => assert_eq!(magenta, 0),
        _ => panic!("render failed: {}", stderr(&o)),
    }
}

/// `verify` exits 0 when every answer agrees or differs harmlessly, and prints
/// the node visits per category.
#[test]
fn verify_prints_node_visits_and_exits_0_when_clean() {
    let scene = scene_path("cornell_box.obj");
    let o = kdtrace(&["verify", scene.to_str().unwrap(), "--count", "32"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}{}", out, stderr(&o));
    assert!(out.contains("p99 nodes") && out.contains("far origin 1e7") && out.contains("0 incomplete"), "{out}");
}

/// `trace` writes exactly the hits the library returns, bit for bit, for a ray
/// file with invalid rays among hard ones (NaN and infinite origins, zero and NaN
/// directions, NaN bounds), robust and `--plain`; invalid rays come out as
/// PRIM_INVALID with t = NaN, and the run exits 0.
#[test]
fn trace_hits_equal_the_library_bit_for_bit() {
    use kdtrace::kdtree::traverse::{Traversal, Variant};
    use kdtrace::kdtree::{BuildConfig, KdTree};
    use kdtrace::stress::{stress_rays, Category};
    use kdtrace::trace::{TraceOptions, Tracer};
    let path = scene_path("teapot.obj");
    let scene = kdtrace::scene::Scene::load(&path).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let mut rays: Vec<kdtrace::Ray> =
        Category::ALL.iter().flat_map(|&c| stress_rays(c, &scene.triangles, &tree, 40, 5)).collect();
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    let o = glam::Vec3::new(0.1, 0.2, 0.3);
    let invalid = [
        kdtrace::Ray::new(glam::Vec3::new(nan, 0.0, 0.0), glam::Vec3::X, 0.0, inf),
        kdtrace::Ray::new(glam::Vec3::new(0.0, inf, 0.0), glam::Vec3::X, 0.0, inf),
        kdtrace::Ray::new(o, glam::Vec3::ZERO, 0.0, inf),
        kdtrace::Ray::new(o, glam::Vec3::new(0.0, nan, 1.0), 0.0, inf),
        kdtrace::Ray::new(o, glam::Vec3::Y, nan, inf),
        kdtrace::Ray::new(o, glam::Vec3::Y, 0.0, nan),
    ];
    for (i, ray) in invalid.iter().enumerate() {
        rays.insert(i * 97, *ray);
    }
    let ray_file = temp("mixed.rays");
    kdtrace::io::write_rays(&ray_file, &rays).unwrap();
    let ctx = common::context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    for (flag, robust) in [(None, true), (Some("--plain"), false)] {
        let hit_file = temp("mixed.hits");
        let mut args =
            vec!["trace", path.to_str().unwrap(), ray_file.to_str().unwrap(), "-o", hit_file.to_str().unwrap()];
        args.extend(flag);
        let o = kdtrace(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains(&format!("{} invalid", invalid.len())), "{}", stderr(&o));
        let written = kdtrace::io::read_hits(&hit_file).unwrap();
        let traversal = Traversal { robust, ..Traversal::closest(Variant::Stack) };
        let library = tracer.trace(&rays, &TraceOptions::new(traversal)).unwrap().hits;
        assert_eq!(written.len(), library.len());
        for (i, (a, b)) in written.iter().zip(&library).enumerate() {
            assert!(bytemuck::bytes_of(a) == bytemuck::bytes_of(b), "ray {i} {:?}: file {a:?}, library {b:?}", rays[i]);
        }
        for i in 0..invalid.len() {
            let h = written[i * 97];
            assert!(h.prim_id == kdtrace::consts::PRIM_INVALID && h.t.is_nan(), "ray {}: {h:?}", i * 97);
        }
    }
    drop(tracer);
    common::assert_validation_clean(&ctx);
}

/// `info` lists the device with its subgroup properties.
#[test]
fn info_lists_devices() {
    let o = kdtrace(&["info"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.starts_with("0: ") && out.contains("subgroup size"), "{out}");
}

/// `subgroups` writes its table, CSV and chart (tiny batches: a smoke test).
#[test]
fn subgroups_writes_table_csv_and_chart() {
    let (csv, png) = (temp("subgroups.csv"), temp("subgroups.png"));
    let scene = scene_path("cornell_box.obj");
    let o = kdtrace(&[
        "subgroups",
        scene.to_str().unwrap(),
        "--width",
        "16",
        "--height",
        "8",
        "--random",
        "256",
        "--repeat",
        "1",
        // Two variants (every one is 48 pipelines, 90 s under the validation layer).
        "--traversal",
        "stack,short-stack",
        "--csv",
        csv.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert!(lines.next().unwrap().starts_with("rays,subgroup_size,traversal,packet_width"));
    let rows: Vec<&str> = lines.collect();
    assert!(rows.iter().any(|r| r.starts_with("camera,")) && rows.iter().any(|r| r.starts_with("random,")), "{text}");
    assert!(rows.iter().any(|r| r.contains(",short-stack,")), "{text}");
    assert!(!rows.iter().any(|r| r.contains(",restart,")), "only the variants asked for: {text}");
    assert!(image::open(&png).unwrap().width() > 100);
    // A variant without packets is refused with a message, before any work.
    let o = kdtrace(&["subgroups", scene.to_str().unwrap(), "--traversal", "ropes"]);
    assert!(!o.status.success() && stderr(&o).contains("ropes has no packet kernel"), "{}", stderr(&o));
}

/// `divergence`: the real kernel, the replay of its control flow, the
/// memory-only kernel and the records' reads, timed per scene, kind, traversal
/// and packet width, with per-stage SIMD efficiency in (0, 1] and the twins'
/// counters; a variant without packets is refused with a message.
#[test]
fn divergence_writes_table_csv_and_chart() {
    let (csv, png) = (temp("divergence.csv"), temp("divergence.png"));
    let scene = scene_path("teapot.obj");
    let o = kdtrace(&[
        "divergence",
        scene.to_str().unwrap(),
        "--traversal",
        "stack,short-stack",
        "--packet-width",
        "1,4",
        "--width",
        "32",
        "--height",
        "24",
        "--random",
        "2000",
        "--repeat",
        "1",
        "--csv",
        csv.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no column {name}"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // 2 kinds × 2 traversals × 2 widths.
    assert_eq!(rows.len(), 8, "{text}");
    let num = |row: &Vec<&str>, name: &str| row[col(name)].parse::<f64>().unwrap();
    for row in &rows {
        for t in ["real_s", "replay_s", "records_read_s", "memory_s", "fetches_read_s"] {
            assert!(num(row, t) > 0.0, "{t}: {text}");
        }
        for e in ["simd_descent", "simd_leaf", "simd_overall", "packet_active"] {
            assert!(num(row, e) > 0.0 && num(row, e) <= 1.0, "{e}: {text}");
        }
        assert!(num(row, "nodes_per_ray") > 1.0 && num(row, "record_bytes") > 0.0, "{text}");
        // Single rays: one fetch word per node visit, an offset per ray.
        let rays = num(row, "rays");
        if row[col("packet_width")] == "1" {
            let words = (num(row, "nodes_per_ray") * rays).round() + rays + 1.0;
            assert!((num(row, "fetch_bytes") - 4.0 * words).abs() <= 4.0 * rays * 1e-3, "{text}");
        }
        // Single rays are active in every step of their own; packet lanes in some.
        assert_eq!(num(row, "packet_active") == 1.0, row[col("packet_width")] == "1", "{text}");
    }
    let find = |kind: &str, traversal: &str, w: &str| {
        rows.iter()
            .find(|r| r[col("kind")] == kind && r[col("traversal")] == traversal && r[col("packet_width")] == w)
            .unwrap_or_else(|| panic!("no row {kind} {traversal} {w}: {text}"))
    };
    // Random rays diverge more than camera rays.
    assert!(num(find("random", "stack", "1"), "simd_overall") < num(find("camera", "stack", "1"), "simd_overall"));
    assert!(num(find("random", "stack", "4"), "packet_active") < num(find("camera", "stack", "4"), "packet_active"));
    assert!(image::open(&png).unwrap().width() > 100);
    let o = kdtrace(&[
        "divergence",
        scene.to_str().unwrap(),
        "--traversal",
        "ropes",
        "--packet-width",
        "4",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains("no packet kernel"), "{}", stderr(&o));
}

/// `--builder` picks the split search on `trace` (and `stats`): each tree's
/// hits equal the library's with the same configuration, bit for bit; and
/// `--timings` prints every stage of the command.
#[test]
fn trace_builder_choice_and_stage_timings() {
    use kdtrace::kdtree::{BuildConfig, Builder, KdTree};
    use kdtrace::trace::{TraceOptions, Tracer};
    let Some(path) = common::fetched_scene("bunny.obj") else { return };
    let scene = kdtrace::scene::Scene::load(&path).unwrap();
    let ray_file = temp("bunny-builders.rays");
    let o =
        kdtrace(&["rays", path.to_str().unwrap(), "-o", ray_file.to_str().unwrap(), "--width", "48", "--height", "36"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rays = kdtrace::io::read_rays(&ray_file).unwrap();
    let ctx = common::context();
    for (name, builder) in [("sweep", Builder::Sweep), ("binned", Builder::BINNED)] {
        let config = BuildConfig { builder, ..BuildConfig::default() };
        let tree = KdTree::build(&scene.triangles, &config);
        let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
        let library = tracer.trace(&rays, &TraceOptions::default()).unwrap().hits;
        let hit_file = temp(&format!("bunny-{name}.hits"));
        let o = kdtrace(&[
            "trace",
            path.to_str().unwrap(),
            ray_file.to_str().unwrap(),
            "-o",
            hit_file.to_str().unwrap(),
            "--builder",
            name,
            "--timings",
        ]);
        let err = stderr(&o);
        assert!(o.status.success(), "{err}");
        for stage in [
            "parse and check the OBJ",
            "kd-tree",
            "wait for the device",
            "device and pipelines, beside the above",
            "upload the scene",
            "trace",
            "total",
        ] {
            assert!(err.contains(stage), "no stage '{stage}' in:\n{err}");
        }
        let written = kdtrace::io::read_hits(&hit_file).unwrap();
        assert_eq!(written.len(), library.len());
        for (i, (a, b)) in written.iter().zip(&library).enumerate() {
            assert!(bytemuck::bytes_of(a) == bytemuck::bytes_of(b), "{name}: ray {i}: file {a:?}, library {b:?}");
        }
        let o = kdtrace(&["stats", path.to_str().unwrap(), "--json", "--builder", name]);
        let text = String::from_utf8_lossy(&o.stdout);
        let nodes = format!("\"nodes\":{},", tree.nodes.len());
        assert!(text.contains(&nodes) && text.contains(&format!("\"builder\":\"{name}")), "{text}");
    }
    let o = kdtrace(&["stats", path.to_str().unwrap(), "--builder", "binned", "--bins", "1"]);
    assert!(!o.status.success() && stderr(&o).contains("--bins"), "{}", stderr(&o));
    common::assert_validation_clean(&ctx);
}

#[test]
fn morton_camera_rays_are_the_row_major_rays_reordered() {
    let scene = scene_path("teapot.obj");
    let (row, z) = (temp("teapot-row.rays"), temp("teapot-z.rays"));
    for (file, extra) in [(&row, None), (&z, Some("--morton"))] {
        let mut args =
            vec!["rays", scene.to_str().unwrap(), "-o", file.to_str().unwrap(), "--width", "37", "--height", "21"];
        args.extend(extra);
        let o = kdtrace(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let row = kdtrace::io::read_rays(&row).unwrap();
    let z = kdtrace::io::read_rays(&z).unwrap();
    let pixels = kdtrace::render::morton_pixels(37, 21);
    assert_eq!(z.len(), row.len());
    assert_ne!(z, row, "Morton order differs from row-major");
    for (ray, &p) in z.iter().zip(&pixels) {
        assert_eq!(*ray, row[p as usize]);
    }
}
