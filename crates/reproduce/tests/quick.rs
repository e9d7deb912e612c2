//! The quick variants of the reproductions, run as their commands are:
//! `reproduce-figures spectral --quick` (no `mfm` binary needed, about 5 s)
//! and a small `reproduce-figures gmm` and `reproduce-figures deform
//! --ablation-only` through an `mfm` binary with its network (skipped, with
//! the reason printed, when there is none; `cargo xtask test` builds one).
//! Each checks the files written and that the numbers are what the method
//! says, not only that the command ran.

#![allow(clippy::unwrap_used)]

use clap::Parser;
use mfm_reproduce::mfm::Mfm;
use mfm_reproduce::reports::{self, EvalReport};
use mfm_reproduce::{Command, FiguresCmd};
use serde_json::Value;
use std::path::{Path, PathBuf};

#[derive(Parser)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The command `mfm-reproduce ARGS` would run.
fn parse(args: &[&str]) -> Command {
    Cli::try_parse_from(std::iter::once("mfm-reproduce").chain(args.iter().copied()))
        .unwrap()
        .command
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Asserts that `dir/name` is a file of more than 100 bytes.
fn written(dir: &Path, name: &str) {
    let len = std::fs::metadata(dir.join(name))
        .map(|m| m.len())
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(len > 100, "{name}: {len} bytes");
}

/// An `mfm` binary with its network: `$MFM_BIN`, else the newest of the
/// workspace's `debug/mfm` (what `cargo test --workspace` builds) and
/// `release/mfm` (what the reproductions build), or why there is none.
fn mfm_binary() -> Result<PathBuf, String> {
    let exe = match std::env::var_os("MFM_BIN") {
        Some(p) => PathBuf::from(p),
        None => {
            let target = mfm_reproduce::workspace::target_dir();
            let newest = ["debug/mfm", "release/mfm"]
                .iter()
                .map(|p| target.join(p))
                .filter_map(|p| Some((std::fs::metadata(&p).ok()?.modified().ok()?, p)))
                .max();
            match newest {
                Some((_, p)) => p,
                None => {
                    return Err(format!(
                        "no mfm binary in {} (build one: cargo build -p mfm-cli, or set MFM_BIN)",
                        target.display()
                    ));
                }
            }
        }
    };
    let trains = std::process::Command::new(&exe)
        .args(["train", "--help"])
        .output()
        .is_ok_and(|o| o.status.success());
    if trains {
        Ok(exe)
    } else {
        Err(format!(
            "{} cannot train (built without its network feature?)",
            exe.display()
        ))
    }
}

#[test]
fn spectral_quick_writes_every_figure_and_matches_the_theory() {
    let dir = tempfile::tempdir().unwrap();
    // the blob the command falls back to without the shared bunny, given
    // as a file so that the run is the same with and without ../shared
    let mesh = dir.path().join("blob.obj");
    mfm_meshio::write_obj(&mesh, &mfm_geometry::procedural::blob(4).unwrap()).unwrap();
    let out = dir.path().join("spectral");
    let command = parse(&[
        "reproduce-figures",
        "spectral",
        "--quick",
        "--mesh",
        path(&mesh),
        "--out",
        path(&out),
    ]);
    mfm_reproduce::run(command).unwrap();

    for f in [
        "per_frequency_statistics.png",
        "spectrum_resolutions.png",
        "spectrum.png",
        "fixed_vs_normalized_tau.png",
        "nonuniform_triangulation.png",
        "per_frequency.csv",
        "timings.csv",
        "numbers.json",
        "README.md",
    ] {
        written(&out, f);
    }
    let json: Value = reports::read(&out.join("numbers.json")).unwrap();
    assert_eq!(json["surface"], "blob.obj");
    // the quick configuration: c_2, c_50, c_200 from 1000 samples
    assert_eq!(
        json["config"]["frequencies"],
        serde_json::json!([2, 50, 200])
    );
    assert_eq!(json["config"]["samples"], 1000);
    // Matérn variances follow 1/(lambda + tau)^2 on all three resolutions,
    // and the kept coefficients' spread is the theory's
    let stats = json["statistics"].as_array().unwrap();
    let materns: Vec<&Value> = stats.iter().filter(|s| s["kind"] == "matern:100").collect();
    assert_eq!(materns.len(), 3);
    for s in &materns {
        assert_eq!(s["samples"], 1000);
        let e = s["max_relative_error_first_64"].as_f64().unwrap();
        assert!(
            e < 0.25,
            "{}: first 64 |Var/theory - 1| up to {e}",
            s["mesh"]
        );
        for k in s["kept"].as_array().unwrap() {
            let r = k["std"].as_f64().unwrap() / k["theory_std"].as_f64().unwrap();
            assert!((r - 1.0).abs() < 0.1, "{}: {k}", s["mesh"]);
        }
    }
    // energies: white is V, naive the area (1, the surface is scaled to it)
    for s in json["energies"].as_array().unwrap() {
        let e = s["mean"].as_f64().unwrap();
        match s["kind"].as_str().unwrap() {
            "white" => {
                let v = s["vertices"].as_f64().unwrap();
                assert!((e / v - 1.0).abs() < 0.05, "white energy {e} vs V = {v}");
            }
            "naive" => assert!((e - 1.0).abs() < 0.05, "naive energy {e}"),
            _ => {}
        }
    }
    // normalized tau: the same noise at every scale; fixed tau: not
    for row in json["scale"].as_array().unwrap() {
        let (d, scale) = (
            row["relative_difference"].as_f64().unwrap(),
            row["scale"].as_f64().unwrap(),
        );
        if row["kind"]
            .as_str()
            .unwrap()
            .starts_with("matern-normalized")
        {
            assert!(d < 1e-9, "normalized differs by {d} at scale {scale}");
        } else if scale != 1.0 {
            assert!(d > 0.1, "fixed tau differs only by {d} at scale {scale}");
        }
    }
    // a refined half: naive noise's per-frequency spread shrinks, Matérn's
    // stays
    let agreement = json["nonuniform"]["agreement"].as_array().unwrap();
    assert_eq!(agreement.len(), 4);
    for a in agreement {
        let r = a["median_std_ratio"].as_f64().unwrap();
        if a["kind"] == "naive" {
            assert!(r < 0.9, "naive median std ratio {r}");
        } else {
            assert!((r - 1.0).abs() < 0.1, "matern median std ratio {r}");
        }
    }
}

#[test]
fn gmm_small_compares_noise_kinds_through_mfm() {
    let exe = match mfm_binary() {
        Ok(exe) => exe,
        Err(why) => {
            println!("skipping the GMM reproduction: {why}");
            return;
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gmm");
    let Command::ReproduceFigures(FiguresCmd::Gmm(args)) = parse(&[
        "reproduce-figures",
        "gmm",
        "--mesh",
        "builtin:blob",
        "--kinds",
        "matern:100",
        "--steps",
        "10",
        "--n",
        "24",
        "--reference",
        "4",
        "--out",
        path(&out),
    ]) else {
        unreachable!("parsed as gmm")
    };
    mfm_reproduce::figures_gmm::gmm(&Mfm::at(exe), &args).unwrap();

    for f in [
        "table.md",
        "means_matern_100.png",
        "run_matern_100/model.safetensors",
    ] {
        written(&out, f);
    }
    let report: EvalReport = reports::read(&out.join("metrics_matern_100.json")).unwrap();
    assert_eq!(report.metrics.num_generated, 4);
    assert_eq!(report.metrics.num_reference, 4);
    assert!((0.0..=1.0).contains(&report.metrics.cov));
    assert!(report.metrics.mmd > 0.0 && report.metrics.mmd.is_finite());
    let quality = report.quality.expect("a GMM evaluation has a bump fit");
    // the reference signals are the generator's own: their fit is near
    // exact, the floor the samples are judged against
    assert!(quality.reference.residual.median < 0.1, "{quality:?}");
    assert!(quality.generated.residual.median.is_finite());
    // the table's row is the report's numbers
    let csv = std::fs::read_to_string(out.join("table.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "{csv}");
    let row: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(row[0], "matern:100");
    let residual: f64 = row[1].parse().unwrap();
    assert_eq!(residual, quality.generated.residual.median);
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(table.contains("| reference set (the floor) |"), "{table}");
    let json: Value = reports::read(&out.join("table.json")).unwrap();
    assert_eq!(json["rows"][0]["noise"], "matern:100");
    assert_eq!(
        json["rows"][0]["metrics"]["mmd"].as_f64(),
        Some(report.metrics.mmd)
    );
}

#[test]
fn deform_ablation_counts_parameters_and_projects_samples() {
    let exe = match mfm_binary() {
        Ok(exe) => exe,
        Err(why) => {
            println!("skipping the deformation reproduction: {why}");
            return;
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("deform");
    let Command::ReproduceFigures(FiguresCmd::Deform(args)) = parse(&[
        "reproduce-figures",
        "deform",
        "--mesh",
        "builtin:capsule",
        "--kinds",
        "matern:100",
        "--steps",
        "10",
        "--n",
        "12",
        "--reference",
        "4",
        "--coarse-faces",
        "400",
        "--ablation-only",
        "--out",
        path(&out),
    ]) else {
        unreachable!("parsed as deform")
    };
    mfm_reproduce::figures_deform::deform(&Mfm::at(exe), &args).unwrap();

    written(&out, "table.md");
    let json: Value = reports::read(&out.join("table.json")).unwrap();
    let row = &json["ablation"][0];
    assert_eq!(row["noise"], "matern:100");
    // the cpu-deform network: tens of thousands of weights, counted from
    // the safetensors header
    let params = row["parameters"].as_u64().unwrap();
    assert!(
        (10_000..10_000_000).contains(&params),
        "{params} parameters"
    );
    let shapes = &row["metrics"];
    let mse = shapes["projection_mse"].as_f64().unwrap();
    let floor = shapes["reference_projection_mse"].as_f64().unwrap();
    assert!(mse.is_finite() && mse >= 0.0 && floor >= 0.0, "{shapes}");
    let nearest = &json["nearest_training_distance"];
    assert!(nearest["generated"].as_f64().unwrap() > 0.0);
    assert!(nearest["held_out"].as_f64().unwrap() > 0.0);
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(table.contains(&format!("| {params} |")), "{table}");
}
