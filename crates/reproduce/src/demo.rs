//! `cargo xtask demo`: the main job on a built-in default.
//!
//! Builds the `mfm` binary and runs the paper's GMM experiment at demo
//! scale on the built-in blob: a dataset of Gaussian-bump signals on a
//! uniform triangulation and a reference set on a non-uniform one (half of
//! the surface refined twice). First the pretrained model shipped in
//! `fixtures/pretrained/gmm-blob/` (`cargo xtask pretrain gmm`) samples the
//! non-uniform mesh (seconds: what the method gives after longer training);
//! then the demo trains its own short run with Matérn noise in the canonical
//! frame (2000 steps of the pretrained model's recipe: a few minutes on two
//! cores) and
//! samples it the same way. Both are judged by the sample quality (bump fit
//! against the data's floor, training signals beside samples on one colour
//! scale) next to the distribution metrics, side by side; plus Matérn vs
//! naive noise and the noise spectrum on the two triangulations. Last, the
//! shipped shape model (`fixtures/pretrained/elephant/`, `cargo xtask
//! pretrain elephant`) samples elephant poses on its training mesh and the
//! same poses on a 768k-face refinement, when `../shared/meshes` is there
//! (the section says why it was skipped otherwise). Writes a Markdown report
//! linking everything.

use crate::flow_steps::{Quality, quartiles};
use crate::mfm::Mfm;
use crate::pretrain::{ELEPHANT_DIR, ELEPHANT_MESH, PRETRAINED_DIR};
use crate::reports::{self, EvalReport, SampleTiming};
use crate::workspace::{self, in_root};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

/// The built-in training mesh (the GMM experiment's default surface).
const DEMO_MESH: &str = "builtin:blob";

/// What the report calls the training recipe.
const DEMO_PRESET: &str = "pretrained model's";

/// Training steps of the demo.
const DEMO_STEPS: u64 = 2000;

/// The demo's run configuration: the pretrained model's recipe
/// ([`crate::pretrain::gmm_config`]: PoissonNet W32 K3 nl3; canonical
/// frame, sigma 3, centred noise and targets, 20 midpoint steps; the
/// official loss; sampling with the weight average; a 250-step warm-up to
/// 4e-3 and a cosine decay to the last step; logit-normal path times)
/// trained 2000 steps instead of 5000: a few minutes on two cores.
/// docs/BENCHMARKS.md ("Time to quality") has the whole curve and the
/// controlled runs that chose the schedule.
pub fn demo_config() -> String {
    crate::pretrain::gmm_config(
        "mfm demo run: `mfm train --config run.toml` (every other field has its default)",
        DEMO_STEPS,
        None,
    )
}

/// `mfm sample` of 64 samples (seed 7) of `run` on `mesh` into `samples`,
/// then `mfm eval` against `reference` into `metrics` with the pictures at
/// `png`; returns both commands' outputs.
fn sample_and_eval(
    mfm: &Mfm,
    run: &Path,
    mesh: &Path,
    reference: &Path,
    samples: &Path,
    metrics: &Path,
    png: &Path,
) -> Result<(String, String)> {
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let sampled = mfm.output(&[
        "sample",
        "--run",
        &s(run),
        "--mesh",
        &s(mesh),
        "--n",
        "64",
        "--seed",
        "7",
        "--out",
        &s(samples),
    ])?;
    let evaluated = mfm.output(&[
        "eval",
        "--samples",
        &s(&samples.join("samples.npy")),
        "--reference",
        &s(reference),
        "--out",
        &s(metrics),
        "--png",
        &s(png),
    ])?;
    Ok((sampled, evaluated))
}

/// Runs the demo, writing everything under `out` (relative to the
/// workspace root); `mfm`'s command lines are not echoed.
///
/// # Errors
/// When a step fails.
pub fn run(mfm: &Mfm, out: &Path) -> Result<()> {
    let out = in_root(out);
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    mfm.exe()?;
    // The clock starts after the build: it measures the job itself.
    let start = std::time::Instant::now();
    let s = |p: &Path| p.to_string_lossy().into_owned();
    // The demo owns these folders; a previous demo's are replaced.
    for sub in [
        "data",
        "run",
        "samples",
        "spectrum",
        "pretrained_samples",
        "elephant",
    ] {
        let dir = out.join(sub);
        if dir.exists() {
            std::fs::remove_dir_all(&dir)
                .with_context(|| format!("cannot remove the previous demo's {}", dir.display()))?;
        }
    }
    let mut timings: Vec<(&str, f64)> = Vec::new();
    let mut lap = std::time::Instant::now();
    let mut tick = |name: &'static str, timings: &mut Vec<(&str, f64)>| {
        timings.push((name, lap.elapsed().as_secs_f64()));
        lap = std::time::Instant::now();
    };

    println!("== GMM dataset on {DEMO_MESH} (train) and its half-refined remeshing (test)");
    let data = out.join("data");
    mfm.run(&[
        "dataset",
        "gmm",
        "--out",
        &s(&data),
        "--n",
        "1000",
        "--reference",
        "100",
        "--seed",
        "0",
    ])?;
    let test_mesh = data.join("reference/mesh.ply");
    let report = mfm.output(&["info", &s(&test_mesh)])?;
    tick("dataset", &mut timings);

    println!("== noise on the non-uniform test mesh: Matérn vs naive, same seed");
    let matern_png = out.join("matern.png");
    let naive_png = out.join("naive.png");
    let noise = mfm.output(&[
        "noise",
        &s(&test_mesh),
        "--kind",
        "matern",
        "--tau",
        "100",
        "--seed",
        "1",
        "--out",
        &s(&out.join("matern.npy")),
        "--png",
        &s(&matern_png),
    ])?;
    mfm.output(&[
        "noise",
        &s(&test_mesh),
        "--kind",
        "naive",
        "--seed",
        "1",
        "--out",
        &s(&out.join("naive.npy")),
        "--png",
        &s(&naive_png),
    ])?;
    println!("== noise spectrum on both triangulations");
    let spectrum = mfm.output(&[
        "spectrum",
        &s(&data.join("train/mesh.ply")),
        &s(&test_mesh),
        "--tau",
        "100",
        "--samples",
        "1000",
        "--k",
        "32",
        "--out",
        &s(&out.join("spectrum.json")),
        "--plots",
        &s(&out.join("spectrum")),
    ])?;
    tick("noise", &mut timings);

    println!("== the pretrained model ({PRETRAINED_DIR}): sampling on the test mesh");
    let pretrained = match crate::pretrain::shipped() {
        Ok(dir) => {
            let (sampled, metrics) = sample_and_eval(
                mfm,
                &dir,
                &test_mesh,
                &data.join("reference"),
                &out.join("pretrained_samples"),
                &out.join("pretrained_metrics.json"),
                &out.join("pretrained_means.png"),
            )?;
            let readme = std::fs::read_to_string(dir.join("README.md")).unwrap_or_default();
            tick("pretrained model", &mut timings);
            Some((sampled, metrics, readme))
        }
        Err(e) => {
            println!("skipping the pretrained model: {e:#}");
            None
        }
    };

    println!("== training (the {DEMO_PRESET} recipe, {DEMO_STEPS} steps, Matérn noise)");
    let run_dir = out.join("run");
    let config_path = out.join("run.toml");
    let config = demo_config();
    std::fs::write(&config_path, &config)
        .with_context(|| format!("cannot write {}", config_path.display()))?;
    mfm.run(&[
        "train",
        "--config",
        &s(&config_path),
        "--dataset",
        &s(&data.join("train")),
        "--out",
        &s(&run_dir),
    ])?;
    tick("train", &mut timings);

    println!("== sampling on the non-uniform test mesh, metrics against the reference set");
    let (sampled, metrics) = sample_and_eval(
        mfm,
        &run_dir,
        &test_mesh,
        &data.join("reference"),
        &out.join("samples"),
        &out.join("metrics.json"),
        &out.join("means.png"),
    )?;
    tick("sample and eval", &mut timings);
    let log = std::fs::read_to_string(run_dir.join("train_log.csv")).unwrap_or_default();
    let log_tail: Vec<&str> = log.lines().collect();
    let log_tail = if log_tail.len() > 8 {
        [&log_tail[..1], &log_tail[log_tail.len() - 6..]].concat()
    } else {
        log_tail
    };

    println!(
        "== the pretrained shape model ({ELEPHANT_DIR}): the training mesh and a fine refinement"
    );
    let shapes = shape_model(mfm, &out.join("elephant"))?;
    tick("pretrained shape model", &mut timings);

    let mut md = String::new();
    writeln!(md, "# mfm demo: flow matching across triangulations\n")?;
    writeln!(
        md,
        "The paper's GMM experiment at demo scale: signals made of three Gaussian bumps \
(geodesic distance, centers drawn in proportion to vertex mass) on `{DEMO_MESH}`; a \
model trained on that uniform triangulation generates on a non-uniform one (the half \
x < centroid refined twice), where a reference set was generated independently.\n"
    )?;
    writeln!(
        md,
        "## Data\n\nTraining signals (`data/train`):\n\n![training signals](data/preview.png)\n"
    )?;
    writeln!(
        md,
        "Test mesh (`data/reference/mesh.ply`):\n\n```\n{report}```\n"
    )?;
    writeln!(
        md,
        "## Noise on the non-uniform mesh\n\nMatérn noise (tau = 100) does not see the \
triangulation; naive per-vertex noise does (finer half, finer grain):\n\n\
![matern](matern.png) ![naive](naive.png)\n\n```\n{noise}```\n"
    )?;
    writeln!(
        md,
        "Per-frequency statistics of Matérn noise on the two triangulations \
(`spectrum.json`):\n\n```\n{spectrum}```\n\n\
![variance](spectrum/variance.png)\n\n![coefficients](spectrum/coefficients.png)\n"
    )?;
    match &pretrained {
        Some((sampled, metrics, readme)) => {
            let m: EvalReport = reports::read(&out.join("pretrained_metrics.json"))?;
            writeln!(
                md,
                "## The pretrained model\n\n`{PRETRAINED_DIR}/` (shipped in the repository; \
`cargo xtask pretrain gmm` makes it again), sampled on the test mesh in seconds:\n\n\
```\n{sampled}```\n\nReference signals (top two rows) and its samples (bottom two rows), \
one colour scale, each captioned with its bump fit:\n\n\
![pretrained: data and samples](pretrained_means_samples.png)\n\n{}\n```\n{metrics}```\n\n\
How it was made:\n\n{}\n",
                quality_section(&m)?,
                readme.lines().skip(1).collect::<Vec<_>>().join("\n").trim()
            )?;
        }
        None => writeln!(
            md,
            "## The pretrained model\n\nNot found ({PRETRAINED_DIR}/ is incomplete): \
`cargo xtask pretrain gmm` makes it.\n"
        )?,
    }
    writeln!(
        md,
        "## A few minutes of training\n\n`mfm train --config run.toml` ({DEMO_STEPS} steps of the {DEMO_PRESET} \
network; log in `run/train_log.csv`, the frame and noise in `run/flow.json`):\n\n```toml\n{config}```\n\n```\n{}\n```\n",
        log_tail.join("\n")
    )?;
    writeln!(
        md,
        "## Its samples on the non-uniform mesh\n\n```\n{sampled}```\n\n![samples](samples/samples.png)\n"
    )?;
    let metrics_json: EvalReport = reports::read(&out.join("metrics.json"))?;
    writeln!(
        md,
        "## Do the samples look like the data?\n\nReference signals (top two rows) and \
generated samples on the test mesh (bottom two rows), on one colour scale; each caption \
gives the sample's fit by the generator's own family (3 bumps of the dataset's width at \
vertices, heights free): relative residual, peak value, bumps above half height.\n\n\
![data and samples](means_samples.png)\n\n{}",
        quality_section(&metrics_json)?
    )?;
    writeln!(
        md,
        "## Metrics\n\n```\n{metrics}```\n\nPoint-wise mean of the generated set vs the \
reference set (the GMM test error is their mass-weighted mean absolute difference), and \
the difference:\n\n![means](means.png)\n\n![difference](means_difference.png)\n\n\
MMD, COV, 1-NNA and the test error do not tell noise from bumps (a flat or noise-like \
set scores about as well); the bump fit above does. `cargo xtask reproduce-figures gmm` \
compares noise kinds.\n"
    )?;
    writeln!(
        md,
        "## Side by side\n\n| model | residual median | peak median | bumps > 1/2 | data-like | diversity | MMD | COV | test error |\n|---|---|---|---|---|---|---|---|---|"
    )?;
    let mut rows = Vec::new();
    if pretrained.is_some() {
        rows.push((
            "pretrained",
            reports::read::<EvalReport>(&out.join("pretrained_metrics.json"))?,
        ));
    }
    rows.push(("this run", metrics_json.clone()));
    for (name, m) in &rows {
        let q = Quality::of(Quality::section(m)?);
        writeln!(
            md,
            "| {name} | {:.3} | {:.2} | {:.2} | {:.0}% | {:.2} | {:.4} | {:.3} | {:.4} |",
            q.residual[1],
            q.peak[1],
            q.bumps,
            100.0 * q.within,
            q.diversity,
            m.metrics.mmd,
            m.metrics.cov,
            m.metrics.test_error
        )?;
    }
    writeln!(
        md,
        "| the goal | <= {} | >= {} | >= {} | | | | | |\n",
        GOAL.1, GOAL.0, GOAL.2
    )?;
    writeln!(md, "{shapes}")?;
    writeln!(md, "## Time\n")?;
    for (name, secs) in &timings {
        writeln!(md, "- {name}: {secs:.1} s")?;
    }
    writeln!(
        md,
        "- total (after the build): {:.1} s",
        start.elapsed().as_secs_f64()
    )?;
    let report_path = out.join("README.md");
    std::fs::write(&report_path, md)?;
    println!(
        "== demo finished in {:.1} s (after the build); report: {}",
        start.elapsed().as_secs_f64(),
        report_path.display()
    );
    Ok(())
}

/// Midpoint subdivisions of the shape model's 3000-face training mesh the
/// demo samples on: 4 rounds, 768k faces.
const SHAPE_SUBDIVISIONS: &str = "4";

/// The demo's shape part: the pretrained elephant model
/// ([`ELEPHANT_DIR`]) samples 4 poses on its training mesh and the same 4
/// (the same noise, drawn on the training mesh and carried, `mfm sample
/// --noise-from`) on the mesh subdivided [`SHAPE_SUBDIVISIONS`] times, with
/// pictures of training poses beside them. Needs the shared elephant mesh
/// (its training mesh is made from it, and the shared meshes are not part
/// of the repository): without it, or without the model, the section says
/// why it was skipped. Returns the report's section.
fn shape_model(mfm: &Mfm, out: &Path) -> Result<String> {
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let heading = "## A pretrained shape model at 768k faces\n\n";
    let model = workspace::root().join(ELEPHANT_DIR);
    let mesh = workspace::root().join(ELEPHANT_MESH);
    let skip = |why: String| -> Result<String> {
        println!("skipping the shape model: {why}");
        Ok(format!("{heading}Skipped: {why}.\n"))
    };
    if let Err(e) = crate::pretrain::shipped_at(ELEPHANT_DIR, "elephant") {
        return skip(format!("{e:#}"));
    }
    if !mesh.is_file() {
        return skip(format!(
            "{} is not there (the shape model's training mesh is made from the shared \
             meshes, which are not part of the repository)",
            mesh.display()
        ));
    }
    let data = out.join("data");
    mfm.run(&[
        "dataset",
        "deform",
        "--mesh",
        &s(&mesh),
        "--n",
        "8",
        "--reference",
        "4",
        "--out",
        &s(&data),
    ])?;
    let coarse = data.join("coarse.ply");
    let fine = out.join("fine.ply");
    mfm.run(&[
        "remesh",
        &s(&coarse),
        "--subdivide",
        SHAPE_SUBDIVISIONS,
        "--out",
        &s(&fine),
    ])?;
    let sample = |mesh: &Path, dir: &str, extra: &[&str]| -> Result<SampleTiming> {
        let target = out.join(dir);
        let mut args = vec![
            "sample".to_owned(),
            "--run".to_owned(),
            s(&model),
            "--mesh".to_owned(),
            s(mesh),
            "--n".to_owned(),
            "4".to_owned(),
            "--ply".to_owned(),
            "1".to_owned(),
            "--out".to_owned(),
            s(&target),
        ];
        args.extend(extra.iter().map(|a| (*a).to_owned()));
        mfm.run(&args)?;
        SampleTiming::of(&target)
    };
    let at_training = sample(&coarse, "coarse_samples", &[])?;
    let at_fine = sample(&fine, "fine_samples", &["--noise-from", &s(&coarse)])?;
    let readme = std::fs::read_to_string(model.join("README.md")).unwrap_or_default();
    Ok(format!(
        "{heading}`{ELEPHANT_DIR}/` (shipped; `cargo xtask pretrain elephant` makes it \
again): a shape model trained on as-rigid-as-possible poses of the elephant on a \
{:.0}-vertex mesh, with smooth Matérn noise (`matern-smooth:100:2`), sampled on that mesh \
and on the mesh subdivided {SHAPE_SUBDIVISIONS} times ({:.0} vertices), from the same \
noise (drawn on the training mesh and carried, `mfm sample --noise-from`).\n\n\
Training poses (`elephant/data/train`, a few of the kind the model learned from):\n\n\
![training poses](elephant/data/preview.png)\n\n\
Its samples on the training mesh ({:.2} s a sample):\n\n\
![samples on the training mesh](elephant/coarse_samples/samples.png)\n\n\
The same samples on the fine mesh ({:.1} s a sample):\n\n\
![samples on the fine mesh](elephant/fine_samples/samples.png)\n\n\
How the model was made:\n\n{}\n",
        at_training.vertices as f64,
        at_fine.vertices as f64,
        at_training.seconds_per_sample,
        at_fine.seconds_per_sample,
        readme.lines().skip(1).collect::<Vec<_>>().join("\n").trim()
    ))
}

/// The demo's goal on the test mesh (generation-quality issue): median peak,
/// median bump-fit residual, mean bumps above half height.
const GOAL: (f64, f64, f64) = (0.8, 0.35, 2.5);

/// The quality table of the report: quartiles of the generated set against
/// the reference set, the first samples' numbers, and the goal.
fn quality_section(metrics: &EvalReport) -> Result<String> {
    let q = Quality::section(metrics)?;
    let (g, r) = (Quality::of(q), &q.reference);
    let quart = |v: [f64; 3]| format!("{:.3} [{:.3}, {:.3}]", v[1], v[0], v[2]);
    let mut md = String::new();
    writeln!(
        md,
        "| set | residual median [q1, q3] | peak median [q1, q3] | bumps above half height | data-like | diversity |\n|---|---|---|---|---|---|"
    )?;
    writeln!(
        md,
        "| generated | {} | {} | {:.2} | {:.0}% | {:.2} |",
        quart(g.residual),
        quart(g.peak),
        g.bumps,
        100.0 * g.within,
        g.diversity
    )?;
    writeln!(
        md,
        "| reference (the floor) | {} | {} | {:.2} | | 1 |\n",
        quart(quartiles(r.residual)),
        quart(quartiles(r.peak)),
        r.bumps_above_half
    )?;
    let (peak, res, bumps) = (g.peak[1], g.residual[1], g.bumps);
    let mark = |ok: bool| if ok { "reached" } else { "not reached" };
    writeln!(
        md,
        "Goal: median peak >= {} ({peak:.2}: {}), median residual <= {} ({res:.3}: {}), \
>= {} bumps above half height per sample ({bumps:.2}: {}).\n",
        GOAL.0,
        mark(peak >= GOAL.0),
        GOAL.1,
        mark(res <= GOAL.1),
        GOAL.2,
        mark(bumps >= GOAL.2)
    )?;
    if !(peak >= GOAL.0 && res <= GOAL.1 && bumps >= GOAL.2) {
        writeln!(
            md,
            "Where the rest is: docs/BENCHMARKS.md (\"Time to quality\") has the curves of these \
numbers against training steps and seconds per network size, and the controlled runs of \
recipe changes at equal budgets (`cargo xtask time-to-quality` reproduces them).\n"
        )?;
    }
    writeln!(
        md,
        "First generated samples:\n\n| sample | residual | peak | bumps above half height |\n|---|---|---|---|"
    )?;
    for (i, f) in q.generated.fits.iter().take(8).enumerate() {
        writeln!(
            md,
            "| {i} | {:.3} | {:.2} | {} |",
            f.residual, f.peak, f.bumps_above_half
        )?;
    }
    Ok(md)
}
