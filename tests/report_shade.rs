//! The shade report's claims on a small image: in unshadowed pixels the ratio estimator is nearly
//! exact (its error is rare rays blocked in pixels that show 99.5–100 % of `U`, plus the
//! reference's residual: a tenth or less of the stochastic error), and over the whole image it
//! beats the fully stochastic estimator at 1 and 2 samples per pixel; at 1 spp, in shadowed
//! pixels, it sits at the visibility floor (the error of any unbiased estimate made of `U` times
//! one binary visibility sample), which on the Cornell box is above half the stochastic error over
//! all pixels. Fixed seeds; 32² pixels, a 1024-spp reference, 16 repetitions. The orderings over
//! all pixels and in shadow are asserted at 95 % confidence: both sides' one-sided 97.5 % bounds
//! (`rmse ± t·rmse_stderr`, the report's delta-method standard error over the repetitions,
//! Student's t for 15 degrees of freedom) must keep the order, so that together they hold with
//! 95 % (Bonferroni, whatever the two estimates' correlation). The ratio's error in unshadowed
//! pixels is made of rare events that most repetitions do not see (its standard error is half
//! its value: one repetition in 16 with an event), where a t interval does not hold: that
//! ordering is a plain margin of 10×.
//!
//! Measured here: Cornell box, 1 spp, ratio in shadow 1.07 × the floor (95 %: 1.03–1.12 ×); floor
//! over all pixels 0.55 × the stochastic RMSE (0.53 × its interval's upper end) (64², 4096-spp
//! reference, 4 repetitions: 1.01 × and 0.57 ×).

use raywave::cpu::CpuBackend;
use raywave::report::shade::{report_shade, ShadeLine, ShadeReportOptions};
use statrs::distribution::{ContinuousCDF, StudentsT};

/// The 95 % confidence interval of `line`'s expected RMSE, `rmse ± t·rmse_stderr` over `reps`
/// repetitions (each end a one-sided 97.5 % bound).
fn interval(line: &ShadeLine, reps: u32) -> (f64, f64) {
    let t = StudentsT::new(0.0, 1.0, f64::from(reps - 1)).expect("two repetitions or more").inverse_cdf(0.975);
    let half_width = t * line.rmse_stderr.expect("a standard error");
    (line.rmse - half_width, line.rmse + half_width)
}

/// Asserts that the expected RMSE of `lower` is below `factor` times that of `higher` with 95 %
/// confidence (module documentation); `what` names the case in the message.
fn assert_below(lower: &ShadeLine, factor: f64, higher: &ShadeLine, reps: u32, what: &str) {
    let (upper, lower_bound) = (interval(lower, reps).1, interval(higher, reps).0);
    assert!(
        upper < factor * lower_bound,
        "{what}: {} ± {:?} is not below {factor} × {} ± {:?} at 95 % (bounds {upper} and {lower_bound})",
        lower.rmse,
        lower.rmse_stderr,
        higher.rmse,
        higher.rmse_stderr
    );
}

#[test]
fn ratio_estimator_is_exact_where_lit_at_the_visibility_floor_in_shadow_and_beats_the_stochastic_one() {
    let options = ShadeReportOptions {
        scenes: vec!["builtin:cornell".into(), "builtin:cornell-two-lights".into()],
        resolution: 32,
        reference_spp: 1024,
        max_spp: 2,
        // The ratio's error in unshadowed pixels is made of rare blocked rays (pixels that show
        // 99.5–100 % of `U`): 4 repetitions put it at 0.00315 ± 0.0016 on the two-light box,
        // 16 at 0.0016 ± 0.0008, 64 at 0.0012 ± 0.0004 (the stochastic estimate's 0.047–0.049).
        reps: 16,
    };
    let mut lines: Vec<ShadeLine> = Vec::new();
    report_shade(&mut CpuBackend::new(), &options, |line| lines.push(line.clone())).expect("report runs");
    assert_eq!(lines.len(), 2 * (3 + 2 * 2 * 3), "scenes × (floor regions + spp × estimators × regions)");
    let line = |scene: &str, spp: u32, estimator: &str, region: &str| {
        lines
            .iter()
            .find(|l| l.scene == scene && l.spp == spp && l.estimator == estimator && l.region == region)
            .expect("line present")
    };
    let rmse = |scene: &str, spp: u32, estimator: &str, region: &str| line(scene, spp, estimator, region).rmse;
    for scene in ["builtin:cornell", "builtin:cornell-two-lights"] {
        for spp in [1, 2] {
            let (ratio, stochastic) = (rmse(scene, spp, "ratio", "all"), rmse(scene, spp, "stochastic", "all"));
            eprintln!("{scene} {spp} spp: ratio {ratio:.5} stochastic {stochastic:.5} ({:.2}×)", ratio / stochastic);
            assert!(ratio.is_finite() && stochastic > 0.0);
            let all = |estimator| line(scene, spp, estimator, "all");
            assert_below(all("ratio"), 0.8, all("stochastic"), options.reps, &format!("{scene} {spp} spp"));
            let (lit_ratio, lit_stochastic) = (rmse(scene, spp, "ratio", "lit"), rmse(scene, spp, "stochastic", "lit"));
            let lit_floor = rmse(scene, 1, "visibility-floor", "lit");
            eprintln!(
                "{scene} {spp} spp lit: ratio {lit_ratio:.5} stochastic {lit_stochastic:.5} floor {lit_floor:.5}"
            );
            // A tenth: the rare-event error (above) is 0.0016 ± 0.0008 against 0.048 on the
            // two-light box at 1 spp — at a twentieth it would pass by about one standard error.
            assert!(lit_ratio < 0.1 * lit_stochastic, "{scene} {spp} spp lit: {lit_ratio} vs {lit_stochastic}");
        }
    }
    // One light of one colour, where the floor holds for unbiased estimates (but for the
    // lobes' colours: README, Shading): the 1-spp ratio estimate is `U` times its one shadow
    // ray's visibility, so in shadowed pixels its error is the floor's, off only by the ratio's
    // bias and the repetitions' noise.
    let cornell = "builtin:cornell";
    // Its 95 % interval lies within 0.9–1.2 × the floor.
    let (floor, ratio) = (rmse(cornell, 1, "visibility-floor", "shadow"), line(cornell, 1, "ratio", "shadow"));
    let (low, high) = interval(ratio, options.reps);
    eprintln!("{cornell} 1 spp shadow: ratio {:.5} ({low:.5}–{high:.5}) floor {floor:.5}", ratio.rmse);
    assert!(floor > 0.0 && low > 0.9 * floor && high < 1.2 * floor, "ratio {low}–{high} vs floor {floor} in shadow");
    // README: issue 5's target (ratio ≤ 0.5 × stochastic over all pixels at 1 spp) is below that
    // floor on the Cornell box — no unbiased estimate of this kind reaches it there.
    // (At 95 %: the floor, computed from the reference, has no repetitions.)
    let (floor_all, stochastic_all) =
        (rmse(cornell, 1, "visibility-floor", "all"), interval(line(cornell, 1, "stochastic", "all"), options.reps));
    eprintln!(
        "{cornell} 1 spp all: floor {floor_all:.5} stochastic {stochastic_all:.5?} ({:.2}×)",
        floor_all / stochastic_all.1
    );
    assert!(floor_all > 0.5 * stochastic_all.1, "floor {floor_all} vs stochastic {stochastic_all:?}");
}
