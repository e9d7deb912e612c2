//! Colormaps (scalar in `[0, 1]` to RGB) and color ranges (scalar values to
//! `[0, 1]`).
//!
//! The maps are matplotlib's, sampled at 65 evenly spaced anchors by
//! `xtask/python/colormap_tables.py` and interpolated linearly in between
//! (within 3 of 255 levels of matplotlib's own lookup tables).

use super::RenderError;
use super::colormap_tables::{ANCHORS, COOLWARM, VIRIDIS};

/// A map from `t` in `[0, 1]` to a color.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Colormap {
    /// matplotlib's `viridis`: sequential, perceptually uniform, lightness
    /// increasing from dark purple (`t = 0`) to yellow (`t = 1`). For
    /// unsigned quantities (areas, variances, distances).
    #[default]
    Viridis,
    /// matplotlib's `coolwarm` (Moreland): diverging blue (`t = 0`), light
    /// gray (`t = 0.5`), red (`t = 1`). For signed quantities; pair it with
    /// [`ColorRange::Symmetric`] so that zero is the neutral middle.
    CoolWarm,
}

impl Colormap {
    fn table(self) -> &'static [[f32; 3]; ANCHORS] {
        match self {
            Colormap::Viridis => &VIRIDIS,
            Colormap::CoolWarm => &COOLWARM,
        }
    }

    /// Color at `t` as RGB in `[0, 1]`. `t` is clamped to `[0, 1]`; NaN reads
    /// as 0. Cost: `O(1)`.
    pub fn rgb_f32(self, t: f64) -> [f32; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let table = self.table();
        let x = t * (ANCHORS - 1) as f64;
        // x is in [0, ANCHORS - 1], so the floor is a valid index
        let i = (x.floor() as usize).min(ANCHORS - 2);
        let w = (x - i as f64) as f32;
        let (a, b) = (table[i], table[i + 1]);
        [
            a[0] + w * (b[0] - a[0]),
            a[1] + w * (b[1] - a[1]),
            a[2] + w * (b[2] - a[2]),
        ]
    }

    /// Color at `t` as 8-bit RGB (rounded). `t` is clamped to `[0, 1]`; NaN
    /// reads as 0. Cost: `O(1)`.
    pub fn rgb(self, t: f64) -> image::Rgb<u8> {
        let c = self.rgb_f32(t);
        image::Rgb([to_u8(c[0]), to_u8(c[1]), to_u8(c[2])])
    }

    /// Whether the map is diverging (meant for signed data around 0).
    pub fn is_diverging(self) -> bool {
        matches!(self, Colormap::CoolWarm)
    }
}

/// `[0, 1]` to `0..=255`, rounded; values outside are clamped.
pub(crate) fn to_u8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Which scalar values map to the two ends of the colormap.
///
/// Non-finite scalars (NaN, ±inf) are ignored when the range is computed and
/// drawn in the "no data" color
/// ([`RenderOptions::nan_color`](super::RenderOptions::nan_color)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum ColorRange {
    /// `min..max` of the finite scalars (default).
    #[default]
    Auto,
    /// `-m..m` with `m` the largest finite `|value|`: zero sits in the middle
    /// of the map. Use with a diverging map for signed signals.
    Symmetric,
    /// A fixed `lo..hi` (finite, `lo <= hi`), e.g. to give several pictures
    /// one scale.
    Fixed(f64, f64),
}

impl ColorRange {
    /// Resolves the range over one scalar field; see [`ColorRange::resolve_all`].
    ///
    /// # Errors
    /// [`RenderError::InvalidRange`] for a `Fixed` range that is not finite or
    /// has `lo > hi`.
    pub fn resolve(&self, values: &[f64]) -> Result<(f64, f64), RenderError> {
        self.resolve_all(&[values])
    }

    /// Resolves the range over several scalar fields together (a shared
    /// scale), returning `(lo, hi)` with `lo < hi`. Cost: `O(total values)`.
    ///
    /// A degenerate range is widened so the colormap stays usable: a
    /// constant `c != 0` gives `c ± |c|/2`, a constant 0 (or no finite value
    /// at all under `Symmetric`) gives `-1..1`, no finite value under `Auto`
    /// gives `0..1`, and `Fixed(c, c)` gives `c ± max(|c|/2, 1e-300)`.
    ///
    /// # Errors
    /// [`RenderError::InvalidRange`] for a `Fixed` range that is not finite or
    /// has `lo > hi`.
    pub fn resolve_all(&self, fields: &[&[f64]]) -> Result<(f64, f64), RenderError> {
        let finite = || {
            fields
                .iter()
                .flat_map(|f| f.iter())
                .copied()
                .filter(|v| v.is_finite())
        };
        let (lo, hi) = match *self {
            ColorRange::Fixed(lo, hi) => {
                if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                    return Err(RenderError::InvalidRange { lo, hi });
                }
                (lo, hi)
            }
            ColorRange::Auto => {
                let (lo, hi) = finite().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                });
                if lo > hi {
                    return Ok((0.0, 1.0));
                }
                (lo, hi)
            }
            ColorRange::Symmetric => {
                let m = finite().fold(0.0f64, |m, v| m.max(v.abs()));
                (-m, m)
            }
        };
        Ok(widen(lo, hi))
    }
}

/// Widens a degenerate (`lo == hi`) range as documented in `resolve_all`.
fn widen(lo: f64, hi: f64) -> (f64, f64) {
    if lo < hi {
        return (lo, hi);
    }
    let c = lo;
    if c == 0.0 {
        return (-1.0, 1.0);
    }
    let d = (0.5 * c.abs()).max(1e-300);
    (c - d, c + d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchors_are_hit_exactly() {
        for (map, table) in [
            (Colormap::Viridis, &VIRIDIS),
            (Colormap::CoolWarm, &COOLWARM),
        ] {
            for (i, c) in table.iter().enumerate() {
                let t = i as f64 / (ANCHORS - 1) as f64;
                let got = map.rgb_f32(t);
                for k in 0..3 {
                    assert!((got[k] - c[k]).abs() < 1e-6, "{map:?} anchor {i}");
                }
            }
        }
    }

    #[test]
    fn out_of_range_is_clamped() {
        assert_eq!(Colormap::Viridis.rgb(-3.0), Colormap::Viridis.rgb(0.0));
        assert_eq!(Colormap::Viridis.rgb(7.0), Colormap::Viridis.rgb(1.0));
        assert_eq!(
            Colormap::CoolWarm.rgb(f64::NAN),
            Colormap::CoolWarm.rgb(0.0)
        );
    }

    #[test]
    fn ranges() {
        let v = [1.0, f64::NAN, -3.0, 2.0, f64::INFINITY];
        assert_eq!(ColorRange::Auto.resolve(&v).ok(), Some((-3.0, 2.0)));
        assert_eq!(ColorRange::Symmetric.resolve(&v).ok(), Some((-3.0, 3.0)));
        assert_eq!(
            ColorRange::Fixed(0.0, 5.0).resolve(&v).ok(),
            Some((0.0, 5.0))
        );
        assert!(ColorRange::Fixed(2.0, 1.0).resolve(&v).is_err());
        assert!(ColorRange::Fixed(f64::NAN, 1.0).resolve(&v).is_err());
        assert_eq!(ColorRange::Auto.resolve(&[4.0, 4.0]).ok(), Some((2.0, 6.0)));
        assert_eq!(ColorRange::Auto.resolve(&[f64::NAN]).ok(), Some((0.0, 1.0)));
        assert_eq!(
            ColorRange::Symmetric.resolve(&[0.0]).ok(),
            Some((-1.0, 1.0))
        );
        assert_eq!(
            ColorRange::Auto.resolve_all(&[&[1.0], &[5.0, 2.0]]).ok(),
            Some((1.0, 5.0))
        );
    }
}
