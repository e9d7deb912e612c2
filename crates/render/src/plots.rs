//! PNG plots (spectral diagnostics, curves, point sets), drawn with
//! [plotters](https://docs.rs/plotters) on an in-memory RGB canvas.
//!
//! - [`variance_plot`]: `Var(c_i)` against `lambda_i` on log-log axes, the
//!   empirical values as dots and the theory as a line, one colour per series
//!   (noise kinds, meshes);
//! - [`coefficient_histograms`]: for a few chosen frequencies (e.g. the
//!   paper's `c_2, c_50, c_500`), histograms of the coefficient over several
//!   meshes, overlaid as step outlines in one panel per frequency;
//! - [`curve_grid`]: panels of curves against steps or time;
//! - [`scatter_plot`]: sets of points on one scale in both directions.
//!
//! Text (titles, tick labels, legends) is rendered with the public-domain
//! `font8x8` bitmap glyphs by this module's own backend, so no system font,
//! fontconfig or font file is needed: the plots look the same on any machine.
//!
//! # Example
//! ```
//! use mfm_render::plots::{VarianceSeries, variance_plot};
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("spectrum.png");
//! let lambda: Vec<f64> = (1..40).map(|i| i as f64).collect();
//! let theory: Vec<f64> = lambda.iter().map(|l| (l + 10.0f64).powi(-2)).collect();
//! let series = VarianceSeries {
//!     label: "matern tau=10".into(),
//!     eigenvalues: lambda,
//!     variance: theory.iter().map(|t| t * 1.02).collect(),
//!     theory: Some(theory),
//! };
//! variance_plot(&path, "spectrum", &[series]).unwrap();
//! assert!(std::fs::metadata(&path).unwrap().len() > 1000);
//! ```

use std::convert::Infallible;
use std::path::Path;

use font8x8::{BASIC_FONTS, GREEK_FONTS, LATIN_FONTS, UnicodeFonts};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingErrorKind};

use crate::RenderError;

type Result<T> = std::result::Result<T, RenderError>;

/// Width and height in pixels of a [`variance_plot`].
pub const VARIANCE_PLOT_SIZE: (u32, u32) = (1000, 720);

/// Size in pixels of one panel of [`coefficient_histograms`].
pub const HISTOGRAM_PANEL_SIZE: (u32, u32) = (560, 480);

/// Series colours, in order (cycled).
const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// One series of a [`variance_plot`]: `Var(c_i)` against `lambda_i`.
#[derive(Debug, Clone, PartialEq)]
pub struct VarianceSeries {
    /// Legend text.
    pub label: String,
    /// `lambda_i`.
    pub eigenvalues: Vec<f64>,
    /// Empirical `Var(c_i)`, drawn as dots.
    pub variance: Vec<f64>,
    /// Theoretical `Var(c_i)`, drawn as a line.
    pub theory: Option<Vec<f64>>,
}

impl VarianceSeries {
    /// A series from borrowed columns (e.g. the fields of a spectrum report).
    pub fn new(
        label: impl Into<String>,
        eigenvalues: &[f64],
        variance: &[f64],
        theory: Option<&[f64]>,
    ) -> Self {
        Self {
            label: label.into(),
            eigenvalues: eigenvalues.to_vec(),
            variance: variance.to_vec(),
            theory: theory.map(<[f64]>::to_vec),
        }
    }
}

/// One panel of [`coefficient_histograms`]: the distribution of one
/// coefficient on several meshes.
#[derive(Debug, Clone, PartialEq)]
pub struct HistogramPanel {
    /// Panel title, e.g. `"c_50"`.
    pub title: String,
    /// `(legend text, coefficient values)` per mesh.
    pub series: Vec<(String, Vec<f64>)>,
    /// Number of bins over the common range (at least 1).
    pub bins: usize,
}

/// Writes a log-log PNG of `Var(c_i)` against `lambda_i` for each series
/// (dots: empirical; line: theory), with axes, tick labels, axis titles and a
/// legend. Frequencies with `lambda_i <= 1e-9 max(lambda)` (the zero modes,
/// which have no place on a log axis) or a non-positive variance are left out.
/// The file is written atomically. Size [`VARIANCE_PLOT_SIZE`].
///
/// # Errors
/// [`RenderError::Plot`] if there is nothing positive to draw, a series has
/// mismatched lengths, or the file cannot be written.
pub fn variance_plot(path: impl AsRef<Path>, title: &str, series: &[VarianceSeries]) -> Result<()> {
    let path = path.as_ref();
    let fail = |message: String| RenderError::Plot {
        path: path.to_path_buf(),
        message,
    };
    let mut points = Vec::new(); // per series: (empirical, theory) point lists
    for s in series {
        let n = s.eigenvalues.len();
        if s.variance.len() != n || s.theory.as_ref().is_some_and(|t| t.len() != n) {
            return Err(fail(format!(
                "series {:?}: {} eigenvalues but {} variances{}",
                s.label,
                n,
                s.variance.len(),
                s.theory
                    .as_ref()
                    .map(|t| format!(" and {} theoretical values", t.len()))
                    .unwrap_or_default()
            )));
        }
        let lmax = s.eigenvalues.iter().copied().fold(0.0, f64::max);
        let keep = |i: &usize, v: &[f64]| {
            let l = s.eigenvalues[*i];
            l > 1e-9 * lmax && l.is_finite() && v[*i] > 0.0 && v[*i].is_finite()
        };
        let emp: Vec<(f64, f64)> = (0..n)
            .filter(|i| keep(i, &s.variance))
            .map(|i| (s.eigenvalues[i], s.variance[i]))
            .collect();
        let th: Vec<(f64, f64)> = match &s.theory {
            Some(t) => (0..n)
                .filter(|i| keep(i, t))
                .map(|i| (s.eigenvalues[i], t[i]))
                .collect(),
            None => Vec::new(),
        };
        points.push((emp, th));
    }
    let all = || points.iter().flat_map(|(e, t)| e.iter().chain(t));
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, 0.0f64, f64::MAX, 0.0f64);
    for &(x, y) in all() {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x1 <= 0.0 {
        return Err(fail(
            "no positive eigenvalue with a positive variance to plot".into(),
        ));
    }
    // pad by ~10% in log space, and give degenerate ranges some width
    let (x0, x1) = (x0 / 1.25, x1.max(x0 * 2.0) * 1.25);
    let (y0, y1) = (y0 / 1.5, y1.max(y0 * 2.0) * 1.5);

    let (w, h) = VARIANCE_PLOT_SIZE;
    plot_png(path, (w, h), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 36))
            .margin(20)
            .x_label_area_size(60)
            .y_label_area_size(110)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("eigenvalue lambda_i")
            .y_desc("Var(c_i)")
            .label_style(("sans-serif", 18))
            .axis_desc_style(("sans-serif", 20))
            .x_label_formatter(&|v| short_number(*v))
            .y_label_formatter(&|v| short_number(*v))
            .draw()
            .map_err(|e| e.to_string())?;
        for (i, (s, (emp, th))) in series.iter().zip(&points).enumerate() {
            let c = color(i);
            if !th.is_empty() {
                chart
                    .draw_series(LineSeries::new(th.iter().copied(), c.stroke_width(2)))
                    .map_err(|e| e.to_string())?
                    .label(format!("{} (theory)", s.label))
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                    });
            }
            chart
                .draw_series(emp.iter().map(|&p| Circle::new(p, 3, c.mix(0.8).filled())))
                .map_err(|e| e.to_string())?
                .label(format!("{} (empirical)", s.label))
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
        }
        draw_legend(&mut chart, SeriesLabelPosition::LowerLeft, 18)?;
        Ok(())
    })
}

/// Writes a PNG with one panel per entry of `panels`, side by side: the
/// histograms of that coefficient on each mesh, as density-normalized step
/// outlines (one colour per series, the same colour order in every panel)
/// over a common symmetric range (`±` the largest magnitude found), with
/// axes, tick labels and a legend. The file is written atomically. Each
/// panel is [`HISTOGRAM_PANEL_SIZE`].
///
/// # Errors
/// [`RenderError::Plot`] if `panels` is empty, a panel has no finite value or
/// zero bins, or the file cannot be written.
pub fn coefficient_histograms(path: impl AsRef<Path>, panels: &[HistogramPanel]) -> Result<()> {
    let path = path.as_ref();
    let fail = |message: String| RenderError::Plot {
        path: path.to_path_buf(),
        message,
    };
    if panels.is_empty() {
        return Err(fail("no histogram panel to draw".into()));
    }
    let mut prepared = Vec::with_capacity(panels.len());
    for p in panels {
        if p.bins == 0 {
            return Err(fail(format!("panel {:?} has 0 bins", p.title)));
        }
        let r = p
            .series
            .iter()
            .flat_map(|(_, v)| v.iter())
            .filter(|x| x.is_finite())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        if r <= 0.0 {
            return Err(fail(format!(
                "panel {:?} has no nonzero finite value",
                p.title
            )));
        }
        let width = 2.0 * r / p.bins as f64;
        let outlines: Vec<Vec<(f64, f64)>> = p
            .series
            .iter()
            .map(|(_, v)| {
                let mut counts = vec![0usize; p.bins];
                let mut n = 0usize;
                for &x in v.iter().filter(|x| x.is_finite()) {
                    let b = (((x + r) / width) as usize).min(p.bins - 1);
                    counts[b] += 1;
                    n += 1;
                }
                let dens = |c: usize| c as f64 / (n.max(1) as f64 * width);
                let mut pts = vec![(-r, 0.0)];
                for (b, &c) in counts.iter().enumerate() {
                    let lo = -r + b as f64 * width;
                    pts.push((lo, dens(c)));
                    pts.push((lo + width, dens(c)));
                }
                pts.push((r, 0.0));
                pts
            })
            .collect();
        let ymax = outlines
            .iter()
            .flatten()
            .map(|p| p.1)
            .fold(0.0f64, f64::max)
            .max(f64::MIN_POSITIVE);
        prepared.push((r, ymax * 1.15, outlines));
    }
    let (pw, h) = HISTOGRAM_PANEL_SIZE;
    let w = pw * panels.len() as u32;
    plot_png(path, (w, h), |root| {
        let areas = root.split_evenly((1, panels.len()));
        for ((area, p), (r, ymax, outlines)) in areas.iter().zip(panels).zip(&prepared) {
            let mut chart = ChartBuilder::on(area)
                .caption(&p.title, ("sans-serif", 30))
                .margin(15)
                .x_label_area_size(50)
                .y_label_area_size(80)
                .build_cartesian_2d(-r..*r, 0.0..*ymax)
                .map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .x_desc("coefficient value")
                .y_desc("density")
                .label_style(("sans-serif", 16))
                .axis_desc_style(("sans-serif", 18))
                .x_labels(6)
                // ticks that land on 0 up to round-off read "0"
                .x_label_formatter(&|v| short_number(if v.abs() < 1e-9 * r { 0.0 } else { *v }))
                .y_label_formatter(&|v| short_number(*v))
                .draw()
                .map_err(|e| e.to_string())?;
            for (i, ((label, _), pts)) in p.series.iter().zip(outlines).enumerate() {
                let c = color(i);
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
                    .map_err(|e| e.to_string())?
                    .label(label.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                    });
            }
            draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 16)?;
        }
        Ok(())
    })
}

/// Size in pixels of one panel of [`curve_grid`].
pub const CURVE_PANEL_SIZE: (u32, u32) = (620, 440);

/// One line of a [`CurvePanel`]: `(x, y)` points joined in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// Legend text.
    pub label: String,
    /// The points; those with a non-finite coordinate (or `x <= 0` on a
    /// logarithmic axis) are left out.
    pub points: Vec<(f64, f64)>,
}

/// One panel of [`curve_grid`]: several curves against a common `x`.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvePanel {
    /// Panel title.
    pub title: String,
    /// `x` axis title.
    pub x_label: String,
    /// `y` axis title.
    pub y_label: String,
    /// Logarithmic `x` axis (steps, seconds).
    pub log_x: bool,
    /// Horizontal reference lines `(value, label)`, drawn dashed in grey
    /// (a goal, the data's own value).
    pub references: Vec<(f64, String)>,
    /// The curves; the `i`-th curve of every panel has the same colour.
    pub curves: Vec<Curve>,
}

/// Writes a PNG of `panels` in a grid of `columns` columns (rows as
/// needed): each panel's curves as lines with dots at the points, its
/// reference lines dashed, with axes, tick labels and a legend. The file is
/// written atomically. Each panel is [`CURVE_PANEL_SIZE`].
///
/// # Errors
/// [`RenderError::Plot`] if `panels` is empty, `columns` is 0, a panel has
/// no drawable point, or the file cannot be written.
///
/// # Example
/// ```
/// use mfm_render::plots::{Curve, CurvePanel, curve_grid};
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("curves.png");
/// let panel = CurvePanel {
///     title: "residual".into(),
///     x_label: "steps".into(),
///     y_label: "median".into(),
///     log_x: true,
///     references: vec![(0.35, "goal".into())],
///     curves: vec![Curve { label: "W16".into(), points: vec![(100.0, 0.9), (1000.0, 0.7)] }],
/// };
/// curve_grid(&path, &[panel], 1).unwrap();
/// assert!(std::fs::metadata(&path).unwrap().len() > 1000);
/// ```
pub fn curve_grid(path: impl AsRef<Path>, panels: &[CurvePanel], columns: usize) -> Result<()> {
    let path = path.as_ref();
    let fail = |message: String| RenderError::Plot {
        path: path.to_path_buf(),
        message,
    };
    if panels.is_empty() {
        return Err(fail("no curve panel to draw".into()));
    }
    if columns == 0 {
        return Err(fail("a curve grid needs at least one column".into()));
    }
    let mut ranges = Vec::with_capacity(panels.len());
    let mut kept: Vec<Vec<Vec<(f64, f64)>>> = Vec::with_capacity(panels.len());
    for p in panels {
        let ok = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite() && (!p.log_x || x > 0.0);
        let curves: Vec<Vec<(f64, f64)>> = p
            .curves
            .iter()
            .map(|c| c.points.iter().copied().filter(ok).collect())
            .collect();
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, y) in curves.iter().flatten() {
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
        if x0 > x1 {
            return Err(fail(format!("panel {:?} has no point to draw", p.title)));
        }
        for (v, _) in p.references.iter().filter(|(v, _)| v.is_finite()) {
            (y0, y1) = (y0.min(*v), y1.max(*v));
        }
        let (x0, x1) = if p.log_x {
            (x0 / 1.3, x1.max(x0 * 2.0) * 1.3)
        } else {
            let pad = ((x1 - x0) * 0.05).max(1e-9);
            (x0 - pad, x1 + pad)
        };
        let pad = ((y1 - y0) * 0.08).max(1e-3 * y1.abs().max(1.0));
        ranges.push((x0, x1, y0 - pad, y1 + pad));
        kept.push(curves);
    }
    let rows = panels.len().div_ceil(columns);
    let cols = columns.min(panels.len());
    let (pw, ph) = CURVE_PANEL_SIZE;
    let (w, h) = (pw * cols as u32, ph * rows as u32);
    plot_png(path, (w, h), |root| {
        let areas = root.split_evenly((rows, cols));
        for (k, p) in panels.iter().enumerate() {
            let (x0, x1, y0, y1) = ranges[k];
            let mut builder = ChartBuilder::on(&areas[k]);
            builder
                .caption(&p.title, ("sans-serif", 24))
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(70);
            // one closure per axis kind: plotters' log and linear
            // coordinates are different types
            macro_rules! body {
                ($chart:expr) => {{
                    let mut chart = $chart;
                    chart
                        .configure_mesh()
                        .x_desc(p.x_label.as_str())
                        .y_desc(p.y_label.as_str())
                        .label_style(("sans-serif", 15))
                        .axis_desc_style(("sans-serif", 16))
                        .x_label_formatter(&|v| short_number(*v))
                        .y_label_formatter(&|v| short_number(*v))
                        .draw()
                        .map_err(|e| e.to_string())?;
                    for (v, label) in &p.references {
                        let grey = RGBColor(120, 120, 120);
                        let n = 40;
                        let segments = (0..n).step_by(2).map(|i| {
                            let at = |j: usize| {
                                let f = j as f64 / n as f64;
                                if p.log_x {
                                    (x0.ln() + f * (x1.ln() - x0.ln())).exp()
                                } else {
                                    x0 + f * (x1 - x0)
                                }
                            };
                            PathElement::new(
                                vec![(at(i), *v), (at(i + 1), *v)],
                                grey.stroke_width(1),
                            )
                        });
                        chart
                            .draw_series(segments)
                            .map_err(|e| e.to_string())?
                            .label(format!("{label} ({})", short_number(*v)))
                            .legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(1))
                            });
                    }
                    for (i, (c, pts)) in p.curves.iter().zip(&kept[k]).enumerate() {
                        let col = color(i);
                        chart
                            .draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(2)))
                            .map_err(|e| e.to_string())?
                            .label(c.label.as_str())
                            .legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2))
                            });
                        chart
                            .draw_series(pts.iter().map(|&q| Circle::new(q, 3, col.filled())))
                            .map_err(|e| e.to_string())?;
                    }
                    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 14)?;
                }};
            }
            if p.log_x {
                body!(
                    builder
                        .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
                        .map_err(|e| e.to_string())?
                );
            } else {
                body!(
                    builder
                        .build_cartesian_2d(x0..x1, y0..y1)
                        .map_err(|e| e.to_string())?
                );
            }
        }
        Ok(())
    })
}

/// Width and height in pixels of a [`scatter_plot`].
pub const SCATTER_PLOT_SIZE: (u32, u32) = (820, 820);

/// One set of points of a [`scatter_plot`].
#[derive(Debug, Clone, PartialEq)]
pub struct ScatterSeries {
    /// Legend text.
    pub label: String,
    /// The points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Dot radius in pixels.
    pub radius: u32,
}

/// What a [`scatter_plot`] shows.
#[derive(Debug, Clone, PartialEq)]
pub struct ScatterPlot {
    /// Title above the plot.
    pub title: String,
    /// `x` axis title.
    pub x_label: String,
    /// `y` axis title.
    pub y_label: String,
    /// The series, drawn in order (later ones on top), the `i`-th in the
    /// `i`-th colour of the palette.
    pub series: Vec<ScatterSeries>,
}

/// Writes a PNG of `plot`: each series as filled dots, with axes, tick
/// labels and a legend, both axes at **one scale** (a square range about
/// the points' centre, so that distances read the same along `x` and `y`).
/// Points that are not finite are left out. The file is written
/// atomically. Size [`SCATTER_PLOT_SIZE`].
///
/// # Errors
/// [`RenderError::Plot`] if no series has a finite point, or the file
/// cannot be written.
///
/// # Example
/// ```
/// use mfm_render::plots::{ScatterPlot, ScatterSeries, scatter_plot};
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("plane.png");
/// let ring = (0..24).map(|k| {
///     let a = k as f64 * std::f64::consts::TAU / 24.0;
///     (a.cos(), a.sin())
/// });
/// let plot = ScatterPlot {
///     title: "principal plane".into(),
///     x_label: "direction 1".into(),
///     y_label: "direction 2".into(),
///     series: vec![ScatterSeries { label: "data".into(), points: ring.collect(), radius: 4 }],
/// };
/// scatter_plot(&path, &plot).unwrap();
/// assert!(std::fs::metadata(&path).unwrap().len() > 1000);
/// ```
pub fn scatter_plot(path: impl AsRef<Path>, plot: &ScatterPlot) -> Result<()> {
    let path = path.as_ref();
    let fail = |message: String| RenderError::Plot {
        path: path.to_path_buf(),
        message,
    };
    let kept: Vec<Vec<(f64, f64)>> = plot
        .series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect()
        })
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in kept.iter().flatten() {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x0 > x1 {
        return Err(fail(format!(
            "{:?} has no finite point to draw",
            plot.title
        )));
    }
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let half = (x1 - x0)
        .max(y1 - y0)
        .max(1e-12 * cx.abs().max(cy.abs()).max(1.0))
        * 0.55;
    let (w, h) = SCATTER_PLOT_SIZE;
    plot_png(path, (w, h), |root| {
        let builder = || {
            let mut b = ChartBuilder::on(root);
            b.caption(&plot.title, ("sans-serif", 24))
                .margin(20)
                .x_label_area_size(60)
                .y_label_area_size(90);
            b
        };
        // the plotting area's pixels decide the ranges: one scale on both axes
        let (pw, ph) = builder()
            .build_cartesian_2d(0.0..1.0, 0.0..1.0)
            .map_err(|e| e.to_string())?
            .plotting_area()
            .dim_in_pixel();
        let (pw, ph) = (f64::from(pw.max(1)), f64::from(ph.max(1)));
        let (hx, hy) = if pw >= ph {
            (half * pw / ph, half)
        } else {
            (half, half * ph / pw)
        };
        let mut chart = builder()
            .build_cartesian_2d(cx - hx..cx + hx, cy - hy..cy + hy)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(plot.x_label.as_str())
            .y_desc(plot.y_label.as_str())
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 18))
            .x_label_formatter(&|v| short_number(*v))
            .y_label_formatter(&|v| short_number(*v))
            .draw()
            .map_err(|e| e.to_string())?;
        for (i, (s, pts)) in plot.series.iter().zip(&kept).enumerate() {
            let c = color(i);
            let r = s.radius.max(1);
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, r, c.mix(0.85).filled())))
                .map_err(|e| e.to_string())?
                .label(s.label.as_str())
                .legend(move |(x, y)| Circle::new((x + 10, y), r, c.filled()));
        }
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 16)?;
        Ok(())
    })
}

/// Draws a plot onto a white RGB canvas of `size` pixels with `draw` and
/// writes it to `path` as a PNG, atomically; `draw`'s error message
/// becomes [`RenderError::Plot`] naming the path.
fn plot_png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&DrawingArea<Canvas<'_>, Shift>) -> std::result::Result<(), String>,
) -> Result<()> {
    let mut buf = vec![255u8; (w as usize) * (h as usize) * 3];
    {
        let root = Canvas::new(&mut buf, w, h).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| e.to_string())
            .and_then(|()| draw(&root))
            .and_then(|()| root.present().map_err(|e| e.to_string()))
            .map_err(|message| RenderError::Plot {
                path: path.to_path_buf(),
                message,
            })?;
    }
    write_png(path, &buf, w, h)
}

/// The legend every plot draws: its series' labels at `position` in
/// `size`-pixel text on a translucent white box with a black border.
fn draw_legend<'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, Canvas<'a>, CT>,
    position: SeriesLabelPosition,
    size: u32,
) -> std::result::Result<(), String> {
    chart
        .configure_series_labels()
        .position(position)
        .label_font(("sans-serif", size))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())
}

/// Compact tick label: `0`, `12`, `0.25`, `1.5e-3`, `2e4`.
fn short_number(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-2..1e4).contains(&a) {
        let s = format!("{v:.3}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_owned()
    } else {
        let s = format!("{v:.1e}");
        s.replace(".0e", "e")
    }
}

/// Encodes the RGB buffer as PNG next to `path`, then renames it over `path`.
fn write_png(path: &Path, buf: &[u8], w: u32, h: u32) -> Result<()> {
    let fail = |message: String| RenderError::Plot {
        path: path.to_path_buf(),
        message,
    };
    let img = image::RgbImage::from_raw(w, h, buf.to_vec())
        .ok_or_else(|| fail("internal: canvas buffer has the wrong size".into()))?;
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| fail(format!("PNG encoding failed: {e}")))?;
    mfm_files::write_atomic(path, |w| w.write_all(&bytes)).map_err(|e| fail(e.to_string()))
}

/// A plotters backend on an RGB8 buffer whose text is drawn with the
/// `font8x8` glyphs (each font pixel an `s x s` block, `s` from the font
/// size so the text is about as wide as plotters' own estimate of it).
struct Canvas<'a> {
    buf: &'a mut [u8],
    w: u32,
    h: u32,
}

impl<'a> Canvas<'a> {
    fn new(buf: &'a mut [u8], w: u32, h: u32) -> Self {
        Self { buf, w, h }
    }

    /// Glyph scale for a font size in pixels: plotters' estimate of a
    /// character's width is about `0.455 size`, a glyph is 8 pixels wide.
    fn scale(size: f64) -> i32 {
        ((size * 0.455 / 8.0).round() as i32).max(1)
    }

    fn glyph(c: char) -> [u8; 8] {
        let find = |c: char| {
            BASIC_FONTS
                .get(c)
                .or_else(|| LATIN_FONTS.get(c))
                .or_else(|| GREEK_FONTS.get(c))
        };
        find(c).or_else(|| find('?')).unwrap_or([0; 8])
    }

    fn blend(&mut self, (x, y): BackendCoord, color: BackendColor) {
        if x < 0 || y < 0 || x >= self.w as i32 || y >= self.h as i32 || color.alpha <= 0.0 {
            return;
        }
        let i = (y as usize * self.w as usize + x as usize) * 3;
        let a = color.alpha.min(1.0);
        let (r, g, b) = color.rgb;
        for (k, c) in [r, g, b].into_iter().enumerate() {
            let old = f64::from(self.buf[i + k]);
            self.buf[i + k] = (old + (f64::from(c) - old) * a).round() as u8;
        }
    }
}

impl DrawingBackend for Canvas<'_> {
    type ErrorType = Infallible;

    fn get_size(&self) -> (u32, u32) {
        (self.w, self.h)
    }

    fn ensure_prepared(&mut self) -> std::result::Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn present(&mut self) -> std::result::Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> std::result::Result<(), DrawingErrorKind<Infallible>> {
        self.blend(point, color);
        Ok(())
    }

    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> std::result::Result<(), DrawingErrorKind<Infallible>> {
        let color = style.color();
        let s = Self::scale(style.size());
        let n = text.chars().count() as i32;
        let (tw, th) = (8 * s * n, 8 * s);
        let anchor = style.anchor();
        let dx = match anchor.h_pos {
            HPos::Left => 0,
            HPos::Center => -tw / 2,
            HPos::Right => -tw,
        };
        let dy = match anchor.v_pos {
            VPos::Top => 0,
            VPos::Center => -th / 2,
            VPos::Bottom => -th,
        };
        let transform = style.transform();
        for (ci, ch) in text.chars().enumerate() {
            let rows = Self::glyph(ch);
            for (gy, row) in rows.iter().enumerate() {
                for gx in 0..8 {
                    if row & (1 << gx) == 0 {
                        continue;
                    }
                    for py in 0..s {
                        for px in 0..s {
                            let x = dx + ci as i32 * 8 * s + gx * s + px;
                            let y = dy + gy as i32 * s + py;
                            let (x, y) = transform.transform(x, y);
                            self.blend((pos.0 + x, pos.1 + y), color);
                        }
                    }
                }
            }
        }
        Ok(())
    }

    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> std::result::Result<(u32, u32), DrawingErrorKind<Infallible>> {
        let s = Self::scale(style.size()) as u32;
        Ok((8 * s * text.chars().count() as u32, 8 * s))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn short_numbers() {
        assert_eq!(short_number(0.0), "0");
        assert_eq!(short_number(12.0), "12");
        assert_eq!(short_number(0.25), "0.25");
        assert_eq!(short_number(0.0015), "1.5e-3");
        assert_eq!(short_number(20000.0), "2e4");
    }

    #[test]
    fn canvas_draws_text_in_the_text_color() {
        let (w, h) = (64u32, 16u32);
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = Canvas::new(&mut buf, w, h).into_drawing_area();
            root.draw_text(
                "Hi",
                &("sans-serif", 12).into_text_style(&root).color(&RED),
                (0, 0),
            )
            .unwrap();
        }
        let red = buf.chunks(3).filter(|p| p == &[255, 0, 0]).count();
        assert!(red > 10, "{red} red pixels");
    }
}
