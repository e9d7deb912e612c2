//! Losses on mesh signals (docs/conventions.md, "Flow matching").
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
/// (2 sum_f A_f)`, `|.|` the norm of the 2D vector in rows `2f, 2f + 1`:
/// the mean over the two vector components, as the official code's
/// `MSE_loss` with the interleaved areas `A2` as weights (`sum A2 = 2 sum
/// A`). Of a gradient field `G f` it is half the mean squared gradient norm.
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
    // sum of the interleaved areas: twice the surface area
    let total_weight = f64::try_from(a2.sum(tch::Kind::Double))?;
    let w = a2.to_kind(a.kind()).to_device(a.device()).unsqueeze(-1);
    let d = a - b;
    let per_item = (&d * &d * w).sum_dim_intlist([-2i64, -1].as_slice(), false, a.kind());
    let channels = *s.last().unwrap_or(&1) as f64;
    Ok(per_item.mean(a.kind()) / (total_weight * channels))
}

/// The flow-matching loss (docs/conventions.md, "Flow matching") for a target velocity
/// `delta: [B, V, C]`: mass-weighted MSE of the vertex output against
/// `delta`, plus (NJF head) the area-weighted MSE of the Jacobian output
/// against `G delta`, with equal weights.
pub fn flow_matching_loss(
    mesh: &MeshTensors,
    out: &PoissonNetOutput,
    delta: &Tensor,
) -> Result<Tensor> {
    weighted_flow_matching_loss(mesh, out, delta, 1.0)
}

/// [`flow_matching_loss`] with the Jacobian term weighted by
/// `jacobian_weight` (the official `lambda_g / lambda_v`; 1 in the paper).
/// A weight of 0 skips the Jacobian term (and its gradient computation).
pub fn weighted_flow_matching_loss(
    mesh: &MeshTensors,
    out: &PoissonNetOutput,
    delta: &Tensor,
    jacobian_weight: f64,
) -> Result<Tensor> {
    let vertex = mass_weighted_mse(mesh, &out.vertex, delta)?;
    match &out.jacobian {
        Some(j) if jacobian_weight != 0.0 => {
            let gd = mesh.gradient(delta)?;
            // times 1.0 is exact: weight 1 is the official loss bit for bit
            Ok(vertex + area_weighted_mse(mesh, j, &gd)? * jacobian_weight)
        }
        _ => Ok(vertex),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;

    /// A linear function `f = a . p` on a sphere has gradient `a` projected
    /// on each face's plane; against a zero field the Jacobian MSE is half
    /// the area-weighted mean of its squared norm (the official per-component
    /// normalization), computed here face by face from the geometry alone.
    #[test]
    fn area_weighted_mse_averages_the_two_components() {
        let mesh = procedural::icosphere(2);
        let mt = MeshTensors::new(&mesh).unwrap();
        let a = [0.3f64, -1.2, 0.7];
        let f: Vec<f32> = mesh
            .positions()
            .iter()
            .map(|p| (a[0] * p[0] + a[1] * p[1] + a[2] * p[2]) as f32)
            .collect();
        let v = mesh.num_vertices() as i64;
        let x = Tensor::from_slice(&f).reshape([1, v, 1]);
        let g = mt.gradient(&x).unwrap();
        let zero = g.zeros_like();
        let got = f64::try_from(area_weighted_mse(&mt, &g, &zero).unwrap()).unwrap();
        let (mut num, mut den) = (0.0, 0.0);
        for tri in mesh.faces() {
            let [p, q, r] = tri.map(|i| mesh.positions()[i as usize]);
            let e1 = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
            let e2 = [r[0] - p[0], r[1] - p[1], r[2] - p[2]];
            let n = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            let nn = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let area = nn / 2.0;
            let an = (a[0] * n[0] + a[1] * n[1] + a[2] * n[2]) / nn;
            let tangential = a.iter().map(|c| c * c).sum::<f64>() - an * an;
            num += area * tangential;
            den += area;
        }
        let expected = num / (2.0 * den);
        assert!(
            (got - expected).abs() < 1e-5 * expected,
            "{got} vs {expected}"
        );
    }
}
