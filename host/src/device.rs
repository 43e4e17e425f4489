//! Choosing a backend from a user's device string: `auto`, `cpu`, `vulkan` or `vulkan:N`.

use crate::backend::Backend;
use crate::cpu::CpuBackend;
use crate::error::{Error, Result};
use std::str::FromStr;

/// Which backend to run on.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum DeviceChoice {
    /// The best Vulkan device that can run every stage, else the CPU.
    Auto,
    /// The CPU executor.
    Cpu,
    /// A Vulkan device: the best one that can run every stage, or the one at this index.
    Vulkan(Option<usize>),
}

impl FromStr for DeviceChoice {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        let bad = |reason: &str| Error::DeviceChoice {
            requested: s.to_owned(),
            reason: reason.to_owned(),
        };
        match s {
            "auto" => Ok(Self::Auto),
            "cpu" => Ok(Self::Cpu),
            "vulkan" => Ok(Self::Vulkan(None)),
            _ => match s.strip_prefix("vulkan:") {
                Some(n) => n
                    .parse()
                    .map(|i| Self::Vulkan(Some(i)))
                    .map_err(|_| bad("expected vulkan:N with N a device index")),
                None => Err(bad("expected auto, cpu, vulkan or vulkan:N")),
            },
        }
    }
}

/// Options for opening a backend.
#[derive(Clone, Debug, Default)]
pub struct BackendOptions {
    /// Enable the Vulkan validation layers (required to be installed) and record their messages.
    pub validation: bool,
}

/// Opens the backend `choice` names. `Auto` falls back to the CPU when no Vulkan device can run
/// every stage; an explicit Vulkan choice that cannot be honoured is an error.
pub fn open_backend(choice: DeviceChoice, options: &BackendOptions) -> Result<Box<dyn Backend>> {
    match choice {
        DeviceChoice::Cpu => Ok(Box::new(CpuBackend::new())),
        DeviceChoice::Auto => {
            Ok(open_vulkan(None, options).unwrap_or_else(|_| Box::new(CpuBackend::new())))
        }
        DeviceChoice::Vulkan(index) => open_vulkan(index, options),
    }
}

#[cfg(feature = "vulkan")]
fn open_vulkan(index: Option<usize>, options: &BackendOptions) -> Result<Box<dyn Backend>> {
    use crate::vulkan::{enumerate_devices, ContextOptions, VulkanBackend};
    let index = match index {
        Some(i) => i,
        None => best_vulkan_device(&enumerate_devices()?)?,
    };
    Ok(Box::new(VulkanBackend::open(
        index,
        &ContextOptions {
            validation: options.validation,
        },
    )?))
}

#[cfg(not(feature = "vulkan"))]
fn open_vulkan(_index: Option<usize>, _options: &BackendOptions) -> Result<Box<dyn Backend>> {
    Err(Error::VulkanUnavailable {
        reason: "raywave was built without the `vulkan` feature".into(),
    })
}

/// The index of the device to use by default: among those that can run every stage, a discrete
/// GPU before an integrated one before anything else, ties broken by enumeration order.
#[cfg(feature = "vulkan")]
pub fn best_vulkan_device(devices: &[crate::vulkan::DeviceInfo]) -> Result<usize> {
    let rank = |t: &str| match t {
        "DISCRETE_GPU" => 0,
        "INTEGRATED_GPU" => 1,
        "VIRTUAL_GPU" => 2,
        _ => 3,
    };
    devices
        .iter()
        .filter(|d| d.missing_for_ray_query().is_empty())
        .min_by_key(|d| (rank(&d.device_type), d.index))
        .map(|d| d.index)
        .ok_or_else(|| Error::VulkanUnavailable {
            reason: format!(
                "none of the {} Vulkan devices supports ray query with acceleration structures",
                devices.len()
            ),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_device_strings() {
        assert_eq!("auto".parse::<DeviceChoice>().unwrap(), DeviceChoice::Auto);
        assert_eq!("cpu".parse::<DeviceChoice>().unwrap(), DeviceChoice::Cpu);
        assert_eq!(
            "vulkan".parse::<DeviceChoice>().unwrap(),
            DeviceChoice::Vulkan(None)
        );
        assert_eq!(
            "vulkan:3".parse::<DeviceChoice>().unwrap(),
            DeviceChoice::Vulkan(Some(3))
        );
        for bad in ["gpu", "vulkan:", "vulkan:x", "vulkan:-1", ""] {
            assert!(
                matches!(bad.parse::<DeviceChoice>(), Err(Error::DeviceChoice { .. })),
                "{bad}"
            );
        }
    }
}
