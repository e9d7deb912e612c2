//! PoissonNet's layers, one file per kind (docs/network.md); the
//! network that assembles them is [`crate::model`], the kernels they run on
//! are [`mfm_kernels`].
//!
//! - [`ComplexLinear`] (`complex_linear.rs`): `z -> W z` on face features;
//! - [`VectorMlp`] (`vector_mlp.rs`): modulation, complex layers and the
//!   magnitude nonlinearity, ending in the divergence for a block;
//! - `Mlp` (`mlp.rs`): the vertex MLPs `Linear, GELU, Linear`;
//! - [`PoissonBlock`] (`block.rs`): gradient, vector MLP, Poisson solve with
//!   the mean removed, two LayerScale vertex MLPs.
//!
//! To change one layer, change its file: the model only calls `new` and
//! `forward` (and, for the vector MLP, its divergence forms).

mod block;
mod complex_linear;
mod mlp;
mod vector_mlp;

pub use block::PoissonBlock;
pub use complex_linear::ComplexLinear;
pub(crate) use mlp::Mlp;
pub use vector_mlp::VectorMlp;

use tch::{Tensor, nn};

use crate::error::Result;

pub(crate) fn linear(p: nn::Path<'_>, input: usize, output: usize) -> nn::Linear {
    // PyTorch's default initialization of nn.Linear
    let bound = 1.0 / (input.max(1) as f64).sqrt();
    let cfg = nn::LinearConfig {
        ws_init: nn::Init::Uniform {
            lo: -bound,
            up: bound,
        },
        bs_init: Some(nn::Init::Uniform {
            lo: -bound,
            up: bound,
        }),
        bias: true,
    };
    nn::linear(p, input as i64, output as i64, cfg)
}

/// Applies an `nn::Linear` through [`mfm_kernels::dense::linear`].
pub(crate) fn dense(l: &nn::Linear, x: &Tensor) -> Result<Tensor> {
    Ok(mfm_kernels::dense::linear(x, &l.ws, l.bs.as_ref())?)
}

pub(crate) fn gelu(x: &Tensor) -> Tensor {
    x.gelu("none")
}
