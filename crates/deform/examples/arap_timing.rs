//! ARAP timings and automatic handles on a real mesh and its refinements.
//!
//! ```text
//! cargo run --release -p mfm-deform --example arap_timing -- [MESH] [HANDLES] [LEVELS] [SAMPLES]
//! ```
//!
//! `MESH` defaults to `../shared/meshes/elephant.obj`, `HANDLES` (moving) to
//! 5, `LEVELS` (midpoint refinements, each 4x the faces) to 2, `SAMPLES`
//! (random deformations timed per level) to 3. The mesh is normalized to a
//! unit bounding-box diagonal; the handles are placed once on it and reused
//! on a decimated copy (3000 faces, the training resolution) and on every
//! level. For each level it prints the vertex count, the time of
//! `Arap::new` (cotangent Laplacian + regions + Cholesky factorization of
//! the free block, with the Laplacian alone timed separately), and for each
//! sample the iterations to the default tolerance, the time per iteration
//! (total time over iterations + 1, the initial guess counted as one), the
//! total deformation time and the energy of the initial guess and of the
//! result. The first sample of each mesh also pays for factoring the
//! rotation smoother.

use std::time::Instant;

use mfm_deform::{Arap, DeformSpace, HandleSet, normalize_rest};
use mfm_geometry::{operators, subdivide};
use mfm_processing::decimate;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().cloned().unwrap_or_else(|| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/meshes/elephant.obj"
        )
        .to_string()
    });
    let count: usize = args.get(1).map_or(Ok(5), |s| s.parse())?;
    let levels: usize = args.get(2).map_or(Ok(2), |s| s.parse())?;
    let samples: usize = args.get(3).map_or(Ok(3), |s| s.parse())?;
    println!("threads: {}", rayon::current_num_threads());

    let (rest, _, _) = normalize_rest(&mfm_meshio::read_mesh(&path)?)?;
    let handles = HandleSet::auto(&rest, count, mfm_deform::DEFAULT_RADIUS_FRACTION)?;
    println!(
        "{path}: {} vertices, {} faces",
        rest.num_vertices(),
        rest.num_faces()
    );
    for (i, h) in handles.iter().enumerate() {
        println!(
            "  {:9} center [{:+.3}, {:+.3}, {:+.3}] radius {:.3}: {} vertices",
            handles.name(i),
            h.center[0],
            h.center[1],
            h.center[2],
            h.radius,
            h.vertices(&rest).len()
        );
    }
    let space = DeformSpace::new(&rest, handles);

    let coarse = decimate::decimate(&rest, 3000, None)?.mesh;
    let mut meshes = vec![
        ("decimated".to_string(), coarse),
        ("original".to_string(), rest),
    ];
    for level in 1..=levels {
        let finer = subdivide::midpoint(&meshes[meshes.len() - 1].1)?;
        meshes.push((format!("refined x{}", 4usize.pow(level as u32)), finer));
    }
    for (name, mesh) in &meshes {
        let t = Instant::now();
        let l = operators::cotangent_laplacian(mesh);
        let t_laplacian = t.elapsed().as_secs_f64();
        drop(l);
        let t = Instant::now();
        let arap = Arap::new(mesh, &space.handles)?;
        let t_new = t.elapsed().as_secs_f64();
        println!(
            "{name}: V = {}, free = {}, Arap::new {:.3} s (of which Laplacian {:.3} s)",
            mesh.num_vertices(),
            arap.num_free(),
            t_new,
            t_laplacian
        );
        for s in 0..samples {
            let params = space.sample_params(0, s);
            let t = Instant::now();
            let out = arap.deform(&params, &space.arap)?;
            let dt = t.elapsed().as_secs_f64();
            let e0 = out.energies[0];
            let e1 = out.energies[out.energies.len() - 1];
            println!(
                "  sample {s}: {} iterations, {:.1} ms/iteration, {:.3} s total, energy {:.4e} -> {:.4e}",
                out.iterations,
                1e3 * dt / (out.iterations + 1) as f64,
                dt,
                e0,
                e1
            );
        }
    }
    Ok(())
}
