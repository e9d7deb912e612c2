//! What the `mfm` binary's test files share: running it in a folder and
//! expecting success or a refusal.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Runs `mfm ARGS` in `dir`.
pub fn mfm_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mfm"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("the mfm binary runs")
}

/// The standard error of `o`.
pub fn err(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The standard output of `o`.
pub fn out(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs and expects failure with `needle` in the one-line error.
#[track_caller]
pub fn refused(dir: &Path, args: &[&str], needle: &str) -> String {
    let o = mfm_in(dir, args);
    assert!(!o.status.success(), "{args:?} succeeded: {}", err(&o));
    let e = err(&o);
    assert!(e.contains(needle), "{args:?}: expected `{needle}` in: {e}");
    e
}

/// Runs and expects success.
#[track_caller]
pub fn ok(dir: &Path, args: &[&str]) -> Output {
    let o = mfm_in(dir, args);
    assert!(o.status.success(), "{args:?}: {}", err(&o));
    o
}

/// The tiny run configuration the training checks start from (4 steps of
/// a width-8 network, checkpoints every 2).
pub const TINY: &str = "[model]\npreset = \"small\"\nwidth = 8\nblocks = 1\nvector_layers = 1\n\
[train]\nsteps = 4\nbatch = 2\ncheckpoint_every = 2\nlog_every = 1\n[sample]\nsteps = 2\n";

/// Starts `mfm ARGS` in `dir`, waits (polling every millisecond, up to
/// two minutes) until `ready(pid)` holds, sends it each of `signals` in
/// turn (`-TERM`, `-KILL`...) and returns its output.
#[track_caller]
pub fn signals_when(
    dir: &Path,
    args: &[&str],
    ready: impl Fn(u32) -> bool,
    signals: &[&str],
) -> Output {
    let child = Command::new(env!("CARGO_BIN_EXE_mfm"))
        .current_dir(dir)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the mfm binary runs");
    let t0 = std::time::Instant::now();
    while !ready(child.id()) {
        assert!(t0.elapsed().as_secs() < 120, "{args:?} did not get going");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    for signal in signals {
        let sent = Command::new("kill")
            .args([*signal, &child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(sent.success());
    }
    child.wait_with_output().expect("the mfm binary ends")
}

/// [`signals_when`] with one signal, once `ready()` holds.
#[track_caller]
pub fn interrupt_when(dir: &Path, args: &[&str], ready: impl Fn() -> bool, signal: &str) -> Output {
    signals_when(dir, args, |_| ready(), &[signal])
}
