//! Geometry shared by the builder, the CPU traversals and the GPU layouts:
//! boxes, rays, hits and the watertight ray/triangle test.

use glam::Vec3;

pub use crate::abi::{Hit, Ray};

/// An axis-aligned box. The empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner (inclusive).
    pub min: Vec3,
    /// Upper corner (inclusive).
    pub max: Vec3,
}

impl Aabb {
    /// The empty box: the identity of `union`.
    pub const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };

    /// The box `[min, max]`, taken as given (no reordering of the corners).
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Aabb { min, max }
    }

    /// The smallest box holding every point; [`Aabb::EMPTY`] for no points.
    pub fn from_points(points: &[Vec3]) -> Self {
        points.iter().fold(Aabb::EMPTY, |b, &p| b.grow(p))
    }

    /// The box enlarged to hold the point `p`.
    pub fn grow(self, p: Vec3) -> Self {
        Aabb { min: self.min.min(p), max: self.max.max(p) }
    }

    /// The smallest box holding both boxes.
    pub fn union(self, o: Aabb) -> Self {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    /// The common part of both boxes; empty (`min > max` on some axis) when they are disjoint.
    pub fn intersection(self, o: Aabb) -> Self {
        Aabb { min: self.min.max(o.min), max: self.max.min(o.max) }
    }

    /// True when `min > max` on some axis; a flat box (`min == max`) is not empty.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Edge lengths `max - min`, clamped at 0 per axis (zero for an empty box).
    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    /// Midpoint `(min + max) / 2` (meaningless for an empty box).
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Surface area (0 for an empty box).
    pub fn area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// True when the closed boxes share at least one point.
    pub fn overlaps(&self, o: &Aabb) -> bool {
        !self.intersection(*o).is_empty()
    }

    /// True when the closed box `o` lies inside this closed box (shared faces count).
    pub fn contains_box(&self, o: &Aabb) -> bool {
        self.min.cmple(o.min).all() && o.max.cmple(self.max).all()
    }
}

impl Ray {
    /// The segment `origin + t * dir`, `tmin <= t <= tmax`.
    pub fn new(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray { origin: origin.into(), tmin, dir: dir.into(), tmax }
    }

    /// The direction as every tracer takes it: components smaller in magnitude
    /// than `f32::MIN_POSITIVE` (denormals) become a zero of the same sign, as on
    /// GPUs that flush denormals. The CPU twins and the exact reference use it too.
    pub fn traced_dir(&self) -> Vec3 {
        Vec3::from(self.dir).to_array().map(|d| if d.abs() < f32::MIN_POSITIVE { d * 0.0 } else { d }).into()
    }

    /// A ray is valid when its origin is finite, its direction has no NaN and is
    /// not zero (after [`Ray::traced_dir`]), and its bounds are not NaN. Invalid
    /// rays get `PRIM_INVALID`.
    pub fn is_valid(&self) -> bool {
        let o = Vec3::from(self.origin);
        let d = self.traced_dir();
        o.is_finite() && !d.is_nan() && d != Vec3::ZERO && !self.tmin.is_nan() && !self.tmax.is_nan()
    }
}

impl Hit {
    /// The miss: `t = +inf`, `prim_id = PRIM_MISS`, `u = v = 0`.
    pub const MISS: Hit = Hit { t: f32::INFINITY, prim_id: crate::consts::PRIM_MISS, u: 0.0, v: 0.0 };

    /// True when `prim_id` is a triangle index, i.e. not one of the special `PRIM_*` values.
    pub fn is_hit(&self) -> bool {
        self.prim_id < crate::consts::PRIM_INCOMPLETE
    }
}

impl Default for Hit {
    fn default() -> Self {
        Hit::MISS
    }
}

/// Per-ray constants of the watertight test (Woop, Benthin & Wald 2013, JCGT 2(1)):
/// the dominant axis `kz` of the direction becomes z, and a shear maps the ray onto +z.
/// Mirrored by `WatertightRay` in `glsl/shared/triangle.glsl`.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    /// Axis (0..=2) that becomes x: the next after `kz`, swapped with `ky` when `dir[kz] < 0`.
    pub kx: usize,
    /// Axis (0..=2) that becomes y.
    pub ky: usize,
    /// Dominant axis (0..=2) of the direction: largest `|dir|` component, ties to the lower axis.
    pub kz: usize,
    /// Shear `dir[kx] / dir[kz]`.
    pub sx: f32,
    /// Shear `dir[ky] / dir[kz]`.
    pub sy: f32,
    /// Scale `1 / dir[kz]`.
    pub sz: f32,
    /// Ray origin; the f64 test translates the vertices by `-origin` before the shear.
    pub origin: Vec3,
    /// The segment frame (`TraceRay` in `glsl/traverse/segment.glsl`): the f32
    /// test translates by `-(seg_origin + seg_lo)`, the point `origin +
    /// t_shift·dir` of the ray, and answers `t - t_shift`; `seg_err` bounds (per axis, scaled by
    /// `1/EDGE_GAMMA`) how far `seg_origin + seg_lo` may lie from that point.
    /// `origin`, 0, 0, 0 unless a far ray was shifted to the scene box.
    pub seg_origin: Vec3,
    /// See `seg_origin`.
    pub seg_lo: Vec3,
    /// See `seg_origin`.
    pub seg_err: Vec3,
    /// See `seg_origin`.
    pub t_shift: f32,
    /// `ray_tmax - t_shift`: the ray's own end in the segment frame (f32 test).
    pub seg_tmax: f32,
    /// Ray direction, for the f64 fallback near edges.
    pub dir: Vec3,
    /// The ray's own `tmax` (the `tmax` argument of [`WatertightRay::intersect`]
    /// may be the closest hit so far): the f64 decision near the ray's end uses
    /// it, so a triangle's answer never depends on what was tested before it.
    /// `+inf` from [`WatertightRay::new`]; set it with [`WatertightRay::with_tmax`].
    pub ray_tmax: f32,
    /// The f64 fallback near edges and bounds (`Traversal::robust`; true from
    /// [`WatertightRay::new`]). False: the plain test, with the f64 recompute only
    /// at an edge function of exactly 0.
    pub robust: bool,
}

/// The bound on an f32 edge function's error, relative to the magnitude of its
/// terms: `2^-EDGE_GAMMA_LOG2` ([`crate::consts::EDGE_GAMMA_LOG2`]).
pub const EDGE_GAMMA: f32 = 1.0 / (1u32 << crate::consts::EDGE_GAMMA_LOG2) as f32;

/// The f64 product `a·b` as `p + e` exactly (Dekker 1971, Veltkamp's split; no
/// FMA, so every IEEE device gives the same bits). Twin of `two_product` in
/// `glsl/shared/triangle.glsl`.
#[inline]
fn two_product(a: f64, b: f64) -> (f64, f64) {
    let split = |x: f64| {
        let c = 134_217_729.0 * x;
        let hi = c - (c - x);
        (hi, x - hi)
    };
    let ((a_hi, a_lo), (b_hi, b_lo)) = (split(a), split(b));
    let p = a * b;
    (p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo)
}

/// `a·b − c·d` in f64 from exact products: 0 exactly when `a·b == c·d`, and of
/// the exact sign unless the products' rounding errors cancel their difference.
/// Twin of `diff_of_products` in `glsl/shared/triangle.glsl`.
#[inline]
fn diff_of_products(a: f64, b: f64, c: f64, d: f64) -> f64 {
    let (p1, e1) = two_product(a, b);
    let (p2, e2) = two_product(c, d);
    (p1 - p2) + (e1 - e2)
}

/// The answer of the f32 watertight test ([`WatertightRay::intersect_f32`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TriTest {
    /// No hit in `[tmin, tmax]`.
    Miss,
    /// A hit: `(t, u, v, e)`, `e` a bound on the error of `t` (0 unless robust).
    Hit(f32, f32, f32, f32),
    /// Rounding could decide it: ask [`WatertightRay::intersect_f64`].
    Unsure,
}

impl WatertightRay {
    /// The per-ray constants for `origin + t * dir` (`dir` non-zero, finite).
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        let a = dir.abs();
        // Largest component; ties go to the lower axis, exactly as in the shader.
        let mut kz = 0;
        if a.y > a[kz] {
            kz = 1;
        }
        if a.z > a[kz] {
            kz = 2;
        }
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swap x and y when the dominant component is negative.
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / dir[kz];
        WatertightRay {
            kx,
            ky,
            kz,
            sx: dir[kx] * sz,
            sy: dir[ky] * sz,
            sz,
            origin,
            seg_origin: origin,
            seg_lo: Vec3::ZERO,
            seg_err: Vec3::ZERO,
            t_shift: 0.0,
            seg_tmax: f32::INFINITY,
            dir,
            ray_tmax: f32::INFINITY,
            robust: true,
        }
    }

    /// The same constants for a ray ending at `tmax`.
    pub fn with_tmax(self, tmax: f32) -> Self {
        WatertightRay { ray_tmax: tmax, seg_tmax: tmax, ..self }
    }

    /// The watertight ray/triangle test. Returns `(t, u, v)` when the ray hits the
    /// triangle at `tmin <= t <= tmax` (edges and vertices count as hits, both
    /// faces are hit, a ray in the triangle's plane misses): the f32 test, and
    /// the f64 one when the f32 test is unsure. Every operation is the shader's,
    /// in the same order, so CPU and GPU give the same bits.
    #[inline]
    pub fn intersect(&self, v0: Vec3, v1: Vec3, v2: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        match self.intersect_f32(v0, v1, v2, tmin, tmax) {
            TriTest::Hit(t, u, v, _) => (t <= tmax).then_some((t, u, v)),
            TriTest::Miss => None,
            TriTest::Unsure => {
                self.intersect_f64(v0, v1, v2, tmin).filter(|h| h.0 <= tmax).map(|(t, u, v, _, _)| (t, u, v))
            }
        }
    }

    /// The f32 test (`intersect_triangle_f32` in triangle.glsl): a hit, a miss,
    /// or unsure when rounding could decide it — an edge function or the
    /// distance to the ray's bounds within its error bound; then
    /// [`WatertightRay::intersect_f64`] decides. Whether a pair is unsure does
    /// not depend on `tmax` (the closest hit so far).
    ///
    /// When robust, a hit carries `e`, a bound on `|t - exact t|` (the edge
    /// functions' errors carried through `t = Σ u_i z_i / Σ u_i`, plus the
    /// rounding of `t`), and a hit whose interval `[t - e, t]` reaches `tmax`
    /// counts (`t <= ray_tmax` still holds), so that callers can order two hits
    /// whose `t` lie within rounding of each other in f64.
    #[inline]
    pub fn intersect_f32(&self, v0: Vec3, v1: Vec3, v2: Vec3, tmin: f32, tmax: f32) -> TriTest {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = (v0 - self.seg_origin) - self.seg_lo;
        let b = (v1 - self.seg_origin) - self.seg_lo;
        let c = (v2 - self.seg_origin) - self.seg_lo;
        // Shear and scale the vertices into ray space.
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        // Scaled barycentric coordinates (edge functions).
        let (mut u, mut v, mut w) = (cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax);
        let (mut eu, mut ev, mut ew) = (0.0f32, 0.0f32, 0.0f32);
        if !self.robust {
            // Plain Woop, Benthin & Wald: recompute in f64 only at an edge function of 0.
            if u == 0.0 || v == 0.0 || w == 0.0 {
                let (ax, ay, bx, by, cx, cy) = (ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64);
                u = (cx * by - cy * bx) as f32;
                v = (ax * cy - ay * cx) as f32;
                w = (bx * ay - by * ax) as f32;
            }
            if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
                return TriTest::Miss;
            }
        } else {
            // Error bounds: |a[kx]| + |sx a[kz]| is the magnitude of ax before the shear cancels.
            // A shifted origin adds its own error (seg_err, 0 unless shifted).
            let ex = self.seg_err[kx] + (self.sx * self.seg_err[kz]).abs();
            let ey = self.seg_err[ky] + (self.sy * self.seg_err[kz]).abs();
            let aex = (a[kx].abs() + (self.sx * a[kz]).abs()) + ex;
            let aey = (a[ky].abs() + (self.sy * a[kz]).abs()) + ey;
            let bex = (b[kx].abs() + (self.sx * b[kz]).abs()) + ex;
            let bey = (b[ky].abs() + (self.sy * b[kz]).abs()) + ey;
            let cex = (c[kx].abs() + (self.sx * c[kz]).abs()) + ex;
            let cey = (c[ky].abs() + (self.sy * c[kz]).abs()) + ey;
            // Each sheared coordinate lies within EDGE_GAMMA·m of its exact value, m the
            // largest magnitude before the shear cancelled; with l the largest
            // |coordinate|, an edge function is off by less than EDGE_GAMMA·m·(4.2·l +
            // 2·EDGE_GAMMA·m) (see triangle.glsl).
            let m = aex.max(aey).max(bex.max(bey)).max(cex.max(cey));
            let l = ax.abs().max(ay.abs()).max(bx.abs().max(by.abs())).max(cx.abs().max(cy.abs()));
            let bound = EDGE_GAMMA * m * (5.0 * l + 2.0 * EDGE_GAMMA * m);
            (eu, ev, ew) = (bound, bound, bound);
            // Certainly outside (one edge function surely negative, another surely positive)?
            let negative = u < -eu || v < -ev || w < -ew;
            let positive = u > eu || v > ev || w > ew;
            if negative && positive {
                return TriTest::Miss;
            }
            // Any sign in doubt: decide in f64.
            if !(u.abs() > eu && v.abs() > ev && w.abs() > ew) {
                return TriTest::Unsure;
            }
        }
        let det = u + v + w;
        if det == 0.0 {
            return TriTest::Miss;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        let rcp_det = 1.0 / det;
        let t = t_scaled * rcp_det;
        let mut e = 0.0;
        if self.robust {
            // A bound on |t − exact t|: the edge functions' errors δu_i move t_scaled −
            // t·det by Σ δu_i (z_i − t), and |z_i − t| is at most the spread of the z_i;
            // then the roundings of t_scaled, det and t.
            let ez = (u.abs() + v.abs() + w.abs()) * (self.sz * self.seg_err[kz]).abs();
            let t_err = EDGE_GAMMA * (((u * az).abs() + (v * bz).abs() + (w * cz).abs()) + ez);
            let weights_err = eu + ev + ew;
            let spread = az.max(bz).max(cz) - az.min(bz).min(cz);
            e = (t_err + weights_err * spread + EDGE_GAMMA * t_scaled.abs()) / det.abs() + EDGE_GAMMA * t.abs();
            // A hit within that bound of tmin or of the ray's own tmax (a ray leaving a
            // surface, a shadow ray ending on a vertex): decide in f64 which side of the
            // bound it lies on (see triangle.glsl).
            let near_tmin = !tmin.is_infinite() && (t - tmin).abs() <= e;
            let near_tmax = !self.seg_tmax.is_infinite() && (t - self.seg_tmax).abs() <= e;
            if near_tmin || near_tmax {
                return TriTest::Unsure;
            }
        }
        let below = t <= tmax || (self.robust && t - e <= tmax && t <= self.seg_tmax);
        if !(t >= tmin && below) {
            return TriTest::Miss;
        }
        TriTest::Hit(t, v * rcp_det, w * rcp_det, e)
    }

    /// The test in f64 on the f32 inputs, for rays near an edge, a vertex or the
    /// ray's bounds: the vertices sheared as in the f32 test but scaled by
    /// `|dir[kz]|` instead of divided by `dir[kz]`, so each vertex's 2D
    /// coordinates are the same for every triangle sharing it, and 2D edge
    /// functions with exact signs (`diff_of_products`): the triangles around an
    /// edge or vertex tile the plane exactly, and a ray through a vertex hits one
    /// of them, never none.
    ///
    /// The hit's `t` lies in `[tmin, ray_tmax]` (exactly, in f64, in the ray's
    /// own parameter); the answer is `(t, u, v, t64, err)` in the segment frame
    /// (`t - t_shift`), `t64` the f64 `t` by which callers order hits whose f32
    /// `t` lie within rounding of each other, and, for a shifted ray, `err` a
    /// bound on `t64`'s error (0 otherwise: callers use `EDGE_GAMMA·|t|`).
    pub fn intersect_f64(&self, v0: Vec3, v1: Vec3, v2: Vec3, tmin: f32) -> Option<(f32, f32, f32, f64, f32)> {
        let (o, d) = (self.origin.as_dvec3(), self.dir.as_dvec3());
        let a = v0.as_dvec3() - o;
        let b = v1.as_dvec3() - o;
        let c = v2.as_dvec3() - o;
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let dz = d[kz].abs();
        let sign = if d[kz] < 0.0 { -1.0 } else { 1.0 };
        let (sx, sy) = (d[kx] * sign, d[ky] * sign);
        let ax = a[kx] * dz - sx * a[kz];
        let ay = a[ky] * dz - sy * a[kz];
        let bx = b[kx] * dz - sx * b[kz];
        let by = b[ky] * dz - sy * b[kz];
        let cx = c[kx] * dz - sx * c[kz];
        let cy = c[ky] * dz - sy * c[kz];
        // The edge functions times dir[kz]²: u for the edge v1-v2, v for v2-v0, w for v0-v1.
        let u = diff_of_products(cx, by, cy, bx);
        let v = diff_of_products(ax, cy, ay, cx);
        let w = diff_of_products(bx, ay, by, ax);
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        // t from the plane, with the normal from the (exact) f32 edge differences:
        // an origin on a triangle in an axis plane gives t = 0 exactly.
        let (e1, e2) = (v1.as_dvec3() - v0.as_dvec3(), v2.as_dvec3() - v0.as_dvec3());
        let nx = e1.y * e2.z - e1.z * e2.y;
        let ny = e1.z * e2.x - e1.x * e2.z;
        let nz = e1.x * e2.y - e1.y * e2.x;
        let num = a.x * nx + a.y * ny + a.z * nz;
        let den = d.x * nx + d.y * ny + d.z * nz;
        if den == 0.0 {
            return None;
        }
        let t64 = num / den;
        // Exact against the ray's bounds.
        if !(t64 >= tmin as f64 && t64 <= self.ray_tmax as f64) {
            return None;
        }
        // The segment frame (see triangle.glsl): t less t_shift, with a bound on
        // the error of num, den and the subtraction when shifted.
        let t_seg = t64 - self.t_shift as f64;
        let mut err = 0.0f32;
        if self.t_shift != 0.0 {
            let num_mag = (a.x * nx).abs() + (a.y * ny).abs() + (a.z * nz).abs();
            let den_mag = (d.x * nx).abs() + (d.y * ny).abs() + (d.z * nz).abs();
            let bound = (num_mag + t64.abs() * den_mag) / den.abs() * 2f64.powi(-49) + t64.abs() * 2f64.powi(-50);
            err = (bound * 1.000001) as f32;
        }
        Some((t_seg as f32, (v / det) as f32, (w / det) as f32, t_seg, err))
    }
}
