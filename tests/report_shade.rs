//! The shade report's claims on a small image: in unshadowed pixels the ratio estimator is exact
//! (its error is the reference's residual, ≪ the stochastic error), and over the whole image it
//! beats the fully stochastic estimator at 1 and 2 samples per pixel. Fixed seeds; 32² pixels,
//! a 1024-spp reference, 4 repetitions.

use raywave::cpu::CpuBackend;
use raywave::report::shade::{report_shade, ShadeLine, ShadeReportOptions};

#[test]
fn ratio_estimator_is_exact_where_lit_and_beats_the_stochastic_one() {
    let options = ShadeReportOptions {
        scenes: vec!["builtin:cornell".into(), "builtin:cornell-two-lights".into()],
        resolution: 32,
        reference_spp: 1024,
        max_spp: 2,
        reps: 4,
    };
    let mut lines: Vec<ShadeLine> = Vec::new();
    report_shade(&mut CpuBackend::new(), &options, |line| lines.push(line.clone())).expect("report runs");
    assert_eq!(lines.len(), 2 * 2 * 2 * 3, "scenes × spp × estimators × regions");
    let rmse = |scene: &str, spp: u32, estimator: &str, region: &str| {
        lines
            .iter()
            .find(|l| l.scene == scene && l.spp == spp && l.estimator == estimator && l.region == region)
            .map(|l| l.rmse)
            .expect("line present")
    };
    for scene in ["builtin:cornell", "builtin:cornell-two-lights"] {
        for spp in [1, 2] {
            let (ratio, stochastic) = (rmse(scene, spp, "ratio", "all"), rmse(scene, spp, "stochastic", "all"));
            eprintln!("{scene} {spp} spp: ratio {ratio:.5} stochastic {stochastic:.5} ({:.2}×)", ratio / stochastic);
            assert!(ratio.is_finite() && stochastic > 0.0);
            assert!(ratio < 0.8 * stochastic, "{scene} {spp} spp: ratio {ratio} vs stochastic {stochastic}");
            let (lit_ratio, lit_stochastic) = (rmse(scene, spp, "ratio", "lit"), rmse(scene, spp, "stochastic", "lit"));
            assert!(lit_ratio < 0.05 * lit_stochastic, "{scene} {spp} spp lit: {lit_ratio} vs {lit_stochastic}");
        }
    }
}
