//! The `mfm` binary as the reproductions run it: built once (release, with
//! the project's libtorch) on first use, then run with its output live,
//! captured, or measured for peak memory. Every call of the binary goes
//! through [`Mfm::command`].

use anyhow::{Context, Result};
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use crate::pyenv::PyEnv;
use crate::workspace;

/// Builds the release `mfm` binary with the project environment and returns
/// its path.
///
/// # Errors
/// When cargo fails or the binary is not where it should be.
pub fn build_release(env: &PyEnv) -> Result<PathBuf> {
    workspace::run(workspace::cargo(env).args(["build", "--release", "--quiet", "-p", "mfm-cli"]))?;
    let exe = workspace::target_dir().join("release/mfm");
    anyhow::ensure!(exe.is_file(), "built mfm not found at {}", exe.display());
    Ok(exe)
}

/// Where the binary comes from.
#[derive(Debug)]
enum Source {
    /// Built by [`build_release`] on first use.
    Build(PyEnv),
    /// A binary at hand.
    At(PathBuf),
}

/// The `mfm` binary.
#[derive(Debug)]
pub struct Mfm {
    source: Source,
    exe: OnceLock<PathBuf>,
    echo: bool,
}

impl Mfm {
    /// The release binary of this workspace, built with `env`'s libtorch
    /// when first needed (a build that is up to date takes a second).
    pub fn build(env: &PyEnv) -> Self {
        Self {
            source: Source::Build(env.clone()),
            exe: OnceLock::new(),
            echo: true,
        }
    }

    /// The binary at `exe` (e.g. one built before, for tests).
    pub fn at(exe: impl Into<PathBuf>) -> Self {
        Self {
            source: Source::At(exe.into()),
            exe: OnceLock::new(),
            echo: true,
        }
    }

    /// Without the `$ mfm ARGS` line before each run.
    pub fn quiet(mut self) -> Self {
        self.echo = false;
        self
    }

    /// The binary's path, built first if it comes from the workspace.
    ///
    /// # Errors
    /// When the build fails, or a given binary is not a file.
    pub fn exe(&self) -> Result<&Path> {
        if let Some(exe) = self.exe.get() {
            return Ok(exe);
        }
        let exe = match &self.source {
            Source::Build(env) => build_release(env)?,
            Source::At(exe) => {
                anyhow::ensure!(exe.is_file(), "mfm binary {} not found", exe.display());
                exe.clone()
            }
        };
        Ok(self.exe.get_or_init(|| exe))
    }

    /// `mfm ARGS` as a command, not yet started (standard streams
    /// inherited unless changed).
    ///
    /// # Errors
    /// Those of [`Mfm::exe`].
    pub fn command<S: AsRef<OsStr>>(&self, args: &[S]) -> Result<Command> {
        let mut cmd = Command::new(self.exe()?);
        cmd.args(args);
        Ok(cmd)
    }

    fn announce<S: AsRef<OsStr>>(&self, args: &[S]) {
        if self.echo {
            println!("$ mfm {}", call(args));
        }
    }

    /// Runs `mfm ARGS` with the terminal attached (progress bars stay
    /// live).
    ///
    /// # Errors
    /// When it cannot start or fails.
    pub fn run<S: AsRef<OsStr>>(&self, args: &[S]) -> Result<()> {
        self.announce(args);
        let status = self
            .command(args)?
            .status()
            .with_context(|| format!("cannot run mfm {}", call(args)))?;
        anyhow::ensure!(status.success(), "mfm {} failed ({status})", call(args));
        Ok(())
    }

    /// Runs `mfm ARGS` to its end, then prints what it wrote (standard
    /// output, then standard error) and returns its standard output.
    ///
    /// # Errors
    /// When it cannot start or fails.
    pub fn output<S: AsRef<OsStr>>(&self, args: &[S]) -> Result<String> {
        self.announce(args);
        let out = self
            .command(args)?
            .output()
            .with_context(|| format!("cannot run mfm {}", call(args)))?;
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        print!("{stdout}");
        eprint!("{}", String::from_utf8_lossy(&out.stderr));
        anyhow::ensure!(
            out.status.success(),
            "mfm {} failed ({})",
            call(args),
            out.status
        );
        Ok(stdout)
    }

    /// Runs `mfm ARGS` (terminal attached) and returns its peak resident
    /// memory in bytes ([`run_with_peak_memory`]).
    ///
    /// # Errors
    /// As [`run_with_peak_memory`].
    pub fn run_with_peak_memory<S: AsRef<OsStr>>(&self, args: &[S]) -> Result<u64> {
        self.announce(args);
        run_with_peak_memory(&mut self.command(args)?)
    }
}

/// The arguments as one line.
fn call<S: AsRef<OsStr>>(args: &[S]) -> String {
    args.iter()
        .map(|a| a.as_ref().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Runs `cmd` (with the standard streams it was given) to its end and
/// returns the peak resident memory of the process, in bytes (`wait4`);
/// a failure is an error with the program's arguments and, when `cmd`
/// pipes its standard error, what it wrote there.
///
/// # Errors
/// When it cannot start, cannot be waited for, or fails.
pub fn run_with_peak_memory(cmd: &mut Command) -> Result<u64> {
    let call = call(&cmd.get_args().collect::<Vec<_>>());
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_binary_is_named() {
        let mfm = Mfm::at("/nonexistent/mfm");
        let e = mfm.run(&["info"]).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/mfm"), "{e}");
    }

    #[test]
    fn peak_memory_of_a_child_and_its_failure() {
        let peak = run_with_peak_memory(Command::new("true").arg("x")).unwrap();
        assert!(peak > 0);
        let e = run_with_peak_memory(Command::new("false").arg("y"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("mfm y failed"), "{e}");
    }
}
