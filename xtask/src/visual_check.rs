//! `cargo xtask visual-check DIR`: contact sheets of the PLY files under `DIR`.
//!
//! Every folder under `DIR` (itself included) that holds `.ply` files gets one
//! PNG sheet (more when it has more files than `--per-sheet`): a grid of tiles,
//! one per file, titled with the file name. A mesh with per-vertex scalar
//! properties (`mfm` writes signals as `property double NAME`) is colored by
//! one of them, a mesh without is drawn shaded; the color bar is shared by the
//! sheet when all its tiles show the same property, else drawn per tile.
//! Files are ordered naturally (`s2` before `s10`); hidden files and the
//! output folder are skipped. The camera follows `mfm render`'s rig (`--up`,
//! `--azimuth`, `--elevation`; default y up, 30° and 20°), orthographic, with
//! each mesh's projected vertices framed to fill its tile.
//!
//! Rendering is done by `xtask/python/visual_check.py` with pyvista (VTK) in
//! the project's Python environment, offscreen. VTK needs an OpenGL
//! implementation that works without a screen; this module finds one before
//! starting Python, in this order:
//! 1. `$VTK_DEFAULT_OPENGL_WINDOW` set by the user: used as is.
//! 2. `$DISPLAY` set, with `libGL.so.1` and `libX11.so.6`: VTK's default (X).
//! 3. EGL: `libEGL.so.1` with the NVIDIA vendor library, or with Mesa's and
//!    its software rasterizer (`dri/swrast_dri.so`).
//! 4. OSMesa (`libOSMesa.so.8`), Mesa's off-screen software renderer.
//!
//! When none is there, it installs Debian's `libosmesa6` with `apt-get`
//! (non-interactively; as root, or through `sudo -n`), saying so, and uses
//! OSMesa. Libraries are looked up in the `ldconfig` cache and
//! `$LD_LIBRARY_PATH`, which takes milliseconds, so a second run goes straight
//! to rendering. Should the renderer still crash (VTK segfaults when the
//! OpenGL library it picked cannot make a context), the run is repeated once
//! with OSMesa, installing it first if needed.

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use serde_json::{Value, json};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Arguments of `cargo xtask visual-check`.
#[derive(Args, Debug)]
pub struct VisualCheckArgs {
    /// Folder searched recursively for `.ply` files.
    pub dir: PathBuf,
    /// Folder for the PNG sheets [default: DIR/visual-check].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Vertex property to color by: a property name, `first` (each file's
    /// first scalar property) or `all` (one tile per property).
    #[arg(long, default_value = "first")]
    pub field: String,
    /// Color range: `shared` by the sheet, `per-tile`, or `auto` (shared when
    /// every colored tile of the sheet shows the same property).
    #[arg(long, value_enum, default_value_t = RangeMode::Auto)]
    pub range: RangeMode,
    /// Matplotlib colormap name.
    #[arg(long, default_value = "viridis")]
    pub cmap: String,
    /// Side of one rendered tile, in pixels.
    #[arg(long, default_value_t = 320, value_parser = clap::value_parser!(u32).range(64..=2048))]
    pub tile: u32,
    /// Tiles per row [default: about the square root of the tile count].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub columns: Option<u32>,
    /// Most files on one sheet; a folder with more gets several sheets.
    #[arg(long, default_value_t = 36, value_parser = clap::value_parser!(u32).range(1..))]
    pub per_sheet: u32,
    /// Which axis points up in the image (`y`, as `mfm render`, or `z`).
    #[arg(long, value_enum, default_value_t = UpAxis::Y)]
    pub up: UpAxis,
    /// Camera azimuth about the up axis, degrees (0 looks from +z with y up,
    /// from -y with z up; positive turns towards +x), as `mfm render`.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    pub azimuth: f64,
    /// Camera elevation above the horizontal plane, degrees (clamped to ±89).
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub elevation: f64,
}

/// How the colors of a sheet's tiles are scaled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RangeMode {
    /// Shared when all colored tiles show the same property, else per tile.
    Auto,
    /// One range (min to max over all colored tiles) and one color bar.
    Shared,
    /// Each tile its own range and color bar.
    PerTile,
}

/// The world axis that points up in every tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum UpAxis {
    /// `+y` up (scanned meshes such as the bunny; `mfm render`'s default).
    Y,
    /// `+z` up (CAD and many procedural meshes).
    Z,
}

impl RangeMode {
    fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Shared => "shared",
            Self::PerTile => "per-tile",
        }
    }
}

impl UpAxis {
    fn name(self) -> &'static str {
        match self {
            Self::Y => "y",
            Self::Z => "z",
        }
    }
}

/// One PNG to draw: its title, path and files (path, label).
#[derive(Debug, PartialEq)]
struct Sheet {
    title: String,
    out: PathBuf,
    files: Vec<(PathBuf, String)>,
}

/// Renders the sheets for `args.dir` with `python` (the project's
/// environment) and prints where they went. Fails when `DIR` has no PLY file,
/// when offscreen rendering cannot be set up, or (after writing the sheets)
/// when some files could not be read.
pub fn run(python: &Path, args: &VisualCheckArgs) -> Result<()> {
    let start = Instant::now();
    let dir = args
        .dir
        .canonicalize()
        .with_context(|| format!("cannot open folder {}", args.dir.display()))?;
    if !dir.is_dir() {
        bail!("{} is not a folder", dir.display());
    }
    let out = match &args.out {
        Some(o) if o.is_relative() => std::env::current_dir()
            .context("cannot read the current folder")?
            .join(o),
        Some(o) => o.clone(),
        None => dir.join("visual-check"),
    };
    let folders = collect_ply(&dir, &out)?;
    if folders.is_empty() {
        bail!("no .ply files under {}", dir.display());
    }
    std::fs::create_dir_all(&out)
        .with_context(|| format!("cannot create output folder {}", out.display()))?;
    let out = out
        .canonicalize()
        .with_context(|| format!("cannot open output folder {}", out.display()))?;
    let sheets = plan_sheets(&dir, &out, folders, args.per_sheet as usize);
    let script = mfm_reproduce::workspace::root().join("xtask/python/visual_check.py");
    let pid = std::process::id();
    let job_path = std::env::temp_dir().join(format!("mfm-visual-check-{pid}-job.json"));
    let result_path = std::env::temp_dir().join(format!("mfm-visual-check-{pid}-result.json"));
    let mut sheet_jobs = Vec::new();
    for s in &sheets {
        let mut files = Vec::new();
        for (path, label) in &s.files {
            files.push(json!({"path": utf8(path)?, "label": label}));
        }
        sheet_jobs.push(json!({"title": s.title, "out": utf8(&s.out)?, "files": files}));
    }
    let job = json!({
        "tile": args.tile,
        "cmap": args.cmap,
        "field": args.field,
        "range": args.range.name(),
        "up": args.up.name(),
        "azimuth": args.azimuth,
        "elevation": args.elevation.clamp(-89.0, 89.0),
        "columns": args.columns,
        "sheets": sheet_jobs,
    });
    std::fs::write(&job_path, serde_json::to_vec_pretty(&job)?)
        .with_context(|| format!("cannot write {}", job_path.display()))?;

    let _ = std::fs::remove_file(&result_path);
    let mut backend = choose_backend()?;
    println!("xtask: offscreen OpenGL: {}", backend.describe());
    let mut attempt = render(python, &script, &job_path, &result_path, &backend);
    let crashed = attempt
        .as_ref()
        .err()
        .and_then(|e| e.downcast_ref::<Crash>())
        .copied();
    let retry = matches!(backend, Backend::Display | Backend::Egl);
    if let (Some(Crash(signal)), true) = (crashed, retry) {
        eprintln!(
            "xtask: the renderer crashed (signal {signal}) with {}; retrying with OSMesa",
            backend.describe()
        );
        if !gl_support().osmesa {
            install_osmesa("the OpenGL library VTK chose cannot make a context")?;
        }
        backend = Backend::OsMesa;
        attempt = render(python, &script, &job_path, &result_path, &backend);
    }
    let _ = std::fs::remove_file(&job_path);
    attempt?;
    let text = std::fs::read_to_string(&result_path).with_context(|| {
        format!(
            "the renderer wrote no result file {}",
            result_path.display()
        )
    })?;
    let _ = std::fs::remove_file(&result_path);
    let result: Value = serde_json::from_str(&text)
        .with_context(|| format!("bad result file {}", result_path.display()))?;
    report(&result, &dir, start)
}

/// The path as UTF-8 (JSON strings for the renderer must be).
fn utf8(path: &Path) -> Result<&str> {
    path.to_str()
        .with_context(|| format!("{} is not valid UTF-8", path.display()))
}

/// Prints one line per sheet; fails when a file could not be read.
fn report(result: &Value, dir: &Path, start: Instant) -> Result<()> {
    let empty = Vec::new();
    let sheets = result["sheets"].as_array().unwrap_or(&empty);
    let mut failures = Vec::new();
    for s in sheets {
        let tiles = s["tiles"].as_u64().unwrap_or(0);
        let colored = s["colored"].as_u64().unwrap_or(0);
        let shaded = s["shaded"].as_u64().unwrap_or(0);
        let fields: Vec<&str> = s["fields"]
            .as_array()
            .unwrap_or(&empty)
            .iter()
            .filter_map(Value::as_str)
            .collect();
        let mut what = Vec::new();
        if colored > 0 {
            let range = match s["range"].as_array() {
                Some(r) if r.len() == 2 => format!(
                    ", shared range [{:.4}, {:.4}]",
                    r[0].as_f64().unwrap_or(f64::NAN),
                    r[1].as_f64().unwrap_or(f64::NAN)
                ),
                _ => ", range per tile".to_owned(),
            };
            what.push(format!("{colored} colored by {}{range}", fields.join("/")));
        }
        if shaded > 0 {
            what.push(format!("{shaded} shaded"));
        }
        let rgb = s["rgb"].as_u64().unwrap_or(0);
        if rgb > 0 {
            what.push(format!("{rgb} with their vertex colors"));
        }
        let errors = s["errors"].as_array().unwrap_or(&empty);
        if !errors.is_empty() {
            what.push(format!("{} failed", errors.len()));
        }
        println!(
            "wrote {}  ({tiles} tiles: {}; {:.1} s)",
            s["out"].as_str().unwrap_or("?"),
            what.join(", "),
            s["seconds"].as_f64().unwrap_or(f64::NAN)
        );
        for e in errors {
            let file = e["file"].as_str().unwrap_or("?");
            let error = e["error"].as_str().unwrap_or("?");
            failures.push(if error.contains(file) {
                error.to_owned()
            } else {
                format!("{file}: {error}")
            });
        }
    }
    println!(
        "xtask: {} sheet(s) for {} in {:.1} s",
        sheets.len(),
        dir.display(),
        start.elapsed().as_secs_f64()
    );
    if !failures.is_empty() {
        bail!(
            "{} file(s) could not be drawn (red tiles on the sheets):\n  {}",
            failures.len(),
            failures.join("\n  ")
        );
    }
    Ok(())
}

/// The renderer died from a signal (VTK crashes when it cannot make an
/// OpenGL context).
#[derive(Clone, Copy, Debug)]
struct Crash(i32);

impl std::fmt::Display for Crash {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the renderer was killed by signal {}", self.0)
    }
}

impl std::error::Error for Crash {}

fn render(
    python: &Path,
    script: &Path,
    job: &Path,
    result: &Path,
    backend: &Backend,
) -> Result<()> {
    let mut cmd = Command::new(python);
    cmd.arg(script)
        .arg(job)
        .arg(result)
        .env("MPLBACKEND", "Agg")
        .env("PYVISTA_OFF_SCREEN", "true");
    if let Some(window) = backend.vtk_window() {
        cmd.env("VTK_DEFAULT_OPENGL_WINDOW", window);
    }
    let status = cmd
        .status()
        .with_context(|| format!("cannot run {}", python.display()))?;
    if status.success() {
        return Ok(());
    }
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(signal) = status.signal() {
            return Err(anyhow::Error::new(Crash(signal)));
        }
    }
    bail!("{} failed ({status})", script.display())
}

/// The OpenGL route VTK is told to take.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Backend {
    /// `$VTK_DEFAULT_OPENGL_WINDOW` as the user set it.
    User(String),
    /// VTK's own choice (X, with its fallbacks).
    Display,
    /// `vtkEGLRenderWindow`.
    Egl,
    /// `vtkOSOpenGLRenderWindow`.
    OsMesa,
}

impl Backend {
    fn vtk_window(&self) -> Option<&'static str> {
        match self {
            Self::User(_) | Self::Display => None,
            Self::Egl => Some("vtkEGLRenderWindow"),
            Self::OsMesa => Some("vtkOSOpenGLRenderWindow"),
        }
    }

    fn describe(&self) -> String {
        match self {
            Self::User(w) => format!("{w} (from $VTK_DEFAULT_OPENGL_WINDOW)"),
            Self::Display => "the X display $DISPLAY".to_owned(),
            Self::Egl => "EGL (vtkEGLRenderWindow)".to_owned(),
            Self::OsMesa => "OSMesa (vtkOSOpenGLRenderWindow)".to_owned(),
        }
    }
}

/// Which OpenGL routes the installed libraries allow.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct GlSupport {
    display: bool,
    egl: bool,
    osmesa: bool,
}

/// Picks the backend, installing OSMesa when nothing else is there.
fn choose_backend() -> Result<Backend> {
    if let Some(w) = std::env::var("VTK_DEFAULT_OPENGL_WINDOW")
        .ok()
        .filter(|w| !w.is_empty())
    {
        return Ok(Backend::User(w));
    }
    let gl = gl_support();
    if gl.display {
        return Ok(Backend::Display);
    }
    if gl.egl {
        return Ok(Backend::Egl);
    }
    if !gl.osmesa {
        install_osmesa("no X display, no usable EGL and no OSMesa library were found")?;
    }
    Ok(Backend::OsMesa)
}

fn gl_support() -> GlSupport {
    let libs = shared_libraries();
    let has = |name: &str| libs.contains_key(name);
    let display = std::env::var_os("DISPLAY").is_some_and(|d| !d.is_empty())
        && has("libGL.so.1")
        && has("libX11.so.6");
    let mesa_software = libs.get("libEGL_mesa.so.0").is_some_and(|p| {
        p.parent().is_some_and(|d| {
            ["swrast_dri.so", "kms_swrast_dri.so"]
                .iter()
                .any(|f| d.join("dri").join(f).exists())
        })
    });
    let egl = has("libEGL.so.1") && (has("libEGL_nvidia.so.0") || mesa_software);
    let osmesa = has("libOSMesa.so.8") || has("libOSMesa.so.6");
    GlSupport {
        display,
        egl,
        osmesa,
    }
}

/// Shared libraries the dynamic loader can find: the `ldconfig -p` cache
/// (entries of this machine's architecture) and the files in
/// `$LD_LIBRARY_PATH`. Maps file name to path.
fn shared_libraries() -> HashMap<String, PathBuf> {
    let mut libs = HashMap::new();
    let arch_tag = match std::env::consts::ARCH {
        "x86_64" => Some("x86-64"),
        "aarch64" => Some("AArch64"),
        _ => None,
    };
    for ldconfig in ["ldconfig", "/sbin/ldconfig", "/usr/sbin/ldconfig"] {
        let Ok(out) = Command::new(ldconfig).arg("-p").output() else {
            continue;
        };
        if !out.status.success() {
            continue;
        }
        libs.extend(parse_ldconfig(
            &String::from_utf8_lossy(&out.stdout),
            arch_tag,
        ));
        break;
    }
    if let Some(paths) = std::env::var_os("LD_LIBRARY_PATH") {
        for dir in std::env::split_paths(&paths) {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for e in entries.flatten() {
                libs.entry(e.file_name().to_string_lossy().into_owned())
                    .or_insert_with(|| e.path());
            }
        }
    }
    libs
}

/// Parses `ldconfig -p` lines such as
/// `\tlibEGL.so.1 (libc6,x86-64) => /lib/x86_64-linux-gnu/libEGL.so.1`,
/// keeping entries whose tag names `arch_tag` (all when `None`).
fn parse_ldconfig(text: &str, arch_tag: Option<&str>) -> HashMap<String, PathBuf> {
    let mut libs = HashMap::new();
    for line in text.lines() {
        let Some((left, path)) = line.split_once(" => ") else {
            continue;
        };
        let Some((name, tag)) = left.trim().split_once(' ') else {
            continue;
        };
        if arch_tag.is_some_and(|a| !tag.contains(a)) {
            continue;
        }
        libs.entry(name.to_owned())
            .or_insert_with(|| PathBuf::from(path.trim()));
    }
    libs
}

/// Debian packages that give VTK an offscreen OpenGL without a display.
const OSMESA_PACKAGES: &[&str] = &["libosmesa6"];

/// Installs [`OSMESA_PACKAGES`] with `apt-get`, running `apt-get update` first
/// when the install fails (missing or stale package lists).
fn install_osmesa(why: &str) -> Result<()> {
    let packages = OSMESA_PACKAGES.join(" ");
    let manual = format!(
        "offscreen rendering needs Mesa's OSMesa library ({why}); install it with \
         `sudo apt-get install -y {packages}` (Debian/Ubuntu) or your distribution's \
         OSMesa package, or set VTK_DEFAULT_OPENGL_WINDOW to a working VTK window class"
    );
    if Command::new("apt-get").arg("--version").output().is_err() {
        bail!("{manual}; apt-get is not available here");
    }
    let sudo = if is_root() {
        false
    } else if Command::new("sudo")
        .args(["-n", "true"])
        .status()
        .is_ok_and(|s| s.success())
    {
        true
    } else {
        bail!("{manual}; not root and `sudo -n` is not allowed");
    };
    let apt = |args: &[&str]| -> Result<bool> {
        let mut cmd = if sudo {
            let mut c = Command::new("sudo");
            c.args(["-n", "env", "DEBIAN_FRONTEND=noninteractive", "apt-get"]);
            c
        } else {
            let mut c = Command::new("apt-get");
            c.env("DEBIAN_FRONTEND", "noninteractive");
            c
        };
        cmd.args(args);
        Ok(cmd
            .status()
            .with_context(|| format!("cannot run apt-get {}", args.join(" ")))?
            .success())
    };
    let start = Instant::now();
    eprintln!(
        "xtask: {why}; installing the Debian package {packages} (Mesa's offscreen OpenGL) with apt-get{}",
        if sudo { " through sudo" } else { "" }
    );
    let mut install = vec!["install", "-y", "-q", "--no-install-recommends"];
    install.extend(OSMESA_PACKAGES);
    if !apt(&install)? {
        eprintln!("xtask: apt-get install failed; updating the package lists and retrying");
        if !apt(&["update", "-q"])? || !apt(&install)? {
            bail!("{manual}; `apt-get install {packages}` failed");
        }
    }
    if !gl_support().osmesa {
        bail!("{manual}; {packages} is installed but libOSMesa.so.8 is still not found");
    }
    eprintln!(
        "xtask: installed {packages} in {:.0} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

fn is_root() -> bool {
    let uid = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            let line = status.lines().find(|l| l.starts_with("Uid:"))?;
            line.split_whitespace().nth(1).map(str::to_owned)
        });
    if let Some(uid) = uid {
        return uid == "0";
    }
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// The `.ply` files under `dir`, grouped by folder (relative to `dir`),
/// naturally sorted. Skips hidden entries, `skip` (the output folder) and
/// symbolic links to folders.
fn collect_ply(dir: &Path, skip: &Path) -> Result<BTreeMap<PathBuf, Vec<PathBuf>>> {
    let mut folders: BTreeMap<PathBuf, Vec<PathBuf>> = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        if folder == skip {
            continue;
        }
        let entries = std::fs::read_dir(&folder)
            .with_context(|| format!("cannot list {}", folder.display()))?;
        for entry in entries {
            let entry = entry.with_context(|| format!("cannot list {}", folder.display()))?;
            let name = entry.file_name();
            if name.to_string_lossy().starts_with('.') {
                continue;
            }
            let path = entry.path();
            let kind = entry
                .file_type()
                .with_context(|| format!("cannot stat {}", path.display()))?;
            if kind.is_dir() {
                stack.push(path);
            } else if path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("ply"))
                && path.is_file()
            {
                let rel = folder.strip_prefix(dir).unwrap_or(&folder).to_path_buf();
                folders.entry(rel).or_default().push(path);
            }
        }
    }
    for files in folders.values_mut() {
        files.sort_by_cached_key(|p| {
            natural_key(&p.file_name().unwrap_or_default().to_string_lossy())
        });
    }
    Ok(folders)
}

/// Splits the folders into sheets of at most `per_sheet` files, named after
/// the folder path (`a/b` gives `a__b.png`, `DIR` itself its own name), with
/// `-2`, `-3`, ... for further pages.
fn plan_sheets(
    dir: &Path,
    out: &Path,
    folders: BTreeMap<PathBuf, Vec<PathBuf>>,
    per_sheet: usize,
) -> Vec<Sheet> {
    let root_name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "root".to_owned());
    let mut used = HashSet::new();
    let mut sheets = Vec::new();
    for (rel, files) in folders {
        let parts: Vec<String> = rel
            .components()
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect();
        let (title, mut stem) = if parts.is_empty() {
            (root_name.clone(), root_name.clone())
        } else {
            (format!("{root_name}/{}", parts.join("/")), parts.join("__"))
        };
        while !used.insert(stem.clone()) {
            stem.push('_');
        }
        let pages = files.len().div_ceil(per_sheet.max(1));
        for (page, chunk) in files.chunks(per_sheet.max(1)).enumerate() {
            let (name, title) = if pages == 1 {
                (format!("{stem}.png"), title.clone())
            } else {
                (
                    format!("{stem}-{}.png", page + 1),
                    format!("{title} ({} of {pages})", page + 1),
                )
            };
            sheets.push(Sheet {
                title,
                out: out.join(name),
                files: chunk
                    .iter()
                    .map(|p| {
                        let label = p
                            .file_name()
                            .unwrap_or_default()
                            .to_string_lossy()
                            .into_owned();
                        (p.clone(), label)
                    })
                    .collect(),
            });
        }
    }
    sheets
}

/// A piece of a file name for natural ordering: digit runs compare as
/// numbers (by length without leading zeros, then digits), text as text.
#[derive(Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Chunk {
    Number(usize, String),
    Text(String),
}

fn natural_key(name: &str) -> Vec<Chunk> {
    let mut key = Vec::new();
    let mut rest = name;
    while let Some(c) = rest.chars().next() {
        let digit = c.is_ascii_digit();
        let end = rest
            .find(|ch: char| ch.is_ascii_digit() != digit)
            .unwrap_or(rest.len());
        let (run, tail) = rest.split_at(end);
        key.push(if digit {
            let trimmed = run.trim_start_matches('0');
            Chunk::Number(trimmed.len(), trimmed.to_owned())
        } else {
            Chunk::Text(run.to_owned())
        });
        rest = tail;
    }
    key
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_puts_numbers_in_numeric_order() {
        let mut names = vec![
            "s10.ply", "s2.ply", "s1.ply", "b.ply", "s002.ply", "a10.ply",
        ];
        names.sort_by_key(|n| natural_key(n));
        assert_eq!(
            names,
            [
                "a10.ply", "b.ply", "s1.ply", "s2.ply", "s002.ply", "s10.ply"
            ]
        );
    }

    #[test]
    fn ldconfig_lines_are_parsed_per_architecture() {
        let text = "5 libs found in cache `/etc/ld.so.cache'\n\
            \tlibOSMesa.so.8 (libc6,x86-64) => /usr/lib/x86_64-linux-gnu/libOSMesa.so.8\n\
            \tlibEGL.so.1 (libc6) => /usr/lib/i386-linux-gnu/libEGL.so.1\n\
            \tlibEGL.so.1 (libc6,x86-64) => /lib/x86_64-linux-gnu/libEGL.so.1\n\
            Cache generated by: ldconfig (GNU libc) stable release version 2.36\n";
        let libs = parse_ldconfig(text, Some("x86-64"));
        assert_eq!(libs.len(), 2);
        assert_eq!(
            libs["libEGL.so.1"],
            PathBuf::from("/lib/x86_64-linux-gnu/libEGL.so.1")
        );
        assert!(libs.contains_key("libOSMesa.so.8"));
        assert_eq!(parse_ldconfig(text, None).len(), 2);
    }

    #[test]
    fn sheets_are_paged_and_named_after_folders() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let root = dir.path().join("samples");
        std::fs::create_dir_all(root.join("deep/er")).expect("test folder");
        std::fs::create_dir_all(root.join("visual-check")).expect("test folder");
        for name in ["s10.ply", "s2.ply", "s1.PLY", ".s3.ply.tmp", "notes.txt"] {
            std::fs::write(root.join(name), "").expect("test folder");
        }
        std::fs::write(root.join("deep/er/m.ply"), "").expect("test folder");
        std::fs::write(root.join("visual-check/old.ply"), "").expect("test folder");
        let out = root.join("visual-check");
        let folders = collect_ply(&root, &out).expect("test folder");
        assert_eq!(folders.len(), 2);
        let sheets = plan_sheets(&root, &out, folders, 2);
        let summary: Vec<(String, PathBuf, Vec<String>)> = sheets
            .into_iter()
            .map(|s| (s.title, s.out, s.files.into_iter().map(|f| f.1).collect()))
            .collect();
        assert_eq!(
            summary,
            vec![
                (
                    "samples (1 of 2)".to_owned(),
                    out.join("samples-1.png"),
                    vec!["s1.PLY".to_owned(), "s2.ply".to_owned()]
                ),
                (
                    "samples (2 of 2)".to_owned(),
                    out.join("samples-2.png"),
                    vec!["s10.ply".to_owned()]
                ),
                (
                    "samples/deep/er".to_owned(),
                    out.join("deep__er.png"),
                    vec!["m.ply".to_owned()]
                ),
            ]
        );
    }
}
