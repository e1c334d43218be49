//! The link in front of fcu-core's station, as the firmware runs it: each command's answer,
//! what reaches the control tick, and what a ground station hears back of a parameter set.

#[path = "../../fcu-link/tests/support/mod.rs"]
mod support;

use fcu_core::flight::{FlightController, Status};
use fcu_core::gcs::{Disarm, MotorTestChange};
use fcu_core::rc::Sticks;
use fcu_core::supervisor::FlightState;
use fcu_core::Config;
use fcu_gcs::Station;
use fcu_link::command::FORCE_DISARM;
use fcu_link::{Link, LinkConfig, Rates, Severity, Vehicle};
use fcu_params as parameters;
use mavlink::dialects::common::{MavCmd, MavResult};
use support::*;

fn link() -> TestLink {
    Link::new(LinkConfig::DEFAULT)
}

fn ack_of(sent: &[Sent]) -> (u16, MavResult) {
    let acks = acks(sent);
    assert_eq!(acks.len(), 1, "one ACK in {:?}", messages(sent));
    acks[0]
}

fn station(state: FlightState, sticks: Sticks) -> Station {
    let mut s: Status = FlightController::new(&Config::default()).unwrap().status();
    s.state = state;
    s.sticks = sticks;
    let mut st = Station::new(Config::default(), &Config::DEFAULT);
    st.observe(&s, 3900, [0; 4], 0);
    st
}

fn ask(st: &mut Station, cmd: MavCmd, params: [f32; 7]) -> (MavResult, Vec<String>) {
    let mut link = link();
    link.receive(&v2(&command_long(cmd, params)), 0, st);
    let sent = drain(&mut link);
    (ack_of(&sent).1, texts(&sent))
}

const REST: Sticks = Sticks::new(0, 0, 0, 0);
const UP: Sticks = Sticks::new(0, 0, 1500, 0);
const DISARM: [f32; 7] = [0.0; 7];
const FORCED: [f32; 7] = [0.0, FORCE_DISARM, 0.0, 0.0, 0.0, 0.0, 0.0];

#[test]
fn disarm_accepted_on_the_ground_refused_in_the_air_unless_forced() {
    let mut st = station(FlightState::Armed, REST);
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, DISARM).0, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(st.take_gcs().and_then(|g| g.disarm), Some(Disarm { forced: false }));

    let mut st = station(FlightState::Armed, UP);
    let (result, texts) = ask(&mut st, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, DISARM);
    assert_eq!(result, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    assert_eq!(texts.len(), 1);
    assert!(texts[0].contains("21196"), "{texts:?}");
    assert_eq!(st.take_gcs(), None);
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, FORCED).0, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(st.take_gcs().and_then(|g| g.disarm), Some(Disarm { forced: true }));

    // The level stage: refused for now as armed with the throttle up (the stage flies the held
    // throttle), with its rule.
    let mut st = station(FlightState::FailsafeLevel, REST);
    let (result, texts) = ask(&mut st, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, DISARM);
    assert_eq!(result, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    assert_eq!(texts, ["Disarm refused: in failsafe (force 21196)"]);
}

#[test]
fn motor_test_accepted_disarmed_refused_armed_and_while_calibrating() {
    let test = [2.0, 0.0, 50.0, 1.5, 0.0, 0.0, 0.0];
    let mut st = station(FlightState::Disarmed, REST);
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_DO_MOTOR_TEST, test).0, MavResult::MAV_RESULT_ACCEPTED);
    match st.take_gcs().and_then(|g| g.motor_test) {
        Some(MotorTestChange::Start(t)) => {
            assert_eq!((t.motor, t.duty_pct, t.duration_ms), (1, fcu_core::gcs::MOTOR_TEST_MAX_DUTY_PCT, 1500));
        }
        other => panic!("{other:?}"),
    }
    let mut st = station(FlightState::Armed, REST);
    let (result, texts) = ask(&mut st, MavCmd::MAV_CMD_DO_MOTOR_TEST, test);
    // Refused for now, as a calibration, a save and a reboot are while armed.
    assert_eq!((result, texts), (MavResult::MAV_RESULT_TEMPORARILY_REJECTED, vec!["Motor test: disarmed only".to_string()]));
    assert_eq!(st.take_gcs(), None);
    // Which motors there are is the flight controller's rule too.
    let mut st = station(FlightState::Disarmed, REST);
    let (result, texts) = ask(&mut st, MavCmd::MAV_CMD_DO_MOTOR_TEST, [5.0, 0.0, 10.0, 1.0, 0.0, 0.0, 0.0]);
    assert_eq!((result, texts), (MavResult::MAV_RESULT_DENIED, vec!["Motor test: motor must be 1 to 4".to_string()]));
    assert_eq!(st.take_gcs(), None);
    let mut st = station(FlightState::Calibrating, REST);
    let (result, texts) = ask(&mut st, MavCmd::MAV_CMD_DO_MOTOR_TEST, test);
    assert_eq!((result, texts), (MavResult::MAV_RESULT_DENIED, vec!["Motor test: calibrating".to_string()]));
}

#[test]
fn calibrations_accepted_disarmed_refused_otherwise() {
    let imu = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let radio = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
    let mut st = station(FlightState::Disarmed, REST);
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, imu).0, MavResult::MAV_RESULT_ACCEPTED);
    assert!(st.take_gcs().is_some_and(|g| g.calibrate_imu));
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, radio).0, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(st.take_gcs().and_then(|g| g.radio_calibration), Some(true));
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, [0.0; 7]).0, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(st.take_gcs().and_then(|g| g.radio_calibration), Some(false));

    let mut st = station(FlightState::Fault, REST);
    let (result, texts) = ask(&mut st, MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, imu);
    assert_eq!((result, texts), (MavResult::MAV_RESULT_DENIED, vec!["Calibration refused: fault or failsafe".to_string()]));
    let mut st = station(FlightState::Armed, REST);
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, radio).0, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    assert_eq!(st.take_gcs(), None);
}

#[test]
fn arming_from_the_link_is_refused_with_the_flight_controllers_rule() {
    for state in [FlightState::Disarmed, FlightState::Armed] {
        let mut st = station(state, REST);
        let (result, texts) = ask(&mut st, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [1.0, FORCE_DISARM, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!((result, texts), (MavResult::MAV_RESULT_DENIED, vec!["Arm refused: arm with the stick gesture".to_string()]));
        assert_eq!(st.take_gcs(), None);
    }
}

#[test]
fn storage_and_reboot_accepted_disarmed_refused_for_now_armed() {
    let save = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let reset = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let reboot = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut st = station(FlightState::Disarmed, REST);
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_PREFLIGHT_STORAGE, save).0, MavResult::MAV_RESULT_ACCEPTED);
    assert!(st.unsaved());
    let mut st = station(FlightState::Disarmed, REST);
    assert_eq!(ask(&mut st, MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, reboot).0, MavResult::MAV_RESULT_ACCEPTED);
    assert!(st.reboot_asked());
    for state in [FlightState::Arming, FlightState::Armed, FlightState::FailsafeLevel] {
        let mut st = station(state, REST);
        for (cmd, params, what) in [
            (MavCmd::MAV_CMD_PREFLIGHT_STORAGE, save, "Storage"),
            (MavCmd::MAV_CMD_PREFLIGHT_STORAGE, reset, "Storage"),
            (MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, reboot, "Reboot"),
        ] {
            let (result, texts) = ask(&mut st, cmd, params);
            assert_eq!(result, MavResult::MAV_RESULT_TEMPORARILY_REJECTED, "{state:?} {cmd:?}");
            assert_eq!(texts, [format!("{what} refused: disarmed only")]);
        }
        assert!(!st.unsaved() && !st.reboot_asked(), "{state:?}");
        assert_eq!(st.take_change(), None, "{state:?}: a reset refused changes nothing");
    }
}

#[test]
fn whatever_the_flight_controller_refuses_the_link_cannot_carry_out() {
    // Every command the link decodes, in every state: refused by the station (fcu-core's rules),
    // the link sends it nowhere: no input for the tick, no configuration change, no save, no
    // reboot (the link decides nothing, so it has nothing to let through on its own).
    let commands: [(MavCmd, [f32; 7]); 9] = [
        (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, DISARM),
        (MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        (MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
        (MavCmd::MAV_CMD_PREFLIGHT_STORAGE, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        (MavCmd::MAV_CMD_PREFLIGHT_STORAGE, [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        (MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        (MavCmd::MAV_CMD_DO_MOTOR_TEST, [1.0, 0.0, 10.0, 1.0, 0.0, 0.0, 0.0]),
        (MavCmd::MAV_CMD_DO_MOTOR_TEST, [5.0, 0.0, 10.0, 1.0, 0.0, 0.0, 0.0]),
    ];
    let mut refused = 0;
    for state in FlightState::ALL {
        for sticks in [REST, UP] {
            for (cmd, params) in commands {
                let mut st = station(state, sticks);
                // Differs from the defaults, for a reset to change.
                let i = parameters::index_of(b"ANGLE_MAX").unwrap() as u16;
                let _ = st.set_param(i, 25.0);
                let _ = st.take_change();
                let mut link = link();
                link.receive(&v2(&command_long(cmd, params)), 0, &mut st);
                let sent = drain(&mut link);
                if ack_of(&sent).1 == MavResult::MAV_RESULT_ACCEPTED {
                    continue;
                }
                refused += 1;
                let what = format!("{state:?} {sticks:?} {cmd:?} {params:?}");
                assert_eq!(st.take_gcs(), None, "{what}");
                assert_eq!(st.take_change(), None, "{what}");
                assert!(!st.reboot_asked() && !link.reboot_ready(), "{what}");
                assert_eq!(texts(&sent).len(), 1, "{what}: the rule named");
            }
        }
    }
    assert!(refused > 40, "{refused} refusals: the states must refuse most of these");
}

/// Telemetry off but for a heartbeat a minute apart: what goes out is the answers.
fn quiet_link() -> Link<512> {
    let rates = Rates {
        attitude_ms: 0,
        sys_status_ms: 0,
        battery_ms: 0,
        rc_channels_ms: 0,
        servo_output_ms: 0,
        vfr_hud_ms: 0,
        altitude_ms: 0,
        scaled_pressure_ms: 0,
        heartbeat_ms: 60_000,
        param_ms: 10,
    };
    Link::new(LinkConfig { rates, ..LinkConfig::DEFAULT })
}

fn booted_station() -> Station {
    Station::new(Config::default(), &Config::DEFAULT)
}

fn index(name: &str) -> usize {
    parameters::index_of(name.as_bytes()).unwrap()
}

const RCMAP: [&str; 4] = ["RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW"];

/// The ground station's copy of the table, from a download, as it shows and saves it.
fn downloaded(st: &Station) -> Vec<f32> {
    (0..st.param_count()).map(|i| st.param(i).unwrap().value).collect()
}

fn apply(copy: &mut [f32], sent: &[Sent]) {
    for (_, value, index, _) in param_values(sent) {
        copy[usize::from(index)] = value;
    }
}

#[test]
fn a_param_set_that_changes_other_parameters_reports_them_too() {
    let mut link = quiet_link();
    let mut st = booted_station();
    let mut copy = downloaded(&st);
    let before: Vec<f32> = RCMAP.iter().map(|n| copy[index(n)]).collect();
    assert_eq!(before, [1.0, 2.0, 3.0, 4.0]);
    link.receive(&v2(&param_set("RCMAP_ROLL", 3.0)), 0, &mut st);
    let sent = drain(&mut link);
    let echoed: Vec<(String, f32)> = param_values(&sent).into_iter().map(|p| (p.0, p.1)).collect();
    // The one set first, then the one it swapped with.
    assert_eq!(echoed, [("RCMAP_ROLL".to_string(), 3.0), ("RCMAP_THROTTLE".to_string(), 1.0)]);
    apply(&mut copy, &sent);
    assert_eq!(copy, downloaded(&st), "the ground station's copy is the board's table");
    let mut map: Vec<f32> = RCMAP.iter().map(|n| copy[index(n)]).collect();
    map.sort_by(f32::total_cmp);
    assert_eq!(map, [1.0, 2.0, 3.0, 4.0], "a permutation");
}

#[test]
fn param_values_a_set_owes_go_out_on_the_next_tick_when_the_queue_is_full() {
    // A STATUSTEXT of 50 bytes is a 63-byte frame, of 10 bytes a 23-byte one; answers may
    // fill the queue up to its size less the telemetry's reserve (341 bytes: 512 - 21 for the
    // heartbeat - 341 leaves 150 for texts and answers, a PARAM_VALUE is 37).
    assert_eq!(fcu_link::TELEMETRY_RESERVE, 341);
    let fifty = [b'x'; 50];
    for (texts, sent_at_once) in [(&[&fifty[..], &fifty][..], 0), (&[&fifty[..], b"0123456789"][..], 1)] {
        let mut link = quiet_link();
        let mut st = booted_station();
        link.tick(0, &mut st);
        for text in texts {
            assert!(link.send_text(Severity::Info, text));
        }
        let mut copy = downloaded(&st);
        link.receive(&v2(&param_set("RCMAP_ROLL", 3.0)), 1, &mut st);
        let at_once = drain(&mut link);
        assert_eq!(param_values(&at_once).len(), sent_at_once);
        link.tick(2, &mut st);
        let later = drain(&mut link);
        let names: Vec<String> = param_values(&at_once).into_iter().chain(param_values(&later)).map(|p| p.0).collect();
        assert_eq!(names, ["RCMAP_ROLL", "RCMAP_THROTTLE"]);
        apply(&mut copy, &at_once);
        apply(&mut copy, &later);
        assert_eq!(copy, downloaded(&st));
        let stats = link.stats();
        assert_eq!((stats.tx_dropped, stats.answers_dropped), (0, 0), "nothing lost");
    }
}

/// What a ground station hears back of pymavlink's `set_mode` (a DO_SET_MODE with ArduCopter's
/// mode number): with `ALT_MODE` in the table, the ACK and the parameter's PARAM_VALUE; without
/// it, a named refusal.
#[test]
fn a_set_mode_sets_alt_mode_by_name_or_is_refused_by_name() {
    const ALT_HOLD: [f32; 7] = [1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut st = station(FlightState::Disarmed, REST);
    let mut link = link();
    link.receive(&v2(&command_long(MavCmd::MAV_CMD_DO_SET_MODE, ALT_HOLD)), 0, &mut st);
    let sent = drain(&mut link);
    match parameters::index_of(fcu_gcs::station::ALT_MODE) {
        None => {
            assert_eq!(ack_of(&sent), (MavCmd::MAV_CMD_DO_SET_MODE as u16, MavResult::MAV_RESULT_DENIED));
            assert_eq!(texts(&sent), [format!("Mode refused: {}", fcu_core::gcs::RULE_NO_ALTITUDE_HOLD)]);
            assert!(param_values(&sent).is_empty());
            assert!(!st.unsaved());
        }
        Some(i) => {
            assert_eq!(ack_of(&sent), (MavCmd::MAV_CMD_DO_SET_MODE as u16, MavResult::MAV_RESULT_ACCEPTED));
            let values = param_values(&sent);
            assert_eq!(values.len(), 1, "{values:?}");
            assert_eq!((values[0].0.as_str(), values[0].1, usize::from(values[0].2)), ("ALT_MODE", 1.0, i));
            assert!(st.unsaved(), "saved after the debounce, as a PARAM_SET");
        }
    }
}
