//! Hard rays for the accuracy stress suite, and the agreement table of a
//! tracer's answers with the exact reference ([`crate::exact`]). Used by
//! `kdtrace verify` and `tests/stress.rs`.
//!
//! Each [`Category`] aims at one of the numerical pitfalls of kd-tree ray
//! tracing: rays through vertices and edges, along edges, inside triangle
//! planes and split planes, leaving surfaces, from 1e3 to 1e7 scene diagonals
//! away (also nearly parallel to an axis plane), exactly axis-parallel with
//! signed zeros and denormals, bounded segments ending within ulps of a hit,
//! huge finite `tmax`, and direction lengths from 1e-15 to 1e15. Every batch is
//! seeded and reproducible.

use glam::Vec3;
use rayon::prelude::*;

use crate::exact::{closest_exact, judge, judge_any, Exact, Verdict};
use crate::geom::{Aabb, Hit, Ray};
use crate::kdtree::build::is_skipped;
use crate::kdtree::KdTree;
use crate::raygen::SplitMix64;

/// A kind of hard ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Category {
    /// Easy rays: uniform origins in the box, uniform directions (the baseline).
    Random,
    /// Exactly axis-parallel directions, the other components ±0.0 or ±denormal,
    /// through points on triangles.
    AxisParallel,
    /// Origins exactly on split planes of the tree, half of them with the
    /// direction inside the plane.
    SplitPlaneOrigin,
    /// Origins whose coordinates are vertex coordinates (where split planes lie).
    VertexCoordOrigin,
    /// Rays aimed exactly at vertices.
    ToVertex,
    /// Rays aimed at points of edges (shared edges mostly).
    ToEdge,
    /// Rays along edges, starting before them.
    AlongEdge,
    /// Rays inside a triangle's plane.
    InTrianglePlane,
    /// Rays inside axis-aligned planes that contain triangles (direction
    /// component exactly 0 along the axis).
    AxisPlane,
    /// Rays leaving a point on a triangle (`tmin = 0`), either side.
    OnSurface,
    /// Origins 1e5 scene diagonals away, aimed at points on triangles.
    FarOrigin,
    /// Rays toward points on triangles with direction lengths 1e-15 … 1e15.
    DirectionScale,
    /// Origins 1e3 scene diagonals away, aimed at points on triangles.
    FarOrigin1e3,
    /// Origins 1e7 scene diagonals away, aimed at points on triangles.
    FarOrigin1e7,
    /// Huge finite `tmax` (1e30, 3e38 or `f32::MAX`) toward points on triangles,
    /// vertices and edge midpoints, from points in the box or 1e5 diagonals
    /// away, direction lengths 2^-20 … 2^40 times the distance to the target.
    HugeTmax,
    /// From 1e5 scene diagonals away toward points on triangles, nearly parallel
    /// to an axis plane: one direction component 1e-3 … 1e-30 of the others.
    FarGrazing,
    /// Origins 1e10 … 1e30 scene diagonals away (a power of ten drawn per ray,
    /// at most 1e36 from the box: every `t` stays finite), aimed at points on
    /// triangles along directions within a few scene diagonals over the distance of
    /// an axis (an f32 direction of any other kind cannot be aimed from that far).
    FarOrigin1e30,
    /// Exactly axis-parallel rays through points on triangles (the other
    /// direction components ±0.0) from 1e3 … 1e30 scene diagonals away along
    /// the axis (as for `FarOrigin1e30`).
    FarAxisParallel,
    /// Bounded segments toward a point on a triangle (reached at t ≈ 1): `tmax` a
    /// few ulps before, at or after 1 (some with `tmin` > 0 too), `tmin` a few
    /// ulps around 1 with `tmax` = +inf, and shadow-ray segments between two
    /// surface points; from the box or 1e5 diagonals away.
    BoundedSegment,
}

impl Category {
    /// Every category, in table order.
    pub const ALL: [Category; 19] = [
        Category::Random,
        Category::AxisParallel,
        Category::SplitPlaneOrigin,
        Category::VertexCoordOrigin,
        Category::ToVertex,
        Category::ToEdge,
        Category::AlongEdge,
        Category::InTrianglePlane,
        Category::AxisPlane,
        Category::OnSurface,
        Category::FarOrigin1e3,
        Category::FarOrigin,
        Category::FarOrigin1e7,
        Category::FarOrigin1e30,
        Category::FarAxisParallel,
        Category::HugeTmax,
        Category::FarGrazing,
        Category::BoundedSegment,
        Category::DirectionScale,
    ];

    /// Name for tables and the CLI.
    pub fn name(self) -> &'static str {
        match self {
            Category::Random => "random",
            Category::AxisParallel => "axis-parallel",
            Category::SplitPlaneOrigin => "split-plane origin",
            Category::VertexCoordOrigin => "vertex-coord origin",
            Category::ToVertex => "to vertex",
            Category::ToEdge => "to edge",
            Category::AlongEdge => "along edge",
            Category::InTrianglePlane => "in triangle plane",
            Category::AxisPlane => "in axis plane",
            Category::OnSurface => "on surface",
            Category::FarOrigin1e3 => "far origin 1e3",
            Category::FarOrigin => "far origin 1e5",
            Category::FarOrigin1e7 => "far origin 1e7",
            Category::FarOrigin1e30 => "far origin 1e10-1e30",
            Category::FarAxisParallel => "far axis-parallel 1e3-1e30",
            Category::HugeTmax => "huge tmax",
            Category::FarGrazing => "far, nearly axis-parallel",
            Category::BoundedSegment => "bounded segment",
            Category::DirectionScale => "direction scale",
        }
    }
}

/// What the generators draw from.
struct Source<'a> {
    triangles: &'a [[Vec3; 3]],
    /// Triangles the tracer can hit (not skipped).
    live: Vec<u32>,
    bounds: Aabb,
    size: f32,
    rng: SplitMix64,
}

impl Source<'_> {
    fn index(&mut self, n: usize) -> usize {
        (self.rng.next_u64() % n as u64) as usize
    }

    /// 10^k scene diagonals for k drawn from `lowest` to 30, at most 1e36 (so that
    /// an origin that far and every `t` to the box stay finite in f32).
    fn far_distance(&mut self, lowest: i32, diagonal: f32) -> f32 {
        let k = lowest + self.index((31 - lowest) as usize) as i32;
        (10f64.powi(k) * diagonal as f64).min(1e36) as f32
    }

    fn triangle(&mut self) -> [Vec3; 3] {
        let i = self.index(self.live.len());
        self.triangles[self.live[i] as usize]
    }

    fn vertex(&mut self) -> Vec3 {
        self.triangle()[self.index(3)]
    }

    /// A uniform point of a random triangle (rounded to f32).
    fn surface_point(&mut self) -> Vec3 {
        let [a, b, c] = self.triangle();
        let (mut s, mut t) = (self.rng.next_f32(), self.rng.next_f32());
        if s + t > 1.0 {
            (s, t) = (1.0 - s, 1.0 - t);
        }
        a + s * (b - a) + t * (c - a)
    }

    /// A uniform point of the box grown by 10 % on each side.
    fn box_point(&mut self) -> Vec3 {
        let e = self.bounds.extent();
        let p = Vec3::new(self.rng.next_f32(), self.rng.next_f32(), self.rng.next_f32());
        self.bounds.min - 0.1 * e + p * 1.2 * e
    }

    fn sign(&mut self) -> f32 {
        if self.rng.next_u64() & 1 == 0 {
            1.0
        } else {
            -1.0
        }
    }
}

fn toward(origin: Vec3, target: Vec3) -> Ray {
    Ray::new(origin, target - origin, 0.0, f32::INFINITY)
}

/// `count` rays of `category` for the scene (`tree` gives the split planes).
/// Returns no rays for [`Category::AxisPlane`] when no triangle lies in an axis plane,
/// and fewer than `count` where a scene near f32's limits would make a ray non-finite.
///
/// About 160 lines: one short match arm per category, kept in one place so the
/// categories read side by side.
pub fn stress_rays(category: Category, triangles: &[[Vec3; 3]], tree: &KdTree, count: usize, seed: u64) -> Vec<Ray> {
    let live: Vec<u32> = (0..triangles.len() as u32).filter(|&i| !is_skipped(&triangles[i as usize])).collect();
    if live.is_empty() {
        return Vec::new();
    }
    let bounds = tree.bounds;
    let size = bounds.extent().max_element().max(f32::MIN_POSITIVE);
    // In f64: an f32 length overflows for extents above about 1e19 (the far
    // categories then made no finite ray at all).
    let diagonal = (bounds.extent().as_dvec3().length() as f32).max(f32::MIN_POSITIVE);
    let mut s = Source { triangles, live, bounds, size, rng: SplitMix64(seed ^ (category as u64) << 32) };
    let mut splits = Vec::new();
    if category == Category::SplitPlaneOrigin {
        tree.for_each_node(|_, node, b, _| {
            if !node.is_leaf() {
                splits.push((node.axis(), node.split(), b));
            }
        });
    }
    let mut planes = Vec::new();
    if category == Category::AxisPlane {
        for &i in &s.live {
            let t = &triangles[i as usize];
            planes.extend(
                (0..3).filter(|&axis| t[0][axis] == t[1][axis] && t[1][axis] == t[2][axis]).map(|axis| (axis, i)),
            );
        }
        if planes.is_empty() {
            return Vec::new();
        }
    }
    (0..count)
        .map(|_| match category {
            Category::Random => Ray::new(s.box_point(), s.rng.unit_vector(), 0.0, f32::INFINITY),
            Category::AxisParallel => {
                let p = s.surface_point();
                let axis = s.index(3);
                let sign = s.sign();
                let mut origin = p;
                origin[axis] =
                    if sign > 0.0 { bounds.min[axis] - 0.1 * s.size } else { bounds.max[axis] + 0.1 * s.size };
                let mut dir = Vec3::ZERO;
                dir[axis] = sign * 10f32.powi(s.index(7) as i32 - 3);
                for other in [(axis + 1) % 3, (axis + 2) % 3] {
                    dir[other] = match s.index(3) {
                        0 => 0.0,
                        1 => -0.0,
                        _ => s.sign() * f32::from_bits(1 + s.index(1000) as u32),
                    };
                }
                Ray::new(origin, dir, 0.0, f32::INFINITY)
            }
            Category::SplitPlaneOrigin => {
                if splits.is_empty() {
                    return Ray::new(s.box_point(), s.rng.unit_vector(), 0.0, f32::INFINITY);
                }
                let (axis, split, b) = splits[s.index(splits.len())];
                let e = b.extent();
                let mut origin = b.min + Vec3::new(s.rng.next_f32(), s.rng.next_f32(), s.rng.next_f32()) * e;
                origin[axis] = split;
                if s.rng.next_u64() & 1 == 0 {
                    toward(origin, s.surface_point())
                } else {
                    let mut dir = s.rng.unit_vector();
                    dir[axis] = if s.rng.next_u64() & 1 == 0 { 0.0 } else { -0.0 };
                    Ray::new(origin, dir, 0.0, f32::INFINITY)
                }
            }
            Category::VertexCoordOrigin => {
                let origin = Vec3::new(s.vertex().x, s.vertex().y, s.vertex().z);
                toward(origin, s.surface_point())
            }
            Category::ToVertex => {
                let origin = s.box_point();
                toward(origin, s.vertex())
            }
            Category::ToEdge => {
                let [a, b, c] = s.triangle();
                let (p, q) = [(a, b), (b, c), (c, a)][s.index(3)];
                let h = if s.rng.next_u64() & 1 == 0 { 0.5 } else { s.rng.next_f32() };
                let origin = s.box_point();
                toward(origin, p + h * (q - p))
            }
            Category::AlongEdge => {
                let [a, b, c] = s.triangle();
                let (p, q) = [(a, b), (b, c), (c, a)][s.index(3)];
                Ray::new(p - 0.5 * (q - p), q - p, 0.0, f32::INFINITY)
            }
            Category::InTrianglePlane => {
                let [a, b, c] = s.triangle();
                let plane_point = |s: &mut Source| {
                    let (u, v) = (s.rng.next_f32() * 2.0 - 0.5, s.rng.next_f32() * 2.0 - 0.5);
                    a + u * (b - a) + v * (c - a)
                };
                let (p, q) = (plane_point(&mut s), plane_point(&mut s));
                toward(p, q)
            }
            Category::AxisPlane => {
                let (axis, i) = planes[s.index(planes.len())];
                let tri = triangles[i as usize];
                let mut origin = s.box_point();
                origin[axis] = tri[0][axis];
                let (mut u, mut v) = (s.rng.next_f32(), s.rng.next_f32());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let mut target = tri[0] + u * (tri[1] - tri[0]) + v * (tri[2] - tri[0]);
                target[axis] = tri[0][axis];
                let mut dir = target - origin;
                dir[axis] = 0.0;
                Ray::new(origin, dir, 0.0, f32::INFINITY)
            }
            Category::OnSurface => {
                let origin = s.surface_point();
                Ray::new(origin, s.rng.unit_vector(), 0.0, f32::INFINITY)
            }
            Category::FarOrigin1e3 | Category::FarOrigin | Category::FarOrigin1e7 => {
                let distance = match category {
                    Category::FarOrigin1e3 => 1e3,
                    Category::FarOrigin => 1e5,
                    _ => 1e7,
                };
                let origin = bounds.center() + s.rng.unit_vector() * (distance * diagonal);
                toward(origin, s.surface_point())
            }
            Category::FarOrigin1e30 => {
                // An f32 direction holds 24 bits, so a generic one cannot aim at the
                // scene from this far (its rounding alone moves the ray by about 1e-7
                // of the distance). These run off an axis by an angle of about a few
                // scene diagonals over the distance, and reach the target within
                // rounding of the scene's size: the dominant axis exactly, the others
                // offset from the target by scene-sized amounts.
                let target = s.surface_point().as_dvec3();
                let distance = s.far_distance(10, diagonal) as f64;
                let axis = s.index(3);
                let mut u = glam::DVec3::ZERO;
                u[axis] = s.sign() as f64;
                for other in [(axis + 1) % 3, (axis + 2) % 3] {
                    u[other] = (2.0 * s.rng.next_f32() as f64 - 1.0) * 2.0 * diagonal as f64 / distance;
                }
                Ray::new((target - u * distance).as_vec3(), u.as_vec3(), 0.0, f32::INFINITY)
            }
            Category::FarAxisParallel => {
                let target = s.surface_point();
                let axis = s.index(3);
                let sign = s.sign();
                let mut origin = target;
                origin[axis] -= sign * s.far_distance(3, diagonal);
                let mut dir = Vec3::ZERO;
                dir[axis] = sign;
                for other in [(axis + 1) % 3, (axis + 2) % 3] {
                    dir[other] = if s.rng.next_u64() & 1 == 0 { 0.0 } else { -0.0 };
                }
                Ray::new(origin, dir, 0.0, f32::INFINITY)
            }
            Category::HugeTmax => {
                let origin = match s.rng.next_u64() & 1 {
                    0 => s.box_point(),
                    _ => bounds.center() + s.rng.unit_vector() * (1e5 * diagonal),
                };
                // Aimed at edges and vertices too (the exact test decides those, with
                // the bound scaled far beyond f32's range when the direction is long).
                let target = match s.index(3) {
                    0 => s.surface_point(),
                    1 => s.vertex(),
                    _ => {
                        let [a, b, c] = s.triangle();
                        let (p, q) = [(a, b), (b, c), (c, a)][s.index(3)];
                        p + 0.5 * (q - p)
                    }
                };
                let tmax = [1e30, 3e38, f32::MAX][s.index(3)];
                let length = 2f32.powi(s.index(61) as i32 - 20);
                let ray = toward(origin, target);
                Ray { tmax, dir: (Vec3::from(ray.dir) * length).into(), ..ray }
            }
            Category::BoundedSegment => {
                let target = s.surface_point();
                let origin = match s.index(4) {
                    0 => bounds.center() + s.rng.unit_vector() * (1e5 * diagonal),
                    _ => s.box_point(),
                };
                // One ulp of 1.0 up or down, k times.
                let near_one = |k: i32| f32::from_bits((1.0f32.to_bits() as i32 + k) as u32);
                let k = s.index(7) as i32 - 3;
                match s.index(4) {
                    0 => Ray { tmax: near_one(k), ..toward(origin, target) },
                    1 => Ray { tmin: 0.25 * s.rng.next_f32(), tmax: near_one(k), ..toward(origin, target) },
                    2 => Ray { tmin: near_one(k), ..toward(origin, target) },
                    // A shadow ray: from one surface point to another, both ends left out.
                    _ => {
                        let from = s.surface_point();
                        Ray::new(from, target - from, 1e-4, 1.0 - 1e-4)
                    }
                }
            }
            Category::FarGrazing => {
                let target = s.surface_point();
                let mut dir = s.rng.unit_vector();
                let axis = s.index(3);
                dir[axis] = s.sign() * 10f32.powi(-3 - s.index(28) as i32) * dir.abs().max_element();
                let dir = dir.normalize();
                Ray::new(target - dir * (1e5 * diagonal), dir, 0.0, f32::INFINITY)
            }
            Category::DirectionScale => {
                let origin = s.box_point();
                let target = s.surface_point();
                let scale = 10f32.powi(s.index(31) as i32 - 15);
                Ray::new(origin, (target - origin) * scale, 0.0, f32::INFINITY)
            }
        })
        // A scene near f32's limits (e.g. scaled by 1e25) can push a far origin or a
        // long direction past f32::MAX: such a ray is left out, not traced as an
        // invalid one (the exact reference needs finite inputs).
        .filter(|r| Vec3::from(r.origin).is_finite() && Vec3::from(r.dir).is_finite())
        .collect()
}

/// Counts of verdicts over a batch.
#[derive(Clone, Debug, Default)]
pub struct Tally {
    /// Rays judged.
    pub rays: usize,
    /// Count per verdict, indexed like [`Verdict::ALL`].
    pub counts: [usize; Verdict::ALL.len()],
    /// Largest distance between the tracer's and the exact hit point among
    /// agreeing hits, relative to the magnitude of the coordinates.
    pub max_point_error: f64,
    /// Rays the tracer marked [`PRIM_INCOMPLETE`](crate::consts::PRIM_INCOMPLETE)
    /// (also counted as bad answers).
    pub incomplete: usize,
    /// Up to 5 seriously wrong rays, with the tracer's answer.
    pub serious_examples: Vec<(Ray, Hit, Verdict)>,
    /// Up to 5 rays that disagree without a serious error, with the tracer's answer.
    pub other_examples: Vec<(Ray, Hit, Verdict)>,
}

impl Tally {
    /// Rays whose answer agrees with the exact one.
    pub fn agreeing(&self) -> usize {
        Verdict::ALL.iter().zip(&self.counts).filter(|(v, _)| v.agrees()).map(|(_, n)| n).sum()
    }

    /// Rays with a serious error.
    pub fn serious(&self) -> usize {
        Verdict::ALL.iter().zip(&self.counts).filter(|(v, _)| v.is_serious()).map(|(_, n)| n).sum()
    }

    /// Fraction of rays that agree (1 for an empty batch).
    pub fn agreement(&self) -> f64 {
        if self.rays == 0 {
            1.0
        } else {
            self.agreeing() as f64 / self.rays as f64
        }
    }

    /// The count of one verdict.
    pub fn count(&self, v: Verdict) -> usize {
        self.counts[Verdict::ALL.iter().position(|&x| x == v).expect("a verdict")]
    }
}

/// The exact answers for `rays` (brute force over `triangles`, in parallel).
pub fn exact_answers(triangles: &[[Vec3; 3]], rays: &[Ray]) -> Vec<Exact> {
    rays.par_iter().map(|ray| closest_exact(triangles, ray)).collect()
}

/// Judges a tracer's `hits` for `rays` against the exact reference (brute
/// force over `triangles`, in parallel). `any_hit`: the hits are any-hit answers.
pub fn judge_batch(triangles: &[[Vec3; 3]], rays: &[Ray], hits: &[Hit], any_hit: bool) -> Tally {
    judge_with(triangles, rays, hits, &exact_answers(triangles, rays), any_hit)
}

/// [`judge_batch`] with the exact answers computed beforehand ([`exact_answers`]).
pub fn judge_with(triangles: &[[Vec3; 3]], rays: &[Ray], hits: &[Hit], exacts: &[Exact], any_hit: bool) -> Tally {
    assert_eq!(rays.len(), hits.len(), "one hit per ray");
    assert_eq!(rays.len(), exacts.len(), "one exact answer per ray");
    let verdicts: Vec<(Verdict, f64)> = rays
        .par_iter()
        .zip(hits)
        .zip(exacts)
        .map(|((ray, hit), exact)| {
            if any_hit {
                (judge_any(triangles, ray, hit, exact), 0.0)
            } else {
                let (v, err) = judge(triangles, ray, hit, exact);
                let o = Vec3::from(ray.origin).as_dvec3();
                let p = o + hit.t as f64 * Vec3::from(ray.dir).as_dvec3();
                let scale = o.abs().max_element().max(p.abs().max_element()).max(f64::MIN_POSITIVE);
                (v, if v.agrees() && err.is_finite() { err / scale } else { 0.0 })
            }
        })
        .collect();
    let incomplete = crate::trace::incomplete_rays(hits).len();
    let mut tally = Tally { rays: rays.len(), incomplete, ..Tally::default() };
    for (i, (v, err)) in verdicts.into_iter().enumerate() {
        tally.counts[Verdict::ALL.iter().position(|&x| x == v).expect("a verdict")] += 1;
        tally.max_point_error = tally.max_point_error.max(err);
        if v.is_serious() && tally.serious_examples.len() < 5 {
            tally.serious_examples.push((rays[i], hits[i], v));
        } else if !v.agrees() && !v.is_serious() && tally.other_examples.len() < 5 {
            tally.other_examples.push((rays[i], hits[i], v));
        }
    }
    tally
}

/// The header of [`table_row`]'s table (markdown).
pub fn table_header() -> String {
    let mut s = String::from("| category | rays | agree | ");
    s += &Verdict::ALL.map(|v| v.name()).join(" | ");
    s += " | incomplete | max point err |\n|---|---|---|";
    s += &"---|".repeat(Verdict::ALL.len() + 2);
    s
}

/// One row of the agreement table.
pub fn table_row(label: &str, t: &Tally) -> String {
    let counts: Vec<String> = t.counts.iter().map(|n| n.to_string()).collect();
    format!(
        "| {label} | {} | {:.2}% | {} | {} | {:.1e} |",
        t.rays,
        100.0 * t.agreement(),
        counts.join(" | "),
        t.incomplete,
        t.max_point_error
    )
}
