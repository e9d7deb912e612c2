//! `MaternNoise`: a noise sampler built once per mesh, sampled many times.

use crate::arrays;
use crate::errors::{bad_argument, runtime_error, value_error};
use crate::memory::require_memory;
use mfm_geometry::TriMesh;
use mfm_geometry::frame::CanonicalFrame;
use mfm_noise::{KindName, KindParameters, NoiseError, NoiseKind, NoiseSampler};
use numpy::ndarray::Array3;
use numpy::{PyArray3, PyArrayDescrMethods};
use pyo3::prelude::*;

/// Where the mesh sits when the noise is built.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Frame {
    /// Bounding box centred at the origin, largest extent 1 (what
    /// `mfm train` does before sampling noise: `tau` is then a property
    /// of the shape, not of its units).
    Canonical,
    /// The coordinates as given (what `mfm noise` and `mfm spectrum` do).
    AsIs,
}

impl Frame {
    fn parse(frame: &str) -> PyResult<Self> {
        match frame {
            "canonical" => Ok(Self::Canonical),
            "as-is" | "as_is" => Ok(Self::AsIs),
            other => Err(bad_argument(
                "frame",
                format!("expected \"canonical\" or \"as-is\", got {other:?}"),
            )),
        }
    }
}

/// The noise kind named by `kind` and the separate parameters, as `mfm
/// noise --noise KIND` (`kind` with its parameters, `"matern:50"`) or `mfm
/// noise --kind KIND --tau/--c/--k-noise` (a bare name and the keywords).
pub fn parse_kind(
    kind: &str,
    tau: Option<f64>,
    c: Option<f64>,
    k_noise: Option<i64>,
) -> PyResult<NoiseKind> {
    let k_noise = match k_noise {
        Some(k) if k < 1 => {
            return Err(bad_argument(
                "k_noise",
                format!("must be at least 1, got {k}"),
            ));
        }
        Some(k) => Some(k as usize),
        None => None,
    };
    if kind.contains(':') {
        if let Some(name) = [
            ("tau", tau.is_some()),
            ("c", c.is_some()),
            ("k_noise", k_noise.is_some()),
        ]
        .iter()
        .find(|(_, given)| *given)
        .map(|(n, _)| n)
        {
            return Err(bad_argument(
                name,
                format!(
                    "kind {kind:?} already sets its parameters; pass the bare name (kind=\"{}\") with {name}=...",
                    kind.split(':').next().unwrap_or(kind)
                ),
            ));
        }
        return kind
            .parse()
            .map_err(|e: NoiseError| bad_argument("kind", e));
    }
    let name: KindName = kind
        .to_ascii_lowercase()
        .parse()
        .map_err(|e: NoiseError| bad_argument("kind", e))?;
    let parameters = KindParameters {
        tau,
        c,
        k: k_noise,
        order: None,
    };
    NoiseKind::from_parts(name, parameters).map_err(|e| match e {
        NoiseError::UnusedParameter { parameter, .. } => {
            let argument = if parameter == "k" {
                "k_noise"
            } else {
                parameter
            };
            bad_argument(argument, e)
        }
        NoiseError::InvalidParameter { name, .. } => {
            let argument = match name {
                "tau" | "c" => name,
                "k" => "k_noise",
                _ => "kind",
            };
            bad_argument(argument, e)
        }
        e => bad_argument("kind", e),
    })
}

/// The sampler's error as a Python exception: bad parameters and meshes are
/// `ValueError`s, a failed factorization a `RuntimeError`.
pub fn noise_error(e: NoiseError) -> PyErr {
    match e {
        NoiseError::Solver(_) => runtime_error(e.to_string()),
        NoiseError::Operators(_) | NoiseError::NonPositiveMass { .. } => bad_argument("F", e),
        e => value_error(e.to_string()),
    }
}

/// Whether a `dtype` argument asks for `float32` (the default) or `float64`.
fn wants_f32(py: Python<'_>, dtype: Option<&Bound<'_, PyAny>>) -> PyResult<bool> {
    let Some(dtype) = dtype else { return Ok(true) };
    if dtype.is_none() {
        return Ok(true);
    }
    let numpy = py.import("numpy")?;
    let descr = numpy
        .getattr("dtype")?
        .call1((dtype,))
        .map_err(|_| bad_argument("dtype", "expected numpy.float32 or numpy.float64"))?;
    let descr = descr
        .cast::<numpy::PyArrayDescr>()
        .map_err(|_| bad_argument("dtype", "expected numpy.float32 or numpy.float64"))?;
    if descr.is_equiv_to(&numpy::dtype::<f32>(py)) {
        Ok(true)
    } else if descr.is_equiv_to(&numpy::dtype::<f64>(py)) {
        Ok(false)
    } else {
        Err(bad_argument(
            "dtype",
            format!("expected numpy.float32 or numpy.float64, got {descr}"),
        ))
    }
}

/// A count argument: an integer of at least `min`.
pub fn count(argument: &str, value: i64, min: i64) -> PyResult<usize> {
    if value < min {
        return Err(bad_argument(
            argument,
            format!("must be at least {min}, got {value}"),
        ));
    }
    usize::try_from(value).map_err(|_| bad_argument(argument, format!("{value} is too large")))
}

/// Noise on a triangle mesh, built once (operators, the Cholesky factor of
/// `L + tau M`, or eigenpairs), then sampled any number of times.
///
/// `MaternNoise(V, F, tau=None, sigma=1.0, kind="matern",
/// frame="canonical", c=None, k_noise=None)`:
/// - `kind`: `"matern"` (solve `(L + tau M) f = M^1/2 n`, `tau` default
///   100), `"matern-normalized"` (`c`, default 1e-4: `tau = c Gamma`,
///   scaled by `sqrt(Gamma)`), `"matern-smooth"` (`tau`; order 2, or
///   the short form `"matern-smooth:100:3"`), `"white"`, `"naive"`, `"explicit"`
///   (`k_noise` eigenpairs, default 64, and `tau`); or the command line's
///   short form with the parameters inside, `"matern:50"`,
///   `"explicit:32:100"`, `"matern-normalized:1e-3"`.
/// - `sigma`: every sample is multiplied by it.
/// - `frame`: `"canonical"` moves the mesh into the canonical frame
///   (bounding box centred, largest extent 1) first, as `mfm train`
///   does; `"as-is"` uses the coordinates as given, as `mfm noise` does.
///
/// `sample(n, channels=1, seed=0, first=0, dtype=numpy.float32)` returns
/// `[n, V, channels]`. With `dtype=numpy.float64` (and `sigma = 1`, the
/// same frame) its bits equal `mfm noise MESH --seed SEED`'s samples
/// `first .. first + n`; `float32` draws its own `float32` normals on the
/// same per-sample streams (the same law, other bits). A seed gives the
/// same bits on any number of threads.
///
/// Example:
///
/// >>> import mfm, numpy as np
/// >>> V, F = mfm.read_mesh("builtin:icosphere:3")
/// >>> noise = mfm.MaternNoise(V, F, tau=100.0)
/// >>> x = noise.sample(8, channels=3, seed=7)
/// >>> x.shape == (8, V.shape[0], 3), x.dtype.name
/// (True, 'float32')
/// >>> np.array_equal(noise.sample(2, channels=3, seed=7, first=6), x[6:])
/// True
#[pyclass(module = "mfm", frozen)]
pub struct MaternNoise {
    sampler: NoiseSampler,
    mesh: TriMesh,
    frame: CanonicalFrame,
    sigma: f64,
}

impl MaternNoise {
    /// The sampler.
    pub fn sampler(&self) -> &NoiseSampler {
        &self.sampler
    }

    /// The mesh the noise lives on (in the chosen frame).
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// Builds the noise of `kind` on `(V, F)` in `frame`;
    /// `kind_spelled_out` says whether the kind's parameters came inside
    /// the `kind` string (errors about them then name `kind`).
    pub fn build(
        py: Python<'_>,
        v: &Bound<'_, PyAny>,
        f: &Bound<'_, PyAny>,
        kind: NoiseKind,
        kind_spelled_out: bool,
        sigma: f64,
        frame: &str,
    ) -> PyResult<Self> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(bad_argument(
                "sigma",
                format!("must be finite and > 0, got {sigma}"),
            ));
        }
        let frame = Frame::parse(frame)?;
        let mesh = arrays::mesh(py, v, f)?;
        let (mesh, frame) = match frame {
            Frame::AsIs => (mesh, CanonicalFrame::identity()),
            Frame::Canonical => {
                let fr = CanonicalFrame::of(&mesh).map_err(|e| bad_argument("V", e))?;
                (fr.apply(&mesh), fr)
            }
        };
        if let NoiseKind::Explicit { k, .. } = kind
            && k > mesh.num_vertices()
        {
            return Err(bad_argument(
                if kind_spelled_out { "kind" } else { "k_noise" },
                format!(
                    "explicit noise with {k} eigenpairs asked, but the mesh has {} vertices",
                    mesh.num_vertices()
                ),
            ));
        }
        let sampler = py
            .detach(|| NoiseSampler::new(&mesh, kind))
            .map_err(noise_error)?;
        Ok(Self {
            sampler,
            mesh,
            frame,
            sigma,
        })
    }
}

#[pymethods]
impl MaternNoise {
    #[new]
    #[pyo3(signature = (V, F, tau = None, sigma = 1.0, kind = "matern", frame = "canonical", c = None, k_noise = None))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        V: &Bound<'_, PyAny>,
        F: &Bound<'_, PyAny>,
        tau: Option<f64>,
        sigma: f64,
        kind: &str,
        frame: &str,
        c: Option<f64>,
        k_noise: Option<i64>,
    ) -> PyResult<Self> {
        let spelled_out = kind.contains(':');
        let kind = parse_kind(kind, tau, c, k_noise)?;
        Self::build(py, V, F, kind, spelled_out, sigma, frame)
    }

    /// Samples `first .. first + n` of the sequence of `seed`, `channels`
    /// independent channels each, as a `[n, V, channels]` array of `dtype`
    /// (`numpy.float32` by default, or `numpy.float64`). Releases the GIL.
    #[pyo3(signature = (n, channels = 1, seed = 0, first = 0, dtype = None))]
    fn sample<'py>(
        &self,
        py: Python<'py>,
        n: i64,
        channels: i64,
        seed: i128,
        first: i64,
        dtype: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = count("n", n, 1)?;
        let channels = count("channels", channels, 1)?;
        let first = count("first", first, 0)?;
        let seed = u64::try_from(seed)
            .map_err(|_| bad_argument("seed", format!("expected 0 <= seed < 2^64, got {seed}")))?;
        let f32 = wants_f32(py, dtype)?;
        let v = self.sampler.num_vertices();
        let values = n as u128 * v as u128 * channels as u128;
        require_memory(
            &format!("{n} samples x {v} vertices x {channels} channels"),
            values,
            if f32 { 4 } else { 8 },
        )?;
        let sigma = self.sigma;
        let shape = (n, v, channels);
        if f32 {
            let data = py
                .detach(|| {
                    self.sampler
                        .sample_range_f32(first, n, channels, seed)
                        .map(|b| {
                            let mut d = b.into_data();
                            if sigma != 1.0 {
                                let s = sigma as f32;
                                d.iter_mut().for_each(|x| *x *= s);
                            }
                            d
                        })
                })
                .map_err(noise_error)?;
            let arr =
                Array3::from_shape_vec(shape, data).map_err(|e| runtime_error(e.to_string()))?;
            Ok(PyArray3::from_owned_array(py, arr).into_any())
        } else {
            let data = py
                .detach(|| {
                    self.sampler
                        .sample_range(first, n, channels, seed)
                        .map(|b| {
                            let mut d = b.into_data();
                            if sigma != 1.0 {
                                d.iter_mut().for_each(|x| *x *= sigma);
                            }
                            d
                        })
                })
                .map_err(noise_error)?;
            let arr =
                Array3::from_shape_vec(shape, data).map_err(|e| runtime_error(e.to_string()))?;
            Ok(PyArray3::from_owned_array(py, arr).into_any())
        }
    }

    /// The per-frequency statistics of `samples` samples (one channel) on
    /// the `k` lowest eigenpairs, as `mfm spectrum` reports them: a dict of
    /// arrays and numbers (see `mfm.spectrum`).
    #[pyo3(signature = (samples = 2000, k = 64, seed = 0))]
    fn spectrum<'py>(
        &self,
        py: Python<'py>,
        samples: i64,
        k: i64,
        seed: i128,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        crate::spectrum::measure(py, self, samples, k, seed)
    }

    /// Number of vertices of the mesh.
    #[getter]
    fn vertices(&self) -> usize {
        self.sampler.num_vertices()
    }

    /// The noise kind in the command line's short form (`"matern:100"`).
    #[getter]
    fn kind(&self) -> String {
        self.sampler.kind().to_string()
    }

    /// The screening weight `tau` actually used (`c Gamma` for the
    /// normalized kind); `None` for kinds without one.
    #[getter]
    fn tau(&self) -> Option<f64> {
        self.sampler.tau()
    }

    /// `Gamma = ||M^-1 L||_F` of the mesh (in the chosen frame).
    #[getter]
    fn gamma(&self) -> f64 {
        self.sampler.gamma()
    }

    /// The factor every sample is multiplied by.
    #[getter]
    fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The map into the frame the noise was built in, `(scale, shift)`:
    /// `p -> scale * p + shift` (`(1.0, (0, 0, 0))` for `frame="as-is"`).
    #[getter]
    fn frame(&self) -> (f64, (f64, f64, f64)) {
        let s = self.frame.shift;
        (self.frame.scale, (s[0], s[1], s[2]))
    }

    fn __repr__(&self) -> String {
        format!(
            "MaternNoise(kind={:?}, vertices={}, sigma={}, frame scale={})",
            self.sampler.kind().to_string(),
            self.sampler.num_vertices(),
            self.sigma,
            self.frame.scale
        )
    }
}
