//! Times the intrinsic operators on mesh files and prints JSON.
//!
//! ```text
//! cargo run --release -p mfm-geometry --example operator_timings -- \
//!     [--subdiv 0,2,3,4] [--runs 9] MESH [MESH ...]
//! ```
//!
//! Each mesh is optionally refined by 1-to-4 midpoint subdivision
//! (`mfm_geometry::subdivide::midpoint`, the same scheme as `igl.upsample`),
//! once per requested level. For every (mesh, level) the median wall time of
//! `--runs` runs (after one warm-up run) is printed per operator, in
//! milliseconds, with the fastest run (`min_ms`, less sensitive to other load
//! on the machine). `xtask/python/bench_operators.py` prints the same for libigl.
//! Meshes are read with `mfm_meshio::read_mesh` (OBJ, OFF, PLY, glTF).

use std::error::Error;
use std::path::Path;
use std::time::Instant;

use mfm_geometry::operators::{self, Operators};
use mfm_geometry::{TriMesh, subdivide};

type Res<T> = Result<T, Box<dyn Error>>;

fn main() -> Res<()> {
    let mut levels = vec![0u32];
    let mut runs = 9usize;
    let mut paths = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--subdiv" => {
                let v = args
                    .next()
                    .ok_or("--subdiv expects a level or a list like 0,2,3")?;
                levels = v
                    .split(',')
                    .map(|s| {
                        s.trim()
                            .parse::<u32>()
                            .map_err(|e| format!("--subdiv {v:?}: {e}"))
                    })
                    .collect::<Result<_, _>>()?;
            }
            "--runs" => {
                let v = args.next().ok_or("--runs expects a count")?;
                runs = v.parse().map_err(|e| format!("--runs {v:?}: {e}"))?;
                runs = runs.max(1);
            }
            "-h" | "--help" => {
                println!("usage: operator_timings [--subdiv 0,2,3,4] [--runs 9] MESH...");
                return Ok(());
            }
            _ => paths.push(a),
        }
    }
    if paths.is_empty() {
        return Err("expected at least one mesh path".into());
    }
    levels.sort_unstable();
    println!("{{");
    println!("  \"tool\": \"mfm-geometry operator_timings\",");
    println!("  \"threads\": {},", rayon::current_num_threads());
    println!("  \"runs\": {runs},");
    println!("  \"results\": [");
    let mut first = true;
    for path in &paths {
        let mut mesh = mfm_meshio::read_mesh(path).map_err(|e| format!("{path}: {e}"))?;
        let mut level = 0;
        for &target in &levels {
            while level < target {
                mesh = subdivide::midpoint(&mesh)?;
                level += 1;
            }
            if !first {
                println!(",");
            }
            first = false;
            print!("{}", time_mesh(path, level, &mesh, runs)?);
        }
    }
    println!("\n  ]");
    println!("}}");
    Ok(())
}

/// `(median, min)` wall time in milliseconds of `runs` calls after a warm-up.
fn time_ms(runs: usize, mut f: impl FnMut()) -> (f64, f64) {
    f();
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[0])
}

fn time_mesh(path: &str, level: u32, mesh: &TriMesh, runs: usize) -> Res<String> {
    Operators::new(mesh)?;
    let name = Path::new(path)
        .file_name()
        .map_or(path.into(), |n| n.to_string_lossy());
    let timings = [
        (
            "face_areas",
            time_ms(runs, || drop(operators::face_areas(mesh))),
        ),
        (
            "lumped_mass",
            time_ms(runs, || drop(operators::lumped_mass(mesh))),
        ),
        (
            "cotangent_laplacian",
            time_ms(runs, || drop(operators::cotangent_laplacian(mesh))),
        ),
        (
            "intrinsic_gradient",
            time_ms(runs, || drop(operators::intrinsic_gradient(mesh))),
        ),
        (
            "laplacian_and_mass",
            time_ms(runs, || {
                drop(operators::cotangent_laplacian(mesh));
                drop(operators::lumped_mass(mesh));
            }),
        ),
        (
            "operators_new",
            time_ms(runs, || drop(Operators::new(mesh))),
        ),
    ];
    let field = |pick: fn(&(f64, f64)) -> f64| {
        timings
            .iter()
            .map(|(k, t)| format!("\"{k}\": {:.3}", pick(t)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    Ok(format!(
        "    {{\"mesh\": \"{name}\", \"subdiv\": {level}, \"vertices\": {}, \"faces\": {}, \
\"median_ms\": {{{}}}, \"min_ms\": {{{}}}}}",
        mesh.num_vertices(),
        mesh.num_faces(),
        field(|t| t.0),
        field(|t| t.1),
    ))
}
