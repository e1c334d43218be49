//! What a ground station sees of the height (VFR_HUD, ALTITUDE, SCALED_PRESSURE, HEARTBEAT's
//! vertical mode) and the set-mode it may send (SET_MODE, DO_SET_MODE). Frames in are built by
//! the `mavlink` crate and frames out are checked and parsed by it.

mod support;

use fcu_link::{AltMode, Link, LinkConfig, Refused, Request, VerticalMode};
use mavlink::dialects::common::{self as common, MavCmd, MavMessage, MavModeFlag, MavResult};
use mavlink::{Message, MessageData};
use support::*;

fn link() -> TestLink {
    Link::new(LinkConfig::DEFAULT)
}

/// Feeds a frame at `now_ms` and returns what the link answered.
fn exchange(link: &mut TestLink, mock: &mut Mock, frame: &[u8], now_ms: u32) -> Vec<Sent> {
    drain(link);
    link.receive(frame, now_ms, mock);
    drain(link)
}

/// The messages one tick at `now_ms` sends.
fn tick(link: &mut TestLink, mock: &mut Mock, now_ms: u32) -> Vec<MavMessage> {
    link.tick(now_ms, mock);
    messages(&drain(link))
}

fn vfr_hud(sent: &[MavMessage]) -> Option<common::VFR_HUD_DATA> {
    sent.iter().find_map(|m| match m {
        MavMessage::VFR_HUD(v) => Some(v.clone()),
        _ => None,
    })
}

fn altitude(sent: &[MavMessage]) -> Option<common::ALTITUDE_DATA> {
    sent.iter().find_map(|m| match m {
        MavMessage::ALTITUDE(a) => Some(a.clone()),
        _ => None,
    })
}

fn scaled_pressure(sent: &[MavMessage]) -> Option<common::SCALED_PRESSURE_DATA> {
    sent.iter().find_map(|m| match m {
        MavMessage::SCALED_PRESSURE(p) => Some(p.clone()),
        _ => None,
    })
}

#[test]
fn vfr_hud_carries_the_height_climb_throttle_and_heading() {
    let mut link = link();
    let mut mock = Mock::new();
    let v = vfr_hud(&tick(&mut link, &mut mock, 0)).unwrap();
    assert_eq!((v.alt, v.climb), (1.25, -0.5));
    // The mock's motors at 1000, 1100, 1200, 1300: a mean of 1150 on the 1000–2000 scale.
    assert_eq!(v.throttle, 15);
    // Yaw 1.5 rad, clockwise from the boot heading.
    assert_eq!(v.heading, 86);
    assert_eq!((v.airspeed, v.groundspeed), (0.0, 0.0), "not measured");
}

#[test]
fn vfr_hud_heading_is_0_to_359_and_throttle_0_to_100() {
    use std::f32::consts::{PI, TAU};
    for (yaw_rad, heading) in [(-0.01f32, 359), (-PI, 180), (0.0, 0), (TAU, 0), (-0.0087, 0), (f32::NAN, 0)] {
        let mut link = link();
        let mut mock = Mock::new();
        mock.state.attitude.yaw_rad = yaw_rad;
        assert_eq!(vfr_hud(&tick(&mut link, &mut mock, 0)).unwrap().heading, heading, "{yaw_rad}");
    }
    for (outputs, throttle) in [([1000; 4], 0), ([2000; 4], 100), ([900, 900, 900, 900], 0), ([2100; 4], 100), ([1500; 4], 50)] {
        let mut link = link();
        let mut mock = Mock::new();
        mock.state.motor_outputs_us = outputs;
        assert_eq!(vfr_hud(&tick(&mut link, &mut mock, 0)).unwrap().throttle, throttle, "{outputs:?}");
    }
}

#[test]
fn altitude_carries_the_height_above_take_off_and_nan_or_the_spec_markers_for_the_rest() {
    let mut link = link();
    let mut mock = Mock::new();
    let a = altitude(&tick(&mut link, &mut mock, 1234)).unwrap();
    assert_eq!(a.time_usec, 1_234_000);
    assert_eq!((a.altitude_relative, a.altitude_local), (1.25, 1.25));
    assert!(a.altitude_monotonic.is_nan() && a.altitude_amsl.is_nan());
    assert!(a.altitude_terrain < -1000.0, "the spec's unknown terrain");
    assert!(a.bottom_clearance < 0.0, "the spec's no measurement");
}

#[test]
fn an_unknown_height_is_nan_not_zero() {
    let mut link = link();
    let mut mock = Mock::new();
    mock.state.altitude.height_m = None;
    mock.state.altitude.climb_m_s = None;
    let sent = tick(&mut link, &mut mock, 0);
    let v = vfr_hud(&sent).unwrap();
    assert!(v.alt.is_nan() && v.climb.is_nan());
    let a = altitude(&sent).unwrap();
    assert!(a.altitude_relative.is_nan() && a.altitude_local.is_nan());
}

#[test]
fn scaled_pressure_carries_the_last_sample_in_hpa_and_cdegc() {
    let mut link = link();
    let mut mock = Mock::new();
    let p = scaled_pressure(&tick(&mut link, &mut mock, 700)).unwrap();
    assert_eq!((p.time_boot_ms, p.press_abs, p.press_diff, p.temperature), (700, 1010.0, 0.0, 2450));
}

#[test]
fn scaled_pressure_is_not_sent_before_the_first_sample_then_at_its_rate() {
    let mut link = link();
    let mut mock = Mock::new();
    mock.state.altitude.pressure_pa = None;
    let mut count = 0;
    for now in 0..2000 {
        count += tick(&mut link, &mut mock, now).iter().filter(|m| matches!(m, MavMessage::SCALED_PRESSURE(_))).count();
    }
    assert_eq!(count, 0, "no pressure: no message, rather than a zero");
    mock.state.altitude.pressure_pa = Some(99_000.0);
    let mut times = Vec::new();
    for now in 2000..4000 {
        if scaled_pressure(&tick(&mut link, &mut mock, now)).is_some() {
            times.push(now);
        }
    }
    assert_eq!(times, [2000, 2500, 3000, 3500], "the first sample at once, then every 500 ms");
}

#[test]
fn heartbeat_says_the_vertical_mode_above_the_flight_state() {
    for mode in VerticalMode::ALL {
        let mut link = link();
        let mut mock = Mock::new();
        mock.state.altitude.mode = mode;
        let hb = tick(&mut link, &mut mock, 0)
            .into_iter()
            .find_map(|m| match m {
                MavMessage::HEARTBEAT(h) => Some(h),
                _ => None,
            })
            .unwrap();
        assert_eq!(hb.custom_mode, 1 | u32::from(mode.number()) << 8, "{mode:?}");
        assert!(!hb.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED));
    }
}

/// A COMMAND_LONG DO_SET_MODE as pymavlink's `set_mode` and MAVProxy's `mode` send it.
fn do_set_mode(base_mode: f32, custom_mode: f32) -> Vec<u8> {
    v2(&command_long(MavCmd::MAV_CMD_DO_SET_MODE, [base_mode, custom_mode, 0.0, 0.0, 0.0, 0.0, 0.0]))
}

const CUSTOM: f32 = 1.0;

#[test]
fn do_set_mode_names_manual_or_altitude_hold_by_arducopters_numbers() {
    for (custom_mode, mode) in [(2.0, AltMode::Hold), (0.0, AltMode::Manual)] {
        let mut link = link();
        let mut mock = Mock::new();
        mock.mode_param = Some(2);
        // The base mode as ground stations send it: the custom-mode flag, maybe others.
        for base_mode in [CUSTOM, CUSTOM + 128.0 + 64.0 + 16.0] {
            let sent = exchange(&mut link, &mut mock, &do_set_mode(base_mode, custom_mode), 0);
            assert_eq!(acks(&sent), [(MavCmd::MAV_CMD_DO_SET_MODE as u16, MavResult::MAV_RESULT_ACCEPTED)]);
            assert_eq!(mock.requests.pop(), Some(Request::SetMode(mode)));
            // The ACK first, then the parameter the set-mode set.
            let ids: Vec<u32> = sent.iter().map(|s| s.message.message_id()).collect();
            assert_eq!(ids, [common::COMMAND_ACK_DATA::ID, common::PARAM_VALUE_DATA::ID]);
            assert_eq!(param_values(&sent)[0].0, "ANGLE_MAX_DEG");
        }
    }
}

#[test]
fn command_int_do_set_mode_is_taken_as_the_long_one() {
    let mut link = link();
    let mut mock = Mock::new();
    let command = common::COMMAND_INT_DATA {
        param1: CUSTOM,
        param2: 2.0,
        command: MavCmd::MAV_CMD_DO_SET_MODE,
        target_system: 1,
        target_component: 1,
        ..common::COMMAND_INT_DATA::DEFAULT
    };
    let sent = exchange(&mut link, &mut mock, &v2(&command), 0);
    assert_eq!(acks(&sent), [(MavCmd::MAV_CMD_DO_SET_MODE as u16, MavResult::MAV_RESULT_ACCEPTED)]);
    assert_eq!(mock.requests, [Request::SetMode(AltMode::Hold)]);
}

#[test]
fn a_set_mode_naming_no_mode_a_ground_station_may_ask_for_is_denied_unasked() {
    for (base_mode, custom_mode) in [
        // ArduCopter's ACRO, AUTO; the failsafe's descent (LAND) is shown, never asked for.
        (CUSTOM, 1.0),
        (CUSTOM, 3.0),
        (CUSTOM, 9.0),
        // Not whole, negative, not a number, past u32, our HEARTBEAT's whole field.
        (CUSTOM, 2.5),
        (CUSTOM, -2.0),
        (CUSTOM, f32::NAN),
        (CUSTOM, 1e12),
        (CUSTOM, 0x0203 as f32),
        // A base mode alone (MAV_MODE_STABILIZE_ARMED), or one that is no byte.
        (208.0, 2.0),
        (0.0, 0.0),
        (1.5, 2.0),
        (257.0, 2.0),
        (f32::NAN, 2.0),
    ] {
        let mut link = link();
        let mut mock = Mock::new();
        let sent = exchange(&mut link, &mut mock, &do_set_mode(base_mode, custom_mode), 0);
        assert_eq!(acks(&sent), [(MavCmd::MAV_CMD_DO_SET_MODE as u16, MavResult::MAV_RESULT_DENIED)], "{base_mode} {custom_mode}");
        assert_eq!(texts(&sent), ["Mode refused: 0 (STABILIZE) or 2 (ALT_HOLD) only"], "{base_mode} {custom_mode}");
        assert!(mock.requests.is_empty(), "{base_mode} {custom_mode}");
    }
}

#[test]
fn the_vehicles_refusal_of_a_set_mode_is_answered_with_its_rule() {
    for (refused, result) in [
        (Refused::for_now("only while disarmed"), MavResult::MAV_RESULT_TEMPORARILY_REJECTED),
        (Refused::denied("no altitude hold on this board"), MavResult::MAV_RESULT_DENIED),
    ] {
        let mut link = link();
        let mut mock = Mock::new();
        mock.refuse_requests = Some(refused);
        mock.mode_param = Some(2);
        let sent = exchange(&mut link, &mut mock, &do_set_mode(CUSTOM, 2.0), 0);
        assert_eq!(acks(&sent), [(MavCmd::MAV_CMD_DO_SET_MODE as u16, result)]);
        assert_eq!(texts(&sent), [format!("Mode refused: {}", refused.rule)]);
        assert!(param_values(&sent).is_empty(), "nothing was set");
    }
}

#[allow(deprecated)]
const SET_MODE_ID: u32 = common::SET_MODE_DATA::ID;
#[allow(deprecated)]
const SET_MODE_EXTRA_CRC: u8 = common::SET_MODE_DATA::EXTRA_CRC;

/// A SET_MODE frame, built byte by byte (the crate marks the message deprecated).
fn set_mode(target_system: u8, base_mode: u8, custom_mode: u32) -> Vec<u8> {
    let mut payload = custom_mode.to_le_bytes().to_vec();
    payload.extend_from_slice(&[target_system, base_mode]);
    v2_raw(SET_MODE_ID, SET_MODE_EXTRA_CRC, &payload)
}

#[test]
fn set_mode_is_taken_as_do_set_mode_and_acked_with_its_message_id() {
    let mut link = link();
    let mut mock = Mock::new();
    mock.mode_param = Some(2);
    let sent = exchange(&mut link, &mut mock, &set_mode(1, 1, 2), 0);
    assert_eq!(acks(&sent), [(11, MavResult::MAV_RESULT_ACCEPTED)]);
    assert_eq!(mock.requests, [Request::SetMode(AltMode::Hold)]);
    assert_eq!(param_values(&sent).len(), 1);
    // Answered to its sender.
    let ack = sent.iter().find(|s| s.message.message_id() == common::COMMAND_ACK_DATA::ID).unwrap();
    assert_eq!(&ack.payload[8..10], &[GCS_SYSTEM, GCS_COMPONENT]);

    let sent = exchange(&mut link, &mut mock, &set_mode(1, 1, 5), 0);
    assert_eq!(acks(&sent), [(11, MavResult::MAV_RESULT_DENIED)]);
    let sent = exchange(&mut link, &mut mock, &set_mode(0, 1, 0), 0);
    assert_eq!(acks(&sent), [(11, MavResult::MAV_RESULT_ACCEPTED)], "to every system");
    assert_eq!(mock.requests.last(), Some(&Request::SetMode(AltMode::Manual)));
}

#[test]
fn set_mode_for_another_system_is_ignored_and_counted() {
    let mut link = link();
    let mut mock = Mock::new();
    assert!(exchange(&mut link, &mut mock, &set_mode(2, 1, 2), 0).is_empty());
    assert_eq!(link.stats().not_for_us, 1);
    assert!(mock.requests.is_empty());
}

#[test]
fn a_short_set_mode_is_zero_padded_as_mavlink_2_drops_trailing_zeros() {
    let mut link = link();
    let mut mock = Mock::new();
    // custom_mode 0 with target 1 and base mode 1: nothing to drop; custom mode 2 with
    // target 0 and base mode 0 loses its last two bytes, and is denied for the base mode.
    let sent = exchange(&mut link, &mut mock, &v2_raw(SET_MODE_ID, SET_MODE_EXTRA_CRC, &[2, 0, 0, 0]), 0);
    assert_eq!(acks(&sent), [(11, MavResult::MAV_RESULT_DENIED)]);
    assert!(mock.requests.is_empty());
}
