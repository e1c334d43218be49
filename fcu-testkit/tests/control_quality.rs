//! How well the default profile flies (its gains tuned on the measured loop, and for yaw its
//! shaped turns), against ST's reference on the same airframes:
//! five seeds with every airframe parameter randomised by ±30 %, each scenario's metric
//! checked against its goal and against the reference's on the same seed. The README's table
//! is the medians of these numbers (`cargo test -p fcu-testkit --test control_quality --
//! --nocapture` prints them).

use fcu_testkit::sim::metrics::{self, Metrics};
use fcu_testkit::sim::{self, scenario, RunOptions};
use fcu_testkit::Profile;

const SEEDS: [u64; 5] = [1, 2, 3, 4, 5];
const SPREAD: f64 = 0.3;

fn fly(name: &str, profile: Profile, seed: u64) -> Metrics {
    let sc = scenario::by_name(name).unwrap_or_else(|| panic!("no scenario {name}"));
    let log = sim::run(&sc, profile, &RunOptions { seed, plant_spread: SPREAD, ..RunOptions::default() }).unwrap_or_else(|e| panic!("{e}"));
    metrics::compute(&log, &sc)
}

/// Per seed (default, reference) of one metric of one scenario.
fn per_seed(name: &str, metric: fn(&Metrics) -> Option<f64>) -> Vec<(f64, f64)> {
    SEEDS
        .iter()
        .map(|&seed| {
            let value = |p| metric(&fly(name, p, seed)).unwrap_or_else(|| panic!("{name}, seed {seed}: no metric"));
            (value(Profile::Default), value(Profile::Reference))
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Every seed within `goal` and at most half the reference's value; prints the medians.
fn check(what: &str, values: &[(f64, f64)], goal: f64) {
    let (d, r): (Vec<f64>, Vec<f64>) = values.iter().copied().unzip();
    eprintln!("{what}: median default {:.3}, reference {:.3} (seeds {SEEDS:?}, ±30 %)", median(d.clone()), median(r.clone()));
    for (k, &(d, r)) in values.iter().enumerate() {
        assert!(d <= goal, "{what}, seed {}: {d:.3} over the goal {goal}", SEEDS[k]);
        assert!(d <= r / 2.0, "{what}, seed {}: {d:.3} is not twice as good as the reference's {r:.3}", SEEDS[k]);
    }
}

#[test]
fn hover_attitude_error_is_within_0_32_deg_and_half_the_reference() {
    check("hover RMS, °", &per_seed("hover", |m| m.hover_rms_deg), 0.32);
}

#[test]
fn a_gust_tilts_less_than_3_5_deg_and_half_as_much_as_the_reference() {
    check("gust largest tilt, °", &per_seed("gust", |m| m.max_tilt_armed_deg), 3.5);
}

#[test]
fn a_20_deg_step_rises_within_0_30_s_overshooting_at_most_5_percent() {
    check("20° step rise, s", &per_seed("steps", |m| m.step_rise_s), 0.30);
    let overshoot: Vec<f64> = per_seed("steps", |m| m.step_overshoot_pct).into_iter().map(|(d, _)| d).collect();
    eprintln!("20° step overshoot, %: median default {:.2}", median(overshoot.clone()));
    assert!(overshoot.iter().all(|&o| o <= 5.0), "overshoot {overshoot:?}");
}

#[test]
fn a_weak_motor_leaves_less_than_0_5_deg_and_half_the_reference() {
    check("weak-motor RMS, °", &per_seed("weak-motor", |m| m.hover_rms_deg), 0.5);
}

#[test]
fn yaw_turns_track_their_rate_twice_as_well_as_the_reference() {
    // The goal is 9 °/s, measured against the rate the stick asks for (not the core's own,
    // shaped, heading target): the median meets it; each airframe is held to 10 °/s and half
    // the reference. Not every airframe can meet 9 °/s: the error is the stops and starts of
    // full-stick turns, and no loop stops a turn faster than the motors' lag and the weak yaw
    // torque allow (`examples/yaw_floor.rs` measures that floor; its figures per seed are in
    // docs/control.md). The default shapes the stick's rate into a turn the airframe can
    // follow and leads the demand by its acceleration, so the rate loop asks for the torque
    // before an error builds up.
    let values = per_seed("yaw", |m| m.yaw_rate_rms_dps);
    eprintln!("yaw rate RMS error per seed, default: {:?}", values.iter().map(|v| (v.0 * 100.0).round() / 100.0).collect::<Vec<_>>());
    check("yaw rate RMS error, °/s", &values, 10.0);
    let (d, _): (Vec<f64>, Vec<f64>) = values.into_iter().unzip();
    assert!(median(d.clone()) <= 9.0, "median {}", median(d));
}
