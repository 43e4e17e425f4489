//! The shade stage (seed 000): form factors of polygonal lights under linearly transformed
//! cosines (analytic U), and the stage that pairs them with stochastic shadows.

pub mod ltc;
pub mod polygon;
pub mod stage;
