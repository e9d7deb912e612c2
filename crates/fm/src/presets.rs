//! The named run configurations ([`RunConfig::preset`]): the authors'
//! recipes for a GPU and the same method sized for two cores.

use mfm_train::LrSchedule;

use crate::config::{ModelConfig, NoiseScale, PriorKind, RunConfig, TrainConfig};
use crate::error::{FmError, Result};
use crate::path::TimeSampling;

/// Names accepted by [`RunConfig::preset`].
pub const PRESETS: [&str; 4] = ["paper", "paper-elastic", "cpu", "cpu-deform"];

/// The noise amplitude `sigma` of the `cpu-deform` preset: with the data
/// prior the start already varies as the data does, and the noise only
/// blurs it (docs/BENCHMARKS.md, "The data prior").
pub const CPU_DEFORM_SIGMA: f64 = 1.0;

/// The weight average's decay of the `cpu` presets (`train.ema`).
pub const CPU_EMA: f64 = 0.999;

impl RunConfig {
    /// A named preset. The `paper` ones are the official recipe
    /// (kts707/Matern-FM's configs) on the paper's network, for a GPU; the
    /// `cpu` ones the same method sized for two cores. All train in the
    /// canonical frame with centred noise and targets, no augmentation
    /// (the official single-source recipe) and sample with 20 midpoint
    /// steps (step 0.05).
    /// - `paper`: the human-pose model (official `moyo_fixed_source`):
    ///   PoissonNet `W = 128, K = 5, nl = 3` conditioned on source xyz and
    ///   `t`, `matern:100` noise with `sigma = 5`, batch 32, 160k steps, lr
    ///   `5e-4` times 0.2 from step 40k, gradient clipping at 1.
    /// - `paper-elastic`: the elastic-deformation model (official
    ///   `stanford_bunny` and `fish`): as `paper` with `sigma = 3`, batch
    ///   40, lr `5e-4` times 0.2 at steps 5k and 140k.
    /// - `cpu`: scalar signals (the GMM experiment) on the pretrained demo
    ///   model's network, `W = 32, K = 3, nl = 3`, conditioned on `t`,
    ///   batch 4, 2000 steps, a checkpoint every 100 steps, `sigma = 3`, the
    ///   official loss, and the two changes that helped most in
    ///   docs/BENCHMARKS.md ("Training beyond the paper"): a warm-up over
    ///   the first 5% of the run to lr `4e-3` and a cosine decay to `1e-5`
    ///   at the run's last step (so `--steps` stretches it), and
    ///   logit-normal path times; sampling with the weight average
    ///   (`train.ema = 0.999`). A few minutes of training on two cores at
    ///   ~2.5k vertices (docs/BENCHMARKS.md, "The `cpu` preset").
    /// - `cpu-deform`: shapes (positions), `cpu` conditioned on the source
    ///   xyz and `t`, for 3000 steps: on the shared galloping horse this
    ///   recipe took samples from 2.9 to 2.0 times the data's floor from
    ///   the nearest real shape and flipped faces from 7.9% to 2.0%, where
    ///   the former shape recipe (`W = 16, K = 2, nl = 2`, 1000 steps, lr
    ///   `2e-3` then `5e-4`, uniform times, no average), 3000 steps of it,
    ///   the new schedule alone, the larger network alone or `sigma = 1`
    ///   moved it by 0.3 at most (docs/BENCHMARKS.md, "Own data"); about
    ///   12 minutes on two cores at 8.4k vertices. Sampling takes 5
    ///   midpoint steps (`sample.steps = 5`): its flows are nearly straight,
    ///   and 2, 5, 10 and 20 steps gave the same plausibility, coverage and
    ///   roughness within 0.05 on the horse and the crane, so 20 would only
    ///   cost 4x the time, minutes a sample at a million faces. Every
    ///   start is a draw of the Gaussian fit of the training shapes plus
    ///   Matérn noise of a third the `cpu` preset's amplitude
    ///   (`noise.prior = "gaussian"`, [`crate::prior`]; `sigma =`
    ///   [`CPU_DEFORM_SIGMA`]): on the horse plausibility went from 1.99
    ///   (noise alone) to 1.61 (the prior, `sigma = 3`) and 1.20 (`sigma =
    ///   1`), coverage from 1.81 to 1.26, flipped faces from 1.6% to 0.3%;
    ///   on the crane plausibility from 2.76 to 2.42 and coverage from 1.61
    ///   to 1.12 (`sigma = 0.3` is better on the horse, worse on the
    ///   crane; docs/BENCHMARKS.md, "The data prior").
    ///
    /// # Errors
    /// [`FmError::Config`] naming the known presets.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => {
                let mut c = Self::default();
                c.model.condition_on_xyz = true;
                c.noise.scale = NoiseScale::Factor(5.0);
                c.train.lr_schedule = LrSchedule::Decay {
                    factor: 0.2,
                    at: vec![40_000],
                };
                Ok(c)
            }
            "paper-elastic" => {
                let mut c = Self::preset("paper")?;
                c.noise.scale = NoiseScale::Factor(3.0);
                c.train.batch = 40;
                c.train.lr_schedule = LrSchedule::Decay {
                    factor: 0.2,
                    at: vec![5_000, 140_000],
                };
                Ok(c)
            }
            "cpu" => {
                let base = Self::default();
                Ok(Self {
                    model: ModelConfig {
                        preset: "small".into(),
                        width: Some(32),
                        blocks: Some(3),
                        vector_layers: Some(3),
                        ..ModelConfig::default()
                    },
                    train: TrainConfig {
                        steps: 2000,
                        batch: 4,
                        lr: 4e-3,
                        lr_schedule: LrSchedule::CosineOverRun {
                            warmup_fraction: 0.05,
                            floor: 1e-5,
                        },
                        checkpoint_every: 100,
                        log_every: 10,
                        ema: CPU_EMA,
                        time: TimeSampling::LogitNormal {
                            mean: 0.0,
                            std: 1.0,
                        },
                        ..base.train
                    },
                    ..base
                })
            }
            "cpu-deform" => {
                let mut c = Self::preset("cpu")?;
                c.model.condition_on_xyz = true;
                c.noise.prior = PriorKind::Gaussian;
                c.noise.scale = NoiseScale::Factor(CPU_DEFORM_SIGMA);
                c.train.steps = 3000;
                c.sample.steps = 5;
                Ok(c)
            }
            other => Err(FmError::Config(format!(
                "unknown run preset {other:?}; expected one of {}",
                PRESETS.join(", ")
            ))),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate_and_roundtrip() {
        for name in PRESETS {
            let c = RunConfig::preset(name).unwrap();
            c.validate().unwrap();
            let text = c.to_toml_string().unwrap();
            assert_eq!(RunConfig::from_toml_str(&text, "x").unwrap(), c, "{text}");
        }
        assert_eq!(
            RunConfig::preset("paper")
                .unwrap()
                .model
                .net_config(3)
                .unwrap()
                .num_parameters(),
            1_369_600
        );
        assert!(RunConfig::preset("gpu").is_err());
        // only the shape preset starts from the data prior
        for name in PRESETS {
            let prior = RunConfig::preset(name).unwrap().noise.prior;
            assert_eq!(prior == PriorKind::Gaussian, name == "cpu-deform", "{name}");
        }
        let deform = RunConfig::preset("cpu-deform").unwrap();
        assert_eq!(deform.noise.scale, NoiseScale::Factor(CPU_DEFORM_SIGMA));
        for (text, scale) in [
            ("0.3", NoiseScale::Factor(0.3)),
            ("unit", NoiseScale::Unit),
            ("data", NoiseScale::Data),
        ] {
            assert_eq!(text.parse::<NoiseScale>().unwrap(), scale);
        }
        for bad in ["0", "-1", "inf", "loud"] {
            assert!(bad.parse::<NoiseScale>().is_err(), "{bad}");
        }
    }
}
