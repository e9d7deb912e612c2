//! `cargo xtask bench net`: PoissonNet training-step and batch-1 inference
//! times (`mfm net bench`) at the three presets, repeated in rounds and,
//! with `--baseline`, interleaved with another `mfm` binary, next to the
//! reference PyTorch implementation's times (docs/BENCHMARKS.md, "Reference numbers").
//!
//! Why rounds and interleaving: on a shared virtual machine the speed of the
//! same binary drifts by 20-40% within minutes, so one run of each side says
//! little. Each round runs every preset once per binary, alternating which
//! binary goes first; the table gives the median and range over rounds and,
//! for a baseline, the median of the per-round ratios (the two runs of a
//! round are seconds apart, so they see nearly the same machine).

use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A preset with its benchmark batch and the reference PyTorch
/// PoissonNet's times on the 2-core benchmark machine (docs/BENCHMARKS.md, "Reference numbers":
/// training step in seconds, batch-1 inference in seconds).
struct Reference {
    preset: &'static str,
    batch: usize,
    step: f64,
    inference: f64,
}

const REFERENCES: [Reference; 3] = [
    Reference {
        preset: "paper",
        batch: 8,
        step: 10.7,
        inference: 0.441,
    },
    Reference {
        preset: "medium",
        batch: 8,
        step: 3.3,
        inference: 0.151,
    },
    Reference {
        preset: "small",
        batch: 4,
        step: 0.71,
        inference: 0.075,
    },
];

/// Settings of one `cargo xtask bench net` run.
pub struct NetBench<'a> {
    /// Mesh file (or `builtin:NAME`).
    pub mesh: &'a str,
    /// Comma-separated presets.
    pub presets: &'a str,
    /// Rounds (each runs every preset once per binary).
    pub rounds: usize,
    /// Timed training steps per run (the run reports their median).
    pub steps: usize,
    /// libtorch threads.
    pub threads: usize,
    /// A second `mfm` binary to interleave with.
    pub baseline: Option<&'a Path>,
}

/// Median training step and batch-1 inference of one `mfm net bench` run, in
/// seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
struct RunTimes {
    step: f64,
    inference: f64,
}

/// Reads the medians from `mfm net bench`'s text report (the text, not a
/// JSON flag, so that binaries from older commits can be the baseline).
fn parse_report(text: &str) -> Result<RunTimes> {
    let value_after_colon = |prefix: &str| -> Result<f64> {
        let line = text
            .lines()
            .find(|l| l.starts_with(prefix))
            .with_context(|| format!("no line starting with {prefix:?} in the report"))?;
        let (_, rest) = line
            .split_once("): ")
            .with_context(|| format!("unexpected line {line:?}"))?;
        let number = rest.split_whitespace().next().unwrap_or("");
        number
            .parse::<f64>()
            .with_context(|| format!("cannot read a number in {line:?}"))
    };
    Ok(RunTimes {
        step: value_after_colon("training step")?,
        inference: value_after_colon("inference, batch 1")? * 1e-3,
    })
}

/// The median of a sample (`NaN` when empty).
pub(crate) fn median(xs: &[f64]) -> f64 {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// `median [min-max]` of a sample, scaled by `unit` and printed with
/// `decimals`.
pub(crate) fn spread(xs: &[f64], unit: f64, decimals: usize) -> String {
    let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    format!(
        "{:.d$} [{:.d$}-{:.d$}]",
        median(xs) * unit,
        lo * unit,
        hi * unit,
        d = decimals
    )
}

/// Per-round ratios `b / a`, paired by round.
pub(crate) fn paired_ratios(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| y / x).collect()
}

fn run_once(exe: &Path, bench: &NetBench<'_>, r: &Reference) -> Result<RunTimes> {
    let out = Command::new(exe)
        .args(["net", "bench", bench.mesh, "--preset", r.preset])
        .args(["--batch", &r.batch.to_string()])
        .args(["--steps", &bench.steps.to_string()])
        .args(["--threads", &bench.threads.to_string()])
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    let text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        bail!(
            "{} net bench --preset {} failed ({}): {}",
            exe.display(),
            r.preset,
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    parse_report(&text).with_context(|| format!("reading the report of {}", exe.display()))
}

/// Runs the benchmark and prints (and writes under `out`) a Markdown table.
pub fn net(exe: &Path, bench: &NetBench<'_>, out: &Path) -> Result<()> {
    if bench.rounds == 0 || bench.steps == 0 || bench.threads == 0 {
        bail!("--rounds, --steps and --threads must be at least 1");
    }
    if let Some(b) = bench.baseline.filter(|b| !b.is_file()) {
        bail!("--baseline {}: no such file", b.display());
    }
    let mut refs = Vec::new();
    for name in bench.presets.split(',').map(str::trim) {
        let r = REFERENCES
            .iter()
            .find(|r| r.preset == name)
            .with_context(|| {
                format!("--presets: unknown preset {name:?} (paper, medium, small)")
            })?;
        refs.push(r);
    }
    // times[preset][0 = this build, 1 = baseline]
    let mut times: Vec<[Vec<RunTimes>; 2]> =
        refs.iter().map(|_| [Vec::new(), Vec::new()]).collect();
    for round in 0..bench.rounds {
        for (i, r) in refs.iter().enumerate() {
            let mut order: Vec<usize> = if bench.baseline.is_some() {
                vec![0, 1]
            } else {
                vec![0]
            };
            if round % 2 == 1 {
                order.reverse();
            }
            for side in order {
                let exe_side = if side == 0 {
                    exe
                } else {
                    bench.baseline.unwrap_or(exe)
                };
                let t = run_once(exe_side, bench, r)?;
                eprintln!(
                    "xtask: round {}/{} {} {}: step {:.3} s, inference {:.1} ms",
                    round + 1,
                    bench.rounds,
                    r.preset,
                    if side == 0 { "this build" } else { "baseline" },
                    t.step,
                    t.inference * 1e3
                );
                times[i][side].push(t);
            }
        }
    }
    let table = table(&refs, &times, bench);
    println!("{table}");
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let path = out.join("table.md");
    std::fs::write(&path, &table).with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!("xtask: wrote {}", path.display());
    Ok(())
}

fn table(refs: &[&Reference], times: &[[Vec<RunTimes>; 2]], bench: &NetBench<'_>) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "mesh {}, {} threads, {} rounds of {} timed steps; median [range] over rounds; \
         reference: docs/BENCHMARKS.md, \"Reference numbers\", goal: a third of it\n",
        bench.mesh, bench.threads, bench.rounds, bench.steps
    );
    let base = bench.baseline.is_some();
    let mut header = "| preset | batch |".to_owned();
    let mut rule = "|---|---|".to_owned();
    for m in &METRICS {
        let (name, unit) = (m.name, m.unit);
        header.push_str(&format!(" {name} ({unit}) |"));
        rule.push_str("---|");
        if base {
            header.push_str(&format!(" baseline {name} ({unit}) | {name} / baseline |"));
            rule.push_str("---|---|");
        }
        header.push_str(&format!(" reference / {name} | goal |"));
        rule.push_str("---|---|");
    }
    let _ = writeln!(s, "{header}\n{rule}");
    for (r, [ours, theirs]) in refs.iter().zip(times) {
        let mut row = format!("| {} | {} |", r.preset, r.batch);
        for m in &METRICS {
            let ours: Vec<f64> = ours.iter().map(m.of_run).collect();
            let theirs: Vec<f64> = theirs.iter().map(m.of_run).collect();
            let _ = write!(row, " {} |", spread(&ours, m.scale, m.decimals));
            if base {
                let _ = write!(
                    row,
                    " {} | {:.3} |",
                    spread(&theirs, m.scale, m.decimals),
                    median(&paired_ratios(&theirs, &ours))
                );
            }
            let reference = (m.of_reference)(r);
            let _ = write!(
                row,
                " {:.2}x | {:.d$} {} |",
                reference / median(&ours),
                reference / 3.0 * m.scale,
                m.unit,
                d = m.goal_decimals
            );
        }
        let _ = writeln!(s, "{row}");
    }
    s
}

/// A measured quantity of the table: how it is read from a run and from
/// the reference, and how it is printed.
struct Metric {
    name: &'static str,
    unit: &'static str,
    /// Seconds to `unit`.
    scale: f64,
    decimals: usize,
    goal_decimals: usize,
    of_run: fn(&RunTimes) -> f64,
    of_reference: fn(&Reference) -> f64,
}

const METRICS: [Metric; 2] = [
    Metric {
        name: "step",
        unit: "s",
        scale: 1.0,
        decimals: 3,
        goal_decimals: 3,
        of_run: |t| t.step,
        of_reference: |r| r.step,
    },
    Metric {
        name: "inference",
        unit: "ms",
        scale: 1e3,
        decimals: 1,
        goal_decimals: 0,
        of_run: |t| t.inference,
        of_reference: |r| r.inference,
    },
];

/// Where the table goes.
pub fn output_dir() -> PathBuf {
    mfm_reproduce::workspace::target_dir().join("bench-net")
}

#[cfg(test)]
mod tests {
    use super::*;

    const REPORT: &str = "preset small (W32 K3 nl3) on Cpu
mesh: 3485 vertices, 6966 faces; 56000 parameters; batch 4; 2 threads
setup (operators + factor): 15.5 ms
training step (median of 10): 0.357 s  [forward 0.138 s, backward 0.211 s, adam 0.007 s; cpu 0.573 s]
inference, batch 1 (median of 5): 44.7 ms
";

    #[test]
    fn reads_the_medians_of_a_report() {
        let t = parse_report(REPORT).unwrap();
        assert_eq!(t.step, 0.357);
        assert!((t.inference - 0.0447).abs() < 1e-12);
        let no_inference: String = REPORT
            .lines()
            .filter(|l| !l.starts_with("inference"))
            .collect::<Vec<_>>()
            .join("\n");
        assert!(parse_report(&no_inference).is_err());
        assert!(parse_report("training step (median of 3): fast s").is_err());
    }

    #[test]
    fn ratios_are_paired_by_round_and_medians_are_medians() {
        assert_eq!(paired_ratios(&[1.0, 2.0], &[0.5, 3.0]), vec![0.5, 1.5]);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(spread(&[0.3, 0.1, 0.2], 1e3, 0), "200 [100-300]");
    }

    #[test]
    fn table_has_a_row_per_preset_and_baseline_columns_only_with_a_baseline() {
        let refs: Vec<&Reference> = REFERENCES.iter().filter(|r| r.preset == "small").collect();
        let t = |step, inference| RunTimes { step, inference };
        let times = vec![[
            vec![t(0.24, 0.025), t(0.26, 0.027)],
            vec![t(0.30, 0.030), t(0.26, 0.030)],
        ]];
        let mut bench = NetBench {
            mesh: "m.off",
            presets: "small",
            rounds: 2,
            steps: 5,
            threads: 2,
            baseline: None,
        };
        let plain = table(&refs, &times, &bench);
        assert!(!plain.contains("baseline"));
        assert!(
            plain.contains("| small | 4 | 0.250 [0.240-0.260] |"),
            "{plain}"
        );
        // 0.71 / 0.25 and 75 / 26 ms
        assert!(
            plain.contains(" 2.84x |") && plain.contains(" 2.88x |"),
            "{plain}"
        );
        let path = PathBuf::from("old-mfm");
        bench.baseline = Some(&path);
        let with = table(&refs, &times, &bench);
        // per-round ratios 0.8 and 1.0 -> 0.9; inference 0.833, 0.9 -> 0.867
        assert!(
            with.contains("| 0.900 |") && with.contains("| 0.867 |"),
            "{with}"
        );
    }
}
