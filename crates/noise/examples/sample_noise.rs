//! Samples noise on a mesh, prints statistics, writes the samples as PLY
//! vertex scalars (and optionally a PNG picture of the first one).
//!
//! ```text
//! cargo run --release -p mfm-noise --example sample_noise -- [MESH] [options]
//!
//!   MESH               OBJ/OFF/PLY/glTF file (default: a built-in icosphere, 10242 vertices)
//!   --kind KIND        naive | white | matern[:TAU] | matern-normalized:C |
//!                      matern-smooth[:TAU[:P]] | explicit:K[:TAU]
//!                      (default matern:100)
//!   --samples N        number of samples (default 4)
//!   --channels C       channels per sample (default 1)
//!   --seed S           seed (default 0)
//!   --out FILE.ply     output PLY (default noise.ply); scalars noise_S (C = 1) or noise_S_C
//!   --png FILE.png     also render the first sample's first channel
//! ```

use std::process::ExitCode;
use std::time::Instant;

use mfm_geometry::{TriMesh, procedural};
use mfm_noise::{NoiseKind, NoiseSampler};
use mfm_render::{ColorRange, Colormap, RenderOptions, render_mesh, save_png};

struct Args {
    mesh: Option<String>,
    kind: NoiseKind,
    samples: usize,
    channels: usize,
    seed: u64,
    out: String,
    png: Option<String>,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        mesh: None,
        kind: NoiseKind::Matern { tau: 100.0 },
        samples: 4,
        channels: 1,
        seed: 0,
        out: "noise.ply".into(),
        png: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--kind" => a.kind = value("--kind")?.parse().map_err(|e| format!("{e}"))?,
            "--samples" => {
                a.samples = value("--samples")?
                    .parse()
                    .map_err(|e| format!("--samples: {e}"))?
            }
            "--channels" => {
                a.channels = value("--channels")?
                    .parse()
                    .map_err(|e| format!("--channels: {e}"))?
            }
            "--seed" => {
                a.seed = value("--seed")?
                    .parse()
                    .map_err(|e| format!("--seed: {e}"))?
            }
            "--out" => a.out = value("--out")?,
            "--png" => a.png = Some(value("--png")?),
            "-h" | "--help" => {
                return Err("usage: sample_noise [MESH] [--kind KIND] [--samples N] \
                 [--channels C] [--seed S] [--out FILE.ply] [--png FILE.png]"
                    .into());
            }
            s if s.starts_with("--") => return Err(format!("unknown option {s}")),
            s => a.mesh = Some(s.to_owned()),
        }
    }
    Ok(a)
}

fn run() -> Result<(), String> {
    let args = parse()?;
    let mesh: TriMesh = match &args.mesh {
        Some(p) => mfm_meshio::read_mesh(p).map_err(|e| e.to_string())?,
        None => procedural::icosphere(5),
    };
    let name = args.mesh.as_deref().unwrap_or("icosphere(5)");
    println!(
        "mesh {name}: {} vertices, {} faces, area {:.6}",
        mesh.num_vertices(),
        mesh.num_faces(),
        mesh.total_area()
    );

    let t = Instant::now();
    let sampler = NoiseSampler::new(&mesh, args.kind).map_err(|e| e.to_string())?;
    let build = t.elapsed();
    let t = Instant::now();
    let batch = sampler
        .sample(args.samples, args.channels, args.seed)
        .map_err(|e| e.to_string())?;
    let draw = t.elapsed();
    println!(
        "noise {}: Gamma = {:.6e}, tau = {}, amplitude = {:.6e}",
        args.kind,
        sampler.gamma(),
        sampler.tau().map_or("-".into(), |t| format!("{t:.6e}")),
        sampler.amplitude()
    );
    println!(
        "setup {:.2} ms, sampling {} x {} channels {:.2} ms ({:.3} ms per signal)",
        build.as_secs_f64() * 1e3,
        args.samples,
        args.channels,
        draw.as_secs_f64() * 1e3,
        draw.as_secs_f64() * 1e3 / (args.samples * args.channels).max(1) as f64
    );

    // mass-weighted statistics per signal: mean, standard deviation, energy f^T M f
    let mass = sampler.mass();
    let area: f64 = mass.iter().sum();
    let mut scalars: Vec<(String, Vec<f64>)> = Vec::new();
    println!(
        "{:>8} {:>8} {:>12} {:>12} {:>12} {:>12} {:>12}",
        "sample", "channel", "mean", "std", "min", "max", "f^T M f"
    );
    for s in 0..batch.samples() {
        for c in 0..batch.channels() {
            let f = batch.signal(s, c);
            let mean = f.iter().zip(mass).map(|(f, m)| f * m).sum::<f64>() / area;
            let energy: f64 = f.iter().zip(mass).map(|(f, m)| f * f * m).sum();
            let var = energy / area - mean * mean;
            let (lo, hi) = f
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
            println!(
                "{s:>8} {c:>8} {mean:>12.4e} {:>12.4e} {lo:>12.4e} {hi:>12.4e} {energy:>12.4e}",
                var.max(0.0).sqrt()
            );
            let label = if batch.channels() == 1 {
                format!("noise_{s}")
            } else {
                format!("noise_{s}_{c}")
            };
            scalars.push((label, f));
        }
    }

    let refs: Vec<(&str, &[f64])> = scalars
        .iter()
        .map(|(n, v)| (n.as_str(), v.as_slice()))
        .collect();
    mfm_meshio::write_ply(&args.out, &mesh, &refs).map_err(|e| e.to_string())?;
    println!("wrote {} ({} scalar fields)", args.out, refs.len());

    if let (Some(png), Some((_, first))) = (&args.png, scalars.first()) {
        let opts = RenderOptions {
            colormap: Colormap::CoolWarm,
            range: ColorRange::Symmetric,
            colorbar: true,
            ..RenderOptions::with_size(800, 600)
        };
        let img = render_mesh(&mesh, Some(first), &opts).map_err(|e| e.to_string())?;
        save_png(&img, png).map_err(|e| e.to_string())?;
        println!("wrote {png}");
    }
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
