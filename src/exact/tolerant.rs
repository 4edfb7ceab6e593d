//! The float64 comparison with tolerances: the closest hit by brute force in
//! f64, and [`agrees`], the rule the builder's and the GPU tracer's random-ray
//! tests use to compare a tracer's hits (f32) with it, checking `t` and the
//! barycentrics as well as the triangle. Cheaper than the exact answer of the
//! parent module, and answers "close enough" where that one answers "exactly".
//!
//! The test is the watertight ray/triangle test of Woop, Benthin & Wald 2013
//! ("Watertight Ray/Triangle Intersection", JCGT 2(1)) evaluated in f64 on the
//! f32 inputs: translate the vertices to the ray origin, permute the axes so the
//! direction's largest component is z, shear the ray onto +z, and take the 2D
//! edge functions of the projected triangle. The ray hits when the three edge
//! functions share a sign (zero counts: edges and vertices are hits; both faces
//! are hit) and their sum (the determinant) is not zero (a ray in the
//! triangle's plane misses); `t` must lie in `[ray.tmin, ray.tmax]`. Zero-area
//! and non-finite triangles are never hit, as in the kd-tree builder
//! ([`crate::kdtree::build::is_skipped`]).
//!
//! The f32 tracer and this comparison round differently, so hits within a few
//! f32 ulps of an edge, of the ray's bounds, or at equal distances may differ
//! legitimately. [`agrees`] separates those cases from real disagreements.
//! Everything here is O(triangles) per ray: for tests only.

use glam::{DVec3, Vec3};

use crate::consts::{PRIM_INCOMPLETE, PRIM_INVALID, PRIM_MISS};
use crate::geom::{Hit, Ray};
use crate::kdtree::build::is_skipped;

/// A hit found by the reference: triangle `prim` at `origin + t·dir`, with the
/// barycentrics of [`Hit`]: point = `(1-u-v)·v0 + u·v1 + v·v2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefHit {
    /// Triangle index.
    pub prim: u32,
    /// Ray parameter of the hit, in units of `dir`.
    pub t: f64,
    /// Barycentric weight of `v1`.
    pub u: f64,
    /// Barycentric weight of `v2`.
    pub v: f64,
}

/// Relative tolerance on `t`: hits whose distances differ by less than this
/// fraction of `t` (plus the position tolerance below, projected onto the ray)
/// count as equally close.
pub const T_REL_TOLERANCE: f64 = 1e-4;

/// Tolerance on positions, relative to the magnitude of the coordinates the
/// test works with (the vertices relative to the ray origin, scaled by the
/// shear): about 170 f32 ulps. A ray passing within this distance of a
/// triangle's edge may be reported as a hit or a miss of that triangle.
pub const POSITION_REL_TOLERANCE: f64 = 1e-5;

/// How a tracer's answer for one ray compares with the reference.
#[derive(Clone, Debug, PartialEq)]
pub enum Agreement {
    /// Neither hits (or the ray is invalid and the tracer says `PRIM_INVALID`).
    BothMiss,
    /// Same triangle, same `t` and barycentrics within tolerance.
    SamePrim,
    /// A different triangle, which the ray hits (within the position tolerance)
    /// at the reference's closest `t` within tolerance: e.g. a ray through an
    /// edge or vertex shared by several triangles, or coincident triangles.
    Tie,
    /// The answers differ only because a hit lies within the position
    /// tolerance of a triangle's edge or of the ray's `[tmin, tmax]` bounds: a
    /// tracer that reports a miss or a farther hit where every closer reference
    /// hit is such a marginal one, or a closer hit on a triangle the reference
    /// misses by less than the tolerance. Rare for random rays; acceptable.
    Grazing,
    /// A real disagreement, described.
    Disagree(String),
}

impl Agreement {
    /// True unless [`Agreement::Disagree`].
    pub fn is_ok(&self) -> bool {
        !matches!(self, Agreement::Disagree(_))
    }
}

/// The ray in f64, with the watertight test's per-ray constants.
struct RefRay {
    origin: DVec3,
    dir: DVec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f64,
    sy: f64,
    sz: f64,
    tmin: f64,
    tmax: f64,
}

impl RefRay {
    fn new(ray: &Ray) -> Option<RefRay> {
        if !ray.is_valid() {
            return None;
        }
        let origin = Vec3::from(ray.origin).as_dvec3();
        let dir = ray.traced_dir().as_dvec3();
        // The watertight test's axes (in f64 the same order of |dir| components).
        let wr = crate::geom::WatertightRay::new(Vec3::from(ray.origin), ray.traced_dir());
        let (kx, ky, kz) = (wr.kx, wr.ky, wr.kz);
        let sz = 1.0 / dir[kz];
        Some(RefRay {
            origin,
            dir,
            kx,
            ky,
            kz,
            sx: dir[kx] * sz,
            sy: dir[ky] * sz,
            sz,
            tmin: ray.tmin as f64,
            tmax: ray.tmax as f64,
        })
    }
}

/// The geometry of one ray/triangle pair, before the hit decision.
#[derive(Clone, Copy, Debug)]
struct Exam {
    t: f64,
    u: f64,
    v: f64,
    /// Signed distance (in the sheared plane) from the ray to the nearest edge
    /// of the projected triangle: ≥ 0 inside or on an edge, < 0 outside.
    margin: f64,
    /// The position tolerance for this pair (see [`POSITION_REL_TOLERANCE`]).
    slack: f64,
    /// Tolerance on `t` ([`T_REL_TOLERANCE`] plus the position tolerance moved
    /// along the ray, larger at grazing angles).
    t_tol: f64,
    /// Tolerance on the barycentrics `u`, `v`.
    bary_tol: f64,
}

impl Exam {
    /// Hit by the exact rule: edges count, `t` within the ray's bounds.
    fn strict(&self, r: &RefRay) -> bool {
        self.margin >= 0.0 && self.t >= r.tmin && self.t <= r.tmax
    }

    /// Hit even when the edges and the bounds move inwards by the tolerance:
    /// every tracer must find it.
    fn robust(&self, r: &RefRay) -> bool {
        self.margin >= self.slack && self.t >= r.tmin + self.t_tol && self.t <= r.tmax - self.t_tol
    }

    /// Hit when the edges and the bounds move outwards by the tolerance: a
    /// tracer may report it.
    fn marginal(&self, r: &RefRay) -> bool {
        self.margin >= -self.slack && self.t >= r.tmin - self.t_tol && self.t <= r.tmax + self.t_tol
    }

    fn to_hit(self, prim: u32) -> RefHit {
        RefHit { prim, t: self.t, u: self.u, v: self.v }
    }
}

/// The watertight test in f64, without the hit decision. `None` when the
/// determinant is zero (the ray is parallel to the triangle's plane or the
/// triangle is degenerate) or not finite.
fn examine(r: &RefRay, tri: &[Vec3; 3]) -> Option<Exam> {
    let (kx, ky, kz) = (r.kx, r.ky, r.kz);
    let a = tri[0].as_dvec3() - r.origin;
    let b = tri[1].as_dvec3() - r.origin;
    let c = tri[2].as_dvec3() - r.origin;
    let ax = a[kx] - r.sx * a[kz];
    let ay = a[ky] - r.sy * a[kz];
    let bx = b[kx] - r.sx * b[kz];
    let by = b[ky] - r.sy * b[kz];
    let cx = c[kx] - r.sx * c[kz];
    let cy = c[ky] - r.sy * c[kz];
    // Edge functions: `e0` is opposite v0 (edge v1-v2), and so on.
    let e0 = cx * by - cy * bx;
    let e1 = ax * cy - ay * cx;
    let e2 = bx * ay - by * ax;
    let det = e0 + e1 + e2;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let sign = det.signum();
    let len0 = (cx - bx).hypot(cy - by);
    let len1 = (ax - cx).hypot(ay - cy);
    let len2 = (bx - ax).hypot(by - ay);
    let dist = |e: f64, len: f64| if len > 0.0 { sign * e / len } else { 0.0 };
    let margin = dist(e0, len0).min(dist(e1, len1)).min(dist(e2, len2));
    let t = (e0 * r.sz * a[kz] + e1 * r.sz * b[kz] + e2 * r.sz * c[kz]) / det;
    let magnitude = a.abs().max_element().max(b.abs().max_element()).max(c.abs().max_element());
    let slack = POSITION_REL_TOLERANCE * magnitude * (1.0 + r.sx.abs() + r.sy.abs());
    let normal = (tri[1] - tri[0]).as_dvec3().cross((tri[2] - tri[0]).as_dvec3());
    let cos = (normal.dot(r.dir) / normal.length()).abs();
    // Edge functions off by `slack · edge length` move the barycentrics by up to
    // `bary_err`: large for slivers and needles, whose determinant is small.
    let bary_err = 2.0 * slack * len0.max(len1).max(len2) / det.abs();
    let (za, zb, zc) = (r.sz * a[kz], r.sz * b[kz], r.sz * c[kz]);
    let z_spread = za.max(zb).max(zc) - za.min(zb).min(zc);
    let t_tol = T_REL_TOLERANCE * t.abs() + if cos > 0.0 { slack / cos } else { f64::INFINITY } + bary_err * z_spread;
    let bary_tol = 1e-4 + bary_err;
    Some(Exam { t, u: e1 / det, v: e2 / det, margin, slack, t_tol, bary_tol })
}

/// Every triangle a tracer may report for `ray` ([`Exam::marginal`]), in index order.
fn candidates(triangles: &[[Vec3; 3]], r: &RefRay) -> Vec<(u32, Exam)> {
    triangles
        .iter()
        .enumerate()
        .filter(|(_, tri)| !is_skipped(tri))
        .filter_map(|(i, tri)| examine(r, tri).map(|e| (i as u32, e)))
        .filter(|(_, e)| e.marginal(r))
        .collect()
}

/// The f64 test of one triangle (see the module docs); `None` for a miss, an
/// invalid ray, or a skipped (zero-area, non-finite) triangle.
pub fn intersect_f64(tri: &[Vec3; 3], ray: &Ray) -> Option<(f64, f64, f64)> {
    let r = RefRay::new(ray)?;
    if is_skipped(tri) {
        return None;
    }
    examine(&r, tri).filter(|e| e.strict(&r)).map(|e| (e.t, e.u, e.v))
}

/// Every triangle the ray hits in `[tmin, tmax]`, by increasing `t`, ties by
/// increasing index.
pub fn all_hits_f64(triangles: &[[Vec3; 3]], ray: &Ray) -> Vec<RefHit> {
    let Some(r) = RefRay::new(ray) else { return Vec::new() };
    let mut hits: Vec<RefHit> =
        candidates(triangles, &r).into_iter().filter(|(_, e)| e.strict(&r)).map(|(i, e)| e.to_hit(i)).collect();
    hits.sort_by(|a, b| a.t.total_cmp(&b.t).then(a.prim.cmp(&b.prim)));
    hits
}

/// The closest hit over all triangles (brute force, f64); among hits at the
/// same `t`, the lowest index. `None` for a miss or an invalid ray.
pub fn closest_hit_f64(triangles: &[[Vec3; 3]], ray: &Ray) -> Option<RefHit> {
    let r = RefRay::new(ray)?;
    let mut best: Option<RefHit> = None;
    for (i, tri) in triangles.iter().enumerate() {
        if is_skipped(tri) {
            continue;
        }
        if let Some(e) = examine(&r, tri).filter(|e| e.strict(&r)) {
            if best.map_or(true, |b| e.t < b.t) {
                best = Some(e.to_hit(i as u32));
            }
        }
    }
    best
}

/// The triangles hit (exactly, as [`closest_hit_f64`] decides) at a distance
/// within `rel_eps · |t|` of `t`, in index order: the candidates of a tie, e.g.
/// the triangles sharing the edge or vertex a ray passes through.
pub fn hits_near(triangles: &[[Vec3; 3]], ray: &Ray, t: f64, rel_eps: f64) -> Vec<RefHit> {
    let tol = rel_eps * t.abs();
    all_hits_f64(triangles, ray).into_iter().filter(|h| (h.t - t).abs() <= tol).collect()
}

/// Compares a tracer's closest hit for `ray` with the f64 reference over all
/// `triangles` (see [`Agreement`]).
///
/// Tolerances, per ray/triangle pair: positions within
/// [`POSITION_REL_TOLERANCE`] × the largest coordinate of the triangle relative
/// to the ray origin (× `1 + |sx| + |sy|`, the shear); distances within
/// [`T_REL_TOLERANCE`] · |t| plus that position tolerance divided by
/// `|n̂ · dir|` (a small position error moves `t` more at grazing angles);
/// barycentrics within 1e-4 plus `2 · position tolerance · longest projected
/// edge / |det|` (large for slivers and needles, whose barycentrics f32 cannot
/// pin down), which also widens the `t` tolerance by that much times the spread
/// of the vertices' distances along the ray.
///
/// The checks: a reported hit must be a hit of the reported triangle (within
/// tolerance) at the reported `t`, `u`, `v`; it must be the closest, unless
/// every closer reference hit is marginal; a miss is right only if no triangle
/// is hit robustly (inside by more than the tolerance).
pub fn agrees(triangles: &[[Vec3; 3]], ray: &Ray, hit: &Hit) -> Agreement {
    Reference::new(triangles, ray).agrees(hit)
}

/// The f64 reference of one ray over all triangles, computed once: [`agrees`]
/// for several tracers' hits of the same ray at the cost of one brute force.
pub struct Reference {
    ray: Ray,
    triangle_count: usize,
    /// `None` for an invalid ray.
    r: Option<RefRay>,
    /// Every triangle a tracer may report ([`Exam::marginal`]), in index order.
    cands: Vec<(u32, Exam)>,
}

impl Reference {
    /// Examines every triangle for `ray` (brute force, f64).
    pub fn new(triangles: &[[Vec3; 3]], ray: &Ray) -> Reference {
        let r = RefRay::new(ray);
        let cands = r.as_ref().map(|r| candidates(triangles, r)).unwrap_or_default();
        Reference { ray: *ray, triangle_count: triangles.len(), r, cands }
    }

    /// Compares a tracer's closest hit for the ray with the reference (see [`agrees`]).
    pub fn agrees(&self, hit: &Hit) -> Agreement {
        use Agreement::*;
        let ray = &self.ray;
        let Some(r) = &self.r else {
            return if hit.prim_id == PRIM_INVALID {
                BothMiss
            } else {
                Disagree(format!("invalid ray {ray:?}: expected PRIM_INVALID, got {hit:?}"))
            };
        };
        let cands = &self.cands;
        let closest = cands
            .iter()
            .filter(|(_, e)| e.strict(r))
            .min_by(|(i, a), (j, b)| a.t.total_cmp(&b.t).then(i.cmp(j)))
            .map(|&(i, e)| (i, e));
        let describe = |what: &str| {
            let reference = closest.map(|(i, e)| e.to_hit(i));
            Disagree(format!("{what}; ray {ray:?}, tracer {hit:?}, reference {reference:?}"))
        };
        if hit.prim_id == PRIM_MISS {
            return match (closest, cands.iter().any(|(_, e)| e.robust(r))) {
                (None, _) => BothMiss,
                (Some(_), false) => Grazing,
                (Some(_), true) => describe("the tracer misses a triangle the ray hits"),
            };
        }
        if hit.prim_id >= PRIM_INCOMPLETE {
            return describe("the tracer returned no valid answer");
        }
        let prim = hit.prim_id;
        if prim as usize >= self.triangle_count {
            return describe("the tracer's triangle index is out of range");
        }
        let Some(&(_, e)) = cands.iter().find(|(i, _)| *i == prim) else {
            return describe("the tracer reports a triangle the ray does not hit");
        };
        let t = hit.t as f64;
        // Written so that a NaN fails the checks.
        let t_ok = (t - e.t).abs() <= e.t_tol;
        if !t_ok {
            return describe(&format!("the tracer's t differs from the reference's {} (tolerance {})", e.t, e.t_tol));
        }
        let uv_ok = (hit.u as f64 - e.u).abs() <= e.bary_tol && (hit.v as f64 - e.v).abs() <= e.bary_tol;
        if !uv_ok {
            return describe(&format!(
                "the tracer's u, v differ from the reference's {}, {} (tolerance {})",
                e.u, e.v, e.bary_tol
            ));
        }
        let Some((closest_prim, c)) = closest else {
            // The reported triangle is hit only within the tolerance.
            return Grazing;
        };
        if closest_prim == prim {
            SamePrim
        } else if (e.t - c.t).abs() <= e.t_tol + c.t_tol {
            Tie
        } else if e.t > c.t {
            // A farther hit: fine only if every closer hit is marginal.
            let missed = cands.iter().find(|(_, o)| o.robust(r) && o.t + o.t_tol < e.t - e.t_tol);
            match missed {
                Some((i, o)) => describe(&format!("the tracer misses a closer hit on triangle {i} at t = {}", o.t)),
                None => Grazing,
            }
        } else {
            // Closer than the reference's closest: the reported triangle is hit only
            // within the tolerance (otherwise it would be the reference's answer).
            Grazing
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::tests::quad;

    fn down(x: f32, y: f32) -> Ray {
        Ray::new(Vec3::new(x, y, 2.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY)
    }

    fn hit_of(h: RefHit) -> Hit {
        Hit { t: h.t as f32, prim_id: h.prim, u: h.u as f32, v: h.v as f32 }
    }

    #[test]
    fn closest_hit_and_bounds() {
        let tris = quad();
        let h = closest_hit_f64(&tris, &down(0.7, 0.2)).unwrap();
        assert_eq!((h.prim, h.t), (2, 1.0));
        // Below the z = 1 triangle: tmin skips it.
        let mut ray = down(0.7, 0.2);
        ray.tmin = 1.5;
        let h = closest_hit_f64(&tris, &ray).unwrap();
        assert_eq!((h.prim, h.t), (0, 2.0));
        // Barycentrics reproduce the point.
        let [v0, v1, v2] = tris[0].map(|v| v.as_dvec3());
        let p = (1.0 - h.u - h.v) * v0 + h.u * v1 + h.v * v2;
        assert!((p - DVec3::new(0.7f32 as f64, 0.2f32 as f64, 0.0)).length() < 1e-12, "{p}");
        // tmax excludes everything.
        ray.tmax = 1.9;
        assert_eq!(closest_hit_f64(&tris, &ray), None);
        // Outside the square and the big triangle.
        assert_eq!(closest_hit_f64(&tris, &down(5.0, 5.0)), None);
        // Both faces count.
        let up = Ray::new(Vec3::new(0.7, 0.2, -1.0), Vec3::Z, 0.0, f32::INFINITY);
        assert_eq!(closest_hit_f64(&tris, &up).unwrap().prim, 0);
        // A ray in the plane of a triangle misses it.
        let along = Ray::new(Vec3::new(-1.0, 0.5, 0.0), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(closest_hit_f64(&tris, &along), None);
        // Invalid rays hit nothing.
        let bad = Ray::new(Vec3::ZERO, Vec3::ZERO, 0.0, 1.0);
        assert_eq!(closest_hit_f64(&tris, &bad), None);
    }

    #[test]
    fn edges_and_ties() {
        let tris = quad();
        let mut ray = down(0.5, 0.5);
        ray.tmin = 1.5;
        // On the shared diagonal: both triangles, the lower index wins.
        let h = closest_hit_f64(&tris, &ray).unwrap();
        assert_eq!(h.prim, 0);
        let near: Vec<u32> = hits_near(&tris, &ray, h.t, 1e-9).iter().map(|h| h.prim).collect();
        assert_eq!(near, vec![0, 1]);
        // The other triangle is a tie.
        let other = hit_of(hits_near(&tris, &ray, h.t, 1e-9)[1]);
        assert_eq!(agrees(&tris, &ray, &other), Agreement::Tie);
        assert_eq!(agrees(&tris, &ray, &hit_of(h)), Agreement::SamePrim);
        // Vertices and outer edges count.
        assert_eq!(closest_hit_f64(&tris, &Ray { tmin: 1.5, ..down(1.0, 0.0) }).unwrap().prim, 0);
        assert_eq!(closest_hit_f64(&tris, &Ray { tmin: 1.5, ..down(0.0, 0.5) }).unwrap().prim, 1);
        assert_eq!(all_hits_f64(&tris, &down(0.5, 0.5)).len(), 3);
    }

    #[test]
    fn agreement_verdicts() {
        let tris = quad();
        let ray = down(0.7, 0.2);
        let right = hit_of(closest_hit_f64(&tris, &ray).unwrap());
        assert_eq!(agrees(&tris, &ray, &right), Agreement::SamePrim);
        // Missing a robust hit, reporting the farther triangle, a wrong t, wrong u/v,
        // a triangle that is not hit, an incomplete answer: all disagree.
        assert!(!agrees(&tris, &ray, &Hit::MISS).is_ok());
        let far = hit_of(closest_hit_f64(&tris, &Ray { tmin: 1.5, ..ray }).unwrap());
        assert!(!agrees(&tris, &ray, &far).is_ok());
        assert!(!agrees(&tris, &ray, &Hit { t: 1.01, ..right }).is_ok());
        assert!(!agrees(&tris, &ray, &Hit { u: right.u + 0.1, ..right }).is_ok());
        assert!(!agrees(&tris, &ray, &Hit { prim_id: 1, ..far }).is_ok());
        assert!(!agrees(&tris, &ray, &Hit { prim_id: PRIM_INCOMPLETE, ..right }).is_ok());
        assert!(!agrees(&tris, &ray, &Hit { prim_id: 7, ..right }).is_ok());
        // A miss where nothing is hit.
        assert_eq!(agrees(&tris, &down(5.0, 5.0), &Hit::MISS), Agreement::BothMiss);
        // Invalid rays expect PRIM_INVALID.
        let bad = Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X, 0.0, 1.0);
        assert_eq!(agrees(&tris, &bad, &Hit { prim_id: PRIM_INVALID, ..Hit::MISS }), Agreement::BothMiss);
        assert!(!agrees(&tris, &bad, &Hit::MISS).is_ok());
        // A ray grazing the outer edge x = 1 of triangle 0 (below the big one):
        // a miss and a hit are both acceptable.
        let graze = Ray { tmin: 1.5, ..down(1.0 + 1e-7, 0.5) };
        assert_eq!(closest_hit_f64(&tris, &graze), None);
        assert_eq!(agrees(&tris, &graze, &Hit::MISS), Agreement::BothMiss);
        let h = Hit { t: 2.0, prim_id: 0, u: 0.5, v: 0.5 };
        assert_eq!(agrees(&tris, &graze, &h), Agreement::Grazing);
        let inside = Ray { tmin: 1.5, ..down(1.0 - 1e-7, 0.5) };
        assert_eq!(agrees(&tris, &inside, &Hit::MISS), Agreement::Grazing);
        // ... but not a clear miss of the edge.
        assert!(!agrees(&tris, &Ray { tmin: 1.5, ..down(1.01, 0.5) }, &h).is_ok());
    }

    #[test]
    fn skipped_triangles_are_never_hit() {
        let tris = vec![
            [Vec3::ZERO, Vec3::X, Vec3::X],
            [Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            [Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X, Vec3::Y],
        ];
        let ray = Ray::new(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
        assert_eq!(closest_hit_f64(&tris, &ray), None);
        assert!(!agrees(&tris, &ray, &Hit { t: 1.0, prim_id: 0, u: 0.0, v: 0.0 }).is_ok());
    }
}
