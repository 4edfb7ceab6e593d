//! Pinhole cameras: framing a box, primary rays, and `cameras.json`.

use std::path::Path;

use glam::{DVec3, Vec3};

use super::text::{as_text, line_of, scene_error};
use crate::error::{Error, Result};
use crate::geom::Aabb;

/// A pinhole camera looking from `eye` at `target`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Where the rays start.
    pub eye: Vec3,
    /// The point the image centre looks at.
    pub target: Vec3,
    /// The approximate up direction of the image (need not be orthogonal to the view).
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_deg: f32,
}

impl Camera {
    /// The field of view `frame` uses.
    pub const DEFAULT_FOV_DEG: f32 = 40.0;

    /// A camera that sees all of `bounds`: it looks at the box centre from the
    /// +z side, a little from the right and above, far enough that the box's
    /// bounding sphere fits the 40° vertical field of view; up is +y. Flat,
    /// point-like, empty, or huge boxes still give a camera with finite `eye`
    /// different from `target`.
    pub fn frame(bounds: &Aabb) -> Camera {
        let fov_deg = Self::DEFAULT_FOV_DEG;
        let (min, max) = (bounds.min.as_dvec3(), bounds.max.as_dvec3());
        let (center, mut radius) = if bounds.is_empty() || !min.is_finite() || !max.is_finite() {
            (DVec3::ZERO, 1.0)
        } else {
            (0.5 * (min + max), 0.5 * (max - min).length())
        };
        if radius <= 0.0 {
            radius = 1.0;
        }
        // Keep the eye well apart from the target in f32, however far from the origin.
        radius = radius.max(center.length() * 1e-4);
        let distance = radius / (0.5 * f64::from(fov_deg).to_radians()).sin();
        let dir = DVec3::new(0.25, 0.4, 1.0).normalize();
        let to_f32 =
            |p: DVec3| p.clamp(DVec3::splat(-f64::from(f32::MAX)), DVec3::splat(f64::from(f32::MAX))).as_vec3();
        let target = to_f32(center);
        let mut eye = to_f32(center + dir * distance);
        if eye == target {
            // Only when the box touches the largest f32: look from the other side.
            eye = to_f32(center - dir * distance);
        }
        Camera { eye, target, up: Vec3::Y, fov_deg }
    }

    /// The primary ray through image point `(px, py)`, where the image is
    /// `width` × `height` pixels, x to the right, y down, and pixel `(i, j)`
    /// covers `[i, i+1) × [j, j+1)` (its centre is `(i + 0.5, j + 0.5)`).
    /// Returns `(origin, direction)`, the direction normalized.
    pub fn ray(&self, px: f32, py: f32, width: u32, height: u32) -> (Vec3, Vec3) {
        let (forward, right, up) = self.basis();
        let (w, h) = (f64::from(width.max(1)), f64::from(height.max(1)));
        let fov = if self.fov_deg.is_finite() { f64::from(self.fov_deg).clamp(1e-3, 179.0) } else { 40.0 };
        let tan = (0.5 * fov.to_radians()).tan();
        let sx = (2.0 * f64::from(px) / w - 1.0) * tan * (w / h);
        let sy = (1.0 - 2.0 * f64::from(py) / h) * tan;
        let dir = (forward + sx * right + sy * up).normalize();
        (self.eye, dir.as_vec3())
    }

    /// The pinhole model of [`Camera::ray`] as four vectors, for shaders: the ray
    /// through image point `(px, py)` has direction
    /// `forward + sx · right + sy · up` with `sx = 2·px/width − 1` and
    /// `sy = 1 − 2·py/height`, normalized. Returns `[eye, forward, right, up]`,
    /// `right` and `up` scaled by the field of view and aspect ratio.
    pub fn pinhole(&self, width: u32, height: u32) -> [Vec3; 4] {
        let (forward, right, up) = self.basis();
        let (w, h) = (f64::from(width.max(1)), f64::from(height.max(1)));
        let fov = if self.fov_deg.is_finite() { f64::from(self.fov_deg).clamp(1e-3, 179.0) } else { 40.0 };
        let tan = (0.5 * fov.to_radians()).tan();
        [self.eye, forward.as_vec3(), (right * tan * (w / h)).as_vec3(), (up * tan).as_vec3()]
    }

    /// Orthonormal forward, right and up vectors (f64, so that far-apart eye and
    /// target do not overflow). A degenerate camera (eye = target, up parallel
    /// to the view or zero) still gets a basis.
    fn basis(&self) -> (DVec3, DVec3, DVec3) {
        let forward = (self.target.as_dvec3() - self.eye.as_dvec3()).try_normalize().unwrap_or(DVec3::NEG_Z);
        let right = match forward.cross(self.up.as_dvec3()).try_normalize() {
            Some(r) => r,
            None => forward.any_orthonormal_vector(),
        };
        (forward, right, right.cross(forward))
    }

    /// The camera for `scene_name` (an OBJ file stem such as `"teapot"`) in a
    /// `cameras.json` file: a JSON object mapping names to objects with `eye`,
    /// `target`, `up` (3 numbers each) and `fov_deg` (vertical, degrees); other
    /// keys are ignored. `up` defaults to +y and `fov_deg` to 40.
    ///
    /// `Ok(None)` when the file has no entry of that name; `Error::Io` when it
    /// cannot be read; `Error::Scene` when it is not such JSON or the entry is
    /// not a valid camera.
    pub fn from_cameras_json(path: &Path, scene_name: &str) -> Result<Option<Camera>> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        let text = as_text(path, &bytes)?;
        let root = json::parse(text)
            .map_err(|(pos, message)| scene_error(path, Some(line_of(text.as_bytes(), pos)), message))?;
        let json::Value::Object(entries) = root else {
            return Err(scene_error(path, None, "expected a JSON object mapping scene names to cameras"));
        };
        // As in most JSON readers, the last of repeated keys wins.
        let Some((_, entry)) = entries.iter().rev().find(|(k, _)| k == scene_name) else {
            return Ok(None);
        };
        let bad = |message: String| scene_error(path, None, format!("camera {scene_name:?}: {message}"));
        let json::Value::Object(fields) = entry else {
            return Err(bad("not a camera object".into()));
        };
        let field = |key: &str| fields.iter().rev().find(|(k, _)| k == key).map(|(_, v)| v);
        let vec3 = |key: &str, default: Option<Vec3>| -> Result<Vec3> {
            let Some(value) = field(key) else {
                return default.ok_or_else(|| bad(format!("{key} is missing")));
            };
            match value {
                json::Value::Array(a) if a.len() == 3 => {
                    let mut v = Vec3::ZERO;
                    for (i, x) in a.iter().enumerate() {
                        match x {
                            json::Value::Number(x) if (*x as f32).is_finite() => v[i] = *x as f32,
                            _ => return Err(bad(format!("{key} must be 3 finite numbers"))),
                        }
                    }
                    Ok(v)
                }
                _ => Err(bad(format!("{key} must be an array of 3 numbers"))),
            }
        };
        let eye = vec3("eye", None)?;
        let target = vec3("target", None)?;
        let up = vec3("up", Some(Vec3::Y))?;
        let fov_deg = match field("fov_deg") {
            None => Self::DEFAULT_FOV_DEG,
            Some(json::Value::Number(x)) if *x > 0.0 && *x < 180.0 => *x as f32,
            Some(_) => return Err(bad("fov_deg must be a number of degrees in (0, 180)".into())),
        };
        let view = target.as_dvec3() - eye.as_dvec3();
        if view == DVec3::ZERO {
            return Err(bad("eye and target are the same point".into()));
        }
        if view.cross(up.as_dvec3()) == DVec3::ZERO {
            return Err(bad("up is zero or parallel to the view direction".into()));
        }
        Ok(Some(Camera { eye, target, up, fov_deg }))
    }
}

/// A small JSON reader, enough for `cameras.json` (no dependency for one file).
mod json {
    /// A JSON value; objects keep their keys in order (repeats included).
    #[derive(Debug, PartialEq)]
    pub enum Value {
        Null,
        Bool(bool),
        Number(f64),
        String(String),
        Array(Vec<Value>),
        Object(Vec<(String, Value)>),
    }

    /// A parse error: byte offset and message.
    pub type Error = (usize, String);

    /// Deepest nesting accepted (keeps the recursion off the end of the stack).
    const MAX_DEPTH: usize = 64;

    /// Parses one JSON value filling all of `text`.
    pub fn parse(text: &str) -> Result<Value, Error> {
        let mut p = Parser { s: text.as_bytes(), pos: 0, depth: 0 };
        let value = p.value()?;
        p.skip_space();
        if p.pos < p.s.len() {
            return Err(p.error("unexpected characters after the JSON value"));
        }
        Ok(value)
    }

    struct Parser<'a> {
        s: &'a [u8],
        pos: usize,
        depth: usize,
    }

    impl Parser<'_> {
        fn error(&self, message: &str) -> Error {
            (self.pos, format!("JSON: {message}"))
        }

        fn peek(&self) -> Option<u8> {
            self.s.get(self.pos).copied()
        }

        fn skip_space(&mut self) {
            while matches!(self.peek(), Some(b' ' | b'\t' | b'\n' | b'\r')) {
                self.pos += 1;
            }
        }

        fn expect(&mut self, c: u8) -> Result<(), Error> {
            self.skip_space();
            if self.peek() != Some(c) {
                return Err(self.error(&format!("expected '{}'", c as char)));
            }
            self.pos += 1;
            Ok(())
        }

        fn value(&mut self) -> Result<Value, Error> {
            self.skip_space();
            match self.peek() {
                Some(b'{' | b'[') => {
                    if self.depth >= MAX_DEPTH {
                        return Err(self.error("nested too deeply"));
                    }
                    self.depth += 1;
                    let v = if self.peek() == Some(b'{') { self.object() } else { self.array() };
                    self.depth -= 1;
                    v
                }
                Some(b'"') => Ok(Value::String(self.string()?)),
                Some(b't') => self.literal("true", Value::Bool(true)),
                Some(b'f') => self.literal("false", Value::Bool(false)),
                Some(b'n') => self.literal("null", Value::Null),
                Some(b'-' | b'0'..=b'9') => self.number(),
                Some(_) => Err(self.error("unexpected character")),
                None => Err(self.error("unexpected end of file")),
            }
        }

        fn literal(&mut self, word: &str, value: Value) -> Result<Value, Error> {
            if !self.s[self.pos..].starts_with(word.as_bytes()) {
                return Err(self.error("unexpected word"));
            }
            self.pos += word.len();
            Ok(value)
        }

        fn number(&mut self) -> Result<Value, Error> {
            let start = self.pos;
            while matches!(self.peek(), Some(b'0'..=b'9' | b'-' | b'+' | b'.' | b'e' | b'E')) {
                self.pos += 1;
            }
            // The bytes are ASCII, so this slice is valid UTF-8.
            let word = std::str::from_utf8(&self.s[start..self.pos]).unwrap_or("");
            word.parse().map(Value::Number).map_err(|_| (start, format!("JSON: bad number {word:?}")))
        }

        fn string(&mut self) -> Result<String, Error> {
            self.expect(b'"')?;
            let mut out = Vec::new();
            loop {
                let Some(c) = self.peek() else { return Err(self.error("unterminated string")) };
                self.pos += 1;
                match c {
                    b'"' => break,
                    b'\\' => {
                        let Some(e) = self.peek() else { return Err(self.error("unterminated string")) };
                        self.pos += 1;
                        let ch = match e {
                            b'"' => '"',
                            b'\\' => '\\',
                            b'/' => '/',
                            b'b' => '\u{8}',
                            b'f' => '\u{c}',
                            b'n' => '\n',
                            b'r' => '\r',
                            b't' => '\t',
                            // Surrogate pairs are not combined: they become U+FFFD.
                            b'u' => {
                                let hex = self.s.get(self.pos..self.pos + 4).and_then(|h| std::str::from_utf8(h).ok());
                                let code = hex.and_then(|h| u32::from_str_radix(h, 16).ok());
                                let Some(code) = code else { return Err(self.error("bad \\u escape")) };
                                self.pos += 4;
                                char::from_u32(code).unwrap_or('\u{fffd}')
                            }
                            _ => return Err(self.error("bad escape")),
                        };
                        out.extend_from_slice(ch.encode_utf8(&mut [0; 4]).as_bytes());
                    }
                    0..=0x1f => return Err(self.error("control character in string")),
                    _ => out.push(c),
                }
            }
            // The input is UTF-8 and escapes add whole characters, so this cannot fail.
            String::from_utf8(out).map_err(|_| self.error("string is not UTF-8"))
        }

        fn array(&mut self) -> Result<Value, Error> {
            self.expect(b'[')?;
            let mut items = Vec::new();
            self.skip_space();
            if self.peek() == Some(b']') {
                self.pos += 1;
                return Ok(Value::Array(items));
            }
            loop {
                items.push(self.value()?);
                self.skip_space();
                match self.peek() {
                    Some(b',') => self.pos += 1,
                    Some(b']') => {
                        self.pos += 1;
                        return Ok(Value::Array(items));
                    }
                    _ => return Err(self.error("expected ',' or ']'")),
                }
            }
        }

        fn object(&mut self) -> Result<Value, Error> {
            self.expect(b'{')?;
            let mut entries = Vec::new();
            self.skip_space();
            if self.peek() == Some(b'}') {
                self.pos += 1;
                return Ok(Value::Object(entries));
            }
            loop {
                self.skip_space();
                let key = self.string()?;
                self.expect(b':')?;
                entries.push((key, self.value()?));
                self.skip_space();
                match self.peek() {
                    Some(b',') => self.pos += 1,
                    Some(b'}') => {
                        self.pos += 1;
                        return Ok(Value::Object(entries));
                    }
                    _ => return Err(self.error("expected ',' or '}'")),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::json::Value;
    use super::*;

    fn assert_valid(c: &Camera, bounds: &Aabb) {
        assert!(c.eye.is_finite() && c.target.is_finite(), "{c:?}");
        assert_ne!(c.eye, c.target, "{c:?}");
        for (px, py) in [(0.0, 0.0), (320.0, 240.0), (639.9, 479.9), (0.5, 479.5)] {
            let (o, d) = c.ray(px, py, 640, 480);
            assert_eq!(o, c.eye);
            assert!(d.is_finite() && (d.length() - 1.0).abs() < 1e-5, "{c:?} {d}");
        }
        if bounds.is_empty() {
            return;
        }
        // Every box corner is inside the vertical and horizontal field of view.
        let (f, r, u) = c.basis();
        let tan = (0.5 * f64::from(c.fov_deg).to_radians()).tan();
        for i in 0..8 {
            let p = DVec3::new(
                if i & 1 == 0 { bounds.min.x } else { bounds.max.x }.into(),
                if i & 2 == 0 { bounds.min.y } else { bounds.max.y }.into(),
                if i & 4 == 0 { bounds.min.z } else { bounds.max.z }.into(),
            ) - c.eye.as_dvec3();
            let z = p.dot(f);
            assert!(z > 0.0, "{c:?}: corner {i} behind the camera");
            assert!(p.dot(u).abs() <= z * tan * 1.0001, "{c:?}: corner {i} outside vertically");
            assert!(p.dot(r).abs() <= z * tan * 1.0001, "{c:?}: corner {i} outside horizontally");
        }
    }

    #[test]
    fn frame_sees_the_box() {
        let boxes = [
            Aabb::new(Vec3::new(-16.0, -7.9, -10.0), Vec3::new(16.0, 7.9, 10.0)),
            Aabb::new(Vec3::new(64.0, 64.0, 56.0), Vec3::new(2752.0, 2752.0, 1024.0)),
            Aabb::new(Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0)), // flat in y
            Aabb::new(Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 5.0)),   // a line along z
            Aabb::new(Vec3::splat(1e6), Vec3::splat(1e6) + 1e-3),            // tiny, far out
            Aabb::new(Vec3::splat(-1e38), Vec3::splat(1e38)),                // huge
        ];
        for b in boxes {
            let c = Camera::frame(&b);
            assert_eq!(c.up, Vec3::Y);
            assert_eq!(c.fov_deg, 40.0);
            if b.max.x < 1e37 {
                assert_valid(&c, &b);
            } else {
                assert_valid(&c, &Aabb::EMPTY);
            }
        }
        for b in [Aabb::EMPTY, Aabb::new(Vec3::splat(3.0), Vec3::splat(3.0)), Aabb::new(Vec3::MAX, Vec3::MAX)] {
            assert_valid(&Camera::frame(&b), &Aabb::EMPTY);
        }
    }

    #[test]
    fn ray_directions() {
        let c = Camera { eye: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, up: Vec3::Y, fov_deg: 90.0 };
        let (o, d) = c.ray(50.0, 50.0, 100, 100);
        assert_eq!(o, c.eye);
        assert!((d - Vec3::NEG_Z).length() < 1e-6, "{d}");
        // Top-left corner: up and to the left, at 45° in both directions (fov 90, square).
        let (_, d) = c.ray(0.0, 0.0, 100, 100);
        assert!((d - Vec3::new(-1.0, 1.0, -1.0).normalize()).length() < 1e-6, "{d}");
        // Bottom-right of a 2:1 image: x reaches twice as far as y.
        let (_, d) = c.ray(200.0, 100.0, 200, 100);
        assert!((d - Vec3::new(2.0, -1.0, -1.0).normalize()).length() < 1e-6, "{d}");
        // Degenerate cameras still give unit directions.
        for c in [
            Camera { eye: Vec3::ZERO, target: Vec3::ZERO, up: Vec3::Y, fov_deg: 40.0 },
            Camera { eye: Vec3::ZERO, target: Vec3::Y, up: Vec3::Y, fov_deg: f32::NAN },
            Camera { eye: Vec3::ZERO, target: Vec3::X, up: Vec3::ZERO, fov_deg: 400.0 },
        ] {
            let (_, d) = c.ray(3.0, 7.0, 10, 0);
            assert!(d.is_finite() && (d.length() - 1.0).abs() < 1e-5, "{c:?} {d}");
        }
    }

    #[test]
    fn json_values() {
        let v = json::parse(r#" {"a": [1, -2.5e3, true, false, null], "b\n\u00e9": {"c": "x\"y"}, "d": {}, "e": []} "#)
            .unwrap();
        let Value::Object(e) = v else { panic!() };
        assert_eq!(e[0].0, "a");
        assert_eq!(
            e[0].1,
            Value::Array(vec![
                Value::Number(1.0),
                Value::Number(-2500.0),
                Value::Bool(true),
                Value::Bool(false),
                Value::Null
            ])
        );
        assert_eq!(e[1].0, "b\né");
        assert_eq!(e[1].1, Value::Object(vec![("c".into(), Value::String("x\"y".into()))]));
        assert_eq!(e[2].1, Value::Object(vec![]));
        assert_eq!(e[3].1, Value::Array(vec![]));
    }

    #[test]
    fn json_errors_do_not_panic() {
        let deep = "[".repeat(100_000);
        for bad in [
            "",
            "{",
            "{\"a\"",
            "{\"a\":}",
            "[1,]",
            "[1 2]",
            "{\"a\":1,}",
            "\"abc",
            "\"\\u12\"",
            "\"\\q\"",
            "tru",
            "1 2",
            "--1",
            "{1:2}",
            "\"\u{1}\"",
            deep.as_str(),
        ] {
            assert!(json::parse(bad).is_err(), "{bad:?}");
        }
    }
}
