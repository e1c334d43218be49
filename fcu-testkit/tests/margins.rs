//! The attitude loops keep classical robustness margins (D15): at least 45° of phase and 6 dB
//! of gain on every axis, measured by `fcu-sim margins` (the loop broken at the motors, in
//! hover), on the nominal airframe and on five airframes with every parameter randomised by
//! ±30 %, each with one more control tick of delay than the firmware has. The reference's
//! gains do not (about 25° on roll and pitch, 18° on yaw), which shows the check can fail.

use fcu_testkit::cli::margins::{all_meet, measure};
use fcu_testkit::sim::loop_id::AXES;
use fcu_testkit::sim::RunOptions;
use fcu_testkit::Profile;

fn summary(loops: &[fcu_testkit::sim::loop_id::AxisLoop]) -> String {
    loops
        .iter()
        .map(|l| {
            format!(
                "{} fc {:?} PM {:?} GM {:?}",
                AXES[l.axis], l.margins.crossover_hz, l.margins.phase_margin_deg, l.margins.gain_margin_db
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

fn check(seed: u64, spread: f64, extra_delay_ticks: u32) {
    let opts = RunOptions { seed, plant_spread: spread, extra_delay_ticks, ..RunOptions::default() };
    let loops = measure(Profile::Default, &opts).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("seed {seed}, ±{spread}, +{extra_delay_ticks}: {}", summary(&loops));
    assert!(all_meet(&loops), "seed {seed}, ±{spread}, +{extra_delay_ticks} tick(s): {}", summary(&loops));
}

#[test]
fn the_nominal_drone_keeps_45_deg_and_6_db_with_and_without_an_extra_tick() {
    check(1, 0.0, 0);
    check(1, 0.0, 1);
}

#[test]
fn airframes_30_percent_off_keep_45_deg_and_6_db_with_an_extra_tick() {
    for seed in 1..=5 {
        check(seed, 0.3, 1);
    }
}

#[test]
fn the_reference_gains_do_not_keep_these_margins() {
    let loops = measure(Profile::Reference, &RunOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(!all_meet(&loops), "{}", summary(&loops));
    assert!(loops.iter().all(|l| l.margins.phase_margin_deg.is_some_and(|pm| pm < 30.0)), "{}", summary(&loops));
}
