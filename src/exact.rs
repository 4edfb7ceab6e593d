//! The exact answer for a ray and a triangle soup, on the f32 inputs taken as
//! exact real numbers: "the correct hit" even for rays through edges and
//! vertices, and the verdict on a tracer's answer measured against it.
//!
//! Every finite f32 is an integer multiple of 2^-149, so scaled by 2^149 it is a
//! (big) integer, and the predicates below are evaluated exactly in integers
//! ([`num_bigint::BigInt`]). With `A, B, C` the vertices minus the ray origin
//! and `d` the direction, the ray's line meets the closed triangle iff the three
//! triple products `d · (C × B)`, `d · (A × C)`, `d · (B × A)` (the edge
//! functions of the watertight test, up to a positive factor) do not have
//! opposite signs and are not all zero (a ray in the triangle's plane misses, as
//! in the tracers). Then `t = (u·A_k + v·B_k + w·C_k) / ((u + v + w) · d_k)` for
//! any axis `k` with `d_k ≠ 0`, exactly rational, compared exactly with `tmin`,
//! `tmax` and the other hits. The *tie set* is every triangle hit at exactly the
//! smallest `t`: the triangles around a vertex or edge the ray passes through,
//! or coincident triangles.
//!
//! An f64 filter with error bounds answers almost every pair; only pairs whose
//! signs or `t` the filter cannot certify are evaluated in integers.
//! Zero-area and non-finite triangles are never hit, as in the builder
//! ([`crate::kdtree::build::is_skipped`]). Brute force over all triangles: for
//! tests and `kdtrace verify`, not for speed.
//!
//! [`tolerant`] is the float64 comparison with tolerances that the random-ray
//! tests of the builder and the GPU tracer use; it also checks barycentrics.

pub mod tolerant;

use std::cmp::Ordering;

use glam::{DVec3, Vec3};
use num_bigint::BigInt;
use num_traits::{Signed, ToPrimitive, Zero};

use crate::consts::{PRIM_INCOMPLETE, PRIM_INVALID, PRIM_MISS};
use crate::geom::{Hit, Ray};
use crate::kdtree::build::is_skipped;

/// `x · 2^149` as an integer (exact for every finite f32).
fn fixed(x: f32) -> BigInt {
    debug_assert!(x.is_finite());
    let bits = x.to_bits();
    let exponent = ((bits >> 23) & 0xff) as i32;
    let fraction = (bits & 0x7f_ffff) as u64;
    // x = mantissa · 2^(shift - 149).
    let (mantissa, shift) = if exponent == 0 { (fraction, 0) } else { (fraction | 1 << 23, exponent - 1) };
    let magnitude = BigInt::from(mantissa) << shift as usize;
    if bits >> 31 == 1 {
        -magnitude
    } else {
        magnitude
    }
}

type Big3 = [BigInt; 3];

fn fixed3(v: Vec3) -> Big3 {
    [fixed(v.x), fixed(v.y), fixed(v.z)]
}

fn sub3(a: &Big3, b: &Big3) -> Big3 {
    [&a[0] - &b[0], &a[1] - &b[1], &a[2] - &b[2]]
}

/// `d · (p × q)`, exactly.
fn triple_exact(d: &Big3, p: &Big3, q: &Big3) -> BigInt {
    let x = &p[1] * &q[2] - &p[2] * &q[1];
    let y = &p[2] * &q[0] - &p[0] * &q[2];
    let z = &p[0] * &q[1] - &p[1] * &q[0];
    &d[0] * x + &d[1] * y + &d[2] * z
}

/// `d · (p × q)` in f64, and the magnitude of its terms (`|d| · (|p| ×⁺ |q|)`).
fn triple_f64(d: DVec3, p: DVec3, q: DVec3) -> (f64, f64) {
    let x = p.y * q.z - p.z * q.y;
    let y = p.z * q.x - p.x * q.z;
    let z = p.x * q.y - p.y * q.x;
    let (d_abs, p_abs, q_abs) = (d.abs(), p.abs(), q.abs());
    let mx = p_abs.y * q_abs.z + p_abs.z * q_abs.y;
    let my = p_abs.z * q_abs.x + p_abs.x * q_abs.z;
    let mz = p_abs.x * q_abs.y + p_abs.y * q_abs.x;
    (d.x * x + d.y * y + d.z * z, d_abs.x * mx + d_abs.y * my + d_abs.z * mz)
}

/// Relative error bound of the f64 triple products (about 10 roundings of 2^-53,
/// the translation's included), generously: 2^-46.
const F64_GAMMA: f64 = 1.0 / (1u64 << 46) as f64;
/// Added to every f64 error bound, so underflow never certifies a sign.
const F64_TINY: f64 = 1e-290;

/// An exact ray parameter `num / den` (`den > 0`).
#[derive(Clone, Debug)]
struct Frac {
    num: BigInt,
    den: BigInt,
}

impl Frac {
    fn cmp(&self, o: &Frac) -> Ordering {
        (&self.num * &o.den).cmp(&(&o.num * &self.den))
    }

    /// Compares with an f32 bound (±inf allowed).
    fn cmp_f32(&self, x: f32) -> Ordering {
        if x == f32::INFINITY {
            Ordering::Less
        } else if x == f32::NEG_INFINITY {
            Ordering::Greater
        } else {
            (&self.num << 149usize).cmp(&(fixed(x) * &self.den))
        }
    }
}

/// A ray, exactly and in f64.
struct ExactRay {
    origin: Big3,
    dir: Big3,
    origin64: DVec3,
    dir64: DVec3,
    /// Axis of the largest direction component.
    k: usize,
    tmin: f32,
    tmax: f32,
}

impl ExactRay {
    fn new(ray: &Ray) -> Option<ExactRay> {
        if !ray.is_valid() {
            return None;
        }
        let (o, d) = (Vec3::from(ray.origin), ray.traced_dir());
        // The watertight test's dominant axis (any axis with d[k] != 0 would do).
        let k = crate::geom::WatertightRay::new(o, d).kz;
        Some(ExactRay {
            origin: fixed3(o),
            dir: fixed3(d),
            origin64: o.as_dvec3(),
            dir64: d.as_dvec3(),
            k,
            tmin: ray.tmin,
            tmax: ray.tmax,
        })
    }

    /// The exact `t` of the hit of `tri` in `[tmin, tmax]`, or `None`.
    fn hit_exact(&self, tri: &[Vec3; 3]) -> Option<Frac> {
        let [a, b, c] = tri.map(|v| sub3(&fixed3(v), &self.origin));
        let d = &self.dir;
        let u = triple_exact(d, &c, &b);
        let v = triple_exact(d, &a, &c);
        let w = triple_exact(d, &b, &a);
        let neg = u.is_negative() || v.is_negative() || w.is_negative();
        let pos = u.is_positive() || v.is_positive() || w.is_positive();
        if neg && pos {
            return None;
        }
        let det = &u + &v + &w;
        if det.is_zero() {
            return None;
        }
        let k = self.k;
        let mut num = &u * &a[k] + &v * &b[k] + &w * &c[k];
        let mut den = det * &d[k];
        if den.is_negative() {
            num = -num;
            den = -den;
        }
        let t = Frac { num, den };
        let in_bounds = t.cmp_f32(self.tmin) != Ordering::Less && t.cmp_f32(self.tmax) != Ordering::Greater;
        in_bounds.then_some(t)
    }

    /// The f64 filter: a certain miss, a certain hit with `t` and its error
    /// bound, or unsure.
    fn filter(&self, tri: &[Vec3; 3]) -> Filter {
        let o = self.origin64;
        let [a, b, c] = tri.map(|v| v.as_dvec3() - o);
        let d = self.dir64;
        let (u, mu) = triple_f64(d, c, b);
        let (v, mv) = triple_f64(d, a, c);
        let (w, mw) = triple_f64(d, b, a);
        let (eu, ev, ew) = (F64_GAMMA * mu + F64_TINY, F64_GAMMA * mv + F64_TINY, F64_GAMMA * mw + F64_TINY);
        let negative = u < -eu || v < -ev || w < -ew;
        let positive = u > eu || v > ev || w > ew;
        if negative && positive {
            return Filter::Miss;
        }
        if !(u.abs() > eu && v.abs() > ev && w.abs() > ew && (mu + mv + mw).is_finite()) {
            return Filter::Unsure;
        }
        // All three certain and of one sign: the line hits inside.
        let k = self.k;
        let det = u + v + w;
        let t = (u * a[k] + v * b[k] + w * c[k]) / (det * d[k]);
        // The weights' errors move t by at most their relative error times the
        // spread of the vertices along the ray; the rest is rounding of t itself.
        let rel = (eu + ev + ew) / det.abs();
        let spread = (a[k].abs() + b[k].abs() + c[k].abs()) / d[k].abs();
        let t_err = 4.0 * rel * spread + F64_GAMMA * t.abs() + F64_TINY;
        if !t.is_finite() || !t_err.is_finite() || rel > 0.25 {
            return Filter::Unsure;
        }
        let (tmin, tmax) = (self.tmin as f64, self.tmax as f64);
        if t + t_err < tmin || t - t_err > tmax {
            Filter::Miss
        } else if t - t_err >= tmin && t + t_err <= tmax {
            Filter::Hit { t, t_err }
        } else {
            Filter::Unsure
        }
    }
}

enum Filter {
    Miss,
    Hit { t: f64, t_err: f64 },
    Unsure,
}

/// The exact answer for one ray.
#[derive(Clone, Debug, PartialEq)]
pub enum Exact {
    /// The ray is invalid (NaN or infinite origin, NaN or zero direction, NaN bounds).
    Invalid,
    /// No triangle is hit in `[tmin, tmax]`.
    Miss,
    /// The closest hit.
    Hit {
        /// Every triangle hit at exactly the closest `t`, ascending.
        ties: Vec<u32>,
        /// That `t`, rounded to f64.
        t: f64,
    },
}

fn frac_to_f64(f: &Frac) -> f64 {
    if f.num.is_zero() {
        return 0.0;
    }
    // The quotient to 64 significant bits (or more) by integer division, then
    // scaled: within 2^-63 relative before the final rounding to f64. (Cutting
    // both to 64 bits instead lost the bits of the smaller one: t near 2^-20 came
    // out 1e-14 off, beyond the tie tolerance of `closest_exact`.)
    let s = 64 + f.den.bits() as i64 - f.num.bits() as i64;
    let q = if s >= 0 { (&f.num << s as usize) / &f.den } else { &f.num / (&f.den << (-s) as usize) };
    let half = (-s / 2).clamp(-1000, 1000) as i32;
    let rest = (-s - half as i64).clamp(-1100, 1100) as i32;
    q.to_f64().unwrap_or(f64::NAN) * 2f64.powi(half) * 2f64.powi(rest)
}

/// The exact closest hit of `ray` among `triangles` (brute force).
pub fn closest_exact(triangles: &[[Vec3; 3]], ray: &Ray) -> Exact {
    let Some(r) = ExactRay::new(ray) else { return Exact::Invalid };
    // Certain hits with their f64 intervals, and exact hits of the unsure pairs.
    let mut cands: Vec<(u32, f64, f64, Option<Frac>)> = Vec::new();
    for (i, tri) in triangles.iter().enumerate() {
        if is_skipped(tri) {
            continue;
        }
        match r.filter(tri) {
            Filter::Miss => {}
            Filter::Hit { t, t_err } => cands.push((i as u32, t, t_err, None)),
            Filter::Unsure => {
                if let Some(f) = r.hit_exact(tri) {
                    let t = frac_to_f64(&f);
                    cands.push((i as u32, t, 1e-15 * t.abs() + F64_TINY, Some(f)));
                }
            }
        }
    }
    let Some(upper) = cands.iter().map(|c| c.1 + c.2).min_by(f64::total_cmp) else {
        return Exact::Miss;
    };
    let mut near: Vec<(u32, f64, f64, Option<Frac>)> = cands.into_iter().filter(|c| c.1 - c.2 <= upper).collect();
    if near.len() == 1 {
        return Exact::Hit { ties: vec![near[0].0], t: near[0].1 };
    }
    // Close calls: exact t for each, then the exact minimum and its ties.
    for c in near.iter_mut() {
        if c.3.is_none() {
            c.3 = r.hit_exact(&triangles[c.0 as usize]);
        }
    }
    near.retain(|c| c.3.is_some());
    near.sort_by(|x, y| x.3.as_ref().unwrap().cmp(y.3.as_ref().unwrap()).then(x.0.cmp(&y.0)));
    let Some(first) = near.first() else { return Exact::Miss };
    let best = first.3.clone().unwrap();
    let ties: Vec<u32> =
        near.iter().filter(|c| c.3.as_ref().unwrap().cmp(&best) == Ordering::Equal).map(|c| c.0).collect();
    Exact::Hit { ties, t: frac_to_f64(&best) }
}

/// True when `ray` hits triangle `prim` exactly inside `[tmin, tmax]`.
pub fn hits_exact(triangles: &[[Vec3; 3]], ray: &Ray, prim: u32) -> bool {
    let Some(r) = ExactRay::new(ray) else { return false };
    let tri = &triangles[prim as usize];
    if is_skipped(tri) {
        return false;
    }
    match r.filter(tri) {
        Filter::Miss => false,
        Filter::Hit { .. } => true,
        Filter::Unsure => r.hit_exact(tri).is_some(),
    }
}

/// The exact `t` (rounded to f64) at which `ray` hits triangle `prim` inside
/// `[tmin, tmax]`, or `None` when it misses it.
pub fn hit_t_exact(triangles: &[[Vec3; 3]], ray: &Ray, prim: u32) -> Option<f64> {
    let r = ExactRay::new(ray)?;
    let tri = triangles.get(prim as usize)?;
    if is_skipped(tri) {
        return None;
    }
    r.hit_exact(tri).map(|f| frac_to_f64(&f))
}

/// Distance from `p` to the closed triangle `tri` (f64).
pub fn point_triangle_distance(p: DVec3, tri: &[Vec3; 3]) -> f64 {
    let [a, b, c] = tri.map(|v| v.as_dvec3());
    let n = (b - a).cross(c - a);
    let len = n.length();
    let segment = |s: DVec3, e: DVec3| {
        let se = e - s;
        let l2 = se.length_squared();
        let h = if l2 > 0.0 { ((p - s).dot(se) / l2).clamp(0.0, 1.0) } else { 0.0 };
        (p - (s + h * se)).length()
    };
    let edges = segment(a, b).min(segment(b, c)).min(segment(c, a));
    if len == 0.0 || !len.is_finite() {
        return edges;
    }
    let n = n / len;
    let q = p - n * n.dot(p - a);
    let inside =
        n.dot((b - a).cross(q - a)) >= 0.0 && n.dot((c - b).cross(q - b)) >= 0.0 && n.dot((a - c).cross(q - c)) >= 0.0;
    if inside {
        n.dot(p - a).abs()
    } else {
        edges
    }
}

/// Distance from `p` (in the triangle's plane) to the triangle's boundary.
fn boundary_distance(p: DVec3, tri: &[Vec3; 3]) -> f64 {
    let [a, b, c] = tri.map(|v| v.as_dvec3());
    let segment = |s: DVec3, e: DVec3| {
        let se = e - s;
        let l2 = se.length_squared();
        let h = if l2 > 0.0 { ((p - s).dot(se) / l2).clamp(0.0, 1.0) } else { 0.0 };
        (p - (s + h * se)).length()
    };
    segment(a, b).min(segment(b, c)).min(segment(c, a))
}

/// How a tracer's answer compares with the exact one. The first three agree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Verdict {
    /// Both say miss (or both say the ray is invalid).
    BothMiss,
    /// The same triangle (the lowest of the tie set, or the only hit).
    Same,
    /// Another triangle of the exact tie set.
    Tie,
    /// Another triangle, hit within the tolerance of the exact hit point: a
    /// neighbour across an edge the ray passes within rounding of.
    Neighbor,
    /// The tracer misses (or hits farther) where the exact hit lies within the
    /// tolerance of its triangle's boundary or of the ray's bounds.
    GrazingMiss,
    /// The tracer hits a triangle the ray passes within the tolerance of, where
    /// the exact answer is a miss or a farther hit.
    GrazingHit,
    /// Serious: the tracer misses, or hits farther, while the exact closest hit
    /// lies inside its triangle by more than the tolerance.
    MissedHit,
    /// Serious: the tracer's hit point is farther than the tolerance from the
    /// triangle it names (or the index is out of range).
    FalseHit,
    /// Serious: the tracer's answer is not an answer (incomplete, or invalid
    /// flags that disagree with the ray).
    BadAnswer,
}

impl Verdict {
    /// Every verdict, in order.
    pub const ALL: [Verdict; 9] = [
        Verdict::BothMiss,
        Verdict::Same,
        Verdict::Tie,
        Verdict::Neighbor,
        Verdict::GrazingMiss,
        Verdict::GrazingHit,
        Verdict::MissedHit,
        Verdict::FalseHit,
        Verdict::BadAnswer,
    ];

    /// True for the verdicts that agree with the exact answer.
    pub fn agrees(self) -> bool {
        matches!(self, Verdict::BothMiss | Verdict::Same | Verdict::Tie)
    }

    /// True for the serious errors.
    pub fn is_serious(self) -> bool {
        matches!(self, Verdict::MissedHit | Verdict::FalseHit | Verdict::BadAnswer)
    }

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Verdict::BothMiss => "both miss",
            Verdict::Same => "same",
            Verdict::Tie => "tie",
            Verdict::Neighbor => "neighbour",
            Verdict::GrazingMiss => "grazing miss",
            Verdict::GrazingHit => "grazing hit",
            Verdict::MissedHit => "MISSED HIT",
            Verdict::FalseHit => "FALSE HIT",
            Verdict::BadAnswer => "BAD ANSWER",
        }
    }
}

/// Position tolerance of the verdicts, relative to the magnitude of the
/// coordinates involved (origin, hit point): 2^-16, about 256 f32 ulps.
pub const POSITION_TOLERANCE: f64 = 1.0 / 65536.0;

/// Position tolerance of the verdicts relative to a triangle's own coordinates
/// (their largest magnitude): 2^-40. A point nearer a triangle than this cannot
/// be told off it: the distance, computed in f64, carries rounding of a few
/// 2^-53 of those coordinates, the tracers' float-float settles hits to about
/// 2^-46 of them, and their on-edge band is 2^-40 (ACCURACY.md). It matters only
/// where the ray's origin and hit point are far smaller than the triangle (a
/// hit beside the world origin on a unit-sized triangle), so that
/// [`POSITION_TOLERANCE`] alone would demand more than f64 can measure.
pub const TRIANGLE_TOLERANCE: f64 = 1.0 / 1_099_511_627_776.0;

/// [`TRIANGLE_TOLERANCE`] for `tri`.
fn triangle_tolerance(tri: &[Vec3; 3]) -> f64 {
    let m = tri.iter().fold(0.0f32, |m, v| m.max(v.abs().max_element()));
    TRIANGLE_TOLERANCE * m as f64
}

/// The verdict on a tracer's closest hit `hit` for `ray`, against `exact`
/// (from [`closest_exact`]). Also returns the distance between the tracer's
/// and the exact hit point when both hit (0 otherwise).
pub fn judge(triangles: &[[Vec3; 3]], ray: &Ray, hit: &Hit, exact: &Exact) -> (Verdict, f64) {
    let (o, d) = (Vec3::from(ray.origin).as_dvec3(), ray.traced_dir().as_dvec3());
    let point = |t: f64| o + t * d;
    let tol_at =
        |p: DVec3| POSITION_TOLERANCE * o.abs().max_element().max(p.abs().max_element()).max(f64::MIN_POSITIVE);
    match exact {
        Exact::Invalid => {
            let v = if hit.prim_id == PRIM_INVALID { Verdict::BothMiss } else { Verdict::BadAnswer };
            return (v, 0.0);
        }
        _ if hit.prim_id == PRIM_INVALID || hit.prim_id == PRIM_INCOMPLETE => return (Verdict::BadAnswer, 0.0),
        _ => {}
    }
    // The exact closest hit lies within the tolerance of its triangle's boundary,
    // or of the ray's bounds?
    let grazing_exact = |ties: &[u32], t: f64| {
        let p = point(t);
        let tol = tol_at(p);
        let near_bound = |b: f32| b.is_finite() && ((t - b as f64) * d.length()).abs() <= tol;
        near_bound(ray.tmin)
            || near_bound(ray.tmax)
            || ties.iter().all(|&i| {
                let tri = &triangles[i as usize];
                boundary_distance(p, tri) <= tol.max(triangle_tolerance(tri))
            })
    };
    if hit.prim_id == PRIM_MISS {
        return match exact {
            Exact::Hit { ties, t } if grazing_exact(ties, *t) => (Verdict::GrazingMiss, 0.0),
            Exact::Hit { .. } => (Verdict::MissedHit, 0.0),
            _ => (Verdict::BothMiss, 0.0),
        };
    }
    let prim = hit.prim_id;
    if prim as usize >= triangles.len() {
        return (Verdict::FalseHit, 0.0);
    }
    let p = point(hit.t as f64);
    let tol = tol_at(p);
    let tol_t = tol / d.length();
    let t_in_bounds = hit.t as f64 >= ray.tmin as f64 - tol_t && hit.t as f64 <= ray.tmax as f64 + tol_t;
    let tri = &triangles[prim as usize];
    if !(t_in_bounds && point_triangle_distance(p, tri) <= tol.max(triangle_tolerance(tri))) {
        return (Verdict::FalseHit, 0.0);
    }
    let Exact::Hit { ties, t } = exact else { return (Verdict::GrazingHit, 0.0) };
    let err = (p - point(*t)).length();
    if ties.first() == Some(&prim) {
        return (Verdict::Same, err);
    }
    if ties.contains(&prim) {
        return (Verdict::Tie, err);
    }
    if err <= tol {
        return (Verdict::Neighbor, err);
    }
    if (hit.t as f64) < *t {
        (Verdict::GrazingHit, err)
    } else if grazing_exact(ties, *t) {
        (Verdict::GrazingMiss, err)
    } else {
        (Verdict::MissedHit, err)
    }
}

/// The verdict on an any-hit (shadow) answer: agreement when both say
/// occluded (the reported triangle really hit in `[tmin, tmax]`) or both say
/// free.
pub fn judge_any(triangles: &[[Vec3; 3]], ray: &Ray, hit: &Hit, exact: &Exact) -> Verdict {
    match exact {
        Exact::Invalid => return if hit.prim_id == PRIM_INVALID { Verdict::BothMiss } else { Verdict::BadAnswer },
        _ if hit.prim_id == PRIM_INVALID || hit.prim_id == PRIM_INCOMPLETE => return Verdict::BadAnswer,
        _ => {}
    }
    if hit.prim_id != PRIM_MISS && (hit.prim_id as usize) < triangles.len() && hits_exact(triangles, ray, hit.prim_id) {
        return if exact == &Exact::Miss { Verdict::BadAnswer } else { Verdict::Same };
    }
    // Not an exact occluder: judge it like a closest hit (grazing or false).
    match judge(triangles, ray, hit, exact).0 {
        Verdict::Same | Verdict::Tie => Verdict::Same,
        v => v,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact triangle test's edge signs near an edge (`geom::edge_sign`, twin
    /// of `edge_sign_exact` in triangle.glsl) are the exact triple product's,
    /// except within 2^-100 of the vectors' magnitudes, where they may say 0 (on
    /// the edge); reversing the edge negates them exactly. Origins exactly on an
    /// edge's line and 1e-17, 1e-25 or 3e-35 (relative) off it: spokes of a fan
    /// (`cos`/`sin` values, cos(π/2) = 6.1e-17 beside 1) and lines through small
    /// integer points, at scales 2^-60..2^60, axes permuted.
    #[test]
    fn edge_signs_are_exact_outside_2_pow_minus_100() {
        use crate::geom::edge_sign;
        use crate::raygen::SplitMix64;
        let mut rng = SplitMix64(5);
        let (mut hard, mut zero_exact, mut decided) = (0, 0, 0);
        for i in 0..20_000 {
            let scale = 2f32.powi(rng.below(121) as i32 - 60);
            let off = [0.0, 1e-17, -1e-25, 3e-35][rng.below(4)] * scale;
            let k = 2f32.powi(-(rng.below(10) as i32 + 1));
            let (p, q, o) = if i % 2 == 0 {
                let a = rng.below(64) as f64 * std::f64::consts::TAU / 64.0;
                let q = Vec3::new(a.cos() as f32, a.sin() as f32, 0.0) * scale;
                let on = |c: f32| if c.abs() < 1e-10 * scale { 0.0 } else { c * k };
                (Vec3::ZERO, q, Vec3::new(on(q.x), on(q.y), off))
            } else {
                let mut int = || (rng.below(17) as f32 - 8.0) * scale;
                let (p, q) = (Vec3::new(int(), int(), 0.0), Vec3::new(int(), int(), 0.0));
                (p, q, Vec3::new(p.x + (q.x - p.x) * k, p.y + (q.y - p.y) * k, off))
            };
            let turn = rng.below(3);
            let [p, q, o] = [p, q, o].map(|v| Vec3::from_array([v[turn], v[(turn + 1) % 3], v[(turn + 2) % 3]]));
            let mut d = rng.unit_vector();
            if i % 5 == 0 {
                d[rng.below(3)] = 0.0;
            }
            let (dd, pp, qq) = (fixed3(d), sub3(&fixed3(p), &fixed3(o)), sub3(&fixed3(q), &fixed3(o)));
            let exact = triple_exact(&dd, &pp, &qq);
            let exact_sign = if exact.is_zero() {
                0
            } else if exact.is_positive() {
                1
            } else {
                -1
            };
            let sign = edge_sign(p, q, o, d);
            assert_eq!(edge_sign(q, p, o, d), -sign, "reversed edge {p} {q} {o} {d}");
            // |det| relative to the max norms of p - o, q - o and d (each scaled by 2^149).
            let norm = |v: Vec3| (v.abs().max_element() as f64).max(f64::MIN_POSITIVE);
            let relative = exact.to_f64().unwrap().abs() * 2f64.powi(-447) / (norm(p - o) * norm(q - o) * norm(d));
            hard += usize::from(relative < 2f64.powi(-40));
            zero_exact += usize::from(exact_sign == 0);
            decided += usize::from(exact_sign != 0 && relative < 2f64.powi(-40) && sign == exact_sign);
            if sign != exact_sign {
                assert!(
                    sign == 0 && relative <= 2f64.powi(-99),
                    "{p} {q} {o} {d}: {sign} vs exact {exact_sign} ({relative:e})"
                );
            }
        }
        // Inside the float-float band (what the exact orientation is for): some exactly on
        // the line, many off it and decided.
        assert!(hard > 10_000 && zero_exact > 1_000 && decided > 5_000, "{hard} {zero_exact} {decided}");
    }

    /// Two triangles sharing the diagonal (0,0,0)-(1,1,0) of the unit square in
    /// z = 0, and one more at z = 1 covering the same square.
    pub(super) fn quad() -> Vec<[Vec3; 3]> {
        vec![
            [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0)],
            [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)],
            [Vec3::new(-1.0, -1.0, 1.0), Vec3::new(3.0, -1.0, 1.0), Vec3::new(-1.0, 3.0, 1.0)],
        ]
    }

    fn down(x: f32, y: f32, tmin: f32) -> Ray {
        Ray::new(Vec3::new(x, y, 2.0), Vec3::new(0.0, 0.0, -1.0), tmin, f32::INFINITY)
    }

    #[test]
    fn fixed_point_is_exact() {
        assert_eq!(fixed(1.0), BigInt::from(1) << 149usize);
        assert_eq!(fixed(-0.5), -(BigInt::from(1) << 148usize));
        assert_eq!(fixed(f32::from_bits(1)), BigInt::from(1));
        assert_eq!(fixed(0.0), BigInt::zero());
        assert_eq!(fixed(-0.0), BigInt::zero());
        assert_eq!(fixed(3.0), BigInt::from(3) << 149usize);
        assert_eq!(fixed(f32::MAX), BigInt::from(0xff_ffffu64) << (104 + 149usize));
    }

    #[test]
    fn edges_vertices_and_bounds() {
        let tris = quad();
        // Interior of triangle 0 under the big one.
        assert_eq!(closest_exact(&tris, &down(0.7, 0.2, 0.0)), Exact::Hit { ties: vec![2], t: 1.0 });
        assert_eq!(closest_exact(&tris, &down(0.7, 0.2, 1.5)), Exact::Hit { ties: vec![0], t: 2.0 });
        // Exactly on the shared diagonal: both triangles tie.
        assert_eq!(closest_exact(&tris, &down(0.5, 0.5, 1.5)), Exact::Hit { ties: vec![0, 1], t: 2.0 });
        // The shared vertex (0, 0).
        assert_eq!(closest_exact(&tris, &down(0.0, 0.0, 1.5)), Exact::Hit { ties: vec![0, 1], t: 2.0 });
        // Just off the diagonal, by one ulp each way.
        let x = 0.5f32;
        let above = f32::from_bits(x.to_bits() + 1);
        assert_eq!(closest_exact(&tris, &down(x, above, 1.5)), Exact::Hit { ties: vec![1], t: 2.0 });
        assert_eq!(closest_exact(&tris, &down(above, x, 1.5)), Exact::Hit { ties: vec![0], t: 2.0 });
        // Outer edge x = 1 is a hit, one ulp beyond is a miss.
        assert_eq!(closest_exact(&tris, &down(1.0, 0.5, 1.5)), Exact::Hit { ties: vec![0], t: 2.0 });
        assert_eq!(closest_exact(&tris, &down(1.0000001, 0.5, 1.5)), Exact::Miss);
        // A hit exactly at tmin counts, one ulp past it does not.
        assert_eq!(closest_exact(&tris, &down(0.7, 0.2, 2.0)), Exact::Hit { ties: vec![0], t: 2.0 });
        assert_eq!(closest_exact(&tris, &down(0.7, 0.2, 2.0000002)), Exact::Miss);
        let mut r = down(0.7, 0.2, 1.5);
        r.tmax = 2.0;
        assert_eq!(closest_exact(&tris, &r), Exact::Hit { ties: vec![0], t: 2.0 });
        r.tmax = 1.9999999;
        assert_eq!(closest_exact(&tris, &r), Exact::Miss);
        // In the plane of triangles 0 and 1: they miss; invalid rays are invalid.
        let along = Ray::new(Vec3::new(-1.0, 0.5, 0.0), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(closest_exact(&tris, &along), Exact::Miss);
        assert_eq!(closest_exact(&tris, &Ray::new(Vec3::ZERO, Vec3::ZERO, 0.0, 1.0)), Exact::Invalid);
    }

    #[test]
    fn filter_and_exact_agree_on_random_pairs() {
        let mut rng = crate::raygen::SplitMix64(12345);
        let mut rnd = || rng.range(-1.0, 1.0);
        for _ in 0..2000 {
            let tri = [Vec3::new(rnd(), rnd(), rnd()), Vec3::new(rnd(), rnd(), rnd()), Vec3::new(rnd(), rnd(), rnd())];
            let ray =
                Ray::new(Vec3::new(rnd(), rnd(), rnd()) * 3.0, Vec3::new(rnd(), rnd(), rnd()), 0.0, f32::INFINITY);
            let r = ExactRay::new(&ray).unwrap();
            let exact = r.hit_exact(&tri);
            match r.filter(&tri) {
                Filter::Miss => assert!(exact.is_none()),
                Filter::Hit { t, t_err } => {
                    let f = exact.expect("filter hit, exact miss");
                    assert!((frac_to_f64(&f) - t).abs() <= t_err);
                }
                Filter::Unsure => {}
            }
        }
    }

    #[test]
    fn verdicts() {
        let tris = quad();
        let ray = down(0.5, 0.5, 1.5);
        let exact = closest_exact(&tris, &ray);
        let hit = |prim, t| Hit { t, prim_id: prim, u: 0.0, v: 0.0 };
        assert_eq!(judge(&tris, &ray, &hit(0, 2.0), &exact).0, Verdict::Same);
        assert_eq!(judge(&tris, &ray, &hit(1, 2.0), &exact).0, Verdict::Tie);
        assert_eq!(judge(&tris, &ray, &Hit::MISS, &exact).0, Verdict::GrazingMiss);
        assert_eq!(judge(&tris, &ray, &hit(2, 1.0), &exact).0, Verdict::FalseHit);
        let inside = down(0.7, 0.2, 1.5);
        let exact = closest_exact(&tris, &inside);
        assert_eq!(judge(&tris, &inside, &Hit::MISS, &exact).0, Verdict::MissedHit);
        assert_eq!(judge(&tris, &inside, &hit(1, 2.0), &exact).0, Verdict::FalseHit);
        assert_eq!(judge(&tris, &inside, &hit(0, 2.5), &exact).0, Verdict::FalseHit);
        let incomplete = Hit { prim_id: PRIM_INCOMPLETE, ..Hit::MISS };
        assert_eq!(judge(&tris, &inside, &incomplete, &exact).0, Verdict::BadAnswer);
        // Any-hit: the big triangle occludes the segment too.
        let shadow = down(0.7, 0.2, 0.0);
        let exact = closest_exact(&tris, &shadow);
        assert_eq!(judge_any(&tris, &shadow, &hit(0, 2.0), &exact), Verdict::Same);
        assert_eq!(judge_any(&tris, &shadow, &Hit::MISS, &exact), Verdict::MissedHit);
    }

    /// Beside the world origin on a unit-sized triangle, a point 2^-45 off the
    /// triangle (t off by 1/32 of itself; float-float settles t to ~2^-46 of the
    /// triangle's coordinates) is no FALSE HIT, though it lies far beyond 2^-16
    /// of the origin's and the point's own magnitude (2^-40); 2^-35 off is.
    #[test]
    fn tolerance_includes_the_triangle_scale() {
        let tris = quad();
        let tiny = 2f32.powi(-40);
        let ray = Ray::new(Vec3::new(tiny, 0.5 * tiny, tiny), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY);
        let exact = closest_exact(&tris, &ray);
        assert_eq!(exact, Exact::Hit { ties: vec![0], t: tiny as f64 });
        let hit = |t: f32| Hit { t, prim_id: 0, u: 0.0, v: 0.0 };
        let near = judge(&tris, &ray, &hit(tiny - 2f32.powi(-45)), &exact).0;
        assert!(!near.is_serious(), "{near:?}");
        let far = judge(&tris, &ray, &hit(tiny + 2f32.powi(-35)), &exact).0;
        assert_eq!(far, Verdict::FalseHit);
    }

    /// A long direction (t near 2^-20) through the shared diagonal: both
    /// triangles tie at exactly t = 2^-20. (The f64 view of an exact `t` once
    /// kept 64 bits of the denominator and fewer of the numerator, 1e-14 off,
    /// and the tie set lost a triangle.)
    #[test]
    fn ties_survive_tiny_t() {
        let tris = quad();
        let scale = 2f32.powi(20);
        let ray = Ray::new(Vec3::new(0.5, 0.5, 2.0), Vec3::new(0.0, 0.0, -2.0 * scale), 0.0, f32::INFINITY);
        assert_eq!(closest_exact(&tris[..2], &ray), Exact::Hit { ties: vec![0, 1], t: 2f64.powi(-20) });
        for (num, den) in [(1i64, 3i64), (-7, 1 << 40), (12345, 1 << 20)] {
            let f = Frac { num: BigInt::from(num) << 300usize, den: BigInt::from(den) << 300usize };
            assert_eq!(frac_to_f64(&f), num as f64 / den as f64);
        }
        // A numerator with fewer bits than the denominator and a low bit that
        // matters at f64 precision: (2^100 + 2^50) / 2^120 = 2^-20 + 2^-70 (cutting
        // both to the denominator's top 64 bits dropped the 2^50).
        let f = Frac {
            num: (BigInt::from(1) << 100usize) + (BigInt::from(1) << 50usize),
            den: BigInt::from(1) << 120usize,
        };
        assert_eq!(frac_to_f64(&f), 2f64.powi(-20) + 2f64.powi(-70));
    }
}
