//! PoissonNet configuration and presets.

use serde::{Deserialize, Serialize};

use crate::error::{NetError, Result};

/// Which output head the network ends with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum HeadKind {
    /// Neural-Jacobian-field head: a modulated vector MLP (width `W` to
    /// `C_out`) on `G x`, plus the input's gradients `G X_in` as a residual
    /// (so `C_in = C_out`), then a Poisson solve with the mean removed.
    /// Outputs the vertex field and the Jacobian field.
    #[default]
    Njf,
    /// The NJF head without the input-gradient residual: the vector MLP's
    /// output alone is the Jacobian field (an ablation of the paper's head;
    /// `C_in` and `C_out` may differ). Same parameters as [`HeadKind::Njf`].
    NjfNoInputGradient,
    /// A per-vertex `Linear(W, C_out)` on the final features (vertex output
    /// only).
    Linear,
}

impl HeadKind {
    /// Whether this is one of the neural-Jacobian-field heads (vertex and
    /// Jacobian outputs, the vertex output's mean removed).
    pub fn is_njf(self) -> bool {
        matches!(self, Self::Njf | Self::NjfNoInputGradient)
    }
}

/// Hyper-parameters of a [`crate::PoissonNet`]; stored as JSON next to the
/// weights.
///
/// Architecture (docs/network.md): `proj_in: Linear(C_in, W)`; a
/// conditioning MLP `Linear(C_e, W), GELU, Linear(W, W)` shared by every block
/// (absent when `cond_channels == 0`); `blocks` Poisson blocks of width `W`
/// with `vector_layers` complex layers each; then the head.
///
/// # Example
/// ```
/// use mfm_net::PoissonNetConfig;
/// let c = PoissonNetConfig::paper();
/// assert_eq!((c.width, c.blocks, c.vector_layers), (128, 5, 3));
/// assert_eq!(c.num_parameters(), 1_369_600);
/// let json = serde_json::to_string(&c).unwrap();
/// assert_eq!(serde_json::from_str::<PoissonNetConfig>(&json).unwrap(), c);
/// ```
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoissonNetConfig {
    /// Hidden width `W` (channels of vertex and face features).
    pub width: usize,
    /// Number of Poisson blocks `K`.
    pub blocks: usize,
    /// Complex linear layers per vector MLP (`nl`, at least 1); all but the
    /// last are followed by the magnitude nonlinearity.
    pub vector_layers: usize,
    /// Input channels `C_in` per vertex.
    pub in_channels: usize,
    /// Output channels `C_out` per vertex.
    pub out_channels: usize,
    /// Conditioning channels `C_e` per vertex (0: no conditioning).
    pub cond_channels: usize,
    /// Whether vector MLPs are modulated by the face means of the features.
    #[serde(default = "default_true")]
    pub modulation: bool,
    /// The output head.
    #[serde(default)]
    pub head: HeadKind,
    /// Whether every block also reads a global view of the shape: the
    /// mass-weighted mean over the whole surface of its first vertex MLP's
    /// hidden features, through `Linear(W, W)` (no bias), added to every
    /// vertex's output of that MLP (`blocks.k.global.weight`). A surface
    /// integral, so it converges under refinement like the rest of the
    /// network; it gives each vertex what the Poisson solves convey only
    /// smoothed: which shape the whole surface is becoming. Default `false`
    /// (the paper's network); not written to JSON when `false`, so earlier
    /// files read and write unchanged.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub global_context: bool,
}

fn default_true() -> bool {
    true
}

/// Names accepted by [`PoissonNetConfig::preset`].
pub const PRESETS: [&str; 3] = ["paper", "medium", "small"];

impl PoissonNetConfig {
    /// The paper's configuration: `W = 128`, `K = 5`, `nl = 3`, modulation on,
    /// `C_in = C_out = 3`, `C_e = 4` (noisy xyz in, source xyz and `t` as
    /// conditioning), NJF head: 1,369,600 parameters.
    pub fn paper() -> Self {
        Self::deformation(128, 5)
    }

    /// `W = 64`, `K = 4` (otherwise as [`PoissonNetConfig::paper`]):
    /// 282,688 parameters.
    pub fn medium() -> Self {
        Self::deformation(64, 4)
    }

    /// `W = 32`, `K = 3` (otherwise as [`PoissonNetConfig::paper`]):
    /// 56,000 parameters.
    pub fn small() -> Self {
        Self::deformation(32, 3)
    }

    /// A deformation model (`C_in = C_out = 3`, `C_e = 4`, `nl = 3`, NJF head)
    /// of width `width` with `blocks` blocks.
    pub fn deformation(width: usize, blocks: usize) -> Self {
        Self {
            width,
            blocks,
            vector_layers: 3,
            in_channels: 3,
            out_channels: 3,
            cond_channels: 4,
            modulation: true,
            head: HeadKind::Njf,
            global_context: false,
        }
    }

    /// A preset by name: `paper`, `medium` or `small`.
    ///
    /// Errors: [`NetError::Config`] naming the known presets.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(Self::paper()),
            "medium" => Ok(Self::medium()),
            "small" => Ok(Self::small()),
            other => Err(NetError::Config(format!(
                "unknown preset {other:?}; expected one of {}",
                PRESETS.join(", ")
            ))),
        }
    }

    /// Checks the values: positive sizes, `vector_layers >= 1`, and
    /// `in_channels == out_channels` for the NJF head (its residual adds the
    /// input's gradients to the output's).
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("width", self.width),
            ("vector_layers", self.vector_layers),
            ("in_channels", self.in_channels),
            ("out_channels", self.out_channels),
        ];
        for (name, v) in positive {
            if v == 0 {
                return Err(NetError::Config(format!(
                    "{name} must be at least 1, found 0"
                )));
            }
        }
        if self.head == HeadKind::Njf && self.in_channels != self.out_channels {
            return Err(NetError::Config(format!(
                "the NJF head adds G X_in to its output, so in_channels must equal out_channels; found {} and {}",
                self.in_channels, self.out_channels
            )));
        }
        Ok(())
    }

    /// Parameters of one vector MLP from `W` to `out` channels (in `u128`,
    /// so no size overflows).
    fn vector_mlp_parameters(&self, out: usize) -> u128 {
        let w = self.width as u128;
        let modulation = if self.modulation {
            (w * w + w) + (w * 2 * w + 2 * w)
        } else {
            0
        };
        let n = self.vector_layers as u128;
        // the first n - 1 layers are W -> W, the last W -> out
        let layers = n.saturating_sub(1) * 2 * w * w + 2 * w * out as u128;
        modulation + layers + n.saturating_sub(1) * w
    }

    /// Parameters of one Poisson block, in `u128`.
    fn block_parameters_wide(&self) -> u128 {
        let w = self.width as u128;
        let h = if self.cond_channels > 0 { 3 * w } else { 2 * w };
        let mlp1 = (h * w + w) + (w * w + w);
        let mlp2 = 2 * (w * w + w);
        let global = if self.global_context { w * w } else { 0 };
        self.vector_mlp_parameters(self.width) + mlp1 + mlp2 + 2 * w + global
    }

    /// Parameters of one Poisson block (saturating at `usize::MAX`).
    pub fn block_parameters(&self) -> usize {
        usize::try_from(self.block_parameters_wide()).unwrap_or(usize::MAX)
    }

    /// Total number of trainable parameters in `u128` (computed from the
    /// sizes, so absurd sizes give a number instead of an overflow).
    pub fn num_parameters_wide(&self) -> u128 {
        let w = self.width as u128;
        let proj = self.in_channels as u128 * w + w;
        let cond = if self.cond_channels > 0 {
            (self.cond_channels as u128 * w + w) + (w * w + w)
        } else {
            0
        };
        let out = self.out_channels as u128;
        let head = match self.head {
            HeadKind::Njf | HeadKind::NjfNoInputGradient => {
                self.vector_mlp_parameters(self.out_channels)
            }
            HeadKind::Linear => w * out + out,
        };
        proj + cond + (self.blocks as u128).saturating_mul(self.block_parameters_wide()) + head
    }

    /// Total number of trainable parameters (computed from the sizes; equals
    /// the count of a built [`crate::PoissonNet`]; saturating at
    /// `usize::MAX`).
    pub fn num_parameters(&self) -> usize {
        usize::try_from(self.num_parameters_wide()).unwrap_or(usize::MAX)
    }

    /// Refuses a network whose `bytes_per_parameter` bytes per parameter
    /// (4 for the weights alone; 20 to train: weights, gradients, two Adam
    /// moments and a weight average) exceed this machine's available
    /// memory, before anything is allocated.
    ///
    /// Errors: [`NetError::Config`] naming the size, the need and what is
    /// available.
    pub fn ensure_fits(&self, bytes_per_parameter: u128) -> Result<()> {
        let params = self.num_parameters_wide();
        let what = format!(
            "a network of width {} with {} blocks ({params} parameters{})",
            self.width,
            self.blocks,
            if bytes_per_parameter > 4 {
                ", with gradients and optimizer state"
            } else {
                ""
            }
        );
        match mfm_files::space::ensure_memory(&what, params, bytes_per_parameter) {
            Err(mfm_files::FileError::NoMemory {
                needed, available, ..
            }) => Err(NetError::Config(format!(
                "{what} needs {} of memory, but this machine has {} available; lower \
                 model.width or model.blocks",
                mfm_files::space::human_bytes(needed),
                mfm_files::space::human_bytes(available)
            ))),
            Err(other) => Err(NetError::Config(other.to_string())),
            Ok(()) => Ok(()),
        }
    }

    /// Floating-point operations (two per multiply-add) of the dense matrix
    /// products in one forward pass of one batch item on a mesh with
    /// `num_vertices` vertices and `num_faces` faces, as the CPU path of
    /// [`crate::PoissonNet::forward`] runs them: complex layers at least
    /// [`mfm_kernels::dense::GAUSS_MIN_WIDTH`] wide with three real products
    /// (narrower ones with four), the modulation's first layer and each
    /// block's last complex layer on vertices, and the columns of the first
    /// vertex MLP that read the solve output folded into that last layer
    /// (see [`crate::model`]). A training step's backward pass does exactly
    /// twice these products (input and weight gradients), so a step costs
    /// `3 B` times this. Not counted: the solves, the mesh operators, the
    /// elementwise work and the `O(W^3)` products of weights with weights.
    ///
    /// For the paper preset on bunny (3485 vertices, 6966 faces) this is
    /// about 15.78 GFLOP, so ~379 GFLOP per training step at batch 8.
    pub fn forward_product_flops(&self, num_vertices: usize, num_faces: usize) -> u64 {
        let (v, f) = (num_vertices as u64, num_faces as u64);
        let w = self.width as u64;
        // multiply-adds of `rows` complex rows through a `k -> o` complex layer
        let complex = |rows: u64, k: u64, o: u64| {
            let products = if k.min(o) >= mfm_kernels::dense::GAUSS_MIN_WIDTH as u64 {
                3
            } else {
                4
            };
            products * rows * k * o
        };
        let modulation = if self.modulation {
            v * w * w + f * w * 2 * w
        } else {
            0
        };
        let hidden = (self.vector_layers as u64 - 1) * complex(f, w, w);
        let conditioned = self.cond_channels > 0;
        let mlp1_direct = if conditioned { 2 * w } else { w };
        let block = modulation
            + hidden
            + v * 2 * w * w // last complex layer after the divergence
            + v * mlp1_direct * w
            + v * w * w // MLP1's second layer
            + 2 * v * w * w // MLP2
            + if self.global_context { w * w } else { 0 }; // global context
        let out = self.out_channels as u64;
        let head = match self.head {
            HeadKind::Njf | HeadKind::NjfNoInputGradient => {
                modulation + hidden + complex(f, w, out)
            }
            HeadKind::Linear => v * w * out,
        };
        let cond = if conditioned {
            v * self.cond_channels as u64 * w + v * w * w
        } else {
            0
        };
        let proj = v * self.in_channels as u64 * w;
        2 * (proj + cond + self.blocks as u64 * block + head)
    }
}
