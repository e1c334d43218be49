//! How well altitude hold flies (issue 28): the altitude scenarios on five airframes with every
//! parameter randomised by ±30 % and, from the same seeds, the barometer's errors drawn
//! (offset, warm-up drift, prop wash, ground effect, gust pressure). The goals are on the
//! medians over the airframes, as tests/control_quality.rs checks the attitude's; the safety
//! rule (never motors off above 0.3 m) on every airframe. `cargo test -p fcu-testkit --test
//! altitude_quality -- --nocapture` prints the figures docs/simulation.md and the README quote.

use fcu_testkit::sim::metrics::{self, Metrics};
use fcu_testkit::sim::scenario::{self, Criterion};
use fcu_testkit::sim::{self, RunOptions};
use fcu_testkit::Profile;

const SEEDS: [u64; 5] = [1, 2, 3, 4, 5];
const SPREAD: f64 = 0.3;

fn fly(name: &str, seed: u64) -> (sim::FlightLog, scenario::Scenario, Metrics) {
    let sc = scenario::by_name(name).unwrap_or_else(|| panic!("no scenario {name}"));
    let log = sim::run(&sc, Profile::Default, &RunOptions { seed, plant_spread: SPREAD, ..RunOptions::default() })
        .unwrap_or_else(|e| panic!("{name}, seed {seed}: {e}"));
    let m = metrics::compute(&log, &sc);
    (log, sc, m)
}

/// One metric of one scenario per seed (`NaN` where the flight did not produce it).
fn per_seed(name: &str, metric: fn(&Metrics) -> Option<f64>) -> Vec<f64> {
    SEEDS.iter().map(|&seed| metric(&fly(name, seed).2).unwrap_or(f64::NAN)).collect()
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn report(label: &str, unit: &str, v: &[f64]) -> f64 {
    let m = median(v);
    let each: Vec<String> = v.iter().map(|x| format!("{x:.3}")).collect();
    eprintln!("{label}: median {m:.3} {unit} (seeds {SEEDS:?}, ±30 %: {})", each.join(", "));
    m
}

#[test]
fn a_calm_hold_drifts_less_than_0_10_m_over_30_s() {
    let drift: Vec<f64> = per_seed("althold-hover", |m| m.height_drift_m).into_iter().map(f64::abs).collect();
    let m = report("height drift over the hold (30 s)", "m", &drift);
    assert!(m <= scenario::HOLD_DRIFT_MAX_M, "drift {m:.3} m over the goal");
}

/// The error is measured on the true height: the hold's own unsteadiness and the estimate's
/// offset from the true height (the barometer is re-referenced to the accelerometer's height
/// once clear of the floor after the lift-off, which takes the prop wash at hover and ground
/// effect out; docs/altitude.md) are printed beside it.
#[test]
fn a_calm_hold_stays_within_0_05_m_rms() {
    let rms = per_seed("althold-hover", |m| m.height_rms_m);
    report("  of which the estimate's offset (mean, calm)", "m", &per_seed("althold-hover", |m| m.height_offset_m));
    report("  and the hold's unsteadiness (calm)", "m", &per_seed("althold-hover", |m| m.height_rms_about_offset_m));
    let m = report("height RMS error while holding (calm)", "m", &rms);
    assert!(m <= scenario::HOLD_RMS_CALM_MAX_M, "height RMS error {m:.3} m over the goal");
}

#[test]
fn a_hold_in_gusts_stays_within_0_15_m_rms() {
    report("  and the hold's unsteadiness (gusts)", "m", &per_seed("althold-gust", |m| m.height_rms_about_offset_m));
    let m = report("height RMS error while holding (gusts)", "m", &per_seed("althold-gust", |m| m.height_rms_m));
    assert!(m <= scenario::HOLD_RMS_GUSTS_MAX_M, "height RMS error in gusts {m:.3} m over the goal");
}

/// Against a simulated pilot who sees the true height and climb rate without noise: the hold
/// flies on a barometer, and its estimate's noise reaches the throttle (the estimator's
/// ALT_EST_TAU of 4 s and the height loop's ALT_POS_P of 1/s keep it under the pilot's).
#[test]
fn the_hold_moves_the_throttle_less_than_a_pilot_hovering_by_hand() {
    let hold = per_seed("althold-hover", |m| m.throttle_oscillation_counts);
    let manual = per_seed("hover", |m| m.throttle_oscillation_counts);
    let (h, p) = (report("throttle oscillation in hold", "counts", &hold), report("throttle oscillation, manual hover", "counts", &manual));
    assert!(h < p, "the hold's {h:.2} counts against the manual hover's {p:.2}");
}

#[test]
fn the_failsafe_lands_gently_and_never_stops_the_motors_in_the_air() {
    let mut touchdown = Vec::new();
    for seed in SEEDS {
        let (log, sc, m) = fly("failsafe-descent", seed);
        // On every airframe: the motors never stop above 0.3 m, and it ends disarmed.
        let rule = metrics::check(
            &log,
            &Criterion::MotorsOffOnlyBelow { from_s: scenario::ARM_RELEASE_S, max_m: scenario::MOTORS_OFF_MAX_HEIGHT_M },
        );
        assert!(rule.passed, "seed {seed}: {}", rule.detail);
        assert!(m.level_after_link_loss_s.is_some(), "seed {seed}: not level after the link loss");
        let end = metrics::check(&log, &Criterion::MotorsOffDisarmedFrom { t_s: sc.duration_s - 0.5 });
        assert!(end.passed, "seed {seed}: {}", end.detail);
        touchdown.push(m.touchdown_speed_m_s.unwrap_or(f64::NAN));
    }
    let t = report("touchdown speed (failsafe)", "m/s", &touchdown);
    assert!(t <= scenario::FAILSAFE_TOUCHDOWN_MAX_M_S, "touchdown {t:.3} m/s over the goal");
}

/// Landing by stick at the bottom in hold: the descent slows near the floor (issue 28's
/// touchdown goal, the failsafe's), and the motors never stop in the air on any airframe.
#[test]
fn the_stick_at_the_bottom_in_hold_lands_gently() {
    let mut touchdown = Vec::new();
    for seed in SEEDS {
        let (log, _, m) = fly("althold-hover", seed);
        let rule = metrics::check(
            &log,
            &Criterion::MotorsOffOnlyBelow { from_s: scenario::ARM_RELEASE_S, max_m: scenario::MOTORS_OFF_MAX_HEIGHT_M },
        );
        assert!(rule.passed, "seed {seed}: {}", rule.detail);
        touchdown.push(m.touchdown_speed_m_s.unwrap_or(f64::NAN));
    }
    let t = report("touchdown speed (stick at the bottom in hold)", "m/s", &touchdown);
    assert!(t <= scenario::STICK_TOUCHDOWN_MAX_M_S, "touchdown {t:.3} m/s over the goal");
}

#[test]
fn the_failsafe_disarms_within_1_s_of_the_touchdown() {
    let d = report("disarmed after touchdown (failsafe)", "s", &per_seed("failsafe-descent", |m| m.disarmed_after_touchdown_s));
    assert!(d <= scenario::FAILSAFE_DISARM_AFTER_TOUCHDOWN_MAX_S, "disarmed {d:.3} s after the touchdown, over the goal");
}

#[test]
fn a_stuck_barometer_is_reported_and_the_hold_lets_go_without_a_drop() {
    let mut lost = Vec::new();
    for seed in SEEDS {
        let (log, sc, m) = fly("baro-fault", seed);
        let t = sc.baro_freeze_s.unwrap_or(f64::NAN);
        let reported = metrics::check(&log, &Criterion::BaroFaultReportedWithin { t_s: t, max_s: 0.5 });
        assert!(reported.passed, "seed {seed}: {}", reported.detail);
        lost.push(m.height_lost_leaving_hold_m.unwrap_or(f64::NAN));
    }
    let m = report("height lost on leaving hold (stuck barometer)", "m", &lost);
    assert!(m <= scenario::BARO_FAULT_HEIGHT_LOST_MAX_M, "lost {m:.3} m");
}
