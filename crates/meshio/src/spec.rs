//! Naming a mesh by one string, as a command line does: a file path, or a
//! built-in procedural mesh `builtin:NAME[:N]`.
//!
//! `N` is a resolution parameter: subdivisions for `icosphere` (default 3)
//! and `blob` (default 4, at most 8 for both), cells per side for `grid`
//! (default 32, 0 taken as 1, at most 1024), and a resolution multiplier
//! (default 1, 0 taken as 1, at most 32) for `uv-sphere`, `torus` and
//! `capsule`: every built-in mesh has at most about 1.6M vertices, and a
//! larger `N` is refused before anything is built.
//!
//! [`load_mesh_spec_checked`] is the policy of every command that computes
//! on a mesh: the problems [`MeshReport`] finds are warnings, except
//! duplicate faces, which every operator would count twice.
//!
//! # Example
//! ```
//! let mesh = mfm_meshio::spec::load_mesh_spec("builtin:icosphere:1").unwrap();
//! assert_eq!(mesh.num_vertices(), 42);
//! assert!(mfm_meshio::spec::spec_path("builtin:grid").is_none());
//! let err = mfm_meshio::spec::load_mesh_spec("builtin:cube").unwrap_err();
//! assert!(err.to_string().contains("unknown built-in mesh `cube`"));
//! ```

use crate::{ReadError, read_mesh};
use mfm_geometry::TriMesh;
use mfm_geometry::procedural::{self, ProceduralError};
use mfm_geometry::validate::{MeshProblem, MeshReport};
use std::path::Path;
use thiserror::Error;

/// Names accepted after `builtin:`.
pub const BUILTINS: &[&str] = &["icosphere", "blob", "uv-sphere", "torus", "capsule", "grid"];

/// The prefix of a built-in mesh's name.
pub const BUILTIN_PREFIX: &str = "builtin:";

/// Why a mesh named by a string could not be had. Every message starts
/// with the string as given.
#[derive(Debug, Error)]
pub enum MeshSpecError {
    /// The file could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// `builtin:NAME:N` with an `N` that is not a non-negative integer.
    #[error("{spec}: resolution `{value}` is not a non-negative integer")]
    BadResolution {
        /// The name as given.
        spec: String,
        /// The text after the second colon.
        value: String,
    },
    /// A resolution above the built-in mesh's cap (see the [module
    /// docs](self)).
    #[error(
        "{spec}: the resolution is at most {max} for this mesh (it would have {vertices} \
         vertices); for finer meshes subdivide a file with `mfm remesh --subdivide`"
    )]
    TooFine {
        /// The name as given.
        spec: String,
        /// The largest resolution taken.
        max: u32,
        /// The vertices the mesh would have had.
        vertices: u64,
    },
    /// A name after `builtin:` that is not in [`BUILTINS`].
    #[error("{spec}: unknown built-in mesh `{name}` (known: {})", BUILTINS.join(", "))]
    UnknownBuiltin {
        /// The name as given.
        spec: String,
        /// The unknown mesh name.
        name: String,
    },
    /// The procedural construction refused its parameters.
    #[error("{spec}: {source}")]
    Procedural {
        /// The name as given.
        spec: String,
        /// Why.
        #[source]
        source: ProceduralError,
    },
    /// The mesh's faces are too small or too large for the operators'
    /// `f64` arithmetic.
    #[error(
        "{spec}: {problem}; no operator can be built on it (`mfm info {spec}` lists its problems)"
    )]
    OutOfRange {
        /// The name as given.
        spec: String,
        /// The problem as [`MeshReport`] states it.
        problem: MeshProblem,
    },
    /// The mesh has duplicate faces, which every operator would count twice.
    #[error(
        "{spec}: {problem}; every operator would count their area twice: remove them first \
(`mfm info {spec}` lists the mesh's problems)"
    )]
    DuplicateFaces {
        /// The name as given.
        spec: String,
        /// The problem as [`MeshReport`] states it.
        problem: MeshProblem,
    },
}

/// Most subdivisions of `icosphere` and `blob`.
pub const MAX_SUBDIVISIONS: u32 = 8;
/// Most cells per side of `grid`.
pub const MAX_GRID_CELLS: u32 = 1024;
/// Largest resolution multiplier of `uv-sphere`, `torus` and `capsule`.
pub const MAX_MULTIPLIER: u32 = 32;

/// Loads the mesh `spec` names: a file ([`read_mesh`], by extension) or a
/// built-in mesh (see the [module docs](self)).
///
/// # Errors
/// [`MeshSpecError`], naming `spec`.
pub fn load_mesh_spec(spec: &str) -> Result<TriMesh, MeshSpecError> {
    let Some(rest) = spec.strip_prefix(BUILTIN_PREFIX) else {
        return Ok(read_mesh(Path::new(spec))?);
    };
    let (name, param) = match rest.split_once(':') {
        Some((n, p)) => {
            let v: u32 = p.parse().map_err(|_| MeshSpecError::BadResolution {
                spec: spec.to_owned(),
                value: p.to_owned(),
            })?;
            (n, Some(v))
        }
        None => (rest, None),
    };
    let procedural = |r: Result<TriMesh, ProceduralError>| {
        r.map_err(|source| MeshSpecError::Procedural {
            spec: spec.to_owned(),
            source,
        })
    };
    // the resolution, refused above `max` (naming the vertices it would
    // have made, from `vertices`)
    let capped = |value: u32, max: u32, vertices: fn(u64) -> u64| {
        if value > max {
            return Err(MeshSpecError::TooFine {
                spec: spec.to_owned(),
                max,
                vertices: vertices(u64::from(value)),
            });
        }
        Ok(value)
    };
    let icosphere_vertices = |s: u64| 10u64.saturating_mul(4u64.saturating_pow(s as u32)) + 2;
    let subdivisions = |default: u32| {
        capped(
            param.unwrap_or(default),
            MAX_SUBDIVISIONS,
            icosphere_vertices,
        )
    };
    let multiplier =
        |per_unit: fn(u64) -> u64| capped(param.unwrap_or(1).max(1), MAX_MULTIPLIER, per_unit);
    match name {
        "icosphere" => Ok(procedural::icosphere(subdivisions(3)?)),
        "blob" => procedural(procedural::blob(subdivisions(4)?)),
        "uv-sphere" => {
            let k = multiplier(|k| (24 * k).saturating_mul(48 * k))?;
            procedural(procedural::uv_sphere(24 * k, 48 * k))
        }
        "torus" => {
            let k = multiplier(|k| (64 * k).saturating_mul(24 * k))?;
            procedural(procedural::torus(1.0, 0.4, 64 * k, 24 * k))
        }
        "capsule" => {
            let k = multiplier(|k| (16 * k).saturating_mul(48 * k))?;
            procedural(procedural::capsule(0.5, 0.75, 16 * k, 48 * k))
        }
        "grid" => {
            let n = capped(param.unwrap_or(32).max(1), MAX_GRID_CELLS, |n| {
                (n + 1).saturating_mul(n + 1)
            })?;
            procedural(procedural::plane_grid(n, n, 1.0, 1.0))
        }
        other => Err(MeshSpecError::UnknownBuiltin {
            spec: spec.to_owned(),
            name: other.to_owned(),
        }),
    }
}

/// The file `spec` names, `None` for a built-in mesh.
pub fn spec_path(spec: &str) -> Option<&Path> {
    (!spec.starts_with(BUILTIN_PREFIX)).then(|| Path::new(spec))
}

/// A mesh named by one command-line argument: `builtin:NAME[:N]`, or a
/// file whose name may be any the system allows (UTF-8 or not: a name that
/// is not UTF-8 is always a file). Shown with [`Path::display`]'s
/// replacement characters.
///
/// # Example
/// ```
/// use mfm_meshio::spec::MeshSpec;
/// let spec = MeshSpec::from("builtin:icosphere:1");
/// assert!(spec.path().is_none());
/// assert_eq!(spec.load().unwrap().num_vertices(), 42);
/// #[cfg(unix)]
/// {
///     use std::os::unix::ffi::OsStringExt;
///     let latin1 = MeshSpec::from(std::ffi::OsString::from_vec(b"caf\xe9.obj".to_vec()));
///     assert_eq!(latin1.to_string(), "caf\u{fffd}.obj");
///     assert!(latin1.path().is_some());
/// }
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MeshSpec(std::ffi::OsString);

impl MeshSpec {
    /// The file, `None` for a built-in mesh.
    pub fn path(&self) -> Option<&Path> {
        match self.0.to_str() {
            Some(s) => spec_path(s),
            None => Some(Path::new(&self.0)),
        }
    }

    /// The mesh ([`load_mesh_spec`]).
    ///
    /// # Errors
    /// As [`load_mesh_spec`].
    pub fn load(&self) -> Result<TriMesh, MeshSpecError> {
        match self.0.to_str() {
            Some(s) => load_mesh_spec(s),
            None => Ok(read_mesh(Path::new(&self.0))?),
        }
    }

    /// The mesh for computing on ([`load_mesh_spec_checked`]).
    ///
    /// # Errors
    /// As [`load_mesh_spec_checked`].
    pub fn load_checked(&self) -> Result<CheckedMesh, MeshSpecError> {
        let mesh = self.load()?;
        let warnings = check_mesh(&self.to_string(), &mesh)?;
        Ok(CheckedMesh { mesh, warnings })
    }
}

impl std::fmt::Display for MeshSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", Path::new(&self.0).display())
    }
}

impl AsRef<std::ffi::OsStr> for MeshSpec {
    fn as_ref(&self) -> &std::ffi::OsStr {
        &self.0
    }
}

impl From<std::ffi::OsString> for MeshSpec {
    fn from(s: std::ffi::OsString) -> Self {
        Self(s)
    }
}

impl From<&str> for MeshSpec {
    fn from(s: &str) -> Self {
        Self(s.into())
    }
}

impl From<String> for MeshSpec {
    fn from(s: String) -> Self {
        Self(s.into())
    }
}

/// A mesh loaded for computing on, with the problems that did not stop it.
#[derive(Clone, Debug)]
pub struct CheckedMesh {
    /// The mesh.
    pub mesh: TriMesh,
    /// What [`MeshReport`] found, every problem but duplicate faces.
    pub warnings: Vec<MeshProblem>,
}

/// [`load_mesh_spec`] for computing on the mesh (operators, noise,
/// datasets, sampling): duplicate faces are an error, the other problems
/// [`MeshReport`] finds are returned as warnings.
///
/// # Errors
/// Those of [`load_mesh_spec`], and [`MeshSpecError::DuplicateFaces`].
pub fn load_mesh_spec_checked(spec: &str) -> Result<CheckedMesh, MeshSpecError> {
    MeshSpec::from(spec).load_checked()
}

/// The policy of [`load_mesh_spec_checked`] on a mesh already loaded: the
/// warnings, or the duplicate faces or faces out of `f64`'s range as an
/// error.
///
/// # Errors
/// [`MeshSpecError::DuplicateFaces`], [`MeshSpecError::OutOfRange`].
pub fn check_mesh(spec: &str, mesh: &TriMesh) -> Result<Vec<MeshProblem>, MeshSpecError> {
    let report = MeshReport::new(mesh);
    if let Some(p) = report
        .problems
        .iter()
        .find(|p| matches!(p, MeshProblem::DuplicateFaces { .. }))
    {
        return Err(MeshSpecError::DuplicateFaces {
            spec: spec.to_owned(),
            problem: p.clone(),
        });
    }
    if let Some(p) = report
        .problems
        .iter()
        .find(|p| matches!(p, MeshProblem::OutOfRange { .. }))
    {
        return Err(MeshSpecError::OutOfRange {
            spec: spec.to_owned(),
            problem: p.clone(),
        });
    }
    Ok(report.problems)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn builtins_have_their_documented_resolutions() -> Result<(), MeshSpecError> {
        assert_eq!(load_mesh_spec("builtin:icosphere")?.num_vertices(), 642);
        assert_eq!(load_mesh_spec("builtin:icosphere:0")?.num_vertices(), 12);
        assert_eq!(load_mesh_spec("builtin:grid:4")?.num_vertices(), 25);
        assert_eq!(load_mesh_spec("builtin:grid:0")?.num_vertices(), 4);
        assert_eq!(load_mesh_spec("builtin:blob")?.num_vertices(), 2562);
        for name in BUILTINS {
            let m = load_mesh_spec(&format!("builtin:{name}"))?;
            assert!(m.num_faces() > 0, "{name}");
        }
        Ok(())
    }

    #[test]
    fn bad_names_are_refused_with_the_name() {
        let e = load_mesh_spec("builtin:icosphere:9")
            .map(|_| ())
            .unwrap_err();
        assert!(matches!(e, MeshSpecError::TooFine { max: 8, .. }), "{e}");
        assert!(e.to_string().contains("2621442 vertices"), "{e}");
        // every built-in is capped before anything is built
        for (name, max) in [
            ("grid", MAX_GRID_CELLS),
            ("uv-sphere", MAX_MULTIPLIER),
            ("torus", MAX_MULTIPLIER),
            ("capsule", MAX_MULTIPLIER),
        ] {
            for n in [max + 1, 100_000, u32::MAX] {
                let e = load_mesh_spec(&format!("builtin:{name}:{n}"))
                    .map(|_| ())
                    .unwrap_err();
                assert!(
                    matches!(e, MeshSpecError::TooFine { .. }),
                    "{name}:{n}: {e}"
                );
            }
        }
        let e = load_mesh_spec("builtin:grid:x").map(|_| ()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "builtin:grid:x: resolution `x` is not a non-negative integer"
        );
        let e = load_mesh_spec("/nonexistent/m.off")
            .map(|_| ())
            .unwrap_err();
        assert!(e.to_string().contains("/nonexistent/m.off"), "{e}");
    }

    #[test]
    fn duplicate_faces_are_an_error_and_other_problems_warnings() {
        let base = procedural::icosphere(1);
        let mut faces = base.faces().to_vec();
        let unused = base.positions().len();
        let mut positions = base.positions().to_vec();
        positions.push([5.0, 5.0, 5.0]);
        let isolated = TriMesh::new(positions, faces.clone()).map(|m| check_mesh("iso", &m));
        match isolated {
            Ok(Ok(w)) => assert!(!w.is_empty(), "the unused vertex {unused} is reported"),
            other => panic!("an unused vertex is only a warning: {other:?}"),
        }
        faces.push(faces[0]);
        let dup = TriMesh::new(base.positions().to_vec(), faces).map(|m| check_mesh("dup", &m));
        match dup {
            Ok(Err(e @ MeshSpecError::DuplicateFaces { .. })) => {
                assert!(e.to_string().starts_with("dup: "), "{e}")
            }
            other => panic!("duplicate faces are an error: {other:?}"),
        }
    }
}
