//! The modulated complex MLP on face features (a block's step 3 and the NJF head).

use tch::Tensor;
use tch::nn;

use crate::error::{NetError, Result};
use mfm_kernels::mesh::MeshTensors;
use mfm_kernels::profile::section;

use super::{ComplexLinear, dense, gelu, linear};

/// Modulated complex MLP on face features (docs/network.md, "Blocks", step 3).
#[derive(Debug)]
pub struct VectorMlp {
    modulation: Option<(nn::Linear, nn::Linear)>,
    layers: Vec<ComplexLinear>,
    biases: Vec<Tensor>,
}

impl VectorMlp {
    /// Creates the modulation MLP (`mod.0: Linear(W, W)`, `mod.1:
    /// Linear(W, 2W)`), `nl` complex layers `layers.i` (the last one to
    /// `output` channels) and the nonlinearity biases `bias.i` (zeros).
    pub fn new(
        p: nn::Path<'_>,
        width: usize,
        layers: usize,
        output: usize,
        modulation: bool,
    ) -> Self {
        let modulation = modulation.then(|| {
            (
                linear(&p / "mod" / 0, width, width),
                linear(&p / "mod" / 1, width, 2 * width),
            )
        });
        let mut ls = Vec::with_capacity(layers);
        let mut biases = Vec::new();
        for i in 0..layers {
            let out = if i + 1 == layers { output } else { width };
            ls.push(ComplexLinear::new(&p / "layers" / i, width, out));
            if i + 1 < layers {
                biases.push((&p / "bias").zeros(&i.to_string(), &[width as i64]));
            }
        }
        Self {
            modulation,
            layers: ls,
            biases,
        }
    }

    /// `g: [B, 2F, W]`, `x: [B, V, W]` the vertex features whose face means
    /// drive the modulation. Returns `[B, 2F, C_out]`.
    pub fn forward(&self, g: &Tensor, x: &Tensor, mesh: &MeshTensors) -> Result<Tensor> {
        let (hidden, last) = self.hidden(g, x, mesh)?;
        let _s = section("vector.layers");
        last.forward(&hidden)
    }

    /// `mesh.divergence(self.forward(g, x, mesh))`, `[B, V, C_out]`, with the
    /// last complex layer applied after the divergence, on vertices
    /// ([`ComplexLinear::forward_divergence`]): what a block needs, at about
    /// a third of that layer's cost.
    pub fn forward_divergence(&self, g: &Tensor, x: &Tensor, mesh: &MeshTensors) -> Result<Tensor> {
        self.forward_divergence_mapped(g, x, mesh, None)
    }

    /// `forward_divergence(g, x, mesh) B^T` for a real channel map `B: [C,
    /// C_out]`, folded into the last complex layer's weight
    /// ([`ComplexLinear::forward_divergence_mapped`]). Returns `[B, V, C]`.
    pub fn forward_divergence_mapped(
        &self,
        g: &Tensor,
        x: &Tensor,
        mesh: &MeshTensors,
        map: Option<&Tensor>,
    ) -> Result<Tensor> {
        let (hidden, last) = self.hidden(g, x, mesh)?;
        let _s = section("vector.divergence");
        last.forward_divergence_mapped(&hidden, mesh, map)
    }

    /// [`VectorMlp::forward_divergence_mapped`] of the face gradients of
    /// `x` computed face block by face block ([`MeshTensors::face_blocks`],
    /// every block over all the vertices): the paired divergences of the
    /// blocks are summed before the last layer, so only one block's face
    /// activations exist at a time. The same function as the whole mesh's,
    /// up to the order of the sums.
    ///
    /// # Errors
    /// As [`VectorMlp::forward_divergence_mapped`]; [`NetError::Config`]
    /// for no blocks.
    pub fn forward_divergence_mapped_blocks(
        &self,
        x: &Tensor,
        blocks: &[MeshTensors],
        map: Option<&Tensor>,
    ) -> Result<Tensor> {
        let h = self.modulation_input(x)?;
        let mut sum: Option<(Tensor, &ComplexLinear)> = None;
        for block in blocks {
            let g = {
                let _s = section("block.gradient");
                block.gradient(x)?
            };
            let (hidden, last) = self.hidden_from(&g, h.as_ref(), block)?;
            let _s = section("vector.divergence");
            let part = block.paired_divergence(&hidden)?;
            sum = Some(match sum {
                Some((acc, last)) => (acc + part, last),
                None => (part, last),
            });
        }
        let Some((pq, last)) = sum else {
            return Err(NetError::Config("no face blocks to run on".into()));
        };
        let _s = section("vector.divergence");
        last.map_paired(&pq, map)
    }

    /// [`VectorMlp::forward`] of the face gradients of `x`, face block by
    /// face block: one `[B, 2F_b, C_out]` output per block.
    ///
    /// # Errors
    /// As [`VectorMlp::forward`].
    pub fn forward_blocks(&self, x: &Tensor, blocks: &[MeshTensors]) -> Result<Vec<Tensor>> {
        let h = self.modulation_input(x)?;
        blocks
            .iter()
            .map(|block| {
                let (hidden, last) = self.hidden_from(&block.gradient(x)?, h.as_ref(), block)?;
                let _s = section("vector.layers");
                last.forward(&hidden)
            })
            .collect()
    }

    /// The modulation and every layer but the last (with their
    /// nonlinearities), and the last layer.
    fn hidden(
        &self,
        g: &Tensor,
        x: &Tensor,
        mesh: &MeshTensors,
    ) -> Result<(Tensor, &ComplexLinear)> {
        let h = self.modulation_input(x)?;
        self.hidden_from(g, h.as_ref(), mesh)
    }

    /// The modulation's first layer on the vertices, `Linear1(x)` (it
    /// commutes with the face mean: an affine map, weights summing to 1),
    /// shared by every face block; `None` without modulation.
    fn modulation_input(&self, x: &Tensor) -> Result<Option<Tensor>> {
        match &self.modulation {
            Some((l1, _)) => {
                let _s = section("vector.modulation");
                Ok(Some(mfm_kernels::profile::timed(
                    "vector.modulation.l1",
                    || dense(l1, x),
                )?))
            }
            None => Ok(None),
        }
    }

    /// The hidden layers on the faces of `mesh` (the whole mesh or one face
    /// block) from `g` and the modulation input `h`
    /// ([`VectorMlp::modulation_input`]).
    fn hidden_from(
        &self,
        g: &Tensor,
        h: Option<&Tensor>,
        mesh: &MeshTensors,
    ) -> Result<(Tensor, &ComplexLinear)> {
        let Some((last, rest)) = self.layers.split_last() else {
            return Err(NetError::Config(
                "a vector MLP needs at least one layer".into(),
            ));
        };
        let mut g = match (&self.modulation, h) {
            (Some((_, l2)), Some(h)) => {
                let _s = section("vector.modulation");
                let s = gelu(&mesh.face_mean(h)?);
                let ps = mfm_kernels::profile::timed("vector.modulation.l2", || dense(l2, &s))?;
                let _t = section("vector.modulation.apply");
                mfm_kernels::fused::modulate(g, &ps)?
            }
            _ => g.shallow_clone(),
        };
        let _s = section("vector.layers");
        for (layer, b) in rest.iter().zip(&self.biases) {
            g = mfm_kernels::fused::magnitude_gelu(&layer.forward(&g)?, b)?;
        }
        Ok((g, last))
    }
}
