//! `cargo xtask bench import`: how fast `mfm dataset import` streams a
//! large collection of shapes, and how much memory it holds while doing so.
//!
//! Writes `--shapes` meshes of one connectivity (an icosphere of about
//! `--vertices` vertices, each shape a different smooth deformation of it)
//! as binary PLY or OBJ files into a folder, and a NumPy array of the same
//! shapes, then times `mfm dataset import` on the folder and on the array
//! (`--signals`), 10% held out (so the reference set is carried too),
//! with the peak resident memory of the import process
//! (`wait4`'s `ru_maxrss`) next to the size of the `signals.npy` it wrote.

use anyhow::{Result, bail};
use mfm_reproduce::flow_steps::arg;
use mfm_reproduce::mfm::{Mfm, run_with_peak_memory};
use mfm_reproduce::pyenv::PyEnv;
use std::io::Write as _;
use std::path::Path;
use std::time::Instant;

/// Arguments of `bench import`.
#[derive(clap::Args)]
pub struct ImportBenchArgs {
    /// Number of shapes.
    #[arg(long, default_value_t = 2000)]
    pub shapes: usize,
    /// Vertices per shape (rounded to an icosphere: 10242 for 10,000).
    #[arg(long, default_value_t = 10_000)]
    pub vertices: usize,
    /// File format of the folder: ply (binary) or obj.
    #[arg(long, default_value = "ply")]
    pub format: String,
    /// Keep the inputs in target/bench-import (they are written again
    /// otherwise).
    #[arg(long)]
    pub keep: bool,
}

/// Runs the benchmark (see the [module docs](self)).
pub fn import(env: &PyEnv, args: &ImportBenchArgs) -> Result<()> {
    if !matches!(args.format.as_str(), "ply" | "obj") {
        bail!("--format {}: expected ply or obj", args.format);
    }
    let dir = mfm_reproduce::workspace::target_dir().join("bench-import");
    let inputs = dir.join(format!(
        "shapes-{}-{}-{}",
        args.shapes, args.vertices, args.format
    ));
    let level = (0..9u32)
        .find(|&l| 10 * 4usize.pow(l) + 2 >= args.vertices)
        .unwrap_or(8);
    let rest = mfm_geometry::procedural::icosphere(level);
    let v = rest.num_vertices();
    let array = inputs.join("shapes.npy");
    let folder = inputs.join("meshes");
    if !array.is_file() {
        if inputs.exists() {
            std::fs::remove_dir_all(&inputs)?;
        }
        std::fs::create_dir_all(&folder)?;
        write_inputs(&rest, args, &folder, &array)?;
    }
    let mfm = Mfm::build(env);
    mfm.exe()?;
    let output_bytes = 4 * args.shapes as u64 * v as u64 * 3;
    println!(
        "{} shapes x {v} vertices ({:.2} GB of float32 positions); idle machine assumed",
        args.shapes,
        output_bytes as f64 / 1e9
    );
    println!("| input | seconds | shapes/s | peak memory | peak / output |\n|---|---|---|---|---|");
    let sets = [
        (
            format!("folder of {} files", args.format),
            vec![arg(&folder)],
        ),
        (
            "one .npy array (--signals)".to_owned(),
            vec![
                "--signals".into(),
                arg(&array),
                "--mesh".into(),
                arg(&inputs.join(format!("rest.{}", args.format))),
            ],
        ),
    ];
    for (what, input) in sets {
        let out = dir.join("out");
        if out.exists() {
            std::fs::remove_dir_all(&out)?;
        }
        let mut cmd = mfm.command(&["dataset", "import"])?;
        cmd.args(&input).args(["--out", &arg(&out)]);
        let t = Instant::now();
        cmd.stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        let peak = run_with_peak_memory(&mut cmd)?;
        let s = t.elapsed().as_secs_f64();
        println!(
            "| {what} | {s:.1} | {:.0} | {:.2} GB | {:.2}x |",
            args.shapes as f64 / s,
            peak as f64 / 1e9,
            peak as f64 / output_bytes as f64
        );
        std::fs::remove_dir_all(&out)?;
    }
    if !args.keep {
        std::fs::remove_dir_all(&inputs)?;
    }
    Ok(())
}

/// Writes the shapes as files and as one array, and the rest shape.
fn write_inputs(
    rest: &mfm_geometry::TriMesh,
    args: &ImportBenchArgs,
    folder: &Path,
    array: &Path,
) -> Result<()> {
    let v = rest.num_vertices();
    let parent = array.parent().unwrap_or(Path::new("."));
    let rest_file = parent.join(format!("rest.{}", args.format));
    write_mesh(&rest_file, rest, &args.format)?;
    let mut npy =
        mfm_files::npy::NpyStream::<f32>::create(array, &[args.shapes as u64, v as u64, 3])?;
    eprint!("xtask: writing {} input shapes", args.shapes);
    for k in 0..args.shapes {
        let a = 0.3 * (k as f64 * 0.37).sin();
        let b = 0.2 * (k as f64 * 0.11).cos();
        let moved: Vec<[f64; 3]> = rest
            .positions()
            .iter()
            .map(|p| {
                [
                    p[0] * (1.0 + a * p[1]),
                    p[1] + b * p[0] * p[0],
                    p[2] * (1.0 - a * p[1]),
                ]
            })
            .collect();
        let shape = rest.with_positions(moved)?;
        write_mesh(
            &folder.join(format!("shape_{k}.{}", args.format)),
            &shape,
            &args.format,
        )?;
        let values: Vec<f32> = shape
            .positions()
            .iter()
            .flat_map(|p| p.map(|x| x as f32))
            .collect();
        npy.append(&values)?;
        if k % 500 == 0 {
            eprint!(".");
            let _ = std::io::stderr().flush();
        }
    }
    eprintln!();
    npy.finish()?;
    Ok(())
}

fn write_mesh(path: &Path, mesh: &mfm_geometry::TriMesh, format: &str) -> Result<()> {
    if format == "obj" {
        mfm_meshio::write_obj(path, mesh)?;
    } else {
        mfm_meshio::write_ply(path, mesh, &[])?;
    }
    Ok(())
}
