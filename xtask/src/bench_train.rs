//! `cargo xtask bench train`: seconds per training step of `mfm train`, the
//! whole loop (data, noise, network, Adam, logs, checkpoints), at the two
//! CPU presets on generated datasets, repeated in rounds and, with
//! `--baseline`, interleaved with another `mfm` binary; and whether the two
//! binaries' final models are the same bytes (a change to the loop must
//! not change a run).
//!
//! The rounds and per-round ratios work as in `bench net` (this VM's speed
//! drifts by 20-40% within minutes): each round trains every preset once
//! per binary, alternating which goes first.

use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

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

/// Seconds per step from `mfm train`'s summary line, "... (T s/step) ...":
/// the text, so that binaries of older commits can be the baseline.
fn seconds_per_step(stdout: &str) -> Result<f64> {
    let line = stdout
        .lines()
        .find(|l| l.contains(" s/step)"))
        .context("no summary line with \"s/step\" in mfm train's output")?;
    let (before, _) = line.split_once(" s/step)").unwrap_or((line, ""));
    let number = before.rsplit('(').next().unwrap_or("");
    number
        .trim()
        .parse::<f64>()
        .with_context(|| format!("cannot read the seconds per step in {line:?}"))
}

fn train(exe: &Path, preset: &str, data: &Path, steps: u64, out: &Path) -> Result<f64> {
    let o = Command::new(exe)
        .args(["train", "--preset", preset, "--steps", &steps.to_string()])
        .arg("--dataset")
        .arg(data)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    if !o.status.success() {
        bail!(
            "{} train --preset {preset} failed ({}): {}",
            exe.display(),
            o.status,
            String::from_utf8_lossy(&o.stderr).trim()
        );
    }
    seconds_per_step(&String::from_utf8_lossy(&o.stdout))
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
    let mut data = Vec::new();
    for c in &cases {
        let out = work.join(format!("data-{}", c.preset));
        let o = Command::new(exe)
            .arg("dataset")
            .args(c.dataset)
            .arg("--out")
            .arg(&out)
            .output()
            .with_context(|| format!("cannot run {}", exe.display()))?;
        if !o.status.success() {
            bail!(
                "mfm dataset for {}: {}",
                c.preset,
                String::from_utf8_lossy(&o.stderr).trim()
            );
        }
        data.push(out.join("train"));
    }
    let sides: Vec<(&str, &Path)> = match bench.baseline {
        Some(b) => vec![("this build", exe), ("baseline", b)],
        None => vec![("this build", exe)],
    };
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
                let t = train(sides[side].1, c.preset, &data[i], bench.steps, &out)?;
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
    fn reads_the_seconds_per_step_of_both_summary_forms() {
        let new =
            "dataset d: 4 signals\nsteps 0..150 of 150 in 21.3 s (0.142 s/step), last loss 1.55\n";
        let old = "steps 0..150 in 18.3 s (0.122 s/step), last loss 1.55\n";
        assert_eq!(seconds_per_step(new).unwrap(), 0.142);
        assert_eq!(seconds_per_step(old).unwrap(), 0.122);
        assert!(seconds_per_step("steps 0..150 in 1 s, last loss 1").is_err());
        assert!(seconds_per_step("(fast s/step)").is_err());
    }
}
