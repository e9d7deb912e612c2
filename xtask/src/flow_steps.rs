//! The flow-matching steps the figure commands run through the release
//! `mfm` binary (train, sample, eval), and the folder and mesh choices they
//! share.

use anyhow::{Context, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `p` as a command-line argument.
pub fn arg(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// `path` if absolute, else relative to the workspace root.
pub fn out_dir(path: &Path) -> PathBuf {
    if path.is_absolute() {
        path.to_path_buf()
    } else {
        crate::root().join(path)
    }
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
    let shared = crate::root().join("../shared/meshes").join(name);
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

/// The number `v[k]`, NaN when it is missing.
pub fn num(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or(f64::NAN)
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
    /// `mfm eval`'s metrics, or `{"error": message}` when sampling broke
    /// down (a result of the experiment, not a crash).
    pub metrics: Value,
    /// Wall seconds of training.
    pub train_seconds: f64,
    /// Wall seconds of sampling (until the failure, if it failed).
    pub sample_seconds: f64,
}

impl KindResult {
    /// Whether sampling failed.
    pub fn failed(&self) -> bool {
        self.metrics["error"].is_string()
    }
}

/// The bump-fit numbers of one set in an `mfm eval` report (`quality`).
#[derive(Clone, Debug)]
pub struct Quality {
    /// q1, median, q3 of the residual.
    pub residual: [f64; 3],
    /// q1, median, q3 of the peak value.
    pub peak: [f64; 3],
    /// Mean bumps above half height per sample.
    pub bumps: f64,
    /// Fraction of data-like samples (NaN for the reference set).
    pub within: f64,
    /// Diversity against the reference set (1 for the reference set).
    pub diversity: f64,
}

impl Quality {
    fn set(q: &Value, within: f64, diversity: f64) -> Self {
        let quartiles = |v: &Value| [num(v, "q1"), num(v, "median"), num(v, "q3")];
        Self {
            residual: quartiles(&q["residual"]),
            peak: quartiles(&q["peak"]),
            bumps: num(q, "bumps_above_half"),
            within,
            diversity,
        }
    }

    /// The generated set's numbers.
    pub fn of(metrics: &Value) -> Self {
        let q = &metrics["quality"];
        Self::set(
            &q["generated"],
            num(q, "within_twice_floor"),
            num(q, "diversity"),
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

    /// The reference set's numbers.
    pub fn reference_of(metrics: &Value) -> Self {
        Self::set(&metrics["quality"]["reference"], f64::NAN, 1.0)
    }
}

impl Mfm<'_> {
    /// The demo's GMM data in `data` (`n` training signals on the built-in
    /// blob, 100 reference signals on its half-refined remeshing, seed 0),
    /// made unless a complete one is there (an incomplete one is replaced).
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
}

/// Runs `cmd` (with the standard streams it was given) to its end and
/// returns the peak resident memory of the process, in bytes (`wait4`);
/// a failure is an error with the program's arguments and, when `cmd`
/// pipes its standard error, what it wrote there.
pub fn run_with_peak_memory(cmd: &mut std::process::Command) -> Result<u64> {
    let call = cmd
        .get_args()
        .map(|a| a.to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join(" ");
    let child = cmd
        .spawn()
        .with_context(|| format!("cannot run {}", cmd.get_program().to_string_lossy()))?;
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value for wait4 to fill.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: waits for our own child (not through `child`, which is never
    // waited for); both pointers are valid for writes.
    let waited = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    if waited != pid {
        anyhow::bail!(
            "waiting for mfm {call} failed: {}",
            std::io::Error::last_os_error()
        );
    }
    if !(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0) {
        let mut err = String::new();
        if let Some(mut e) = child.stderr {
            use std::io::Read as _;
            let _ = e.read_to_string(&mut err);
        }
        anyhow::bail!("mfm {call} failed (wait status {status}): {err}");
    }
    // ru_maxrss is in KiB on Linux
    Ok(u64::try_from(usage.ru_maxrss).unwrap_or(0) * 1024)
}

/// The arguments of `mfm train` that train `config` on `dataset` into
/// `run`, or resume `run` when it already holds its `config.toml`.
pub fn train_args(run: &Path, config: &Path, dataset: &Path) -> Vec<String> {
    let (out, data) = (arg(run), arg(dataset));
    if run.join("config.toml").is_file() {
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

/// Reads a JSON file.
pub fn read_json(path: &Path) -> Result<Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: invalid JSON", path.display()))
}

/// The release `mfm` binary, with its output shown live.
pub struct Mfm<'a> {
    /// Path of the binary.
    pub exe: &'a Path,
}

impl Mfm<'_> {
    /// Runs `mfm ARGS`, echoing the command line.
    pub fn run(&self, args: &[&str]) -> Result<()> {
        println!("$ mfm {}", args.join(" "));
        crate::demo::mfm_live(self.exe, args)
    }

    /// `mfm train --preset PRESET --dataset D --out RUN --steps S --seed
    /// SEED --noise KIND --quiet`; returns the wall seconds.
    #[allow(clippy::too_many_arguments)]
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
        self.run(&[
            "train",
            "--preset",
            preset,
            "--dataset",
            &arg(dataset),
            "--out",
            &arg(run),
            "--steps",
            &steps.to_string(),
            "--seed",
            &seed.to_string(),
            "--noise",
            noise,
            "--quiet",
        ])?;
        Ok(t.elapsed().as_secs_f64())
    }

    /// `mfm sample --run RUN --mesh MESH --n N --seed SEED --out OUT
    /// [EXTRA...]`.
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
    /// `against` is `["--reference", DIR]` or `["--space", S, "--mesh", M]`;
    /// returns the metrics JSON.
    pub fn eval(
        &self,
        samples: &Path,
        against: &[&str],
        out: &Path,
        png: Option<&Path>,
    ) -> Result<Value> {
        let (samples, out_arg) = (arg(samples), arg(out));
        let mut args = vec!["eval", "--samples", &samples];
        args.extend_from_slice(against);
        args.extend_from_slice(&["--out", &out_arg]);
        let png = png.map(arg);
        if let Some(p) = &png {
            args.extend_from_slice(&["--png", p]);
        }
        self.run(&args)?;
        read_json(out)
    }

    /// Trains `kind` as `c` says, samples on the test mesh and evaluates the
    /// samples against the reference set. A kind whose sampling breaks down
    /// gives a row with `{"error": ...}` (and says so) instead of an error.
    pub fn compare_kind(&self, c: &Comparison<'_>, kind: &str) -> Result<KindResult> {
        let tag = tag(kind);
        let run = c.out.join(format!("run_{tag}"));
        let train_seconds = self.train(c.preset, c.dataset, &run, c.steps, c.seed, kind)?;
        let samples = c.out.join(format!("samples_{tag}"));
        let t = Instant::now();
        let sampled = self.sample(&run, c.test_mesh, c.samples, c.seed, &samples, &[]);
        let sample_seconds = t.elapsed().as_secs_f64();
        let metrics = match sampled {
            Ok(()) => self.eval(
                &samples.join("samples.npy"),
                &["--reference", &arg(c.reference)],
                &c.out.join(format!("metrics_{tag}.json")),
                Some(&c.out.join(format!("{}_{tag}.png", c.picture))),
            )?,
            Err(e) => {
                println!("{kind}: sampling failed: {e:#}");
                serde_json::json!({ "error": format!("{e:#}") })
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
