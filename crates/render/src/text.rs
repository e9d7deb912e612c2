//! Bitmap text: 8x8 glyphs from the public-domain `font8x8` set, scaled by
//! an integer factor, and compact number formatting for tick labels.
//!
//! Glyphs come from the Basic Latin, Latin-1 and Greek blocks (so captions
//! such as `ν = 1.5` or `σ² = 0.1` are fine); anything else, and control
//! characters other than `\n`, is drawn as `?`. A `\n` starts a new line.
//! Text is drawn without anti-aliasing, clipped to the image.

use font8x8::{BASIC_FONTS, GREEK_FONTS, LATIN_FONTS, UnicodeFonts};
use image::{Rgb, RgbImage};

/// Glyph cell size in pixels at scale 1 (glyphs are `GLYPH x GLYPH`).
pub const GLYPH: u32 = 8;

/// Extra space between lines at scale 1, in pixels.
const LINE_GAP: u32 = 2;

/// The 8 rows of a glyph (bit `i` of a row is column `i`, left to right).
fn glyph(c: char) -> [u8; 8] {
    let lookup = |c: char| {
        if c.is_control() {
            return None;
        }
        BASIC_FONTS
            .get(c)
            .or_else(|| LATIN_FONTS.get(c))
            .or_else(|| GREEK_FONTS.get(c))
    };
    lookup(c).or_else(|| lookup('?')).unwrap_or([0; 8])
}

/// Width in pixels of the widest line of `text` at `scale` (0 is read as 1).
pub fn text_width(text: &str, scale: u32) -> u32 {
    let s = scale.max(1);
    let widest = text
        .split('\n')
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(0);
    u32::try_from(widest)
        .unwrap_or(u32::MAX)
        .saturating_mul(GLYPH * s)
}

/// Height in pixels of `text` at `scale` (0 is read as 1): `8·scale` per
/// line plus `2·scale` between lines.
pub fn text_height(text: &str, scale: u32) -> u32 {
    let s = scale.max(1);
    let lines = u32::try_from(text.split('\n').count()).unwrap_or(u32::MAX);
    lines
        .saturating_mul(GLYPH * s)
        .saturating_add(lines.saturating_sub(1).saturating_mul(LINE_GAP * s))
}

/// Draws `text` with its top-left corner at `(x, y)`, each font pixel
/// becoming a `scale x scale` block (0 is read as 1), in `color`. Parts
/// outside the image are clipped. Cost: `O(pixels drawn)`.
///
/// # Example
/// ```
/// use image::{Rgb, RgbImage};
/// use mfm_render::draw_text;
/// let mut img = RgbImage::from_pixel(40, 12, Rgb([255, 255, 255]));
/// draw_text(&mut img, 2, 2, "Hi", 1, Rgb([0, 0, 0]));
/// assert!(img.pixels().any(|p| p.0 == [0, 0, 0]));
/// ```
pub fn draw_text(img: &mut RgbImage, x: i64, y: i64, text: &str, scale: u32, color: Rgb<u8>) {
    let s = i64::from(scale.max(1));
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    let advance = i64::from(GLYPH) * s;
    let line_step = i64::from(GLYPH + LINE_GAP) * s;
    for (line_no, line) in text.split('\n').enumerate() {
        let y0 = y + line_no as i64 * line_step;
        if y0 >= h || y0 + advance <= 0 {
            continue;
        }
        for (col, c) in line.chars().enumerate() {
            let x0 = x + col as i64 * advance;
            if x0 >= w {
                break;
            }
            if x0 + advance <= 0 {
                continue;
            }
            let rows = glyph(c);
            for (r, bits) in rows.iter().enumerate() {
                for b in 0..8 {
                    if bits >> b & 1 == 0 {
                        continue;
                    }
                    let px = x0 + b * s;
                    let py = y0 + r as i64 * s;
                    for yy in py.max(0)..(py + s).min(h) {
                        for xx in px.max(0)..(px + s).min(w) {
                            // both in range by the loop bounds
                            img.put_pixel(xx as u32, yy as u32, color);
                        }
                    }
                }
            }
        }
    }
}

/// Formats tick values compactly and distinguishably: fixed notation when
/// the largest `|value|` is in `[0.01, 10^4)`, with as many decimals as the
/// smallest gap between consecutive values needs for two significant digits
/// (`-0.50`, `0.00`, `0.50`), scientific otherwise (`1.2e-3`); an exact zero
/// is always `0`. Non-finite values print as `nan`, `inf`, `-inf`.
///
/// # Example
/// ```
/// use mfm_render::format_ticks;
/// assert_eq!(format_ticks(&[-0.5, 0.0, 0.5]), ["-0.50", "0", "0.50"]);
/// assert_eq!(format_ticks(&[0.0, 0.0006, 0.0012]), ["0", "6.0e-4", "1.2e-3"]);
/// ```
pub fn format_ticks(values: &[f64]) -> Vec<String> {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    let largest = finite.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut gap = f64::INFINITY;
    for (i, a) in finite.iter().enumerate() {
        for b in &finite[i + 1..] {
            let d = (a - b).abs();
            if d > 0.0 {
                gap = gap.min(d);
            }
        }
    }
    if !gap.is_finite() {
        gap = if largest > 0.0 { largest } else { 1.0 };
    }
    let gap_exp = gap.log10().floor() as i32;
    let scientific = largest != 0.0 && !(1e-2..1e4).contains(&largest);
    values
        .iter()
        .map(|&v| {
            if !v.is_finite() {
                return format!("{v}").to_lowercase();
            }
            if v == 0.0 {
                return "0".to_string();
            }
            if scientific {
                let exp = v.abs().log10().floor() as i32;
                let decimals = (exp - gap_exp).clamp(1, 6) as usize;
                format!("{v:.decimals$e}")
            } else {
                let decimals = (1 - gap_exp).clamp(0, 8) as usize;
                format!("{v:.decimals$}")
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks() {
        assert_eq!(format_ticks(&[0.0, 0.5, 1.0]), ["0", "0.50", "1.00"]);
        assert_eq!(
            format_ticks(&[0.98, 1.0, 1.02]),
            ["0.980", "1.000", "1.020"]
        );
        assert_eq!(format_ticks(&[0.0, 50.0, 100.0]), ["0", "50", "100"]);
        assert_eq!(format_ticks(&[-2e5, 0.0, 2e5]), ["-2.0e5", "0", "2.0e5"]);
        assert_eq!(format_ticks(&[3.0, 3.0]), ["3.0", "3.0"]);
        assert_eq!(format_ticks(&[f64::NAN, 1.0]), ["nan", "1.0"]);
    }

    #[test]
    fn text_metrics_and_clipping() {
        assert_eq!(text_width("abc", 2), 48);
        assert_eq!(text_width("a\nlonger", 1), 48);
        assert_eq!(text_height("a\nb", 1), 18);
        let mut img = RgbImage::from_pixel(10, 10, Rgb([255, 255, 255]));
        // partly and fully outside: no panic, something drawn for the visible part
        draw_text(&mut img, -4, -4, "MM", 1, Rgb([0, 0, 0]));
        draw_text(&mut img, 1000, -1000, "x", 3, Rgb([0, 0, 0]));
        assert!(img.pixels().any(|p| p.0 == [0, 0, 0]));
    }

    #[test]
    fn unknown_glyphs_read_as_question_marks() {
        assert_eq!(glyph('\u{4e2d}'), glyph('?'));
        assert_eq!(glyph('\t'), glyph('?'));
        assert_ne!(glyph('A'), glyph('?'));
        assert_ne!(glyph('ν'), glyph('?'));
        // 'A' has a left-right symmetric shape whose top row is centred
        assert_ne!(glyph('A')[0], 0);
    }
}
