//! `raywave report …`: accuracy measurements with stated repetitions, printed as a table or as
//! one JSON object per line.

pub mod error_vs_time;
pub mod flip;
pub mod sampling;
pub mod scenes;
pub mod shade;
pub mod spectrum;
pub mod variance;

/// What a scene report (`report shade`, `report error-vs-time`) measures: on each scene, a
/// converged reference and runs at 1, 2, 4, … `max_spp` samples per pixel.
#[derive(Clone, Debug)]
pub struct SceneReportOptions {
    /// Scenes: `builtin:NAME` or scene files, each with a quad light.
    pub scenes: Vec<String>,
    /// Image side in pixels.
    pub resolution: u32,
    /// Samples per pixel of the reference.
    pub reference_spp: u32,
    /// Largest sample count measured, a power of two (the report measures powers of two from 1).
    pub max_spp: u32,
    /// Independent repetitions averaged per measurement.
    pub reps: u32,
}

/// Most repetitions a report averages (`--reps`): far more than any statistic here needs, and
/// small enough that the repetitions' seeds (`0..reps`) never reach the seeds a report keeps apart
/// for other images (the scene reports' reference, [`REFERENCE_SEED`]; the sampling report's
/// second estimator, from 2²⁰ on).
pub const MAX_REPS: u32 = 4096;

/// The sampler seed of a scene report's converged reference (65 261), apart from every
/// repetition's seed (`0..`[`MAX_REPS`]), so that no measured run shares its samples.
pub const REFERENCE_SEED: u32 = 0xfeed;

const _: () = assert!(REFERENCE_SEED >= MAX_REPS);

/// How many times `max-spp` a scene report's reference must sample at least: its own noise then
/// adds at most `√(1 + 1/4) − 1` ≈ 12 % to `report shade`'s ratio RMSE at `max-spp` over all
/// pixels and over shadowed ones (its variance a quarter of theirs, independent of them), less at
/// fewer samples — not in unshadowed pixels, where the ratio's own error is all but 0 and what
/// is measured is mostly the reference's rarely blocked samples —, but up to 25 % to a relMSE,
/// an MSE, and more to the error of a denoised image, whose own variance is far below the raw
/// estimate's at the same samples, so `report error-vs-time` wants a much larger factor (its
/// default 4096 at 64 spp is 64 ×, as is `report shade`'s). A floor that catches a reference
/// no better than what it measures, not a guarantee of accuracy.
pub const MIN_REFERENCE_FACTOR: u32 = 4;

/// Checks a report's repetitions: `minimum..=`[`MAX_REPS`], the error naming `--reps` and, below
/// the minimum, adding `why_minimum` (why fewer will not do).
pub fn check_reps(reps: u32, minimum: u32, why_minimum: &str) -> crate::Result<()> {
    if (minimum..=MAX_REPS).contains(&reps) {
        return Ok(());
    }
    let why = if reps < minimum { why_minimum } else { "" };
    Err(crate::Error::InvalidParameter {
        name: "reps",
        reason: format!("{reps} is outside {minimum}..={MAX_REPS}{why}"),
    })
}

impl SceneReportOptions {
    /// Checks the options: reps within `1..=`[`MAX_REPS`], no scene name empty or listed twice, max-spp a power of two,
    /// reference-spp at least [`MIN_REFERENCE_FACTOR`] × max-spp, the resolution
    /// ([`check_resolution`]) and the reference's sample count
    /// ([`check_samples_per_pixel`](crate::frame::check_samples_per_pixel)); an error names the
    /// option.
    pub fn check(&self) -> crate::Result<()> {
        let invalid = |name, reason: String| Err(crate::Error::InvalidParameter { name, reason });
        check_reps(self.reps, 1, "")?;
        if let Some(index) = self.scenes.iter().position(|s| s.trim().is_empty()) {
            // `--scenes ,` had been refused as a scene `` listed twice, and a trailing comma as
            // a scene `` of unsupported format.
            let reason = format!(
                "entry {} of {} is empty: a comma must stand between two scene names",
                index + 1,
                self.scenes.len()
            );
            return invalid("scenes", reason);
        }
        if let Some(repeated) =
            self.scenes.iter().enumerate().find_map(|(i, s)| self.scenes[..i].contains(s).then_some(s))
        {
            // Lines, plots and tables are keyed by the scene's name: a second run would merge into the first.
            return invalid("scenes", format!("{repeated} is listed twice"));
        }
        if !self.max_spp.is_power_of_two() {
            let reason = format!("{} is not a power of two (the report measures 1, 2, 4, … up to it)", self.max_spp);
            return invalid("max-spp", reason);
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
        let (kind, resolution) = (crate::shared::sampling::sampler_kind::ZSOBOL, self.resolution);
        crate::frame::check_samples_per_pixel("reference-spp", kind, resolution, resolution, self.reference_spp)
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

/// The warning a scene report prints on stderr when `count` values of `scene`'s frames at `spp`
/// samples went non-finite and were replaced ([`crate::StageReport::sanitized`]; only a scene
/// of broken geometry does that): its errors were measured on the replacements. `None` for 0.
fn sanitized_warning(scene: &str, spp: u32, count: u64) -> Option<String> {
    (count > 0).then(|| {
        format!(
            "warning: {scene} at {spp} spp: {count} value(s) went non-finite and were replaced (rays or hits \
             as misses, samples without their contribution, colours by the emitted radiance); the errors \
             reported include them"
        )
    })
}

/// Prints [`sanitized_warning`] on stderr, if any.
pub(crate) fn warn_if_sanitized(scene: &str, spp: u32, count: u64) {
    if let Some(warning) = sanitized_warning(scene, spp, count) {
        crate::output_line::warn(&warning);
    }
}

/// Checks a report's image side: 4 to 1024 pixels (smaller images have no statistics worth
/// reporting, larger ones only cost time).
pub fn check_resolution(resolution: u32) -> crate::Result<()> {
    if (4..=1024).contains(&resolution) {
        Ok(())
    } else {
        let reason = format!("{resolution} is outside 4..=1024");
        Err(crate::Error::InvalidParameter { name: "resolution", reason })
    }
}

/// A measurement repeated over independent seeds: its mean, and the standard error of that mean
/// (Welford's running mean and sum of squared deviations, which do not cancel when the values
/// barely differ).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Repeated {
    count: u32,
    mean: f64,
    squared_deviations: f64,
}

impl Repeated {
    /// Adds one repetition's value.
    pub fn add(&mut self, value: f64) {
        self.count += 1;
        let delta = value - self.mean;
        self.mean += delta / f64::from(self.count);
        self.squared_deviations += delta * (value - self.mean);
    }

    /// The mean of the values (0 for none).
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// The standard error of [`Self::mean`], `s/√n` with `s` the values' sample standard
    /// deviation: the expectation lies within ±t of it of the mean with 95 % confidence, t the
    /// Student-t quantile for `n − 1` degrees of freedom (4.30 for 3 values, 3.18 for 4, 2.26 for
    /// 10, 1.96 for many; each value a mean over many pixels, so close to normal). `None` for
    /// fewer than two values.
    pub fn standard_error(&self) -> Option<f64> {
        (self.count >= 2).then(|| {
            let n = f64::from(self.count);
            (self.squared_deviations / (n - 1.0) / n).sqrt()
        })
    }
}

/// The sum of `values`, +0 for none: `Iterator::sum` of no `f64` is −0, which an empty region's
/// RMSE printed as `-0.0`.
pub(crate) fn sum_from_zero(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(0.0, |sum, value| sum + value)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An empty name in `--scenes` (a leading, doubled or trailing comma) is refused as such.
    #[test]
    fn an_empty_scene_name_is_refused() {
        let options = |scenes: &[&str]| SceneReportOptions {
            scenes: scenes.iter().map(|&s| s.to_owned()).collect(),
            resolution: 16,
            reference_spp: 64,
            max_spp: 4,
            reps: 1,
        };
        options(&["builtin:cornell"]).check().unwrap();
        for (scenes, expected) in [
            (&["", ""][..], "entry 1 of 2 is empty"),
            (&["builtin:cornell", ""], "entry 2 of 2 is empty"),
            (&["builtin:cornell", " ", "builtin:cornell-two-lights"], "entry 2 of 3 is empty"),
        ] {
            match options(scenes).check() {
                Err(crate::Error::InvalidParameter { name: "scenes", reason }) => {
                    assert!(reason.starts_with(expected), "{scenes:?}: {reason}")
                }
                other => panic!("{scenes:?}: {other:?}"),
            }
        }
    }

    #[test]
    fn only_sanitized_values_warn_and_the_warning_names_scene_and_count() {
        assert_eq!(sanitized_warning("builtin:cornell", 4, 0), None);
        let warning = sanitized_warning("broken.obj", 2, 17).expect("a warning");
        assert!(warning.starts_with("warning: broken.obj at 2 spp: 17 value(s) went non-finite"), "{warning}");
    }

    #[test]
    fn repeated_values_give_their_mean_and_its_standard_error() {
        let mut repeated = Repeated::default();
        assert_eq!((repeated.mean(), repeated.standard_error()), (0.0, None));
        repeated.add(2.0);
        assert_eq!((repeated.mean(), repeated.standard_error()), (2.0, None), "one value has no spread");
        for value in [4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0] {
            repeated.add(value);
        }
        // Mean 5, sample variance 32/7 over 8 values.
        assert!((repeated.mean() - 5.0).abs() < 1e-12);
        let expected = (32.0 / 7.0 / 8.0f64).sqrt();
        assert!((repeated.standard_error().unwrap() - expected).abs() < 1e-12);
        // Values that barely differ, far from 0: the sum of squares minus the squared sum would
        // cancel to nothing (or below zero) here.
        let mut close = Repeated::default();
        for k in 0..4 {
            close.add(1.0e6 + f64::from(k) * 1.0e-6);
        }
        let expected = (1.25e-12f64 * 4.0 / 3.0 / 4.0).sqrt();
        assert!((close.standard_error().unwrap() / expected - 1.0).abs() < 1e-3, "{close:?}");
    }
}
