//! Reading OBJ and MTL files.
//!
//! The OBJ geometry goes through an own single pass over the lines rather than
//! through tobj. tobj 4.0.5 triangulates in the right order (fans
//! `(a0,a1,a2), (a0,a2,a3), …`, models in file order: the integration tests
//! compare the two), but on bad input it reports no line, turns 1- and 2-vertex
//! faces and `l` polylines into triangles, and panics on an out-of-range
//! negative texture-coordinate index. The pass here checks every statement it
//! uses and names the line of the first problem.
//!
//! MTL files go through tobj after a check of the statements on which tobj
//! would fail or panic (`Kd 1 1` panics inside tobj), so that errors name a line.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::Vec3;

use super::text::{as_text, scene_error};
use super::Material;
use crate::error::Result;

/// `ObjFile::usemtl` of a triangle that comes before any `usemtl`.
pub(crate) const NO_USEMTL: u32 = u32::MAX;

/// The geometry of an OBJ file, triangles numbered in face order: an indexed
/// mesh, which `Scene::load` hands to `Scene::from_geometries` as one
/// [`Geometry`](super::Geometry) like any other.
#[derive(Debug, Default)]
pub(crate) struct ObjFile {
    /// Every `v` statement's position, in file order.
    pub positions: Vec<Vec3>,
    /// Every face fanned into triangles, in the order the faces appear: three
    /// indices into `positions` per triangle.
    pub indices: Vec<u32>,
    /// Per triangle, the index into `usemtl_names` of the `usemtl` in force, or `NO_USEMTL`.
    pub usemtl: Vec<u32>,
    /// The distinct names given to `usemtl`, in order of first use.
    pub usemtl_names: Vec<String>,
    /// The `mtllib` arguments with their (1-based) lines.
    pub mtllibs: Vec<(String, usize)>,
}

impl ObjFile {
    /// Triangles of the faces.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The triangles' corners (tests).
    #[cfg(test)]
    fn triangles(&self) -> Vec<[Vec3; 3]> {
        self.indices.chunks(3).map(|t| [0, 1, 2].map(|k| self.positions[t[k] as usize])).collect()
    }
}

/// The rest of a statement after its keyword, trimmed (names may contain spaces).
fn argument<'a>(content: &'a str, keyword: &str) -> &'a str {
    content.trim_start()[keyword.len()..].trim()
}

/// Shortens what an error message quotes from the file.
fn quote(s: &str) -> String {
    let short: String = s.chars().take(40).collect();
    format!("{short:?}")
}

/// Parses the OBJ text in `bytes`; `path` is only used in error messages.
pub(crate) fn parse_obj(path: &Path, bytes: &[u8]) -> Result<ObjFile> {
    let text = as_text(path, bytes)?;
    let mut obj = ObjFile::default();
    let mut positions: Vec<Vec3> = Vec::new();
    let mut position_lines: Vec<usize> = Vec::new();
    let (mut texcoords, mut normals) = (0usize, 0usize);
    let mut material_index: HashMap<String, u32> = HashMap::new();
    let mut current = NO_USEMTL;
    let mut face: Vec<usize> = Vec::new();

    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let err = |message: String| scene_error(path, Some(line), message);
        if raw.contains('\0') {
            return Err(err("contains NUL bytes (is this a binary file?)".into()));
        }
        let content = raw.find('#').map_or(raw, |k| &raw[..k]);
        let mut words = content.split_whitespace();
        let Some(keyword) = words.next() else { continue };
        match keyword {
            "v" => {
                let mut values = [""; 7];
                let mut n = 0;
                for w in words {
                    if n < values.len() {
                        values[n] = w;
                    }
                    n += 1;
                }
                if !matches!(n, 3 | 4 | 6) {
                    return Err(err(format!(
                        "a vertex needs 3 coordinates (x y z, optionally w or r g b), found {n} values"
                    )));
                }
                let number = |w: &str| w.parse::<f32>().map_err(|_| err(format!("bad number {}", quote(w))));
                let mut p = Vec3::new(number(values[0])?, number(values[1])?, number(values[2])?);
                // x y z w is homogeneous: divided out as tobj does; w = 0 gives a
                // non-finite vertex, reported when a face uses it. The colours of
                // x y z r g b are ignored.
                if n == 4 {
                    p /= number(values[3])?;
                }
                positions.push(p);
                position_lines.push(line);
            }
            "vt" => texcoords += 1,
            "vn" => normals += 1,
            "f" => {
                face.clear();
                for w in words {
                    let mut parts = w.split('/');
                    let v = parts.next().unwrap_or("");
                    face.push(resolve_index(v, positions.len(), "vertex").map_err(&err)?);
                    if let Some(vt) = parts.next().filter(|s| !s.is_empty()) {
                        resolve_index(vt, texcoords, "texture coordinate").map_err(&err)?;
                    }
                    if let Some(vn) = parts.next().filter(|s| !s.is_empty()) {
                        resolve_index(vn, normals, "normal").map_err(&err)?;
                    }
                    if parts.next().is_some() {
                        return Err(err(format!("bad face vertex {} (expected v, v/vt, v//vn or v/vt/vn)", quote(w))));
                    }
                }
                if face.len() < 3 {
                    return Err(err(format!("a face needs at least 3 vertices, found {}", face.len())));
                }
                for &k in &face {
                    if !positions[k].is_finite() {
                        return Err(scene_error(
                            path,
                            Some(position_lines[k]),
                            format!(
                                "vertex {} has a non-finite coordinate ({}) and is used by the face on line {line}",
                                k + 1,
                                positions[k]
                            ),
                        ));
                    }
                }
                // Fan: (a0, a1, a2), (a0, a2, a3), ...
                let index = |k: usize| {
                    u32::try_from(face[k]).map_err(|_| err(format!("vertex {} is past 2^32 vertices", face[k] + 1)))
                };
                for k in 1..face.len() - 1 {
                    obj.indices.extend([index(0)?, index(k)?, index(k + 1)?]);
                    obj.usemtl.push(current);
                }
            }
            "usemtl" => {
                let name = argument(content, keyword);
                if name.is_empty() {
                    return Err(err("usemtl without a material name".into()));
                }
                current = match material_index.get(name) {
                    Some(&k) => k,
                    None => {
                        let k = obj.usemtl_names.len() as u32;
                        material_index.insert(name.to_owned(), k);
                        obj.usemtl_names.push(name.to_owned());
                        k
                    }
                };
            }
            "mtllib" => {
                let name = argument(content, keyword);
                if name.is_empty() {
                    return Err(err("mtllib without a file name".into()));
                }
                obj.mtllibs.push((name.to_owned(), line));
            }
            // Everything else that looks like an OBJ statement (o, g, s, l, p, vp,
            // curv, surf, ...) does not make triangles and is skipped.
            _ if keyword.starts_with(|c: char| c.is_ascii_alphabetic())
                && keyword.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') => {}
            _ => return Err(err(format!("not an OBJ statement: {}", quote(keyword)))),
        }
    }
    if obj.triangle_count() >= crate::consts::PRIM_INCOMPLETE as usize {
        return Err(scene_error(path, None, format!("too many triangles ({})", obj.triangle_count())));
    }
    obj.positions = positions;
    Ok(obj)
}

/// A 1-based (or negative, relative) OBJ index into a list of `count` elements
/// defined so far, as a 0-based index.
fn resolve_index(word: &str, count: usize, what: &str) -> std::result::Result<usize, String> {
    let i: i64 = word.parse().map_err(|_| format!("bad {what} index {}", quote(word)))?;
    let index = match i {
        0 => return Err(format!("{what} index 0 is invalid (OBJ indices start at 1)")),
        1.. => i as i128 - 1,
        _ => count as i128 + i as i128,
    };
    if index < 0 || index >= count as i128 {
        return Err(format!("{what} index {i} is out of range: {count} {what}(s) defined before this line"));
    }
    Ok(index as usize)
}

/// The files named by an `mtllib` argument, relative to the OBJ's folder: the
/// whole argument if such a file exists (names may contain spaces), else each
/// whitespace-separated word (the OBJ specification allows several files).
pub(crate) fn mtl_paths(obj_path: &Path, argument: &str) -> Vec<PathBuf> {
    let dir = obj_path.parent().unwrap_or(Path::new(""));
    let whole = dir.join(argument);
    if whole.is_file() {
        return vec![whole];
    }
    argument.split_whitespace().map(|name| dir.join(name)).collect()
}

/// Loads the materials of one MTL file. `Ok(None)` when the file cannot be read
/// (the caller warns and uses the default material); an error when it is malformed.
pub(crate) fn load_mtl(path: &Path) -> Result<Option<Vec<Material>>> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(_) => return Ok(None),
    };
    parse_mtl(path, &bytes).map(Some)
}

/// Parses MTL text: checks it, then hands it to tobj.
pub(crate) fn parse_mtl(path: &Path, bytes: &[u8]) -> Result<Vec<Material>> {
    let text = as_text(path, bytes)?;
    check_mtl(path, text)?;
    let (materials, _) = tobj::load_mtl_buf(&mut text.as_bytes())
        .map_err(|e| scene_error(path, None, format!("malformed material file: {e}")))?;
    Ok(materials.into_iter().map(Material::from_tobj).collect())
}

/// Finds the first line of an MTL file on which tobj 4.0.5 would fail or panic,
/// mirroring its statement parsing; also rejects non-finite numbers.
fn check_mtl(path: &Path, text: &str) -> Result<()> {
    for (i, raw) in text.lines().enumerate() {
        let err = |message: String| scene_error(path, Some(i + 1), message);
        let line = raw.trim();
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else { continue };
        let number = |w: Option<&str>| -> Result<f32> {
            let w = w.unwrap_or("");
            match w.parse::<f32>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(err(format!("{keyword}: bad or missing number {}", quote(w)))),
            }
        };
        match keyword {
            "Ka" | "Kd" | "Ks" | "Ke" => {
                for _ in 0..3 {
                    number(words.next())?;
                }
            }
            "Ns" | "Ni" | "d" => {
                number(words.next())?;
            }
            "illum" if words.next().and_then(|w| w.parse::<u8>().ok()).is_none() => {
                return Err(err("illum needs an illumination model number 0..255".into()));
            }
            "newmtl" | "map_Ka" | "map_Kd" | "map_Ks" | "map_Bump" | "map_bump" | "map_Ns" | "map_ns" | "map_NS"
            | "bump" | "map_d"
                if line[keyword.len()..].trim().is_empty() =>
            {
                return Err(err(format!("{keyword} needs an argument")));
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;

    fn parse(text: &str) -> Result<ObjFile> {
        parse_obj(Path::new("t.obj"), text.as_bytes())
    }

    fn error_line(text: &str) -> (Option<usize>, String) {
        match parse(text) {
            Err(Error::Scene { line, message, .. }) => (line, message),
            other => panic!("expected a scene error for {text:?}, got {other:?}"),
        }
    }

    #[test]
    fn fans_polygons_in_face_order() {
        let text = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nv 4 0 0\n\
                    f 1 2 3 4 5\nf 5 4 3\nf 2 3 4 5\n";
        let obj = parse(text).unwrap();
        let x: Vec<[f32; 3]> = obj.triangles().iter().map(|t| [t[0].x, t[1].x, t[2].x]).collect();
        let want = [[0., 1., 2.], [0., 2., 3.], [0., 3., 4.], [4., 3., 2.], [1., 2., 3.], [1., 3., 4.]];
        assert_eq!(x, want);
    }

    #[test]
    fn index_forms_and_relative_indices() {
        let text = "v 0 0 0\nv 1 0 0\nv 2 0 0\nvt 0 0\nvn 0 0 1\n\
                    f 1/1 2/1 3/1\nf 1//1 2//1 3//1\nf 1/1/1 2/1/1 3/1/1\nf -3 -2 -1\nf -3/-1/-1 2 3 # comment\n";
        let obj = parse(text).unwrap();
        assert_eq!(obj.triangle_count(), 5);
        for t in &obj.triangles() {
            assert_eq!([t[0].x, t[1].x, t[2].x], [0., 1., 2.]);
        }
    }

    #[test]
    fn homogeneous_and_coloured_vertices() {
        let obj = parse("v 2 4 6 2\nv 1 0 0 0.5 0.5 0.5\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(obj.triangles()[0][0], Vec3::new(1., 2., 3.));
    }

    #[test]
    fn usemtl_and_mtllib() {
        let text = "mtllib a b.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nusemtl red one\nf 1 2 3\n\
                    usemtl blue\nf 1 2 3\nusemtl red one\nf 1 2 3 1\n";
        let obj = parse(text).unwrap();
        assert_eq!(obj.usemtl, [NO_USEMTL, 0, 1, 0, 0]);
        assert_eq!(obj.usemtl_names, ["red one", "blue"]);
        assert_eq!(obj.mtllibs, [("a b.mtl".to_string(), 1)]);
    }

    #[test]
    fn skips_other_statements_and_crlf() {
        let text =
            "\u{feff}# c\r\no a\r\ng b c\r\ns 1\r\nl 1 2 3\r\np 1\r\nv 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n";
        assert_eq!(parse(text).unwrap().triangle_count(), 1);
    }

    #[test]
    fn errors_name_the_line() {
        let v = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        let cases: &[(String, usize, &str)] = &[
            ("v 1 2\n".into(), 1, "3 coordinates"),
            ("v 1 2 3 4 5\n".into(), 1, "3 coordinates"),
            ("v 1 x 3\n".into(), 1, "bad number"),
            (format!("{v}f 1 2 9\n"), 4, "out of range"),
            (format!("{v}f 0 1 2\n"), 4, "index 0"),
            (format!("{v}f -9 1 2\n"), 4, "out of range"),
            (format!("{v}f 1 2 -9223372036854775808\n"), 4, "out of range"),
            (format!("{v}f 1 2 99999999999999999999\n"), 4, "bad vertex index"),
            (format!("{v}f 1 2\n"), 4, "at least 3"),
            (format!("{v}f\n"), 4, "at least 3"),
            (format!("{v}f 1/1 2 3\n"), 4, "texture coordinate index 1 is out of range"),
            (format!("{v}vt 0 0\nf 1/-5 2 3\n"), 5, "out of range"),
            (format!("{v}f 1//2 2 3\n"), 4, "normal index"),
            (format!("{v}vt 0 0\nvn 0 0 1\nf 1/1/1/1 2 3\n"), 6, "bad face vertex"),
            (format!("{v}f a b c\n"), 4, "bad vertex index"),
            (format!("f 1 2 3\n{v}"), 1, "out of range"),
            (format!("v 1 nan 3\n{v}f 1 2 3\n"), 1, "non-finite"),
            (format!("{v}v 1 inf 3\nf 2 3 4\n"), 4, "non-finite"),
            (format!("{v}v 1 2 3 0\nf 2 3 4\n"), 4, "non-finite"),
            (format!("{v}usemtl\n"), 4, "usemtl"),
            ("mtllib\n".into(), 1, "mtllib"),
            ("v 0 0 0\n\0\0\0\n".into(), 2, "NUL"),
            ("v 0 0 0\n1 2 3\n".into(), 2, "not an OBJ statement"),
        ];
        for (text, line, what) in cases {
            let (got_line, message) = error_line(text);
            assert_eq!(got_line, Some(*line), "{text:?}: {message}");
            assert!(message.contains(what), "{text:?}: {message:?} lacks {what:?}");
        }
    }

    #[test]
    fn unused_non_finite_vertex_is_fine() {
        assert_eq!(parse("v nan 0 0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 2 3 4\n").unwrap().triangle_count(), 1);
    }

    #[test]
    fn invalid_utf8_names_its_line() {
        let (line, message) = match parse_obj(Path::new("t.obj"), b"v 0 0 0\n\nv \xff\xfe 0 0\n") {
            Err(Error::Scene { line, message, .. }) => (line, message),
            other => panic!("{other:?}"),
        };
        assert_eq!(line, Some(3));
        assert!(message.contains("UTF-8"));
    }

    #[test]
    fn never_panics_on_mutated_input() {
        let base: &[u8] = b"mtllib x.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\ng a\nusemtl m\nf 1/1/1 2/1/1 3/1/1\nf -1 -2 -3 1\n";
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mtl: &[u8] = b"newmtl a\nKd 1 0 0\nKe 1 2 3\nillum 3\nNs 10\nmap_Kd x.png\n";
        let alphabet = b" \n/-+.#0123456789eEfvgtnaiNIKd\0\xff";
        for round in 0..6000 {
            let mut bytes = if round % 2 == 0 { base.to_vec() } else { mtl.to_vec() };
            for _ in 0..1 + next() % 4 {
                let at = (next() % bytes.len() as u64) as usize;
                let c = alphabet[(next() % alphabet.len() as u64) as usize];
                match next() % 3 {
                    0 => bytes[at] = c,
                    1 => bytes.insert(at, c),
                    _ => {
                        bytes.remove(at);
                    }
                }
            }
            let _ = parse_obj(Path::new("t.obj"), &bytes);
            let _ = parse_mtl(Path::new("t.mtl"), &bytes);
        }
    }

    #[test]
    fn mtl_checks_what_tobj_would_panic_on() {
        let bad = |text: &str| match parse_mtl(Path::new("t.mtl"), text.as_bytes()) {
            Err(Error::Scene { line, message, .. }) => (line, message),
            other => panic!("{text:?}: {other:?}"),
        };
        assert_eq!(bad("newmtl a\nKe 5\n").0, Some(2));
        assert_eq!(bad("newmtl a\nKd 1 1\n").0, Some(2));
        assert_eq!(bad("newmtl a\nKd 1 nan 1\n").0, Some(2));
        assert_eq!(bad("newmtl a\nNs\n").0, Some(2));
        assert_eq!(bad("newmtl a\nillum 300\n").0, Some(2));
        assert_eq!(bad("newmtl\n").0, Some(1));
        assert_eq!(bad("newmtl a\nmap_Kd\n").0, Some(2));
        let m = parse_mtl(Path::new("t.mtl"), b"newmtl a\nKd 1 0 0\nKe 1 2 3\nillum 3\nNs 10\nKs 1 1 1\n").unwrap();
        assert_eq!(m.len(), 1);
        assert_eq!(m[0].ke, Vec3::new(1., 2., 3.));
    }
}
