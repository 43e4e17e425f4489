//! Workgroup sizes of a Vulkan backend's 1-D stream stages, set per stage for occupancy tuning.

use crate::error::{Error, Result};
use raywave_shared::bindings::WORKGROUP_SIZE;

/// Invocations per workgroup of each of a Vulkan backend's 1-D stream stages. How many
/// workgroups fit a GPU's cores at once (occupancy) depends on each kernel's registers and
/// private memory — the software trace's traversal stack above all — so the best size is a
/// property of kernel and GPU, found by measuring (`raywave bench trace --workgroup-sizes`,
/// criterion's `workgroup_size` group). Every field defaults to the compiled
/// [`WORKGROUP_SIZE`], 64; each must be a power of two the device runs
/// (`DeviceInfo::workgroup_sizes`), else the device refuses to open with
/// [`Error::InvalidParameter`] naming the field. Results do not depend on the sizes. The
/// bilateral denoise pass, whose workgroup-memory tile the size fixes, always runs 64, and the
/// ray-tracing pipeline has no workgroups.
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

impl Default for WorkgroupSizes {
    fn default() -> Self {
        Self::all(WORKGROUP_SIZE)
    }
}

impl WorkgroupSizes {
    /// Every stream stage in workgroups of `size`.
    pub fn all(size: u32) -> Self {
        Self { generate: size, trace: size, shade: size, denoise: size }
    }

    /// Each stage's size with the name of its field (`workgroup_sizes.trace`, …), as errors name
    /// them.
    pub fn named(&self) -> [(&'static str, u32); 4] {
        [
            ("workgroup_sizes.generate", self.generate),
            ("workgroup_sizes.trace", self.trace),
            ("workgroup_sizes.shade", self.shade),
            ("workgroup_sizes.denoise", self.denoise),
        ]
    }

    /// The smallest of the sizes.
    pub fn smallest(&self) -> u32 {
        self.named().iter().map(|&(_, size)| size).min().unwrap_or(WORKGROUP_SIZE)
    }

    /// Checks every size against `runnable`, the sizes a device runs (ascending): the first one
    /// it does not run is [`Error::InvalidParameter`] naming its field and what the device runs.
    pub fn check(&self, runnable: &[u32]) -> Result<()> {
        match self.named().into_iter().find(|(_, size)| !runnable.contains(size)) {
            None => Ok(()),
            Some((name, size)) => Err(Error::InvalidParameter {
                name,
                reason: match (runnable.first(), runnable.last()) {
                    (Some(least), Some(most)) => format!("{size}: this device runs the powers of two {least}..={most}"),
                    _ => format!("{size}: this device runs no 1-D workgroup of a stream stage"),
                },
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_size_the_device_does_not_run_is_named() {
        let runnable = [32, 64, 128, 256];
        assert_eq!(WorkgroupSizes::default(), WorkgroupSizes::all(64));
        assert!(WorkgroupSizes::default().check(&runnable).is_ok());
        assert!(WorkgroupSizes { trace: 256, shade: 32, ..Default::default() }.check(&runnable).is_ok());
        let refused = |sizes: WorkgroupSizes| match sizes.check(&runnable) {
            Err(Error::InvalidParameter { name, reason }) => (name, reason),
            other => panic!("{sizes:?}: {other:?}"),
        };
        let (name, reason) = refused(WorkgroupSizes { shade: 96, ..Default::default() });
        assert_eq!(
            (name, reason.as_str()),
            ("workgroup_sizes.shade", "96: this device runs the powers of two 32..=256")
        );
        assert_eq!(
            refused(WorkgroupSizes { generate: 0, denoise: 512, ..Default::default() }).0,
            "workgroup_sizes.generate"
        );
        assert_eq!(refused(WorkgroupSizes { denoise: 512, ..Default::default() }).0, "workgroup_sizes.denoise");
        assert_eq!(refused(WorkgroupSizes { trace: 16, ..Default::default() }).0, "workgroup_sizes.trace");
        assert_eq!(WorkgroupSizes { trace: 256, shade: 32, ..Default::default() }.smallest(), 32);
        assert!(WorkgroupSizes::default().check(&[]).is_err());
    }
}
