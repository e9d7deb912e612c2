//! [`NoiseKind`]: which noise to sample, with its parameters.

use std::fmt;
use std::str::FromStr;

use mfm_files::fmt_f64;
use serde::{Deserialize, Serialize};

use crate::error::{NoiseError, Result};
use crate::sampler::explicit_weights;
use crate::spectrum::{Eigenpairs, check_vertices};

/// Default screening weight `tau` of the paper's experiments (`tau = 100`).
pub const DEFAULT_TAU: f64 = 100.0;

/// The largest screening weight `tau` taken: far above the largest
/// Laplacian eigenvalue of any practical mesh (about `1 / h^2` for edge
/// length `h`), where Matérn noise is only white noise divided by `tau`,
/// vanishing (at `1e300` every value underflows to zero and every sample
/// is the same).
pub const MAX_TAU: f64 = 1e10;

/// Default factor `c` of [`NoiseKind::MaternNormalized`] in the long form
/// ([`NoiseKind::from_parts`]).
pub const DEFAULT_NORMALIZED_C: f64 = 1e-4;

/// Default number of eigenpairs of [`NoiseKind::Explicit`] in the long
/// form ([`NoiseKind::from_parts`]).
pub const DEFAULT_EXPLICIT_K: usize = 64;

/// Default order `p` of [`NoiseKind::MaternSmooth`] (two solves per
/// sample, Matérn smoothness `nu = 3` on a surface).
pub const DEFAULT_SMOOTH_ORDER: u32 = 2;

/// The largest order `p` of [`NoiseKind::MaternSmooth`] taken: each order
/// is one more solve per sample, and beyond 4 the noise keeps almost
/// nothing but its few lowest frequencies.
pub const MAX_SMOOTH_ORDER: u32 = 4;

/// A noise kind's name without its parameters: the first word of the
/// short form, and the `--kind` value of the long form.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum KindName {
    /// [`NoiseKind::Naive`].
    Naive,
    /// [`NoiseKind::White`].
    White,
    /// [`NoiseKind::Matern`].
    Matern,
    /// [`NoiseKind::MaternNormalized`].
    MaternNormalized,
    /// [`NoiseKind::MaternSmooth`].
    MaternSmooth,
    /// [`NoiseKind::Explicit`].
    Explicit,
}

impl KindName {
    /// Every name, in the order the docs list them.
    pub const ALL: [Self; 6] = [
        Self::Matern,
        Self::MaternNormalized,
        Self::MaternSmooth,
        Self::White,
        Self::Naive,
        Self::Explicit,
    ];

    /// The name as the short form writes it (`matern-normalized`...).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Naive => "naive",
            Self::White => "white",
            Self::Matern => "matern",
            Self::MaternNormalized => "matern-normalized",
            Self::MaternSmooth => "matern-smooth",
            Self::Explicit => "explicit",
        }
    }
}

impl FromStr for KindName {
    type Err = NoiseError;

    /// One of [`KindName::ALL`] as [`KindName::as_str`] writes it.
    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| NoiseError::ParseKind {
                input: s.to_owned(),
                reason: format!("expected one of {}", Self::ALL.map(Self::as_str).join(", ")),
            })
    }
}

/// A noise distribution on the vertices of a mesh (docs/conventions.md, "Noise"; paper §3).
///
/// With `L` the PSD cotangent Laplacian, `M` the lumped mass, `n ~ N(0, I)`
/// one standard normal per vertex, `(lambda_i, phi_i)` the generalized
/// eigenpairs `L phi = lambda M phi` (`phi^T M phi = 1`) and
/// `Gamma = ||M^-1 L||_F`:
///
/// | kind | one sample | `Var(c_i)`, `c_i = phi_i^T M f` |
/// |---|---|---|
/// | [`Naive`](Self::Naive) | `n` | `phi_i^T M^2 phi_i` |
/// | [`White`](Self::White) | `M^-1/2 n` | `1` |
/// | [`Matern`](Self::Matern) | solve `(L + tau M) f = M^1/2 n` | `1 / (lambda_i + tau)^2` |
/// | [`Matern`](Self::Matern), `tau = 0` | `f = L^+ P M^1/2 n` (pseudo-inverse, mean-free per component) | `1 / lambda_i^2`, `0` for the zero modes |
/// | [`MaternNormalized`](Self::MaternNormalized) | `sqrt(Gamma) f`, `f` Matérn with `tau = c Gamma` | `Gamma / (lambda_i + c Gamma)^2` |
/// | [`MaternSmooth`](Self::MaternSmooth) `(tau, p)` | `f = (tau K^-1 M)^(p-1) K^-1 M^1/2 n`, `K = L + tau M` | `tau^(2p-2) / (lambda_i + tau)^(2p)` |
/// | [`Explicit`](Self::Explicit) | `sum_{i<k} chi_i / (lambda_i + tau) phi_i`, `chi ~ N(0, I_k)` | `1 / (lambda_i + tau)^2` for `i < k`, else `0` |
///
/// Serialized (serde) with an internal `kind` tag in snake case, e.g.
/// `{"kind":"matern","tau":100.0}`, `{"kind":"matern_normalized","c":0.5}`,
/// `{"kind":"explicit","k":64,"tau":100.0}`, `{"kind":"white"}`.
///
/// `P` is the projection that removes the zero modes (the constants of each
/// connected component, where `L` vanishes) from a right-hand side; see
/// [`Matern`](Self::Matern).
///
/// It also parses from and prints to a short command-line form (see
/// [`FromStr`](#impl-FromStr-for-NoiseKind)): `naive`, `white`,
/// `matern[:TAU]`, `matern-normalized:C` (alias `normalized:C`),
/// `matern-smooth[:TAU[:P]]`, `explicit:K[:TAU]`; `TAU` defaults to
/// [`DEFAULT_TAU`], `P` to [`DEFAULT_SMOOTH_ORDER`].
///
/// # Example
/// ```
/// use mfm_noise::NoiseKind;
/// let kind: NoiseKind = "explicit:32:50".parse().unwrap();
/// assert_eq!(kind, NoiseKind::Explicit { k: 32, tau: 50.0 });
/// assert_eq!(kind.to_string(), "explicit:32:50");
/// assert_eq!("matern".parse::<NoiseKind>().unwrap(), NoiseKind::Matern { tau: 100.0 });
/// // Matérn noise without screening (the paper's "no screening" ablation)
/// assert_eq!("matern:0".parse::<NoiseKind>().unwrap(), NoiseKind::Matern { tau: 0.0 });
/// let json = serde_json::to_string(&NoiseKind::MaternNormalized { c: 0.5 }).unwrap();
/// assert_eq!(json, r#"{"kind":"matern_normalized","c":0.5}"#);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum NoiseKind {
    /// iid `N(0, 1)` per vertex, ignoring the mesh (the mesh-dependent baseline).
    Naive,
    /// Discrete white noise `M^-1/2 n`: spectrally `N(0, I)`.
    White,
    /// Matérn noise (paper Alg. 1): `(L + tau M) f = M^1/2 n`, `tau >= 0`.
    ///
    /// `tau = 0` (no screening, the paper's ablation) is the pseudo-inverse
    /// `f = L^+ M^1/2 n`: `L` is singular (it vanishes on the functions that
    /// are constant on each connected component), so the zero-mode part of
    /// the right-hand side is projected out before the solve and the sample
    /// has zero mass-weighted mean on every connected component. Spectrally
    /// `Var(c_i) = 1 / lambda_i^2` for `lambda_i > 0` and `0` for the zero
    /// modes. See [`NoiseSampler`](crate::NoiseSampler) for how it is solved.
    Matern {
        /// Screening weight, `>= 0` (units of an eigenvalue: 1 / length²);
        /// `0` means no screening.
        tau: f64,
    },
    /// Scale-normalized Matérn noise (paper Alg. 2): `tau = c Gamma`, the
    /// Matérn sample multiplied by `sqrt(Gamma)`. The same seed gives the same
    /// vertex values on a globally scaled copy of the mesh.
    MaternNormalized {
        /// Dimensionless screening factor, `> 0`.
        c: f64,
    },
    /// Smoother Matérn noise: the SPDE of [`Matern`](Self::Matern) with
    /// the operator to the power `p`, `(L + tau M)^p` in the sense of the
    /// generalized eigenproblem, i.e. `p` screened Poisson solves per
    /// sample with the one factor of `K = L + tau M`:
    /// `f = (tau K^-1 M)^(p-1) K^-1 M^1/2 n`. Spectrally
    /// `Var(c_i) = tau^(2p-2) / (lambda_i + tau)^(2p)`: the factor
    /// `tau^(p-1)` keeps the frequencies well below `tau` at the variance
    /// `1 / tau^2` of [`Matern`](Self::Matern) noise of the same `tau`,
    /// while the high frequencies fall as `lambda^-2p` instead of
    /// `lambda^-2`. On a surface this is Matérn smoothness `nu = 2p - 1`;
    /// with `p >= 2` a sample's bending energy (`sum lambda_i^2 Var(c_i)`)
    /// stays bounded as the mesh is refined, where that of
    /// [`Matern`](Self::Matern) noise grows with the vertex count: the
    /// noise to train on when samples are drawn on meshes much finer than
    /// the training mesh.
    MaternSmooth {
        /// Screening weight, `> 0`.
        tau: f64,
        /// Order `p`: solves per sample, `2 ..= `[`MAX_SMOOTH_ORDER`].
        order: u32,
    },
    /// The Matérn spectrum truncated to the `k` lowest eigenpairs, sampled
    /// explicitly in the eigenbasis. With `tau = 0` the zero eigenvalues
    /// (constant per connected component) are left out instead of dividing
    /// by zero.
    Explicit {
        /// Number of eigenpairs, `1 <= k <= V`.
        k: usize,
        /// Screening weight, `>= 0`.
        tau: f64,
    },
}

impl NoiseKind {
    /// Checks the parameters: `tau` in `[0, MAX_TAU]` for Matérn and
    /// explicit, `c > 0`, `k >= 1`, all finite.
    ///
    /// # Errors
    /// [`NoiseError::InvalidParameter`] naming the offending parameter.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, expected, v: f64| {
            Err(NoiseError::InvalidParameter {
                name,
                expected,
                found: fmt_f64(v),
            })
        };
        match *self {
            Self::Naive | Self::White => Ok(()),
            Self::Matern { tau } if !(tau.is_finite() && (0.0..=MAX_TAU).contains(&tau)) => bad(
                "tau",
                "in [0, 1e10] (0: no screening; the paper uses 100; larger values make the noise \
                 vanish)",
                tau,
            ),
            Self::MaternNormalized { c } if !(c.is_finite() && c > 0.0) => {
                bad("c", "a finite value > 0", c)
            }
            Self::MaternSmooth { tau, .. } if !(tau.is_finite() && tau > 0.0 && tau <= MAX_TAU) => {
                bad(
                    "tau",
                    "in (0, 1e10] (smooth Matérn noise needs screening; the paper's Matérn uses 100)",
                    tau,
                )
            }
            Self::MaternSmooth { order, .. } if !(2..=MAX_SMOOTH_ORDER).contains(&order) => {
                Err(NoiseError::InvalidParameter {
                    name: "order",
                    expected: "2, 3 or 4 (solves per sample; order 1 is plain Matérn noise, matern:TAU)",
                    found: order.to_string(),
                })
            }
            Self::Explicit { k: 0, .. } => Err(NoiseError::InvalidParameter {
                name: "k",
                expected: "at least 1 eigenpair",
                found: "0".to_owned(),
            }),
            Self::Explicit { tau, .. } if !(tau.is_finite() && (0.0..=MAX_TAU).contains(&tau)) => {
                bad("tau", "in [0, 1e10]", tau)
            }
            _ => Ok(()),
        }
    }

    /// The closed-form `Var(c_i)` of this kind for each eigenpair
    /// `(lambda_i, phi_i)` in `pairs` of a mesh with lumped mass `mass` and
    /// `gamma = ||M^-1 L||_F` (docs/conventions.md, "Noise"):
    ///
    /// - naive: `phi_i^T M^2 phi_i`;
    /// - white: `1`;
    /// - Matérn: `1 / (lambda_i + tau)^2`; without screening (`tau == 0`),
    ///   `1 / lambda_i^2` and `0` for the zero modes (eigenvalues at or below
    ///   `1e-8` times the largest one in `pairs`, as for the explicit kind);
    /// - normalized Matérn: `Gamma / (lambda_i + c Gamma)^2`;
    /// - smooth Matérn `(tau, p)`: `tau^(2p-2) / (lambda_i + tau)^(2p)`;
    /// - explicit `(k, tau)`: `1 / (lambda_i + tau)^2` for `i < k` (`0` for the
    ///   zero modes when `tau == 0`), `0` for `i >= k`.
    ///
    /// Cost: `O(V K)` for naive, `O(K)` otherwise.
    ///
    /// # Errors
    /// [`NoiseError::SizeMismatch`] if `mass` and the eigenvectors disagree on
    /// the vertex count.
    ///
    /// # Example
    /// ```
    /// use mfm_noise::{NoiseKind, procedural, spectrum};
    /// let mesh = procedural::icosphere(2);
    /// let ops = mfm_geometry::operators::Operators::new(&mesh).unwrap();
    /// let pairs = spectrum::eigenpairs(&ops.laplacian, &ops.mass, 8).unwrap();
    /// let v = NoiseKind::Matern { tau: 10.0 }.spectral_variance(&pairs, &ops.mass, 1.0).unwrap();
    /// assert_eq!(v[1], (pairs.values[1] + 10.0).powi(-2));
    /// ```
    pub fn spectral_variance(
        &self,
        pairs: &Eigenpairs,
        mass: &[f64],
        gamma: f64,
    ) -> Result<Vec<f64>> {
        check_vertices(pairs, mass.len())?;
        let values = &pairs.values;
        Ok(match *self {
            Self::Naive => (0..values.len())
                .map(|i| {
                    pairs
                        .vectors
                        .col(i)
                        .iter()
                        .zip(mass)
                        .map(|(p, m)| (p * m) * (p * m))
                        .sum()
                })
                .collect(),
            Self::White => vec![1.0; values.len()],
            Self::Matern { tau: 0.0 } => explicit_weights(values, 0.0)
                .into_iter()
                .map(|w| w * w)
                .collect(),
            Self::Matern { tau } => values.iter().map(|l| (l + tau).powi(-2)).collect(),
            Self::MaternNormalized { c } => values
                .iter()
                .map(|l| gamma / (l + c * gamma).powi(2))
                .collect(),
            Self::MaternSmooth { tau, order } => {
                let p = order as i32;
                values
                    .iter()
                    .map(|l| tau.powi(2 * p - 2) / (l + tau).powi(2 * p))
                    .collect()
            }
            Self::Explicit { k, tau } => {
                let kk = k.min(values.len());
                let mut v: Vec<f64> = explicit_weights(&values[..kk], tau)
                    .into_iter()
                    .map(|w| w * w)
                    .collect();
                v.resize(values.len(), 0.0);
                v
            }
        })
    }

    /// Short name of the kind without parameters: `naive`, `white`,
    /// `matern`, `matern-normalized` or `explicit`.
    pub fn name(&self) -> &'static str {
        self.kind_name().as_str()
    }

    /// The kind's [`KindName`].
    pub fn kind_name(&self) -> KindName {
        match self {
            Self::Naive => KindName::Naive,
            Self::White => KindName::White,
            Self::Matern { .. } => KindName::Matern,
            Self::MaternNormalized { .. } => KindName::MaternNormalized,
            Self::MaternSmooth { .. } => KindName::MaternSmooth,
            Self::Explicit { .. } => KindName::Explicit,
        }
    }

    /// The long form of a kind: its name and its parameters one by one
    /// (`--kind matern --tau 100` on the command line, the same kind as
    /// `matern:100`). A parameter left out takes its default
    /// ([`DEFAULT_TAU`], [`DEFAULT_NORMALIZED_C`], [`DEFAULT_EXPLICIT_K`],
    /// [`DEFAULT_SMOOTH_ORDER`]); the result is
    /// [validated](NoiseKind::validate).
    ///
    /// # Errors
    /// [`NoiseError::UnusedParameter`] for a parameter the kind does not
    /// take (rather than ignoring it), [`NoiseError::InvalidParameter`] for
    /// an out-of-range value.
    ///
    /// # Example
    /// ```
    /// use mfm_noise::kind::{KindName, KindParameters, NoiseKind};
    /// let tau = KindParameters { tau: Some(30.0), ..Default::default() };
    /// let long = NoiseKind::from_parts(KindName::Matern, tau).unwrap();
    /// assert_eq!(long, "matern:30".parse().unwrap());
    /// assert!(NoiseKind::from_parts(KindName::White, tau).is_err());
    /// let smooth = NoiseKind::from_parts(KindName::MaternSmooth, tau).unwrap();
    /// assert_eq!(smooth, NoiseKind::MaternSmooth { tau: 30.0, order: 2 });
    /// ```
    pub fn from_parts(name: KindName, parameters: KindParameters) -> Result<Self> {
        let KindParameters { tau, c, k, order } = parameters;
        let kind = name.as_str();
        let refuse = |parameter: &'static str, hint: &'static str| {
            Err(NoiseError::UnusedParameter {
                kind,
                parameter,
                hint,
            })
        };
        let (takes_tau, takes_c, takes_k, takes_order) = match name {
            KindName::Naive | KindName::White => (false, false, false, false),
            KindName::Matern => (true, false, false, false),
            KindName::MaternNormalized => (false, true, false, false),
            KindName::MaternSmooth => (true, false, false, true),
            KindName::Explicit => (true, false, true, false),
        };
        if tau.is_some() && !takes_tau {
            let hint = if name == KindName::MaternNormalized {
                " (it sets tau = c Gamma; give c)"
            } else {
                ""
            };
            return refuse("tau", hint);
        }
        if c.is_some() && !takes_c {
            return refuse("c", "");
        }
        if k.is_some() && !takes_k {
            return refuse("k", "");
        }
        if order.is_some() && !takes_order {
            let hint = if name == KindName::Matern {
                " (plain Matérn noise is order 1; matern-smooth takes an order)"
            } else {
                ""
            };
            return refuse("order", hint);
        }
        let tau = tau.unwrap_or(DEFAULT_TAU);
        let out = match name {
            KindName::Naive => Self::Naive,
            KindName::White => Self::White,
            KindName::Matern => Self::Matern { tau },
            KindName::MaternNormalized => Self::MaternNormalized {
                c: c.unwrap_or(DEFAULT_NORMALIZED_C),
            },
            KindName::MaternSmooth => Self::MaternSmooth {
                tau,
                order: order.unwrap_or(DEFAULT_SMOOTH_ORDER),
            },
            KindName::Explicit => Self::Explicit {
                k: k.unwrap_or(DEFAULT_EXPLICIT_K),
                tau,
            },
        };
        out.validate()?;
        Ok(out)
    }
}

/// The parameters of a kind's long form ([`NoiseKind::from_parts`]), each
/// `None` when not given.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct KindParameters {
    /// Screening weight (`matern`, `matern-smooth`, `explicit`).
    pub tau: Option<f64>,
    /// Screening factor of `matern-normalized`.
    pub c: Option<f64>,
    /// Eigenpairs of `explicit`.
    pub k: Option<usize>,
    /// Order of `matern-smooth`.
    pub order: Option<u32>,
}

impl fmt::Display for NoiseKind {
    /// The command-line form, which [`FromStr`] reads back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Naive | Self::White => f.write_str(self.name()),
            Self::Matern { tau } => write!(f, "matern:{}", fmt_f64(*tau)),
            Self::MaternNormalized { c } => write!(f, "matern-normalized:{}", fmt_f64(*c)),
            Self::MaternSmooth { tau, order } => {
                write!(f, "matern-smooth:{}:{order}", fmt_f64(*tau))
            }
            Self::Explicit { k, tau } => write!(f, "explicit:{k}:{}", fmt_f64(*tau)),
        }
    }
}

const FORMS: &str = "expected naive, white, matern[:TAU], matern-normalized:C (or normalized:C), \
                     matern-smooth[:TAU[:P]], explicit:K[:TAU]";

impl FromStr for NoiseKind {
    type Err = NoiseError;

    /// Parses `naive`, `white`, `matern[:TAU]`, `matern-normalized:C` (or
    /// `normalized:C`), `matern-smooth[:TAU[:P]]`, `explicit:K[:TAU]`
    /// (case-insensitive names; `TAU` defaults to [`DEFAULT_TAU`], `P` to
    /// [`DEFAULT_SMOOTH_ORDER`]), then [validates](NoiseKind::validate).
    fn from_str(s: &str) -> Result<Self> {
        let err = |reason: String| NoiseError::ParseKind {
            input: s.to_owned(),
            reason,
        };
        let parts: Vec<&str> = s.trim().split(':').map(str::trim).collect();
        let name = parts[0].to_ascii_lowercase();
        let num = |i: usize, what: &str| -> Result<f64> {
            parts[i]
                .parse::<f64>()
                .map_err(|e| err(format!("{what} {:?} is not a number ({e})", parts[i])))
        };
        let arity = |lo: usize, hi: usize| -> Result<()> {
            let n = parts.len() - 1;
            if n < lo || n > hi {
                Err(err(format!(
                    "{name} takes {lo} to {hi} parameters, found {n}; {FORMS}"
                )))
            } else {
                Ok(())
            }
        };
        let kind = match name.as_str() {
            "naive" => {
                arity(0, 0)?;
                Self::Naive
            }
            "white" => {
                arity(0, 0)?;
                Self::White
            }
            "matern" => {
                arity(0, 1)?;
                let tau = if parts.len() > 1 {
                    num(1, "tau")?
                } else {
                    DEFAULT_TAU
                };
                Self::Matern { tau }
            }
            "matern-smooth" | "matern_smooth" => {
                arity(0, 2)?;
                let tau = if parts.len() > 1 {
                    num(1, "tau")?
                } else {
                    DEFAULT_TAU
                };
                let order = match parts.get(2) {
                    Some(p) => p
                        .parse::<u32>()
                        .map_err(|e| err(format!("order {p:?} is not a whole number ({e})")))?,
                    None => DEFAULT_SMOOTH_ORDER,
                };
                Self::MaternSmooth { tau, order }
            }
            "matern-normalized" | "matern_normalized" | "normalized" => {
                arity(1, 1)?;
                Self::MaternNormalized { c: num(1, "c")? }
            }
            "explicit" => {
                arity(1, 2)?;
                let k = parts[1]
                    .parse::<usize>()
                    .map_err(|e| err(format!("k {:?} is not a count ({e})", parts[1])))?;
                let tau = if parts.len() > 2 {
                    num(2, "tau")?
                } else {
                    DEFAULT_TAU
                };
                Self::Explicit { k, tau }
            }
            _ => return Err(err(format!("unknown noise kind {name:?}; {FORMS}"))),
        };
        kind.validate()?;
        Ok(kind)
    }
}

/// A [`NoiseKind`] in its text form (`"matern:100"`, as the command line
/// and [`std::str::FromStr`] write it) instead of the tagged form of its
/// own `Serialize`: for a configuration field, with `#[serde(with =
/// "mfm_noise::kind::as_text")]`. Reading checks the kind as parsing does.
///
/// ```
/// #[derive(serde::Serialize, serde::Deserialize, Debug, PartialEq)]
/// struct Config {
///     #[serde(with = "mfm_noise::kind::as_text")]
///     noise: mfm_noise::NoiseKind,
/// }
/// let c = Config { noise: mfm_noise::NoiseKind::Matern { tau: 100.0 } };
/// let json = serde_json::to_string(&c).unwrap();
/// assert_eq!(json, r#"{"noise":"matern:100"}"#);
/// assert_eq!(serde_json::from_str::<Config>(&json).unwrap(), c);
/// assert!(serde_json::from_str::<Config>(r#"{"noise":"matern:-1"}"#).is_err());
/// ```
pub mod as_text {
    use serde::{Deserialize, Deserializer, Serializer};

    use super::NoiseKind;

    /// Writes `kind` as its text form.
    ///
    /// # Errors
    /// The serializer's.
    pub fn serialize<S: Serializer>(kind: &NoiseKind, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&kind.to_string())
    }

    /// Reads a kind from its text form.
    ///
    /// # Errors
    /// A custom error with the parse error's message.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<NoiseKind, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}
