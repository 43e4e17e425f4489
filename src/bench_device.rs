//! How every `raywave bench` measures a Vulkan device: which device (the one `--device auto`
//! picks), the workgroup sizes of the stage the bench sweeps, benchmark mode, and how long the
//! warm-up waits for the times to settle — all checked before anything is measured, so a bad
//! option fails before the first line is printed.

use crate::bench::{check_settle_seconds, GPU_SETTLE_SECONDS};
use crate::{Result, StreamStage};

/// A bench's options for the Vulkan device.
#[derive(Clone, Debug, Default)]
pub struct VulkanBenchOptions {
    /// Workgroup sizes of the stage the bench sweeps ([`crate::WorkgroupSizes`], for occupancy
    /// tuning), each a power of two the device runs, else a typed error before anything is
    /// measured; empty: the stage's preferred size only ([`crate::WorkgroupSizes::preferred_on`]).
    pub workgroup_sizes: Vec<u32>,
    /// How long the Vulkan times must have stopped falling before they are measured, in seconds
    /// (finite, `0..=30`); `None`: 5 s, long enough for a GPU to raise its clocks. Shorter only
    /// for a quick check of the output.
    pub settle_seconds: Option<f64>,
}

impl VulkanBenchOptions {
    /// The device a bench measures — if `enabled` and there is one — with these options checked
    /// against it, and its `image` (width, height; one stream element a pixel) in each workgroup
    /// size measured; `stage` is the stage the bench sweeps, the others run their preferred sizes.
    /// The settling time, and that no workgroup size is listed twice, are checked with or without
    /// a device (or the `vulkan` feature); workgroup sizes or a settling time without a device to
    /// use them are an error, not ignored.
    #[cfg_attr(not(feature = "vulkan"), allow(unused_variables))]
    pub(crate) fn device(&self, enabled: bool, stage: StreamStage, image: [u32; 2]) -> Result<Option<BenchDevice>> {
        let settle_seconds = self.settle_seconds.map(check_settle_seconds).transpose()?.unwrap_or(GPU_SETTLE_SECONDS);
        let sizes = &self.workgroup_sizes;
        if let Some(repeated) = sizes.iter().enumerate().find_map(|(i, s)| sizes[..i].contains(s).then_some(s)) {
            // Lines are keyed by the size: a second run of it printed a second line of that key.
            let reason = format!("{repeated} is listed twice");
            return Err(crate::Error::InvalidParameter { name: "workgroup-sizes", reason });
        }
        // Without a device the bench measures the CPU alone, and says why unless it was asked to.
        let no_device = |why: &str| -> Result<Option<BenchDevice>> {
            let device_only = [
                ("workgroup-sizes", !self.workgroup_sizes.is_empty()),
                ("settle-seconds", self.settle_seconds.is_some()),
            ];
            if let Some((name, _)) = device_only.into_iter().find(|&(_, given)| given) {
                return Err(crate::Error::InvalidParameter {
                    name,
                    reason: format!("no Vulkan device is measured ({why}), so nothing uses it"),
                });
            }
            if enabled {
                crate::output_line::warn(&format!("note: no Vulkan device is measured: {why}"));
            }
            Ok(None)
        };
        if !enabled {
            return no_device("--no-vulkan");
        }
        #[cfg(feature = "vulkan")]
        {
            let info = match crate::device::best_vulkan_device_info() {
                Ok(info) => info,
                Err(err) => return no_device(&err.to_string()),
            };
            let preferred = crate::WorkgroupSizes::preferred_on(&info.workgroup_sizes);
            for &size in &self.workgroup_sizes {
                preferred.with(stage, size).check(&info.workgroup_sizes).map_err(|err| match err {
                    // The option, not the field of `WorkgroupSizes` it sets.
                    crate::Error::InvalidParameter { reason, .. } => {
                        crate::Error::InvalidParameter { name: "workgroup-sizes", reason }
                    }
                    other => other,
                })?;
            }
            let sizes = match self.workgroup_sizes.as_slice() {
                [] => vec![preferred.of(stage)],
                sizes => sizes.to_vec(),
            };
            for &size in &sizes {
                info.check_image_size(image[0], image[1], &preferred.with(stage, size))?;
            }
            Ok(Some(BenchDevice { info, settle_seconds, sizes, preferred, stage }))
        }
        #[cfg(not(feature = "vulkan"))]
        no_device("raywave was built without the `vulkan` feature")
    }
}

/// The Vulkan device a bench measures, and how ([`VulkanBenchOptions::device`]).
#[cfg(feature = "vulkan")]
pub(crate) struct BenchDevice {
    /// The device.
    pub info: crate::vulkan::DeviceInfo,
    /// The warm-up's settling time, seconds.
    pub settle_seconds: f64,
    /// The swept stage's workgroup sizes, each checked against the device.
    pub sizes: Vec<u32>,
    /// The device's preferred sizes, which the stages not swept run.
    pub preferred: crate::WorkgroupSizes,
    stage: StreamStage,
}

/// Without the `vulkan` feature there is no device to measure.
#[cfg(not(feature = "vulkan"))]
pub(crate) enum BenchDevice {}

#[cfg(feature = "vulkan")]
impl BenchDevice {
    /// The device opened in benchmark mode (`crate::bench::SUSTAIN_SECONDS`) with the swept
    /// stage in workgroups of `size`, trace method `trace` (`None`: the best it has) and, for
    /// software traversal, a CWBVH of preset `software_bvh`.
    pub fn open(
        &self,
        size: u32,
        trace: Option<crate::TraceMethod>,
        software_bvh: crate::cpu::BvhQuality,
    ) -> Result<crate::vulkan::VulkanBackend> {
        let context = crate::vulkan::ContextOptions {
            sustain_seconds: crate::bench::SUSTAIN_SECONDS,
            workgroup_sizes: Some(self.preferred.with(self.stage, size)),
            software_bvh,
            ..Default::default()
        };
        crate::vulkan::VulkanBackend::open(self.info.index, &context, trace)
    }
}

/// A table row's note of the workgroup size it was measured in (empty where there is none).
pub(crate) fn workgroup_note(workgroup_size: Option<u32>) -> String {
    workgroup_size.map(|size| format!("  workgroup {size}")).unwrap_or_default()
}
