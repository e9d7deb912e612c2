//! Files written by `torch.save` read here, and files written here read by
//! `torch.load(weights_only=True)`, through the project's Python
//! environment (skipped with a printed reason without it); and the round
//! trip of the writer and the reader.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

use mfm_geometry::test_support::python_oracle;
use mfm_torchfile::{Checkpoint, Dtype, TensorData, TorchFileError, Value, state_dict_archive};
use proptest::prelude::*;

fn run_python(python: &Path, script: &str, dir: &Path) -> String {
    let out = Command::new(python)
        .arg("-c")
        .arg(script)
        .arg(dir)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "python failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

const WRITE_LIGHTNING: &str = r#"
import sys, collections, json, torch
d = sys.argv[1]
g = torch.Generator().manual_seed(3)
w = torch.randn(4, 3, generator=g)
base = torch.arange(12, dtype=torch.float64)
sd = collections.OrderedDict()
sd["base_model.w"] = w
sd["base_model.wT"] = w.t()                 # a strided view
sd["base_model.slice"] = base[5:9]          # an offset into a shared storage
sd["base_model.whole"] = base
sd["base_model.ints"] = torch.tensor([-3, 2**40], dtype=torch.int64)
sd["base_model.mask"] = torch.tensor([True, False])
sd["base_model.half"] = torch.tensor([1.5, -0.25], dtype=torch.float16)
sd["base_model.scalar"] = torch.tensor(2.5)
sd._metadata = collections.OrderedDict({"": {"version": 1}})
ckpt = {
    "epoch": 3, "global_step": 160000, "pytorch-lightning_version": "2.5.1",
    "state_dict": sd,
    "loops": {"fit_loop": {"state_dict": {}, "epoch_progress": {"total": {"ready": 4}}}},
    "callbacks": {"ModelCheckpoint{'monitor': None}": {"best_model_score": None, "kth_value": torch.tensor(float("inf")), "dirpath": "x/y"}},
    "optimizer_states": [{"state": {0: {"step": torch.tensor(5.0), "exp_avg": torch.zeros(2)}},
                          "param_groups": [{"lr": 5e-4, "betas": (0.9, 0.999), "amsgrad": False, "foreach": None, "params": [0, 1]}]}],
    "lr_schedulers": [{"milestones": collections.Counter({5000: 1, 140000: 1}), "gamma": 0.2, "big": 2**70, "neg": -2**63}],
}
torch.save(ckpt, d + "/lightning.ckpt")
expect = {k: {"shape": list(v.shape), "values": v.double().flatten().tolist() if v.dtype != torch.bool else v.int().tolist()} for k, v in sd.items()}
json.dump(expect, open(d + "/expect.json", "w"))
import argparse
torch.save({"state_dict": sd, "hyper_parameters": {"config": argparse.Namespace(a=1)}}, d + "/object.ckpt")
"#;

#[test]
fn reads_a_lightning_checkpoint_written_by_torch_save() {
    let Some(python) = python_oracle() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    run_python(&python, WRITE_LIGHTNING, dir.path());
    let expect: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("expect.json")).unwrap())
            .unwrap();

    let mut ckpt = Checkpoint::open(dir.path().join("lightning.ckpt")).unwrap();
    let root = ckpt.root().clone();
    assert_eq!(root.get("global_step"), Some(&Value::Int(160000)));
    assert_eq!(
        root.get("pytorch-lightning_version"),
        Some(&Value::Str("2.5.1".into()))
    );
    let sched = match root.get("lr_schedulers") {
        Some(Value::List(l)) => l[0].clone(),
        other => panic!("lr_schedulers: {other:?}"),
    };
    assert_eq!(
        sched.get("milestones"),
        Some(&Value::Dict(vec![
            (Value::Int(5000), Value::Int(1)),
            (Value::Int(140000), Value::Int(1))
        ]))
    );
    assert_eq!(sched.get("neg"), Some(&Value::Int(i64::MIN)));
    let mut big = vec![0u8; 9];
    big[8] = 0x40; // 2^70 = 0x40 << 64
    assert_eq!(sched.get("big"), Some(&Value::BigInt(big)));

    let tensors = ckpt.state_dict("state_dict").unwrap();
    let names: Vec<&str> = tensors.iter().map(|(n, _)| n.as_str()).collect();
    let expected_names: Vec<&str> = expect
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    let mut sorted = names.clone();
    sorted.sort_unstable();
    let mut expected_sorted = expected_names.clone();
    expected_sorted.sort_unstable();
    assert_eq!(sorted, expected_sorted);
    assert_eq!(names[0], "base_model.w", "file order is kept");
    for (name, t) in &tensors {
        let e = &expect[name.as_str()];
        let shape: Vec<usize> = e["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(t.shape, shape, "{name}");
        let values: Vec<f64> = e["values"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let got: Vec<f64> = match t.dtype {
            Dtype::I64 => t
                .bytes
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes(c.try_into().unwrap()) as f64)
                .collect(),
            Dtype::Bool => t.bytes.iter().map(|&b| f64::from(b)).collect(),
            _ => t.to_f64().unwrap(),
        };
        assert_eq!(got, values, "{name}");
    }
    let dtype = |n: &str| tensors.iter().find(|(k, _)| k == n).unwrap().1.dtype;
    assert_eq!(dtype("base_model.whole"), Dtype::F64);
    assert_eq!(dtype("base_model.half"), Dtype::F16);
    assert_eq!(dtype("base_model.mask"), Dtype::Bool);
}

#[test]
fn refuses_a_checkpoint_holding_an_arbitrary_object_naming_the_entry() {
    let Some(python) = python_oracle() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    run_python(&python, WRITE_LIGHTNING, dir.path());
    let e = Checkpoint::open(dir.path().join("object.ckpt")).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, TorchFileError::Entry { .. }), "{msg}");
    assert!(msg.contains("hyper_parameters.config"), "{msg}");
    assert!(msg.contains("argparse.Namespace"), "{msg}");
    assert!(msg.contains("object.ckpt"), "{msg}");
}

#[test]
fn torch_load_reads_what_the_writer_writes() {
    let Some(python) = python_oracle() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let a = TensorData::from_f32(vec![2, 3], &[1.0, -2.0, 3.5, 0.0, 1e-30, -7.25]);
    let s = TensorData::from_f32(vec![], &[4.0]);
    let bytes = state_dict_archive(
        &[("base_model.a".into(), a), ("base_model.s".into(), s)],
        Some("state_dict"),
    )
    .unwrap();
    std::fs::write(dir.path().join("out.ckpt"), bytes).unwrap();
    let out = run_python(
        &python,
        r#"
import sys, torch
c = torch.load(sys.argv[1] + "/out.ckpt", weights_only=True)
sd = c["state_dict"]
print(list(sd.keys()), type(sd).__name__)
print(sd["base_model.a"].dtype, tuple(sd["base_model.a"].shape), sd["base_model.a"].flatten().tolist())
print(sd["base_model.s"].shape, sd["base_model.s"].item())
"#,
        dir.path(),
    );
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "['base_model.a', 'base_model.s'] OrderedDict");
    assert_eq!(
        lines[1],
        "torch.float32 (2, 3) [1.0, -2.0, 3.5, 0.0, 1.0000000031710769e-30, -7.25]"
    );
    assert_eq!(lines[2], "torch.Size([]) 4.0");
}

#[test]
fn a_damaged_or_foreign_file_is_an_archive_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let not_zip = dir.path().join("notes.ckpt");
    std::fs::write(&not_zip, b"hello").unwrap();
    let e = Checkpoint::open(&not_zip).unwrap_err().to_string();
    assert!(
        e.contains("notes.ckpt") && e.contains("not a torch.save zip"),
        "{e}"
    );

    let t = TensorData::from_f32(vec![3], &[1.0, 2.0, 3.0]);
    let mut bytes = state_dict_archive(&[("w".into(), t)], None).unwrap();
    // cut the storage record short: the file's central directory is at the
    // end, so rewrite the record's bytes in place instead of truncating.
    let needle = [0u8, 0, 0x80, 0x3f, 0, 0, 0, 0x40];
    let at = bytes.windows(8).position(|w| w == needle).unwrap();
    bytes[at + 2] ^= 0x01;
    let flipped = dir.path().join("flipped.ckpt");
    std::fs::write(&flipped, &bytes).unwrap();
    let e = Checkpoint::open(&flipped)
        .and_then(|mut c| c.state_dict(""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("flipped.ckpt"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn written_state_dicts_read_back_exactly(
        shapes in prop::collection::vec(prop::collection::vec(0usize..4, 0..4), 0..6),
        seed in any::<u32>(),
        wrap in any::<bool>(),
    ) {
        let tensors: Vec<(String, TensorData)> = shapes
            .iter()
            .enumerate()
            .map(|(i, shape)| {
                let n: usize = shape.iter().product();
                let values: Vec<f32> = (0..n).map(|j| (seed as f32) * 0.5 - (i * 31 + j) as f32).collect();
                (format!("layer.{i}.weight"), TensorData::from_f32(shape.clone(), &values))
            })
            .collect();
        let key = wrap.then_some("state_dict");
        let bytes = state_dict_archive(&tensors, key).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.ckpt");
        std::fs::write(&path, bytes).unwrap();
        let mut c = Checkpoint::open(&path).unwrap();
        prop_assert_eq!(c.state_dict(key.unwrap_or("")).unwrap(), tensors);
    }
}
