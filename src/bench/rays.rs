//! The ray kinds of the benchmark matrix. Camera and random rays come from the
//! scene; shadow, reflection and diffuse-bounce rays are made on the CPU from
//! the camera rays' first hits, as a path tracer's second bounce would make them.

use glam::Vec3;

use crate::geom::{Aabb, Hit, Ray};
use crate::raygen::SplitMix64;

/// Offset of a secondary ray's origin from its hit point, along the geometric
/// normal on the side the incoming ray came from, relative to the size of the
/// coordinates: `SECONDARY_OFFSET · max(‖p‖∞, 0.01 · largest extent of the
/// scene box)`. 1e-4 is about 800 f32 ulps of the point, far above the error of
/// the hit point computed from the barycentrics, so no ray starts behind its own
/// surface; the floor keeps points near the origin from getting a zero offset.
pub const SECONDARY_OFFSET: f32 = 1e-4;

/// A batch of rays in the benchmark matrix.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RayKind {
    /// One ray per pixel through the pixel centre, in Morton order.
    Camera,
    /// From each camera hit toward a point light above the scene box; any-hit
    /// over the segment `[0, 1]` of `light - origin`. Points facing away from the
    /// light make no ray.
    Shadow,
    /// From each camera hit in the mirror direction about the geometric normal.
    Reflection,
    /// From each camera hit in a cosine-weighted direction around the geometric
    /// normal (seeded [`SplitMix64`]).
    Diffuse,
    /// Uniform origins in the scene box, uniform directions.
    Random,
    /// The hard rays of `kdtrace verify`: every [`crate::stress::Category`],
    /// [`HARD_PER_CATEGORY`] rays each (where the scene has such rays), so that
    /// the error axis shows what the robustness measures buy.
    Hard,
}

/// Rays per stress category in [`RayKind::Hard`].
pub const HARD_PER_CATEGORY: usize = 64;

impl RayKind {
    /// Every kind, in table order.
    pub const ALL: [RayKind; 6] =
        [RayKind::Camera, RayKind::Shadow, RayKind::Reflection, RayKind::Diffuse, RayKind::Random, RayKind::Hard];

    /// The name used on the command line and in tables.
    pub fn name(self) -> &'static str {
        match self {
            RayKind::Camera => "camera",
            RayKind::Shadow => "shadow",
            RayKind::Reflection => "reflection",
            RayKind::Diffuse => "diffuse",
            RayKind::Random => "random",
            RayKind::Hard => "hard",
        }
    }

    /// True for the kinds traced any-hit (shadow rays).
    pub fn any_hit(self) -> bool {
        self == RayKind::Shadow
    }

    /// True for the kinds made from the camera rays' first hits.
    pub fn is_secondary(self) -> bool {
        matches!(self, RayKind::Shadow | RayKind::Reflection | RayKind::Diffuse)
    }
}

impl std::fmt::Display for RayKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RayKind {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        RayKind::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let names: Vec<&str> = RayKind::ALL.iter().map(|k| k.name()).collect();
            crate::Error::InvalidInput(format!("unknown ray kind '{s}' ({})", names.join(", ")))
        })
    }
}

/// The point light of the shadow rays: above the middle of the box (+y), half
/// the box's height over its top.
pub fn light_position(bounds: &Aabb) -> Vec3 {
    let c = bounds.center();
    Vec3::new(c.x, bounds.max.y + 0.5 * bounds.extent().y.max(bounds.extent().max_element() * 0.1), c.z)
}

/// An orthonormal basis around the unit vector `n` (Duff et al., *Building an
/// Orthonormal Basis, Revisited*, JCGT 2017): two unit tangents.
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3::new(b, sign + n.y * n.y * a, -n.y))
}

/// Secondary rays of `kind` from the first hits `hits` of the camera rays
/// `primary` (misses and degenerate triangles make no ray). Camera and random
/// kinds give no rays here.
pub fn secondary_rays(
    kind: RayKind,
    triangles: &[[Vec3; 3]],
    bounds: &Aabb,
    primary: &[Ray],
    hits: &[Hit],
    seed: u64,
) -> Vec<Ray> {
    let light = light_position(bounds);
    let floor = 0.01 * bounds.extent().max_element();
    let mut rng = SplitMix64(seed);
    let mut rays = Vec::new();
    for (ray, hit) in primary.iter().zip(hits) {
        if !hit.is_hit() || hit.prim_id as usize >= triangles.len() {
            continue;
        }
        let [a, b, c] = triangles[hit.prim_id as usize];
        let Some(mut normal) = (b - a).cross(c - a).try_normalize() else { continue };
        let dir = ray.traced_dir().normalize();
        if normal.dot(dir) > 0.0 {
            normal = -normal;
        }
        // The hit point from the barycentrics: on the triangle up to rounding.
        let point = (1.0 - hit.u - hit.v) * a + hit.u * b + hit.v * c;
        let origin = point + normal * (SECONDARY_OFFSET * point.abs().max_element().max(floor));
        match kind {
            RayKind::Shadow => {
                let to_light = light - origin;
                if to_light.dot(normal) > 0.0 {
                    rays.push(Ray::new(origin, to_light, 0.0, 1.0));
                }
            }
            RayKind::Reflection => {
                rays.push(Ray::new(origin, dir - 2.0 * dir.dot(normal) * normal, 0.0, f32::INFINITY));
            }
            RayKind::Diffuse => {
                let (s, t) = basis(normal);
                let (r1, r2) = (rng.next_f32(), rng.next_f32());
                let (radius, phi) = (r1.sqrt(), std::f32::consts::TAU * r2);
                let local = Vec3::new(radius * phi.cos(), radius * phi.sin(), (1.0 - r1).max(0.0).sqrt());
                let d = s * local.x + t * local.y + normal * local.z;
                rays.push(Ray::new(origin, d, 0.0, f32::INFINITY));
            }
            RayKind::Camera | RayKind::Random | RayKind::Hard => {}
        }
    }
    rays
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_orthonormal() {
        let mut rng = SplitMix64(3);
        for _ in 0..1000 {
            let n = rng.unit_vector();
            let (s, t) = basis(n);
            for (x, y) in [(s, t), (s, n), (t, n)] {
                assert!(x.dot(y).abs() < 1e-5);
            }
            assert!((s.length() - 1.0).abs() < 1e-5 && (t.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn secondary_rays_leave_the_surface_on_the_incoming_side() {
        // A floor at y = 0 seen from above.
        let tris = vec![[Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, -1.0), Vec3::new(0.0, 0.0, 1.0)]];
        let bounds = Aabb::new(Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 1.0, 1.0));
        let primary = [Ray::new(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.1, -1.0, 0.0), 0.0, f32::INFINITY)];
        let hits = [Hit { t: 1.0, prim_id: 0, u: 0.25, v: 0.5 }];
        for kind in [RayKind::Shadow, RayKind::Reflection, RayKind::Diffuse] {
            let rays = secondary_rays(kind, &tris, &bounds, &primary, &hits, 1);
            assert_eq!(rays.len(), 1, "{kind}");
            assert!(rays[0].origin[1] > 0.0 && rays[0].dir[1] > 0.0, "{kind}: {:?}", rays[0]);
        }
        let r = secondary_rays(RayKind::Reflection, &tris, &bounds, &primary, &hits, 1)[0];
        assert!((Vec3::from(r.dir) - Vec3::new(0.1, 1.0, 0.0).normalize()).length() < 1e-5);
        let s = secondary_rays(RayKind::Shadow, &tris, &bounds, &primary, &hits, 1)[0];
        let end = Vec3::from(s.origin) + Vec3::from(s.dir) * s.tmax;
        assert!((end - light_position(&bounds)).length() < 1e-5);
        // A miss makes no ray.
        assert!(secondary_rays(RayKind::Diffuse, &tris, &bounds, &primary, &[Hit::MISS], 1).is_empty());
    }
}
