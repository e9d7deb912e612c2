//! Where a run computes: the `train.device` choice of a run configuration
//! and the libtorch device it resolves to in this process.

use crate::error::{FmError, Result};
use serde::{Deserialize, Serialize};

/// Where training runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeviceChoice {
    /// The first CUDA device when libtorch sees one, else the CPU.
    #[default]
    Auto,
    /// The CPU.
    Cpu,
    /// The first CUDA device (an error without one).
    Cuda,
}

impl DeviceChoice {
    /// The device this choice resolves to in this process.
    ///
    /// # Errors
    /// [`FmError::Config`] for `cuda` when libtorch sees no CUDA device.
    pub fn resolve(self) -> Result<tch::Device> {
        let cuda = tch::Cuda::is_available();
        match self {
            Self::Auto if cuda => Ok(tch::Device::Cuda(0)),
            Self::Auto | Self::Cpu => Ok(tch::Device::Cpu),
            Self::Cuda if cuda => Ok(tch::Device::Cuda(0)),
            Self::Cuda => Err(FmError::Config(
                "device \"cuda\" asked for, but libtorch sees no CUDA device".into(),
            )),
        }
    }
}

impl std::str::FromStr for DeviceChoice {
    type Err = FmError;

    /// `auto`, `cpu` or `cuda` (as in `train.device`).
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(Self::Auto),
            "cpu" => Ok(Self::Cpu),
            "cuda" => Ok(Self::Cuda),
            other => Err(FmError::Config(format!(
                "unknown device {other:?}; expected auto, cpu or cuda"
            ))),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn device_choices_parse_and_resolve() {
        for (text, choice) in [
            ("auto", DeviceChoice::Auto),
            (" CPU", DeviceChoice::Cpu),
            ("cuda", DeviceChoice::Cuda),
        ] {
            assert_eq!(text.parse::<DeviceChoice>().unwrap(), choice);
        }
        let e = "gpu".parse::<DeviceChoice>().unwrap_err().to_string();
        assert!(
            e.contains("\"gpu\"") && e.contains("auto, cpu or cuda"),
            "{e}"
        );
        assert_eq!(DeviceChoice::Cpu.resolve().unwrap(), tch::Device::Cpu);
        match DeviceChoice::Cuda.resolve() {
            Ok(d) => assert_eq!(d, tch::Device::Cuda(0)),
            Err(e) => assert!(e.to_string().contains("no CUDA device"), "{e}"),
        }
    }
}
