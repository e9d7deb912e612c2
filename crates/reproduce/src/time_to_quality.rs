//! `cargo xtask time-to-quality`: sample quality against training time.
//!
//! The GMM blob experiment of the demo (1000 training signals on the
//! built-in blob, 100 reference signals on its half-refined remeshing, seed
//! 0), trained once per *variant* (a network size and optional recipe
//! changes) for a wall-time budget. Each run keeps its checkpoints at
//! log-spaced steps (`train.keep_at`); every kept checkpoint is sampled on
//! the test mesh (64 samples, seed 7, its weight average when the run has
//! one) and evaluated by `mfm eval` (bump fit against the data's floor,
//! MMD, COV, test error). Training stops by Ctrl-C (SIGINT) at the budget
//! and a later call resumes it bit for bit, so the budget can be spent over
//! several sessions; samples and evaluations already made are reused.
//!
//! Writes under `--out`: `data/`, one folder per variant (`run/`,
//! `eval/step-N.json` with `step-N_samples.png`), and
//! `time_to_quality.{csv,md,png}`: the table and the curves (residual,
//! peak, bumps per sample, COV and test error against steps, residual
//! against training seconds).

use crate::flow_steps::{Quality, arg, train_args};
use crate::mfm::Mfm;
use crate::reports::{self, EvalOutcome};
use crate::workspace::{self, in_root};
use anyhow::{Context, Result, bail};
use mfm_eval::metrics::Metrics;
use mfm_files::run_folder::{CheckpointInfo, CheckpointState, STATE_FILE, list_checkpoints};
use mfm_render::plots::{Curve, CurvePanel, curve_grid};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Steps whose checkpoints every run keeps (log-spaced, 1-2-5).
pub const SNAPSHOTS: [u64; 12] = [
    100, 200, 500, 1_000, 2_000, 5_000, 10_000, 20_000, 50_000, 100_000, 200_000, 500_000,
];

/// The goal of the generation-quality issue on the test mesh: median
/// residual, median peak, bumps above half height per sample.
pub const GOAL: (f64, f64, f64) = (0.35, 0.8, 2.5);

/// Arguments of `cargo xtask time-to-quality`.
#[derive(clap::Args)]
pub struct TimeToQualityArgs {
    /// Output folder (relative paths are relative to the workspace root).
    #[arg(long, default_value = "out/time-to-quality")]
    pub out: PathBuf,
    /// Variants, comma-separated: `NAME:WIDTHxBLOCKSxLAYERS` optionally
    /// followed by `:SECTION.KEY=VALUE;...` run-config settings (TOML
    /// values), e.g. `W32-ema:32x3x3:train.ema=0.999`; `data.signals=N`
    /// trains on N signals of the same generator instead of 1000 (the
    /// evaluation's reference set stays the same).
    /// Commas inside brackets or braces (`keep_at = [1000, 2000]`,
    /// `lr_schedule = { warmup = 250, cosine = 3000 }`) do not split.
    #[arg(long, default_value = "W16K2:16x2x2,W32K3:32x3x3,W64K4:64x4x3")]
    pub variants: Vec<String>,
    /// Training budget per variant in minutes of training time (summed over
    /// resumed calls).
    #[arg(long, default_value_t = 60.0)]
    pub minutes: f64,
    /// Generated samples per evaluation.
    #[arg(long, default_value_t = 64)]
    pub samples: usize,
    /// Only sample and evaluate what the runs hold (no training).
    #[arg(long)]
    pub eval_only: bool,
    /// Also write the plot here (e.g. docs/time_to_quality.png).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Splits a `--variants` list at the commas that are not inside brackets or
/// braces (TOML arrays and inline tables keep theirs); empty items are
/// dropped.
fn split_variants(list: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, c) in list.char_indices() {
        match c {
            '[' | '{' => depth += 1,
            ']' | '}' => depth -= 1,
            ',' if depth <= 0 => {
                out.push(&list[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(&list[start..]);
    out.into_iter().filter(|v| !v.trim().is_empty()).collect()
}

/// One variant: a network size and run-config settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// Folder and legend name.
    pub name: String,
    /// Width, blocks, complex layers per vector MLP.
    pub size: (usize, usize, usize),
    /// `(section, key, TOML value)`.
    pub settings: Vec<(String, String, String)>,
    /// Training signals (`data.signals`, [`DEFAULT_SIGNALS`] unless given).
    pub signals: usize,
}

/// Training signals of a variant that does not set `data.signals`: the
/// demo's 1000.
pub const DEFAULT_SIGNALS: usize = 1000;

impl std::str::FromStr for Variant {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Self> {
        let mut parts = s.splitn(3, ':');
        let name = parts.next().unwrap_or_default().trim();
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
        {
            bail!("variant {s:?}: the name must be letters, digits, '-', '_' or '.'");
        }
        let size = parts
            .next()
            .with_context(|| format!("variant {s:?}: expected NAME:WIDTHxBLOCKSxLAYERS"))?;
        let dims: Vec<usize> = size
            .split('x')
            .map(|d| d.trim().parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .with_context(|| format!("variant {s:?}: size {size:?} is not WIDTHxBLOCKSxLAYERS"))?;
        let [w, k, nl] = dims[..] else {
            bail!("variant {s:?}: size {size:?} is not WIDTHxBLOCKSxLAYERS");
        };
        let mut settings = Vec::new();
        let mut signals = DEFAULT_SIGNALS;
        for item in parts
            .next()
            .unwrap_or_default()
            .split(';')
            .filter(|x| !x.trim().is_empty())
        {
            let (key, value) = item.split_once('=').with_context(|| {
                format!("variant {s:?}: setting {item:?} is not SECTION.KEY=VALUE")
            })?;
            let (section, key) = key.trim().split_once('.').with_context(|| {
                format!("variant {s:?}: setting {item:?} needs a section (model., train., noise.)")
            })?;
            if section == "data" {
                if key != "signals" {
                    bail!("variant {s:?}: the data section has one setting, `signals`");
                }
                signals = value
                    .trim()
                    .parse::<usize>()
                    .ok()
                    .filter(|&n| n >= 2)
                    .with_context(|| {
                        format!("variant {s:?}: data.signals must be a count of at least 2, found {value:?}")
                    })?;
                continue;
            }
            settings.push((section.to_owned(), key.to_owned(), value.trim().to_owned()));
        }
        Ok(Self {
            name: name.to_owned(),
            size: (w, k, nl),
            settings,
            signals,
        })
    }
}

impl Variant {
    /// The run configuration: the demo's recipe (batch 4, lr `2e-3` then
    /// `5e-4` from step 2000, the official noise and centring) at this size,
    /// open-ended (the budget stops it), keeping [`SNAPSHOTS`], with the
    /// variant's settings last (a setting of a key already given replaces it).
    pub fn config_toml(&self) -> String {
        let (w, k, nl) = self.size;
        let keep: Vec<String> = SNAPSHOTS.iter().map(u64::to_string).collect();
        let mut sections: Vec<(String, Vec<(String, String)>)> = vec![
            (
                "model".into(),
                vec![
                    ("preset".into(), "\"small\"".into()),
                    ("width".into(), w.to_string()),
                    ("blocks".into(), k.to_string()),
                    ("vector_layers".into(), nl.to_string()),
                ],
            ),
            (
                "train".into(),
                vec![
                    ("steps".into(), "10000000".into()),
                    ("batch".into(), "4".into()),
                    ("lr".into(), "2e-3".into()),
                    (
                        "lr_schedule".into(),
                        "{ milestones = [[2000, 5e-4]] }".into(),
                    ),
                    ("checkpoint_every".into(), "500".into()),
                    ("log_every".into(), "100".into()),
                    ("keep_at".into(), format!("[{}]", keep.join(", "))),
                ],
            ),
        ];
        for (section, key, value) in &self.settings {
            let entries = match sections.iter_mut().find(|(s, _)| s == section) {
                Some((_, e)) => e,
                None => {
                    sections.push((section.clone(), Vec::new()));
                    &mut sections.last_mut().expect("just pushed").1
                }
            };
            entries.retain(|(k, _)| k != key);
            entries.push((key.clone(), value.clone()));
        }
        let mut toml = format!("# cargo xtask time-to-quality, variant {}\n", self.name);
        if self.signals != DEFAULT_SIGNALS {
            // not a run setting, but part of what the variant is: a changed
            // count is refused like a changed setting
            toml.push_str(&format!(
                "# trained on {} signals (data.signals)\n",
                self.signals
            ));
        }
        for (section, entries) in sections {
            toml.push_str(&format!("[{section}]\n"));
            for (k, v) in entries {
                toml.push_str(&format!("{k} = {v}\n"));
            }
        }
        toml
    }
}

/// One evaluated checkpoint.
#[derive(Clone, Debug)]
struct Point {
    step: u64,
    seconds: f64,
    /// The evaluation; `None` when sampling broke down.
    evaluated: Option<Evaluated>,
}

/// What the report shows of a checkpoint's evaluation.
#[derive(Clone, Debug)]
struct Evaluated {
    quality: Quality,
    metrics: Metrics,
}

impl Point {
    /// `f` of the evaluation, NaN (a gap in the curves) when sampling
    /// failed.
    fn value(&self, f: impl Fn(&Evaluated) -> f64) -> f64 {
        self.evaluated.as_ref().map_or(f64::NAN, f)
    }
}

/// Training seconds recorded in a checkpoint folder's `state.json`.
fn checkpoint_seconds(dir: &Path) -> Result<f64> {
    Ok(CheckpointState::read(dir)?.elapsed_seconds)
}

/// The complete checkpoints of a run (with their `state.json`, which is
/// written last), ascending.
fn checkpoints(run: &Path) -> Result<Vec<CheckpointInfo>> {
    Ok(list_checkpoints(run)?
        .into_iter()
        .filter(|c| c.dir.join(STATE_FILE).is_file())
        .collect())
}

/// Trains (or resumes) `run` until its training time reaches `budget`
/// seconds; the run is stopped with SIGINT, which makes `mfm train` write a
/// checkpoint and exit.
fn train_for(mfm: &Mfm, run: &Path, config: &Path, dataset: &Path, budget: f64) -> Result<()> {
    let done = match checkpoints(run)?.last() {
        Some(c) => checkpoint_seconds(&c.dir)?,
        None => 0.0,
    };
    let left = budget - done;
    if left < 1.0 {
        println!(
            "{}: {done:.0} s of training already, budget {budget:.0} s",
            run.display()
        );
        return Ok(());
    }
    let mut cmd = mfm.command(&train_args(run, config, dataset))?;
    cmd.arg("--quiet").stdin(Stdio::null());
    println!(
        "$ mfm {} (for {left:.0} s)",
        cmd.get_args()
            .map(|a| a.to_string_lossy())
            .collect::<Vec<_>>()
            .join(" ")
    );
    let mut child = cmd
        .spawn()
        .with_context(|| format!("cannot run mfm train on {}", run.display()))?;
    let start = Instant::now();
    let mut signalled = false;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        // the process also spends a few seconds building operators before
        // its first step: those do not count as training time
        if !signalled && start.elapsed().as_secs_f64() > left + 5.0 {
            let pid = child.id().to_string();
            workspace::run(Command::new("kill").args(["-INT", &pid]))?;
            signalled = true;
        }
        std::thread::sleep(Duration::from_millis(500));
    };
    // 130: stopped by the signal, after writing its checkpoint
    if !(status.success() || (signalled && status.code() == Some(130))) {
        bail!("mfm train on {} failed ({status})", run.display());
    }
    Ok(())
}

/// Samples and evaluates the kept checkpoints of `run` (and its newest
/// one) that have no evaluation yet; returns every evaluated point.
fn evaluate(mfm: &Mfm, variant_dir: &Path, data: &Path, samples: usize) -> Result<Vec<Point>> {
    let run = variant_dir.join("run");
    let eval_dir = variant_dir.join("eval");
    std::fs::create_dir_all(&eval_dir)
        .with_context(|| format!("cannot create {}", eval_dir.display()))?;
    let all = checkpoints(&run)?;
    let newest = all.last().map(|c| c.step);
    let mut points = Vec::new();
    for CheckpointInfo { step, dir } in &all {
        if !SNAPSHOTS.contains(step) && Some(*step) != newest {
            continue;
        }
        let json = eval_dir.join(format!("step-{step}.json"));
        // a failure recorded by an earlier run is tried again: it may have
        // been the machine (disk, memory), not the model
        if !json.is_file() || reports::read::<EvalOutcome>(&json)?.report().is_none() {
            let out = variant_dir.join("samples").join(format!("step-{step}"));
            if out.exists() {
                std::fs::remove_dir_all(&out)
                    .with_context(|| format!("cannot remove {}", out.display()))?;
            }
            let sampled = mfm.sample(
                &run,
                &data.join("reference/mesh.ply"),
                samples,
                7,
                &out,
                &["--ply", "0", "--step", &step.to_string()],
            );
            match sampled {
                Ok(()) => {
                    let reference = arg(&data.join("reference"));
                    mfm.eval::<EvalOutcome>(
                        &out.join("samples.npy"),
                        &["--reference", &reference],
                        &json,
                        Some(&eval_dir.join(format!("step-{step}.png"))),
                    )?;
                }
                // a model whose sampling breaks down is a result, not a crash
                Err(e) => {
                    println!("step {step}: sampling failed ({e:#}); recorded as such");
                    reports::write(&json, &EvalOutcome::failed(&e))?;
                }
            }
        }
        let evaluated = match reports::read::<EvalOutcome>(&json)? {
            EvalOutcome::Report(r) => Some(Evaluated {
                quality: Quality::of(Quality::section(&r)?),
                metrics: r.metrics,
            }),
            EvalOutcome::Failed { .. } => None,
        };
        points.push(Point {
            step: *step,
            seconds: checkpoint_seconds(dir)?,
            evaluated,
        });
    }
    Ok(points)
}

/// Runs the experiment.
///
/// # Errors
/// For arguments out of range, and when a step fails (a checkpoint whose
/// sampling fails is recorded, not an error).
pub fn run(mfm: &Mfm, args: &TimeToQualityArgs) -> Result<()> {
    let variants: Vec<Variant> = args
        .variants
        .iter()
        .flat_map(|list| split_variants(list))
        .map(|v| v.parse())
        .collect::<Result<_>>()?;
    if variants.is_empty() {
        bail!("--variants: give at least one variant");
    }
    if !(args.minutes.is_finite() && args.minutes > 0.0) {
        bail!(
            "--minutes must be a positive number, found {}",
            args.minutes
        );
    }
    if args.samples < 2 {
        bail!("--samples must be at least 2, found {}", args.samples);
    }
    let out = in_root(&args.out);
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    mfm.exe()?;
    let data = out.join("data");
    mfm.ensure_gmm_dataset(&data, 1000)?;
    let mut results = Vec::new();
    for v in &variants {
        let dir = out.join(&v.name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let config = dir.join("run.toml");
        let toml = v.config_toml();
        match std::fs::read_to_string(&config) {
            Ok(old) if old != toml && dir.join("run/config.toml").is_file() => bail!(
                "{} was made with other settings than variant {:?} now gives; use another name or remove {}",
                config.display(),
                v.name,
                dir.display()
            ),
            _ => std::fs::write(&config, &toml)
                .with_context(|| format!("cannot write {}", config.display()))?,
        }
        if !args.eval_only {
            // other training-set sizes: the same generator and seed, their
            // own folder; every variant is evaluated on `data/reference`
            let train_data = if v.signals == DEFAULT_SIGNALS {
                data.clone()
            } else {
                let d = out.join(format!("data-{}", v.signals));
                mfm.ensure_gmm_dataset(&d, v.signals)?;
                d
            };
            train_for(
                mfm,
                &dir.join("run"),
                &config,
                &train_data.join("train"),
                args.minutes * 60.0,
            )?;
        }
        let points = evaluate(mfm, &dir, &data, args.samples)?;
        results.push((v.clone(), points));
    }
    write_report(&out, &results)?;
    let png = out.join("time_to_quality.png");
    plot(&png, &results)?;
    if let Some(p) = &args.plot {
        let p = in_root(p);
        std::fs::copy(&png, &p)
            .with_context(|| format!("cannot copy the plot to {}", p.display()))?;
    }
    println!(
        "time-to-quality: {}",
        out.join("time_to_quality.md").display()
    );
    Ok(())
}

/// The first point at which the median residual is at most `bound`.
fn first_below(points: &[Point], bound: f64) -> Option<&Point> {
    points
        .iter()
        .find(|p| p.value(|e| e.quality.residual[1]) <= bound)
}

fn write_report(out: &Path, results: &[(Variant, Vec<Point>)]) -> Result<()> {
    let mut csv = String::from(
        "variant,width,blocks,layers,step,train_seconds,samples,residual_q1,residual_median,residual_q3,peak_median,bumps_above_half,data_like,diversity,mmd,cov,test_error\n",
    );
    let mut md = String::from(
        "| variant | step | train s | samples | residual median [q1, q3] | peak median | bumps > 1/2 | data-like | diversity | MMD | COV | test error |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut summary = String::from(
        "\n| variant | steps | train s | to residual <= 0.5 | to residual <= 0.35 | best residual |\n|---|---|---|---|---|---|\n",
    );
    for (v, points) in results {
        let (w, k, nl) = v.size;
        for p in points {
            let Some(Evaluated {
                quality: q,
                metrics: m,
            }) = &p.evaluated
            else {
                writeln!(
                    csv,
                    "{},{w},{k},{nl},{},{:.1},0,,,,,,,,,,",
                    v.name, p.step, p.seconds
                )?;
                writeln!(
                    md,
                    "| {} | {} | {:.0} | | sampling failed (see the log) | | | | | | | |",
                    v.name, p.step, p.seconds
                )?;
                continue;
            };
            writeln!(
                csv,
                "{},{w},{k},{nl},{},{:.1},{},{:.4},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{:.5},{:.3},{:.5}",
                v.name,
                p.step,
                p.seconds,
                m.num_generated,
                q.residual[0],
                q.residual[1],
                q.residual[2],
                q.peak[1],
                q.bumps,
                q.within,
                q.diversity,
                m.mmd,
                m.cov,
                m.test_error
            )?;
            writeln!(
                md,
                "| {} | {} | {:.0} | {} | {} | {:.4} | {:.3} | {:.4} |",
                v.name,
                p.step,
                p.seconds,
                m.num_generated,
                q.cells(),
                m.mmd,
                m.cov,
                m.test_error
            )?;
        }
        let reach = |b: f64| {
            first_below(points, b).map_or_else(
                || "not reached".to_owned(),
                |p| format!("{} steps, {:.0} s", p.step, p.seconds),
            )
        };
        let best = points
            .iter()
            .filter_map(|p| p.evaluated.as_ref())
            .map(|e| e.quality.residual[1])
            .fold(f64::INFINITY, f64::min);
        let best = if best.is_finite() {
            format!("{best:.3}")
        } else {
            "none sampled".to_owned()
        };
        let last = points.last();
        writeln!(
            summary,
            "| {} | {} | {:.0} | {} | {} | {} |",
            v.name,
            last.map_or(0, |p| p.step),
            last.map_or(0.0, |p| p.seconds),
            reach(0.5),
            reach(0.35),
            best
        )?;
    }
    std::fs::write(out.join("time_to_quality.csv"), csv)?;
    std::fs::write(out.join("time_to_quality.md"), format!("{md}{summary}"))?;
    print!("{md}{summary}");
    Ok(())
}

fn plot(path: &Path, results: &[(Variant, Vec<Point>)]) -> Result<()> {
    let curves = |f: &dyn Fn(&Point) -> (f64, f64)| -> Vec<Curve> {
        results
            .iter()
            .map(|(v, pts)| Curve {
                label: v.name.clone(),
                points: pts.iter().map(f).collect(),
            })
            .collect()
    };
    let panel =
        |title: &str, x: &str, y: &str, refs: Vec<(f64, String)>, c: Vec<Curve>| CurvePanel {
            title: title.into(),
            x_label: x.into(),
            y_label: y.into(),
            log_x: true,
            references: refs,
            curves: c,
        };
    let goal = |v: f64| vec![(v, "goal".to_owned())];
    let panels = vec![
        panel(
            "bump-fit residual (median)",
            "training steps",
            "residual",
            goal(GOAL.0),
            curves(&|p| (p.step as f64, p.value(|e| e.quality.residual[1]))),
        ),
        panel(
            "bump-fit residual (median)",
            "training seconds (wall)",
            "residual",
            goal(GOAL.0),
            curves(&|p| (p.seconds, p.value(|e| e.quality.residual[1]))),
        ),
        panel(
            "peak value (median)",
            "training steps",
            "peak",
            vec![(GOAL.1, "goal".into()), (1.0, "data".into())],
            curves(&|p| (p.step as f64, p.value(|e| e.quality.peak[1]))),
        ),
        panel(
            "bumps above half height per sample",
            "training steps",
            "bumps",
            vec![(GOAL.2, "goal".into()), (3.0, "data".into())],
            curves(&|p| (p.step as f64, p.value(|e| e.quality.bumps))),
        ),
        panel(
            "COV",
            "training steps",
            "COV",
            Vec::new(),
            curves(&|p| (p.step as f64, p.value(|e| e.metrics.cov))),
        ),
        panel(
            "GMM test error",
            "training steps",
            "test error",
            Vec::new(),
            curves(&|p| (p.step as f64, p.value(|e| e.metrics.test_error))),
        ),
    ];
    curve_grid(path, &panels, 3).with_context(|| format!("cannot draw {}", path.display()))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn variants_parse_with_and_without_settings() {
        let v: Variant = "W32-ema:32x3x3:train.ema=0.999;noise.scale=\"data\""
            .parse()
            .unwrap();
        assert_eq!(v.name, "W32-ema");
        assert_eq!(v.size, (32, 3, 3));
        assert_eq!(
            v.settings,
            vec![
                ("train".into(), "ema".into(), "0.999".into()),
                ("noise".into(), "scale".into(), "\"data\"".into())
            ]
        );
        assert_eq!(v.signals, DEFAULT_SIGNALS);
        let plain: Variant = "W16K2:16x2x2".parse().unwrap();
        assert!(plain.settings.is_empty());
        let more: Variant = "W32-4k:32x3x3:data.signals=4000;train.ema=0.999"
            .parse()
            .unwrap();
        assert_eq!(more.signals, 4000);
        assert_eq!(
            more.settings,
            vec![("train".into(), "ema".into(), "0.999".into())]
        );
        assert!(!more.config_toml().contains("signals ="));
        assert!(more.config_toml().contains("# trained on 4000 signals"));
        for bad in [
            "",
            "W:16x2",
            "W:16x2x2:ema=1",
            "bad name:16x2x2",
            "W:axbxc",
            "W:16x2x2:data.signals=1",
            "W:16x2x2:data.signals=many",
            "W:16x2x2:data.seed=3",
        ] {
            assert!(bad.parse::<Variant>().is_err(), "{bad:?} should be refused");
        }
    }

    #[test]
    fn variant_lists_split_outside_brackets_and_braces() {
        let list = "A:16x2x2:train.keep_at=[1000, 2000],B:32x3x3:train.lr_schedule={ warmup = 250, cosine = 3000 };train.ema=0.9,C:8x1x1,";
        let parts = split_variants(list);
        assert_eq!(
            parts,
            vec![
                "A:16x2x2:train.keep_at=[1000, 2000]",
                "B:32x3x3:train.lr_schedule={ warmup = 250, cosine = 3000 };train.ema=0.9",
                "C:8x1x1"
            ]
        );
        let b: Variant = parts[1].parse().unwrap();
        assert!(
            b.config_toml()
                .contains("lr_schedule = { warmup = 250, cosine = 3000 }\n")
        );
        assert!(!b.config_toml().contains("milestones"));
    }

    #[test]
    fn settings_replace_the_base_recipe_and_add_sections() {
        let v: Variant = "X:16x2x2:train.lr=1e-3;noise.scale=5.0".parse().unwrap();
        let toml = v.config_toml();
        assert!(toml.contains("lr = 1e-3\n"));
        assert!(!toml.contains("lr = 2e-3"));
        assert!(toml.contains("[noise]\nscale = 5.0\n"));
        assert!(toml.contains("keep_at = [100, 200, 500, 1000"));
    }
}
