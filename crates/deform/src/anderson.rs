//! Anderson acceleration of a fixed-point iteration `x <- G(x)` (type II, as
//! in Walker & Ni 2011; used for local/global solvers by Peng et al. 2018).
//!
//! With the residual `f = G(x) - x` and the last `m` differences
//! `dF_j = f_(j+1) - f_j`, `dG_j = G(x_(j+1)) - G(x_j)`, the accelerated
//! iterate is `G(x_k) - dG gamma` for the `gamma` minimizing
//! `|f_k - dF gamma|^2` (small normal equations, lightly regularized). The
//! caller safeguards it: it keeps the candidate only if it lowers the
//! energy, else it takes the plain step `G(x_k)` and calls
//! [`Anderson::reset`].
//!
//! Every reduction runs sequentially in a fixed order, so the result does not
//! depend on the number of threads.

use std::collections::VecDeque;

/// History of an Anderson-accelerated iteration over vectors of one length.
#[derive(Debug)]
pub(crate) struct Anderson {
    window: usize,
    prev_f: Option<Vec<f64>>,
    prev_g: Option<Vec<f64>>,
    d_f: VecDeque<Vec<f64>>,
    d_g: VecDeque<Vec<f64>>,
}

impl Anderson {
    /// An empty history keeping at most `window` differences.
    pub(crate) fn new(window: usize) -> Self {
        Self {
            window,
            prev_f: None,
            prev_g: None,
            d_f: VecDeque::with_capacity(window),
            d_g: VecDeque::with_capacity(window),
        }
    }

    /// Forgets the differences (keeps the last iterate, which the next
    /// [`Anderson::step`] differences against).
    pub(crate) fn reset(&mut self) {
        self.d_f.clear();
        self.d_g.clear();
    }

    /// Records the iterate `x` and its image `g = G(x)`, and returns the
    /// accelerated next iterate, or `None` when there is no history yet (or
    /// the least-squares problem is singular): then use `g`.
    pub(crate) fn step(&mut self, x: &[f64], g: &[f64]) -> Option<Vec<f64>> {
        if self.window == 0 {
            return None;
        }
        let f: Vec<f64> = g.iter().zip(x).map(|(a, b)| a - b).collect();
        if let (Some(pf), Some(pg)) = (self.prev_f.take(), self.prev_g.take()) {
            if self.d_f.len() == self.window {
                self.d_f.pop_front();
                self.d_g.pop_front();
            }
            self.d_f
                .push_back(f.iter().zip(&pf).map(|(a, b)| a - b).collect());
            self.d_g
                .push_back(g.iter().zip(&pg).map(|(a, b)| a - b).collect());
        }
        self.prev_f = Some(f.clone());
        self.prev_g = Some(g.to_vec());
        let m = self.d_f.len();
        if m == 0 {
            return None;
        }
        let mut gram = vec![0.0; m * m];
        let mut rhs = vec![0.0; m];
        for i in 0..m {
            for j in 0..=i {
                let v = dot(&self.d_f[i], &self.d_f[j]);
                gram[i * m + j] = v;
                gram[j * m + i] = v;
            }
            rhs[i] = dot(&self.d_f[i], &f);
        }
        let trace: f64 = (0..m).map(|i| gram[i * m + i]).sum();
        if !(trace.is_finite() && trace > 0.0) {
            return None;
        }
        for i in 0..m {
            gram[i * m + i] += 1e-10 * trace / m as f64;
        }
        let gamma = solve_dense(&mut gram, &mut rhs, m)?;
        let mut out = g.to_vec();
        for (dg, c) in self.d_g.iter().zip(&gamma) {
            for (o, d) in out.iter_mut().zip(dg) {
                *o -= c * d;
            }
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solves the `m x m` system `a x = b` (row-major) by Gaussian elimination
/// with partial pivoting; `None` if it is singular.
fn solve_dense(a: &mut [f64], b: &mut [f64], m: usize) -> Option<Vec<f64>> {
    for col in 0..m {
        let pivot =
            (col..m).max_by(|&r, &s| a[r * m + col].abs().total_cmp(&a[s * m + col].abs()))?;
        if a[pivot * m + col] == 0.0 {
            return None;
        }
        if pivot != col {
            for c in 0..m {
                a.swap(pivot * m + c, col * m + c);
            }
            b.swap(pivot, col);
        }
        for r in col + 1..m {
            let factor = a[r * m + col] / a[col * m + col];
            for c in col..m {
                a[r * m + c] -= factor * a[col * m + c];
            }
            b[r] -= factor * b[col];
        }
    }
    let mut x = vec![0.0; m];
    for r in (0..m).rev() {
        let s: f64 = (r + 1..m).map(|c| a[r * m + c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r * m + r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn dense_solve_is_exact_on_a_small_system() {
        let mut a = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let mut b = vec![5.0, 3.0, 4.0];
        let x = solve_dense(&mut a, &mut b, 3).unwrap();
        // solution (1, 2, 1) (needs the pivoting: a[0][0] = 0)
        for (xi, want) in x.iter().zip([1.0, 2.0, 1.0]) {
            assert!((xi - want).abs() < 1e-14);
        }
    }

    #[test]
    fn accelerates_a_linear_iteration_to_its_fixed_point() {
        // G(x) = A x + c with a slow contraction: plain iteration needs
        // hundreds of steps, Anderson(3) converges in a few (exact for a
        // linear map of dimension <= window after window + 1 steps)
        let a = [[0.95, 0.01, 0.0], [0.0, 0.9, 0.02], [0.01, 0.0, 0.97]];
        let c = [1.0, -2.0, 0.5];
        let g = |x: &[f64]| -> Vec<f64> {
            (0..3)
                .map(|r| (0..3).map(|k| a[r][k] * x[k]).sum::<f64>() + c[r])
                .collect()
        };
        let mut acc = Anderson::new(3);
        let mut x = vec![0.0; 3];
        for _ in 0..8 {
            let gx = g(&x);
            x = acc.step(&x, &gx).unwrap_or(gx);
        }
        let r: f64 = g(&x).iter().zip(&x).map(|(p, q)| (p - q).abs()).sum();
        assert!(r < 1e-9, "residual {r}");
    }
}
