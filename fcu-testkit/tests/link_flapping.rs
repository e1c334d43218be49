//! A flapping link, flown: a receiver that delivers a burst of frames now and then must not
//! keep the drone flying (the adversarial review flew 20 s on 4 % of the frames, and climbed
//! to 85 m on bursts carrying 1400 µs of throttle).

use fcu_testkit::sim::scenario::{self, StickRow, Throttle, Timeline};
use fcu_testkit::sim::{self, RunOptions};
use fcu_testkit::Profile;

fn flap(off_ms: f64, on_ms: f64, thr_us: f64) -> sim::FlightLog {
    // Armed by the gesture, flying at `thr_us`, then from 6 s the link is off for `off_ms`
    // and on for `on_ms`, over and over.
    let gesture = |t_s: f64| StickRow {
        t_s,
        ail_us: scenario::AIL_CENTRE_US - 325.0,
        ele_us: scenario::ELE_CENTRE_US - 325.0,
        thr: Throttle::Us(1000.0),
        rud_us: scenario::RUD_CENTRE_US + 325.0,
        link: true,
    };
    let mut rows =
        vec![StickRow::idle(0.0), gesture(2.5), StickRow::idle(4.0), StickRow { thr: Throttle::Us(thr_us), ..StickRow::idle(4.5) }];
    let mut t = 6.0;
    while t < 14.0 {
        rows.push(StickRow { link: false, thr: Throttle::Us(thr_us), ..StickRow::idle(t) });
        rows.push(StickRow { link: true, thr: Throttle::Us(thr_us), ..StickRow::idle(t + off_ms / 1000.0) });
        t += (off_ms + on_ms) / 1000.0;
    }
    let sc = scenario::from_timeline("flapping link", Timeline { rows }, 14.0);
    sim::run(&sc, Profile::Default, &RunOptions { seed: 6, duration_s: Some(14.0), ..RunOptions::default() }).unwrap()
}

fn stage2_at(log: &sim::FlightLog) -> Option<f64> {
    log.rows.iter().find(|r| r.state == "failsafe2").map(|r| r.t_s)
}

#[test]
fn a_link_that_delivers_a_fifth_of_its_frames_ends_in_stage_2_within_about_3_s() {
    for (off, on) in [(150.0, 40.0), (900.0, 40.0), (300.0, 60.0)] {
        let log = flap(off, on, 1400.0);
        let at = stage2_at(&log).unwrap_or_else(|| panic!("off {off} / on {on} ms: never reached stage 2"));
        eprintln!("off {off} / on {on} ms: stage 2 {:.2} s after the first loss", at - 6.0);
        assert!(at - 6.0 <= 3.5, "off {off} / on {on} ms: stage 2 {:.2} s after the first loss", at - 6.0);
        assert!(log.rows.iter().filter(|r| r.t_s >= at).all(|r| !r.armed && r.motors == [0; 4]), "motors restarted after stage 2");
    }
}

#[test]
fn a_flapping_link_never_hands_control_back() {
    let log = flap(150.0, 40.0, 1400.0);
    let after_loss: Vec<&str> = log.rows.iter().filter(|r| r.t_s > 6.2).map(|r| r.state).collect();
    assert!(!after_loss.contains(&"armed"), "control went back to a link that delivers a fifth of its frames");
}
