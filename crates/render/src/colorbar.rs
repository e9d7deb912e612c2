//! Vertical colorbars with min / mid / max tick labels.
//!
//! Layout (at text scale `s`, for a strip of height `H`): a bar `10s + 4`
//! pixels wide with a thin dark frame, running from `max(H/10, 4s + 2)`
//! below the top to the same distance above the bottom, largest value at the
//! top; ticks and labels at the top, middle and bottom of the bar, labels
//! formatted by [`format_ticks`].

use image::{Rgb, RgbImage};

use super::colormap::Colormap;
use super::text::{GLYPH, draw_text, format_ticks, text_width};
use super::{RenderError, RenderOptions};

/// Geometry of a colorbar strip.
struct Layout {
    scale: u32,
    pad: u32,
    bar_width: u32,
    tick: u32,
    gap: u32,
    margin: u32,
    labels: Vec<String>,
    width: u32,
}

fn layout(lo: f64, hi: f64, height: u32, scale: u32) -> Layout {
    let s = scale.max(1);
    let labels = format_ticks(&[hi, 0.5 * (lo + hi), lo]);
    let label_width = labels.iter().map(|l| text_width(l, s)).max().unwrap_or(0);
    // the gap keeps a tick from reading as a minus sign in front of its label
    let (pad, bar_width, tick, gap) = (4 * s, 10 * s + 4, 3 * s, 3 * s + 2);
    let margin = (height / 10).max(GLYPH / 2 * s + 2);
    Layout {
        scale: s,
        pad,
        bar_width,
        tick,
        gap,
        margin,
        width: pad + bar_width + tick + gap + label_width + pad,
        labels,
    }
}

/// Width in pixels of a colorbar strip for the range `lo..hi`.
pub(crate) fn colorbar_width(lo: f64, hi: f64, height: u32, scale: u32) -> u32 {
    layout(lo, hi, height, scale).width
}

/// Draws a colorbar strip with its top-left corner at `(x0, y0)` and the
/// given height (the strip's width is [`colorbar_width`]); clipped to `img`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn draw_colorbar(
    img: &mut RgbImage,
    x0: i64,
    y0: i64,
    height: u32,
    (lo, hi): (f64, f64),
    colormap: Colormap,
    scale: u32,
    text_color: Rgb<u8>,
) {
    let l = layout(lo, hi, height, scale);
    let bar_height = height.saturating_sub(2 * l.margin).max(1);
    let bx = x0 + i64::from(l.pad);
    let by = y0 + i64::from(l.margin);
    let (bw, bh) = (i64::from(l.bar_width), i64::from(bar_height));
    let put = |img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>| {
        if x >= 0 && y >= 0 && x < i64::from(img.width()) && y < i64::from(img.height()) {
            img.put_pixel(x as u32, y as u32, c);
        }
    };
    for r in 0..bh {
        let t = 1.0 - (r as f64 + 0.5) / bh as f64;
        let c = colormap.rgb(t);
        for x in 0..bw {
            put(img, bx + x, by + r, c);
        }
    }
    // frame just outside the bar
    for x in -1..=bw {
        put(img, bx + x, by - 1, text_color);
        put(img, bx + x, by + bh, text_color);
    }
    for y in -1..=bh {
        put(img, bx - 1, by + y, text_color);
        put(img, bx + bw, by + y, text_color);
    }
    // ticks and labels at max (top), mid, min (bottom)
    let half_glyph = i64::from(GLYPH / 2 * l.scale);
    let thickness = i64::from(l.scale.div_ceil(2));
    for (label, ty) in l.labels.iter().zip([by, by + bh / 2, by + bh - 1]) {
        for x in 0..i64::from(l.tick) {
            for d in 0..thickness {
                put(img, bx + bw + x, ty + d - thickness / 2, text_color);
            }
        }
        let tx = bx + bw + i64::from(l.tick + l.gap);
        draw_text(img, tx, ty - half_glyph, label, l.scale, text_color);
    }
}

/// Renders a standalone colorbar of the given height for the values
/// `lo..hi` in `opts.colormap`, on `opts.background`, labelled in
/// `opts.text_color` at the text scale [`render_mesh`](super::render_mesh)
/// would use for `opts` (the strip's width follows from its labels).
///
/// # Errors
/// [`RenderError::InvalidRange`] unless `lo < hi` are finite;
/// [`RenderError::InvalidOption`] for a height of 0 or above
/// [`MAX_IMAGE_SIDE`](super::MAX_IMAGE_SIDE).
///
/// # Example
/// ```
/// use mfm_render::{render_colorbar, RenderOptions};
/// let bar = render_colorbar(200, -1.0, 1.0, &RenderOptions::default()).unwrap();
/// assert_eq!(bar.height(), 200);
/// ```
pub fn render_colorbar(
    height: u32,
    lo: f64,
    hi: f64,
    opts: &RenderOptions,
) -> Result<RgbImage, RenderError> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(RenderError::InvalidRange { lo, hi });
    }
    super::check_side("height", height)?;
    let scale = opts.resolved_text_scale();
    let width = colorbar_width(lo, hi, height, scale);
    let mut img = RgbImage::from_pixel(width, height, opts.background);
    draw_colorbar(
        &mut img,
        0,
        0,
        height,
        (lo, hi),
        opts.colormap,
        scale,
        opts.text_color,
    );
    Ok(img)
}
