//! Workgroup sizes of a Vulkan backend's 1-D stream stages, set per stage for occupancy tuning.

use crate::error::{Error, Result};
use raywave_shared::bindings::WORKGROUP_SIZE;

/// A Vulkan backend's 1-D stream stages that each have their own workgroup size
/// ([`WorkgroupSizes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StreamStage {
    /// Generate, and the sampler and warp probes.
    Generate,
    /// The compute trace and occlusion (software and ray query).
    Trace,
    /// Shade.
    Shade,
    /// The denoisers' per-pixel passes and the copy probe.
    Denoise,
}

impl StreamStage {
    /// Every stage, in the order of [`WorkgroupSizes`]' fields.
    pub const ALL: [StreamStage; 4] = [Self::Generate, Self::Trace, Self::Shade, Self::Denoise];

    /// The stage's field as errors name it (`workgroup_sizes.trace`, …).
    pub fn field_name(self) -> &'static str {
        match self {
            Self::Generate => "workgroup_sizes.generate",
            Self::Trace => "workgroup_sizes.trace",
            Self::Shade => "workgroup_sizes.shade",
            Self::Denoise => "workgroup_sizes.denoise",
        }
    }
}

/// Invocations per workgroup of each of a Vulkan backend's 1-D stream stages. How many
/// workgroups fit a GPU's cores at once (occupancy) depends on each kernel's registers and
/// private memory — the software trace's traversal stack above all — so the best size is a
/// property of kernel and GPU, found by measuring (`raywave bench trace|shade|denoise
/// --workgroup-sizes`, criterion's `workgroup_size` group). A backend opened without sizes runs
/// [`WorkgroupSizes::PREFERRED`] (as far as the device runs them: [`WorkgroupSizes::preferred_on`]);
/// sizes given must each be a power of two the device runs (`DeviceInfo::workgroup_sizes`), else
/// the device refuses to open with [`Error::InvalidParameter`] naming the field. Results do not
/// depend on the sizes. The bilateral denoise pass, whose workgroup-memory tile the size fixes,
/// always runs the compiled [`WORKGROUP_SIZE`], and the ray-tracing pipeline has no workgroups.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WorkgroupSizes {
    /// Generate, and the sampler and warp probes.
    pub generate: u32,
    /// The compute trace and occlusion (software and ray query).
    pub trace: u32,
    /// Shade.
    pub shade: u32,
    /// The denoisers' per-pixel passes (ratio, noise estimate, its blur, composites, SVGF's
    /// variance and à-trous) and the copy probe.
    pub denoise: u32,
}

impl WorkgroupSizes {
    /// The sizes every kernel's SPIR-V is compiled with: [`WORKGROUP_SIZE`] (64) everywhere.
    pub const COMPILED: WorkgroupSizes = WorkgroupSizes::all(WORKGROUP_SIZE);

    /// The sizes a backend runs unless told otherwise: shade in workgroups of 256, the others
    /// of the compiled 64. Chosen when shade led in 256: on an NVIDIA H100 (README, "Workgroup
    /// size") 1.12× as fast as in 64 on the 512² Cornell box and 1.37× with the 20 lights of
    /// `builtin:cornell-light-grid` at 1024² (512 and 1024 slower), on lavapipe 1.22× and
    /// 1.05×; trace (32–256) and the denoise passes (32, 64, 256) were within 4 % of 64 on
    /// both. Since the shade stage's speed-ups the H100 shades within ±5 % in 32–256 (the grid
    /// 1 % ahead in 256, the 512² box 5 % behind), so 256 costs nothing there.
    pub const PREFERRED: WorkgroupSizes = WorkgroupSizes { shade: 256, ..Self::COMPILED };

    /// Every stream stage in workgroups of `size`.
    pub const fn all(size: u32) -> Self {
        Self { generate: size, trace: size, shade: size, denoise: size }
    }

    /// [`Self::PREFERRED`] on a device that runs `runnable` (ascending powers of two,
    /// `DeviceInfo::workgroup_sizes`): each stage's preferred size, else the largest smaller one
    /// the device runs (Vulkan guarantees only 128 invocations a workgroup), else its smallest.
    pub fn preferred_on(runnable: &[u32]) -> Self {
        let mut sizes = Self::PREFERRED;
        for stage in StreamStage::ALL {
            let preferred = sizes.of(stage);
            let fitting = runnable.iter().rev().find(|&&size| size <= preferred).or(runnable.first());
            sizes = sizes.with(stage, fitting.copied().unwrap_or(preferred));
        }
        sizes
    }

    /// The size of `stage`.
    pub fn of(&self, stage: StreamStage) -> u32 {
        match stage {
            StreamStage::Generate => self.generate,
            StreamStage::Trace => self.trace,
            StreamStage::Shade => self.shade,
            StreamStage::Denoise => self.denoise,
        }
    }

    /// These sizes with `stage`'s replaced by `size`.
    pub fn with(self, stage: StreamStage, size: u32) -> Self {
        match stage {
            StreamStage::Generate => Self { generate: size, ..self },
            StreamStage::Trace => Self { trace: size, ..self },
            StreamStage::Shade => Self { shade: size, ..self },
            StreamStage::Denoise => Self { denoise: size, ..self },
        }
    }

    /// The smallest of the sizes.
    pub fn smallest(&self) -> u32 {
        StreamStage::ALL.into_iter().map(|stage| self.of(stage)).min().unwrap_or(WORKGROUP_SIZE)
    }

    /// Checks every size against `runnable`, the sizes a device runs (ascending): the first one
    /// it does not run is [`Error::InvalidParameter`] naming its field and what the device runs.
    pub fn check(&self, runnable: &[u32]) -> Result<()> {
        let Some(stage) = StreamStage::ALL.into_iter().find(|&stage| !runnable.contains(&self.of(stage))) else {
            return Ok(());
        };
        let size = self.of(stage);
        Err(Error::InvalidParameter {
            name: stage.field_name(),
            reason: match (runnable.first(), runnable.last()) {
                (Some(least), Some(most)) => format!("{size}: this device runs the powers of two {least}..={most}"),
                _ => format!("{size}: this device runs no 1-D workgroup of a stream stage"),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_size_the_device_does_not_run_is_named() {
        let runnable = [32, 64, 128, 256];
        assert_eq!(WorkgroupSizes::COMPILED, WorkgroupSizes::all(64));
        assert!(WorkgroupSizes::COMPILED.check(&runnable).is_ok());
        assert!(WorkgroupSizes::PREFERRED.check(&runnable).is_ok());
        assert!(WorkgroupSizes { trace: 256, shade: 32, ..WorkgroupSizes::COMPILED }.check(&runnable).is_ok());
        let refused = |sizes: WorkgroupSizes| match sizes.check(&runnable) {
            Err(Error::InvalidParameter { name, reason }) => (name, reason),
            other => panic!("{sizes:?}: {other:?}"),
        };
        let (name, reason) = refused(WorkgroupSizes { shade: 96, ..WorkgroupSizes::COMPILED });
        assert_eq!(
            (name, reason.as_str()),
            ("workgroup_sizes.shade", "96: this device runs the powers of two 32..=256")
        );
        assert_eq!(
            refused(WorkgroupSizes { generate: 0, denoise: 512, ..WorkgroupSizes::COMPILED }).0,
            "workgroup_sizes.generate"
        );
        assert_eq!(refused(WorkgroupSizes { denoise: 512, ..WorkgroupSizes::COMPILED }).0, "workgroup_sizes.denoise");
        assert_eq!(refused(WorkgroupSizes { trace: 16, ..WorkgroupSizes::COMPILED }).0, "workgroup_sizes.trace");
        assert_eq!(WorkgroupSizes { trace: 256, shade: 32, ..WorkgroupSizes::COMPILED }.smallest(), 32);
        assert!(WorkgroupSizes::COMPILED.check(&[]).is_err());
    }

    #[test]
    fn the_preferred_sizes_shrink_to_what_the_device_runs() {
        let lavapipe: Vec<u32> = (5..=10).map(|k| 1 << k).collect();
        assert_eq!(WorkgroupSizes::preferred_on(&lavapipe), WorkgroupSizes::PREFERRED);
        assert_eq!(WorkgroupSizes::PREFERRED.of(StreamStage::Shade), 256);
        // Vulkan's minimum: 128 invocations a workgroup.
        let least = WorkgroupSizes::preferred_on(&[32, 64, 128]);
        assert_eq!(least, WorkgroupSizes { shade: 128, ..WorkgroupSizes::PREFERRED });
        assert!(least.check(&[32, 64, 128]).is_ok());
        // Only sizes above the preferred ones: the smallest of them.
        assert_eq!(WorkgroupSizes::preferred_on(&[512, 1024]), WorkgroupSizes::all(512));
        assert_eq!(WorkgroupSizes::preferred_on(&[]), WorkgroupSizes::PREFERRED);
    }

    #[test]
    fn each_stage_reads_and_replaces_its_own_field() {
        let sizes = WorkgroupSizes { generate: 1, trace: 2, shade: 4, denoise: 8 };
        for (k, stage) in StreamStage::ALL.into_iter().enumerate() {
            assert_eq!(sizes.of(stage), 1 << k);
            let replaced = sizes.with(stage, 1024);
            for other in StreamStage::ALL {
                assert_eq!(replaced.of(other), if other == stage { 1024 } else { sizes.of(other) }, "{stage:?}");
            }
            assert!(stage.field_name().ends_with(&format!("{stage:?}").to_lowercase()));
        }
    }
}
