//! Sample pictures from the software renderer, for a human to look at, and
//! its timing on a large mesh.
//!
//! ```text
//! cargo run --release -p mfm-geometry --example render_demo [OUTDIR]
//! ```
//! writes to `OUTDIR` (default `/tmp/render_demo`):
//! - `icosphere_z.png`: a shaded icosphere colored by `z`, with a colorbar;
//! - `grid.png`: a 2x2 grid with captions, a title and a shared colorbar;
//! - `small.png`: 192x128, a signed field on a diverging map, `+z` up;
//! - `wireframe.png`: a coarse sphere, flat shading, wireframe, perspective;
//!
//! and prints how long a 900k-face torus takes at 1024x1024.

use std::path::PathBuf;
use std::time::Instant;

use mfm_geometry::{TriMesh, procedural, test_support};
use mfm_render::{
    ColorRange, Colormap, GridOptions, Panel, Projection, RenderOptions, Shading, UpAxis, View,
    Wireframe, render_grid, render_mesh, save_png,
};

fn coordinate(mesh: &TriMesh, k: usize) -> Vec<f64> {
    mesh.positions().iter().map(|p| p[k]).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/tmp/render_demo"));
    std::fs::create_dir_all(&out)?;

    let sphere = procedural::icosphere(4);
    let z = coordinate(&sphere, 2);
    let opts = RenderOptions {
        width: 640,
        height: 512,
        colorbar: true,
        ..RenderOptions::default()
    };
    save_png(
        &render_mesh(&sphere, Some(&z), &opts)?,
        out.join("icosphere_z.png"),
    )?;

    // a small picture: text scale 1, diverging map on a signed field
    let small = RenderOptions {
        width: 192,
        height: 128,
        colorbar: true,
        colormap: Colormap::CoolWarm,
        range: ColorRange::Symmetric,
        view: View {
            up: UpAxis::Z,
            ..View::default()
        },
        ..RenderOptions::default()
    };
    let xz: Vec<f64> = sphere
        .positions()
        .iter()
        .map(|p| 1e-3 * p[0] * p[2])
        .collect();
    save_png(
        &render_mesh(&sphere, Some(&xz), &small)?,
        out.join("small.png"),
    )?;

    let torus = procedural::torus(1.0, 0.35, 96, 48)?;
    let torus_y = coordinate(&torus, 1);
    let sphere_x = coordinate(&sphere, 0);
    let bunny_path = test_support::workspace_root().join("../shared/meshes/bunny.off");
    let bunny = mfm_meshio::read_mesh(&bunny_path).ok();
    let mut panels = vec![
        Panel::new(&sphere, Some(&z), "sphere, z"),
        Panel::new(&sphere, Some(&sphere_x), "sphere, x"),
        Panel::new(&torus, Some(&torus_y), "torus, y"),
    ];
    let bunny_y;
    if let Some(b) = &bunny {
        let (lo, hi) = b.bounding_box();
        let c = 0.5 * (lo[1] + hi[1]);
        let h = 0.5 * (hi[1] - lo[1]);
        bunny_y = b
            .positions()
            .iter()
            .map(|p| (p[1] - c) / h)
            .collect::<Vec<_>>();
        panels.push(Panel::new(b, Some(&bunny_y), "bunny, height"));
    } else {
        panels.push(Panel::new(&torus, None, "torus, no scalars"));
    }
    let grid_opts = GridOptions {
        panel: RenderOptions {
            width: 320,
            height: 320,
            colormap: Colormap::CoolWarm,
            range: ColorRange::Symmetric,
            colorbar: true,
            ..RenderOptions::default()
        },
        title: Some("mfm renderer: 2x2 grid, shared scale".into()),
        ..GridOptions::default()
    };
    save_png(&render_grid(&panels, 2, &grid_opts)?, out.join("grid.png"))?;

    let coarse = procedural::icosphere(1);
    let wire = RenderOptions {
        width: 400,
        height: 400,
        shading: Shading::Flat,
        wireframe: Some(Wireframe::default()),
        view: View {
            projection: Projection::Perspective { fov_deg: 40.0 },
            ..View::default()
        },
        ..RenderOptions::default()
    };
    save_png(
        &render_mesh(&coarse, None, &wire)?,
        out.join("wireframe.png"),
    )?;

    // timing: a 900k-face torus at 1024x1024, 2x2 supersampling
    let big = procedural::torus(1.0, 0.35, 1000, 450)?;
    let big_z = coordinate(&big, 2);
    let big_opts = RenderOptions {
        width: 1024,
        height: 1024,
        colorbar: true,
        ..RenderOptions::default()
    };
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        let img = render_mesh(&big, Some(&big_z), &big_opts)?;
        best = best.min(t.elapsed().as_secs_f64());
        std::hint::black_box(img);
    }
    println!(
        "{} faces at 1024x1024 (supersample 2): best of 3 = {:.0} ms on {} threads",
        big.num_faces(),
        best * 1e3,
        rayon::current_num_threads()
    );
    println!("wrote {}", out.display());
    Ok(())
}
