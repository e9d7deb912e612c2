//! Adam with exactly restorable state: the optimizer of [`crate::TrainingLoop`].

use std::collections::BTreeMap;
use std::path::Path;

use mfm_net::PoissonNet;
use tch::{Device, Kind, Tensor};

use crate::error::{Result, TrainError};

/// Adam (Kingma & Ba) over a network's variables, with state that can be
/// saved and restored exactly.
///
/// Update of step `k` (1-based) for a parameter `p` with gradient `g`:
/// `m <- b1 m + (1 - b1) g`, `v <- b2 v + (1 - b2) g^2`,
/// `p <- p - lr (m / (1 - b1^k)) / (sqrt(v / (1 - b2^k)) + eps)`,
/// computed in place without recording gradients. Variables are handled
/// in name order; a variable without a gradient is left alone.
#[derive(Debug)]
pub struct Adam {
    names: Vec<String>,
    params: Vec<Tensor>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    beta1: f64,
    beta2: f64,
    eps: f64,
    steps: u64,
}

impl Adam {
    /// Zero moments for every trainable variable of `net`.
    pub fn new(net: &PoissonNet, beta1: f64, beta2: f64, eps: f64) -> Self {
        let vars: BTreeMap<String, Tensor> = net.var_store().variables().into_iter().collect();
        let (mut names, mut params, mut m, mut v) = (vec![], vec![], vec![], vec![]);
        for (name, t) in vars {
            if !t.requires_grad() {
                continue;
            }
            m.push(t.zeros_like());
            v.push(t.zeros_like());
            names.push(name);
            params.push(t);
        }
        Self {
            names,
            params,
            m,
            v,
            beta1,
            beta2,
            eps,
            steps: 0,
        }
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Sets every parameter's gradient to zero (where one exists).
    pub fn zero_grad(&mut self) {
        for p in &mut self.params {
            p.zero_grad();
        }
    }

    /// The global gradient norm `sqrt(sum over parameters of |g|^2)`
    /// (accumulated in `f64`), after which every gradient is multiplied by
    /// `max_norm / (norm + 1e-6)` if the norm exceeds `max_norm > 0`.
    /// Returns the norm before clipping.
    ///
    /// # Errors
    /// libtorch errors.
    pub fn clip_grad_norm(&mut self, max_norm: f64) -> Result<f64> {
        let grads: Vec<Tensor> = self
            .params
            .iter()
            .map(|p| p.grad())
            .filter(|g| g.defined())
            .collect();
        if grads.is_empty() {
            return Ok(0.0);
        }
        let squares: Vec<Tensor> = grads
            .iter()
            .map(|g| g.to_kind(Kind::Double).square().sum(Kind::Double))
            .collect();
        let norm = Tensor::stack(&squares, 0)
            .sum(Kind::Double)
            .sqrt()
            .to_device(Device::Cpu)
            .double_value(&[]);
        if max_norm > 0.0 && norm > max_norm {
            let coef = max_norm / (norm + 1e-6);
            tch::no_grad(|| -> Result<()> {
                for mut g in grads {
                    let _ = g.f_mul_scalar_(coef)?;
                }
                Ok(())
            })?;
        }
        Ok(norm)
    }

    /// One update with learning rate `lr`.
    ///
    /// # Errors
    /// libtorch errors.
    pub fn step(&mut self, lr: f64) -> Result<()> {
        self.steps += 1;
        let k = self.steps as i32;
        let bias1 = 1.0 - self.beta1.powi(k);
        let bias2 = 1.0 - self.beta2.powi(k);
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        tch::no_grad(|| -> Result<()> {
            for ((p, m), v) in self.params.iter_mut().zip(&mut self.m).zip(&mut self.v) {
                let g = p.grad();
                if !g.defined() {
                    continue;
                }
                let _ = m.f_mul_scalar_(b1)?;
                let _ = m.f_add_(&(&g * (1.0 - b1)))?;
                let _ = v.f_mul_scalar_(b2)?;
                let _ = v.f_add_(&(&g * &g * (1.0 - b2)))?;
                let denom = (&*v / bias2).sqrt() + eps;
                let update = &*m / denom * (lr / bias1);
                let _ = p.f_sub_(&update)?;
            }
            Ok(())
        })
    }

    /// Writes the moments (`m.<name>`, `v.<name>`) as safetensors.
    ///
    /// # Errors
    /// libtorch errors naming the file.
    pub fn save(&self, path: &Path) -> Result<()> {
        let mut named: Vec<(String, Tensor)> = Vec::with_capacity(2 * self.names.len());
        for (i, name) in self.names.iter().enumerate() {
            named.push((format!("m.{name}"), self.m[i].to_device(Device::Cpu)));
            named.push((format!("v.{name}"), self.v[i].to_device(Device::Cpu)));
        }
        Tensor::write_safetensors(&named, path)?;
        Ok(())
    }

    /// Restores moments written by [`Adam::save`] and the step count.
    ///
    /// # Errors
    /// [`TrainError::Files`] (`Format`) naming the file when a moment is missing or has
    /// another shape; libtorch read errors.
    pub fn load(&mut self, path: &Path, steps: u64) -> Result<()> {
        let file: BTreeMap<String, Tensor> = Tensor::read_safetensors(path)?.into_iter().collect();
        if file.len() != 2 * self.names.len() {
            return Err(TrainError::format(
                path,
                format!(
                    "optimizer state has {} tensors, expected {} (two per network variable)",
                    file.len(),
                    2 * self.names.len()
                ),
            ));
        }
        tch::no_grad(|| -> Result<()> {
            for (i, name) in self.names.iter().enumerate() {
                for (prefix, dst) in [("m", &mut self.m[i]), ("v", &mut self.v[i])] {
                    let key = format!("{prefix}.{name}");
                    let src = file.get(&key).ok_or_else(|| {
                        TrainError::format(path, format!("optimizer state lacks {key}"))
                    })?;
                    if src.size() != dst.size() {
                        return Err(TrainError::format(
                            path,
                            format!(
                                "{key} has shape {:?}, the network variable {:?}",
                                src.size(),
                                dst.size()
                            ),
                        ));
                    }
                    dst.f_copy_(src)?;
                }
            }
            Ok(())
        })?;
        self.steps = steps;
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::seeding::INIT_LOCK;
    use mfm_net::{HeadKind, MeshTensors, loss};

    /// Independent oracle: libtorch's own Adam and tch's gradient clipping
    /// on a twin network, same inputs, several steps with clipping active.
    #[test]
    fn adam_and_clipping_match_libtorch() {
        use mfm_net::PoissonNetConfig;
        use tch::nn::OptimizerConfig;
        tch::set_num_threads(1);
        let mesh = mfm_geometry::procedural::icosphere(1);
        let mt = MeshTensors::new(&mesh).unwrap();
        let cfg = PoissonNetConfig {
            width: 4,
            blocks: 1,
            vector_layers: 2,
            in_channels: 1,
            out_channels: 1,
            cond_channels: 1,
            modulation: true,
            head: HeadKind::Njf,
            global_context: false,
        };
        let make = || {
            let _g = INIT_LOCK.lock().unwrap_or_else(|p| p.into_inner());
            tch::manual_seed(3);
            PoissonNet::new(&cfg, Device::Cpu).unwrap()
        };
        let (a, b) = (make(), make());
        let v = mesh.num_vertices();
        let wave = |f: f64| -> Tensor {
            let vals: Vec<f32> = (0..2 * v).map(|i| (f * i as f64).sin() as f32).collect();
            Tensor::from_slice(&vals).reshape([2, v as i64, 1])
        };
        let (x, cond, delta) = (wave(0.37), wave(0.011), wave(1.3) * 3.0);
        let mut mine = Adam::new(&a, 0.9, 0.999, 1e-8);
        let mut theirs = tch::nn::Adam::default().build(b.var_store(), 1e-2).unwrap();
        let mut clipped = 0;
        for _ in 0..6 {
            let la =
                loss::flow_matching_loss(&mt, &a.forward(&mt, &x, Some(&cond)).unwrap(), &delta)
                    .unwrap();
            mine.zero_grad();
            la.backward();
            let norm = mine.clip_grad_norm(0.5).unwrap();
            clipped += usize::from(norm > 0.5);
            mine.step(1e-2).unwrap();

            let lb =
                loss::flow_matching_loss(&mt, &b.forward(&mt, &x, Some(&cond)).unwrap(), &delta)
                    .unwrap();
            theirs.zero_grad();
            lb.backward();
            theirs.clip_grad_norm(0.5);
            theirs.step();
        }
        assert!(clipped >= 3, "clipping was active in only {clipped} steps");
        assert_eq!(mine.steps(), 6);
        let (va, vb) = (a.var_store().variables(), b.var_store().variables());
        let mut worst = 0.0f64;
        for (name, ta) in &va {
            let d = (ta - &vb[name]).abs().max().double_value(&[]);
            worst = worst.max(d);
        }
        assert!(worst < 1e-5, "largest difference {worst}");
        // and the parameters did move
        let moved = va.iter().any(|(name, t)| {
            let fresh = make();
            (t - &fresh.var_store().variables()[name])
                .abs()
                .max()
                .double_value(&[])
                > 1e-3
        });
        assert!(moved);
    }
}
