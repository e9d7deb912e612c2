//! `cargo xtask bench train`: seconds per training step of `mfm train`, the
//! whole loop (data, noise, network, Adam, logs, checkpoints), at the two
//! CPU presets on generated datasets, repeated in rounds and, with
//! `--baseline`, interleaved with another `mfm` binary; and whether the two
//! binaries' final models are the same bytes (a change to the loop must
//! not change a run). The seconds are the training seconds of each run's
//! log (its last row), so process start and set-up are not counted.
//!
//! The rounds and per-round ratios work as in `bench net` (this VM's speed
//! drifts by 20-40% within minutes): each round trains every preset once
//! per binary, alternating which goes first.

use anyhow::{Context, Result, bail};
use std::ffi::OsStr;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use mfm_reproduce::mfm::Mfm;

use crate::bench_net::{median, paired_ratios, spread};

/// A preset and the dataset it trains on.
struct Case {
    preset: &'static str,
    /// `mfm dataset` arguments (after `dataset`), `--out` appended.
    dataset: &'static [&'static str],
}

const CASES: [Case; 2] = [
    Case {
        preset: "cpu",
        dataset: &["gmm", "--n", "1000", "--reference", "10", "--seed", "0"],
    },
    Case {
        preset: "cpu-deform",
        dataset: &[
            "deform",
            "--mesh",
            "builtin:capsule",
            "--n",
            "64",
            "--reference",
            "4",
        ],
    },
];

/// Settings of one `cargo xtask bench train` run.
pub struct TrainBench<'a> {
    /// Comma-separated presets (`cpu`, `cpu-deform`).
    pub presets: &'a str,
    /// Rounds (each trains every preset once per binary).
    pub rounds: usize,
    /// Training steps per run.
    pub steps: u64,
    /// A second `mfm` binary to interleave with.
    pub baseline: Option<&'a Path>,
}

/// Seconds per step of a finished run in `run`: the training seconds of
/// the last row of its log (`step,loss,lr,grad_norm,seconds`, written
/// with millisecond digits by this build and older ones alike) over its
/// step.
fn seconds_per_step(run: &Path) -> Result<f64> {
    let path = run.join(mfm_files::owned::RUN_LOG);
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let last = text
        .lines()
        .skip(1)
        .last()
        .with_context(|| format!("{}: no rows", path.display()))?;
    let fields: Vec<&str> = last.split(',').collect();
    let number = |i: usize| -> Result<f64> {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .with_context(|| format!("{}: unreadable row {last:?}", path.display()))
    };
    let (step, seconds) = (number(0)?, number(4)?);
    if step < 1.0 {
        bail!("{}: the last row is at step {step}", path.display());
    }
    Ok(seconds / step)
}

/// Trains `preset` on `data` for `steps` steps into `out` with `mfm` and
/// returns its seconds per step.
fn train(mfm: &Mfm, preset: &str, data: &Path, steps: u64, out: &Path) -> Result<f64> {
    let os = OsStr::new;
    let steps = steps.to_string();
    mfm.output(&[
        os("train"),
        os("--preset"),
        os(preset),
        os("--steps"),
        os(&steps),
        os("--dataset"),
        data.as_os_str(),
        os("--out"),
        out.as_os_str(),
        os("--quiet"),
    ])?;
    seconds_per_step(out)
}

/// Runs the benchmark in `work` (emptied first) and prints (and writes
/// there) a Markdown table.
pub fn train_steps(exe: &Path, bench: &TrainBench<'_>, work: &Path) -> Result<()> {
    if bench.rounds == 0 || bench.steps == 0 {
        bail!("--rounds and --steps must be at least 1");
    }
    if let Some(b) = bench.baseline.filter(|b| !b.is_file()) {
        bail!("--baseline {}: no such file", b.display());
    }
    let mut cases = Vec::new();
    for name in bench.presets.split(',').map(str::trim) {
        cases.push(
            CASES
                .iter()
                .find(|c| c.preset == name)
                .with_context(|| format!("--presets: unknown preset {name:?} (cpu, cpu-deform)"))?,
        );
    }
    if work.exists() {
        std::fs::remove_dir_all(work)
            .with_context(|| format!("cannot empty {}", work.display()))?;
    }
    std::fs::create_dir_all(work).with_context(|| format!("cannot create {}", work.display()))?;
    let this = Mfm::at(exe).quiet();
    let mut data = Vec::new();
    for c in &cases {
        let out = work.join(format!("data-{}", c.preset));
        let mut args = vec![OsStr::new("dataset")];
        args.extend(c.dataset.iter().map(OsStr::new));
        args.extend([OsStr::new("--out"), out.as_os_str()]);
        this.output(&args)?;
        data.push(out.join("train"));
    }
    let mut sides = vec![("this build", this)];
    if let Some(b) = bench.baseline {
        sides.push(("baseline", Mfm::at(b).quiet()));
    }
    // seconds[case][side]
    let mut seconds: Vec<Vec<Vec<f64>>> = cases
        .iter()
        .map(|_| vec![Vec::new(); sides.len()])
        .collect();
    for round in 0..bench.rounds {
        for (i, c) in cases.iter().enumerate() {
            let mut order: Vec<usize> = (0..sides.len()).collect();
            if round % 2 == 1 {
                order.reverse();
            }
            for side in order {
                let out = work.join(format!("run-{}-{side}-{round}", c.preset));
                let t = train(&sides[side].1, c.preset, &data[i], bench.steps, &out)?;
                eprintln!(
                    "xtask: round {}/{} {} {}: {t:.4} s/step",
                    round + 1,
                    bench.rounds,
                    c.preset,
                    sides[side].0
                );
                seconds[i][side].push(t);
            }
        }
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} rounds of {} steps per preset and binary; median [range] over rounds\n",
        bench.rounds, bench.steps
    );
    if bench.baseline.is_some() {
        let _ = writeln!(
            s,
            "| preset | s/step | baseline s/step | step / baseline | final models |\n|---|---|---|---|---|"
        );
    } else {
        let _ = writeln!(s, "| preset | s/step |\n|---|---|");
    }
    for (i, c) in cases.iter().enumerate() {
        let ours = &seconds[i][0];
        let _ = write!(s, "| {} | {} |", c.preset, spread(ours, 1.0, 4));
        if bench.baseline.is_some() {
            let theirs = &seconds[i][1];
            let same = (0..bench.rounds).all(|r| {
                let model = |side: usize| {
                    std::fs::read(
                        work.join(format!("run-{}-{side}-{r}", c.preset))
                            .join("model.safetensors"),
                    )
                    .ok()
                };
                let a = model(0);
                a.is_some() && a == model(1)
            });
            let _ = write!(
                s,
                " {} | {:.3} | {} |",
                spread(theirs, 1.0, 4),
                median(&paired_ratios(theirs, ours)),
                if same { "identical bytes" } else { "differ" }
            );
        }
        let _ = writeln!(s);
    }
    println!("{s}");
    let path = work.join("table.md");
    std::fs::write(&path, &s).with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!("xtask: wrote {}", path.display());
    Ok(())
}

/// Where the datasets, runs and table go.
pub fn output_dir() -> PathBuf {
    mfm_reproduce::workspace::target_dir().join("bench-train")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_seconds_per_step_are_the_last_log_row_s() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join(mfm_files::owned::RUN_LOG);
        std::fs::write(
            &log,
            "step,loss,lr,grad_norm,seconds\n100,1,1,1,3.100\n150,1,1,1,4.500\n",
        )
        .unwrap();
        assert!((seconds_per_step(dir.path()).unwrap() - 0.03).abs() < 1e-15);
        std::fs::write(&log, "step,loss,lr,grad_norm,seconds\n").unwrap();
        assert!(seconds_per_step(dir.path()).is_err());
        std::fs::write(&log, "step,loss,lr,grad_norm,seconds\n150,1,1,1,fast\n").unwrap();
        assert!(seconds_per_step(dir.path()).is_err());
    }
}
