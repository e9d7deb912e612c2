//! The authors' parameter names (the reference PoissonNet of the official
//! Matérn-FM code) and the map between them and this crate's variables.
//!
//! The two networks compute the same function with the same parameters;
//! only the names and the complex weights' storage differ:
//!
//! | mfm variable | official parameter (under `base_model.`) |
//! |---|---|
//! | `proj_in.{weight,bias}` | `proj_in.{weight,bias}` |
//! | `cond.0.*`, `cond.1.*` | `extra_feat_mlp.0.*`, `extra_feat_mlp.2.*` |
//! | `blocks.k.vector.layers.i.weight` `[2, out, in]` | `blocks.k.grad_mlp.layers.i.lin_real.weight`, `...lin_imag.weight` `[out, in]` each |
//! | `blocks.k.vector.bias.i` | `blocks.k.grad_mlp.layers.i.mag_bias` |
//! | `blocks.k.vector.mod.0.*`, `mod.1.*` | `blocks.k.grad_mlp.modulator.modulator.0.*`, `.2.*` |
//! | `blocks.k.mlp1.0.*`, `mlp1.1.*` | `blocks.k.vert_mlp.mlp1.layers.0.*`, `.3.*` |
//! | `blocks.k.mlp2.0.*`, `mlp2.1.*` | `blocks.k.vert_mlp.mlp2.layers.0.*`, `.3.*` |
//! | `blocks.k.gamma1`, `gamma2` | `blocks.k.vert_mlp.ls1`, `ls2` |
//! | `head.*` (NJF) | `head.grad_mlp.*` (as a block's `grad_mlp`) |
//! | `head.linear.*` | `head.*` |
//!
//! Conventions shared by both (checked by the import parity test): the
//! first vertex MLP reads `[x, u, conditioning]`; the modulation's output is
//! `[phase, raw scale]`; the conditioning is `[x, y, z, t]` (the official
//! `extra_features: ['v_source', 't']`).

use std::collections::{BTreeSet, HashMap};

use tch::{Kind, Tensor};

use crate::config::HeadKind;
use crate::error::{NetError, Result};
use crate::model::PoissonNet;

/// The prefix of the network's parameters in the official Lightning
/// module's `state_dict`.
pub const OFFICIAL_PREFIX: &str = "base_model.";

/// Where one mfm variable lives in the official state dict.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum OfficialParam {
    /// One tensor of the same shape.
    Same(String),
    /// A complex layer's weight: the real and imaginary `[out, in]` parts
    /// (mfm stacks them as `[2, out, in]`).
    Complex {
        /// `...lin_real.weight`.
        real: String,
        /// `...lin_imag.weight`.
        imag: String,
    },
}

impl OfficialParam {
    /// The official names this variable is made of.
    pub fn names(&self) -> Vec<&str> {
        match self {
            OfficialParam::Same(n) => vec![n],
            OfficialParam::Complex { real, imag } => vec![real, imag],
        }
    }
}

/// The official name (without [`OFFICIAL_PREFIX`]) of every variable of
/// `net`, sorted by the mfm name.
///
/// # Errors
/// [`NetError::Config`] for a variable this map does not know (a network
/// this module was not written for).
pub fn official_params(net: &PoissonNet) -> Result<Vec<(String, OfficialParam)>> {
    let mut names: Vec<String> = net.var_store().variables().into_keys().collect();
    names.sort();
    let linear_head = net.config().head == HeadKind::Linear;
    names
        .into_iter()
        .map(|n| {
            let p = official_param(&n, linear_head).ok_or_else(|| {
                NetError::Config(format!(
                    "variable {n} has no counterpart in the official PoissonNet"
                ))
            })?;
            Ok((n, p))
        })
        .collect()
}

/// The official parameter of one mfm vector-MLP variable (`rest` after
/// `vector.` or `head.`), under `base` (`blocks.k.grad_mlp.`).
fn vector_param(base: &str, rest: &str) -> Option<OfficialParam> {
    let parts: Vec<&str> = rest.split('.').collect();
    Some(match parts.as_slice() {
        ["layers", i, "weight"] => OfficialParam::Complex {
            real: format!("{base}layers.{i}.lin_real.weight"),
            imag: format!("{base}layers.{i}.lin_imag.weight"),
        },
        ["bias", i] => OfficialParam::Same(format!("{base}layers.{i}.mag_bias")),
        ["mod", "0", w] => OfficialParam::Same(format!("{base}modulator.modulator.0.{w}")),
        ["mod", "1", w] => OfficialParam::Same(format!("{base}modulator.modulator.2.{w}")),
        _ => return None,
    })
}

fn official_param(name: &str, linear_head: bool) -> Option<OfficialParam> {
    let same = |s: String| Some(OfficialParam::Same(s));
    let parts: Vec<&str> = name.splitn(3, '.').collect();
    match parts.as_slice() {
        ["proj_in", w] => same(format!("proj_in.{w}")),
        ["cond", "0", w] => same(format!("extra_feat_mlp.0.{w}")),
        ["cond", "1", w] => same(format!("extra_feat_mlp.2.{w}")),
        ["head", "linear", w] if linear_head => same(format!("head.{w}")),
        ["head", a, rest] if !linear_head => vector_param("head.grad_mlp.", &format!("{a}.{rest}")),
        ["blocks", k, rest] => {
            let base = format!("blocks.{k}.");
            let (first, tail) = rest.split_once('.').unwrap_or((rest, ""));
            match (first, tail) {
                ("vector", t) => vector_param(&format!("{base}grad_mlp."), t),
                ("gamma1", "") => same(format!("{base}vert_mlp.ls1")),
                ("gamma2", "") => same(format!("{base}vert_mlp.ls2")),
                ("mlp1" | "mlp2", t) => {
                    let (layer, w) = t.split_once('.')?;
                    let official = match layer {
                        "0" => "0",
                        "1" => "3",
                        _ => return None,
                    };
                    same(format!("{base}vert_mlp.{first}.layers.{official}.{w}"))
                }
                _ => None,
            }
        }
        _ => None,
    }
}

/// A tensor of an official state dict: shape and `f32` values, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficialTensor {
    /// Shape.
    pub shape: Vec<usize>,
    /// Values.
    pub values: Vec<f32>,
}

/// Loads the official state dict `tensors` (names with `prefix`, e.g.
/// [`OFFICIAL_PREFIX`]) into `net`. `cond_columns[j]` is the official
/// conditioning column that mfm's column `j` (`x, y, z, t` order) reads
/// (the identity for `['v_source', 't']`).
///
/// Entries outside `prefix` are ignored (a Lightning module holds other
/// state); under it, every entry must be used exactly once.
///
/// # Errors
/// [`NetError::WeightsMismatch`] (with `source` as the file) naming the
/// first missing parameter, the unexpected ones, or a parameter whose shape
/// differs from what the network's configuration needs.
pub fn load_official(
    net: &mut PoissonNet,
    tensors: &HashMap<String, OfficialTensor>,
    prefix: &str,
    cond_columns: &[usize],
    source: &std::path::Path,
) -> Result<()> {
    let mismatch = |detail: String| NetError::WeightsMismatch {
        path: source.to_path_buf(),
        detail,
    };
    let params = official_params(net)?;
    let mut used = BTreeSet::new();
    let vars = net.var_store().variables();
    let mut values: Vec<(String, Tensor)> = Vec::with_capacity(params.len());
    for (name, p) in &params {
        let var = &vars[name];
        let want: Vec<usize> = var.size().iter().map(|&d| d as usize).collect();
        let fetch = |n: &str, shape: &[usize]| -> Result<Tensor> {
            let full = format!("{prefix}{n}");
            let t = tensors.get(&full).ok_or_else(|| {
                mismatch(format!(
                    "parameter {full} is missing (the network's configuration needs it as {name})"
                ))
            })?;
            if t.shape != shape {
                return Err(mismatch(format!(
                    "parameter {full} has shape {:?}, the configuration needs {shape:?}",
                    t.shape
                )));
            }
            let dims: Vec<i64> = shape.iter().map(|&d| d as i64).collect();
            Ok(Tensor::from_slice(&t.values).reshape(dims))
        };
        let value = match p {
            OfficialParam::Same(n) => {
                let t = fetch(n, &want)?;
                if name == "cond.0.weight" && cond_columns.len() == want[1] {
                    let idx = Tensor::from_slice(
                        &cond_columns.iter().map(|&c| c as i64).collect::<Vec<_>>(),
                    );
                    t.index_select(1, &idx)
                } else {
                    t
                }
            }
            OfficialParam::Complex { real, imag } => {
                let part = &want[1..];
                Tensor::stack(&[fetch(real, part)?, fetch(imag, part)?], 0)
            }
        };
        used.extend(p.names().into_iter().map(|n| format!("{prefix}{n}")));
        values.push((name.clone(), value));
    }
    let extra: Vec<&String> = tensors
        .keys()
        .filter(|k| k.starts_with(prefix) && !used.contains(*k))
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    if !extra.is_empty() {
        let shown: Vec<&str> = extra.iter().take(8).map(|s| s.as_str()).collect();
        return Err(mismatch(format!(
            "{} parameter(s) the configuration has no place for: {}{}",
            extra.len(),
            shown.join(", "),
            if extra.len() > shown.len() {
                ", ..."
            } else {
                ""
            }
        )));
    }
    let kind = net.kind();
    tch::no_grad(|| {
        for (name, value) in &values {
            let mut var = vars[name].shallow_clone();
            var.copy_(&value.to_kind(kind).to_device(var.device()));
        }
    });
    Ok(())
}

/// The network's weights under the official names (with `prefix`), in the
/// order of [`official_params`], as `f32`.
///
/// # Errors
/// As [`official_params`]; libtorch errors reading the values.
pub fn official_state_dict(
    net: &PoissonNet,
    prefix: &str,
) -> Result<Vec<(String, OfficialTensor)>> {
    let vars = net.var_store().variables();
    let mut out = Vec::new();
    let to_official = |t: &Tensor| -> Result<OfficialTensor> {
        let t = t
            .to_kind(Kind::Float)
            .to_device(tch::Device::Cpu)
            .contiguous();
        let shape = t.size().iter().map(|&d| d as usize).collect();
        Ok(OfficialTensor {
            shape,
            values: Vec::<f32>::try_from(&t.view([-1]))?,
        })
    };
    for (name, p) in official_params(net)? {
        let var = vars[&name].detach();
        match p {
            OfficialParam::Same(n) => out.push((format!("{prefix}{n}"), to_official(&var)?)),
            OfficialParam::Complex { real, imag } => {
                out.push((format!("{prefix}{real}"), to_official(&var.get(0))?));
                out.push((format!("{prefix}{imag}"), to_official(&var.get(1))?));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::config::PoissonNetConfig;

    #[test]
    fn every_variable_has_an_official_name_and_the_counts_match() {
        for head in [HeadKind::Njf, HeadKind::Linear] {
            let mut cfg = PoissonNetConfig::deformation(8, 2);
            cfg.head = head;
            let net = PoissonNet::new(&cfg, tch::Device::Cpu).unwrap();
            let sd = official_state_dict(&net, OFFICIAL_PREFIX).unwrap();
            let count: usize = sd.iter().map(|(_, t)| t.values.len()).sum();
            assert_eq!(count, net.num_parameters(), "{head:?}");
            let names: BTreeSet<&str> = sd.iter().map(|(n, _)| n.as_str()).collect();
            assert_eq!(names.len(), sd.len(), "official names are distinct");
            for must in [
                "base_model.proj_in.weight",
                "base_model.extra_feat_mlp.2.bias",
                "base_model.blocks.1.grad_mlp.layers.2.lin_imag.weight",
                "base_model.blocks.0.grad_mlp.layers.1.mag_bias",
                "base_model.blocks.0.grad_mlp.modulator.modulator.2.weight",
                "base_model.blocks.1.vert_mlp.mlp2.layers.3.weight",
                "base_model.blocks.1.vert_mlp.ls1",
            ] {
                assert!(names.contains(must), "{must} missing");
            }
            match head {
                HeadKind::Njf | HeadKind::NjfNoInputGradient => {
                    assert!(names.contains("base_model.head.grad_mlp.layers.0.lin_real.weight"))
                }
                HeadKind::Linear => assert!(names.contains("base_model.head.weight")),
            }
        }
    }

    #[test]
    fn export_then_load_gives_the_same_weights_and_mismatches_are_named() {
        let cfg = PoissonNetConfig::deformation(8, 2);
        tch::manual_seed(1);
        let a = PoissonNet::new(&cfg, tch::Device::Cpu).unwrap();
        tch::manual_seed(2);
        let mut b = PoissonNet::new(&cfg, tch::Device::Cpu).unwrap();
        let sd: HashMap<String, OfficialTensor> = official_state_dict(&a, OFFICIAL_PREFIX)
            .unwrap()
            .into_iter()
            .collect();
        let src = std::path::Path::new("x.ckpt");
        load_official(&mut b, &sd, OFFICIAL_PREFIX, &[0, 1, 2, 3], src).unwrap();
        let (va, vb) = (a.var_store().variables(), b.var_store().variables());
        for (n, t) in &va {
            assert!(t.equal(&vb[n]), "{n}");
        }

        let mut missing = sd.clone();
        missing.remove("base_model.blocks.1.vert_mlp.ls2");
        let e = load_official(&mut b, &missing, OFFICIAL_PREFIX, &[0, 1, 2, 3], src)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("base_model.blocks.1.vert_mlp.ls2")
                && e.contains("missing")
                && e.contains("x.ckpt"),
            "{e}"
        );

        let mut extra = sd.clone();
        extra.insert(
            "base_model.blocks.0.vert_mlp.norm_pde.weight".into(),
            OfficialTensor {
                shape: vec![8],
                values: vec![1.0; 8],
            },
        );
        let e = load_official(&mut b, &extra, OFFICIAL_PREFIX, &[0, 1, 2, 3], src)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("norm_pde.weight") && e.contains("no place"),
            "{e}"
        );

        let mut shaped = sd.clone();
        shaped.insert(
            "base_model.proj_in.bias".into(),
            OfficialTensor {
                shape: vec![9],
                values: vec![0.0; 9],
            },
        );
        let e = load_official(&mut b, &shaped, OFFICIAL_PREFIX, &[0, 1, 2, 3], src)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("base_model.proj_in.bias") && e.contains("[9]") && e.contains("[8]"),
            "{e}"
        );

        // a conditioning permutation moves the columns: official [t, x, y, z]
        let mut permuted = sd.clone();
        let w = &sd["base_model.extra_feat_mlp.0.weight"];
        let mut vals = Vec::new();
        for r in 0..8 {
            let row = &w.values[r * 4..r * 4 + 4];
            vals.extend_from_slice(&[row[3], row[0], row[1], row[2]]);
        }
        permuted.insert(
            "base_model.extra_feat_mlp.0.weight".into(),
            OfficialTensor {
                shape: vec![8, 4],
                values: vals,
            },
        );
        load_official(&mut b, &permuted, OFFICIAL_PREFIX, &[1, 2, 3, 0], src).unwrap();
        assert!(b.var_store().variables()["cond.0.weight"].equal(&va["cond.0.weight"]));
    }
}
