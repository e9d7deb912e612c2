//! PoissonNet: the network assembled from its [`crate::layers`], saving and
//! loading.
//!
//! The layers follow docs/network.md. Face features are complex numbers
//! stored as real tensors `[B, 2F, C]` (rows `2f, 2f + 1` the real and
//! imaginary parts, i.e. the two tangent components of face `f`; see
//! [`crate::mesh`]). Every face operation is equivariant under a rotation of
//! each face's frame (multiplication by a unit complex number per face), so
//! the vertex outputs do not depend on the frames.
//!
//! One exact rewrite saves work without changing the function: the first
//! modulation layer is affine, and face means are averages, so
//! `Linear1(face_mean(x)) = face_mean(Linear1(x))`; it runs on the `V`
//! vertices instead of the `F ~ 2V` faces.
//!
//! Two more rewrites move products from faces to vertices or drop them:
//! a block needs only the divergence of its vector MLP's output, so the last
//! complex layer runs after the divergence, on vertices
//! ([`VectorMlp::forward_divergence`]); and the block's solve output `u` is
//! read only by the first vertex MLP's first layer, through the columns `B`
//! of its weight that multiply `u`. The solve and the mass-weighted mean
//! removal act on each channel alike (linear maps over vertices), so they
//! commute with a channel map: `u B^T = remove_mean(solve(div B^T))`, and
//! `B` is folded into the last complex layer's weight before the solve
//! ([`VectorMlp::forward_divergence_mapped`]), which saves one `[V, W] x [W,
//! W]` product per block.
//!
//! ## Variables (names in the safetensors file)
//! - `proj_in.{weight,bias}`: `Linear(C_in, W)`;
//!   `cond.{0,1}.{weight,bias}`: `Linear(C_e, W)`, `Linear(W, W)`.
//! - `blocks.k.vector.mod.{0,1}.{weight,bias}`: modulation `Linear(W, W)`,
//!   `Linear(W, 2W)` (output channels `0..W` are the phase, `W..2W` the raw
//!   scale); `blocks.k.vector.layers.i.weight`: complex layer `i` as
//!   `[2, C_out, C_in]` (real part, imaginary part; `z -> W z`);
//!   `blocks.k.vector.bias.i`: nonlinearity bias after layer `i`;
//!   `blocks.k.mlp{1,2}.{0,1}.{weight,bias}`; `blocks.k.gamma{1,2}`.
//! - NJF head: `head.mod.*`, `head.layers.i.weight`, `head.bias.i` as in a
//!   block's vector MLP (last layer to `C_out`); linear head:
//!   `head.linear.{weight,bias}`.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use tch::nn;
use tch::{Device, Kind, Tensor};

use crate::config::{HeadKind, PoissonNetConfig};
use crate::error::{KernelError, NetError, Result, shape_error};
use crate::layers::{Mlp, PoissonBlock, VectorMlp, dense, linear};
use mfm_kernels::mesh::MeshTensors;
use mfm_kernels::profile::section;

pub use mfm_kernels::fused::{
    MAGNITUDE_EPS, SCALE_EPS, magnitude_gelu_reference, modulate_reference,
};

#[derive(Debug)]
enum Head {
    /// The vector MLP, and whether `G X_in` is added to its output.
    Njf(VectorMlp, bool),
    Linear(nn::Linear),
}

/// What [`PoissonNet::forward`] returns.
#[derive(Debug)]
pub struct PoissonNetOutput {
    /// Vertex output `[B, V, C_out]` (for the NJF head: the vertex velocity
    /// `u`, mass-weighted mean zero per channel and component).
    pub vertex: Tensor,
    /// Jacobian output `[B, 2F, C_out]` (NJF head only): the face gradients
    /// `g'` whose Poisson solve gave `vertex`.
    pub jacobian: Option<Tensor>,
}

/// One row of [`Summary`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LayerRow {
    /// Variable name (`blocks.0.vector.layers.1.weight`, ...).
    pub name: String,
    /// Its shape.
    pub shape: Vec<i64>,
    /// Its number of elements.
    pub params: usize,
}

/// The network's variables (in natural name order) and their total.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Summary {
    /// One row per variable.
    pub rows: Vec<LayerRow>,
    /// Sum of `params` over the rows.
    pub total: usize,
}

/// A preset's configuration with its parameter count, as `mfm net summary
/// --json` prints it.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PresetReport<'a> {
    /// The configuration.
    pub config: &'a PoissonNetConfig,
    /// Its number of parameters.
    pub parameters: usize,
    /// The preset's name.
    pub preset: &'a str,
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let w = self
            .rows
            .iter()
            .map(|r| r.name.len())
            .max()
            .unwrap_or(4)
            .max(4);
        writeln!(f, "{:<w$}  {:<16}  {:>10}", "name", "shape", "params")?;
        for r in &self.rows {
            let shape = format!("{:?}", r.shape);
            writeln!(f, "{:<w$}  {:<16}  {:>10}", r.name, shape, r.params)?;
        }
        write!(f, "{:<w$}  {:<16}  {:>10}", "total", "", self.total)
    }
}

/// Orders names with embedded numbers numerically (`blocks.2` < `blocks.10`).
fn natural_key(s: &str) -> Vec<(String, u64)> {
    s.split('.')
        .map(|part| match part.parse::<u64>() {
            Ok(n) => (String::new(), n),
            Err(_) => (part.to_owned(), 0),
        })
        .collect()
}

/// PoissonNet (docs/network.md) on a tch [`nn::VarStore`].
///
/// Input conventions: vertex features `x: [B, V, C_in]` (or `[V, C_in]`),
/// conditioning `cond: [B, V, C_e]` (or `[V, C_e]`, shared by the batch), all
/// of one mesh; use [`PoissonNet::forward_many`] for a batch of different
/// meshes. The parameters' element type (`f32` by default, see
/// [`PoissonNet::set_kind`]) must match the inputs'.
///
/// # Example
/// ```
/// use mfm_geometry::procedural;
/// use mfm_net::{MeshTensors, PoissonNet, PoissonNetConfig};
/// use tch::{Device, Kind, Tensor};
///
/// let mesh = procedural::icosphere(1);
/// let mt = MeshTensors::new(&mesh).unwrap();
/// let cfg = PoissonNetConfig { width: 8, blocks: 1, ..PoissonNetConfig::small() };
/// let net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
/// let v = mt.num_vertices() as i64;
/// let x = Tensor::randn([2, v, 3], (Kind::Float, Device::Cpu));
/// let e = Tensor::randn([2, v, 4], (Kind::Float, Device::Cpu));
/// let out = net.forward(&mt, &x, Some(&e)).unwrap();
/// assert_eq!(out.vertex.size(), vec![2, v, 3]);
/// assert_eq!(out.jacobian.unwrap().size(), vec![2, 2 * mt.num_faces() as i64, 3]);
/// ```
#[derive(Debug)]
pub struct PoissonNet {
    config: PoissonNetConfig,
    vs: nn::VarStore,
    proj_in: nn::Linear,
    cond: Option<Mlp>,
    blocks: Vec<PoissonBlock>,
    head: Head,
}

impl PoissonNet {
    /// Builds a freshly initialized network on `device` (`f32` parameters).
    ///
    /// The parameters are drawn on the CPU, from libtorch's CPU generator
    /// (`tch::manual_seed`), and then moved to `device`: a seed gives the same
    /// initial network on every device (CUDA's generator draws other numbers).
    ///
    /// Errors: [`NetError::Config`] for an invalid configuration, or one
    /// whose weights do not fit in the available memory
    /// ([`PoissonNetConfig::ensure_fits`]).
    pub fn new(config: &PoissonNetConfig, device: Device) -> Result<Self> {
        config.validate()?;
        config.ensure_fits(4)?;
        let mut vs = nn::VarStore::new(Device::Cpu);
        let root = vs.root();
        let w = config.width;
        let proj_in = linear(&root / "proj_in", config.in_channels, w);
        let conditioned = config.cond_channels > 0;
        let cond = conditioned.then(|| Mlp::new(&root / "cond", config.cond_channels, w, w));
        let blocks = (0..config.blocks)
            .map(|k| {
                PoissonBlock::new(
                    &root / "blocks" / k,
                    w,
                    config.vector_layers,
                    config.modulation,
                    conditioned,
                    config.global_context,
                )
            })
            .collect();
        let head = match config.head {
            HeadKind::Njf | HeadKind::NjfNoInputGradient => Head::Njf(
                VectorMlp::new(
                    &root / "head",
                    w,
                    config.vector_layers,
                    config.out_channels,
                    config.modulation,
                ),
                config.head == HeadKind::Njf,
            ),
            HeadKind::Linear => {
                Head::Linear(linear(&root / "head" / "linear", w, config.out_channels))
            }
        };
        if device != Device::Cpu {
            vs.set_device(device);
        }
        Ok(Self {
            config: config.clone(),
            vs,
            proj_in,
            cond,
            blocks,
            head,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &PoissonNetConfig {
        &self.config
    }

    /// The variable store (for optimizers: `nn::Adam::default().build(net.var_store(), lr)`).
    pub fn var_store(&self) -> &nn::VarStore {
        &self.vs
    }

    /// Mutable access to the variable store.
    pub fn var_store_mut(&mut self) -> &mut nn::VarStore {
        &mut self.vs
    }

    /// The device of the parameters.
    pub fn device(&self) -> Device {
        self.vs.device()
    }

    /// The element type of the parameters.
    pub fn kind(&self) -> Kind {
        self.vs
            .trainable_variables()
            .first()
            .map(|t| t.kind())
            .unwrap_or(Kind::Float)
    }

    /// Converts all parameters to `kind` (`Kind::Double` for gradient checks).
    pub fn set_kind(&mut self, kind: Kind) {
        self.vs.set_kind(kind);
    }

    /// Number of trainable parameters (elements).
    pub fn num_parameters(&self) -> usize {
        self.vs
            .trainable_variables()
            .iter()
            .map(|t| t.numel())
            .sum()
    }

    /// The variables (natural name order) with shapes and sizes, and the total.
    pub fn summary(&self) -> Summary {
        let mut rows: Vec<LayerRow> = self
            .vs
            .variables()
            .into_iter()
            .map(|(name, t)| LayerRow {
                name,
                shape: t.size(),
                params: t.numel(),
            })
            .collect();
        rows.sort_by_key(|r| natural_key(&r.name));
        let total = rows.iter().map(|r| r.params).sum();
        Summary { rows, total }
    }

    fn batched(&self, t: &Tensor, what: &str, v: i64, c: usize) -> Result<Tensor> {
        let expected = || format!("[B, V={v}, {c}] or [V={v}, {c}]");
        let t = match t.dim() {
            2 => t.unsqueeze(0),
            3 => t.shallow_clone(),
            _ => return Err(shape_error(what, expected(), t)),
        };
        let s = t.size();
        if s[1] != v || s[2] != c as i64 {
            return Err(shape_error(what, expected(), &t));
        }
        if t.kind() != self.kind() {
            return Err(KernelError::Kind {
                what: format!("{what} (the parameters are {:?})", self.kind()),
                kind: t.kind(),
            }
            .into());
        }
        Ok(t)
    }

    /// Runs the network on one mesh.
    ///
    /// `x`: `[B, V, C_in]` or `[V, C_in]`; `cond`: `[B, V, C_e]`, `[1, V, C_e]`
    /// or `[V, C_e]`, required exactly when `C_e > 0`. Outputs are batched
    /// (`[B, ...]`) even for an unbatched input.
    ///
    /// Cost: the dense products of
    /// [`PoissonNetConfig::forward_product_flops`] per batch item (about
    /// `(3 (nl - 1) + 2) F W^2 + 8 V W^2` multiply-adds per block, with
    /// conditioning), plus one multi-column solve of `B W` right-hand sides
    /// per block, and twice those products again in the backward pass. For
    /// the paper preset at batch 8 on a 3.5k-vertex mesh that is ~126 GFLOP
    /// forward, ~379 per training step.
    ///
    /// Errors: [`KernelError::Shape`] / [`KernelError::Kind`] (as
    /// [`NetError::Kernel`]) for inputs that do not fit the mesh or the
    /// configuration, solver errors from the solves.
    pub fn forward(
        &self,
        mesh: &MeshTensors,
        x: &Tensor,
        cond: Option<&Tensor>,
    ) -> Result<PoissonNetOutput> {
        self.forward_over(mesh, None, x, cond)
    }

    /// [`PoissonNet::forward`] with every per-face computation run face
    /// block by face block: `blocks` are [`MeshTensors::face_blocks`] of
    /// `mesh`. Only one block's face activations (of width `W`) exist at a
    /// time, so on a mesh of millions of faces the memory is that of a
    /// block, not of the mesh; the vertex outputs are the same function up
    /// to the order of the sums over faces (the Jacobian output is the
    /// blocks' outputs concatenated). For inference: the backward pass
    /// works, but keeps every block's activations anyway.
    ///
    /// # Errors
    /// As [`PoissonNet::forward`]; [`NetError::Config`] for no blocks.
    pub fn forward_blocks(
        &self,
        mesh: &MeshTensors,
        blocks: &[MeshTensors],
        x: &Tensor,
        cond: Option<&Tensor>,
    ) -> Result<PoissonNetOutput> {
        if blocks.is_empty() {
            return Err(NetError::Config("no face blocks to run on".into()));
        }
        self.forward_over(mesh, Some(blocks), x, cond)
    }

    fn forward_over(
        &self,
        mesh: &MeshTensors,
        blocks: Option<&[MeshTensors]>,
        x: &Tensor,
        cond: Option<&Tensor>,
    ) -> Result<PoissonNetOutput> {
        let v = mesh.num_vertices() as i64;
        let x_in = self.batched(x, "input features", v, self.config.in_channels)?;
        let b = x_in.size()[0];
        let e = match (cond, self.cond.as_ref()) {
            (Some(c), Some(mlp)) => {
                let c = self.batched(c, "conditioning", v, self.config.cond_channels)?;
                let cb = c.size()[0];
                if cb != b && cb != 1 {
                    return Err(shape_error(
                        "conditioning",
                        format!("batch {b} or 1 (the input's batch is {b})"),
                        &c,
                    ));
                }
                let _s = section("cond_mlp");
                let e = mlp.forward(&c)?;
                Some(if cb == b {
                    e
                } else {
                    e.expand([b, v, self.config.width as i64], false)
                })
            }
            (None, None) => None,
            (Some(c), None) => {
                return Err(shape_error(
                    "conditioning",
                    "no conditioning (the configuration has cond_channels = 0)",
                    c,
                ));
            }
            (None, Some(_)) => {
                return Err(NetError::Config(format!(
                    "this network expects conditioning with {} channels per vertex",
                    self.config.cond_channels
                )));
            }
        };
        let mut h = {
            let _s = section("proj_in");
            dense(&self.proj_in, &x_in)?
        };
        for (k, block) in self.blocks.iter().enumerate() {
            let _s = section(format!("block{k}"));
            h = match blocks {
                None => block.forward(&h, e.as_ref(), mesh)?,
                Some(faces) => block.forward_blocks(&h, e.as_ref(), mesh, faces)?,
            };
        }
        let _s = section("head");
        match &self.head {
            Head::Linear(l) => Ok(PoissonNetOutput {
                vertex: dense(l, &h)?,
                jacobian: None,
            }),
            Head::Njf(vector, input_gradient) => {
                let with_input = |g: Tensor, m: &MeshTensors| -> Result<Tensor> {
                    Ok(if *input_gradient {
                        g + m.gradient(&x_in)?
                    } else {
                        g
                    })
                };
                let (g, div) = match blocks {
                    None => {
                        let g = with_input(vector.forward(&mesh.gradient(&h)?, &h, mesh)?, mesh)?;
                        let div = mesh.divergence(&g)?;
                        (g, div)
                    }
                    Some(faces) => {
                        let mut parts = Vec::with_capacity(faces.len());
                        let mut div: Option<Tensor> = None;
                        for (g, m) in vector.forward_blocks(&h, faces)?.into_iter().zip(faces) {
                            let g = with_input(g, m)?;
                            let d = m.divergence(&g)?;
                            div = Some(match div {
                                Some(acc) => acc + d,
                                None => d,
                            });
                            parts.push(g);
                        }
                        let div =
                            div.ok_or_else(|| NetError::Config("no face blocks to run on".into()))?;
                        (Tensor::cat(&parts, -2), div)
                    }
                };
                let u = {
                    let _s = section("head.poisson");
                    mesh.remove_mass_mean(&mesh.solve(&div)?)?
                };
                Ok(PoissonNetOutput {
                    vertex: u,
                    jacobian: Some(g),
                })
            }
        }
    }

    /// Runs the network on several meshes (one [`PoissonNet::forward`] per
    /// item, each with its own batch; the outputs keep the items' order).
    /// Gradients of a loss summed over the items flow to the shared
    /// parameters as usual.
    pub fn forward_many(
        &self,
        items: &[(&MeshTensors, &Tensor, Option<&Tensor>)],
    ) -> Result<Vec<PoissonNetOutput>> {
        items
            .iter()
            .map(|(m, x, c)| self.forward(m, x, *c))
            .collect()
    }

    /// The path of the configuration written next to a weights file:
    /// `model.safetensors -> model.json`.
    pub fn config_path(weights: &Path) -> PathBuf {
        weights.with_extension("json")
    }

    /// Writes the weights to `path` (safetensors; the name must end in
    /// `.safetensors`) and the configuration as JSON to
    /// [`PoissonNet::config_path`]. Each file is written to a temporary name
    /// in the same folder and renamed, so a crash never leaves a torn file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        if path.extension().and_then(|e| e.to_str()) != Some("safetensors") {
            return Err(NetError::Config(format!(
                "weights file {} must have the extension .safetensors",
                path.display()
            )));
        }
        let refused = |e: mfm_files::FileError| match e {
            mfm_files::FileError::Io { path, source } => NetError::Io { path, source },
            other => NetError::Io {
                path: path.to_path_buf(),
                source: std::io::Error::other(other.to_string()),
            },
        };
        // libtorch writes the weights to a path of its own: a temporary file
        // beside the (link-resolved) target, renamed over it once complete.
        let target = mfm_files::atomic::resolve_target(path).map_err(refused)?;
        let stem = target
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("weights");
        let tmp = target.with_file_name(format!(".{stem}.tmp-{}.safetensors", std::process::id()));
        let saved = self.vs.save(&tmp).map_err(NetError::from).and_then(|()| {
            std::fs::File::open(&tmp)
                .and_then(|f| f.sync_all())
                .and_then(|()| std::fs::rename(&tmp, &target))
                .map_err(|source| NetError::Io {
                    path: path.to_path_buf(),
                    source,
                })
        });
        if let Err(e) = saved {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
        let cfg_path = Self::config_path(path);
        let json = serde_json::to_string_pretty(&self.config).map_err(|source| NetError::Json {
            path: cfg_path.clone(),
            source,
        })?;
        mfm_files::write_atomic(&cfg_path, |w| w.write_all(json.as_bytes())).map_err(refused)
    }

    /// Reads the configuration written next to `weights` by [`PoissonNet::save`].
    pub fn read_config(weights: impl AsRef<Path>) -> Result<PoissonNetConfig> {
        let path = Self::config_path(weights.as_ref());
        let text = std::fs::read_to_string(&path).map_err(|source| NetError::Io {
            path: path.clone(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| NetError::Json { path, source })
    }

    /// Builds the network described by the configuration next to `weights`
    /// and loads the weights, on `device`.
    pub fn load(weights: impl AsRef<Path>, device: Device) -> Result<Self> {
        let config = Self::read_config(weights.as_ref())?;
        let mut net = Self::new(&config, device)?;
        net.load_weights(weights)?;
        Ok(net)
    }

    /// Loads weights saved by [`PoissonNet::save`] into this network.
    ///
    /// Errors: [`NetError::WeightsMismatch`] naming the file and what differs
    /// when the configuration next to the file differs from this network's,
    /// or when the file's tensors (names or shapes) do not match this
    /// network's variables; nothing is loaded then.
    pub fn load_weights(&mut self, weights: impl AsRef<Path>) -> Result<()> {
        let path = weights.as_ref();
        let mismatch = |detail: String| NetError::WeightsMismatch {
            path: path.to_path_buf(),
            detail,
        };
        if Self::config_path(path).is_file() {
            let theirs = Self::read_config(path)?;
            if theirs != self.config {
                return Err(mismatch(config_difference(&theirs, &self.config)));
            }
        }
        let file: HashMap<String, Tensor> = Tensor::read_safetensors(path)?.into_iter().collect();
        let mine = self.vs.variables();
        let mut problems = Vec::new();
        let mut missing: Vec<&String> = mine.keys().filter(|k| !file.contains_key(*k)).collect();
        missing.sort();
        if !missing.is_empty() {
            problems.push(format!("missing in the file: {}", list(&missing)));
        }
        let mut extra: Vec<&String> = file.keys().filter(|k| !mine.contains_key(*k)).collect();
        extra.sort();
        if !extra.is_empty() {
            problems.push(format!("not in the network: {}", list(&extra)));
        }
        let mut shapes: Vec<String> = mine
            .iter()
            .filter_map(|(k, t)| {
                let f = file.get(k)?;
                (f.size() != t.size())
                    .then(|| format!("{k}: file {:?}, network {:?}", f.size(), t.size()))
            })
            .collect();
        shapes.sort();
        if !shapes.is_empty() {
            problems.push(format!("shape differences: {}", list(&shapes)));
        }
        if !problems.is_empty() {
            return Err(mismatch(problems.join("; ")));
        }
        tch::no_grad(|| -> Result<()> {
            for (k, mut t) in mine {
                if let Some(src) = file.get(&k) {
                    t.f_copy_(&src.to_kind(t.kind()).to_device(t.device()))?;
                }
            }
            Ok(())
        })
    }
}

fn list<T: std::fmt::Display>(items: &[T]) -> String {
    const SHOWN: usize = 6;
    let mut s: Vec<String> = items.iter().take(SHOWN).map(|x| x.to_string()).collect();
    if items.len() > SHOWN {
        s.push(format!("and {} more", items.len() - SHOWN));
    }
    s.join(", ")
}

fn config_difference(file: &PoissonNetConfig, net: &PoissonNetConfig) -> String {
    let to_map = |c: &PoissonNetConfig| -> BTreeMap<String, String> {
        match serde_json::to_value(c) {
            Ok(serde_json::Value::Object(m)) => {
                m.into_iter().map(|(k, v)| (k, v.to_string())).collect()
            }
            _ => BTreeMap::new(),
        }
    };
    let (a, b) = (to_map(file), to_map(net));
    // fields left out of the JSON at their default (global_context) are
    // compared too, read as the default
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let default = String::from("its default");
    let diffs: Vec<String> = keys
        .into_iter()
        .filter_map(|k| {
            let (va, vb) = (a.get(k).unwrap_or(&default), b.get(k).unwrap_or(&default));
            (va != vb)
                .then(|| format!("{k} = {va} in the file's configuration, {vb} in the network's"))
        })
        .collect();
    format!("configuration differs: {}", diffs.join(", "))
}
