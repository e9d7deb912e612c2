//! # mfm-python
//!
//! The Python extension module `mfm._mfm` behind the `mfm` wheel: mesh files,
//! operators, eigenpairs, Matérn noise, cached Poisson solvers and noise
//! spectra, numpy in and out. It sits on the libtorch-free crates only, so
//! the wheel needs neither libtorch nor a Rust toolchain on the user's side;
//! `mfm.torch` (pure Python, in `python/mfm/torch.py`) adds an autograd
//! wrapper of the solvers for PyTorch users.
//!
//! ## Conventions (the same as the `mfm` command line)
//! - `V` is a C-contiguous `float64` array `[n, 3]`, `F` a C-contiguous
//!   integer array `[m, 3]` (`int32`, `int64`, `uint32` or `uint64`) of
//!   0-based vertex indices. Anything else raises `ValueError` naming the
//!   argument; no input can crash the interpreter.
//! - `L` is the **positive semi-definite** cotangent Laplacian (libigl's
//!   `cotmatrix` negated), `M` the lumped barycentric mass, `G` the `2F x V`
//!   intrinsic gradient (rows `2f, 2f + 1` in an orthonormal frame of face
//!   `f`), eigenpairs solve `L phi = lambda M phi` with `phi^T M phi = 1`.
//! - Long computations release the GIL and run on the crate's rayon
//!   threads (`RAYON_NUM_THREADS` sets their number); a seed gives the same
//!   bits on any thread count.
//!
//! The module is tested from Python (`crates/python/tests`, run by
//! `cargo xtask test`).

mod arrays;
mod errors;
mod memory;
mod mesh_io;
mod noise;
mod operators;
mod solvers;
mod sparse;
mod spectrum;

use pyo3::prelude::*;

/// The extension module `mfm._mfm` (re-exported by the `mfm` package).
#[pymodule]
fn _mfm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(mesh_io::read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_io::write_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(operators::cotan_laplacian, m)?)?;
    m.add_function(wrap_pyfunction!(operators::mass_matrix, m)?)?;
    m.add_function(wrap_pyfunction!(operators::face_gradients, m)?)?;
    m.add_function(wrap_pyfunction!(operators::face_areas, m)?)?;
    m.add_function(wrap_pyfunction!(operators::eigs, m)?)?;
    m.add_function(wrap_pyfunction!(spectrum::spectrum, m)?)?;
    m.add_class::<noise::MaternNoise>()?;
    m.add_class::<solvers::PoissonSolver>()?;
    m.add_class::<solvers::ScreenedSolver>()?;
    Ok(())
}
