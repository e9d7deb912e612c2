//! How well a trained run's flow brings a noised real shape back: each
//! shape of a position dataset is moved to time `t0` of the training path
//! (`x_t0 = (1 - t0) x0 + t0 x1`, `x1` the shape in the run's frame and
//! centred as in training, `x0` the run's noise of sample `i` for seed 0),
//! then the run's ODE is integrated from `t0` to 1 with `STEPS` midpoint
//! steps and the results are written in the data's units, `[N, V, 3]`.
//! At `t0 = 0` this is ordinary sampling; near 1 the flow only has to
//! denoise. Compare the output with the shapes it started from (nearest
//! real shape, the same shape or another) to see at which times the model
//! decides which shape to become (docs/BENCHMARKS.md, "What the samples
//! are").
//!
//! ```text
//! cargo run --release -p mfm-fm --example return_from_time -- \
//!     RUN MESH SHAPES.npy T0 STEPS OUT.npy
//! ```
//! `MESH` is the mesh the shapes are positions of (for an imported dataset,
//! `DATA/train/mesh.ply` with `DATA/train/signals.npy`).

use std::error::Error;
use std::path::Path;

use mfm_data::{InMemorySignals, SignalSource};
use mfm_fm::config::OdeMethod;
use mfm_fm::sample::{SampleOptions, Sampler};
use tch::{Device, Tensor};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [run, mesh, shapes, t0, steps, out] = args.as_slice() else {
        return Err("usage: return_from_time RUN MESH SHAPES.npy T0 STEPS OUT.npy".into());
    };
    let t0: f64 = t0.parse().map_err(|e| format!("T0 {t0:?}: {e}"))?;
    let steps: usize = steps.parse().map_err(|e| format!("STEPS {steps:?}: {e}"))?;
    let sampler = Sampler::load(run, Some(Device::Cpu))?;
    if !sampler.flow().positions || sampler.flow().displacements {
        return Err(format!(
            "{run}: the run does not generate positions (or generates displacements)"
        )
        .into());
    }
    let mesh = mfm_meshio::read_mesh(mesh)?;
    let target = sampler.prepare(&mesh)?;
    let shapes = InMemorySignals::read_npy(Path::new(shapes))?;
    let v = mesh.num_vertices();
    if shapes.num_vertices() != v || shapes.channels() != 3 {
        return Err(format!(
            "the shapes are [{}, {}, {}], the mesh has {v} vertices and positions have 3 channels",
            shapes.len(),
            shapes.num_vertices(),
            shapes.channels()
        )
        .into());
    }
    let n = shapes.len();
    // the shapes as the training run saw them: in its frame, centred
    let frame = sampler.flow().frame;
    let shift = Tensor::from_slice(&frame.shift.map(|x| x as f32)).reshape([1, 1, 3]);
    let p = Tensor::from_slice(shapes.data()).reshape([n as i64, v as i64, 3]);
    let mut x1 = p * frame.scale + shift;
    if sampler.flow().centered {
        x1 = target.mesh_tensors().remove_mass_mean(&x1)?;
    }
    let x0 = sampler.noise(&target, 0, n, 0)?;
    let xt = x0 * (1.0 - t0) + x1 * t0;
    let options = SampleOptions {
        steps,
        method: OdeMethod::Midpoint,
        ..SampleOptions::default()
    };
    let x = sampler.integrate_from(&target, &xt, t0, &options)?;
    let y = sampler.finish(&target, &x).contiguous().view([-1]);
    let values = Vec::<f32>::try_from(&y)?;
    mfm_files::npy::write(out, &values, &[n as u64, v as u64, 3])?;
    println!("{n} shapes from t = {t0} in {steps} steps: {out}");
    Ok(())
}
