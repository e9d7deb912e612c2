//! The folder `mfm sample` writes: samples streamed to `samples.npy`
//! `[N, V, C]` (`f32`), the mesh as `mesh.ply`, the first samples as
//! [`sample_ply_name`] files, a picture (`samples.png`) and
//! [`SampleTiming`] (`timing.json`).
//!
//! [`SampleFolder::write`] checks its outputs first (none may be a file of
//! the run or the mesh; enough free space for the `.npy`), and removes what
//! it created if sampling fails; a folder written before keeps everything
//! but the names it writes (and stale [`sample_ply_name`] files of an
//! earlier, longer run, which it removes).

use std::path::{Path, PathBuf};

use mfm_geometry::TriMesh;

use mfm_train::checkpoint::{CHECKPOINTS_DIR, NET_CONFIG_FILE, WEIGHTS_FILE};

use crate::checkpoint::{CONFIG_FILE, FLOW_FILE};
use crate::config::RunConfig;
use crate::error::{FmError, Result};
use crate::sample::{
    SAMPLE_FILES, SampleOptions, SampleRequest, SampleTiming, Sampler, is_sample_ply,
    sample_ply_name,
};

/// The integration options a run folder asks for: its `config.toml`'s
/// `[sample]` table; `None` when the run has no `config.toml` (the caller
/// says which defaults it assumes).
///
/// # Errors
/// [`FmError::Config`] (or `Files`) naming the file when it exists but does
/// not read as a run configuration: a damaged run is not sampled with
/// options it never asked for.
pub fn run_sample_options(run: &Path) -> Result<Option<SampleOptions>> {
    let path = run.join(CONFIG_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let config = RunConfig::from_toml_file(&path)?;
    Ok(Some(SampleOptions::from(&config.sample)))
}

/// Refuses an output folder that is not a folder, or one with anything in
/// it unless `replace` (`--force` of `command`, e.g. `mfm sample`), naming
/// the files the command writes (`writes`) so the user knows what would be
/// replaced. Even with `replace`, a dataset, experiment or training run
/// folder ([`protected_folder_kind`]) is refused: `--force` replaces a
/// command's own outputs, never another command's folder.
///
/// # Errors
/// [`FmError::RunFolder`].
pub fn check_output_folder(
    out: &Path,
    replace: bool,
    command: &str,
    writes: &[&str],
) -> Result<()> {
    if out.exists() && !out.is_dir() {
        return Err(FmError::RunFolder(format!(
            "--out {}: exists and is not a folder",
            out.display()
        )));
    }
    // the temporaries of a writer killed here (SIGKILL) are not content
    mfm_files::interrupt::remove_stale_temporaries(out, None);
    let non_empty = std::fs::read_dir(out).is_ok_and(|mut d| d.next().is_some());
    if non_empty && !replace {
        return Err(FmError::RunFolder(format!(
            "{} exists and is not empty; choose another --out, or add --force to replace what \
`{command}` writes there ({}; nothing else is touched)",
            out.display(),
            writes.join(", ")
        )));
    }
    if let Some((kind, marker)) = protected_folder_kind(out) {
        return Err(FmError::RunFolder(format!(
            "--out {}: is {kind} (it holds {marker}); --force never writes into a dataset, \
experiment or run folder: choose another --out",
            out.display()
        )));
    }
    Ok(())
}

/// What kind of mfm folder `dir` is, when it is one no other command may
/// write into, and the file that shows it: a folder
/// [`mfm_files::owned::owned_folder_kind`] names, or one holding a run's
/// [`CONFIG_FILE`] (for `--force`, which clears a folder: a configuration
/// there may be a run's that has not written anything else yet).
pub fn protected_folder_kind(dir: &Path) -> Option<(&'static str, String)> {
    mfm_files::owned::owned_folder_kind(dir).or_else(|| {
        dir.join(CONFIG_FILE)
            .exists()
            .then(|| ("a training run folder", CONFIG_FILE.to_owned()))
    })
}

/// What [`SampleFolder::write`] draws and where.
#[derive(Clone, Copy, Debug)]
pub struct SampleFolder<'a> {
    /// The run folder the sampler was loaded from (its files are inputs).
    pub run: &'a Path,
    /// The mesh's file, `None` for a built-in mesh (an input too).
    pub mesh_file: Option<&'a Path>,
    /// The file of the starting noise (`mfm sample --x0`), an input too:
    /// never replaced by the samples.
    pub start_file: Option<&'a Path>,
    /// The output folder.
    pub out: &'a Path,
    /// Samples `0..count` of the seed's sequence.
    pub count: usize,
    /// The noise seed.
    pub seed: u64,
    /// How many of the first samples to also write as PLY.
    pub ply: usize,
    /// Show a progress bar.
    pub progress: bool,
}

impl SampleFolder<'_> {
    /// The files it writes, in order: [`SAMPLE_FILES`], then the PLY files.
    pub fn outputs(&self) -> Vec<PathBuf> {
        let mut outputs: Vec<PathBuf> = SAMPLE_FILES.iter().map(|f| self.out.join(f)).collect();
        outputs.extend((0..self.ply.min(self.count)).map(|i| self.out.join(sample_ply_name(i))));
        outputs
    }

    /// Samples `mesh` with `sampler` and writes the folder (see the
    /// [module docs](self)); returns the timing it wrote.
    ///
    /// # Errors
    /// [`FmError::Config`] for no samples; the output guard's and free
    /// space's [`FmError::Files`]; the sampler's errors (a diverged sample
    /// writes nothing); the writers'.
    pub fn write(
        &self,
        sampler: &Sampler,
        mesh: &TriMesh,
        options: &SampleOptions,
    ) -> Result<SampleTiming> {
        let n = self.count;
        if n == 0 {
            return Err(FmError::Config("no samples asked for".into()));
        }
        let (v, c) = (mesh.num_vertices(), sampler.flow().channels);
        let outputs = self.outputs();
        let run_files = [
            CONFIG_FILE,
            FLOW_FILE,
            crate::prior::PRIOR_FILE,
            WEIGHTS_FILE,
            NET_CONFIG_FILE,
            CHECKPOINTS_DIR,
        ];
        let undo = mfm_files::Outputs::new()
            .inputs(run_files.map(|f| self.run.join(f)))
            .inputs(self.mesh_file)
            .inputs(self.start_file)
            .outputs(&outputs)
            .prepare()?;
        let shape = [n as u64, v as u64, c as u64];
        mfm_files::space::ensure_space(&outputs[0], mfm_files::npy::file_bytes(&shape, 4))?;
        self.remove_stale_plys(&outputs)?;
        let target = sampler.prepare(mesh)?;
        let keep = n.min(self.ply.max(mfm_data::pictures::SHOWN));
        let request = SampleRequest {
            count: n,
            seed: self.seed,
            keep,
            progress: self.progress,
        };
        let streamed = sampler.sample_to_npy(&target, &outputs[0], request, options)?;
        let signals = streamed.first;
        mfm_meshio::write_ply(&outputs[1], mesh, &[])?;
        for (i, path) in outputs[SAMPLE_FILES.len()..].iter().enumerate() {
            signals.write_ply(i, mesh, path)?;
        }
        let title = format!("{n} samples on {v} vertices");
        mfm_data::pictures::signals(mesh, &signals, "sample", &title, &outputs[2])?;
        let timing = SampleTiming {
            samples: n,
            vertices: v,
            channels: c,
            ode_steps: options.steps,
            method: format!("{:?}", options.method).to_lowercase(),
            seconds: streamed.seconds,
            noise_seconds: streamed.noise_seconds,
            seconds_per_sample: streamed.seconds / n as f64,
        };
        mfm_files::write_json(&outputs[3], &timing)?;
        undo.keep();
        Ok(timing)
    }

    /// Removes the [`sample_ply_name`] files in the folder that this run
    /// does not write (left by an earlier run with more of them).
    fn remove_stale_plys(&self, outputs: &[PathBuf]) -> Result<()> {
        let Ok(entries) = std::fs::read_dir(self.out) else {
            return Ok(());
        };
        for e in entries.flatten() {
            let path = e.path();
            let stale = is_sample_ply(&e.file_name().to_string_lossy()) && !outputs.contains(&path);
            if stale {
                std::fs::remove_file(&path).map_err(|err| FmError::io(&path, err))?;
            }
        }
        Ok(())
    }
}
