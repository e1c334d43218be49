//! The arm gesture's release, flown: the drone arms only once every stick is back in a safe
//! place, and the yaw target does not move while the throttle is low (an adversarial run armed
//! with the sticks still at the gesture's deflection and wound the yaw target up to 45° on the
//! ground).

use fcu_testkit::sim::scenario::{self, StickRow, Throttle, Timeline, AIL_CENTRE_US, ELE_CENTRE_US, RUD_CENTRE_US};
use fcu_testkit::sim::{self, RunOptions};
use fcu_testkit::Profile;

/// Gesture deflection, µs (1300 counts of 0.25 µs beyond centre).
const GESTURE_US: f64 = 325.0;

fn fly(rows: Vec<StickRow>, seconds: f64) -> sim::FlightLog {
    let sc = scenario::from_timeline("release", Timeline { rows }, seconds);
    sim::run(&sc, Profile::Default, &RunOptions { seed: 4, duration_s: Some(seconds), ..RunOptions::default() }).unwrap()
}

fn gesture(t_s: f64, thr_us: f64) -> StickRow {
    StickRow {
        t_s,
        ail_us: AIL_CENTRE_US - GESTURE_US,
        ele_us: ELE_CENTRE_US - GESTURE_US,
        thr: Throttle::Us(thr_us),
        rud_us: RUD_CENTRE_US + GESTURE_US,
        link: true,
    }
}

#[test]
fn a_throttle_nudge_with_the_sticks_deflected_does_not_arm() {
    // Full hold from 2.5 s, then at 4.0 s only the throttle leaves zero (still below MIN_THR):
    // aileron, elevator and rudder stay deflected until 6 s, then everything is centred.
    let rows = vec![StickRow::idle(0.0), gesture(2.5, 1000.0), gesture(4.0, 1030.0), StickRow::idle(6.0)];
    let log = fly(rows, 7.0);
    let armed_at = log.rows.iter().find(|r| r.armed).map(|r| r.t_s);
    let armed_at = armed_at.expect("never armed after the sticks were centred");
    assert!(armed_at >= 6.0, "armed at {armed_at:.3} s with the sticks still deflected");
    assert!(log.rows.iter().filter(|r| r.t_s < 6.0).all(|r| r.motors == [0; 4]));
}

#[test]
fn the_yaw_target_does_not_move_while_the_throttle_is_low() {
    // Armed, throttle low, rudder held full right for 2 s, then centred.
    let rudder_right = StickRow { t_s: 5.0, rud_us: RUD_CENTRE_US + GESTURE_US, ..StickRow::idle(5.0) };
    let rows = vec![StickRow::idle(0.0), gesture(2.5, 1000.0), StickRow::idle(4.0), rudder_right, StickRow::idle(7.0)];
    let log = fly(rows, 8.0);
    assert!(log.rows.iter().any(|r| r.armed && r.t_s > 5.0), "not armed with the throttle low");
    let worst = log.rows.iter().filter(|r| r.t_s > 4.0).map(|r| r.yaw_target_deg.abs()).fold(0.0, f64::max);
    assert!(worst < 1e-6, "the yaw target moved to {worst:.2}° with the throttle low");
}
