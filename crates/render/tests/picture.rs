//! The software renderer, checked on pictures whose content is known:
//! coverage of a sphere's disk, depth order, exact colormap colors on
//! surfaces facing the camera, Lambert shading, colorbars, grids, PNG files.

use std::f64::consts::PI;

use image::{Rgb, RgbImage};
use mfm_geometry::{TriMesh, procedural};
use mfm_render::{
    Camera, ColorRange, Colormap, GridOptions, Panel, Projection, RenderError, RenderOptions,
    Shading, UpAxis, View, Wireframe, grid_layout, render_colorbar, render_grid, render_mesh,
    save_png,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const WHITE: [u8; 3] = [255, 255, 255];

fn front() -> View {
    View::default().front()
}

fn small(width: u32, height: u32) -> RenderOptions {
    RenderOptions {
        view: front(),
        ..RenderOptions::with_size(width, height)
    }
}

/// Largest per-channel difference.
fn diff(a: Rgb<u8>, b: Rgb<u8>) -> u8 {
    (0..3).map(|k| a.0[k].abs_diff(b.0[k])).max().unwrap_or(0)
}

fn scaled(c: Rgb<u8>, s: f64) -> Rgb<u8> {
    Rgb(c.0.map(|x| (f64::from(x) * s).round() as u8))
}

fn center(img: &RgbImage) -> Rgb<u8> {
    *img.get_pixel(img.width() / 2, img.height() / 2)
}

/// The square `[-1, 1]^2` in the plane `z = 0` (normal `+z`), as two triangles.
fn quad() -> TriMesh {
    TriMesh::new(
        vec![
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .expect("valid quad")
}

#[test]
fn image_has_the_requested_size() {
    let mesh = procedural::icosphere(1);
    let z: Vec<f64> = mesh.positions().iter().map(|p| p[2]).collect();
    for (w, h, colorbar) in [
        (128, 128, false),
        (97, 61, true),
        (1, 1, true),
        (200, 40, true),
    ] {
        let opts = RenderOptions {
            colorbar,
            ..RenderOptions::with_size(w, h)
        };
        let img = render_mesh(&mesh, Some(&z), &opts).expect("renders");
        assert_eq!(img.dimensions(), (w, h));
    }
}

#[test]
fn sphere_covers_the_expected_disk() {
    let sphere = procedural::icosphere(3);
    let n = 128u32;
    for view in [
        View::default(),
        front(),
        View {
            up: UpAxis::Z,
            azimuth_deg: -50.0,
            elevation_deg: 70.0,
            ..View::default()
        },
    ] {
        // one sample per pixel: a pixel is covered iff its centre is
        let opts = RenderOptions {
            view,
            supersample: 1,
            ..RenderOptions::with_size(n, n)
        };
        let img = render_mesh(&sphere, None, &opts).expect("renders");
        let (mut count, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for (x, y, p) in img.enumerate_pixels() {
            if p.0 != WHITE {
                count += 1.0;
                sx += f64::from(x) + 0.5;
                sy += f64::from(y) + 0.5;
            }
        }
        // the unit sphere spans 85% of the image: radius 0.85 * 64 pixels
        let r = 0.85 * f64::from(n) / 2.0;
        let expected = PI * r * r;
        assert!(
            (count - expected).abs() < 0.03 * expected,
            "{view:?}: {count} pixels covered, expected {expected:.0}"
        );
        assert!((sx / count - 64.0).abs() < 0.5 && (sy / count - 64.0).abs() < 0.5);
    }
}

#[test]
fn perspective_sphere_is_centred_and_fills_the_image() {
    let sphere = procedural::icosphere(3);
    let opts = RenderOptions {
        view: View {
            projection: Projection::Perspective { fov_deg: 50.0 },
            ..View::default()
        },
        supersample: 1,
        ..RenderOptions::with_size(128, 128)
    };
    let img = render_mesh(&sphere, None, &opts).expect("renders");
    let covered: Vec<(u32, u32)> = img
        .enumerate_pixels()
        .filter(|(_, _, p)| p.0 != WHITE)
        .map(|(x, y, _)| (x, y))
        .collect();
    let xmin = covered.iter().map(|c| c.0).min().unwrap_or(0);
    let xmax = covered.iter().map(|c| c.0).max().unwrap_or(0);
    // 85% of 128 = 108.8 pixels across, centred
    assert!(
        (f64::from(xmax - xmin + 1) - 108.8).abs() <= 2.0,
        "{xmin}..{xmax}"
    );
    assert!((f64::from(xmin + xmax + 1) / 2.0 - 64.0).abs() <= 1.0);
}

/// A big triangle with scalar 0 at `z = 0` and a small one with scalar 1 at
/// `z = dz`; `small_first` puts the small one first in the face list.
fn two_triangles(dz: f64, small_first: bool) -> (TriMesh, Vec<f64>) {
    let mut p = vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]];
    p.extend([[-0.2, -0.2, dz], [0.2, -0.2, dz], [0.0, 0.2, dz]]);
    let big = [0u32, 1, 2];
    let little = [3u32, 4, 5];
    let faces = if small_first {
        vec![little, big]
    } else {
        vec![big, little]
    };
    let s = vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    (TriMesh::new(p, faces).expect("valid"), s)
}

#[test]
fn z_buffer_hides_what_is_behind() {
    let blue = Colormap::CoolWarm.rgb(0.0);
    let red = Colormap::CoolWarm.rgb(1.0);
    for projection in [
        Projection::Orthographic,
        Projection::Perspective { fov_deg: 30.0 },
    ] {
        for small_first in [false, true] {
            let opts = RenderOptions {
                colormap: Colormap::CoolWarm,
                range: ColorRange::Fixed(0.0, 1.0),
                view: View {
                    projection,
                    ..front()
                },
                ..RenderOptions::with_size(128, 128)
            };
            // camera on +z: negative dz is behind the big triangle
            let (mesh, s) = two_triangles(-0.5, small_first);
            let img = render_mesh(&mesh, Some(&s), &opts).expect("renders");
            let c = *img.get_pixel(64, 64);
            assert!(diff(c, blue) <= 2, "behind, {projection:?}: {c:?}");
            let (mesh, s) = two_triangles(0.5, small_first);
            let img = render_mesh(&mesh, Some(&s), &opts).expect("renders");
            let c = *img.get_pixel(64, 64);
            assert!(diff(c, red) <= 2, "in front, {projection:?}: {c:?}");
        }
    }
}

#[test]
fn facing_surface_shows_the_exact_colormap_color() {
    let mesh = quad();
    for (map, value, range, t) in [
        (Colormap::Viridis, 0.3, ColorRange::Fixed(0.0, 1.0), 0.3),
        (Colormap::Viridis, 2.0, ColorRange::Fixed(1.0, 5.0), 0.25),
        (Colormap::CoolWarm, -0.4, ColorRange::Fixed(-1.0, 1.0), 0.3),
        // a constant field under Auto sits in the middle of the map
        (Colormap::Viridis, 7.0, ColorRange::Auto, 0.5),
        (Colormap::CoolWarm, 7.0, ColorRange::Fixed(0.0, 1.0), 1.0),
    ] {
        let s = vec![value; 4];
        let opts = RenderOptions {
            colormap: map,
            range,
            ..small(64, 64)
        };
        let c = center(&render_mesh(&mesh, Some(&s), &opts).expect("renders"));
        let want = map.rgb(t);
        assert!(
            diff(c, want) <= 1,
            "{map:?} at {t}: got {c:?}, want {want:?}"
        );
    }
}

#[test]
fn scalars_are_interpolated_across_triangles() {
    // s = x on the quad: the pixel column at x maps to the colormap at (x+1)/2
    let mesh = quad();
    let s: Vec<f64> = mesh.positions().iter().map(|p| p[0]).collect();
    let opts = RenderOptions {
        range: ColorRange::Fixed(-1.0, 1.0),
        supersample: 1,
        ..small(128, 128)
    };
    let img = render_mesh(&mesh, Some(&s), &opts).expect("renders");
    let cam = Camera::fit(&mesh, &opts.view);
    for x in [-0.75, -0.3, 0.1, 0.6] {
        let p = cam.project([x, 0.3, 0.0], 128, 128).expect("in view");
        let (px, py) = (p[0].floor() as u32, p[1].floor() as u32);
        // the colour at the pixel centre, whose x differs slightly from x
        let xc = x + ((f64::from(px) + 0.5) - p[0]) * 2.0 / (0.85 * 128.0);
        let want = Colormap::Viridis.rgb((xc + 1.0) / 2.0);
        let got = *img.get_pixel(px, py);
        assert!(diff(got, want) <= 2, "x = {x}: got {got:?}, want {want:?}");
    }
}

#[test]
fn lambert_shading_follows_the_angle_and_is_two_sided() {
    // quad in the xz plane (normal +y) seen from elevation e: |n.l| = sin e
    let flat = TriMesh::new(
        vec![
            [-1.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 0.0, -1.0],
            [-1.0, 0.0, -1.0],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .expect("valid");
    let flipped =
        TriMesh::new(flat.positions().to_vec(), vec![[0, 2, 1], [0, 3, 2]]).expect("valid");
    for elevation in [30.0f64, 60.0, -45.0] {
        for mesh in [&flat, &flipped] {
            for shading in [Shading::Smooth, Shading::Flat] {
                let opts = RenderOptions {
                    view: View {
                        azimuth_deg: 0.0,
                        elevation_deg: elevation,
                        ..View::default()
                    },
                    shading,
                    ambient: 0.2,
                    diffuse: 0.6,
                    ..RenderOptions::with_size(64, 64)
                };
                let c = center(&render_mesh(mesh, None, &opts).expect("renders"));
                let shade = 0.2 + 0.6 * elevation.to_radians().sin().abs();
                let want = scaled(opts.surface_color, shade);
                assert!(
                    diff(c, want) <= 1,
                    "elevation {elevation}: {c:?} vs {want:?}"
                );
            }
        }
    }
}

#[test]
fn non_finite_scalars_get_the_nan_color() {
    let mesh = quad();
    let opts = RenderOptions {
        nan_color: Rgb([120, 121, 122]),
        ..small(64, 64)
    };
    for bad in [f64::NAN, f64::INFINITY] {
        let s = vec![bad; 4];
        let c = center(&render_mesh(&mesh, Some(&s), &opts).expect("renders"));
        assert_eq!(c, Rgb([120, 121, 122]));
    }
    // one NaN corner: each triangle blends the corner colors, the "no data"
    // corner with weight lambda_0 = (1 - x)/2 below the diagonal (triangle
    // 0-1-2) and (1 - y)/2 above it (triangle 0-2-3)
    let s = vec![f64::NAN, 1.0, 1.0, 1.0];
    let opts = RenderOptions {
        supersample: 1,
        range: ColorRange::Fixed(0.0, 1.0),
        ..opts
    };
    let img = render_mesh(&mesh, Some(&s), &opts).expect("renders");
    let cam = Camera::fit(&mesh, &opts.view);
    let k = 0.85 * 64.0 / 2.0; // pixels per unit
    let (nan, top) = (Rgb([120.0, 121.0, 122.0]), Colormap::Viridis.rgb(1.0));
    for (x, y) in [
        (0.6, -0.7),
        (-0.5, 0.8),
        (0.9, 0.2),
        (-0.8, -0.2),
        (0.3, -0.95),
    ] {
        let p = cam.project([x, y, 0.0], 64, 64).expect("in view");
        let (px, py) = (p[0].floor(), p[1].floor());
        // world coordinates of that pixel's centre
        let (xc, yc) = (x + (px + 0.5 - p[0]) / k, y - (py + 0.5 - p[1]) / k);
        let l0 = if yc < xc {
            (1.0 - xc) / 2.0
        } else {
            (1.0 - yc) / 2.0
        };
        let want = Rgb(
            [0, 1, 2].map(|c| (l0 * nan.0[c] + (1.0 - l0) * f64::from(top.0[c])).round() as u8)
        );
        let got = *img.get_pixel(px as u32, py as u32);
        assert!(
            diff(got, want) <= 2,
            "({x}, {y}): got {got:?}, want {want:?}"
        );
    }
}

#[test]
fn image_is_not_mirrored_or_upside_down() {
    // right triangle with its right angle at (+1, -1): in a front view (+y
    // up, +x right) the bottom row and the right column are full
    let mesh = TriMesh::new(
        vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0]],
        vec![[0, 1, 2]],
    )
    .expect("valid");
    let img = render_mesh(&mesh, None, &small(100, 100)).expect("renders");
    let row = |y: u32| (0..100).filter(|&x| img.get_pixel(x, y).0 != WHITE).count();
    let col = |x: u32| (0..100).filter(|&y| img.get_pixel(x, y).0 != WHITE).count();
    assert!(row(90) > 70 && row(10) < 15, "rows {} {}", row(10), row(90));
    assert!(col(90) > 70 && col(10) < 15, "cols {} {}", col(10), col(90));
    // the same triangle seen with +z up from the front (-y): x still right
    let standing = TriMesh::new(
        vec![[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0]],
        vec![[0, 1, 2]],
    )
    .expect("valid");
    let opts = RenderOptions {
        view: View {
            up: UpAxis::Z,
            ..front()
        },
        ..RenderOptions::with_size(100, 100)
    };
    let img2 = render_mesh(&standing, None, &opts).expect("renders");
    assert_eq!(img, img2);
}

#[test]
fn shared_edges_leave_no_cracks() {
    // an irregular tiling of a rectangle: every pixel strictly inside is covered
    let grid = procedural::plane_grid(23, 17, 2.0, 1.5).expect("valid grid");
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (hx, hy) = (2.0 / 23.0, 1.5 / 17.0);
    let jittered: Vec<[f64; 3]> = grid
        .positions()
        .iter()
        .map(|p| {
            let inner = p[0].abs() < 0.999 && p[1].abs() < 0.749;
            if inner {
                [
                    p[0] + rng.random_range(-0.3..0.3) * hx,
                    p[1] + rng.random_range(-0.3..0.3) * hy,
                    0.0,
                ]
            } else {
                *p
            }
        })
        .collect();
    let mesh = grid.with_positions(jittered).expect("valid");
    for supersample in [1, 3] {
        let opts = RenderOptions {
            supersample,
            ..small(157, 131)
        };
        let img = render_mesh(&mesh, None, &opts).expect("renders");
        let cam = Camera::fit(&mesh, &opts.view);
        let a = cam.project([-1.0, 0.75, 0.0], 157, 131).expect("in view");
        let b = cam.project([1.0, -0.75, 0.0], 157, 131).expect("in view");
        let mut holes = 0;
        for y in (a[1].ceil() as u32 + 1)..(b[1].floor() as u32 - 1) {
            for x in (a[0].ceil() as u32 + 1)..(b[0].floor() as u32 - 1) {
                if diff(*img.get_pixel(x, y), opts.surface_color) > 1 {
                    holes += 1;
                }
            }
        }
        assert_eq!(holes, 0, "supersample {supersample}");
    }
}

#[test]
fn supersampling_antialiases_edges() {
    let mesh = TriMesh::new(
        vec![[-1.0, -1.0, 0.0], [1.0, -0.7, 0.0], [0.2, 1.0, 0.0]],
        vec![[0, 1, 2]],
    )
    .expect("valid");
    let count_blended = |supersample| {
        let opts = RenderOptions {
            supersample,
            ..small(64, 64)
        };
        let img = render_mesh(&mesh, None, &opts).expect("renders");
        img.pixels()
            .filter(|p| p.0 != WHITE && diff(**p, opts.surface_color) > 1)
            .count()
    };
    assert_eq!(count_blended(1), 0);
    assert!(count_blended(3) > 50);
}

#[test]
fn wireframe_marks_edges_only() {
    let mesh = quad();
    let opts = RenderOptions {
        wireframe: Some(Wireframe {
            color: Rgb([255, 0, 0]),
            width: 2.0,
        }),
        supersample: 1,
        ..small(64, 64)
    };
    let img = render_mesh(&mesh, None, &opts).expect("renders");
    let cam = Camera::fit(&mesh, &opts.view);
    let at = |x: f64, y: f64| {
        let p = cam.project([x, y, 0.0], 64, 64).expect("in view");
        *img.get_pixel(p[0] as u32, p[1] as u32)
    };
    // the shared diagonal and the outline are red, the triangle interiors not
    assert_eq!(at(0.0, 0.0), Rgb([255, 0, 0]));
    assert_eq!(at(-0.99, 0.3), Rgb([255, 0, 0]));
    assert_eq!(at(0.5, -0.5), opts.surface_color);
    assert_eq!(at(-0.5, 0.5), opts.surface_color);
    let plain = render_mesh(&mesh, None, &small(64, 64)).expect("renders");
    assert!(plain.pixels().all(|p| p.0 != [255, 0, 0]));
}

/// The (x, y) extent of the longest run of rows in column x whose pixels are
/// colormap colors, with their positions t in the map (top first).
fn colormap_run(img: &RgbImage, x: u32, map: Colormap) -> Vec<f64> {
    let samples: Vec<(f64, Rgb<u8>)> = (0..=1000)
        .map(|i| {
            let t = f64::from(i) / 1000.0;
            (t, map.rgb(t))
        })
        .collect();
    let mut best: Vec<f64> = Vec::new();
    let mut run: Vec<f64> = Vec::new();
    for y in 0..img.height() {
        let p = *img.get_pixel(x, y);
        let hit = samples
            .iter()
            .filter(|(_, c)| diff(*c, p) <= 1)
            .map(|(t, _)| *t)
            .next();
        match hit {
            Some(t) if p.0 != WHITE => run.push(t),
            _ => {
                if run.len() > best.len() {
                    best = std::mem::take(&mut run);
                }
                run.clear();
            }
        }
    }
    if run.len() > best.len() {
        best = run;
    }
    best
}

#[test]
fn colorbar_shows_the_map_in_order() {
    let sphere = procedural::icosphere(2);
    let z: Vec<f64> = sphere.positions().iter().map(|p| p[2]).collect();
    let (w, h) = (192, 128);
    for map in [Colormap::Viridis, Colormap::CoolWarm] {
        let with = RenderOptions {
            colormap: map,
            colorbar: true,
            ..RenderOptions::with_size(w, h)
        };
        let img = render_mesh(&sphere, Some(&z), &with).expect("renders");
        // some column in the right half holds the whole map, max at the top
        let runs: Vec<Vec<f64>> = (w / 2..w).map(|x| colormap_run(&img, x, map)).collect();
        let bar = runs
            .iter()
            .find(|r| r.len() as f64 > 0.7 * f64::from(h))
            .unwrap_or_else(|| panic!("{map:?}: no colorbar column"));
        assert!(
            bar.windows(2).all(|p| p[1] <= p[0]),
            "{map:?}: not monotone"
        );
        assert!(
            bar[0] > 0.97 && bar[bar.len() - 1] < 0.03,
            "{map:?}: {bar:?}"
        );

        let without = RenderOptions {
            colorbar: false,
            ..with.clone()
        };
        let img = render_mesh(&sphere, Some(&z), &without).expect("renders");
        assert!((w / 2..w).all(|x| colormap_run(&img, x, map).len() < h as usize / 4));
    }
}

#[test]
fn standalone_colorbar() {
    let opts = RenderOptions::with_size(128, 128);
    let bar = render_colorbar(100, -2.0, 3.0, &opts).expect("renders");
    assert_eq!(bar.height(), 100);
    let best = (0..bar.width())
        .map(|x| colormap_run(&bar, x, Colormap::Viridis))
        .max_by_key(|r| r.len())
        .unwrap_or_default();
    assert!(best.len() >= 70, "{}", best.len());
    // labels are drawn: dark pixels right of the bar
    assert!(bar.pixels().any(|p| p.0 == opts.text_color.0));
    assert!(matches!(
        render_colorbar(100, 1.0, 1.0, &opts),
        Err(RenderError::InvalidRange { .. })
    ));
    assert!(matches!(
        render_colorbar(0, 0.0, 1.0, &opts),
        Err(RenderError::InvalidOption { .. })
    ));
}

#[test]
fn grid_dimensions_and_placement() {
    let sphere = procedural::icosphere(1);
    let x: Vec<f64> = sphere.positions().iter().map(|p| p[0]).collect();
    let panel_opts = RenderOptions::with_size(48, 40);
    // no captions, title or colorbar: exactly columns x rows of panels
    let panels: Vec<Panel<'_>> = (0..5).map(|_| Panel::new(&sphere, Some(&x), "")).collect();
    let opts = GridOptions {
        panel: panel_opts.clone(),
        ..GridOptions::default()
    };
    for columns in [1usize, 2, 3, 5, 7] {
        let img = render_grid(&panels, columns, &opts).expect("renders");
        let rows = 5usize.div_ceil(columns) as u32;
        assert_eq!(img.dimensions(), (columns as u32 * 48, rows * 40));
        let layout = grid_layout(&panels, columns, &opts).expect("layout");
        assert_eq!((layout.width, layout.height), img.dimensions());
    }
    // 5 panels in 3 columns: the last cell is empty, the others are not
    let img = render_grid(&panels, 3, &opts).expect("renders");
    let cell_empty = |c: u32, r: u32| {
        (0..48).all(|x| (0..40).all(|y| img.get_pixel(c * 48 + x, r * 40 + y).0 == WHITE))
    };
    assert!(cell_empty(2, 1));
    assert!(!cell_empty(0, 0) && !cell_empty(1, 1));

    // captions, a title and a shared colorbar add bands around the cells
    let captioned: Vec<Panel<'_>> = (0..4)
        .map(|i| Panel::new(&sphere, Some(&x), format!("p{i}")))
        .collect();
    let opts = GridOptions {
        panel: RenderOptions {
            colorbar: true,
            ..panel_opts
        },
        title: Some("T".into()),
        ..GridOptions::default()
    };
    let layout = grid_layout(&captioned, 2, &opts).expect("layout");
    let img = render_grid(&captioned, 2, &opts).expect("renders");
    assert_eq!((layout.width, layout.height), img.dimensions());
    assert!(layout.caption_height >= 8 && layout.title_height >= 8);
    assert!(layout.colorbar_width > 0);
    assert_eq!(layout.cell_height, 40 + layout.caption_height);
    assert_eq!(layout.width, 2 * 48 + layout.colorbar_width);
    assert_eq!(layout.height, layout.title_height + 2 * layout.cell_height);
    // each caption band holds text
    for (c, r) in [(0u32, 0u32), (1, 0), (0, 1), (1, 1)] {
        let y0 = layout.title_height + r * layout.cell_height + 40;
        let inked = (0..48).any(|x| {
            (y0..y0 + layout.caption_height)
                .any(|y| img.get_pixel(c * 48 + x, y).0 == opts.panel.text_color.0)
        });
        assert!(inked, "caption of cell ({c}, {r})");
    }
}

#[test]
fn long_captions_stay_in_their_cell() {
    let mesh = quad();
    let long = "a caption far too long for a 64 pixel cell";
    let panels = [Panel::new(&mesh, None, long), Panel::new(&mesh, None, "")];
    let opts = GridOptions {
        panel: RenderOptions::with_size(64, 64),
        ..GridOptions::default()
    };
    let img = render_grid(&panels, 2, &opts).expect("renders");
    let layout = grid_layout(&panels, 2, &opts).expect("layout");
    let ink = |x0: u32| {
        (x0..x0 + 64)
            .flat_map(|x| (64..layout.cell_height).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == opts.panel.text_color.0)
            .count()
    };
    assert!(ink(0) > 0);
    assert_eq!(ink(64), 0);
}

#[test]
fn grid_shares_the_color_scale() {
    let mesh = quad();
    let one = vec![1.0; 4];
    let two = vec![2.0; 4];
    let panels = [
        Panel::new(&mesh, Some(&one), "1"),
        Panel::new(&mesh, Some(&two), "2"),
    ];
    let panel = small(64, 64);
    let centre_of = |img: &RgbImage, i: u32| *img.get_pixel(64 * i + 32, 32);
    let shared = render_grid(
        &panels,
        2,
        &GridOptions {
            panel: panel.clone(),
            ..GridOptions::default()
        },
    )
    .expect("renders");
    assert!(diff(centre_of(&shared, 0), Colormap::Viridis.rgb(0.0)) <= 1);
    assert!(diff(centre_of(&shared, 1), Colormap::Viridis.rgb(1.0)) <= 1);
    let separate = render_grid(
        &panels,
        2,
        &GridOptions {
            panel,
            shared_range: false,
            ..GridOptions::default()
        },
    )
    .expect("renders");
    assert!(diff(centre_of(&separate, 0), Colormap::Viridis.rgb(0.5)) <= 1);
    assert!(diff(centre_of(&separate, 1), Colormap::Viridis.rgb(0.5)) <= 1);
}

#[test]
fn grid_shared_camera_keeps_relative_sizes() {
    let sphere = procedural::icosphere(2);
    let big = sphere.transformed(2.0, [0.0; 3]);
    let panels = [Panel::new(&sphere, None, ""), Panel::new(&big, None, "")];
    let covered = |img: &RgbImage, i: u32| {
        (0..64)
            .flat_map(|x| (0..64).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(64 * i + x, y).0 != WHITE)
            .count() as f64
    };
    let opts = GridOptions {
        panel: RenderOptions::with_size(64, 64),
        ..GridOptions::default()
    };
    let img = render_grid(&panels, 2, &opts).expect("renders");
    assert!((covered(&img, 0) / covered(&img, 1) - 1.0).abs() < 0.05);
    let opts = GridOptions {
        shared_camera: true,
        ..opts
    };
    let img = render_grid(&panels, 2, &opts).expect("renders");
    assert!((covered(&img, 1) / covered(&img, 0) - 4.0).abs() < 0.4);
}

#[test]
fn invalid_input_is_an_error_not_a_panic() {
    let mesh = quad();
    let opts = RenderOptions::with_size(32, 32);
    assert!(matches!(
        render_mesh(&mesh, Some(&[1.0, 2.0]), &opts),
        Err(RenderError::ScalarCount {
            expected: 4,
            found: 2
        })
    ));
    for bad in [
        RenderOptions::with_size(0, 32),
        RenderOptions::with_size(32, 100_000),
        RenderOptions {
            supersample: 0,
            ..opts.clone()
        },
        RenderOptions {
            ambient: f64::NAN,
            ..opts.clone()
        },
        RenderOptions {
            width: 16000,
            height: 16000,
            supersample: 2,
            ..opts.clone()
        },
    ] {
        assert!(matches!(
            render_mesh(&mesh, None, &bad),
            Err(RenderError::InvalidOption { .. })
        ));
    }
    let bad_range = RenderOptions {
        range: ColorRange::Fixed(1.0, 0.0),
        ..opts.clone()
    };
    assert!(matches!(
        render_mesh(&mesh, Some(&[0.0; 4]), &bad_range),
        Err(RenderError::InvalidRange { .. })
    ));
    let grid = GridOptions::default();
    assert!(matches!(
        render_grid(&[], 2, &grid),
        Err(RenderError::EmptyGrid { .. })
    ));
    let panels = [
        Panel::new(&mesh, None, "a"),
        Panel::new(&mesh, Some(&[1.0]), "b"),
    ];
    assert!(matches!(
        render_grid(&panels, 0, &grid),
        Err(RenderError::EmptyGrid { .. })
    ));
    match render_grid(&panels, 2, &grid) {
        Err(e @ RenderError::Panel { index: 1, .. }) => {
            assert!(e.to_string().contains("\"b\""), "{e}");
        }
        other => panic!("expected a panel error, got {other:?}"),
    }
}

#[test]
fn save_png_round_trips_atomically() {
    let dir = tempfile::tempdir().expect("temp dir");
    let img = render_mesh(&quad(), None, &RenderOptions::with_size(40, 30)).expect("renders");
    let path = dir.path().join("quad.png");
    save_png(&img, &path).expect("writes");
    save_png(&img, &path).expect("overwrites");
    let back = image::open(&path).expect("decodes").to_rgb8();
    assert_eq!(back, img);
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .expect("lists")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["quad.png"], "no temporary files left");
    let missing = dir.path().join("no/such/dir/x.png");
    let err = save_png(&img, &missing).expect_err("directory is missing");
    assert!(err.to_string().contains("no/such/dir/x.png"), "{err}");
}

#[test]
fn rendering_is_deterministic() {
    let sphere = procedural::icosphere(3);
    let z: Vec<f64> = sphere.positions().iter().map(|p| p[2]).collect();
    let opts = RenderOptions {
        wireframe: Some(Wireframe::default()),
        colorbar: true,
        ..RenderOptions::with_size(150, 130)
    };
    let a = render_mesh(&sphere, Some(&z), &opts).expect("renders");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let b = pool.install(|| render_mesh(&sphere, Some(&z), &opts).expect("renders"));
    assert_eq!(a, b);
}
