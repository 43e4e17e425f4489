//! Every warp of `raywave_kernels::sampling::warp` on the CPU, against its own pdf: 10⁶ samples
//! per case from independent random numbers (fixed seed), checked by
//! [`warp_cases::check_warp`] — finite unit directions, sample pdf = `warp::pdf` within 10⁻³,
//! pdf integral 1 within 2·10⁻³, chi-square tests at family significance 0.01 (Šidák-corrected
//! per test). The same cases and check serve the Vulkan warp parity tests.

mod common;

use common::warp_cases::{cpu_samples, warp_cases, warp_report};
use raywave::shared::sampling::warp_kind;
use std::time::Instant;

#[test]
fn every_warp_matches_its_pdf() {
    let start = Instant::now();
    let mut failures = Vec::new();
    for (name, params) in warp_cases() {
        let samples = cpu_samples(&params);
        let report = warp_report(&name, &params, &samples);
        println!("{report}");
        if let Err(e) = report.result() {
            failures.push(e);
        }
    }
    println!("{} cases in {:.1} s", warp_cases().len(), start.elapsed().as_secs_f64());
    assert!(failures.is_empty(), "{} warp cases failed:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn the_cases_cover_every_warp_kind() {
    let cases = warp_cases();
    for kind in 0..warp_kind::COUNT {
        assert!(cases.iter().any(|(_, p)| p.kind == kind), "no case for warp kind {kind}");
    }
}
