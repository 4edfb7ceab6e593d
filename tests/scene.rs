//! Scene loading: the shipped scenes, face-order numbering, materials, cameras,
//! and errors on bad files (each names the file, and the line where there is one).

mod common;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;
use kdtrace::scene::{Camera, Scene};
use kdtrace::{Aabb, Error};

fn scene_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name)
}

/// A fresh folder under the system temp folder (no tempfile crate), removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("kdtrace-scene-test-{}-{n}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Writes `files` (name, bytes) into a fresh folder; returns it and the path of the first file.
fn write_files(test: &str, files: &[(&str, &[u8])]) -> (TempDir, PathBuf) {
    let dir = TempDir::new(test);
    for (name, bytes) in files {
        std::fs::write(dir.0.join(name), bytes).unwrap();
    }
    let path = dir.0.join(files[0].0);
    (dir, path)
}

/// The triangles tobj makes of an OBJ file (triangulated, models in order), for comparison.
fn tobj_triangles(path: &Path) -> Vec<[Vec3; 3]> {
    let options = tobj::LoadOptions { triangulate: true, ..Default::default() };
    let (models, _) = tobj::load_obj(path, &options).unwrap();
    let mut out = Vec::new();
    for m in &models {
        let p = |i: u32| Vec3::from_slice(&m.mesh.positions[3 * i as usize..3 * i as usize + 3]);
        for t in m.mesh.indices.chunks(3) {
            out.push([p(t[0]), p(t[1]), p(t[2])]);
        }
    }
    out
}

fn camera_bbox(name: &str) -> Aabb {
    // The bbox arrays of cameras.json, read with a plain text search to stay
    // independent of the reader under test.
    let text = std::fs::read_to_string(scene_path("cameras.json")).unwrap();
    let start = text.find(&format!("\"{name}\":")).unwrap();
    let bbox = start + text[start..].find("\"bbox\"").unwrap();
    let numbers: Vec<f32> = text[bbox + 6..]
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .filter(|s| !s.is_empty())
        .take(6)
        .map(|s| s.parse().unwrap())
        .collect();
    Aabb::new(Vec3::from_slice(&numbers[0..3]), Vec3::from_slice(&numbers[3..6]))
}

fn check_shipped(name: &str, triangles: usize) -> Scene {
    let path = scene_path(&format!("{name}.obj"));
    let scene = Scene::load(&path).unwrap();
    assert_eq!(scene.triangles.len(), triangles, "{name}");
    assert_eq!(scene.material_ids.len(), triangles);
    assert!(scene.material_ids.iter().all(|&m| (m as usize) < scene.materials.len()));
    assert_eq!(scene.path.as_deref(), Some(path.as_path()));
    assert_eq!(scene.bounds, camera_bbox(name), "{name}");
    assert_eq!(scene.triangles, tobj_triangles(&path), "{name}: numbering differs from tobj's");
    scene
}

#[test]
fn cornell_box() {
    let s = check_shipped("cornell_box", 38);
    assert_eq!(s.degenerate_count, 0);
    let names: Vec<&str> = s.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["white", "red", "green", "light", "mirror"]); // every face has a material: no default
    let light = &s.materials[3];
    assert_eq!(light.ke, Vec3::new(17.0, 12.0, 4.0));
    assert!(light.is_emissive());
    let mirror = &s.materials[4];
    assert_eq!((mirror.illum, mirror.ks, mirror.kd, mirror.ns), (3, Vec3::ONE, Vec3::ZERO, 100000.0));
    assert_eq!(s.materials[1].kd, Vec3::new(0.63, 0.065, 0.05));
    // Faces: floor, 4 ceiling pieces (white), light, back (white), right (green),
    // left (red), 5 short block (white), 5 tall block (mirror); 2 triangles each.
    let faces = [0, 0, 0, 0, 0, 3, 0, 2, 1, 0, 0, 0, 0, 0, 4, 4, 4, 4, 4];
    let want: Vec<u32> = faces.iter().flat_map(|&m| [m, m]).collect();
    assert_eq!(s.material_ids, want);
    // The light quad: f 21 22 23 24 fans into (21,22,23), (21,23,24).
    assert_eq!(
        s.triangles[10],
        [Vec3::new(343., 548.8, 227.), Vec3::new(343., 548.8, 332.), Vec3::new(213., 548.8, 332.)]
    );
    assert_eq!(
        s.triangles[11],
        [Vec3::new(343., 548.8, 227.), Vec3::new(213., 548.8, 332.), Vec3::new(213., 548.8, 227.)]
    );
}

#[test]
fn teapot() {
    let s = check_shipped("teapot", 992);
    assert_eq!(s.materials.len(), 1);
    assert_eq!(s.materials[0].name, "default");
    assert!(s.material_ids.iter().all(|&m| m == 0));
}

#[test]
fn q3_20kdm2() {
    check_shipped("q3_20kdm2", 10_786);
}

/// bunny.obj and dragon_200k.obj are fetched by tools/fetch-scenes; skipped when absent (a failure under CI).
#[test]
fn fetched_scenes_when_present() {
    for (name, triangles) in [("bunny", 69_666), ("dragon_200k", 202_520)] {
        let Some(path) = common::fetched_scene(&format!("{name}.obj")) else {
            continue;
        };
        let s = Scene::load(&path).unwrap();
        assert_eq!(s.triangles.len(), triangles, "{name}");
        assert_eq!(s.bounds, camera_bbox(name), "{name}");
        assert_eq!(s.triangles, tobj_triangles(&path), "{name}: numbering differs from tobj's");
    }
}

#[test]
fn fan_numbering_groups_and_materials() {
    let text = "mtllib m.mtl\n\
        vt 0 0\nvn 0 0 1\n\
        v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nv 4 0 0\nv 5 0 0\n\
        o first\n\
        f 1 2 3 4\n\
        usemtl a\n\
        f 1 2 3 4 5\n\
        g second\n\
        f 6 5 4\n\
        usemtl b\n\
        f -1 -2 -3 -4\n\
        usemtl a\n\
        o first\n\
        f 2/1 3/1 4/1\n\
        usemtl nosuch\n\
        f 3//1 4//1 5//1 6//1 1//1\n";
    let mtl = b"newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\nKe 0.5 0.5 0.5\n";
    let (_dir, path) = write_files("fan", &[("fan.obj", text.as_bytes()), ("m.mtl", mtl)]);
    let s = Scene::load(&path).unwrap();
    let xs: Vec<[f32; 3]> = s.triangles.iter().map(|t| [t[0].x, t[1].x, t[2].x]).collect();
    let want = [
        [0., 1., 2.], // quad 1 2 3 4
        [0., 2., 3.],
        [0., 1., 2.], // pentagon 1 2 3 4 5
        [0., 2., 3.],
        [0., 3., 4.],
        [5., 4., 3.], // triangle 6 5 4
        [5., 4., 3.], // quad -1 -2 -3 -4 = 6 5 4 3
        [5., 3., 2.],
        [1., 2., 3.], // triangle 2 3 4
        [2., 3., 4.], // pentagon 3 4 5 6 1
        [2., 4., 5.],
        [2., 5., 0.],
    ];
    assert_eq!(xs, want);
    assert_eq!(s.triangles, tobj_triangles(&path), "numbering differs from tobj's");
    assert_eq!(s.materials.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), ["a", "b", "default"]);
    assert_eq!(s.material_ids, [2, 2, 0, 0, 0, 0, 1, 1, 0, 2, 2, 2]);
    assert_eq!(s.materials[1].ke, Vec3::splat(0.5));
    assert_eq!(s.degenerate_count, 12); // all on the x axis
}

#[test]
fn missing_mtl_is_a_warning() {
    let (_dir, path) =
        write_files("nomtl", &[("a.obj", b"mtllib gone.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")]);
    let s = Scene::load(&path).unwrap();
    assert_eq!(s.materials.len(), 1);
    assert_eq!(s.materials[0].name, "default");
    assert_eq!(s.degenerate_count, 0);
    assert_eq!(s.bounds, Aabb::new(Vec3::ZERO, Vec3::new(1., 1., 0.)));
}

#[test]
fn malformed_mtl_is_an_error() {
    let (_dir, path) = write_files(
        "badmtl",
        &[
            ("a.obj", b"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
            ("bad.mtl", b"newmtl a\nKd 1 1 1\nKe 5\n"),
        ],
    );
    let e = Scene::load(&path).unwrap_err();
    assert!(matches!(e, Error::Scene { line: Some(3), .. }), "{e:?}");
    assert!(e.to_string().contains("bad.mtl:3"), "{e}");
}

/// Writes `bytes` as a scene file named `file` and checks that loading fails
/// with a message holding the file name, `:line` when given, and `what`.
fn assert_scene_error(file: &str, bytes: &[u8], line: Option<usize>, what: &str) {
    let (_dir, path) = write_files("bad", &[(file, bytes)]);
    let e = Scene::load(&path).expect_err(file);
    let message = e.to_string();
    match &e {
        Error::Scene { path: p, line: l, .. } => {
            assert_eq!(p, &path, "{message}");
            assert_eq!(*l, line, "{file}: {message}");
        }
        other => panic!("{file}: expected Error::Scene, got {other:?}"),
    }
    assert!(message.contains(file), "{message:?} lacks the file name");
    if let Some(line) = line {
        assert!(message.contains(&format!("{file}:{line}:")), "{message:?} lacks the line");
    }
    assert!(message.contains(what), "{message:?} lacks {what:?}");
}

#[test]
fn bad_files_give_errors_naming_file_and_line() {
    let mut garbage = Vec::new();
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    for _ in 0..4096 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        garbage.push((x >> 24) as u8);
    }
    let (_dir, path) = write_files("g", &[("garbage.obj", &garbage)]);
    assert!(matches!(Scene::load(&path), Err(Error::Scene { .. })));
    assert_scene_error("zeros.obj", &[0u8; 1000], Some(1), "NUL");
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let cases: Vec<(&str, String, Option<usize>, &str)> = vec![
        ("few.obj", format!("{tri}v 1 2\nf 1 2 3\n"), Some(4), "3 coordinates"),
        ("nan.obj", format!("{tri}v 1 nan 3\nf 1 2 4\n"), Some(4), "non-finite"),
        ("inf.obj", format!("{tri}\nv 1 inf 3\nf 4 1 2\n"), Some(5), "non-finite"),
        ("range.obj", format!("{tri}f 1 2 9\n"), Some(4), "out of range"),
        ("zero.obj", format!("{tri}f 0 1 2\n"), Some(4), "index 0"),
        ("negative.obj", format!("{tri}f -9 1 2\n"), Some(4), "out of range"),
        ("two.obj", format!("{tri}f 1 2\n"), Some(4), "at least 3"),
        ("number.obj", format!("{tri}v 1 2 3x\n"), Some(4), "bad number"),
        ("empty.obj", String::new(), None, "scene has no triangles"),
        ("vertices.obj", tri.to_string(), None, "scene has no triangles"),
    ];
    for (file, text, line, what) in cases {
        assert_scene_error(file, text.as_bytes(), line, what);
    }
    let mut latin1 = format!("{tri}f 1 2 3\n# caf").into_bytes();
    latin1.push(0xe9);
    assert_scene_error("latin1.obj", &latin1, Some(5), "UTF-8");
}

#[test]
fn unreadable_files_are_io_errors() {
    let dir = TempDir::new("missing");
    let path = dir.0.join("nonexistent.obj");
    let e = Scene::load(&path).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e:?}");
    assert!(e.to_string().contains("nonexistent.obj"), "{e}");
    assert!(matches!(Scene::load(&dir.0), Err(Error::Io { .. })));
    let e = Camera::from_cameras_json(&path, "x").unwrap_err();
    assert!(matches!(e, Error::Io { .. }) && e.to_string().contains("nonexistent.obj"), "{e}");
}

#[test]
fn cameras_json() {
    let json = scene_path("cameras.json");
    let c = Camera::from_cameras_json(&json, "cornell_box").unwrap().unwrap();
    assert_eq!((c.eye, c.target, c.up), (Vec3::new(278., 273., -800.), Vec3::new(278., 273., 0.), Vec3::Y));
    assert!((c.fov_deg - 39.307648).abs() < 1e-4);
    let q3 = Camera::from_cameras_json(&json, "q3_20kdm2").unwrap().unwrap();
    assert_eq!((q3.eye, q3.up, q3.fov_deg), (Vec3::new(1504., 1248., 648.), Vec3::Z, 75.0));
    for name in ["teapot", "bunny", "dragon_200k"] {
        let c = Camera::from_cameras_json(&json, name).unwrap().unwrap();
        assert_eq!(c.fov_deg, 40.0);
    }
    assert_eq!(Camera::from_cameras_json(&json, "nosuch").unwrap(), None);
    // An entry that is not a camera object is an error, not None.
    let e = Camera::from_cameras_json(&json, "q3_20kdm2_spawns").unwrap_err();
    assert!(e.to_string().contains("cameras.json") && e.to_string().contains("q3_20kdm2_spawns"), "{e}");

    // The shipped camera sees the centre of its scene box in the image centre.
    let (o, d) = c.ray(256.0, 256.0, 512, 512);
    assert!(((c.target - o).normalize() - d).length() < 1e-5);
}

#[test]
fn bad_cameras_json() {
    let cases: &[(&str, Option<usize>, &str)] = &[
        ("{\n\"a\": {\"eye\": [0, 0, 1], \"target\": [0, 0, 0]},\n\"b\": [1, 2,, 3]}", Some(3), "JSON"),
        ("[1, 2]", None, "JSON object"),
        ("{\"a\": {\"target\": [0, 0, 0]}}", None, "eye is missing"),
        ("{\"a\": {\"eye\": [0, 0], \"target\": [0, 0, 0]}}", None, "eye must be"),
        ("{\"a\": {\"eye\": [0, 0, 1e39], \"target\": [0, 0, 0]}}", None, "finite"),
        ("{\"a\": {\"eye\": [0, 0, 1], \"target\": [0, 0, 1]}}", None, "same point"),
        ("{\"a\": {\"eye\": [0, 1, 0], \"target\": [0, 0, 0]}}", None, "parallel"),
        ("{\"a\": {\"eye\": [0, 0, 1], \"target\": [0, 0, 0], \"fov_deg\": 180}}", None, "fov_deg"),
        ("{\"a\": 5}", None, "not a camera"),
    ];
    for (text, line, what) in cases {
        let (_dir, path) = write_files("cam", &[("cameras.json", text.as_bytes())]);
        let e = Camera::from_cameras_json(&path, "a").unwrap_err();
        assert!(matches!(&e, Error::Scene { line: l, .. } if l == line), "{text}: {e:?}");
        assert!(e.to_string().contains("cameras.json") && e.to_string().contains(what), "{text}: {e}");
    }
    // Defaults: up +y, fov 40.
    let (_dir, path) = write_files("cam", &[("cameras.json", b"{\"a\": {\"eye\": [0, 0, 1], \"target\": [0, 0, 0]}}")]);
    let c = Camera::from_cameras_json(&path, "a").unwrap().unwrap();
    assert_eq!((c.up, c.fov_deg), (Vec3::Y, 40.0));
}

#[test]
fn frame_the_shipped_scenes() {
    for name in ["cornell_box", "teapot", "q3_20kdm2"] {
        let s = Scene::load(&scene_path(&format!("{name}.obj"))).unwrap();
        let c = Camera::frame(&s.bounds);
        assert_eq!(c.target, s.bounds.center());
        assert!(c.eye.z > c.target.z && c.eye.is_finite());
        // The camera is outside the box, and the centre ray points at the target.
        assert!(!(c.eye.cmpge(s.bounds.min).all() && c.eye.cmple(s.bounds.max).all()));
        let (_, d) = c.ray(320.0, 240.0, 640, 480);
        assert!(((c.target - c.eye).normalize() - d).length() < 1e-5);
    }
}

fn check_gltf_scene(s: &Scene) {
    use glam::{Mat4, Quat};
    let quad = [Vec3::new(0., 0., 0.), Vec3::new(1., 0., 0.), Vec3::new(1., 1., 0.), Vec3::new(0., 1., 0.)];
    let parent = Mat4::from_scale_rotation_translation(
        Vec3::splat(2.),
        Quat::from_xyzw(0., 0., 0.382_683_43, 0.923_879_5),
        Vec3::new(10., 0., 0.),
    );
    let child = parent * Mat4::from_translation(Vec3::new(0., 5., 0.));
    let tri = |m: Mat4, a: usize, b: usize, c: usize| -> [Vec3; 3] {
        [quad[a], quad[b], quad[c]].map(|p| m.transform_point3(p))
    };
    let expected = [
        tri(Mat4::IDENTITY, 0, 1, 2),
        tri(Mat4::IDENTITY, 0, 2, 3),
        tri(parent, 0, 1, 2),
        tri(parent, 0, 2, 3),
        tri(child, 0, 1, 2), // the strip 0 1 2 3: (0 1 2), (2 1 3)
        tri(child, 2, 1, 3),
    ];
    assert_eq!(s.triangles.len(), expected.len());
    for (i, (got, want)) in s.triangles.iter().zip(&expected).enumerate() {
        for k in 0..3 {
            assert!((got[k] - want[k]).length() < 1e-5, "triangle {i} corner {k}: {got:?} vs {want:?}");
        }
    }
    let loc = |p| s.locate(p).unwrap();
    assert_eq!((loc(1).instance_id, loc(1).geometry_id, loc(1).prim_index), (0, 0, 1));
    assert_eq!((loc(3).instance_id, loc(3).geometry_id, loc(3).prim_index), (1, 0, 1));
    assert_eq!((loc(4).instance_id, loc(4).geometry_id, loc(4).prim_index), (2, 1, 0));
    let lamp = s.material(0);
    assert_eq!((lamp.name.as_str(), lamp.kd, lamp.ke), ("lamp", Vec3::new(0.2, 0.4, 0.6), Vec3::new(4., 2., 1.)));
    assert_eq!(s.material(5).name, "default");
    let cam = s.camera.as_ref().expect("the glTF camera");
    assert_eq!(cam.eye, Vec3::new(0., 0., 10.));
    assert!((cam.target - Vec3::new(0., 0., 9.)).length() < 1e-6 && (cam.fov_deg - 0.8f32.to_degrees()).abs() < 1e-4);
}

#[test]
fn gltf_scenes_place_instances_in_node_order() {
    // Embedded (data: URI), external .bin, and GLB give the same scene.
    let (json, bin) = common::gltf_json("{}", 3);
    let embedded = json.replace(
        "\"buffers\": [{}]",
        &format!(
            r#""buffers": [{{"byteLength": 60, "uri": "data:application/octet-stream;base64,{}"}}]"#,
            common::base64(&bin)
        ),
    );
    let (_d1, p1) = write_files("gltf-embedded", &[("scene.gltf", embedded.as_bytes())]);
    check_gltf_scene(&Scene::load(&p1).unwrap());
    let external = json.replace("\"buffers\": [{}]", r#""buffers": [{"byteLength": 60, "uri": "quad%20data.bin"}]"#);
    let (_d2, p2) = write_files("gltf-external", &[("scene.gltf", external.as_bytes()), ("quad data.bin", &bin)]);
    check_gltf_scene(&Scene::load(&p2).unwrap());
    let binary = common::glb(&json.replace("\"buffers\": [{}]", r#""buffers": [{"byteLength": 60}]"#), &bin);
    let (_d3, p3) = write_files("gltf-glb", &[("scene.glb", &binary)]);
    check_gltf_scene(&Scene::load(&p3).unwrap());
}

#[test]
fn bad_gltf_files_fail_with_a_message_naming_them() {
    let (json, bin) = common::gltf_json("{}", 9);
    let bad_index = json.replace(
        "\"buffers\": [{}]",
        &format!(
            r#""buffers": [{{"byteLength": 60, "uri": "data:application/octet-stream;base64,{}"}}]"#,
            common::base64(&bin)
        ),
    );
    let missing = json.replace("\"buffers\": [{}]", r#""buffers": [{"byteLength": 60, "uri": "gone.bin"}]"#);
    let cases: [(&str, &[u8], &[&str]); 4] = [
        ("index.gltf", bad_index.as_bytes(), &["index.gltf", "geometry 0", "vertex 9"]),
        ("missing.gltf", missing.as_bytes(), &["missing.gltf", "buffer 0", "gone.bin"]),
        ("garbage.gltf", b"{ not json", &["garbage.gltf", "not a valid glTF 2.0 file"]),
        ("empty.glb", b"", &["empty.glb", "not a valid glTF 2.0 file"]),
    ];
    for (name, bytes, needles) in cases {
        let (_d, p) = write_files("gltf-bad", &[(name, bytes)]);
        let e = Scene::load(&p).unwrap_err().to_string();
        for n in needles {
            assert!(e.contains(n), "{name}: '{e}' lacks '{n}'");
        }
    }
}
