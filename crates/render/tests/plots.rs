//! The spectrum plots: sizes, one colour per series, text drawn, and errors
//! that name the problem.
#![allow(clippy::unwrap_used)]

use mfm_render::RenderError;
use mfm_render::plots::{
    HISTOGRAM_PANEL_SIZE, HistogramPanel, VARIANCE_PLOT_SIZE, VarianceSeries,
    coefficient_histograms, variance_plot,
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
