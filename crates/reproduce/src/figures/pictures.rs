//! Rendered figures: fixed vs normalized tau on scaled meshes, noise on a
//! non-uniform triangulation, and small helpers to lay pictures out.

use anyhow::{Context, Result};
use image::{Rgb, RgbImage};
use mfm_geometry::TriMesh;
use mfm_noise::{NoiseKind, NoiseSampler};
use mfm_render::{
    ColorRange, Colormap, GridOptions, Panel, RenderOptions, View, Wireframe, draw_text,
    render_grid, render_mesh, text_height, text_width,
};
use serde::Serialize;

const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const INK: Rgb<u8> = Rgb([25, 25, 25]);

/// `images` side by side (`horizontal`) or one above the other, separated by
/// `gap` pixels, on white, each centred across the other axis.
pub fn stack(images: &[RgbImage], horizontal: bool, gap: u32) -> RgbImage {
    let along = |i: &RgbImage| if horizontal { i.width() } else { i.height() };
    let across = |i: &RgbImage| if horizontal { i.height() } else { i.width() };
    let total =
        images.iter().map(along).sum::<u32>() + gap * (images.len().saturating_sub(1)) as u32;
    let thick = images.iter().map(across).max().unwrap_or(1);
    let (w, h) = if horizontal {
        (total.max(1), thick)
    } else {
        (thick, total.max(1))
    };
    let mut out = RgbImage::from_pixel(w, h, WHITE);
    let mut pos = 0i64;
    for img in images {
        let off = i64::from((thick - across(img)) / 2);
        let (x, y) = if horizontal { (pos, off) } else { (off, pos) };
        image::imageops::overlay(&mut out, img, x, y);
        pos += i64::from(along(img) + gap);
    }
    out
}

/// `img` under a band holding `title` (centred, text scale `scale`; `\n`
/// separates lines).
pub fn titled(img: &RgbImage, title: &str, scale: u32) -> RgbImage {
    let pad = 4 * scale;
    let band = text_height(title, scale) + 2 * pad;
    let width = img.width().max(text_width(title, scale) + 2 * pad);
    let mut out = RgbImage::from_pixel(width, img.height() + band, WHITE);
    let x = (i64::from(width) - i64::from(text_width(title, scale))) / 2;
    draw_text(&mut out, x, i64::from(pad), title, scale, INK);
    let x = i64::from((width - img.width()) / 2);
    image::imageops::overlay(&mut out, img, x, i64::from(band));
    out
}

/// `img` over a caption band holding `text` (centred; `\n` separates
/// lines) at the largest text scale up to `max_scale` at which it fits the
/// width.
pub fn captioned(img: &RgbImage, text: &str, max_scale: u32) -> RgbImage {
    let mut scale = max_scale.max(1);
    while scale > 1 && text_width(text, scale) + 2 * scale > img.width() {
        scale -= 1;
    }
    let pad = 3 * scale;
    let band = text_height(text, scale) + 2 * pad;
    let mut out = RgbImage::from_pixel(img.width(), img.height() + band, WHITE);
    image::imageops::overlay(&mut out, img, 0, 0);
    for (k, line) in text.lines().enumerate() {
        let x = (i64::from(img.width()) - i64::from(text_width(line, scale))) / 2;
        let y = i64::from(img.height() + pad + k as u32 * 10 * scale);
        draw_text(&mut out, x.max(0), y, line, scale, INK);
    }
    out
}

/// Panel options for signed noise: coolwarm, symmetric range.
fn noise_options(px: u32, view: View) -> RenderOptions {
    RenderOptions {
        colormap: Colormap::CoolWarm,
        range: ColorRange::Symmetric,
        view,
        ..RenderOptions::with_size(px, px)
    }
}

/// `x` with two significant digits in scientific notation.
pub fn sci(x: f64) -> String {
    format!("{x:.1e}")
}

/// One sample of one kind on one scaled copy of the surface.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleRow {
    /// Noise kind (`matern` with a fixed tau, or `matern-normalized`).
    pub kind: String,
    /// Global scale factor of the mesh.
    pub scale: f64,
    /// Screening weight used (`c Gamma` for the normalized kind).
    pub tau: f64,
    /// `Gamma = ||M^-1 L||_F` of the scaled mesh.
    pub gamma: f64,
    /// `tau / Gamma` (constant for the normalized kind: its `c`).
    pub tau_over_gamma: f64,
    /// Standard deviation over the vertices of the sample.
    pub std: f64,
    /// `max_v |f_v - f_v(scale 1)|`.
    pub max_abs_difference: f64,
    /// `max_abs_difference / max_v |f_v(scale 1)|`.
    pub relative_difference: f64,
}

fn std_dev(f: &[f64]) -> f64 {
    let n = f.len() as f64;
    let m = f.iter().sum::<f64>() / n;
    (f.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// Samples fixed-tau Matérn (`tau`) and normalized Matérn (`c = tau /
/// Gamma` of the unscaled surface, so that the two coincide there up to the
/// factor `sqrt(Gamma)`) with the same `seed` on `surface` scaled by each of
/// `scales`. Returns the figure (row 1 fixed, row 2 normalized; each panel
/// on its own symmetric colour range), the numbers and `c`.
pub fn fixed_vs_normalized(
    surface: &TriMesh,
    scales: &[f64],
    tau: f64,
    seed: u64,
    px: u32,
) -> Result<(RgbImage, Vec<ScaleRow>, f64)> {
    let gamma1 = NoiseSampler::new(surface, NoiseKind::Naive)?.gamma();
    let c = tau / gamma1;
    let meshes: Vec<TriMesh> = scales
        .iter()
        .map(|&s| surface.transformed(s, [0.0; 3]))
        .collect();
    let mut rows = Vec::new();
    let mut signals: Vec<(String, usize, Vec<f64>)> = Vec::new();
    for kind in [NoiseKind::Matern { tau }, NoiseKind::MaternNormalized { c }] {
        let reference = NoiseSampler::new(surface, kind)?
            .sample(1, 1, seed)?
            .into_data();
        let peak = reference.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (i, (&s, mesh)) in scales.iter().zip(&meshes).enumerate() {
            let sampler = NoiseSampler::new(mesh, kind)
                .with_context(|| format!("{kind} sampler at scale {s}"))?;
            let f = sampler.sample(1, 1, seed)?.into_data();
            let diff = f
                .iter()
                .zip(&reference)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            let used_tau = sampler.tau().unwrap_or(f64::NAN);
            let row = ScaleRow {
                kind: kind.name().to_owned(),
                scale: s,
                tau: used_tau,
                gamma: sampler.gamma(),
                tau_over_gamma: used_tau / sampler.gamma(),
                std: std_dev(&f),
                max_abs_difference: diff,
                relative_difference: diff / peak,
            };
            let caption = match kind {
                NoiseKind::Matern { .. } => format!(
                    "fixed tau = {tau}\nscale {s}, std {}\ndiff to scale 1: {}",
                    sci(row.std),
                    sci(row.relative_difference)
                ),
                _ => format!(
                    "normalized c = {}\nscale {s}, std {}\ndiff to scale 1: {}",
                    sci(c),
                    sci(row.std),
                    sci(row.relative_difference)
                ),
            };
            rows.push(row);
            signals.push((caption, i, f));
        }
    }
    let panels: Vec<Panel<'_>> = signals
        .iter()
        .map(|(caption, i, f)| Panel::new(&meshes[*i], Some(f.as_slice()), caption.clone()))
        .collect();
    let opts = GridOptions {
        panel: noise_options(px, View::default()),
        title: Some("Same seed on scaled copies: fixed tau (top), normalized (bottom)".into()),
        shared_range: false,
        shared_camera: false,
    };
    let img = render_grid(&panels, scales.len(), &opts)?;
    Ok((img, rows, c))
}

/// Numbers behind the non-uniform triangulation figure.
#[derive(Debug, Clone, Serialize)]
pub struct NonUniformPanel {
    /// Which surface.
    pub surface: String,
    /// Vertex count of the non-uniform mesh.
    pub vertices: usize,
    /// Ratio of the median vertex mass of the coarse part to that of the
    /// refined part (how much denser the refined part is).
    pub density_ratio: f64,
    /// Per kind: std of the sample over the coarse and over the refined part.
    pub std_by_part: Vec<(String, f64, f64)>,
}

/// One row of the non-uniform figure: the triangulation (wireframe), naive
/// noise and Matérn noise on `mesh`, whose part `refined(p)` was refined.
pub fn nonuniform_row(
    name: &str,
    mesh: &TriMesh,
    refined: impl Fn([f64; 3]) -> bool,
    tau: f64,
    seed: u64,
    px: u32,
    view: View,
) -> Result<(RgbImage, NonUniformPanel)> {
    let s = RenderOptions {
        view,
        ..RenderOptions::with_size(px, px)
    }
    .resolved_text_scale();
    let wire = render_mesh(
        mesh,
        None,
        &RenderOptions {
            view,
            wireframe: Some(Wireframe {
                width: 0.6,
                ..Wireframe::default()
            }),
            ..RenderOptions::with_size(px, px)
        },
    )?;
    let wire = captioned(
        &wire,
        &format!("{name}: triangulation\n{} vertices", mesh.num_vertices()),
        s,
    );
    let mass = mfm_geometry::operators::lumped_mass(mesh);
    let in_part: Vec<bool> = mesh.positions().iter().map(|&p| refined(p)).collect();
    let median = |want: bool| {
        let mut m: Vec<f64> = mass
            .iter()
            .zip(&in_part)
            .filter(|(_, r)| **r == want)
            .map(|(m, _)| *m)
            .collect();
        m.sort_by(f64::total_cmp);
        m.get(m.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let density_ratio = median(false) / median(true);
    let mut std_by_part = Vec::new();
    let mut pictures = vec![wire];
    for kind in [NoiseKind::Naive, NoiseKind::Matern { tau }] {
        let f = NoiseSampler::new(mesh, kind)?
            .sample(1, 1, seed)?
            .into_data();
        let part = |want: bool| {
            let v: Vec<f64> = f
                .iter()
                .zip(&in_part)
                .filter(|(_, r)| **r == want)
                .map(|(x, _)| *x)
                .collect();
            std_dev(&v)
        };
        std_by_part.push((kind.to_string(), part(false), part(true)));
        let img = render_mesh(mesh, Some(&f), &noise_options(px, view))?;
        let label = match kind {
            NoiseKind::Naive => "naive noise\niid N(0,1) per vertex".to_owned(),
            _ => format!("matern noise, tau = {tau}\n(L + tau M) f = M^1/2 n"),
        };
        pictures.push(captioned(&img, &label, s));
    }
    Ok((
        stack(&pictures, true, 8),
        NonUniformPanel {
            surface: name.to_owned(),
            vertices: mesh.num_vertices(),
            density_ratio,
            std_by_part,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stacking_adds_sizes_and_gaps() {
        let a = RgbImage::from_pixel(10, 20, Rgb([0, 0, 0]));
        let b = RgbImage::from_pixel(30, 5, Rgb([0, 0, 0]));
        let h = stack(&[a.clone(), b.clone()], true, 4);
        assert_eq!(h.dimensions(), (44, 20));
        let v = stack(&[a, b], false, 2);
        assert_eq!(v.dimensions(), (30, 27));
        // b is centred across: its first column starts at (30 - 10) / 2 = 10 for a
        assert_eq!(v.get_pixel(0, 0).0, [255, 255, 255]);
        assert_eq!(v.get_pixel(10, 0).0, [0, 0, 0]);
    }

    #[test]
    fn titles_go_above() {
        let a = RgbImage::from_pixel(200, 20, Rgb([0, 0, 0]));
        let t = titled(&a, "x", 2);
        assert_eq!(t.width(), 200);
        assert!(t.height() > 20);
        assert_eq!(t.get_pixel(0, t.height() - 1).0, [0, 0, 0]);
    }
}
