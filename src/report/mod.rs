//! `raywave report …`: accuracy measurements with stated repetitions, printed as a table or as
//! one JSON object per line.

pub mod error_vs_time;
pub mod flip;
pub mod sampling;
pub mod scenes;
pub mod shade;
pub mod spectrum;

/// What a scene report (`report shade`, `report error-vs-time`) measures: on each scene, a
/// converged reference and runs at 1, 2, 4, … `max_spp` samples per pixel.
#[derive(Clone, Debug)]
pub struct SceneReportOptions {
    /// Built-in scenes (`builtin:NAME`).
    pub scenes: Vec<String>,
    /// Image side in pixels.
    pub resolution: u32,
    /// Samples per pixel of the reference.
    pub reference_spp: u32,
    /// Largest sample count measured (powers of two from 1).
    pub max_spp: u32,
    /// Independent repetitions averaged per measurement.
    pub reps: u32,
}

/// Most repetitions a report averages (`--reps`): far more than any statistic here needs, and
/// small enough that the repetitions' seeds (`0..reps`) never reach the seeds a report keeps apart
/// for other images (the scene reports' reference, 65 261; the sampling report's second
/// estimator, from 2²⁰ on).
pub const MAX_REPS: u32 = 4096;

/// How many times `max-spp` a scene report's reference must sample at least: its own noise then
/// adds at most `√(1 + 1/4) − 1` ≈ 12 % to the RMSE measured at `max-spp` (its variance a quarter
/// of theirs, independent of them), less at fewer samples. The default 4096 is 64 × the default 64.
pub const MIN_REFERENCE_FACTOR: u32 = 4;

/// Checks a report's repetitions: `minimum..=`[`MAX_REPS`], the error naming `--reps`.
pub fn check_reps(reps: u32, minimum: u32) -> crate::Result<()> {
    if (minimum..=MAX_REPS).contains(&reps) {
        Ok(())
    } else {
        Err(crate::Error::InvalidParameter {
            name: "reps",
            reason: format!("{reps} is outside {minimum}..={MAX_REPS}"),
        })
    }
}

impl SceneReportOptions {
    /// Checks the options: reps within `1..=`[`MAX_REPS`], max-spp ≥ 1, reference-spp at least
    /// [`MIN_REFERENCE_FACTOR`] × max-spp, the resolution
    /// ([`check_resolution`]) and the reference's sample count
    /// ([`check_samples_per_pixel`](crate::frame::check_samples_per_pixel)); an error names the
    /// option.
    pub fn check(&self) -> crate::Result<()> {
        let invalid = |name, reason: String| Err(crate::Error::InvalidParameter { name, reason });
        check_reps(self.reps, 1)?;
        if self.max_spp < 1 {
            return invalid("max-spp", format!("{} is below 1", self.max_spp));
        }
        if u64::from(self.reference_spp) < u64::from(MIN_REFERENCE_FACTOR) * u64::from(self.max_spp) {
            let reason = format!(
                "{} is below {MIN_REFERENCE_FACTOR} × max-spp ({}): the reference must converge further than what \
                 it measures",
                self.reference_spp, self.max_spp
            );
            return invalid("reference-spp", reason);
        }
        check_resolution(self.resolution)?;
        crate::frame::check_samples_per_pixel("reference-spp", self.resolution, self.resolution, self.reference_spp)
    }

    /// Loads every scene before any is measured, so that a bad name or a scene the report cannot
    /// measure fails at once: each needs a quad light — the estimators compared are of the
    /// direct light from quad lights, and a scene without one would print errors of 0.
    pub fn load_scenes(&self) -> crate::Result<Vec<crate::Scene>> {
        let load = |name: &String| {
            let scene = crate::Scene::load(name)?;
            if scene.lights().is_empty() {
                return Err(crate::Error::InvalidParameter {
                    name: "scenes",
                    reason: format!("{name} has no quad light, so there is no direct light to estimate"),
                });
            }
            Ok(scene)
        };
        self.scenes.iter().map(load).collect()
    }

    /// The measured sample counts: 1, 2, 4, … up to `max_spp`.
    pub fn spp_steps(&self) -> impl Iterator<Item = u32> {
        let max = self.max_spp;
        std::iter::successors(Some(1u32), |&n| n.checked_mul(2)).take_while(move |&n| n <= max)
    }
}

/// Checks a report's image side: 4 to 1024 pixels (smaller images have no statistics worth
/// reporting, larger ones only cost time).
pub fn check_resolution(resolution: u32) -> crate::Result<()> {
    if (4..=1024).contains(&resolution) {
        Ok(())
    } else {
        Err(crate::Error::InvalidParameter { name: "resolution", reason: "must be within 4..=1024".into() })
    }
}

/// The sum of `values`, +0 for none: `Iterator::sum` of no `f64` is −0, which an empty region's
/// RMSE printed as `-0.0`.
pub(crate) fn sum_from_zero(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(0.0, |sum, value| sum + value)
}
