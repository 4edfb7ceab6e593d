//! The image cells of `kdtrace bench --images`: rendered images against a
//! converged reference. Knobs that trade time for error — samples per pixel,
//! diffuse bounces, first hits traced or rasterized, the traversal — each give a
//! cell with its render time and its error: relative RMSE and SSIM (Wang et al.
//! 2004, on the tone-mapped luminance) against the reference, rendered once per
//! scene at `reference_spp` samples and `reference_bounces` bounces.
//!
//! Over the samples-per-pixel sweep of one configuration the cells are a
//! convergence curve: [`convergence`] fits its exponent (RMSE ∝ spp^-e, over
//! the whole image and off the emitters seen directly) and the wall time to
//! reach given errors.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use plotters::prelude::*;

use crate::error::{Error, Result};
use crate::render::{render, PointLight, Primary, RenderOutput, RenderSettings};
use crate::scene::{Camera, Scene};
use crate::trace::Tracer;
use crate::traversal::Traversal;

/// What the image cells sweep.
#[derive(Clone, Debug)]
pub struct ImageOptions {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel of the cells.
    pub spp: Vec<u32>,
    /// Diffuse bounces of the cells.
    pub bounces: Vec<u32>,
    /// First-hit modes of the cells.
    pub primaries: Vec<Primary>,
    /// Traversals of the cells (closest hit; shadow rays use their any-hit twin).
    pub traversals: Vec<Traversal>,
    /// Samples per pixel of the reference.
    pub reference_spp: u32,
    /// Diffuse bounces of the reference (the most a cell may take).
    pub reference_bounces: u32,
    /// Ambient-occlusion rays at the first diffuse hit (cells and reference).
    pub ao_samples: u32,
}

/// One rendered image and its error.
#[derive(Clone, Debug)]
pub struct ImageCell {
    /// Scene name.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// Diffuse bounces.
    pub bounces: u32,
    /// First hits traced or rasterized.
    pub primary: Primary,
    /// The traversal.
    pub traversal: String,
    /// Wall time of the render call (pipelines compiled already: a warm-up ran).
    pub seconds: f64,
    /// GPU time of trace + shade (+ raster) dispatches, when the device gave plausible timestamps.
    pub gpu_seconds: Option<f64>,
    /// Rays of all kinds.
    pub rays: u64,
    /// RMSE against the reference, relative to the reference's mean.
    pub rmse: f64,
    /// Mean SSIM of the tone-mapped luminance (1 = identical).
    pub ssim: f64,
    /// RMSE over the pixels that do not see an emitter directly (see
    /// [`off_emitter_mask`]), relative to the reference's mean there; `None`
    /// when the scene has no emitters.
    pub rmse_off_emitters: Option<f64>,
}

impl ImageCell {
    /// The cell's settings in one label.
    pub fn label(&self) -> String {
        let primary = if self.primary == Primary::Raster { " raster" } else { "" };
        format!("{} spp, {} b{primary}, {}", self.spp, self.bounces, self.traversal)
    }
}

/// RMSE of `a` against `reference` over all channels, relative to the reference's mean.
pub fn relative_rmse(a: &[Vec3], reference: &[Vec3]) -> f64 {
    masked_relative_rmse(a, reference, None)
}

/// [`relative_rmse`] over the pixels whose `mask` entry is true (all without a mask).
pub fn masked_relative_rmse(a: &[Vec3], reference: &[Vec3], mask: Option<&[bool]>) -> f64 {
    let keep = |i: usize| mask.map_or(true, |m| m[i]);
    let (mut n, mut sum, mut sq) = (0usize, 0.0f64, 0.0f64);
    for (_, (x, y)) in a.iter().zip(reference).enumerate().filter(|&(i, _)| keep(i)) {
        n += 1;
        sum += f64::from(y.element_sum());
        sq += f64::from((*x - *y).length_squared());
    }
    let n = n.max(1) as f64;
    (sq / (3.0 * n)).sqrt() / (sum / (3.0 * n)).max(f64::MIN_POSITIVE)
}

/// The pixels that do not see an emitter, directly or in a mirror: true where
/// neither the pixel nor its 8 neighbours has an emissive first hit (of the
/// first sample, `first_hits`, row-major) or a `reference` value of at least a
/// quarter of the dimmest emitter's radiance (luminance; a diffuse surface lit
/// by the emitters stays below that unless they fill most of its sky). Such
/// pixels converge at the rate of the light transport; the emitters' own pixels
/// and their anti-aliased edges at the rate of the pixel filter. `None` when the
/// scene has no emitter.
pub fn off_emitter_mask(
    scene: &Scene,
    first_hits: &[crate::geom::Hit],
    reference: &[Vec3],
    width: u32,
    height: u32,
) -> Option<Vec<bool>> {
    let emissive =
        |prim: u32| scene.material_ids.get(prim as usize).is_some_and(|&m| scene.materials[m as usize].is_emissive());
    let luminance = |c: Vec3| c.dot(Vec3::new(0.2126, 0.7152, 0.0722));
    let dimmest = scene.materials.iter().filter(|m| m.is_emissive()).map(|m| luminance(m.ke)).reduce(f32::min)?;
    let (w, h) = (width as usize, height as usize);
    let on: Vec<bool> = first_hits
        .iter()
        .zip(reference)
        .map(|(hit, &c)| emissive(hit.prim_id) || luminance(c) >= 0.25 * dimmest)
        .collect();
    let mut mask = vec![true; w * h];
    for y in 0..h {
        for x in 0..w {
            if on[y * w + x] {
                for ny in y.saturating_sub(1)..(y + 2).min(h) {
                    for nx in x.saturating_sub(1)..(x + 2).min(w) {
                        mask[ny * w + nx] = false;
                    }
                }
            }
        }
    }
    Some(mask)
}

/// Mean SSIM over 8×8 windows (stride 4) of the luminance after clamping to [0, 1]
/// and sRGB encoding, with the usual constants (K1 = 0.01, K2 = 0.03, range 1).
pub fn ssim(a: &[Vec3], b: &[Vec3], width: u32, height: u32) -> f64 {
    let luma = |img: &[Vec3]| -> Vec<f64> {
        img.iter()
            .map(|c| {
                let y = f64::from(c.dot(Vec3::new(0.2126, 0.7152, 0.0722))).clamp(0.0, 1.0);
                if y <= 0.003_130_8 {
                    12.92 * y
                } else {
                    1.055 * y.powf(1.0 / 2.4) - 0.055
                }
            })
            .collect()
    };
    let (x, y) = (luma(a), luma(b));
    let (w, h) = (width as usize, height as usize);
    let win = 8.min(w).min(h).max(1);
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let mut sum = 0.0;
    let mut count = 0usize;
    let mut wy = 0;
    loop {
        let mut wx = 0;
        loop {
            let (mut mx, mut my, mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for j in wy..wy + win {
                for i in wx..wx + win {
                    let (p, q) = (x[j * w + i], y[j * w + i]);
                    mx += p;
                    my += q;
                    xx += p * p;
                    yy += q * q;
                    xy += p * q;
                }
            }
            let n = (win * win) as f64;
            let (mx, my) = (mx / n, my / n);
            let (vx, vy, cov) = (xx / n - mx * mx, yy / n - my * my, xy / n - mx * my);
            sum += ((2.0 * mx * my + c1) * (2.0 * cov + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
            count += 1;
            if wx + win >= w {
                break;
            }
            wx = (wx + 4).min(w - win);
        }
        if wy + win >= h {
            break;
        }
        wy = (wy + 4).min(h - win);
    }
    sum / count.max(1) as f64
}

/// A point light for scenes without emitters, so that their images have shadows
/// and indirect light to converge: the ray matrix's shadow-ray light above the
/// box, or, for a camera inside the box (an interior such as q3), the eye itself
/// (a light above the box would not get in).
fn scene_lights(scene: &Scene, camera: &Camera) -> Vec<PointLight> {
    if scene.materials.iter().any(|m| m.is_emissive()) {
        return Vec::new();
    }
    let b = &scene.bounds;
    let inside = camera.eye.cmpge(b.min).all() && camera.eye.cmple(b.max).all();
    let position = if inside { camera.eye } else { crate::bench::rays::light_position(b) };
    let d2 = (scene.bounds.center() - position).length_squared().max(f32::MIN_POSITIVE);
    vec![PointLight { position, intensity: Vec3::splat(std::f32::consts::PI * d2) }]
}

/// Renders the reference and every cell of `options` for one scene.
/// `progress` hears what is being rendered.
pub fn run_images(
    tracer: &mut Tracer,
    name: &str,
    scene: &Scene,
    camera: &Camera,
    options: &ImageOptions,
    mut progress: impl FnMut(&str),
) -> Result<(Vec<ImageCell>, RenderOutput)> {
    if options.spp.is_empty() || options.bounces.is_empty() || options.primaries.is_empty() {
        return Err(Error::InvalidInput("--images needs at least one spp, bounce count and primary".into()));
    }
    if let Some(b) = options.bounces.iter().find(|&&b| b > options.reference_bounces) {
        return Err(Error::InvalidInput(format!(
            "a cell with {b} bounces exceeds the reference's {} (--reference-bounces)",
            options.reference_bounces
        )));
    }
    let mut base = RenderSettings::new(options.width, options.height);
    base.lights = scene_lights(scene, camera);
    base.max_depth = 8.max(options.reference_bounces + 2);
    progress(&format!("{name}: reference, {} spp, {} bounces", options.reference_spp, options.reference_bounces));
    base.ao_samples = options.ao_samples;
    let reference_settings = RenderSettings {
        spp: options.reference_spp,
        bounces: options.reference_bounces,
        seed: 0x5eed,
        keep_first_hits: true,
        ..base.clone()
    };
    let reference = render(tracer, scene, camera, &reference_settings, |_, _| {})?;
    let mask = reference
        .first_hits
        .as_deref()
        .and_then(|hits| off_emitter_mask(scene, hits, &reference.pixels, options.width, options.height));
    if reference.pixels.iter().all(|p| p.max_element() <= 0.0) {
        return Err(Error::InvalidInput(format!("{name}: the reference image is black; no light reaches the camera")));
    }
    let mut cells = Vec::new();
    for traversal in &options.traversals {
        for &primary in &options.primaries {
            for &bounces in &options.bounces {
                for &spp in &options.spp {
                    let settings =
                        RenderSettings { spp, bounces, primary, traversal: *traversal, seed: 1, ..base.clone() };
                    let label = crate::bench::matrix::traversal_name(traversal);
                    progress(&format!("{name}: {spp} spp, {bounces} bounces, {primary:?}, {label}"));
                    // A one-sample warm-up compiles the pipelines, so the cell times the render alone.
                    render(tracer, scene, camera, &RenderSettings { spp: 1, ..settings.clone() }, |_, _| {})?;
                    let start = Instant::now();
                    let out = render(tracer, scene, camera, &settings, |_, _| {})?;
                    let seconds = start.elapsed().as_secs_f64();
                    let s = &out.stats;
                    let gpu =
                        s.trace_seconds.zip(s.shade_seconds).map(|(t, sh)| t + sh + s.raster_seconds.unwrap_or(0.0));
                    cells.push(ImageCell {
                        scene: name.to_string(),
                        spp,
                        bounces,
                        primary,
                        traversal: label,
                        seconds,
                        gpu_seconds: gpu,
                        rays: s.rays(),
                        rmse: relative_rmse(&out.pixels, &reference.pixels),
                        ssim: ssim(&out.pixels, &reference.pixels, out.width, out.height),
                        rmse_off_emitters: mask
                            .as_deref()
                            .map(|m| masked_relative_rmse(&out.pixels, &reference.pixels, Some(m))),
                    });
                }
            }
        }
    }
    Ok((cells, reference))
}

/// One configuration's convergence over its samples-per-pixel sweep.
#[derive(Clone, Debug)]
pub struct Convergence {
    /// Scene name.
    pub scene: String,
    /// The configuration: the cell label without its spp.
    pub config: String,
    /// The spp range fitted.
    pub spp: (u32, u32),
    /// e in RMSE ∝ spp^-e (least squares on the logs): 0.5 is plain Monte
    /// Carlo, up to 1 (and beyond for smooth integrands) a stratified sampler.
    pub exponent: f64,
    /// The same off the emitters seen directly, when the scene has emitters.
    pub exponent_off_emitters: Option<f64>,
    /// Per target RMSE (relative), the wall time to reach it from the fit of
    /// ln RMSE on ln wall time, and whether the target lies outside the measured
    /// errors (extrapolated).
    pub time_to: Vec<(f64, f64, bool)>,
}

/// The least-squares slope of ln y on ln x and its intercept.
fn log_fit(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let pts: Vec<(f64, f64)> =
        points.iter().filter(|(x, y)| *x > 0.0 && *y > 0.0).map(|(x, y)| (x.ln(), y.ln())).collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let slope = sxy / sxx;
    Some((slope, my - slope * mx))
}

/// The convergence of every configuration that has two spp values or more,
/// with the wall time to each of `targets` (relative RMSE, e.g. 0.02 for 2 %).
pub fn convergence(cells: &[ImageCell], targets: &[f64]) -> Vec<Convergence> {
    let config = |c: &ImageCell| {
        let primary = if c.primary == Primary::Raster { " raster" } else { "" };
        format!("{} b{primary}, {}", c.bounces, c.traversal)
    };
    let mut keys: Vec<(String, String)> = Vec::new();
    for c in cells {
        let key = (c.scene.clone(), config(c));
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let mut found = Vec::new();
    for (scene, conf) in keys {
        let series: Vec<&ImageCell> = cells.iter().filter(|c| c.scene == scene && config(c) == conf).collect();
        let spp = |f: &dyn Fn(&ImageCell) -> Option<f64>| {
            log_fit(&series.iter().filter_map(|c| Some((f64::from(c.spp), f(c)?))).collect::<Vec<_>>())
        };
        let Some((slope, _)) = spp(&|c| Some(c.rmse)) else { continue };
        let off = spp(&|c| c.rmse_off_emitters).map(|(s, _)| -s);
        let time_to = match log_fit(&series.iter().map(|c| (c.seconds, c.rmse)).collect::<Vec<_>>()) {
            Some((b, a)) if b < 0.0 => {
                let (lo, hi) =
                    series.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), c| (lo.min(c.rmse), hi.max(c.rmse)));
                targets.iter().map(|&x| (x, ((x.ln() - a) / b).exp(), x < lo || x > hi)).collect()
            }
            _ => Vec::new(),
        };
        let lo = series.iter().map(|c| c.spp).min().unwrap_or(0);
        let hi = series.iter().map(|c| c.spp).max().unwrap_or(0);
        found.push(Convergence {
            scene,
            config: conf,
            spp: (lo, hi),
            exponent: -slope,
            exponent_off_emitters: off,
            time_to,
        });
    }
    found
}

/// The convergence fits as a Markdown table.
pub fn convergence_table(found: &[Convergence]) -> String {
    let targets: Vec<f64> = found.first().map_or(Vec::new(), |c| c.time_to.iter().map(|t| t.0).collect());
    let mut s = String::from("| scene | configuration | spp | exponent | exponent off emitters |");
    let mut rule = String::from("|---|---|---|---|---|");
    for t in &targets {
        s += &format!(" time to {} % |", t * 100.0);
        rule += "---|";
    }
    s += "\n";
    s += &rule;
    s += "\n";
    for c in found {
        s += &format!(
            "| {} | {} | {}-{} | {:.3} | {} |",
            c.scene,
            c.config,
            c.spp.0,
            c.spp.1,
            c.exponent,
            c.exponent_off_emitters.map_or("-".into(), |e| format!("{e:.3}"))
        );
        for t in &targets {
            match c.time_to.iter().find(|x| x.0 == *t) {
                Some(&(_, secs, extrapolated)) => {
                    s += &format!(" {:.3} s{} |", secs, if extrapolated { " (extrapolated)" } else { "" })
                }
                None => s += " - |",
            }
        }
        s += "\n";
    }
    s
}

/// The image cells as a Markdown table.
pub fn images_table(cells: &[ImageCell]) -> String {
    let mut s = String::from(
        "| scene | settings | wall ms | GPU ms | rays | RMSE vs reference | off emitters | SSIM |\n|---|---|---|---|---|---|---|---|\n",
    );
    for c in cells {
        s += &format!(
            "| {} | {} | {:.1} | {} | {} | {:.2} % | {} | {:.4} |\n",
            c.scene,
            c.label(),
            c.seconds * 1e3,
            c.gpu_seconds.map_or("-".into(), |g| format!("{:.1}", g * 1e3)),
            c.rays,
            c.rmse * 100.0,
            c.rmse_off_emitters.map_or("-".into(), |r| format!("{:.2} %", r * 100.0)),
            c.ssim
        );
    }
    s
}

/// The image cells as CSV, one row per cell.
pub fn write_images_csv(path: &Path, cells: &[ImageCell]) -> Result<()> {
    let mut s = String::from(
        "scene,spp,bounces,primary,traversal,wall_seconds,gpu_seconds,rays,relative_rmse,ssim,relative_rmse_off_emitters\n",
    );
    for c in cells {
        s += &format!(
            "{},{},{},{},{},{:.6},{},{},{:.6},{:.6},{}\n",
            c.scene,
            c.spp,
            c.bounces,
            if c.primary == Primary::Raster { "raster" } else { "trace" },
            c.traversal,
            c.seconds,
            c.gpu_seconds.map_or(String::new(), |g| format!("{g:.6}")),
            c.rays,
            c.rmse,
            c.ssim,
            c.rmse_off_emitters.map_or(String::new(), |r| format!("{r:.6}"))
        );
    }
    std::fs::write(path, s).map_err(|source| Error::Io { path: path.to_path_buf(), source })
}

/// Render time against RMSE, one panel per scene, every point labelled with its
/// settings, the Pareto front (no other cell both faster and closer) joined.
pub fn plot_images(path: &Path, cells: &[ImageCell], title: &str) -> Result<()> {
    crate::bench::plot::ensure_font()?;
    let mut scenes: Vec<&str> = Vec::new();
    for c in cells {
        if !scenes.contains(&c.scene.as_str()) {
            scenes.push(&c.scene);
        }
    }
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (1200, 560 * scenes.len().max(1) as u32 + 40)).into_drawing_area();
        root.fill(&WHITE)?;
        let (header, body) = root.split_vertically(40);
        header.titled(title, ("sans-serif", 20))?;
        for (area, scene) in body.split_evenly((scenes.len().max(1), 1)).iter().zip(&scenes) {
            let mine: Vec<&ImageCell> = cells.iter().filter(|c| c.scene == *scene).collect();
            let time_error: Vec<(f64, f64)> = mine.iter().map(|c| (c.seconds * 1e3, c.rmse * 100.0)).collect();
            let mut chart = crate::bench::plot::time_error_chart(
                area,
                format!("{scene}: render time vs image error"),
                &time_error,
                1.6,
            )?;
            chart
                .configure_mesh()
                .x_desc("render wall time, ms (log scale)")
                .y_desc("RMSE vs converged reference, % of its mean")
                .draw()?;
            let front = crate::bench::plot::pareto_front(time_error.clone());
            chart.draw_series(LineSeries::new(front, BLACK.stroke_width(1)))?;
            // Each configuration's spp sweep as a curve: its slope on these log axes
            // is the convergence in wall time.
            let mut configs: Vec<String> = Vec::new();
            for c in &mine {
                let key = c.label().split_once(", ").map_or(String::new(), |(_, rest)| rest.to_string());
                if !configs.contains(&key) {
                    configs.push(key);
                }
            }
            for key in &configs {
                let mut curve: Vec<&&ImageCell> =
                    mine.iter().filter(|c| c.label().split_once(", ").is_some_and(|(_, r)| r == key)).collect();
                curve.sort_by_key(|c| c.spp);
                let points: Vec<(f64, f64)> = curve.iter().map(|c| (c.seconds * 1e3, c.rmse * 100.0)).collect();
                chart.draw_series(LineSeries::new(points, RGBColor(150, 150, 150).stroke_width(1)))?;
            }
            for c in &mine {
                let color = if c.primary == Primary::Raster { RGBColor(214, 39, 40) } else { RGBColor(31, 119, 180) };
                let p = (c.seconds * 1e3, c.rmse * 100.0);
                chart.draw_series(std::iter::once(Circle::new(p, 4, color.filled())))?;
                chart.draw_series(std::iter::once(Text::new(c.label(), p, ("sans-serif", 11))))?;
            }
        }
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| Error::InvalidInput(format!("{}: drawing the chart failed: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pareto_front_keeps_only_points_no_faster_point_beats() {
        let front = crate::bench::plot::pareto_front(vec![(3.0, 1.0), (1.0, 5.0), (2.0, 6.0), (2.5, 2.0), (4.0, 1.0)]);
        assert_eq!(front, vec![(1.0, 5.0), (2.5, 2.0), (3.0, 1.0)]);
    }

    #[test]
    fn ssim_is_one_for_equal_images_and_falls_with_noise() {
        let (w, h) = (24u32, 16u32);
        let a: Vec<Vec3> = (0..w * h).map(|i| Vec3::splat((i % w) as f32 / w as f32)).collect();
        assert!((ssim(&a, &a, w, h) - 1.0).abs() < 1e-12);
        assert_eq!(relative_rmse(&a, &a), 0.0);
        let mut rng = crate::raygen::SplitMix64(3);
        let noisy: Vec<Vec3> = a.iter().map(|p| *p + Vec3::splat(0.2 * (rng.next_f32() - 0.5))).collect();
        let s = ssim(&noisy, &a, w, h);
        assert!(s < 0.95 && s > 0.0, "{s}");
        assert!(relative_rmse(&noisy, &a) > 0.05);
    }
}
