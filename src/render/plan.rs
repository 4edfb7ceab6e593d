//! What a render needs ([`RenderPlan`]), decided from the scene and the settings
//! before anything is uploaded or compiled.

use glam::Vec3;

use super::abi::{in_order, Emitter};
use super::consts::{
    EMITTER_CORNER_SHIFT, EMITTER_PARALLELOGRAM, EMITTER_PRIM_MASK, MAT_DIFFUSE, MAT_EMISSIVE, MAT_GLOSSY, MAT_MIRROR,
    SHADE_SPECS, SHADE_SPEC_AO, SHADE_SPEC_AREA_LIGHTS, SHADE_SPEC_BOUNCES, SHADE_SPEC_CONTINUE, SHADE_SPEC_GLOSSY,
    SHADE_SPEC_HEADLIGHT, SHADE_SPEC_HEADLIGHT_SHADOWS, SHADE_SPEC_MIRRORS, SHADE_SPEC_POINT_LIGHTS,
};
use super::settings::{Primary, RenderSettings};
use crate::error::Result;
use crate::scene::Scene;

/// When triangles `t` and `u` share an edge and together form a parallelogram
/// (u is t mirrored through the shared edge's midpoint, to a relative 1e-6 of
/// their size): the index in `t` of its vertex off the shared edge.
fn parallelogram_corner(t: &[Vec3; 3], u: &[Vec3; 3]) -> Option<u32> {
    let shared: Vec<usize> = (0..3).filter(|&i| u.contains(&t[i])).collect();
    let [i, j] = shared[..] else { return None };
    let corner = 3 - i - j;
    let other = u.iter().find(|v| **v != t[i] && **v != t[j])?;
    let [c, s1, s2, d] = [t[corner], t[i], t[j], *other].map(|v| v.as_dvec3());
    let size = (s1 - c).length() + (s2 - c).length();
    ((c + d - s1 - s2).length() <= 1e-6 * size).then_some(corner as u32)
}

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

pub(super) fn material_flags(m: &crate::scene::Material) -> u32 {
    let mut flags = 0;
    if m.kd.max_element() > 0.0 {
        flags |= MAT_DIFFUSE;
    }
    if m.illum == 2 && m.ks.max_element() > 0.0 {
        flags |= MAT_GLOSSY;
    }
    if m.illum == 3 && m.ks.max_element() > 0.0 {
        flags |= MAT_MIRROR;
    }
    if m.ke.max_element() > 0.0 {
        flags |= MAT_EMISSIVE;
    }
    flags
}

/// What a render needs, decided from the scene and the settings before anything
/// is uploaded or compiled. Each `bool` is a specialization constant of the shade
/// pass or selects a pass or buffer.
#[derive(Clone, Debug)]
pub struct RenderPlan {
    /// Eye light: no lights, emitters, ambient occlusion or background.
    pub headlight: bool,
    /// The headlight's visibility traced as shadow rays (only without skipping:
    /// the camera ray itself proves the eye sees the point).
    pub headlight_shadows: bool,
    /// Point-light shadow rays.
    pub point_lights: bool,
    /// Next-event estimation toward emissive triangles.
    pub area_lights: bool,
    /// Mirror reflections (illum 3).
    pub mirrors: bool,
    /// Phong highlights (illum 2).
    pub glossy: bool,
    /// Ambient occlusion.
    pub ao: bool,
    /// Diffuse bounces.
    pub bounces: bool,
    /// Paths continue past their first hit (mirrors or bounces): a second queue.
    pub continue_paths: bool,
    /// Waves of shading per sample (the camera rays' and those of the paths
    /// they continue into): `max_depth` when paths continue, `bounces + 1` at
    /// most without mirrors (every continuation is then a diffuse bounce, so
    /// no path goes deeper), else 1.
    pub waves: u32,
    /// Shadow rays exist: the any-hit pipeline, the shadow queue, the resolve pass.
    pub shadow_pass: bool,
    /// Camera rays jittered inside the pixel (more than one sample per pixel).
    pub jitter: bool,
    /// First hits rasterized ([`Primary::Raster`]).
    pub raster: bool,
    /// Shadow rays one path vertex may cast at most.
    pub shadow_per_vertex: u32,
    /// Background radiance.
    pub background: Vec3,
    /// Ambient radiance for ambient occlusion.
    pub ambient: f32,
    /// Ambient-occlusion ray length.
    pub ao_radius: f32,
    pub(super) emitters: Vec<Emitter>,
    pub(super) emitter_weight: f32,
    explain: Vec<String>,
}

impl RenderPlan {
    /// Inspects `scene` and `settings`.
    pub fn new(scene: &Scene, settings: &RenderSettings) -> Result<RenderPlan> {
        settings.validate()?;
        let flags: Vec<u32> = scene.materials.iter().map(material_flags).collect();
        let count_with = |flag: u32| scene.material_ids.iter().filter(|&&m| flags[m as usize] & flag != 0).count();
        let (mirror_tris, glossy_tris) = (count_with(MAT_MIRROR), count_with(MAT_GLOSSY));

        // Emissive triangles, picked in proportion to area × luminance of Ke. Two
        // consecutive ones of one material that form a parallelogram (a quad lamp)
        // are one emitter, sampled by an affine map of the unit square: a
        // stratified point set stays stratified on it (two triangles each sampled
        // through the square-to-triangle warp lose part of that).
        let mut emitters: Vec<(u32, f64, f64)> = Vec::new();
        let mut total = 0.0f64;
        let mut previous: Option<usize> = None;
        for (prim, tri) in scene.triangles.iter().enumerate() {
            let m = scene.material(prim as u32);
            if flags[scene.material_ids[prim] as usize] & MAT_EMISSIVE == 0 {
                previous = None;
                continue;
            }
            let [a, b, c] = tri.map(|v| v.as_dvec3());
            let area = 0.5 * (b - a).cross(c - a).length();
            let weight = area * f64::from(luminance(m.ke)).max(1e-6);
            if !(area > 0.0 && weight.is_finite()) || prim > EMITTER_PRIM_MASK as usize {
                previous = None;
                continue;
            }
            let pair = previous
                .filter(|&q| scene.material_ids[q] == scene.material_ids[prim])
                .and_then(|q| parallelogram_corner(&scene.triangles[q], tri));
            match (pair, emitters.last_mut()) {
                (Some(corner), Some(last)) => {
                    last.0 |= EMITTER_PARALLELOGRAM | (corner << EMITTER_CORNER_SHIFT);
                    last.1 += area;
                    last.2 += weight;
                    previous = None;
                }
                _ => {
                    emitters.push((prim as u32, area, weight));
                    previous = Some(prim);
                }
            }
            total += weight;
        }
        let mut cumulative = 0.0;
        let emitters: Vec<Emitter> = emitters
            .iter()
            .map(|&(prim, area, weight)| {
                cumulative += weight;
                Emitter { prim, cdf: (cumulative / total) as f32, pick: (weight / total) as f32, area: area as f32 }
            })
            .collect();
        let emitter_tris = emitters.len();
        let parallelograms = emitters.iter().filter(|e| e.prim & EMITTER_PARALLELOGRAM != 0).count();

        let lights = !settings.lights.is_empty();
        let ao = settings.ao_samples > 0;
        let headlight = !lights && emitter_tris == 0 && !ao && settings.background.is_none();
        let skip = settings.skip_unneeded;
        let mirrors = mirror_tris > 0;
        let bounces = settings.bounces > 0 && !headlight;
        let continue_paths = settings.max_depth > 1 && (mirrors || bounces);
        let waves = match (continue_paths || !skip, mirrors || !skip) {
            (false, _) => 1,
            (true, true) => settings.max_depth,
            (true, false) => settings.max_depth.min(settings.bounces + 1),
        };
        let headlight_shadows = headlight && !skip;
        let shadow_per_vertex = settings.lights.len() as u32
            + u32::from(emitter_tris > 0)
            + settings.ao_samples
            + u32::from(headlight_shadows);
        let shadow_pass = shadow_per_vertex > 0;
        let diagonal = scene.bounds.extent().length();
        let ambient = settings.ambient.unwrap_or(if lights || emitter_tris > 0 { 0.1 } else { 1.0 });
        let ao_radius = settings.ao_radius.unwrap_or(0.1 * diagonal).max(f32::MIN_POSITIVE);

        let on_off = |b: bool| if b { "on" } else { "skipped" };
        let mut explain = Vec::new();
        explain.push(format!(
            "point lights: {} (--light) -> point-light shadow rays {}",
            settings.lights.len(),
            on_off(lights)
        ));
        explain.push(match emitter_tris {
            0 => "emitters: no triangle has a Ke -> area-light sampling and the emitter buffer skipped".into(),
            n if parallelograms > 0 => format!(
                "emitters: {} triangles with Ke ({parallelograms} quads sampled as parallelograms) -> next-event \
                 estimation toward them on",
                n + parallelograms
            ),
            n => format!("emitters: {n} triangles with Ke -> next-event estimation toward them on"),
        });
        explain.push(match mirror_tris {
            0 => "mirrors: no illum-3 material with Ks -> reflection code skipped".into(),
            n => format!("mirrors: {n} triangles of illum-3 materials -> reflection rays on"),
        });
        explain.push(match glossy_tris {
            0 => "highlights: no illum-2 material with Ks -> Phong lobe skipped".into(),
            n => format!("highlights: {n} triangles of illum-2 materials -> Phong lobe on"),
        });
        explain.push(if ao {
            format!("ambient occlusion: {} rays of length {ao_radius} at the first diffuse hit", settings.ao_samples)
        } else {
            "ambient occlusion: off (--ao 0) -> skipped".into()
        });
        explain.push(if bounces {
            format!("diffuse bounces: up to {} (cosine-weighted)", settings.bounces)
        } else if settings.bounces > 0 {
            "diffuse bounces: requested, but with a headlight there is no light to bounce -> skipped".into()
        } else {
            "diffuse bounces: off (--bounces 0) -> skipped".into()
        });
        explain.push(if continue_paths {
            format!(
                "paths continue past the first hit (up to {waves} segments{}): second ray queue on, {waves} waves per \
                 sample",
                if mirrors || !skip { "" } else { ", diffuse bounces only: no mirrors" }
            )
        } else {
            "paths end at their first hit (no mirrors, no bounces): second ray queue and its passes skipped".into()
        });
        if headlight {
            explain.push(if skip {
                "headlight: no lights, emitters, AO or background -> eye light; its shadow rays skipped, since the \
                 camera ray proves the eye sees the point"
                    .into()
            } else {
                "headlight: no lights, emitters, AO or background -> eye light, its shadow rays traced (--no-skip)"
                    .into()
            });
        }
        explain.push(if shadow_pass {
            format!("shadow rays: up to {shadow_per_vertex} per hit -> any-hit pipeline, shadow queue, resolve pass on")
        } else {
            "shadow rays: none -> the any-hit pipeline is not compiled, no shadow queue, no resolve pass".into()
        });
        explain.push(if settings.spp > 1 && settings.jitter {
            format!(
                "samples: {} per pixel, jittered by an Owen-scrambled Sobol sequence (seed {})",
                settings.spp, settings.seed
            )
        } else if settings.spp > 1 {
            format!(
                "samples: {} per pixel, all through the pixel centres (--no-jitter: no anti-aliasing) -> jitter \
                 skipped",
                settings.spp
            )
        } else {
            "samples: 1 per pixel through the pixel centres -> jitter skipped".into()
        });
        explain.push(match settings.primary {
            Primary::Trace => "first hits: traced (closest hit of the camera rays); no graphics pipeline".into(),
            Primary::Raster => "first hits: rasterized into a visibility buffer, each pixel's ray tested against \
                                its triangle alone; the camera rays' trace skipped"
                .into(),
        });
        explain.push("textures: not supported (map_Kd and other maps are not read) -> none uploaded".into());
        explain.push("normals: geometric (OBJ vn are not read) -> no normal buffer".into());
        if !skip {
            explain.push("--no-skip: every shading feature compiled in, every buffer and pipeline made anyway".into());
        }

        Ok(RenderPlan {
            headlight,
            headlight_shadows,
            point_lights: lights || !skip,
            area_lights: emitter_tris > 0 || !skip,
            mirrors: mirrors || !skip,
            glossy: glossy_tris > 0 || !skip,
            ao: ao || !skip,
            bounces: bounces || !skip,
            continue_paths: continue_paths || !skip,
            waves,
            shadow_pass: shadow_pass || !skip,
            jitter: settings.jitter && settings.spp > 1,
            raster: settings.primary == Primary::Raster,
            shadow_per_vertex: shadow_per_vertex.max(1),
            background: settings.background.unwrap_or(if headlight { Vec3::splat(0.05) } else { Vec3::ZERO }),
            ambient,
            ao_radius,
            emitters,
            emitter_weight: total as f32,
            explain,
        })
    }

    /// What the render does and skips, one line per feature.
    pub fn explain(&self) -> &[String] {
        &self.explain
    }

    /// The shade pass's specialization constants (`SHADE_SPEC_*` of `render_shade.comp`), in id order.
    pub(super) fn shade_constants(&self) -> [u32; SHADE_SPECS as usize] {
        in_order([
            (SHADE_SPEC_HEADLIGHT, self.headlight),
            (SHADE_SPEC_POINT_LIGHTS, self.point_lights),
            (SHADE_SPEC_AREA_LIGHTS, self.area_lights),
            (SHADE_SPEC_MIRRORS, self.mirrors),
            (SHADE_SPEC_GLOSSY, self.glossy),
            (SHADE_SPEC_AO, self.ao),
            (SHADE_SPEC_BOUNCES, self.bounces),
            (SHADE_SPEC_CONTINUE, self.continue_paths),
            (SHADE_SPEC_HEADLIGHT_SHADOWS, self.headlight_shadows),
        ])
        .map(u32::from)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quads_two_triangles_form_a_parallelogram_and_other_pairs_do_not() {
        let [a, b, c, d] = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        // A fan-triangulated quad: (a, b, c) and (a, c, d); b is off the shared edge a-c.
        assert_eq!(parallelogram_corner(&[a, b, c], &[a, c, d]), Some(1));
        assert_eq!(parallelogram_corner(&[c, a, b], &[d, a, c]), Some(2));
        // A sheared parallelogram still is one.
        let s = Vec3::new(0.5, 0.0, 0.0);
        assert_eq!(parallelogram_corner(&[a, b, c + s], &[a, c + s, d + s]), Some(1));
        // A kite (shared edge, not a parallelogram), a shared vertex only, no shared vertex.
        assert_eq!(parallelogram_corner(&[a, b, c], &[a, c, Vec3::new(0.2, 1.5, 0.0)]), None);
        assert_eq!(parallelogram_corner(&[a, b, c], &[a, Vec3::new(-1.0, 0.0, 0.0), Vec3::new(0.0, -1.0, 0.0)]), None);
        assert_eq!(parallelogram_corner(&[a, b, c], &[d, d + Vec3::X, d + Vec3::Z]), None);
    }
}
