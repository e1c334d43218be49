//! The mailbox between the link task and the control loop: what the tick takes, the outer step
//! follows; what the tick refuses reaches neither half.

use fcu_core::flight::{ChangeKind, ConfigChange, ControlTick, FlightController, ForcedRadio};
use fcu_core::imu::RawImu;
use fcu_core::supervisor::SupervisorConfig;
use fcu_core::Config;
use fcu_gcs::Mailbox;

fn tick() -> ControlTick {
    FlightController::new(&Config::default()).expect("the default configuration is valid").into_parts().0
}

fn with_pitch_p(kp: f32) -> Config {
    let d = Config::default();
    Config {
        control: fcu_core::control::ControlConfig { pitch: fcu_core::control::AxisGains { inner_kp: kp, ..d.control.pitch }, ..d.control },
        ..d
    }
}

/// Another kind of supervisor needs a new controller: the tick refuses it, armed or not.
fn refused_by_the_tick() -> Config {
    Config { supervisor: SupervisorConfig::Reference, ..Config::default() }
}

fn change(cfg: Config) -> Option<ConfigChange> {
    Some(ConfigChange { cfg, kind: ChangeKind::InFlight })
}

#[test]
fn a_change_the_tick_takes_reaches_the_outer_step_once() {
    let mut tick = tick();
    let mut mailbox = Mailbox::new(Config::default());
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), None, "nothing posted, nothing for the outer step");
    mailbox.post(change(with_pitch_p(40.0)), None);
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), Some(with_pitch_p(40.0)));
    assert_eq!(mailbox.config_for_outer(), None, "taken once");
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), None, "the tick takes a change once");
}

#[test]
fn a_newer_change_replaces_one_the_tick_has_not_taken() {
    let mut tick = tick();
    let mut mailbox = Mailbox::new(Config::default());
    mailbox.post(change(with_pitch_p(40.0)), None);
    mailbox.post(None, None);
    mailbox.post(change(with_pitch_p(45.0)), None);
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), Some(with_pitch_p(45.0)));
}

#[test]
fn a_change_the_tick_refuses_reaches_neither_half_and_the_next_one_is_taken() {
    let mut tick = tick();
    let mut mailbox = Mailbox::new(Config::default());
    mailbox.post(change(refused_by_the_tick()), None);
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), None, "the outer step must not run a change the tick refused");
    mailbox.post(change(with_pitch_p(40.0)), None);
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), Some(with_pitch_p(40.0)));
}

#[test]
fn a_change_taken_waits_for_the_outer_step_even_if_a_refused_one_follows() {
    let mut tick = tick();
    let mut mailbox = Mailbox::new(Config::default());
    mailbox.post(change(with_pitch_p(40.0)), None);
    mailbox.deliver_to_tick(&mut tick);
    mailbox.post(change(refused_by_the_tick()), None);
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), Some(with_pitch_p(40.0)), "the outer step follows the tick's last taken change");
}

/// The sequence the mailbox exists for: a ground-only change the link accepted while the board
/// was disarmed, and the board armed before the tick's turn came. The tick refuses it, and the
/// outer step, which follows the tick, never runs it either.
#[test]
fn a_ground_only_change_posted_disarmed_and_delivered_armed_reaches_neither_half() {
    // The reference's supervisor arms on the replay's flag, without a stick gesture.
    let cfg = refused_by_the_tick();
    let mut tick = FlightController::new(&cfg).expect("the reference supervisor's configuration is valid").into_parts().0;
    let mut mailbox = Mailbox::new(cfg);
    let level = RawImu { accel: [0, 0, 8197], gyro: [0; 3] };
    let radio = |armed: bool| ForcedRadio { width_counts: [6000, 6000, 8000, 6000], link: true, armed, cal_request: false };
    for _ in 0..2000 {
        tick.tick_forced(level, &radio(false));
    }
    assert!(!tick.changes_restricted());
    let mut trimmed = cfg;
    trimmed.rc.inputs[0].trim_counts += 20;
    mailbox.post(Some(ConfigChange { cfg: trimmed, kind: ChangeKind::GroundOnly }), None);
    for _ in 0..800 {
        tick.tick_forced(level, &radio(true));
    }
    assert!(tick.changes_restricted(), "the board did not arm");
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), None, "the outer step would run a change the armed tick refused");
    mailbox.deliver_to_tick(&mut tick);
    assert_eq!(mailbox.config_for_outer(), None, "a refused change came back");
}
