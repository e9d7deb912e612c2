//! The rasterizer: a visibility pass (z-buffer of triangle ids at the
//! supersampled resolution) followed by a shading pass that resolves each
//! output pixel from its `s x s` samples.
//!
//! - Vertices are snapped to a fixed-point grid of 1/256 pixel and the edge
//!   functions are evaluated exactly in integers with a top-left-style tie
//!   rule, so two triangles sharing an edge never both miss (or both cover) a
//!   sample on it: no cracks, no double coverage.
//! - The supersampled image is cut into horizontal bands; triangles are
//!   binned by band and each band is rasterized by one rayon task in
//!   triangle order, so the result does not depend on the thread count.
//! - Shading happens once per visible sample (deferred), not per fragment.
//!
//! Cost: `O(V + F + samples covered)` for the visibility pass,
//! `O(width·height·s²)` for shading.

use image::{Rgb, RgbImage};
use rayon::prelude::*;

use super::camera::Camera;
use super::colormap::{Colormap, to_u8};
use super::{RenderOptions, Shading};
use mfm_geometry::mesh::{TriMesh, add, dot, triangle_normal};

/// Sub-pixel bits of the fixed-point vertex grid.
const SUBPIXEL_BITS: u32 = 8;
const ONE: i64 = 1 << SUBPIXEL_BITS;
/// Triangles with a vertex farther than this many pixels from the image are
/// skipped (keeps the integer edge functions far from overflow).
const MAX_COORD_PX: f64 = (1 << 21) as f64;
/// Rows of supersampled pixels per band.
const BAND_ROWS: usize = 32;
/// "No triangle" in the id buffer.
const NONE: u32 = u32::MAX;

/// A scalar field prepared for shading.
pub(crate) struct Field<'a> {
    pub values: &'a [f64],
    pub lo: f64,
    pub hi: f64,
    pub colormap: Colormap,
}

/// A vertex after projection to supersampled pixels.
#[derive(Clone, Copy)]
struct Projected {
    /// Pixel position (y down) and the depth key (smaller is nearer,
    /// affine in screen space).
    x: f64,
    y: f64,
    key: f64,
    /// Perspective depth (1 for orthographic), for perspective-correct
    /// interpolation.
    w: f64,
    /// Fixed-point position.
    ix: i64,
    iy: i64,
    valid: bool,
}

/// Renders the mesh into a `width x height` image (no colorbar).
pub(crate) fn render_surface(
    mesh: &TriMesh,
    field: Option<&Field<'_>>,
    camera: &Camera,
    width: u32,
    height: u32,
    opts: &RenderOptions,
) -> RgbImage {
    let ss = opts.supersample.max(1) as usize;
    let (sw, sh) = (width as usize * ss, height as usize * ss);
    let projected = project(mesh, camera, sw, sh);
    let (ids, _depth) = visibility(mesh, &projected, sw, sh);
    shade(
        mesh, field, camera, &projected, &ids, width, height, ss, opts,
    )
}

fn project(mesh: &TriMesh, camera: &Camera, sw: usize, sh: usize) -> Vec<Projected> {
    let perspective = camera.is_perspective();
    let (k, c) = camera.pixel_mapping(sw as f64, sh as f64);
    let window = camera.window_center();
    mesh.positions()
        .par_iter()
        .map(|p| match camera.to_plane(*p) {
            Some([u, v, d]) => {
                let x = c[0] + (u - window[0]) * k;
                let y = c[1] - (v - window[1]) * k;
                let (key, w) = if perspective { (-1.0 / d, d) } else { (d, 1.0) };
                let in_range = x.abs() < MAX_COORD_PX && y.abs() < MAX_COORD_PX;
                Projected {
                    x,
                    y,
                    key,
                    w,
                    ix: (x * ONE as f64).round() as i64,
                    iy: (y * ONE as f64).round() as i64,
                    valid: in_range,
                }
            }
            None => Projected {
                x: 0.0,
                y: 0.0,
                key: 0.0,
                w: 1.0,
                ix: 0,
                iy: 0,
                valid: false,
            },
        })
        .collect()
}

/// A triangle ready for integer rasterization: counter-clockwise in pixel
/// space (positive `area2`), with per-edge increments and tie biases.
struct Setup {
    xs: [i64; 3],
    ys: [i64; 3],
    area2: i64,
    bias: [i64; 3],
    keys: [f64; 3],
    /// Inclusive pixel bounding box, clipped to the image.
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
}

/// `ceil(a / ONE)` and `floor(a / ONE)` for the pixel-centre bounds.
fn first_center_at_or_after(a: i64) -> i64 {
    // centre of pixel i is i*ONE + ONE/2
    (a - ONE / 2 + ONE - 1).div_euclid(ONE)
}
fn last_center_at_or_before(a: i64) -> i64 {
    (a - ONE / 2).div_euclid(ONE)
}

fn setup(face: [u32; 3], p: &[Projected], sw: usize, sh: usize) -> Option<Setup> {
    let mut v = face.map(|i| i as usize);
    if v.iter().any(|&i| !p[i].valid) {
        return None;
    }
    let area = |v: &[usize; 3]| {
        let (a, b, c) = (&p[v[0]], &p[v[1]], &p[v[2]]);
        (b.ix - a.ix) * (c.iy - a.iy) - (b.iy - a.iy) * (c.ix - a.ix)
    };
    let mut area2 = area(&v);
    if area2 == 0 {
        return None;
    }
    if area2 < 0 {
        v.swap(1, 2);
        area2 = -area2;
    }
    let xs = v.map(|i| p[i].ix);
    let ys = v.map(|i| p[i].iy);
    let xmin = xs.iter().copied().min().unwrap_or(0);
    let xmax = xs.iter().copied().max().unwrap_or(0);
    let ymin = ys.iter().copied().min().unwrap_or(0);
    let ymax = ys.iter().copied().max().unwrap_or(0);
    let x0 = first_center_at_or_after(xmin).max(0);
    let x1 = last_center_at_or_before(xmax).min(sw as i64 - 1);
    let y0 = first_center_at_or_after(ymin).max(0);
    let y1 = last_center_at_or_before(ymax).min(sh as i64 - 1);
    if x0 > x1 || y0 > y1 {
        return None;
    }
    // edge e runs from vertex e+1 to vertex e+2 (opposite vertex e); it owns
    // the samples exactly on it when it points down, or left if horizontal.
    // A shared edge is traversed in opposite directions by its two
    // (counter-clockwise) triangles, so exactly one of them owns it.
    let mut bias = [0i64; 3];
    for (e, b) in bias.iter_mut().enumerate() {
        let (j, k) = ((e + 1) % 3, (e + 2) % 3);
        let (dx, dy) = (xs[k] - xs[j], ys[k] - ys[j]);
        let owned = dy > 0 || (dy == 0 && dx < 0);
        *b = if owned { 0 } else { -1 };
    }
    Some(Setup {
        xs,
        ys,
        area2,
        bias,
        keys: v.map(|i| p[i].key),
        x0: x0 as usize,
        x1: x1 as usize,
        y0: y0 as usize,
        y1: y1 as usize,
    })
}

/// Visibility pass: per supersampled pixel, the id of the nearest triangle
/// covering its centre (or `NONE`) and its depth key.
fn visibility(mesh: &TriMesh, p: &[Projected], sw: usize, sh: usize) -> (Vec<u32>, Vec<f32>) {
    let faces = mesh.faces();
    let bands = sh.div_ceil(BAND_ROWS);
    // band span of every drawable triangle
    let spans: Vec<Option<(u32, u32)>> = faces
        .par_iter()
        .map(|f| {
            setup(*f, p, sw, sh).map(|s| ((s.y0 / BAND_ROWS) as u32, (s.y1 / BAND_ROWS) as u32))
        })
        .collect();
    // bin triangle ids by band (counting sort keeps triangle order per band)
    let mut starts = vec![0usize; bands + 1];
    for &(a, b) in spans.iter().flatten() {
        for band in a..=b {
            starts[band as usize + 1] += 1;
        }
    }
    for i in 0..bands {
        starts[i + 1] += starts[i];
    }
    let mut fill = starts.clone();
    let mut binned = vec![0u32; starts[bands]];
    for (t, span) in spans.iter().enumerate() {
        if let Some((a, b)) = *span {
            for band in a..=b {
                let slot = &mut fill[band as usize];
                binned[*slot] = t as u32;
                *slot += 1;
            }
        }
    }

    let mut ids = vec![NONE; sw * sh];
    let mut depth = vec![f32::INFINITY; sw * sh];
    ids.par_chunks_mut(BAND_ROWS * sw)
        .zip(depth.par_chunks_mut(BAND_ROWS * sw))
        .enumerate()
        .for_each(|(band, (ids, depth))| {
            let row0 = band * BAND_ROWS;
            let row1 = (row0 + BAND_ROWS).min(sh) - 1;
            for &t in &binned[starts[band]..starts[band + 1]] {
                let Some(s) = setup(faces[t as usize], p, sw, sh) else {
                    continue;
                };
                raster_triangle(&s, t, row0, row1, sw, ids, depth);
            }
        });
    (ids, depth)
}

/// Writes one triangle into the rows `row0..=row1` of a band.
fn raster_triangle(
    s: &Setup,
    id: u32,
    row0: usize,
    row1: usize,
    sw: usize,
    ids: &mut [u32],
    depth: &mut [f32],
) {
    let (y0, y1) = (s.y0.max(row0), s.y1.min(row1));
    if y0 > y1 {
        return;
    }
    let inv_area = 1.0 / s.area2 as f64;
    // edge e from vertex j = e+1 to k = e+2:
    // E_e(x, y) = (xk - xj)(y - yj) - (yk - yj)(x - xj)
    let mut step_x = [0i64; 3];
    for (e, step) in step_x.iter_mut().enumerate() {
        let (j, k) = ((e + 1) % 3, (e + 2) % 3);
        *step = -(s.ys[k] - s.ys[j]) * ONE;
    }
    let px0 = s.x0 as i64 * ONE + ONE / 2;
    let edge_at = |e: usize, px: i64, py: i64| {
        let (j, k) = ((e + 1) % 3, (e + 2) % 3);
        (s.xs[k] - s.xs[j]) * (py - s.ys[j]) - (s.ys[k] - s.ys[j]) * (px - s.xs[j])
    };
    for y in y0..=y1 {
        let py = y as i64 * ONE + ONE / 2;
        let mut ev = [
            edge_at(0, px0, py),
            edge_at(1, px0, py),
            edge_at(2, px0, py),
        ];
        let row = (y - row0) * sw;
        for x in s.x0..=s.x1 {
            if ev[0] + s.bias[0] >= 0 && ev[1] + s.bias[1] >= 0 && ev[2] + s.bias[2] >= 0 {
                let z = ((ev[0] as f64) * s.keys[0]
                    + (ev[1] as f64) * s.keys[1]
                    + (ev[2] as f64) * s.keys[2])
                    * inv_area;
                let z = z as f32;
                let i = row + x;
                if z < depth[i] {
                    depth[i] = z;
                    ids[i] = id;
                }
            }
            for e in 0..3 {
                ev[e] += step_x[e];
            }
        }
    }
}

/// Area-weighted vertex normals (unnormalized sums of face normals).
fn vertex_normals(mesh: &TriMesh) -> Vec<[f64; 3]> {
    let mut n = vec![[0.0; 3]; mesh.num_vertices()];
    for (f, face) in mesh.faces().iter().enumerate() {
        let fn_ = triangle_normal(&mesh.face_positions(f));
        for &v in face {
            n[v as usize] = add(n[v as usize], fn_);
        }
    }
    n
}

fn rgb_f32(c: Rgb<u8>) -> [f32; 3] {
    c.0.map(|x| f32::from(x) / 255.0)
}

/// Shading pass: resolves every output pixel from its `ss x ss` samples.
#[allow(clippy::too_many_arguments)]
fn shade(
    mesh: &TriMesh,
    field: Option<&Field<'_>>,
    camera: &Camera,
    p: &[Projected],
    ids: &[u32],
    width: u32,
    height: u32,
    ss: usize,
    opts: &RenderOptions,
) -> RgbImage {
    let sw = width as usize * ss;
    let smooth = matches!(opts.shading, Shading::Smooth);
    let normals = if smooth {
        vertex_normals(mesh)
    } else {
        Vec::new()
    };
    // the headlight: light travels along the view direction
    let light = camera.forward();
    // normalized scalar per vertex (NaN for no data)
    let t: Vec<f32> = match field {
        Some(f) => {
            let inv = 1.0 / (f.hi - f.lo);
            f.values
                .iter()
                .map(|&v| {
                    if v.is_finite() {
                        ((v - f.lo) * inv) as f32
                    } else {
                        f32::NAN
                    }
                })
                .collect()
        }
        None => Vec::new(),
    };
    let colormap = field.map(|f| f.colormap).unwrap_or_default();
    let background = rgb_f32(opts.background);
    let surface = rgb_f32(opts.surface_color);
    let nan_color = rgb_f32(opts.nan_color);
    let wire = opts.wireframe.map(|w| {
        let half = 0.5 * w.width.max(0.0) * ss as f64;
        (rgb_f32(w.color), half)
    });
    let (ambient, diffuse) = (opts.ambient as f32, opts.diffuse as f32);
    let positions = mesh.positions();
    let faces = mesh.faces();
    let perspective = camera.is_perspective();

    let sample = |t_id: u32, sx: f64, sy: f64| -> [f32; 3] {
        if t_id == NONE {
            return background;
        }
        let face = faces[t_id as usize];
        let [a, b, c] = face.map(|i| i as usize);
        let (pa, pb, pc) = (&p[a], &p[b], &p[c]);
        // screen-space barycentrics from the exact projected positions
        let area2 = (pb.x - pa.x) * (pc.y - pa.y) - (pb.y - pa.y) * (pc.x - pa.x);
        let edge = |p0: &Projected, p1: &Projected| {
            (p1.x - p0.x) * (sy - p0.y) - (p1.y - p0.y) * (sx - p0.x)
        };
        let mut l = if area2 != 0.0 {
            [
                edge(pb, pc) / area2,
                edge(pc, pa) / area2,
                edge(pa, pb) / area2,
            ]
        } else {
            [1.0 / 3.0; 3]
        };
        for x in &mut l {
            *x = x.max(0.0);
        }
        let wire_hit = wire.and_then(|(color, half)| {
            // distance to each edge in samples: l_e * |area2| / |edge e|
            let len = |p0: &Projected, p1: &Projected| (p1.x - p0.x).hypot(p1.y - p0.y);
            let d = [
                l[0] * area2.abs() / len(pb, pc),
                l[1] * area2.abs() / len(pc, pa),
                l[2] * area2.abs() / len(pa, pb),
            ];
            (d.iter().any(|&d| d < half)).then_some(color)
        });
        if perspective {
            l = [l[0] / pa.w, l[1] / pb.w, l[2] / pc.w];
        }
        let sum = l[0] + l[1] + l[2];
        if sum > 0.0 {
            l = l.map(|x| x / sum);
        } else {
            l = [1.0 / 3.0; 3];
        }
        if let Some(color) = wire_hit {
            return color;
        }

        // Lambert, two-sided
        let face_normal = || triangle_normal(&[positions[a], positions[b], positions[c]]);
        let mut n = if smooth {
            add(
                add(
                    [
                        normals[a][0] * l[0],
                        normals[a][1] * l[0],
                        normals[a][2] * l[0],
                    ],
                    [
                        normals[b][0] * l[1],
                        normals[b][1] * l[1],
                        normals[b][2] * l[1],
                    ],
                ),
                [
                    normals[c][0] * l[2],
                    normals[c][1] * l[2],
                    normals[c][2] * l[2],
                ],
            )
        } else {
            face_normal()
        };
        let mut n2 = dot(n, n);
        if (n2.is_nan() || n2 <= 1e-300) && smooth {
            n = face_normal();
            n2 = dot(n, n);
        }
        let lambert = if n2 > 1e-300 && n2.is_finite() {
            (dot(n, light).abs() / n2.sqrt()) as f32
        } else {
            1.0
        };
        let shade = ambient + diffuse * lambert.min(1.0);

        let base = if field.is_some() {
            let ts = [t[a], t[b], t[c]];
            if ts.iter().all(|x| !x.is_nan()) {
                let tv = l[0] as f32 * ts[0] + l[1] as f32 * ts[1] + l[2] as f32 * ts[2];
                colormap.rgb_f32(f64::from(tv))
            } else {
                let col = |x: f32| {
                    if x.is_nan() {
                        nan_color
                    } else {
                        colormap.rgb_f32(f64::from(x))
                    }
                };
                let cs = ts.map(col);
                let w = l.map(|x| x as f32);
                [0, 1, 2].map(|k| w[0] * cs[0][k] + w[1] * cs[1][k] + w[2] * cs[2][k])
            }
        } else {
            surface
        };
        base.map(|x| x * shade)
    };

    let mut out = vec![0u8; width as usize * height as usize * 3];
    let inv = 1.0 / (ss * ss) as f32;
    out.par_chunks_mut(width as usize * 3)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..width as usize {
                let mut acc = [0.0f32; 3];
                for dy in 0..ss {
                    let sy_i = y * ss + dy;
                    for dx in 0..ss {
                        let sx_i = x * ss + dx;
                        let c = sample(ids[sy_i * sw + sx_i], sx_i as f64 + 0.5, sy_i as f64 + 0.5);
                        for k in 0..3 {
                            acc[k] += c[k].clamp(0.0, 1.0);
                        }
                    }
                }
                for k in 0..3 {
                    row[3 * x + k] = to_u8(acc[k] * inv);
                }
            }
        });
    // the buffer has exactly width * height * 3 bytes
    RgbImage::from_raw(width, height, out).unwrap_or_else(|| RgbImage::new(width, height))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square split along a diagonal: every sample inside is covered
    /// exactly once (the shared edge neither cracks nor double-counts).
    #[test]
    fn shared_edges_are_watertight() {
        let n = 16usize;
        for (ax, ay, bx, by) in [
            (0.3, 0.7, 15.2, 14.9),
            (0.0, 0.0, 16.0, 16.0),
            (2.5, 2.5, 12.5, 12.5),
        ] {
            let pts = [[ax, ay], [bx, ay], [bx, by], [ax, by]];
            let p: Vec<Projected> = pts
                .iter()
                .map(|q: &[f64; 2]| Projected {
                    x: q[0],
                    y: q[1],
                    key: 0.0,
                    w: 1.0,
                    ix: (q[0] * ONE as f64).round() as i64,
                    iy: (q[1] * ONE as f64).round() as i64,
                    valid: true,
                })
                .collect();
            // both windings of each half: orientation must not matter
            for pair in [
                [[0u32, 1, 2], [0, 2, 3]],
                [[2, 1, 0], [0, 2, 3]],
                [[2, 1, 0], [3, 2, 0]],
            ] {
                let mut count = vec![0u32; n * n];
                for face in pair {
                    let s = setup(face, &p, n, n).expect("non-degenerate");
                    let mut ids = vec![NONE; n * n];
                    let mut depth = vec![f32::INFINITY; n * n];
                    raster_triangle(&s, 0, 0, n - 1, n, &mut ids, &mut depth);
                    for (c, id) in count.iter_mut().zip(&ids) {
                        if *id != NONE {
                            *c += 1;
                        }
                    }
                }
                for y in 0..n {
                    for x in 0..n {
                        let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                        let inside = cx > ax && cx < bx && cy > ay && cy < by;
                        if inside {
                            assert_eq!(count[y * n + x], 1, "sample ({x}, {y}) of square {pts:?}");
                        }
                        assert!(count[y * n + x] <= 1);
                    }
                }
            }
        }
    }
}
