//! `raywave report …`: accuracy measurements with stated repetitions, printed as a table or as
//! one JSON object per line.

pub mod sampling;
pub mod scenes;
pub mod shade;
pub mod spectrum;
