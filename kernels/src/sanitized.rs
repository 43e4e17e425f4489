//! DESIGN rule 5 at a stage's boundary: no NaN or Inf leaves a stage, and what a stage had to
//! replace is counted — flagged per invocation here, summed by the CPU executor and by an atomic
//! counter on Vulkan — so that tests can assert it stayed zero on sound input and a caller can
//! tell a clean frame from one whose inputs (or arithmetic) went non-finite.

/// A stage's result for one invocation, and whether non-finite values — read from its inputs or
/// computed — had to be replaced to produce it.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Sanitized<T> {
    /// The value the stage writes: always finite.
    pub value: T,
    /// Whether a non-finite value was replaced on the way (the stage counts the invocation).
    pub replaced: bool,
}

impl<T> Sanitized<T> {
    /// A value computed from finite inputs without replacing anything.
    pub fn clean(value: T) -> Self {
        Self { value, replaced: false }
    }

    /// `value` after a non-finite input or result was replaced to get it.
    pub fn replacing(value: T) -> Self {
        Self { value, replaced: true }
    }
}
