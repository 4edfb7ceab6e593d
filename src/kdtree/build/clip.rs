//! "Perfect splits" (Havran 2000; Wald & Havran 2006, §4.3): the box of the
//! part of a triangle inside a voxel, by clipping the triangle to the voxel
//! (Sutherland & Hodgman 1974) rather than clipping the triangle's box.
//!
//! The clip runs in f64 on the exact f32 inputs and the resulting box is
//! rounded outward to f32 (with a margin far above the f64 rounding error), so
//! it always contains the exact intersection: a plane the builder later puts
//! between the computed box and the true part of the triangle would otherwise
//! drop the triangle from a leaf it reaches into. Clamped to the voxel and to
//! the triangle's own box, which both contain the exact intersection.

use glam::{DVec3, Vec3};

use crate::geom::Aabb;

/// Largest polygon: a triangle clipped by 6 planes gains at most one vertex per plane.
const MAX_VERTS: usize = 9;

/// A convex polygon on the stack.
#[derive(Clone, Copy)]
struct Polygon {
    verts: [DVec3; MAX_VERTS],
    len: usize,
}

impl Polygon {
    fn push(&mut self, v: DVec3) {
        self.verts[self.len] = v;
        self.len += 1;
    }

    /// Keeps the part with `sign · (v[axis] − bound) ≥ 0`, as Sutherland–Hodgman:
    /// each edge leaving or entering the half-space adds its crossing point, whose
    /// coordinate on `axis` is set to `bound` exactly.
    fn clip(&self, axis: usize, bound: f64, sign: f64) -> Polygon {
        let mut out = Polygon { verts: [DVec3::ZERO; MAX_VERTS], len: 0 };
        let inside = |v: &DVec3| sign * (v[axis] - bound) >= 0.0;
        for i in 0..self.len {
            let a = self.verts[i];
            let b = self.verts[if i + 1 == self.len { 0 } else { i + 1 }];
            let (a_in, b_in) = (inside(&a), inside(&b));
            if a_in {
                out.push(a);
            }
            if a_in != b_in {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                let mut p = a + (b - a) * t;
                p[axis] = bound;
                out.push(p);
            }
        }
        out
    }
}

/// The largest f32 not above `x`.
fn round_down(x: f64) -> f32 {
    let f = x as f32;
    if f as f64 > x {
        next_toward_neg_inf(f)
    } else {
        f
    }
}

/// The smallest f32 not below `x`.
fn round_up(x: f64) -> f32 {
    -round_down(-x)
}

/// The next f32 below a finite `f` (`f32::next_down`, stable only since Rust 1.86).
fn next_toward_neg_inf(f: f32) -> f32 {
    let bits = f.to_bits();
    if f == 0.0 {
        -f32::from_bits(1)
    } else if f > 0.0 {
        f32::from_bits(bits - 1)
    } else {
        f32::from_bits(bits + 1)
    }
}

/// `tri ∩ voxel` as a polygon (empty when the triangle misses the closed voxel).
fn clip_polygon(tri: &[Vec3; 3], tri_box: &Aabb, voxel: &Aabb) -> Polygon {
    let mut poly = Polygon { verts: [DVec3::ZERO; MAX_VERTS], len: 3 };
    for (slot, v) in poly.verts.iter_mut().zip(tri) {
        *slot = v.as_dvec3();
    }
    // Only the planes the triangle crosses need clipping.
    for axis in 0..3 {
        if poly.len > 0 && tri_box.min[axis] < voxel.min[axis] {
            poly = poly.clip(axis, voxel.min[axis] as f64, 1.0);
        }
        if poly.len > 0 && tri_box.max[axis] > voxel.max[axis] {
            poly = poly.clip(axis, voxel.max[axis] as f64, -1.0);
        }
    }
    poly
}

/// A box of points in f64, rounded outward to f32 at the end.
struct Bounds {
    lo: DVec3,
    hi: DVec3,
}

impl Bounds {
    const EMPTY: Bounds = Bounds { lo: DVec3::INFINITY, hi: DVec3::NEG_INFINITY };

    fn add(&mut self, p: DVec3) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    /// The f32 box that surely contains the exact points, clamped to `limit`
    /// (which must contain them too); `None` when no point was added.
    fn conservative(&self, scale: DVec3, limit: &Aabb) -> Option<Aabb> {
        if self.lo.x > self.hi.x {
            return None;
        }
        // The crossing points carry an f64 rounding error of a few ulps of the
        // largest coordinate involved; 2^-40 of it is far above that and far
        // below an f32 ulp, so the outward rounding covers it.
        let margin = scale * (1.0 / (1u64 << 40) as f64);
        let (lo, hi) = (self.lo - margin, self.hi + margin);
        let rounded = Aabb::new(
            Vec3::new(round_down(lo.x), round_down(lo.y), round_down(lo.z)),
            Vec3::new(round_up(hi.x), round_up(hi.y), round_up(hi.z)),
        );
        let clipped = rounded.intersection(*limit);
        // Normalise -0.0 to +0.0, as the triangle boxes are.
        Some(Aabb::new(clipped.min + Vec3::ZERO, clipped.max + Vec3::ZERO))
    }
}

/// The largest coordinate magnitude per axis of a triangle's box and a voxel.
fn scale(tri_box: &Aabb, voxel: &Aabb) -> DVec3 {
    tri_box.min.abs().max(tri_box.max.abs()).max(voxel.min.abs()).max(voxel.max.abs()).as_dvec3()
}

#[cfg(test)]
/// The box of `tri ∩ voxel`, conservatively rounded to f32, or `None` when the
/// triangle misses the (closed) voxel. `tri_box` is the triangle's own box.
pub(super) fn clip_triangle(tri: &[Vec3; 3], tri_box: &Aabb, voxel: &Aabb) -> Option<Aabb> {
    let tight = tri_box.intersection(*voxel);
    if tight.is_empty() {
        return None;
    }
    if voxel.contains_box(tri_box) {
        return Some(*tri_box);
    }
    let poly = clip_polygon(tri, tri_box, voxel);
    let mut bounds = Bounds::EMPTY;
    for v in &poly.verts[..poly.len] {
        bounds.add(*v);
    }
    bounds.conservative(scale(tri_box, voxel), &tight)
}

/// The boxes of `tri ∩ below` and `tri ∩ above`, where `voxel` is split on
/// `axis` at `split` into `below` and `above`: [`clip_triangle`] for both
/// children at the price of one clip.
pub(super) fn clip_triangle_split(
    tri: &[Vec3; 3],
    tri_box: &Aabb,
    voxel: &Aabb,
    axis: usize,
    split: f32,
) -> [Option<Aabb>; 2] {
    let tight = tri_box.intersection(*voxel);
    if tight.is_empty() {
        return [None, None];
    }
    // Most straddlers lie inside the voxel but for the split plane: no clip.
    let (verts, poly);
    let verts: &[DVec3] = if voxel.contains_box(tri_box) {
        verts = tri.map(|v| v.as_dvec3());
        &verts
    } else {
        poly = clip_polygon(tri, tri_box, voxel);
        &poly.verts[..poly.len]
    };
    let pos = split as f64;
    let (mut below, mut above) = (Bounds::EMPTY, Bounds::EMPTY);
    for (i, &a) in verts.iter().enumerate() {
        let b = verts[if i + 1 == verts.len() { 0 } else { i + 1 }];
        if a[axis] <= pos {
            below.add(a);
        }
        if a[axis] >= pos {
            above.add(a);
        }
        if (a[axis] < pos && b[axis] > pos) || (a[axis] > pos && b[axis] < pos) {
            let t = (pos - a[axis]) / (b[axis] - a[axis]);
            let mut p = a + (b - a) * t;
            p[axis] = pos;
            below.add(p);
            above.add(p);
        }
    }
    let scale = scale(tri_box, voxel);
    let (mut tight_below, mut tight_above) = (tight, tight);
    tight_below.max[axis] = tight_below.max[axis].min(split);
    tight_above.min[axis] = tight_above.min[axis].max(split);
    [below.conservative(scale, &tight_below), above.conservative(scale, &tight_above)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_is_outward() {
        for x in [0.1f64, -0.1, 1e-40, -1e-40, 0.0, 3.0, -3.0, 1e30, 16_777_217.0] {
            let (d, u) = (round_down(x), round_up(x));
            assert!((d as f64) <= x && (u as f64) >= x, "{x}: {d} {u}");
            assert!(u == d || next_toward_neg_inf(u) == d, "{x}: {d} {u}");
        }
    }

    #[test]
    fn clips_to_the_voxel() {
        let tri = [Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
        let b = Aabb::from_points(&tri);
        // The corner x, y > 0.6 lies outside the triangle (x + y ≤ 1).
        let corner = Aabb::new(Vec3::new(0.6, 0.6, -1.0), Vec3::new(2.0, 2.0, 1.0));
        assert_eq!(clip_triangle(&tri, &b, &corner), None);
        // The strip x ≥ 0.5 holds the part with y ≤ 0.5.
        let strip = Aabb::new(Vec3::new(0.5, -1.0, -1.0), Vec3::new(2.0, 2.0, 1.0));
        let c = clip_triangle(&tri, &b, &strip).unwrap();
        assert_eq!(c.min, Vec3::new(0.5, 0.0, 0.0));
        assert!(c.max.x == 1.0 && c.max.y >= 0.5 && c.max.y < 0.5 + 1e-6 && c.max.z == 0.0, "{c:?}");
        // Touching the voxel at one vertex: kept, as a point (plus the margin).
        let touch = Aabb::new(Vec3::new(1.0, -1.0, -1.0), Vec3::new(2.0, 2.0, 1.0));
        let c = clip_triangle(&tri, &b, &touch).unwrap();
        assert!(c.min == Vec3::X && c.max.x == 1.0 && c.max.y < 1e-9 && c.max.z == 0.0, "{c:?}");
        // Both children at once agree with clipping to each.
        let voxel = Aabb::new(Vec3::splat(-0.25), Vec3::splat(0.9));
        for (axis, split) in [(0, 0.5), (1, 0.1), (0, 0.85), (2, 0.0)] {
            let (mut below, mut above) = (voxel, voxel);
            below.max[axis] = split;
            above.min[axis] = split;
            let both = clip_triangle_split(&tri, &b, &voxel, axis, split);
            let each = [clip_triangle(&tri, &b, &below), clip_triangle(&tri, &b, &above)];
            for (x, y) in both.iter().zip(&each) {
                let close = |x: &Aabb, y: &Aabb| (x.min - y.min).abs().max((x.max - y.max).abs()).max_element() < 1e-6;
                assert!(
                    x.is_some() == y.is_some() && x.zip(*y).map_or(true, |(x, y)| close(&x, &y)),
                    "{both:?} {each:?}"
                );
            }
        }
        // Inside: the triangle's box.
        assert_eq!(clip_triangle(&tri, &b, &Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0))), Some(b));
    }
}
