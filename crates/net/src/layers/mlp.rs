//! The two-layer vertex MLP (`Linear, GELU, Linear`).

use tch::Tensor;
use tch::nn;

use crate::error::Result;

use super::{dense, gelu, linear};

/// Two-layer MLP `Linear, GELU, Linear`.
#[derive(Debug)]
pub(crate) struct Mlp {
    pub(crate) l1: nn::Linear,
    pub(crate) l2: nn::Linear,
}

impl Mlp {
    pub(crate) fn new(p: nn::Path<'_>, input: usize, hidden: usize, output: usize) -> Self {
        Self {
            l1: linear(&p / 0, input, hidden),
            l2: linear(&p / 1, hidden, output),
        }
    }

    pub(crate) fn forward(&self, x: &Tensor) -> Result<Tensor> {
        dense(&self.l2, &gelu(&dense(&self.l1, x)?))
    }
}
