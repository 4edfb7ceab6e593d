//! glTF 2.0 scenes (`.gltf` with external or `data:` buffers, `.glb`), feature
//! `gltf`: the default scene's nodes with their transforms (world = parent ×
//! local), each mesh primitive a [`Geometry`] placed by its node, the first
//! perspective camera. Through [`Scene::from_geometries`], so the numbering is
//! the same: `prim_id` runs over the placed primitives in node order (depth
//! first, children after their parent), each in its own triangle order.
//! Geometry id: the primitive's number over all meshes in file order (mesh by
//! mesh, primitive by primitive); instance id: the node's index in the file.
//!
//! Materials: `baseColorFactor` as the diffuse colour, `emissiveFactor` ×
//! `KHR_materials_emissive_strength` as the emission; textures are ignored.
//! Triangle strips and fans become triangle lists; points and lines are skipped
//! with a warning.

use std::path::Path;

use glam::{Affine3A, Mat4, Vec3};

use super::text::scene_error;
use super::{Camera, Geometry, Indices, Material, Scene};
use crate::error::{Error, Result};

/// A placed primitive: geometry id, instance id, material, transform, positions, indices.
type Placed = (u32, u32, u32, Affine3A, Vec<Vec3>, Vec<u32>);

/// Loads a `.gltf` or `.glb` file (see the module docs).
pub(super) fn load(path: &Path) -> Result<Scene> {
    let (data, materials, camera) = load_placed(path)?;
    let geometries = geometries_of(&data);
    let mut scene = Scene::from_geometries(&geometries, materials).map_err(|e| match e {
        Error::InvalidInput(m) => scene_error(path, None, m),
        e => e,
    })?;
    scene.path = Some(path.to_path_buf());
    scene.camera = camera;
    Ok(scene)
}

/// The placed primitives of a `.gltf` or `.glb` file as two-level input: each
/// mesh primitive once (its geometry id; object space), placed by its nodes
/// (instance id: the node's index), and the ranges its placements take in the
/// flattened numbering of [`load`].
pub(super) fn load_two_level(
    path: &Path,
    config: &crate::kdtree::BuildConfig,
) -> Result<(crate::twolevel::TwoLevelScene, Vec<super::GeometryRange>)> {
    let (data, _, _) = load_placed(path)?;
    crate::twolevel::TwoLevelScene::from_geometries(&geometries_of(&data), config).map_err(|e| match e {
        Error::InvalidInput(m) => scene_error(path, None, m),
        e => e,
    })
}

/// The placed primitives as geometries (borrowing `data`).
fn geometries_of(data: &[Placed]) -> Vec<Geometry<'_>> {
    data.iter()
        .map(|(id, instance, material, transform, positions, indices)| {
            let g = Geometry::new(*id, positions)
                .with_indices(Indices::U32(indices))
                .with_instance_id(*instance)
                .with_material(*material);
            if *transform == Affine3A::IDENTITY {
                g
            } else {
                g.with_transform(*transform)
            }
        })
        .collect()
}

/// The file's placed primitives, materials and first perspective camera.
fn load_placed(path: &Path) -> Result<(Vec<Placed>, Vec<Material>, Option<Camera>)> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    let err = |message: String| scene_error(path, None, message);
    let file = gltf::Gltf::from_slice(&bytes).map_err(|e| err(format!("not a valid glTF 2.0 file: {e}")))?;
    let doc = &file.document;

    let mut buffers = Vec::new();
    for b in doc.buffers() {
        let data = match b.source() {
            gltf::buffer::Source::Bin => file
                .blob
                .clone()
                .ok_or_else(|| err(format!("buffer {} names the GLB chunk, which is missing", b.index())))?,
            gltf::buffer::Source::Uri(uri) => {
                buffer_from_uri(path, uri).map_err(|m| err(format!("buffer {}: {m}", b.index())))?
            }
        };
        if data.len() < b.length() {
            return Err(err(format!("buffer {} holds {} bytes, {} declared", b.index(), data.len(), b.length())));
        }
        buffers.push(data);
    }

    let mut materials: Vec<Material> = doc
        .materials()
        .map(|m| {
            let pbr = m.pbr_metallic_roughness();
            let [r, g, b, _] = pbr.base_color_factor();
            let strength = m.emissive_strength().unwrap_or(1.0);
            Material {
                name: m.name().map_or_else(|| format!("material{}", m.index().unwrap_or(0)), str::to_string),
                kd: Vec3::new(r, g, b),
                ke: Vec3::from(m.emissive_factor()) * strength,
                ..Material::default()
            }
        })
        .collect();
    let default_material = materials.len() as u32;
    materials.push(Material::default());

    // The first geometry id of each mesh: primitives are numbered over all meshes.
    let mut first_geometry = Vec::new();
    let mut next = 0u32;
    for mesh in doc.meshes() {
        first_geometry.push(next);
        next += mesh.primitives().len() as u32;
    }

    let scene =
        doc.default_scene().or_else(|| doc.scenes().next()).ok_or_else(|| err("the file has no scene".into()))?;
    // (node, world transform) depth first, children after their parent.
    let mut placed = Vec::new();
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    stack.reverse();
    let mut visited = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visited += 1;
        if visited > doc.nodes().len() * 4 + 16 {
            return Err(err("the node hierarchy has a cycle".into()));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        placed.push((node.clone(), world));
        let children: Vec<_> = node.children().collect();
        for child in children.into_iter().rev() {
            stack.push((child, world));
        }
    }

    let mut camera = None;
    // Owned positions and indices per placed primitive, then geometries borrowing them.
    let mut data: Vec<Placed> = Vec::new();
    for (node, world) in &placed {
        if let (None, Some(cam)) = (&camera, node.camera()) {
            if let gltf::camera::Projection::Perspective(p) = cam.projection() {
                let eye = world.transform_point3(Vec3::ZERO);
                let forward = world.transform_vector3(Vec3::NEG_Z);
                let up = world.transform_vector3(Vec3::Y);
                if eye.is_finite() && forward.is_finite() && forward != Vec3::ZERO {
                    camera =
                        Some(Camera { eye, target: eye + forward.normalize(), up, fov_deg: p.yfov().to_degrees() });
                }
            }
        }
        let Some(mesh) = node.mesh() else { continue };
        let transform = Affine3A::from_mat4(*world);
        for prim in mesh.primitives() {
            let geometry_id = first_geometry[mesh.index()] + prim.index() as u32;
            let what = || format!("mesh {} primitive {} (node {})", mesh.index(), prim.index(), node.index());
            let mode = prim.mode();
            use gltf::mesh::Mode;
            if matches!(mode, Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip) {
                eprintln!("warning: {}: {} is {mode:?}, not triangles; skipped", path.display(), what());
                continue;
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let positions: Vec<Vec3> = reader
                .read_positions()
                .ok_or_else(|| err(format!("{} has no POSITION data", what())))?
                .map(Vec3::from)
                .collect();
            let list: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..positions.len() as u32).collect(),
            };
            let indices = match mode {
                Mode::TriangleStrip => strip_to_list(&list),
                Mode::TriangleFan => fan_to_list(&list),
                _ => list,
            };
            let material = prim.material().index().map_or(default_material, |i| i as u32);
            data.push((geometry_id, node.index() as u32, material, transform, positions, indices));
        }
    }
    Ok((data, materials, camera))
}

/// The bytes of a buffer URI: a `data:` URI in base64, or a file relative to
/// the glTF file (percent-encoded).
fn buffer_from_uri(gltf_path: &Path, uri: &str) -> std::result::Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest.split_once(";base64,").ok_or("a data: URI that is not base64")?;
        return base64_decode(payload).ok_or_else(|| "malformed base64 in a data: URI".to_string());
    }
    if uri.contains("://") {
        return Err(format!("URI {uri:?}: only relative file names and data: URIs are read"));
    }
    let name = percent_decode(uri).ok_or_else(|| format!("malformed percent-encoding in {uri:?}"))?;
    let file = gltf_path.parent().unwrap_or(Path::new(".")).join(name);
    std::fs::read(&file).map_err(|e| format!("{}: {e}", file.display()))
}

fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Standard base64 (RFC 4648, `=` padding optional); `None` on a bad character.
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let s = s.trim_end_matches('=').as_bytes();
    if s.len() % 4 == 1 {
        return None;
    }
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    for chunk in s.chunks(4) {
        let mut acc = 0u32;
        for &c in chunk {
            acc = (acc << 6) | value(c)?;
        }
        acc <<= 6 * (4 - chunk.len() as u32);
        let n = chunk.len() * 3 / 4;
        out.extend_from_slice(&acc.to_be_bytes()[1..1 + n]);
    }
    Some(out)
}

/// A triangle strip's triangles, each wound like the first.
fn strip_to_list(strip: &[u32]) -> Vec<u32> {
    let mut out = Vec::new();
    for i in 2..strip.len() {
        let (a, b, c) = (strip[i - 2], strip[i - 1], strip[i]);
        if i % 2 == 0 {
            out.extend([a, b, c]);
        } else {
            out.extend([b, a, c]);
        }
    }
    out
}

/// A triangle fan's triangles.
fn fan_to_list(fan: &[u32]) -> Vec<u32> {
    (2..fan.len()).flat_map(|i| [fan[0], fan[i - 1], fan[i]]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_and_strips() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert_eq!(base64_decode("AAECAw==").unwrap(), [0, 1, 2, 3]);
        assert!(base64_decode("a*==").is_none());
        assert_eq!(percent_decode("a%20b.bin").unwrap(), "a b.bin");
        assert_eq!(strip_to_list(&[0, 1, 2, 3]), [0, 1, 2, 2, 1, 3]);
        assert_eq!(fan_to_list(&[0, 1, 2, 3]), [0, 1, 2, 0, 2, 3]);
    }
}
