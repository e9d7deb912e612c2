//! `spectrum`: the per-frequency statistics of `mfm spectrum` as a dict.

use crate::errors::{bad_argument, runtime_error};
use crate::noise::{MaternNoise, count, noise_error, parse_kind};
use mfm_geometry::operators::Operators;
use mfm_noise::spectrum::{MeshSpectrum, SpectrumRequest};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Measures the spectrum of `noise` (see [`spectrum`]).
pub fn measure<'py>(
    py: Python<'py>,
    noise: &MaternNoise,
    samples: i64,
    k: i64,
    seed: i128,
) -> PyResult<Bound<'py, PyDict>> {
    let samples = count("samples", samples, 2)?;
    let k = count("k", k, 1)?;
    let v = noise.mesh().num_vertices();
    if k > v {
        return Err(bad_argument(
            "k",
            format!("{k} eigenpairs asked, but the mesh has {v} vertices (1 <= k <= {v})"),
        ));
    }
    let seed = u64::try_from(seed)
        .map_err(|_| bad_argument("seed", format!("expected 0 <= seed < 2^64, got {seed}")))?;
    let request = SpectrumRequest {
        samples,
        k,
        seed,
        keep: Vec::new(),
    };
    let (spectrum, _) = py
        .detach(|| {
            let ops = Operators::new(noise.mesh())?;
            MeshSpectrum::measure("(V, F)", &ops, noise.sampler(), &request, |_| {})
        })
        .map_err(noise_error)?;
    let r = &spectrum.report;
    let d = PyDict::new(py);
    d.set_item("vertices", spectrum.vertices)?;
    d.set_item("gamma", spectrum.gamma)?;
    d.set_item("num_signals", r.num_signals)?;
    d.set_item("eigenvalues", PyArray1::from_slice(py, &r.eigenvalues))?;
    d.set_item("mean", PyArray1::from_slice(py, &r.mean))?;
    d.set_item("variance", PyArray1::from_slice(py, &r.variance))?;
    let theory = r
        .theory
        .as_ref()
        .ok_or_else(|| runtime_error("spectrum: the noise kind has no theory"))?;
    d.set_item("theory", PyArray1::from_slice(py, theory))?;
    let ratio: Vec<f64> = r
        .ratio
        .as_ref()
        .map(|v| v.iter().map(|x| x.unwrap_or(f64::NAN)).collect())
        .unwrap_or_default();
    d.set_item("ratio", PyArray1::from_vec(py, ratio))?;
    d.set_item("max_relative_error", r.max_relative_error)?;
    d.set_item("max_abs_correlation", r.independence.max_abs_correlation)?;
    d.set_item("correlation_pair", r.independence.pair.map(|[i, j]| (i, j)))?;
    d.set_item("correlation_reference", r.independence.reference)?;
    d.set_item("mean_energy", r.mean_energy)?;
    d.set_item("captured_energy", r.captured_energy)?;
    d.set_item("theory_energy", r.theory_energy)?;
    Ok(d)
}

/// The spectrum of noise on `(V, F)`, as `mfm spectrum` measures it:
/// samples `0..samples` of `seed` (one channel) projected on the `k`
/// lowest eigenpairs, `c_i = phi_i^T M f`. Returns a dict:
/// `eigenvalues`, `mean`, `variance` (empirical `E[c_i^2]`), `theory`
/// (closed-form `Var(c_i)`), `ratio` (`variance / theory`, NaN where the
/// theory is 0), all `float64 [k]`; `max_relative_error`
/// (`max |ratio - 1|`), `max_abs_correlation`, `correlation_pair`,
/// `correlation_reference` (the level sampling error alone gives),
/// `mean_energy` (mean `f^T M f`), `captured_energy`, `theory_energy`,
/// `gamma`, `vertices`, `num_signals`. The noise arguments are those of
/// `MaternNoise`; `frame="as-is"` reproduces `mfm spectrum`'s numbers.
///
/// Example:
///
/// >>> import mfm
/// >>> V, F = mfm.read_mesh("builtin:icosphere:3")
/// >>> s = mfm.spectrum(V, F, tau=100.0, samples=1000, k=16)
/// >>> bool(s["max_relative_error"] < 0.3), s["eigenvalues"].shape
/// (True, (16,))
#[pyfunction]
#[pyo3(signature = (V, F, kind = "matern", tau = None, c = None, k_noise = None, samples = 2000, k = 64, seed = 0, frame = "canonical"))]
#[allow(non_snake_case, clippy::too_many_arguments)]
pub fn spectrum<'py>(
    py: Python<'py>,
    V: &Bound<'py, PyAny>,
    F: &Bound<'py, PyAny>,
    kind: &str,
    tau: Option<f64>,
    c: Option<f64>,
    k_noise: Option<i64>,
    samples: i64,
    k: i64,
    seed: i128,
    frame: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let spelled_out = kind.contains(':');
    let kind = parse_kind(kind, tau, c, k_noise)?;
    let noise = MaternNoise::build(py, V, F, kind, spelled_out, 1.0, frame)?;
    measure(py, &noise, samples, k, seed)
}
