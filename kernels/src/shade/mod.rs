//! The shade stage's analytic pieces (seed 000): form factors of polygonal lights under linearly
//! transformed cosines.

pub mod ltc;
pub mod polygon;
