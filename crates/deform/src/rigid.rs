//! Rotations and rigid transforms in 3D: axis-angle vectors, unit
//! quaternions, the best rotation for a weighted cross-covariance, and the
//! mass-weighted Kabsch fit of a rigid transform to point correspondences.
//!
//! ## Conventions
//! - A 3x3 matrix [`Mat3`] is row-major: `m[r][c]` is row `r`, column `c`,
//!   and it acts on column vectors, `y = m x`.
//! - A quaternion [`Quat`] is `[w, x, y, z]` (scalar first), unit length for
//!   rotations; `q` and `-q` are the same rotation. Functions returning one
//!   pick `w >= 0`.
//! - An axis-angle vector `v = theta n` (`n` a unit axis, `theta` in radians)
//!   rotates counter-clockwise by `theta` about `n` (right-hand rule).
//! - [`best_rotation`] maximizes `<R, K>_F = sum_rc R_rc K_rc` over proper
//!   rotations (`det R = +1`), for `K = sum_k w_k b_k a_k^T` the weighted
//!   cross-covariance of source vectors `a_k` and target vectors `b_k`; the
//!   result minimizes `sum_k w_k |b_k - R a_k|^2` when the weights are
//!   non-negative. It is computed by Horn's quaternion method: the
//!   eigenvector of the largest eigenvalue of a symmetric 4x4 matrix built
//!   from `K` (cyclic Jacobi). That method handles reflections by itself: it
//!   only ever produces proper rotations, and gives the same optimum as the
//!   SVD recipe `R = U diag(1, 1, det(U V^T)) V^T` for `K = U S V^T` (the
//!   smallest singular vector flipped when `det < 0`), which the tests use as
//!   an independent oracle. Cost: a few hundred flops, no allocation.

/// A 3x3 matrix, row-major (`m[row][col]`).
pub type Mat3 = [[f64; 3]; 3];

/// A quaternion `[w, x, y, z]` (scalar first).
pub type Quat = [f64; 4];

/// The 3x3 identity.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `m v`.
#[inline]
pub fn mat_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// `a b`.
#[inline]
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c];
        }
    }
    out
}

/// `m^T`.
#[inline]
pub fn transpose(m: &Mat3) -> Mat3 {
    [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]
}

/// Determinant of `m`.
pub fn determinant(m: &Mat3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Hamilton product `a b` (apply `b` first, then `a`).
#[inline]
pub fn quat_mul(a: Quat, b: Quat) -> Quat {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Conjugate `[w, -x, -y, -z]` (the inverse rotation of a unit quaternion).
#[inline]
pub fn quat_conj(q: Quat) -> Quat {
    [q[0], -q[1], -q[2], -q[3]]
}

/// `q / |q|` with `w >= 0`; the identity for a zero (or non-finite) input.
pub fn quat_normalize(q: Quat) -> Quat {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if !(n.is_finite() && n > 0.0) {
        return [1.0, 0.0, 0.0, 0.0];
    }
    let s = if q[0] < 0.0 { -1.0 / n } else { 1.0 / n };
    [q[0] * s, q[1] * s, q[2] * s, q[3] * s]
}

/// Rotation matrix of a unit quaternion.
pub fn quat_to_matrix(q: Quat) -> Mat3 {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Unit quaternion (`w >= 0`) of a rotation matrix (Shepperd's method: the
/// largest of the four squared components is computed from the diagonal,
/// the other three from off-diagonal sums, so it is accurate at any angle).
pub fn matrix_to_quat(m: &Mat3) -> Quat {
    let tr = m[0][0] + m[1][1] + m[2][2];
    let cands = [tr, m[0][0], m[1][1], m[2][2]];
    let mut best = 0;
    for (i, c) in cands.iter().enumerate() {
        if *c > cands[best] {
            best = i;
        }
    }
    let q = match best {
        0 => {
            let w4 = 2.0 * (1.0 + tr).max(0.0).sqrt();
            [
                w4 / 4.0,
                (m[2][1] - m[1][2]) / w4,
                (m[0][2] - m[2][0]) / w4,
                (m[1][0] - m[0][1]) / w4,
            ]
        }
        1 => {
            let x4 = 2.0 * (1.0 + m[0][0] - m[1][1] - m[2][2]).max(0.0).sqrt();
            [
                (m[2][1] - m[1][2]) / x4,
                x4 / 4.0,
                (m[0][1] + m[1][0]) / x4,
                (m[0][2] + m[2][0]) / x4,
            ]
        }
        2 => {
            let y4 = 2.0 * (1.0 - m[0][0] + m[1][1] - m[2][2]).max(0.0).sqrt();
            [
                (m[0][2] - m[2][0]) / y4,
                (m[0][1] + m[1][0]) / y4,
                y4 / 4.0,
                (m[1][2] + m[2][1]) / y4,
            ]
        }
        _ => {
            let z4 = 2.0 * (1.0 - m[0][0] - m[1][1] + m[2][2]).max(0.0).sqrt();
            [
                (m[1][0] - m[0][1]) / z4,
                (m[0][2] + m[2][0]) / z4,
                (m[1][2] + m[2][1]) / z4,
                z4 / 4.0,
            ]
        }
    };
    quat_normalize(q)
}

/// Unit quaternion of an axis-angle vector (accurate for tiny angles).
pub fn axis_angle_to_quat(v: [f64; 3]) -> Quat {
    let theta = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let half = 0.5 * theta;
    // sin(theta/2) / theta, by its series below 1e-4 (error < 1e-18)
    let k = if theta < 1e-4 {
        0.5 - theta * theta / 48.0
    } else {
        half.sin() / theta
    };
    [half.cos(), k * v[0], k * v[1], k * v[2]]
}

/// Axis-angle vector of a unit quaternion, with the angle in `[0, pi]`.
pub fn quat_to_axis_angle(q: Quat) -> [f64; 3] {
    let q = quat_normalize(q);
    let s = (q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    // theta = 2 atan2(s, w); v = theta / s * (x, y, z), by its limit 2 / w for tiny s
    let k = if s < 1e-12 {
        2.0 / q[0]
    } else {
        2.0 * s.atan2(q[0]) / s
    };
    [k * q[1], k * q[2], k * q[3]]
}

/// Rotation matrix of an axis-angle vector (Rodrigues' formula).
pub fn axis_angle_to_matrix(v: [f64; 3]) -> Mat3 {
    quat_to_matrix(axis_angle_to_quat(v))
}

/// Axis-angle vector of a rotation matrix, with the angle in `[0, pi]`.
pub fn matrix_to_axis_angle(m: &Mat3) -> [f64; 3] {
    quat_to_axis_angle(matrix_to_quat(m))
}

/// Maximum number of cyclic Jacobi sweeps on the 4x4 matrix of
/// [`best_rotation_quat`]; convergence is quadratic, 4-6 sweeps are typical.
const MAX_JACOBI_SWEEPS: usize = 30;

/// The proper rotation maximizing `<R, K>_F`, as a unit quaternion
/// (`w >= 0`); see the [module docs](self). `K = 0` gives the identity.
///
/// When the optimum is not unique (e.g. all vectors on one line, so any
/// rotation about it is as good), one of the optimal rotations is returned.
pub fn best_rotation_quat(k: &Mat3) -> Quat {
    // Horn (1987): with S = K^T (S_xy = sum w a_x b_y), the quaternion of the
    // best rotation is the top eigenvector of this traceless symmetric matrix.
    let s = |r: usize, c: usize| k[c][r];
    let (sxx, sxy, sxz) = (s(0, 0), s(0, 1), s(0, 2));
    let (syx, syy, syz) = (s(1, 0), s(1, 1), s(1, 2));
    let (szx, szy, szz) = (s(2, 0), s(2, 1), s(2, 2));
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    quat_normalize(top_eigenvector4(n))
}

/// The proper rotation maximizing `<R, K>_F`, as a matrix; see
/// [`best_rotation_quat`].
pub fn best_rotation(k: &Mat3) -> Mat3 {
    quat_to_matrix(best_rotation_quat(k))
}

/// Eigenvector of the largest eigenvalue of a symmetric 4x4 matrix, by cyclic
/// Jacobi rotations. Deterministic; ties go to the lowest index.
#[allow(clippy::needless_range_loop)] // index loops mirror the (p, q) rotations
fn top_eigenvector4(mut a: [[f64; 4]; 4]) -> [f64; 4] {
    let total: f64 = a.iter().flatten().map(|x| x * x).sum();
    if !(total.is_finite() && total > 0.0) {
        return [1.0, 0.0, 0.0, 0.0];
    }
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    // stop when the off-diagonal part is below round-off of the whole matrix
    let threshold = total * (f64::EPSILON * f64::EPSILON);
    for _ in 0..MAX_JACOBI_SWEEPS {
        let mut off = 0.0;
        for p in 0..3 {
            for q in p + 1..4 {
                off += a[p][q] * a[p][q];
            }
        }
        if off <= threshold {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                let apq = a[p][q];
                if apq == 0.0 {
                    continue;
                }
                // rotation J (J_pp = J_qq = c, J_pq = s, J_qp = -s) zeroing a_pq
                let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                let t = if theta.abs() > 1e150 {
                    0.5 / theta
                } else {
                    theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
                };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let sn = t * c;
                for row in a.iter_mut() {
                    let (x, y) = (row[p], row[q]);
                    row[p] = c * x - sn * y;
                    row[q] = sn * x + c * y;
                }
                for col in 0..4 {
                    let (x, y) = (a[p][col], a[q][col]);
                    a[p][col] = c * x - sn * y;
                    a[q][col] = sn * x + c * y;
                }
                a[p][q] = 0.0;
                a[q][p] = 0.0;
                for row in v.iter_mut() {
                    let (x, y) = (row[p], row[q]);
                    row[p] = c * x - sn * y;
                    row[q] = sn * x + c * y;
                }
            }
        }
    }
    let mut best = 0;
    for i in 1..4 {
        if a[i][i] > a[best][best] {
            best = i;
        }
    }
    [v[0][best], v[1][best], v[2][best], v[3][best]]
}

/// A rigid motion `x -> R x + t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    /// The rotation `R` (proper: `det R = +1`).
    pub rotation: Mat3,
    /// The translation `t`, applied after the rotation.
    pub translation: [f64; 3],
}

impl Default for RigidTransform {
    fn default() -> Self {
        Self::identity()
    }
}

impl RigidTransform {
    /// The identity motion.
    pub fn identity() -> Self {
        Self {
            rotation: IDENTITY,
            translation: [0.0; 3],
        }
    }

    /// `R x + t`.
    #[inline]
    pub fn apply(&self, x: [f64; 3]) -> [f64; 3] {
        let r = mat_vec(&self.rotation, x);
        [
            r[0] + self.translation[0],
            r[1] + self.translation[1],
            r[2] + self.translation[2],
        ]
    }

    /// The inverse motion `x -> R^T (x - t)`.
    pub fn inverse(&self) -> Self {
        let rt = transpose(&self.rotation);
        let t = mat_vec(&rt, self.translation);
        Self {
            rotation: rt,
            translation: [-t[0], -t[1], -t[2]],
        }
    }

    /// The motion that applies `first`, then `self`: `x -> self(first(x))`.
    pub fn after(&self, first: &Self) -> Self {
        Self {
            rotation: mat_mul(&self.rotation, &first.rotation),
            translation: self.apply(first.translation),
        }
    }
}

/// Weighted centroid `sum w p / sum w` (the caller guarantees `sum w > 0`).
pub fn weighted_centroid(points: &[[f64; 3]], weights: &[f64]) -> [f64; 3] {
    let mut c = [0.0; 3];
    let mut total = 0.0;
    for (p, &w) in points.iter().zip(weights) {
        for k in 0..3 {
            c[k] += w * p[k];
        }
        total += w;
    }
    [c[0] / total, c[1] / total, c[2] / total]
}

/// The weighted least-squares rigid motion from `source` to `target`
/// (Kabsch): the `T = (R, t)` minimizing `sum_k w_k |target_k - T(source_k)|^2`
/// over proper rotations, or `None` when the lengths differ or the weights
/// do not have a positive, finite sum. Weights should be non-negative.
///
/// `t` maps the weighted centroid of `source` onto that of `target`; `R` is
/// [`best_rotation`] of the centered cross-covariance. With fewer than three
/// non-collinear points the rotation is not unique and one optimum is
/// returned. Cost: `O(n)`.
///
/// # Example
/// ```
/// use mfm_deform::rigid::{axis_angle_to_matrix, fit_rigid, RigidTransform};
/// let truth = RigidTransform { rotation: axis_angle_to_matrix([0.3, -1.0, 0.5]), translation: [1.0, 2.0, 3.0] };
/// let src = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]];
/// let dst: Vec<_> = src.iter().map(|&p| truth.apply(p)).collect();
/// let fit = fit_rigid(&src, &dst, &[1.0; 4]).unwrap();
/// for (p, q) in src.iter().zip(&dst) {
///     let r = fit.apply(*p);
///     assert!((0..3).all(|k| (r[k] - q[k]).abs() < 1e-12));
/// }
/// ```
pub fn fit_rigid(
    source: &[[f64; 3]],
    target: &[[f64; 3]],
    weights: &[f64],
) -> Option<RigidTransform> {
    if source.len() != target.len() || source.len() != weights.len() {
        return None;
    }
    let total: f64 = weights.iter().sum();
    if !(total.is_finite() && total > 0.0) {
        return None;
    }
    let cs = weighted_centroid(source, weights);
    let ct = weighted_centroid(target, weights);
    let mut k = [[0.0; 3]; 3];
    for ((a, b), &w) in source.iter().zip(target).zip(weights) {
        let a = [a[0] - cs[0], a[1] - cs[1], a[2] - cs[2]];
        let b = [b[0] - ct[0], b[1] - ct[1], b[2] - ct[2]];
        for r in 0..3 {
            for c in 0..3 {
                k[r][c] += w * b[r] * a[c];
            }
        }
    }
    let rotation = best_rotation(&k);
    let rc = mat_vec(&rotation, cs);
    Some(RigidTransform {
        rotation,
        translation: [ct[0] - rc[0], ct[1] - rc[1], ct[2] - rc[2]],
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::needless_range_loop)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_round_trips() {
        for v in [
            [0.0, 0.0, 0.0],
            [1e-9, -2e-9, 3e-9],
            [0.3, -1.2, 0.5],
            [0.0, 0.0, std::f64::consts::PI - 1e-9],
            [2.0, 0.0, 0.0],
        ] {
            let m = axis_angle_to_matrix(v);
            assert!((determinant(&m) - 1.0).abs() < 1e-14);
            let back = matrix_to_axis_angle(&m);
            for k in 0..3 {
                assert!(
                    (back[k] - v[k]).abs() < 1e-7 * (1.0 + v[k].abs()),
                    "{v:?} -> {back:?}"
                );
            }
            // the matrix rotates the axis onto itself and is orthogonal
            let mmt = mat_mul(&m, &transpose(&m));
            for r in 0..3 {
                for c in 0..3 {
                    let id = if r == c { 1.0 } else { 0.0 };
                    assert!((mmt[r][c] - id).abs() < 1e-14);
                }
            }
        }
        // a quarter turn about z takes x to y (right-hand rule)
        let m = axis_angle_to_matrix([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        let y = mat_vec(&m, [1.0, 0.0, 0.0]);
        assert!((y[0]).abs() < 1e-15 && (y[1] - 1.0).abs() < 1e-15);
    }

    #[test]
    fn quaternion_product_composes_rotations() {
        let a = [0.4, 0.1, -0.7];
        let b = [-1.1, 0.3, 0.2];
        let qa = axis_angle_to_quat(a);
        let qb = axis_angle_to_quat(b);
        let m1 = quat_to_matrix(quat_mul(qa, qb));
        let m2 = mat_mul(&axis_angle_to_matrix(a), &axis_angle_to_matrix(b));
        for r in 0..3 {
            for c in 0..3 {
                assert!((m1[r][c] - m2[r][c]).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn rigid_transform_algebra() {
        let t = RigidTransform {
            rotation: axis_angle_to_matrix([0.2, 0.9, -0.4]),
            translation: [1.0, -2.0, 0.5],
        };
        let x = [0.3, 0.7, -1.1];
        let back = t.inverse().apply(t.apply(x));
        let composed = t.inverse().after(&t).apply(x);
        for k in 0..3 {
            assert!((back[k] - x[k]).abs() < 1e-14);
            assert!((composed[k] - x[k]).abs() < 1e-14);
        }
    }

    #[test]
    fn zero_covariance_gives_identity() {
        assert_eq!(best_rotation(&[[0.0; 3]; 3]), IDENTITY);
    }
}
