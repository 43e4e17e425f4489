//! `raywave report …`: accuracy measurements with stated repetitions, printed as a table or as
//! one JSON object per line.

pub mod error_vs_time;
pub mod sampling;
pub mod scenes;
pub mod shade;
pub mod spectrum;

/// Checks a report's image side: 4 to 1024 pixels (smaller images have no statistics worth
/// reporting, larger ones only cost time).
pub fn check_resolution(resolution: u32) -> crate::Result<()> {
    if (4..=1024).contains(&resolution) {
        Ok(())
    } else {
        Err(crate::Error::InvalidParameter { name: "resolution", reason: "must be within 4..=1024".into() })
    }
}
