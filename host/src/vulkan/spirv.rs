//! The SPIR-V modules of `raywave-kernels`, embedded at build time (one per entry point).

use crate::error::{Error, Result};

include!(concat!(env!("OUT_DIR"), "/kernels_spv.rs"));

/// The SPIR-V bytes of entry point `entry`.
pub fn module(entry: &str) -> Result<&'static [u8]> {
    MODULES
        .iter()
        .find(|(name, _)| *name == entry)
        .map(|(_, bytes)| *bytes)
        .ok_or_else(|| Error::Vulkan { call: "embedded SPIR-V", result: format!("no module for entry point {entry}") })
}
