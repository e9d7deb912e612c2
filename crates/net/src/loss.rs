//! Losses on mesh signals (DESIGN.md section 6).
//!
//! All are averages over batch items and channels, weighted so that they
//! approximate integrals over the surface divided by its area (and so do not
//! depend on the triangulation).

use tch::Tensor;

use crate::error::Result;
use crate::error::shape_error;
use crate::model::PoissonNetOutput;
use mfm_kernels::mesh::MeshTensors;

/// Mass-weighted mean squared error of vertex signals `a`, `b: [B, V, C]`:
/// `mean over (batch, channel) of sum_v m_v (a - b)^2 / sum_v m_v`.
pub fn mass_weighted_mse(mesh: &MeshTensors, a: &Tensor, b: &Tensor) -> Result<Tensor> {
    if a.size() != b.size() {
        return Err(shape_error(
            "mass-weighted MSE",
            format!("the shape of the first argument {:?}", a.size()),
            b,
        ));
    }
    let s = a.size();
    let per_item = mesh.mass_inner(&(a - b), &(a - b))?;
    let m_total = mesh.total_area();
    let channels = *s.last().unwrap_or(&1) as f64;
    Ok(per_item.mean(a.kind()) / (m_total * channels))
}

/// Area-weighted mean squared error of face-vector signals `a`, `b:
/// [B, 2F, C]`: `mean over (batch, channel) of sum_f A_f |a_f - b_f|^2 /
/// sum_f A_f`, `|.|` the norm of the 2D vector in rows `2f, 2f + 1`.
pub fn area_weighted_mse(mesh: &MeshTensors, a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let rows = 2 * mesh.num_faces() as i64;
    let s = a.size();
    if s.len() < 2 || s[s.len() - 2] != rows || a.size() != b.size() {
        return Err(shape_error(
            "area-weighted MSE",
            format!("[..., 2F={rows}, C], both arguments alike"),
            b,
        ));
    }
    let a2 = mesh.face_areas_interleaved();
    let total_area = f64::try_from(a2.sum(tch::Kind::Double))? / 2.0;
    let w = a2.to_kind(a.kind()).to_device(a.device()).unsqueeze(-1);
    let d = a - b;
    let per_item = (&d * &d * w).sum_dim_intlist([-2i64, -1].as_slice(), false, a.kind());
    let channels = *s.last().unwrap_or(&1) as f64;
    Ok(per_item.mean(a.kind()) / (total_area * channels))
}

/// The flow-matching loss of DESIGN.md section 6 for a target velocity
/// `delta: [B, V, C]`: mass-weighted MSE of the vertex output against
/// `delta`, plus (NJF head) the area-weighted MSE of the Jacobian output
/// against `G delta`, with equal weights.
pub fn flow_matching_loss(
    mesh: &MeshTensors,
    out: &PoissonNetOutput,
    delta: &Tensor,
) -> Result<Tensor> {
    let vertex = mass_weighted_mse(mesh, &out.vertex, delta)?;
    match &out.jacobian {
        Some(j) => {
            let gd = mesh.gradient(delta)?;
            Ok(vertex + area_weighted_mse(mesh, j, &gd)?)
        }
        None => Ok(vertex),
    }
}
