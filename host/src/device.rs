//! Choosing a backend from a user's device string (`auto`, `cpu`, `vulkan` or `vulkan:N`) and trace
//! method (`sw`, `rayquery` or `rtpipe`).

use crate::backend::Backend;
use crate::cpu::CpuBackend;
use crate::error::{Error, Result};
use std::str::FromStr;

/// Which backend to run on.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum DeviceChoice {
    /// The best usable Vulkan device, else the CPU.
    Auto,
    /// The CPU executor.
    Cpu,
    /// A Vulkan device: the best usable one, or the one at this index.
    Vulkan(Option<usize>),
}

impl FromStr for DeviceChoice {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        let bad = |reason: &str| Error::DeviceChoice { requested: s.to_owned(), reason: reason.to_owned() };
        match s {
            "auto" => Ok(Self::Auto),
            "cpu" => Ok(Self::Cpu),
            "vulkan" => Ok(Self::Vulkan(None)),
            _ => match s.strip_prefix("vulkan:") {
                Some(n) => {
                    n.parse().map(|i| Self::Vulkan(Some(i))).map_err(|_| bad("expected vulkan:N with N a device index"))
                }
                None => Err(bad("expected auto, cpu, vulkan or vulkan:N")),
            },
        }
    }
}

/// How the trace stage finds hits.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum TraceMethod {
    /// Software traversal of the CWBVH by the kernels (CPU, and Vulkan compute on any device).
    Software,
    /// `VK_KHR_ray_query` against a BLAS/TLAS (Vulkan devices that expose it).
    RayQuery,
    /// A `VK_KHR_ray_tracing_pipeline` raygen shader against a BLAS/TLAS (devices with
    /// ray-tracing pipelines but no ray query, e.g. NVIDIA data-center GPUs).
    RtPipeline,
}

impl TraceMethod {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Software => "sw",
            Self::RayQuery => "rayquery",
            Self::RtPipeline => "rtpipe",
        }
    }
}

impl FromStr for TraceMethod {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        match s {
            "sw" => Ok(Self::Software),
            "rayquery" => Ok(Self::RayQuery),
            "rtpipe" => Ok(Self::RtPipeline),
            _ => Err(Error::InvalidParameter {
                name: "trace",
                reason: format!("{s:?}: expected sw, rayquery or rtpipe"),
            }),
        }
    }
}

/// Options for opening a backend.
#[derive(Clone, Debug, Default)]
pub struct BackendOptions {
    /// Enable the Vulkan validation layers (required to be installed) and record their messages;
    /// refused with an explicit CPU choice, which has none to enable.
    pub validation: bool,
    /// The trace method; `None` picks the best the backend has (ray query, else the ray-tracing
    /// pipeline, else software traversal).
    pub trace: Option<TraceMethod>,
    /// Benchmark mode of a Vulkan backend, in seconds (`ContextOptions::sustain_seconds`: each
    /// timed submission repeats its dispatch until it keeps the GPU busy about this long, so that
    /// the GPU holds its clocks); 0 (the default) runs every stage once; within 0..=1, checked
    /// for every choice of backend. The CPU backend ignores it otherwise: its stages run once,
    /// timed by the wall clock.
    pub sustain_seconds: f64,
    /// Invocations per workgroup of each of a Vulkan backend's 1-D stream stages, for occupancy
    /// tuning (`ContextOptions::workgroup_sizes`; `None`: the preferred sizes,
    /// [`crate::WorkgroupSizes::PREFERRED`]). The CPU backend ignores them.
    pub workgroup_sizes: Option<crate::WorkgroupSizes>,
}

impl BackendOptions {
    /// Checks what needs no device, as [`open_backend`] does first: `sustain_seconds` within
    /// 0..=1, and with an explicit CPU choice no validation and no trace method but software
    /// traversal (it has neither). A job may call it before any other work, so that a scene is
    /// neither loaded nor its error reported before options that could never run.
    pub fn check_for(&self, choice: DeviceChoice) -> Result<()> {
        crate::backend::check_sustain_seconds(self.sustain_seconds)?;
        if choice != DeviceChoice::Cpu {
            return Ok(());
        }
        if self.validation {
            return Err(Error::InvalidParameter {
                name: "validation",
                reason: "the CPU backend has no validation layers (they check Vulkan calls)".to_owned(),
            });
        }
        match self.trace {
            None | Some(TraceMethod::Software) => Ok(()),
            Some(other) => Err(Error::InvalidParameter {
                name: "trace",
                reason: format!("the CPU backend traces in software only, not with {}", other.name()),
            }),
        }
    }
}

/// Opens the backend `choice` names. `Auto` opens the best Vulkan device that has the trace
/// method and workgroup sizes asked for
#[cfg_attr(feature = "vulkan", doc = "([`best_vulkan_device_for`]),")]
#[cfg_attr(not(feature = "vulkan"), doc = "(`best_vulkan_device_for`, with the `vulkan` feature),")]
/// and falls back to the CPU when no Vulkan device can be opened, unless `options` ask for what
/// only Vulkan has (validation, a hardware trace method, workgroup sizes) or Vulkan refused one of
/// them as invalid: then, as for an explicit Vulkan choice that cannot be honoured, the error says
/// why Vulkan failed (a CPU run would silently drop what was asked). A trace method the backend
/// lacks is an error, and so are validation with an explicit CPU choice and a `sustain_seconds`
/// outside 0..=1 with any ([`BackendOptions::check_for`], first). [`open_backend_telling_fallback`]
/// also returns why `Auto` fell back.
pub fn open_backend(choice: DeviceChoice, options: &BackendOptions) -> Result<Box<dyn Backend>> {
    open_backend_telling_fallback(choice, options).map(|(backend, _)| backend)
}

/// Opens the backend `choice` names, as [`open_backend`] does, and returns with it the Vulkan
/// error that `Auto` fell back to the CPU from (`None` where it did not fall back), so that a
/// program can tell its user why a run meant for a GPU ran on the CPU: a missing driver looks the
/// same as a deliberate CPU run otherwise.
pub fn open_backend_telling_fallback(
    choice: DeviceChoice,
    options: &BackendOptions,
) -> Result<(Box<dyn Backend>, Option<Error>)> {
    options.check_for(choice)?;
    let cpu = |fallback| Ok((Box::new(CpuBackend::new()) as Box<dyn Backend>, fallback));
    let opened = |backend| (backend, None);
    let hardware_trace = options.trace.is_some_and(|method| method != TraceMethod::Software);
    let vulkan_only = options.validation || hardware_trace || options.workgroup_sizes.is_some();
    match choice {
        DeviceChoice::Cpu => cpu(None),
        DeviceChoice::Auto => match open_vulkan(None, options) {
            Ok(backend) => Ok(opened(backend)),
            Err(vulkan_error) if vulkan_only || matches!(vulkan_error, Error::InvalidParameter { .. }) => {
                Err(vulkan_error)
            }
            Err(vulkan_error) => cpu(Some(vulkan_error)),
        },
        DeviceChoice::Vulkan(index) => open_vulkan(index, options).map(opened),
    }
}

/// Drops `backend` and fails with [`Error::Validation`] if its validation layers reported any
/// warning or error, its teardown's included (objects still alive when the device is destroyed,
/// say), which arrive only as it drops. A backend without validation closes with `Ok`.
pub fn close_backend(backend: Box<dyn Backend>) -> Result<()> {
    let (log, name) = (backend.validation_log(), backend.name());
    drop(backend);
    match log.map(|log| log.messages().len()) {
        Some(count) if count > 0 => Err(Error::Validation { backend: name, count }),
        _ => Ok(()),
    }
}

#[cfg(feature = "vulkan")]
fn open_vulkan(index: Option<usize>, options: &BackendOptions) -> Result<Box<dyn Backend>> {
    use crate::vulkan::{enumerate_devices, ContextOptions, VulkanBackend};
    let index = match index {
        Some(i) => i,
        None => best_vulkan_device_for(&enumerate_devices()?, options)?,
    };
    let context = ContextOptions {
        validation: options.validation,
        sustain_seconds: options.sustain_seconds,
        workgroup_sizes: options.workgroup_sizes,
        software_bvh: crate::cpu::BvhQuality::default(),
    };
    Ok(Box::new(VulkanBackend::open(index, &context, options.trace)?))
}

#[cfg(not(feature = "vulkan"))]
fn open_vulkan(_index: Option<usize>, _options: &BackendOptions) -> Result<Box<dyn Backend>> {
    Err(Error::VulkanUnavailable { reason: "raywave was built without the `vulkan` feature".into() })
}

/// The index of the device to use by default: of the devices that run raywave's kernels
/// (`DeviceInfo::missing_for_kernels`: Vulkan 1.2 with `vulkanMemoryModel`, room for the shade
/// pass's storage buffers) — each runs every stage, tracing with ray query, else the ray-tracing
/// pipeline, else in software — a discrete GPU before an integrated one before anything else, ties broken by
/// enumeration order.
#[cfg(feature = "vulkan")]
pub fn best_vulkan_device(devices: &[crate::vulkan::DeviceInfo]) -> Result<usize> {
    best_of(devices).map(|device| device.index)
}

/// [`best_vulkan_device`] among the devices that have what `options` ask for: their trace method
/// (`None`: any) and workgroup sizes (each a size the device runs, `DeviceInfo::workgroup_sizes`);
/// or among all where none has it (the backend then refuses, saying what the device lacks):
/// `--device auto --trace rayquery` on a machine with an NVIDIA H100 (no ray query) and lavapipe
/// opens lavapipe, where it had opened the H100 and failed, as `--workgroup-sizes` of 1024 opens
/// lavapipe beside a GPU that runs up to 512.
#[cfg(feature = "vulkan")]
pub fn best_vulkan_device_for(devices: &[crate::vulkan::DeviceInfo], options: &BackendOptions) -> Result<usize> {
    // Among the devices that run the kernels too: else one that has the method but cannot run
    // the kernels hides another that can (and would say what it lacks for the method).
    let able: Vec<_> = devices
        .iter()
        .filter(|d| d.missing_for_kernels().is_empty())
        .filter(|d| options.trace.is_none_or(|method| d.missing_for(method).is_empty()))
        .filter(|d| options.workgroup_sizes.is_none_or(|sizes| sizes.check(&d.workgroup_sizes).is_ok()))
        .cloned()
        .collect();
    best_vulkan_device(if able.is_empty() { devices } else { &able })
}

/// The device `--device auto` opens when it opens a Vulkan device, described: the
/// [`best_vulkan_device`] of those [`crate::vulkan::enumerate_devices`] finds.
#[cfg(feature = "vulkan")]
pub fn best_vulkan_device_info() -> Result<crate::vulkan::DeviceInfo> {
    best_of(&crate::vulkan::enumerate_devices()?).cloned()
}

/// [`best_vulkan_device`]'s choice among `devices`.
#[cfg(feature = "vulkan")]
fn best_of(devices: &[crate::vulkan::DeviceInfo]) -> Result<&crate::vulkan::DeviceInfo> {
    let rank = |t: &str| match t {
        "DISCRETE_GPU" => 0,
        "INTEGRATED_GPU" => 1,
        "VIRTUAL_GPU" => 2,
        _ => 3,
    };
    devices
        .iter()
        .filter(|d| d.missing_for_kernels().is_empty())
        .min_by_key(|d| (rank(&d.device_type), d.index))
        .ok_or_else(|| {
            let lacks: Vec<String> =
                devices.iter().map(|d| format!("{} lacks {}", d.name, d.missing_for_kernels().join(", "))).collect();
            Error::VulkanUnavailable {
                reason: format!(
                    "none of the {} Vulkan devices runs raywave's kernels: {}",
                    devices.len(),
                    lacks.join("; ")
                ),
            }
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_device_strings() {
        assert_eq!("auto".parse::<DeviceChoice>().unwrap(), DeviceChoice::Auto);
        assert_eq!("cpu".parse::<DeviceChoice>().unwrap(), DeviceChoice::Cpu);
        assert_eq!("vulkan".parse::<DeviceChoice>().unwrap(), DeviceChoice::Vulkan(None));
        assert_eq!("vulkan:3".parse::<DeviceChoice>().unwrap(), DeviceChoice::Vulkan(Some(3)));
        for bad in ["gpu", "vulkan:", "vulkan:x", "vulkan:-1", ""] {
            assert!(matches!(bad.parse::<DeviceChoice>(), Err(Error::DeviceChoice { .. })), "{bad}");
        }
    }

    #[test]
    fn parses_trace_methods_and_rejects_hardware_methods_on_the_cpu() {
        assert_eq!("sw".parse::<TraceMethod>().unwrap(), TraceMethod::Software);
        assert_eq!("rayquery".parse::<TraceMethod>().unwrap(), TraceMethod::RayQuery);
        assert_eq!("rtpipe".parse::<TraceMethod>().unwrap(), TraceMethod::RtPipeline);
        assert!("rtx".parse::<TraceMethod>().is_err());
        let options = BackendOptions { trace: Some(TraceMethod::RayQuery), ..Default::default() };
        let result = open_backend(DeviceChoice::Cpu, &options);
        assert!(matches!(result, Err(Error::InvalidParameter { name: "trace", .. })));
    }

    /// What the CPU backend cannot honour or would silently take is refused whatever the choice:
    /// validation asked of an explicit CPU choice, a busy time outside 0..=1 (it had been checked
    /// only where a Vulkan device opened, so `auto` without one took a NaN).
    #[test]
    fn options_are_checked_for_the_cpu_too() {
        let validation = BackendOptions { validation: true, ..Default::default() };
        let result = open_backend(DeviceChoice::Cpu, &validation);
        assert!(matches!(result, Err(Error::InvalidParameter { name: "validation", .. })));
        for seconds in [-1.0, 1.5, f64::NAN] {
            let options = BackendOptions { sustain_seconds: seconds, ..Default::default() };
            for choice in [DeviceChoice::Cpu, DeviceChoice::Auto] {
                let result = open_backend(choice, &options);
                assert!(matches!(result, Err(Error::InvalidParameter { name: "sustain_seconds", .. })), "{seconds}");
            }
            let mut cpu = crate::cpu::CpuBackend::new();
            assert!(cpu.set_sustain_seconds(seconds).is_err(), "{seconds}");
        }
        let options = BackendOptions { sustain_seconds: 0.5, ..Default::default() };
        assert!(open_backend(DeviceChoice::Cpu, &options).is_ok());
    }
}
