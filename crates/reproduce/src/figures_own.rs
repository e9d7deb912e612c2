//! `cargo xtask reproduce-figures own`: the path a user takes with their
//! own shapes, run on folders of data and written up as a report.
//!
//! For each data folder (a folder of mesh files of one connectivity, or a
//! shared sequence folder holding `frames.npy` and `template.obj`):
//!
//! 1. `mfm dataset import` with every K-th shape held out (`--holdout
//!    every:K`), carried to the default non-uniform reference mesh;
//! 2. `mfm train` with the run preset (or `--config`);
//! 3. `mfm sample` of `--samples` shapes on the reference mesh (PLY files
//!    of the first four);
//! 4. `mfm eval` against the experiment: the generator-free measures
//!    (plausibility, coverage, roughness, novelty, spread, the Gaussian fit, flipped faces,
//!    MMD / COV / 1-NNA), the picture of samples beside their nearest real
//!    shapes and the one of every shape in the training shapes' principal
//!    plane.
//!
//! Without `--data`, the shared sequences `../shared/data/{horse-gallop,
//! crane}` when present, else a built-in sequence (a bending, travelling
//! capsule written as OBJ files) so that a fresh clone runs it too.
//! Drives the release `mfm` binary. Writes `report.md`, `report.json` and
//! each sequence's folders under `--out`.

use crate::flow_steps::{arg, fresh_dir};
use crate::mfm::Mfm;
use crate::reports;
use crate::workspace::{self, in_root};
use anyhow::{Context, Result, bail};
use mfm_data::import::ImportSummary;
use mfm_eval::evaluation::EvalReport;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `reproduce-figures own`.
#[derive(clap::Args)]
pub struct OwnArgs {
    /// Output folder (relative paths are relative to the workspace root).
    #[arg(long, default_value = "out/figures/own")]
    pub out: PathBuf,
    /// Data folders, comma-separated: folders of mesh files, or folders
    /// with frames.npy and template.obj (default: the shared sequences).
    #[arg(long, value_delimiter = ',')]
    pub data: Vec<PathBuf>,
    /// Held-out shapes (`mfm dataset import --holdout`).
    #[arg(long, default_value = "every:8")]
    pub holdout: String,
    /// Turn the shapes to face as the template does (`mfm dataset import
    /// --align`: none, up:x|y|z, rigid).
    #[arg(long, default_value = "none")]
    pub align: String,
    /// Run preset (`mfm train --preset`), unless --config is given.
    #[arg(long, default_value = "cpu-deform")]
    pub preset: String,
    /// A run configuration (`mfm train --config`) instead of the preset.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Training steps (the preset's or configuration's when absent).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Samples on the reference mesh.
    #[arg(long, default_value_t = 32)]
    pub samples: usize,
    /// Seed of the split, the run and the samples.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// One sequence's results.
struct Row {
    name: String,
    import: ImportSummary,
    report: EvalReport,
    train_seconds: f64,
    sample_seconds: f64,
}

/// Runs the command (see the [module docs](self)).
///
/// # Errors
/// When a data folder is neither kind, or a step fails.
pub fn own(mfm: &Mfm, args: &OwnArgs) -> Result<()> {
    let out = in_root(&args.out);
    let mut data = args.data.iter().map(|d| in_root(d)).collect::<Vec<_>>();
    fresh_dir(&out)?;
    if data.is_empty() {
        let shared = workspace::root().join("../shared/data");
        for name in ["horse-gallop", "crane"] {
            if shared.join(name).join("frames.npy").is_file() {
                data.push(shared.join(name));
            }
        }
        if data.is_empty() {
            println!("../shared/data not found: using a built-in sequence (a bending capsule)");
            let dir = out.join("capsule-frames");
            write_builtin_sequence(&dir)?;
            data.push(dir);
        }
    }
    mfm.exe()?;
    let start = Instant::now();
    let mut rows = Vec::new();
    for dir in &data {
        rows.push(run_one(mfm, args, dir, &out)?);
    }
    let report = write_report(args, &rows, start.elapsed().as_secs_f64());
    std::fs::write(out.join("report.md"), &report)
        .with_context(|| format!("cannot write {}", out.join("report.md").display()))?;
    let json: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            serde_json::json!({
                "name": r.name,
                "import": r.import,
                "eval": r.report,
                "train_seconds": r.train_seconds,
                "sample_seconds": r.sample_seconds,
            })
        })
        .collect();
    std::fs::write(
        out.join("report.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    println!("{report}");
    println!("wrote {}", out.join("report.md").display());
    Ok(())
}

/// Import, train, sample and evaluate the data folder `dir`.
fn run_one(mfm: &Mfm, args: &OwnArgs, dir: &Path, out: &Path) -> Result<Row> {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "data".into());
    let base = out.join(&name);
    let data = base.join("data");
    let (seed, holdout) = (args.seed.to_string(), args.holdout.clone());
    let (frames, template) = (dir.join("frames.npy"), dir.join("template.obj"));
    let mut import = vec!["dataset".to_owned(), "import".into()];
    if frames.is_file() && template.is_file() {
        import.extend([
            "--signals".into(),
            arg(&frames),
            "--mesh".into(),
            arg(&template),
        ]);
    } else if dir.is_dir() {
        import.push(arg(dir));
    } else {
        bail!(
            "{}: not a folder of meshes nor of frames.npy + template.obj",
            dir.display()
        );
    }
    import.extend(["--holdout".into(), holdout, "--seed".into(), seed.clone()]);
    import.extend(["--align".into(), args.align.clone()]);
    import.extend(["--out".into(), arg(&data)]);
    mfm.run(&import)?;
    let summary: ImportSummary = reports::read(&data.join(mfm_data::import::SUMMARY))?;

    let run = base.join("run");
    let mut train = vec!["train".to_owned()];
    match &args.config {
        Some(c) => train.extend(["--config".into(), arg(&in_root(c))]),
        None => train.extend(["--preset".into(), args.preset.clone()]),
    }
    train.extend([
        "--dataset".into(),
        arg(&data.join("train")),
        "--out".into(),
        arg(&run),
    ]);
    train.extend(["--seed".into(), seed.clone(), "--quiet".into()]);
    if let Some(s) = args.steps {
        train.extend(["--steps".into(), s.to_string()]);
    }
    let t = Instant::now();
    mfm.run(&train)?;
    let train_seconds = t.elapsed().as_secs_f64();

    let samples = base.join("samples");
    let t = Instant::now();
    mfm.sample(
        &run,
        &data.join("reference/mesh.ply"),
        args.samples,
        args.seed,
        &samples,
        &["--ply", "4"],
    )?;
    let sample_seconds = t.elapsed().as_secs_f64();
    let report: EvalReport = mfm.eval(
        &samples.join("samples.npy"),
        &["--reference", &arg(&data)],
        &base.join("eval.json"),
        Some(&base.join("samples_beside_nearest.png")),
    )?;
    Ok(Row {
        name,
        import: summary,
        report,
        train_seconds,
        sample_seconds,
    })
}

/// The Markdown report.
fn write_report(args: &OwnArgs, rows: &[Row], seconds: f64) -> String {
    let mut s = String::new();
    let recipe = match &args.config {
        Some(c) => format!("`--config {}`", c.display()),
        None => format!("`--preset {}`", args.preset),
    };
    let _ = writeln!(
        s,
        "# Own data: import, train, sample on a finer mesh, evaluate\n\n\
         Holdout `{}`, align `{}`, {recipe}{}, {} samples on the reference mesh (the template \
         with half of it refined twice), seed {}; {:.0} s in all.\n",
        args.holdout,
        args.align,
        args.steps
            .map(|n| format!(", {n} steps"))
            .unwrap_or_default(),
        args.samples,
        args.seed,
        seconds
    );
    let _ = writeln!(
        s,
        "| data | train / held out | template V | reference V | plausibility | coverage | \
         roughness | flipped (median / max; the data's max) | novelty | spread | Gaussian fit: \
         plausibility / coverage / spread | MMD | COV | 1-NNA | train s | sample s |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        let Some(q) = &r.report.shape_quality else {
            let _ = writeln!(s, "| {} | (no shape measures: not positions) |", r.name);
            continue;
        };
        let _ = writeln!(
            s,
            "| {} | {} / {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.1}% / {:.1}%; {} | {:.2} | \
             {} | {} | {:.4} | {:.2} | {:.2} | {:.0} | {:.0} |",
            r.name,
            r.import.train,
            r.import.held_out,
            r.import.template_size[0],
            r.import.reference_size.map_or(0, |x| x[0]),
            q.plausibility,
            q.coverage,
            q.roughness,
            100.0 * q.flipped.median,
            100.0 * q.flipped.max,
            q.held_out_flipped
                .map_or("-".to_owned(), |d| format!("{:.1}%", 100.0 * d.max)),
            q.novelty,
            q.spread.map_or("-".to_owned(), |x| format!("{x:.2}")),
            q.gaussian.map_or("-".to_owned(), |g| format!(
                "{:.2} / {:.2} / {:.2}",
                g.plausibility, g.coverage, g.spread
            )),
            q.metrics.mmd,
            q.metrics.cov,
            q.metrics.one_nna,
            r.train_seconds,
            r.sample_seconds
        );
    }
    let _ = writeln!(
        s,
        "\nTargets (issue 42): plausibility <= 1.5, coverage <= 1.5, roughness in [0.5, 2], \
         flipped faces <= 1% (the data's own: each held-out shape against its nearest \
         training shape), novelty >= 0.3. Distances are mass-weighted RMS after centring, \
         over the template's diagonal; plausibility, coverage and novelty are ratios to the \
         data's floor (a held-out shape's distance to the nearest training shape). Spread: \
         a sample's distance to the training shapes' mean over a real shape's (medians; below \
         1: samples pulled toward the mean shape, blends of shapes). Gaussian fit: the same \
         measures for as many draws from the training shapes' mean and covariance, what a \
         model of the data's first two moments reaches; samples should do better.\n"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "- {}: `{0}/data/preview.png` (training shapes), `{0}/samples_beside_nearest.png` \
             (samples on the reference mesh beside their nearest real shapes), \
             `{0}/samples_beside_nearest_plane.png` (every shape in the training shapes' \
             principal plane), `{0}/samples/sample_00N.ply`",
            r.name
        );
        for w in &r.import.warnings {
            let _ = writeln!(s, "  - import warning: {w}");
        }
    }
    s
}

/// A travelling, bending capsule as `dir/frame_K.obj` (40 frames).
fn write_builtin_sequence(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)?;
    let rest = mfm_geometry::procedural::capsule(0.3, 0.8, 16, 32)?;
    for k in 0..40 {
        let bend = 0.04 * k as f64;
        let moved: Vec<[f64; 3]> = rest
            .positions()
            .iter()
            .map(|p| {
                let a = bend * p[1];
                [
                    p[0] * a.cos() - p[1] * a.sin() + 0.05 * k as f64,
                    p[0] * a.sin() + p[1] * a.cos(),
                    p[2],
                ]
            })
            .collect();
        mfm_meshio::write_obj(
            dir.join(format!("frame_{k}.obj")),
            &rest.with_positions(moved)?,
        )?;
    }
    Ok(())
}
