//! The spectrum plots: sizes, one colour per series, text drawn, and errors
//! that name the problem.
#![allow(clippy::unwrap_used)]

use mfm_render::RenderError;
use mfm_render::plots::{
    CURVE_PANEL_SIZE, Curve, CurvePanel, HISTOGRAM_PANEL_SIZE, HistogramPanel, VARIANCE_PLOT_SIZE,
    VarianceSeries, coefficient_histograms, curve_grid, variance_plot,
};

/// A Matérn-like spectrum `(lambda + tau)^-2` with a deterministic wobble
/// standing in for sampling error.
fn series(label: &str, tau: f64) -> VarianceSeries {
    let eigenvalues: Vec<f64> = (1..60).map(|i| 0.5 * i as f64).collect();
    let theory: Vec<f64> = eigenvalues.iter().map(|l| (l + tau).powi(-2)).collect();
    let variance = theory
        .iter()
        .enumerate()
        .map(|(i, t)| t * (1.0 + 0.2 * ((i as f64) * 1.7).sin()))
        .collect();
    VarianceSeries {
        label: label.into(),
        eigenvalues,
        variance,
        theory: Some(theory),
    }
}

/// Values spread like a standard normal (a deterministic quantile grid).
fn spread(n: usize, scale: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let u = (i as f64 + 0.5) / n as f64;
            scale * (2.0 * u - 1.0) * (1.0 + (2.0 * u - 1.0).powi(2))
        })
        .collect()
}

fn has(img: &image::RgbImage, rgb: [u8; 3]) -> bool {
    img.pixels().any(|p| p.0 == rgb)
}

#[test]
fn plots_are_written() {
    let dir = tempfile::tempdir().unwrap();
    let p1 = dir.path().join("variance.png");
    variance_plot(
        &p1,
        "Var(c_i)",
        &[series("matern:10", 10.0), series("white", 1e3)],
    )
    .unwrap();
    let img = image::open(&p1).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), VARIANCE_PLOT_SIZE);
    // the first two palette colours (the two series) are both drawn
    assert!(has(&img, [31, 119, 180]) && has(&img, [214, 39, 40]));
    // and black text/axes
    assert!(img.pixels().filter(|p| p.0 == [0, 0, 0]).count() > 500);

    let panel = |title: &str| HistogramPanel {
        title: title.into(),
        series: vec![
            ("a".into(), spread(300, 1.0)),
            ("b".into(), spread(300, 1.5)),
        ],
        bins: 30,
    };
    let p2 = dir.path().join("hist.png");
    coefficient_histograms(&p2, &[panel("c_2"), panel("c_20")]).unwrap();
    let img = image::open(&p2).unwrap().to_rgb8();
    let (w, h) = HISTOGRAM_PANEL_SIZE;
    assert_eq!(img.dimensions(), (2 * w, h));
    assert!(has(&img, [31, 119, 180]) && has(&img, [214, 39, 40]));
}

#[test]
fn plot_errors_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.png");
    let e = coefficient_histograms(&p, &[]).unwrap_err();
    assert!(matches!(e, RenderError::Plot { .. }), "{e}");
    let bad = VarianceSeries {
        label: "x".into(),
        eigenvalues: vec![1.0],
        variance: vec![],
        theory: None,
    };
    let e = variance_plot(&p, "t", &[bad]).unwrap_err();
    assert!(matches!(e, RenderError::Plot { .. }), "{e}");
    assert!(
        e.to_string().contains("1 eigenvalues but 0 variances"),
        "{e}"
    );
    // nothing was left behind by the failures
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

fn curve_panel(title: &str, log_x: bool, points: Vec<(f64, f64)>) -> CurvePanel {
    CurvePanel {
        title: title.into(),
        x_label: "steps".into(),
        y_label: "value".into(),
        log_x,
        references: vec![(0.35, "goal".into())],
        curves: vec![
            Curve {
                label: "a".into(),
                points: points.clone(),
            },
            Curve {
                label: "b".into(),
                points: points.iter().map(|&(x, y)| (x, y * 0.5)).collect(),
            },
        ],
    }
}

#[test]
fn curve_grids_lay_panels_out_in_rows_and_refuse_what_cannot_be_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let pts = vec![(100.0, 0.9), (1000.0, 0.6), (10000.0, 0.5)];
    let p = dir.path().join("curves.png");
    let panels: Vec<CurvePanel> = (0..5)
        .map(|i| curve_panel(&format!("panel {i}"), i % 2 == 0, pts.clone()))
        .collect();
    curve_grid(&p, &panels, 3).unwrap();
    let img = image::open(&p).unwrap().to_rgb8();
    let (w, h) = CURVE_PANEL_SIZE;
    // 5 panels in 3 columns: two rows
    assert_eq!(img.dimensions(), (3 * w, 2 * h));
    assert!(has(&img, [31, 119, 180]) && has(&img, [214, 39, 40]));
    // the reference line's grey
    assert!(has(&img, [120, 120, 120]));

    let q = dir.path().join("bad.png");
    assert!(curve_grid(&q, &[], 2).is_err());
    assert!(curve_grid(&q, &panels, 0).is_err());
    // on a log axis, points at x <= 0 are left out: nothing is left here
    let e = curve_grid(
        &q,
        &[curve_panel("empty", true, vec![(0.0, 1.0), (-1.0, 2.0)])],
        1,
    )
    .unwrap_err();
    assert!(e.to_string().contains("no point to draw"), "{e}");
    // a linear axis draws the same points
    curve_grid(
        &q,
        &[curve_panel("linear", false, vec![(0.0, 1.0), (-1.0, 2.0)])],
        1,
    )
    .unwrap();
    // non-finite values are skipped, not drawn
    let nan = vec![
        (1.0, f64::NAN),
        (2.0, 0.5),
        (f64::INFINITY, 0.2),
        (3.0, 0.4),
    ];
    curve_grid(&q, &[curve_panel("nan", true, nan)], 1).unwrap();
}
