//! Geometry shared by the builder, the CPU traversals and the GPU layouts:
//! boxes, rays, hits and the watertight ray/triangle test.

use crate::ff::{exact_sum8, orient_sign, two_prod, Ff};
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
    /// Ray origin; the exact test of an unshifted ray works from it.
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
    /// Ray direction, for the exact fallback near edges.
    pub dir: Vec3,
    /// The ray's own `tmax` (the `tmax` argument of [`WatertightRay::intersect`]
    /// may be the closest hit so far): the exact decision near the ray's end uses
    /// it, so a triangle's answer never depends on what was tested before it.
    /// `+inf` from [`WatertightRay::new`]; set it with [`WatertightRay::with_tmax`].
    pub ray_tmax: f32,
    /// The exact (float-float) fallback near edges and bounds (`Traversal::robust`; true from
    /// [`WatertightRay::new`]). False: the plain test, with the float-float recompute only
    /// at an edge function of exactly 0.
    pub robust: bool,
}

/// The bound on an f32 edge function's error, relative to the magnitude of its
/// terms: `2^-EDGE_GAMMA_LOG2` ([`crate::consts::EDGE_GAMMA_LOG2`]).
pub const EDGE_GAMMA: f32 = 1.0 / (1u32 << crate::consts::EDGE_GAMMA_LOG2) as f32;

/// Within `ON_EDGE_GAMMA` times the magnitude of its two products, an exact-test
/// edge function's float-float sign may be wrong (2^-40, 16× the float-float
/// error of the 2D coordinates, one rounding each, carried through the
/// products): there [`edge_sign`] decides. Twin of `ON_EDGE_GAMMA` in triangle.glsl.
const ON_EDGE_GAMMA: f32 = 1.0 / 1_099_511_627_776.0;

/// The magnitude an in-band edge function takes when [`edge_sign`] corrects its
/// sign ([`ORIENT_ZERO`](crate::consts::ORIENT_ZERO), 2^-100: its barycentric
/// weight is 0 to f32 precision). Twin of `ORIENT_TINY` in triangle.glsl.
const ORIENT_TINY: f32 = crate::consts::ORIENT_ZERO;

/// The exponent `e` of `x = m·2^e`, `m` in `[1, 2)` (0 for `x = 0`). Twin of
/// `exponent_of` in triangle.glsl.
#[inline]
pub(crate) fn exponent_of(x: f32) -> i32 {
    if x == 0.0 {
        0
    } else {
        ((x.to_bits() >> 23) & 0xff) as i32 - 127
    }
}

/// `2^k` for `k` in `[-126, 127]` (clamped to it). Twin of `pow2`.
#[inline]
fn pow2(k: i32) -> f32 {
    f32::from_bits(((k.clamp(-126, 127) + 127) as u32) << 23)
}

/// The sign of the edge function of the edge `p → q` for the ray from `o` along
/// `dir`: of `det[p - o, q - o, dir]`, exact unless within 2^-100 of the three
/// vectors' magnitudes (then 0, on the edge). The pair is taken in a fixed order
/// (lexicographic) and the sign negated when swapped, so `edge_sign(q, p, ..)`
/// is exactly `-edge_sign(p, q, ..)`: the triangles sharing an edge agree on
/// which side the ray passes. Twin of `edge_sign_exact` in triangle.glsl.
pub(crate) fn edge_sign(p: Vec3, q: Vec3, o: Vec3, dir: Vec3) -> i32 {
    let swap = p.x > q.x || (p.x == q.x && (p.y > q.y || (p.y == q.y && p.z > q.z)));
    let (f, g) = if swap { (q, p) } else { (p, q) };
    let (x, y) = (unit_offset(f, o), unit_offset(g, o));
    let ed = exponent_of(dir.x.abs().max(dir.y.abs()).max(dir.z.abs()));
    let d = [0, 1, 2].map(|i| Ff::from_f32(ldexp2(dir[i], -ed)));
    let s = orient_sign(x, y, d);
    if swap {
        -s
    } else {
        s
    }
}

/// The side of the plane through `v0, v1, v2` that `o` lies on: the sign of
/// `det[v0 - o, v1 - o, v2 - o]` (the numerator of the exact test's `t`, whose
/// float-float value can miss the sign of an origin exactly on the plane),
/// exact unless within 2^-100 of the vectors' magnitudes (then 0, on the
/// plane). Twin of `plane_side_exact` in triangle.glsl.
pub(crate) fn plane_side(v0: Vec3, v1: Vec3, v2: Vec3, o: Vec3) -> i32 {
    orient_sign(unit_offset(v0, o), unit_offset(v1, o), unit_offset(v2, o))
}

/// `v - o` exactly in float-float, scaled by the power of two that brings its
/// largest component's high part to `[1, 2)`: the inputs of [`orient_sign`].
/// Twin of `unit_offset` in triangle.glsl.
fn unit_offset(v: Vec3, o: Vec3) -> [Ff; 3] {
    let x = [0, 1, 2].map(|i| Ff::diff(v[i], o[i]));
    let e = exponent_of(x[0].hi.abs().max(x[1].hi.abs()).max(x[2].hi.abs()));
    x.map(|c| ff_ldexp(c, -e))
}

/// The sheared coordinate `(v - o)·dz - s·(v_z - o_z)` from offsets scaled by
/// `2^-eo`, exactly up to one rounding. Twin of `sheared_exact` in triangle.glsl.
fn sheared_exact(v: f32, v_z: f32, o: f32, o_z: f32, dz: f32, s: f32, eo: i32) -> Ff {
    let p = ff_ldexp(Ff::diff(v, o), -eo);
    let q = ff_ldexp(Ff::diff(v_z, o_z), -eo);
    let (pa, pb, pc, pd) = (two_prod(p.hi, dz), two_prod(p.lo, dz), two_prod(q.hi, -s), two_prod(q.lo, -s));
    exact_sum8([pa.hi, pa.lo, pb.hi, pb.lo, pc.hi, pc.lo, pd.hi, pd.lo])
}

/// `x·2^k` in two exact steps (barring overflow and underflow). Twin of `ldexp2`.
#[inline]
pub(crate) fn ldexp2(x: f32, k: i32) -> f32 {
    let k1 = k / 2;
    (x * pow2(k1)) * pow2(k - k1)
}

/// Twin of `ff_ldexp`.
#[inline]
pub(crate) fn ff_ldexp(x: Ff, k: i32) -> Ff {
    Ff { hi: ldexp2(x.hi, k), lo: ldexp2(x.lo, k) }
}

/// Which side of the bound `b·2^k` the quotient `num / den` lies on (`den.hi !=
/// 0`): negative below, 0 on it, positive above, from the sign of `num - b·2^k·den`
/// in float-float. `num` and `den` come from the exact test (`|num| < 2^8`,
/// `|den| >= 2^-149`); the bound may be far outside f32's range there (a
/// huge finite `tmax` on a small scene), so the comparison is scaled by a power
/// of two that keeps every term in range (exact: the same answer as unscaled
/// wherever that one neither overflows nor underflows), and where the bound
/// exceeds every possible quotient its sign decides. Twin of `quotient_side` in
/// triangle.glsl.
pub(crate) fn quotient_side(num: Ff, den: Ff, b: Ff, k: i32) -> i32 {
    let mut scale = 0;
    if b.hi != 0.0 {
        let s = k + exponent_of(b.hi);
        if s > 160 {
            // |num / den| < 2^8 / 2^-149 < |b|·2^k.
            return if b.hi > 0.0 { -1 } else { 1 };
        }
        // The bound's term near 2^±100, num scaled alike.
        scale = if s > 100 {
            100 - s
        } else if s < -100 {
            (-100 - s).min(120)
        } else {
            0
        };
    }
    let diff = ff_ldexp(num, scale).sub(den.mul(ff_ldexp(b, k + scale)));
    let sign = if diff.hi > 0.0 {
        1
    } else if diff.hi < 0.0 {
        -1
    } else {
        0
    };
    if den.hi > 0.0 {
        sign
    } else {
        -sign
    }
}

/// The answer of the f32 watertight test ([`WatertightRay::intersect_f32`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TriTest {
    /// No hit in `[tmin, tmax]`.
    Miss,
    /// A hit: `(t, u, v, e)`, `e` a bound on the error of `t` (0 unless robust).
    Hit(f32, f32, f32, f32),
    /// Rounding could decide it: ask [`WatertightRay::intersect_exact`].
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
    /// the exact one when the f32 test is unsure. Every operation is the shader's,
    /// in the same order, so CPU and GPU give the same bits.
    #[inline]
    pub fn intersect(&self, v0: Vec3, v1: Vec3, v2: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        match self.intersect_f32(v0, v1, v2, tmin, tmax) {
            TriTest::Hit(t, u, v, _) => (t <= tmax).then_some((t, u, v)),
            TriTest::Miss => None,
            TriTest::Unsure => {
                self.intersect_exact(v0, v1, v2, tmin).filter(|h| h.0 <= tmax).map(|(t, u, v, _, _)| (t, u, v))
            }
        }
    }

    /// The f32 test (`intersect_triangle_f32` in triangle.glsl): a hit, a miss,
    /// or unsure when rounding could decide it — an edge function or the
    /// distance to the ray's bounds within its error bound; then
    /// [`WatertightRay::intersect_exact`] decides. Whether a pair is unsure does
    /// not depend on `tmax` (the closest hit so far).
    ///
    /// When robust, a hit carries `e`, a bound on `|t - exact t|` (the edge
    /// functions' errors carried through `t = Σ u_i z_i / Σ u_i`, plus the
    /// rounding of `t`), and a hit whose interval `[t - e, t]` reaches `tmax`
    /// counts (`t <= ray_tmax` still holds), so that callers can order two hits
    /// whose `t` lie within rounding of each other in float-float.
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
            // Plain Woop, Benthin & Wald: recompute in float-float only at an edge function of 0.
            if u == 0.0 || v == 0.0 || w == 0.0 {
                u = two_prod(cx, by).sub(two_prod(cy, bx)).hi;
                v = two_prod(ax, cy).sub(two_prod(ay, cx)).hi;
                w = two_prod(bx, ay).sub(two_prod(by, ax)).hi;
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
            // Any sign in doubt, or a bound below the smallest normal f32 (coordinates
            // under about 1e-16 of the ray's scale: the bound lost its meaning, and a GPU
            // flushes it to 0): decide exactly.
            if !(u.abs() > eu && v.abs() > ev && w.abs() > ew) || bound < f32::MIN_POSITIVE {
                return TriTest::Unsure;
            }
        }
        let det = u + v + w;
        if det == 0.0 {
            return TriTest::Miss;
        }
        if self.robust && !det.is_finite() {
            // The edge functions overflowed (coordinates above about 1e19 of the ray's
            // scale): the exact test scales them.
            return TriTest::Unsure;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        // t = Σ u_i z_i / Σ u_i as the barycentric weights' sum of the z_i: no
        // product of three coordinates, which under- or overflows f32 for scenes
        // whose coordinates are below about 1e-13 or above 1e12.
        let rcp_det = 1.0 / det;
        let (b0, b1, b2) = (u * rcp_det, v * rcp_det, w * rcp_det);
        let t = (b0 * az + b1 * bz) + b2 * cz;
        let mut e = 0.0;
        if self.robust {
            // A bound on |t − exact t|: the edge functions' errors δu_i move t by
            // Σ δu_i (z_i − t) / det, and |z_i − t| is at most the spread of the z_i;
            // then the roundings of the weights (det's included) and of the sum.
            let ez = (b0.abs() + b1.abs() + b2.abs()) * (self.sz * self.seg_err[kz]).abs();
            let terms = (b0 * az).abs() + (b1 * bz).abs() + (b2 * cz).abs();
            let weights_err = (eu + ev + ew) * rcp_det.abs();
            let spread = az.max(bz).max(cz) - az.min(bz).min(cz);
            e = EDGE_GAMMA * ((2.0 * terms + ez) + t.abs()) + weights_err * spread;
            // A hit within that bound of tmin or of the ray's own tmax (a ray leaving a
            // surface, a shadow ray ending on a vertex): decide exactly which side of the
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
        TriTest::Hit(t, b1, b2, e)
    }

    /// The test in float-float ([`crate::ff`]) on the f32 inputs, for rays near
    /// an edge, a vertex or the ray's bounds (`intersect_triangle_exact` in
    /// triangle.glsl, where its guarantees are spelled out): from the segment
    /// frame's origin `seg_origin + seg_lo`, offsets and direction scaled by powers
    /// of two to about 1, the vertices sheared as in the f32 test but scaled by
    /// `|dir[kz]|` instead of divided by `dir[kz]`, so each vertex's 2D
    /// coordinates are the same for every triangle sharing it, and antisymmetric
    /// 2D edge functions: the triangles around an edge or vertex tile the plane,
    /// and a ray through a vertex hits one of them, never none.
    ///
    /// The hit's `t` lies in `[tmin, ray_tmax]` (in float-float, in the ray's own
    /// parameter); the answer is `(t, u, v, t_ff, err)` in the segment frame
    /// (`t - t_shift`), `t_ff` the float-float `t` by which callers order hits
    /// whose f32 `t` lie within rounding of each other, and, for a shifted ray,
    /// `err` a bound on `t_ff`'s error (0 otherwise: callers use `EDGE_GAMMA·|t|`).
    pub fn intersect_exact(&self, v0: Vec3, v1: Vec3, v2: Vec3, tmin: f32) -> Option<(f32, f32, f32, Ff, f32)> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let o = |i: usize| Ff { hi: (self.seg_origin[i]), lo: (self.seg_lo[i]) };
        let offsets = |v: Vec3| [0, 1, 2].map(|i| Ff::from_f32(v[i]).sub(o(i)));
        let (mut a, mut b, mut c) = (offsets(v0), offsets(v1), offsets(v2));
        // Scale: the offsets by 2^-es (largest about 1), the direction by 2^-eq.
        let mut m = 0.0f32;
        for i in 0..3 {
            m = m.max(a[i].hi.abs().max(b[i].hi.abs().max(c[i].hi.abs())));
        }
        let es = exponent_of(m);
        let eq = exponent_of(self.dir[kz].abs());
        let d = [0, 1, 2].map(|i| ldexp2(self.dir[i], -eq));
        for i in 0..3 {
            a[i] = ff_ldexp(a[i], -es);
            b[i] = ff_ldexp(b[i], -es);
            c[i] = ff_ldexp(c[i], -es);
        }
        let dz = d[kz].abs();
        let (sx, sy) = if d[kz] < 0.0 { (-d[kx], -d[ky]) } else { (d[kx], d[ky]) };
        // The 2D coordinates from the ray's own origin, exactly up to one rounding
        // each (see triangle.glsl).
        let [ax, ay, bx, by, cx, cy] = {
            let o = self.origin;
            let vm = v0.abs().max(v1.abs()).max(v2.abs());
            let om = o.x.abs().max(o.y.abs()).max(o.z.abs()).max(vm.x.max(vm.y).max(vm.z));
            let eo = (exponent_of(om) - 99).max(0);
            let exact = |v: Vec3, k: usize, s: f32| sheared_exact(v[k], v[kz], o[k], o[kz], dz, s, eo);
            let coords = [
                exact(v0, kx, sx),
                exact(v0, ky, sy),
                exact(v1, kx, sx),
                exact(v1, ky, sy),
                exact(v2, kx, sx),
                exact(v2, ky, sy),
            ];
            let sm = coords.iter().fold(0.0f32, |m, c| m.max(c.hi.abs()));
            let e2 = exponent_of(sm);
            coords.map(|c| ff_ldexp(c, -e2))
        };
        // The edge functions times dir[kz]²: u for the edge v1-v2, v for v2-v0, w for v0-v1.
        let u = cx.mul(by).sub(cy.mul(bx));
        let v = ax.mul(cy).sub(ay.mul(cx));
        let w = bx.mul(ay).sub(by.mul(ax));
        // Within the coordinates' rounding of 0 the exact sign decides (edge_sign:
        // 0 for a ray through the edge, a hit); see triangle.glsl. Edge k runs
        // from vertex k+2 to vertex k+1 (u: v2 -> v1, v: v0 -> v2, w: v1 -> v0).
        let in_band = |e: Ff, p: Ff, q: Ff, r: Ff, s: Ff| {
            let m = (p.hi * q.hi).abs() + (r.hi * s.hi).abs();
            e.hi.abs() <= m * ON_EDGE_GAMMA
        };
        let band = [in_band(u, cx, by, cy, bx), in_band(v, ax, cy, ay, cx), in_band(w, bx, ay, by, ax)];
        let vs = [v0, v1, v2];
        let mut uvw = [u, v, w];
        for k in 0..3 {
            if band[k] {
                let s = edge_sign(vs[(k + 2) % 3], vs[(k + 1) % 3], self.origin, self.dir);
                let e = uvw[k];
                let agrees = (s > 0 && e.hi > 0.0) || (s < 0 && e.hi < 0.0);
                uvw[k] = if agrees { e } else { Ff { hi: s as f32 * ORIENT_TINY, lo: 0.0 } };
            }
        }
        let [u, v, w] = uvw;
        if (u.hi < 0.0 || v.hi < 0.0 || w.hi < 0.0) && (u.hi > 0.0 || v.hi > 0.0 || w.hi > 0.0) {
            return None;
        }
        let det = u.add(v).add(w);
        if det.hi == 0.0 {
            return None;
        }
        // t from the plane, with the normal from the (exact) edge differences,
        // scaled like the offsets: an origin on a triangle in an axis plane gives
        // t = 0 exactly.
        let e1 = [0, 1, 2].map(|i| ff_ldexp(Ff::diff(v1[i], v0[i]), -es));
        let e2 = [0, 1, 2].map(|i| ff_ldexp(Ff::diff(v2[i], v0[i]), -es));
        let n = [
            e1[1].mul(e2[2]).sub(e1[2].mul(e2[1])),
            e1[2].mul(e2[0]).sub(e1[0].mul(e2[2])),
            e1[0].mul(e2[1]).sub(e1[1].mul(e2[0])),
        ];
        let num = a[0].mul(n[0]).add(a[1].mul(n[1])).add(a[2].mul(n[2]));
        let den = n[0].mul_f(d[0]).add(n[1].mul_f(d[1])).add(n[2].mul_f(d[2]));
        if den.hi == 0.0 {
            return None;
        }
        // The ray's own bounds, on the signs of num - b·den (see triangle.glsl); a
        // shifted ray's from its own origin.
        let (bound_num, bound_k) = if self.t_shift == 0.0 {
            (num, eq - es)
        } else {
            let own = [0, 1, 2].map(|i| Ff::diff(v0[i], self.origin[i]));
            let eo = exponent_of(own[0].hi.abs().max(own[1].hi.abs()).max(own[2].hi.abs()));
            let own = own.map(|x| ff_ldexp(x, -eo));
            (own[0].mul(n[0]).add(own[1].mul(n[1])).add(own[2].mul(n[2])), eq - eo)
        };
        let side = |b: f32| quotient_side(bound_num, den, Ff::from_f32(b), bound_k);
        // A ray from a point of the triangle's plane (tmin = 0, a ray leaving a
        // surface from its exact point): num's float-float value is within its
        // rounding of 0, and its sign is the plane side's (see triangle.glsl).
        let (mut gated, mut at_origin) = (false, false);
        let mut above_min = if tmin.is_infinite() { tmin < 0.0 } else { side(tmin) >= 0 };
        if tmin == 0.0 && self.t_shift == 0.0 {
            let mut mag = 0.0f32;
            for (i, ai) in a.iter().enumerate() {
                let (j, k) = ((i + 1) % 3, (i + 2) % 3);
                mag += ai.hi.abs() * ((e1[j].hi * e2[k].hi).abs() + (e1[k].hi * e2[j].hi).abs());
            }
            if num.hi.abs() <= mag * (1.0 / 1_099_511_627_776.0) {
                // 2^-40
                let s = plane_side(v0, v1, v2, self.origin);
                above_min = s == 0 || (s > 0) == (den.hi > 0.0);
                (gated, at_origin) = (true, s == 0);
            }
        }
        let below_max = if self.ray_tmax.is_infinite() { self.ray_tmax > 0.0 } else { side(self.ray_tmax) <= 0 };
        if !(above_min && below_max) {
            return None;
        }
        // t along the unscaled direction: t' 2^(es - eq); 0 for an origin on the
        // plane, or within rounding of it on the side away from the ray.
        let mut t_scaled = num.div(den);
        if gated && (at_origin || t_scaled.hi < 0.0) {
            t_scaled = Ff::from_f32(0.0);
        }
        let t = ff_ldexp(t_scaled, es - eq);
        let mut err = 0.0f32;
        if self.t_shift != 0.0 {
            // See triangle.glsl: the shifted origin's error and the arithmetic's.
            let origin_err = ldexp2(
                EDGE_GAMMA
                    * (self.seg_err.x * n[0].hi.abs()
                        + self.seg_err.y * n[1].hi.abs()
                        + self.seg_err.z * n[2].hi.abs()),
                -es,
            );
            let num_mag = (a[0].hi * n[0].hi).abs() + (a[1].hi * n[1].hi).abs() + (a[2].hi * n[2].hi).abs();
            let den_mag = (d[0] * n[0].hi).abs() + (d[1] * n[1].hi).abs() + (d[2] * n[2].hi).abs();
            let rel = 1.0 / 1_099_511_627_776.0; // 2^-40
            let bound = (origin_err + (num_mag + t_scaled.hi.abs() * den_mag) * rel) * (1.0 / den.hi.abs())
                + t_scaled.hi.abs() * rel;
            err = ldexp2(bound, es - eq) * 1.0001;
        }
        let rcp_det = 1.0 / det.hi;
        Some((t.hi, (v.hi * rcp_det), (w.hi * rcp_det), t, err))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `quotient_side` against f64 on bounds inside and far outside f32's range
    /// once scaled (a huge finite `tmax` over a long direction).
    #[test]
    fn quotient_side_survives_huge_bounds() {
        let cases =
            [(1.5f32, 1.0f32, 3e38f32, 0), (1.5, 1.0, 3e38, 60), (1.5, 1.0, 3e38, 200), (-1.5, 0.25, 3e38, 150)];
        for (num, den, b, k) in cases {
            let expect = (num as f64 / den as f64).total_cmp(&(b as f64 * 2f64.powi(k))) as i32;
            let got = quotient_side(Ff::from_f32(num), Ff::from_f32(den), Ff::from_f32(b), k);
            assert_eq!(got.signum(), expect, "{num} / {den} against {b}·2^{k}");
        }
        // Near the bound, scaled: the sign of num - b·2^k·den exactly.
        let b = Ff::from_f32(1.0);
        for k in [110, 140, -110, -120] {
            // num / den = 2^k (the bound), then a little below it; |den| <= 1
            // (the exact test's den stays below 2^8).
            let (num, den) = if k > 0 { (1.0, ldexp2(1.0, -k)) } else { (ldexp2(1.0, k), 1.0) };
            let on = quotient_side(Ff::from_f32(num), Ff::from_f32(den), b, k);
            assert_eq!(on, 0, "on the bound at 2^{k}");
            let larger_den = Ff { hi: den * (1.0 + 1.0 / 256.0), lo: 0.0 };
            assert_eq!(quotient_side(Ff::from_f32(num), larger_den, b, k), -1, "below the bound at 2^{k}");
        }
    }

    /// A ray leaving a slanted triangle from one of its vertices (tmin = 0, the
    /// origin exactly on the plane) hits it at t = 0, for triangles of f32
    /// coordinates from 1e-20 to 1e20 in size. Before plane_side, the exact
    /// test's float-float numerator of `t` came out a rounding below 0 for
    /// some of these and the triangle was missed (Cornell box ×1e-5: rays from
    /// its corners, vertex-coord origin 99.4 %).
    #[test]
    fn rays_from_a_vertex_hit_their_triangle_at_t_0() {
        let mut rng = crate::raygen::SplitMix64(17);
        let mut missed = 0;
        let mut total = 0;
        for trial in 0..4000 {
            let scale = 10f32.powi(trial % 41 - 20);
            let mut p = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * scale;
            let tri = [p(), p(), p()];
            let n = (tri[1] - tri[0]).as_dvec3().cross((tri[2] - tri[0]).as_dvec3());
            let k = 1 + (trial as usize % 2);
            let dir = rng.unit_vector();
            // Directions near the plane leave it too slowly to matter here.
            if n.length() == 0.0 || (n.normalize().dot(dir.as_dvec3())).abs() < 0.05 {
                continue;
            }
            total += 1;
            let ray = WatertightRay::new(tri[k], dir);
            match ray.intersect(tri[0], tri[1], tri[2], 0.0, f32::INFINITY) {
                Some((t, _, _)) => assert_eq!(t, 0.0, "{tri:?} from vertex {k} along {dir}"),
                None => missed += 1,
            }
        }
        assert!(total > 3000, "{total} rays");
        assert_eq!(missed, 0, "{missed} of {total} rays from a vertex missed their triangle");
    }
}
