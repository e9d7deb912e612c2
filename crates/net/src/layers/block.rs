//! One Poisson block: gradient, vector MLP, Poisson solve, vertex MLPs.

use tch::Tensor;
use tch::nn;

use crate::error::Result;
use crate::error::shape_error;
use mfm_kernels::mesh::MeshTensors;
use mfm_kernels::profile::section;

use super::{Mlp, VectorMlp, dense, gelu};

/// One Poisson block (docs/network.md, "Blocks"): gradient, vector MLP, Poisson
/// solve with the mean removed, then two LayerScale vertex MLPs; with a
/// global context, the first vertex MLP's output also gets a linear map of
/// its hidden features' mass-weighted mean over the surface.
#[derive(Debug)]
pub struct PoissonBlock {
    vector: VectorMlp,
    mlp1: Mlp,
    mlp2: Mlp,
    gamma1: Tensor,
    gamma2: Tensor,
    /// `Linear(W, W)` without bias reading the surface mean of MLP1's hidden
    /// features (`[W_out, W_in]`), when the block has a global context.
    global: Option<Tensor>,
}

impl PoissonBlock {
    /// Creates a block of width `width` under `p` (`vector`, `mlp1`, `mlp2`,
    /// `gamma1`, `gamma2`, and `global.weight` with `global`);
    /// `conditioned` adds the conditioning features to the first vertex
    /// MLP's input. The global map starts at zero, so a new block computes
    /// what it would without it.
    pub fn new(
        p: nn::Path<'_>,
        width: usize,
        layers: usize,
        modulation: bool,
        conditioned: bool,
        global: bool,
    ) -> Self {
        let h = if conditioned { 3 * width } else { 2 * width };
        let w = width as i64;
        Self {
            vector: VectorMlp::new(&p / "vector", width, layers, width, modulation),
            mlp1: Mlp::new(&p / "mlp1", h, width, width),
            mlp2: Mlp::new(&p / "mlp2", width, width, width),
            gamma1: p.ones("gamma1", &[w]),
            gamma2: p.ones("gamma2", &[w]),
            global: global.then(|| p.sub("global").zeros("weight", &[w, w])),
        }
    }

    /// `x: [B, V, W]`, `cond: [B, V, W]` (the conditioning MLP's output) when
    /// the block is conditioned. Returns the new `[B, V, W]`.
    pub fn forward(&self, x: &Tensor, cond: Option<&Tensor>, mesh: &MeshTensors) -> Result<Tensor> {
        self.forward_over(x, cond, mesh, None)
    }

    /// [`PoissonBlock::forward`] with the face computations run face block
    /// by face block ([`MeshTensors::face_blocks`] of `mesh`, given as
    /// `blocks`; see [`VectorMlp::forward_divergence_mapped_blocks`]).
    pub fn forward_blocks(
        &self,
        x: &Tensor,
        cond: Option<&Tensor>,
        mesh: &MeshTensors,
        blocks: &[MeshTensors],
    ) -> Result<Tensor> {
        self.forward_over(x, cond, mesh, Some(blocks))
    }

    fn forward_over(
        &self,
        x: &Tensor,
        cond: Option<&Tensor>,
        mesh: &MeshTensors,
        blocks: Option<&[MeshTensors]>,
    ) -> Result<Tensor> {
        // MLP1 reads h = [x, u, e]: with its first weight's columns split as
        // [A_x | B | A_e], `h W^T = x A_x^T + u B^T + e A_e^T`, and
        // `u B^T = remove_mean(solve(div B^T))` (module docs), so `B` folds
        // into the last complex layer and `u` itself is never formed
        let l1 = &self.mlp1.l1;
        let w = x.size().last().copied().unwrap_or(0);
        let expected = if cond.is_some() { 3 * w } else { 2 * w };
        if l1.ws.size() != [w, expected] {
            return Err(shape_error(
                "block input (conditioning given to an unconditioned block, or the reverse)",
                format!("a first vertex MLP weight [{w}, {expected}]"),
                &l1.ws,
            ));
        }
        let map = l1.ws.narrow(1, w, w);
        let div = match blocks {
            None => {
                let g = {
                    let _s = section("block.gradient");
                    mesh.gradient(x)?
                };
                self.vector
                    .forward_divergence_mapped(&g, x, mesh, Some(&map))?
            }
            Some(blocks) => self
                .vector
                .forward_divergence_mapped_blocks(x, blocks, Some(&map))?,
        };
        let ub = {
            let _s = section("block.poisson");
            mesh.remove_mass_mean(&mesh.solve(&div)?)?
        };
        let _s = section("block.vertex_mlps");
        let (input, a) = match cond {
            Some(e) => (
                Tensor::cat(&[x, e], -1),
                Tensor::cat(&[l1.ws.narrow(1, 0, w), l1.ws.narrow(1, 2 * w, w)], 1),
            ),
            None => (x.shallow_clone(), l1.ws.narrow(1, 0, w)),
        };
        let pre = mfm_kernels::dense::linear(&input, &a, l1.bs.as_ref())? + ub;
        let hidden = gelu(&pre);
        let out = dense(&self.mlp1.l2, &hidden)?;
        let out = match &self.global {
            // one vector per batch item, the same for every vertex
            Some(g) => out + mfm_kernels::dense::linear(&surface_mean(&hidden, mesh)?, g, None)?,
            None => out,
        };
        let x = x + &self.gamma1 * out;
        let x = &x + &self.gamma2 * self.mlp2.forward(&x)?;
        Ok(x)
    }
}

/// Mass-weighted mean over the whole surface (all components together) of
/// `h: [B, V, C]`, as `[B, 1, C]`.
fn surface_mean(h: &Tensor, mesh: &MeshTensors) -> Result<Tensor> {
    let v = mesh.num_vertices() as i64;
    let mass = mesh.mass().to_kind(h.kind()).to_device(h.device()) / mesh.total_area();
    let size = h.size();
    if size.len() != 3 || size[1] != v {
        return Err(shape_error(
            "global context features",
            format!("[B, {v}, C]"),
            h,
        ));
    }
    Ok(mass.view([1, 1, v]).matmul(h))
}
