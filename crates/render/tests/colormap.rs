//! The embedded colormaps: known endpoints, perceptual properties (CIE L*),
//! and agreement with matplotlib itself when the Python oracle is available.

use std::process::Command;

use image::Rgb;
use mfm_geometry::test_support::python_oracle;
use mfm_render::Colormap;

/// CIE L* (D65) of an sRGB color.
fn lightness(c: Rgb<u8>) -> f64 {
    let lin = |x: u8| {
        let v = f64::from(x) / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let y = 0.2126 * lin(c.0[0]) + 0.7152 * lin(c.0[1]) + 0.0722 * lin(c.0[2]);
    if y > 216.0 / 24389.0 {
        116.0 * y.cbrt() - 16.0
    } else {
        y * 24389.0 / 27.0
    }
}

#[test]
fn endpoints_match_matplotlib() {
    // matplotlib: viridis(0) = (0.267004, 0.004874, 0.329415),
    // viridis(1) = (0.993248, 0.906157, 0.143936); coolwarm(0) =
    // (0.2298, 0.2987, 0.7537), coolwarm(1) = (0.7057, 0.0156, 0.1502)
    assert_eq!(Colormap::Viridis.rgb(0.0), Rgb([68, 1, 84]));
    assert_eq!(Colormap::Viridis.rgb(1.0), Rgb([253, 231, 37]));
    assert_eq!(Colormap::CoolWarm.rgb(0.0), Rgb([59, 76, 192]));
    assert_eq!(Colormap::CoolWarm.rgb(1.0), Rgb([180, 4, 38]));
}

#[test]
fn viridis_lightness_is_monotone() {
    let l: Vec<f64> = (0..=1000)
        .map(|i| lightness(Colormap::Viridis.rgb(f64::from(i) / 1000.0)))
        .collect();
    // allow one 8-bit rounding step of slack between neighbours
    assert!(l.windows(2).all(|w| w[1] >= w[0] - 0.3), "not monotone");
    // and it really climbs: from dark (L* ~ 16) to light (L* ~ 92)
    assert!(l[0] < 20.0 && l[1000] > 88.0, "{} .. {}", l[0], l[1000]);
    // roughly uniform: each tenth of the map adds a similar amount of L*
    let steps: Vec<f64> = (0..10).map(|k| l[100 * (k + 1)] - l[100 * k]).collect();
    assert!(steps.iter().all(|&s| s > 5.0 && s < 10.0), "{steps:?}");
}

#[test]
fn coolwarm_diverges_from_a_light_middle() {
    let l = |t: f64| lightness(Colormap::CoolWarm.rgb(t));
    let mid = l(0.5);
    assert!(mid > 85.0, "{mid}");
    for k in 0..50 {
        let t = f64::from(k) / 100.0;
        // lightness rises towards the middle from both ends
        assert!(l(t) < l(t + 0.01) + 0.3 && l(1.0 - t) < l(1.0 - t - 0.01) + 0.3);
    }
    // the two ends are about equally dark
    assert!((l(0.0) - l(1.0)).abs() < 10.0);
    let c = Colormap::CoolWarm.rgb(0.5).0;
    assert!(
        c.iter().max().unwrap_or(&0) - c.iter().min().unwrap_or(&0) < 12,
        "{c:?}"
    );
    assert!(Colormap::CoolWarm.is_diverging() && !Colormap::Viridis.is_diverging());
}

#[test]
fn tables_agree_with_matplotlib() {
    let Some(python) = python_oracle() else {
        return;
    };
    let script = "import matplotlib, numpy as np\n\
                  t = np.linspace(0, 1, 101)\n\
                  for name in ['viridis', 'coolwarm']:\n\
                  \x20   for r, g, b, _ in matplotlib.colormaps[name](t):\n\
                  \x20       print(name, r, g, b)\n";
    let out = Command::new(&python)
        .args(["-c", script])
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).expect("utf-8");
    let mut worst = 0.0f64;
    for (i, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        let map = match f[0] {
            "viridis" => Colormap::Viridis,
            _ => Colormap::CoolWarm,
        };
        let t = (i % 101) as f64 / 100.0;
        let got = map.rgb_f32(t);
        for k in 0..3 {
            let want: f64 = f[k + 1].parse().expect("a number");
            worst = worst.max((f64::from(got[k]) - want).abs());
        }
    }
    // matplotlib looks up a 256-entry table without interpolating, we
    // interpolate 65 anchors: they differ by at most a few 8-bit levels
    assert!(worst < 5.0 / 255.0, "worst difference {}", worst * 255.0);
}
