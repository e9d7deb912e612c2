//! The complex linear layer of the vector MLPs.

use tch::Tensor;
use tch::nn;

use crate::error::Result;
use crate::error::shape_error;
use mfm_kernels::mesh::MeshTensors;

/// Complex linear map `z -> W z` on face features, `W = W_re + i W_im`
/// (`[C_out, C_in]` each, stored as one `[2, C_out, C_in]` variable, no bias).
#[derive(Debug)]
pub struct ComplexLinear {
    weight: Tensor,
}

impl ComplexLinear {
    /// Creates the layer's variable `weight` under `p`, each component uniform
    /// in `+-1/sqrt(C_in)`.
    pub fn new(p: nn::Path<'_>, input: usize, output: usize) -> Self {
        let bound = 1.0 / (input.max(1) as f64).sqrt();
        let weight = p.var(
            "weight",
            &[2, output as i64, input as i64],
            nn::Init::Uniform {
                lo: -bound,
                up: bound,
            },
        );
        Self { weight }
    }

    /// Applies the layer to `[B, 2F, C_in]`, giving `[B, 2F, C_out]`
    /// ([`mfm_kernels::dense::complex_linear`]: three real products per call).
    pub fn forward(&self, g: &Tensor) -> Result<Tensor> {
        Ok(mfm_kernels::dense::complex_linear(g, &self.weight)?)
    }

    /// `divergence(forward(g))` computed on vertices:
    /// `divergence(g) Wr^T + rotated_divergence(g) Wi^T`, one real product
    /// `[B, V, 2 C_in] x [2 C_in, C_out]` instead of three `[B, F, C_in] x
    /// [C_in, C_out]` ones on faces (see [`MeshTensors::rotated_divergence`]).
    /// Returns `[B, V, C_out]`; equal to the face form up to round-off.
    pub fn forward_divergence(&self, g: &Tensor, mesh: &MeshTensors) -> Result<Tensor> {
        self.forward_divergence_mapped(g, mesh, None)
    }

    /// `forward_divergence(g, mesh) B^T` for a real channel map `B: [C,
    /// C_out]` (`None`: the identity), with `B` multiplied into the weight
    /// (`[C, 2 C_in]`, a product of weights) rather than applied to the
    /// `[B, V, C_out]` result. Returns `[B, V, C]`.
    pub fn forward_divergence_mapped(
        &self,
        g: &Tensor,
        mesh: &MeshTensors,
        map: Option<&Tensor>,
    ) -> Result<Tensor> {
        let pq = mesh.paired_divergence(g)?;
        self.map_paired(&pq, map)
    }

    /// The layer applied to paired divergences `pq = [div g, div i g]: [B,
    /// V, 2 C_in]` (what [`MeshTensors::paired_divergence`] returns, or its
    /// sum over face blocks), with the channel map folded in as in
    /// [`ComplexLinear::forward_divergence_mapped`]: `[B, V, C]`.
    pub fn map_paired(&self, pq: &Tensor, map: Option<&Tensor>) -> Result<Tensor> {
        let w = Tensor::cat(&[self.weight.get(0), self.weight.get(1)], 1);
        let w = match map {
            Some(b) => {
                let (bs, ws) = (b.size(), w.size());
                if bs.len() != 2 || bs[1] != ws[0] {
                    return Err(shape_error(
                        "channel map after a complex layer",
                        format!("[C, {}]", ws[0]),
                        b,
                    ));
                }
                b.matmul(&w)
            }
            None => w,
        };
        Ok(mfm_kernels::dense::linear(pq, &w, None)?)
    }
}
