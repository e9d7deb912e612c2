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
