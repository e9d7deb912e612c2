//! The flow-matching steps the figure commands run through the release
//! `mfm` binary (train, sample, eval), and the folder and mesh choices they
//! share.

use crate::mfm::Mfm;
use crate::reports::{self, EvalOutcome};
use crate::workspace;
use anyhow::{Context, Result};
use mfm_eval::quality::{GmmQualityReport, Quartiles};
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `p` as a command-line argument.
pub fn arg(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// Removes a previous `dir` and creates it empty.
pub fn fresh_dir(dir: &Path) -> Result<()> {
    if dir.exists() {
        std::fs::remove_dir_all(dir)
            .with_context(|| format!("cannot remove the previous {}", dir.display()))?;
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))
}

/// `mesh` when given; else `../shared/meshes/NAME` when present, else
/// `fallback` (saying so).
pub fn mesh_or_shared(mesh: Option<&str>, name: &str, fallback: &str) -> String {
    if let Some(m) = mesh {
        return m.to_owned();
    }
    let shared = workspace::root().join("../shared/meshes").join(name);
    if shared.is_file() {
        arg(&shared)
    } else {
        println!("../shared/meshes/{name} not found: using {fallback}");
        fallback.to_owned()
    }
}

/// A noise kind as a file-name tag (`matern:100` -> `matern_100`).
pub fn tag(kind: &str) -> String {
    kind.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// `[q1, median, q3]`.
pub fn quartiles(q: Quartiles) -> [f64; 3] {
    [q.q1, q.median, q.q3]
}

/// What each noise kind of a figure's comparison table is trained on and
/// evaluated against.
pub struct Comparison<'a> {
    /// The experiment's output folder: runs, samples and metrics go to
    /// `run_TAG`, `samples_TAG`, `metrics_TAG.json`, `PICTURE_TAG.png`.
    pub out: &'a Path,
    /// `mfm train --preset`.
    pub preset: &'a str,
    /// Training dataset folder.
    pub dataset: &'a Path,
    /// Training steps.
    pub steps: u64,
    /// Seed of the training run and of the samples.
    pub seed: u64,
    /// Mesh the samples are generated on.
    pub test_mesh: &'a Path,
    /// Number of samples.
    pub samples: usize,
    /// Reference dataset folder (`mfm eval --reference`).
    pub reference: &'a Path,
    /// File-name stem of `mfm eval`'s picture.
    pub picture: &'a str,
}

/// One noise kind's row of a comparison table.
pub struct KindResult {
    /// The noise kind (`mfm train --noise`).
    pub kind: String,
    /// The run folder.
    pub run: PathBuf,
    /// `mfm eval`'s report, or the failure when sampling broke down (a
    /// result of the experiment, not a crash).
    pub metrics: EvalOutcome,
    /// Wall seconds of training.
    pub train_seconds: f64,
    /// Wall seconds of sampling (until the failure, if it failed).
    pub sample_seconds: f64,
}

/// The generated set's bump-fit numbers in an `mfm eval` report of a GMM
/// reference set (its `quality`).
#[derive(Clone, Debug)]
pub struct Quality {
    /// q1, median, q3 of the residual.
    pub residual: [f64; 3],
    /// q1, median, q3 of the peak value.
    pub peak: [f64; 3],
    /// Mean bumps above half height per sample.
    pub bumps: f64,
    /// Fraction of data-like samples.
    pub within: f64,
    /// Diversity against the reference set.
    pub diversity: f64,
}

impl Quality {
    /// The generated set's numbers of `q`.
    pub fn of(q: &GmmQualityReport) -> Self {
        let g = &q.generated;
        Self {
            residual: quartiles(g.residual),
            peak: quartiles(g.peak),
            bumps: g.bumps_above_half,
            within: q.within_twice_floor,
            diversity: q.diversity,
        }
    }

    /// The quality section of `report`.
    ///
    /// # Errors
    /// When it has none (`mfm eval` writes one for GMM reference sets).
    pub fn section(report: &reports::EvalReport) -> Result<&GmmQualityReport> {
        report.quality.as_ref().context(
            "the evaluation has no quality section (mfm eval on a GMM reference set writes one)",
        )
    }

    /// The quality columns of a Markdown table row: `residual median [q1,
    /// q3] | peak median | bumps | data-like % | diversity` (no outer bars).
    pub fn cells(&self) -> String {
        format!(
            "{:.3} [{:.3}, {:.3}] | {:.2} | {:.2} | {:.0}% | {:.2}",
            self.residual[1],
            self.residual[0],
            self.residual[2],
            self.peak[1],
            self.bumps,
            100.0 * self.within,
            self.diversity
        )
    }
}

impl Mfm {
    /// The demo's GMM data in `data` (`n` training signals on the built-in
    /// blob, 100 reference signals on its half-refined remeshing, seed 0),
    /// made unless a complete one is there (an incomplete one is replaced).
    ///
    /// # Errors
    /// When `mfm dataset gmm` fails.
    pub fn ensure_gmm_dataset(&self, data: &Path, n: usize) -> Result<()> {
        if data.join("reference/mesh.ply").is_file() {
            return Ok(());
        }
        if data.exists() {
            std::fs::remove_dir_all(data)
                .with_context(|| format!("cannot remove the incomplete {}", data.display()))?;
        }
        self.run(&[
            "dataset",
            "gmm",
            "--out",
            &arg(data),
            "--n",
            &n.to_string(),
            "--reference",
            "100",
            "--seed",
            "0",
        ])
    }

    /// `mfm train --preset PRESET --dataset D --out RUN --steps S --seed
    /// SEED --noise KIND --prior none --quiet`; returns the wall seconds.
    /// The paper's experiments compare noise kinds as the start of the
    /// flow, so they start from the noise alone whatever the preset says;
    /// the `cpu-deform` preset's fainter noise (`sigma = 1`) goes with its
    /// data prior, so without it these runs take the official elastic
    /// recipe's `sigma = 3` (`--noise-scale 3`, the `cpu` preset's).
    ///
    /// # Errors
    /// When training fails.
    pub fn train(
        &self,
        preset: &str,
        dataset: &Path,
        run: &Path,
        steps: u64,
        seed: u64,
        noise: &str,
    ) -> Result<f64> {
        let t = Instant::now();
        let (dataset, run, steps, seed) =
            (arg(dataset), arg(run), steps.to_string(), seed.to_string());
        let mut args = vec![
            "train",
            "--preset",
            preset,
            "--dataset",
            &dataset,
            "--out",
            &run,
            "--steps",
            &steps,
            "--seed",
            &seed,
            "--noise",
            noise,
            "--prior",
            "none",
            "--quiet",
        ];
        if preset == "cpu-deform" {
            args.extend(["--noise-scale", "3"]);
        }
        self.run(&args)?;
        Ok(t.elapsed().as_secs_f64())
    }

    /// `mfm sample --run RUN --mesh MESH --n N --seed SEED --out OUT
    /// [EXTRA...]`.
    ///
    /// # Errors
    /// When sampling fails.
    pub fn sample(
        &self,
        run: &Path,
        mesh: &Path,
        n: usize,
        seed: u64,
        out: &Path,
        extra: &[&str],
    ) -> Result<()> {
        let (run, mesh, n, seed, out) = (
            arg(run),
            arg(mesh),
            n.to_string(),
            seed.to_string(),
            arg(out),
        );
        let mut args = vec![
            "sample", "--run", &run, "--mesh", &mesh, "--n", &n, "--seed", &seed, "--out", &out,
        ];
        args.extend_from_slice(extra);
        self.run(&args)
    }

    /// `mfm eval --samples SAMPLES AGAINST... --out OUT [--png PNG]`, where
    /// `against` is `["--reference", DIR]` (an [`EvalReport`] comes back)
    /// or `["--space", S, "--mesh", M]` (a [`PlausibilityReport`]); returns
    /// the report it wrote.
    ///
    /// [`EvalReport`]: reports::EvalReport
    /// [`PlausibilityReport`]: reports::PlausibilityReport
    ///
    /// # Errors
    /// When the evaluation fails or its report is not a `T`.
    pub fn eval<T: DeserializeOwned>(
        &self,
        samples: &Path,
        against: &[&str],
        out: &Path,
        png: Option<&Path>,
    ) -> Result<T> {
        let (samples, out_arg) = (arg(samples), arg(out));
        let mut args = vec!["eval", "--samples", &samples];
        args.extend_from_slice(against);
        args.extend_from_slice(&["--out", &out_arg]);
        let png = png.map(arg);
        if let Some(p) = &png {
            args.extend_from_slice(&["--png", p]);
        }
        self.run(&args)?;
        reports::read(out)
    }

    /// Trains `kind` as `c` says, samples on the test mesh and evaluates the
    /// samples against the reference set. A kind whose sampling breaks down
    /// gives a row with the failure (and says so) instead of an error.
    ///
    /// # Errors
    /// When training or the evaluation fails.
    pub fn compare_kind(&self, c: &Comparison<'_>, kind: &str) -> Result<KindResult> {
        let tag = tag(kind);
        let run = c.out.join(format!("run_{tag}"));
        let train_seconds = self.train(c.preset, c.dataset, &run, c.steps, c.seed, kind)?;
        let samples = c.out.join(format!("samples_{tag}"));
        let t = Instant::now();
        let sampled = self.sample(&run, c.test_mesh, c.samples, c.seed, &samples, &[]);
        let sample_seconds = t.elapsed().as_secs_f64();
        let metrics = match sampled {
            Ok(()) => EvalOutcome::Report(Box::new(self.eval(
                &samples.join("samples.npy"),
                &["--reference", &arg(c.reference)],
                &c.out.join(format!("metrics_{tag}.json")),
                Some(&c.out.join(format!("{}_{tag}.png", c.picture))),
            )?)),
            Err(e) => {
                println!("{kind}: sampling failed: {e:#}");
                EvalOutcome::failed(&e)
            }
        };
        Ok(KindResult {
            kind: kind.to_owned(),
            run,
            metrics,
            train_seconds,
            sample_seconds,
        })
    }
}

/// The arguments of `mfm train` that train `config` on `dataset` into
/// `run`, or resume `run` when it already holds its `config.toml`.
pub fn train_args(run: &Path, config: &Path, dataset: &Path) -> Vec<String> {
    let (out, data) = (arg(run), arg(dataset));
    if run.join(mfm_files::owned::RUN_CONFIG).is_file() {
        ["train", "--resume", "--out", &out, "--dataset", &data]
            .map(str::to_owned)
            .to_vec()
    } else {
        let config = arg(config);
        [
            "train",
            "--config",
            &config,
            "--dataset",
            &data,
            "--out",
            &out,
        ]
        .map(str::to_owned)
        .to_vec()
    }
}
