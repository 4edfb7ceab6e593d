//! Float-float ("double-f32") arithmetic: a value held as `hi + lo` in two
//! `f32`, `|lo| <= ulp(hi) / 2`, about 48 significant bits. The CPU twin of
//! `glsl/shared/ff.glsl`, which replaces f64 in the kernels so that they need
//! no `shaderFloat64` (see that file): the same operations in the same order,
//! so CPU and GPU give the same bits.
//!
//! Plain IEEE f32 operations, denormals kept, as lavapipe computes them (a
//! device that flushes denormals may differ in the last bits of the far-ray
//! paths, whose error bounds allow for the flushed terms; see ff.glsl).

use crate::consts::ORIENT_ZERO;

/// A float-float value `hi + lo`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Ff {
    /// The value rounded to f32.
    pub hi: f32,
    /// The rest, `|lo| <= ulp(hi) / 2`.
    pub lo: f32,
}

impl std::ops::Neg for Ff {
    type Output = Ff;
    #[inline]
    fn neg(self) -> Ff {
        Ff { hi: -self.hi, lo: -self.lo }
    }
}

/// `a + b = s + e` exactly (Knuth's two-sum). Twin of `ff_two_sum`.
#[inline]
pub fn two_sum(a: f32, b: f32) -> Ff {
    let s = a + b;
    let bb = s - a;
    let e = (a - (s - bb)) + (b - bb);
    Ff { hi: s, lo: e }
}

/// Veltkamp's split into two 12-bit halves. Twin of `ff_split`.
#[inline]
fn split(a: f32) -> (f32, f32) {
    let c = 4097.0 * a;
    let hi = c - (c - a);
    (hi, a - hi)
}

/// `a * b = p + e` exactly (Dekker 1971). Twin of `ff_two_prod`.
#[inline]
pub fn two_prod(a: f32, b: f32) -> Ff {
    let (xh, xl) = split(a);
    let (yh, yl) = split(b);
    let p = a * b;
    let e = ((((xh * yh) - p) + (xh * yl)) + (xl * yh)) + (xl * yl);
    Ff { hi: p, lo: e }
}

// The methods are named after their GLSL twins (ff_add, ff_mul, ...), not the
// operator traits, so that the twin reads like the shader.
#[allow(clippy::should_implement_trait)]
impl Ff {
    /// An f32 as a pair.
    #[inline]
    pub fn from_f32(a: f32) -> Ff {
        Ff { hi: a, lo: 0.0 }
    }

    /// `a - b` of two f32, exactly. Twin of `ff_diff`.
    #[inline]
    pub fn diff(a: f32, b: f32) -> Ff {
        two_sum(a, -b)
    }

    /// Twin of `ff_add`.
    #[inline]
    pub fn add(self, y: Ff) -> Ff {
        let s = two_sum(self.hi, y.hi);
        let t = two_sum(self.lo, y.lo);
        let e = s.lo + t.hi;
        let u = two_sum(s.hi, e);
        let f = u.lo + t.lo;
        two_sum(u.hi, f)
    }

    /// Twin of `ff_sub`.
    #[inline]
    pub fn sub(self, y: Ff) -> Ff {
        self.add(-y)
    }

    /// Twin of `ff_add_f`.
    #[inline]
    pub fn add_f(self, b: f32) -> Ff {
        let s = two_sum(self.hi, b);
        let e = s.lo + self.lo;
        two_sum(s.hi, e)
    }

    /// Twin of `ff_mul`.
    #[inline]
    pub fn mul(self, y: Ff) -> Ff {
        let p = two_prod(self.hi, y.hi);
        let cross = (self.hi * y.lo) + (self.lo * y.hi);
        let e = p.lo + cross;
        two_sum(p.hi, e)
    }

    /// Twin of `ff_mul_f`.
    #[inline]
    pub fn mul_f(self, b: f32) -> Ff {
        let p = two_prod(self.hi, b);
        let e = p.lo + (self.lo * b);
        two_sum(p.hi, e)
    }

    /// `self / y` (`y.hi != 0`), about 2^-44 relative. Twin of `ff_div`.
    #[inline]
    pub fn div(self, y: Ff) -> Ff {
        let rcp = 1.0 / y.hi;
        let q1 = self.hi * rcp;
        let r = self.sub(y.mul_f(q1));
        let q2 = r.hi * rcp;
        two_sum(q1, q2)
    }

    /// `self >= b`. Twin of `ff_ge_f`.
    #[inline]
    pub fn ge_f(self, b: f32) -> bool {
        self.hi > b || (self.hi == b && self.lo >= 0.0)
    }

    /// `self <= y`. Twin of `ff_le`.
    #[inline]
    pub fn le(self, y: Ff) -> bool {
        self.hi < y.hi || (self.hi == y.hi && self.lo <= y.lo)
    }

    /// The value in f64 (tests and references only).
    pub fn to_f64(self) -> f64 {
        self.hi as f64 + self.lo as f64
    }
}

/// The sum of eight f32 as an exact expansion (Shewchuk 1997, Grow-Expansion),
/// rounded to float-float. Twin of `ff_exact_sum8`.
pub fn exact_sum8(terms: [f32; 8]) -> Ff {
    let mut h = [0.0f32; 8];
    for m in 0..8 {
        let mut q = terms[m];
        for hi in h.iter_mut().take(m) {
            let s = two_sum(q, *hi);
            (q, *hi) = (s.hi, s.lo);
        }
        h[m] = q;
    }
    let rest = h[1..7].iter().fold(h[0], |acc, &x| acc + x);
    two_sum(h[7], rest)
}

/// Terms of [`orient_sign`]'s expansion at most: 3 cross-product components × 4
/// pairs of parts × 2 products × 2 parts, each times one component of the third
/// vector (1 part for an f32 vector, 2 for float-float) × 2 parts.
const ORIENT_TERMS: usize = 192;

/// The sign of `det[x, y, z] = z · (x × y)` for `x`, `y`, `z` exact float-float
/// vectors, each scaled by a power of two so that its largest component lies
/// in `[1, 2)`: -1, 0 or 1, exact unless the determinant lies within `2^-100`
/// of 0 (then 0). The products of the parts (96 when `z` is an f32 vector, all
/// its low parts 0; else 192) are exact (Dekker), and repeated error-free
/// passes over them (Ogita, Rump & Oishi's VecSum) carry the sum to the last
/// term until it outweighs the rest (0 within [`ORIENT_ZERO`]). Twin of
/// `ff_orient_sign` in ff.glsl.
pub fn orient_sign(x: [Ff; 3], y: [Ff; 3], z: [Ff; 3]) -> i32 {
    let mut t = [0.0f32; ORIENT_TERMS];
    let mut n = 0;
    let parts = if z.iter().any(|c| c.lo != 0.0) { 2 } else { 1 };
    for (c, zc) in z.iter().enumerate() {
        // (x × y)_c = x_a y_b - x_b y_a.
        let (a, b) = ((c + 1) % 3, (c + 2) % 3);
        let (xa, xb, ya, yb) = ([x[a].hi, x[a].lo], [x[b].hi, x[b].lo], [y[a].hi, y[a].lo], [y[b].hi, y[b].lo]);
        for i in 0..2 {
            for j in 0..2 {
                let p = two_prod(xa[i], yb[j]);
                let q = two_prod(xb[i], ya[j]);
                for f in [p.hi, p.lo, -q.hi, -q.lo] {
                    for &zp in &[zc.hi, zc.lo][..parts] {
                        let e = two_prod(f, zp);
                        t[n] = e.hi;
                        t[n + 1] = e.lo;
                        n += 2;
                    }
                }
            }
        }
    }
    let t = &mut t[..n];
    for _ in 0..16 {
        // One VecSum pass: the running sum moves to the last slot, each step's
        // rounding error stays behind; the terms' sum is unchanged.
        let mut s = t[0];
        for i in 1..n {
            let e = two_sum(s, t[i]);
            t[i - 1] = e.lo;
            s = e.hi;
        }
        t[n - 1] = s;
        let rest = t[..n - 1].iter().fold(0.0f32, |acc, x| acc + x.abs());
        // rest is within 191 roundings (2^-16.4) of the exact sum of magnitudes.
        if s.abs() > rest * 1.000_015_3 {
            return if s > 0.0 { 1 } else { -1 };
        }
        if s.abs() + rest <= ORIENT_ZERO {
            return 0;
        }
    }
    0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rng(seed: &mut u64) -> f32 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let bits = (*seed >> 40) as u32;
        let m = bits as f32 / (1u32 << 24) as f32 - 0.5;
        let e = ((*seed >> 20) % 40) as i32 - 20;
        m * 2f32.powi(e)
    }

    #[test]
    fn orient_zero_is_2_pow_minus_100() {
        assert_eq!(ORIENT_ZERO, 2f32.powi(-100));
        assert_eq!(ORIENT_ZERO.to_bits(), 7.888_609e-31f32.to_bits());
    }

    #[test]
    fn error_free_transformations_are_exact() {
        let mut seed = 7;
        for _ in 0..100_000 {
            let (a, b) = (rng(&mut seed), rng(&mut seed));
            let s = two_sum(a, b);
            assert_eq!(s.hi as f64 + s.lo as f64, a as f64 + b as f64, "{a} + {b}");
            let p = two_prod(a, b);
            assert_eq!(p.hi as f64 + p.lo as f64, a as f64 * b as f64, "{a} * {b}");
        }
    }

    #[test]
    fn an_exact_sum_survives_cancellation() {
        // Far-away products that cancel down to a small remainder: the remainder
        // (which f32 or a float-float sum would lose) comes out to 2^-47.
        let mut seed = 3;
        for _ in 0..20_000 {
            let (o, d, s) = (rng(&mut seed) * 1e12, rng(&mut seed), rng(&mut seed) * 1e-6);
            let (p, q, r) = (two_prod(o, d), two_prod(-o, d), two_prod(s, d));
            let sum = exact_sum8([p.hi, p.lo, q.hi, q.lo, r.hi, r.lo, 0.0, 0.0]);
            let exact = s as f64 * d as f64;
            assert!((sum.to_f64() - exact).abs() <= exact.abs() * 2f64.powi(-46), "{sum:?} vs {exact}");
        }
    }

    #[test]
    fn arithmetic_is_accurate_commutative_and_antisymmetric() {
        let mut seed = 11;
        let rel = |x: Ff, exact: f64, scale: f64| ((x.to_f64() - exact).abs() / scale.max(1e-300)) < 2f64.powi(-43);
        for _ in 0..100_000 {
            let x = two_sum(rng(&mut seed), rng(&mut seed) * 1e-8);
            let y = two_sum(rng(&mut seed), rng(&mut seed) * 1e-8);
            let (xf, yf) = (x.to_f64(), y.to_f64());
            assert!(rel(x.add(y), xf + yf, xf.abs() + yf.abs()));
            assert!(rel(x.mul(y), xf * yf, (xf * yf).abs()));
            if y.hi != 0.0 {
                assert!(rel(x.div(y), xf / yf, (xf / yf).abs()));
            }
            assert_eq!(x.add(y), y.add(x));
            assert_eq!(x.mul(y), y.mul(x));
            assert_eq!((-x).add(-y), -x.add(y));
            assert_eq!(x.sub(y), -y.sub(x));
        }
    }
}
