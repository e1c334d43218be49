//! The link's rules, each with a test that fails when the rule breaks. Frames in are built by
//! the `mavlink` crate and frames out are checked and parsed by it.

mod support;

use fcu_core::supervisor::FlightState;
use fcu_link::command::FORCE_DISARM;
use fcu_link::{Link, LinkConfig, Rates, Refused, Request, Severity};
use mavlink::dialects::common::{
    self as common, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavProtocolCapability, MavResult, MavState, MavType,
};
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

fn command(link: &mut TestLink, mock: &mut Mock, cmd: MavCmd, params: [f32; 7]) -> Vec<Sent> {
    exchange(link, mock, &v2(&command_long(cmd, params)), 0)
}

fn ack_of(sent: &[Sent]) -> (u16, MavResult) {
    let acks = acks(sent);
    assert_eq!(acks.len(), 1, "one ACK in {:?}", messages(sent));
    acks[0]
}

#[test]
fn heartbeat_says_who_we_are_and_whether_armed() {
    let mut link = link();
    let mut mock = Mock::new();
    link.tick(0, &mut mock);
    let sent = drain(&mut link);
    let hb = sent
        .iter()
        .find_map(|s| match &s.message {
            MavMessage::HEARTBEAT(h) => Some((s.system_id, s.component_id, h.clone())),
            _ => None,
        })
        .expect("a heartbeat at the first tick");
    assert_eq!((hb.0, hb.1), (1, 1));
    assert_eq!(hb.2.mavtype, MavType::MAV_TYPE_QUADROTOR);
    assert_eq!(hb.2.autopilot, MavAutopilot::MAV_AUTOPILOT_GENERIC);
    assert_eq!(hb.2.system_status, MavState::MAV_STATE_STANDBY);
    assert!(!hb.2.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED));

    for (state, armed, expected) in [
        (FlightState::Armed, true, MavState::MAV_STATE_ACTIVE),
        (FlightState::FailsafeLevel, true, MavState::MAV_STATE_CRITICAL),
        (FlightState::Calibrating, false, MavState::MAV_STATE_BOOT),
    ] {
        let mut link = self::link();
        mock.state.state = state;
        link.tick(0, &mut mock);
        let hb = drain(&mut link)
            .into_iter()
            .find_map(|s| match s.message {
                MavMessage::HEARTBEAT(h) => Some(h),
                _ => None,
            })
            .unwrap();
        assert_eq!(hb.system_status, expected);
        assert_eq!(hb.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED), armed);
        assert_eq!(fcu_link::heartbeat::flight_state(&hb), state, "read back exactly");
        assert_eq!(fcu_link::heartbeat::vertical_mode(&hb), Some(mock.state.altitude.mode), "read back exactly");
    }
}

#[test]
fn telemetry_runs_at_its_rates() {
    let mut link = link();
    let mut mock = Mock::new();
    let mut counts = std::collections::BTreeMap::new();
    for now in 0..2000 {
        link.tick(now, &mut mock);
        for s in drain(&mut link) {
            *counts.entry(s.message.message_name()).or_insert(0) += 1;
        }
    }
    assert_eq!(counts.get("HEARTBEAT"), Some(&2));
    assert_eq!(counts.get("ATTITUDE"), Some(&50));
    assert_eq!(counts.get("SYS_STATUS"), Some(&2));
    assert_eq!(counts.get("BATTERY_STATUS"), Some(&2));
    assert_eq!(counts.get("RC_CHANNELS"), Some(&20));
    assert_eq!(counts.get("SERVO_OUTPUT_RAW"), Some(&20));
    assert_eq!(counts.get("VFR_HUD"), Some(&20));
    assert_eq!(counts.get("ALTITUDE"), Some(&10));
    assert_eq!(counts.get("SCALED_PRESSURE"), Some(&4));
    assert_eq!(counts.len(), 9, "{counts:?}");
}

#[test]
fn rates_are_configurable_and_zero_turns_a_stream_off() {
    let mut link = link();
    let mut mock = Mock::new();
    link.set_rates(Rates { attitude_ms: 10, rc_channels_ms: 0, heartbeat_ms: 0, ..Rates::DEFAULT });
    let mut attitude = 0;
    let mut rc = 0;
    let mut heartbeat = 0;
    for now in 0..1000 {
        link.tick(now, &mut mock);
        for s in drain(&mut link) {
            match s.message {
                MavMessage::ATTITUDE(_) => attitude += 1,
                MavMessage::RC_CHANNELS(_) => rc += 1,
                MavMessage::HEARTBEAT(_) => heartbeat += 1,
                _ => {}
            }
        }
    }
    assert_eq!((attitude, rc), (100, 0));
    assert_eq!(heartbeat, 1, "a heartbeat cannot be turned off");
}

#[test]
fn default_rates_leave_most_of_115200_baud_free() {
    let budget = Rates::DEFAULT.budget_bytes_per_s();
    assert!(budget * 10 < fcu_link::rates::UART_BYTES_PER_S * 6, "{budget} B/s");
    // The table in the rates module's docs.
    assert_eq!(budget, 21 + 1000 + 43 + 48 + 540 + 330 + 320 + 220 + 52 + 3700);
}

#[test]
fn telemetry_carries_the_vehicle_state() {
    let mut link = link();
    let mut mock = Mock::new();
    link.tick(1234, &mut mock);
    let sent = messages(&drain(&mut link));
    let mut seen = 0;
    for m in sent {
        match m {
            MavMessage::ATTITUDE(a) => {
                assert_eq!((a.time_boot_ms, a.roll, a.pitch, a.yaw), (1234, 0.1, -0.2, 1.5));
                assert_eq!((a.rollspeed, a.pitchspeed, a.yawspeed), (0.01, 0.02, 0.03));
                seen += 1;
            }
            MavMessage::RC_CHANNELS(r) => {
                assert_eq!(r.chancount, 6);
                assert_eq!([r.chan1_raw, r.chan3_raw, r.chan6_raw, r.chan7_raw, r.chan18_raw], [1500, 1000, 2000, u16::MAX, u16::MAX]);
                seen += 1;
            }
            MavMessage::SERVO_OUTPUT_RAW(s) => {
                assert_eq!([s.servo1_raw, s.servo2_raw, s.servo3_raw, s.servo4_raw], [1000, 1100, 1200, 1300]);
                seen += 1;
            }
            MavMessage::BATTERY_STATUS(b) => {
                assert_eq!((b.voltages[0], b.voltages[1], b.battery_remaining), (3900, u16::MAX, 70));
                seen += 1;
            }
            MavMessage::SYS_STATUS(s) => {
                assert_eq!((s.voltage_battery, s.load, s.battery_remaining), (3900, 420, 70));
                use common::MavSysStatusSensor as S;
                assert!(s.onboard_control_sensors_present.contains(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER));
                assert!(s.onboard_control_sensors_health.contains(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER));
                // No fence, and none breached: ground stations read a clear health bit as a
                // breach.
                assert!(!s.onboard_control_sensors_present.contains(S::MAV_SYS_STATUS_GEOFENCE));
                assert!(s.onboard_control_sensors_health.contains(S::MAV_SYS_STATUS_GEOFENCE));
                seen += 1;
            }
            _ => {}
        }
    }
    assert_eq!(seen, 5);
    mock.state.health.radio = false;
    mock.state.health.imu = false;
    link.tick(2234, &mut mock);
    let sys = messages(&drain(&mut link))
        .into_iter()
        .find_map(|m| match m {
            MavMessage::SYS_STATUS(s) => Some(s),
            _ => None,
        })
        .unwrap();
    use common::MavSysStatusSensor as S;
    assert!(!sys.onboard_control_sensors_health.contains(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER));
    assert!(!sys.onboard_control_sensors_health.contains(S::MAV_SYS_STATUS_SENSOR_3D_GYRO));
    assert!(sys.onboard_control_sensors_health.contains(S::MAV_SYS_STATUS_AHRS));
}

#[test]
fn sys_status_carries_the_pre_arm_check() {
    use common::MavSysStatusSensor as S;
    let mut link = link();
    let mut mock = Mock::new();
    let mut sys_status = |mock: &mut Mock, now: u32| {
        link.tick(now, mock);
        messages(&drain(&mut link)).into_iter().find_map(|m| match m {
            MavMessage::SYS_STATUS(s) => Some(s),
            _ => None,
        })
    };
    let ready = sys_status(&mut mock, 0).unwrap();
    assert!(ready.onboard_control_sensors_present.contains(S::MAV_SYS_STATUS_PREARM_CHECK));
    assert!(ready.onboard_control_sensors_health.contains(S::MAV_SYS_STATUS_PREARM_CHECK));
    mock.state.health.prearm = false;
    let blocked = sys_status(&mut mock, 5000).unwrap();
    assert!(blocked.onboard_control_sensors_enabled.contains(S::MAV_SYS_STATUS_PREARM_CHECK));
    assert!(!blocked.onboard_control_sensors_health.contains(S::MAV_SYS_STATUS_PREARM_CHECK));
}

#[test]
fn sequence_numbers_count_up_and_wrap() {
    let mut link = link();
    let mut mock = Mock::new();
    let mut seqs = Vec::new();
    for now in 0..6000 {
        link.tick(now, &mut mock);
        seqs.extend(drain(&mut link).iter().map(|s| s.sequence));
    }
    assert!(seqs.len() > 256);
    for w in seqs.windows(2) {
        assert_eq!(w[1], w[0].wrapping_add(1));
    }
}

#[test]
fn param_request_list_sends_every_param_value_paced() {
    let mut link = link();
    let mut mock = Mock::new();
    let request = common::PARAM_REQUEST_LIST_DATA { target_system: 1, target_component: 1 };
    link.receive(&v2(&request), 0, &mut mock);
    link.set_rates(Rates {
        attitude_ms: 0,
        heartbeat_ms: 60_000,
        sys_status_ms: 0,
        battery_ms: 0,
        rc_channels_ms: 0,
        servo_output_ms: 0,
        vfr_hud_ms: 0,
        altitude_ms: 0,
        scaled_pressure_ms: 0,
        param_ms: 10,
    });
    let mut got = Vec::new();
    for now in 0..100 {
        link.tick(now, &mut mock);
        for p in param_values(&drain(&mut link)) {
            got.push((now, p));
        }
    }
    let names: Vec<_> = got.iter().map(|(_, p)| p.0.as_str()).collect();
    assert_eq!(names, ["RCMAP_ROLL", "RC1_MIN", "ANGLE_MAX_DEG", "RATE_ROLL_P_GAIN"]);
    for (i, (_, p)) in got.iter().enumerate() {
        assert_eq!((p.2, p.3), (i as u16, 4));
    }
    let times: Vec<_> = got.iter().map(|(t, _)| *t).collect();
    assert_eq!(times, [0, 10, 20, 30], "one PARAM_VALUE per param_ms");
}

#[test]
fn a_download_waits_for_room_instead_of_dropping() {
    let mut link: Link<64> = Link::new(LinkConfig {
        rates: Rates {
            attitude_ms: 0,
            sys_status_ms: 0,
            battery_ms: 0,
            rc_channels_ms: 0,
            servo_output_ms: 0,
            vfr_hud_ms: 0,
            altitude_ms: 0,
            scaled_pressure_ms: 0,
            heartbeat_ms: 60_000,
            param_ms: 1,
        },
        ..LinkConfig::DEFAULT
    });
    let mut mock = Mock::new();
    link.tick(0, &mut mock);
    let mut buf = [0u8; 64];
    link.poll_tx(&mut buf);
    let request = common::PARAM_REQUEST_LIST_DATA { target_system: 0, target_component: 0 };
    link.receive(&v2(&request), 1, &mut mock);
    // Nobody drains: the queue holds one PARAM_VALUE, the others wait.
    for now in 1..50 {
        link.tick(now, &mut mock);
    }
    assert_eq!(link.stats().tx_dropped, 0);
    let mut bytes = Vec::new();
    for now in 50..100 {
        link.tick(now, &mut mock);
        let n = link.poll_tx(&mut buf);
        bytes.extend_from_slice(&buf[..n]);
    }
    let names: Vec<_> = param_values(&decode_all(&bytes)).into_iter().map(|p| p.0).collect();
    assert_eq!(names, ["RCMAP_ROLL", "RC1_MIN", "ANGLE_MAX_DEG", "RATE_ROLL_P_GAIN"]);
}

#[test]
fn param_request_read_by_index_and_by_name() {
    let mut link = link();
    let mut mock = Mock::new();
    let by_index = common::PARAM_REQUEST_READ_DATA { param_index: 2, target_system: 1, target_component: 1, param_id: name16("") };
    let sent = param_values(&exchange(&mut link, &mut mock, &v2(&by_index), 0));
    assert_eq!(sent, [("ANGLE_MAX_DEG".to_string(), 30.0, 2, 4)]);

    let by_name =
        common::PARAM_REQUEST_READ_DATA { param_index: -1, target_system: 1, target_component: 1, param_id: name16("RATE_ROLL_P_GAIN") };
    let sent = param_values(&exchange(&mut link, &mut mock, &v2(&by_name), 0));
    assert_eq!(sent, [("RATE_ROLL_P_GAIN".to_string(), 0.5, 3, 4)]);

    for unknown in [
        common::PARAM_REQUEST_READ_DATA { param_index: 4, target_system: 1, target_component: 1, param_id: name16("") },
        common::PARAM_REQUEST_READ_DATA { param_index: -1, target_system: 1, target_component: 1, param_id: name16("NOPE") },
    ] {
        assert!(exchange(&mut link, &mut mock, &v2(&unknown), 0).is_empty());
    }
    assert_eq!(link.stats().param_unknown, 2);
}

#[test]
fn param_set_taken_is_echoed_with_the_new_value() {
    let mut link = link();
    let mut mock = Mock::new();
    let sent = exchange(&mut link, &mut mock, &v2(&param_set("RC1_MIN", 1100.0)), 0);
    assert_eq!(param_values(&sent), [("RC1_MIN".to_string(), 1100.0, 1, 4)]);
    assert!(texts(&sent).is_empty());
    assert_eq!(mock.sets, [(1, 1100.0)]);
    // A 16-character name, sent without its NUL.
    let sent = exchange(&mut link, &mut mock, &v2(&param_set("RATE_ROLL_P_GAIN", 0.75)), 0);
    assert_eq!(param_values(&sent), [("RATE_ROLL_P_GAIN".to_string(), 0.75, 3, 4)]);
    // MAVLink 1 too (pymavlink starts there).
    let sent = exchange(&mut link, &mut mock, &v1(&param_set("ANGLE_MAX_DEG", 45.0)), 0);
    assert_eq!(param_values(&sent), [("ANGLE_MAX_DEG".to_string(), 45.0, 2, 4)]);
}

#[test]
fn param_set_refused_is_echoed_with_the_old_value_and_the_rule() {
    let mut link = link();
    let mut mock = Mock::new();
    let sent = exchange(&mut link, &mut mock, &v2(&param_set("RC1_MIN", 5000.0)), 0);
    assert_eq!(param_values(&sent), [("RC1_MIN".to_string(), 1000.0, 1, 4)]);
    assert_eq!(texts(&sent), ["RC1_MIN: out of range"]);

    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let sent = exchange(&mut link, &mut mock, &v2(&param_set("RC1_MIN", bad)), 0);
        assert_eq!(param_values(&sent), [("RC1_MIN".to_string(), 1000.0, 1, 4)]);
        assert_eq!(texts(&sent), ["RC1_MIN: value must be finite"]);
    }

    let mut int32 = param_set("RC1_MIN", 1100.0);
    int32.param_type = common::MavParamType::MAV_PARAM_TYPE_INT32;
    let sent = exchange(&mut link, &mut mock, &v2(&int32), 0);
    assert_eq!(param_values(&sent), [("RC1_MIN".to_string(), 1000.0, 1, 4)]);
    assert_eq!(texts(&sent), ["RC1_MIN: type must be REAL32"]);

    // A type byte the dialect does not list is refused the same way, not dropped.
    let mut payload = v2(&param_set("RC1_MIN", 1100.0))[10..].to_vec();
    payload.truncate(payload.len() - 2);
    payload.resize(23, 0);
    payload[22] = 200;
    let sent = exchange(&mut link, &mut mock, &v2_raw(23, common::PARAM_SET_DATA::EXTRA_CRC, &payload), 0);
    assert_eq!(param_values(&sent), [("RC1_MIN".to_string(), 1000.0, 1, 4)]);

    let sent = exchange(&mut link, &mut mock, &v2(&param_set("NO_SUCH", 1.0)), 0);
    assert!(param_values(&sent).is_empty());
    assert_eq!(texts(&sent), ["PARAM_SET: no parameter NO_SUCH"]);
    // A name that is not ASCII is no parameter either, and is not echoed into the text.
    let mut not_ascii = param_set("RC1_MIN", 1100.0);
    not_ascii.param_id = mavlink::types::CharArray::new(*b"RC1_MIN\xff\0\0\0\0\0\0\0\0");
    let sent = exchange(&mut link, &mut mock, &v2(&not_ascii), 0);
    assert!(param_values(&sent).is_empty());
    assert_eq!(texts(&sent), ["PARAM_SET: no parameter "]);

    assert!(mock.sets.is_empty());
    assert_eq!(mock.value("RC1_MIN"), 1000.0);
}

#[test]
fn messages_for_another_system_are_ignored_and_counted() {
    let mut link = link();
    let mut mock = Mock::new();
    let mut set = param_set("RC1_MIN", 1100.0);
    set.target_system = 2;
    assert!(exchange(&mut link, &mut mock, &v2(&set), 0).is_empty());
    let mut cmd = command_long(MavCmd::MAV_CMD_PREFLIGHT_STORAGE, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    cmd.target_component = 50;
    assert!(exchange(&mut link, &mut mock, &v2(&cmd), 0).is_empty());
    assert_eq!(link.stats().not_for_us, 2);
    assert!(mock.sets.is_empty() && mock.requests.is_empty());
}

#[test]
fn mission_request_list_gets_a_count_of_zero_of_the_asked_type() {
    let mut link = link();
    let mut mock = Mock::new();
    // mission_type is an extension field: mission, fence, rally, all, and a value not listed.
    for mission_type in [0u8, 1, 2, 255, 77] {
        let request = v2_raw(43, common::MISSION_REQUEST_LIST_DATA::EXTRA_CRC, &[1, 1, mission_type]);
        let sent = exchange(&mut link, &mut mock, &request, 0);
        match &sent[..] {
            [Sent { message: MavMessage::MISSION_COUNT(c), payload, .. }] => {
                assert_eq!((c.count, c.target_system, c.target_component), (0, GCS_SYSTEM, GCS_COMPONENT));
                assert_eq!(payload.get(4).copied().unwrap_or(0), mission_type);
            }
            other => panic!("{:?}", messages(other)),
        }
    }
    // MAVLink 1 carries no mission_type.
    let request = common::MISSION_REQUEST_LIST_DATA { target_system: 1, target_component: 1 };
    let sent = exchange(&mut link, &mut mock, &v1(&request), 0);
    assert!(matches!(&sent[..], [Sent { message: MavMessage::MISSION_COUNT(c), .. }] if c.count == 0));
}

#[test]
fn file_transfer_gets_a_nak() {
    let mut link = link();
    let mut mock = Mock::new();
    let mut payload = [0u8; 251];
    // seq 41, session 0, OpenFileRO (4), "@PARAM/param.pck"
    payload[..4].copy_from_slice(&[41, 0, 0, 4]);
    payload[12..28].copy_from_slice(b"@PARAM/param.pck");
    let request = common::FILE_TRANSFER_PROTOCOL_DATA { target_network: 0, target_system: 1, target_component: 1, payload };
    let sent = exchange(&mut link, &mut mock, &v2(&request), 0);
    match &sent[..] {
        [Sent { message: MavMessage::FILE_TRANSFER_PROTOCOL(f), .. }] => {
            assert_eq!((f.target_system, f.target_component), (GCS_SYSTEM, GCS_COMPONENT));
            // seq + 1, session, NAK (129), size 1, the request's opcode, ..., error UnknownCommand
            assert_eq!(&f.payload[..6], &[42, 0, 0, 129, 1, 4]);
            assert_eq!(f.payload[12], 7);
        }
        other => panic!("{:?}", messages(other)),
    }
}

#[test]
fn every_command_gets_an_ack_unsupported_by_default() {
    let mut link = link();
    let mut mock = Mock::new();
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_NAV_TAKEOFF, [0.0; 7]);
    assert_eq!(ack_of(&sent), (MavCmd::MAV_CMD_NAV_TAKEOFF as u16, MavResult::MAV_RESULT_UNSUPPORTED));
    // target_system and target_component, extension fields at 8 and 9.
    let ack_target = sent.iter().find_map(|s| match &s.message {
        MavMessage::COMMAND_ACK(_) => Some((s.payload[8], s.payload[9])),
        _ => None,
    });
    assert_eq!(ack_target, Some((GCS_SYSTEM, GCS_COMPONENT)));
    assert!(mock.requests.is_empty());

    // A number the dialect does not list: answered with that number.
    let mut payload = v2(&command_long(MavCmd::MAV_CMD_NAV_TAKEOFF, [1.0; 7]))[10..].to_vec();
    payload.truncate(payload.len() - 2);
    payload[28..30].copy_from_slice(&31_999u16.to_le_bytes());
    let sent = exchange(&mut link, &mut mock, &v2_raw(76, common::COMMAND_LONG_DATA::EXTRA_CRC, &payload), 0);
    assert_eq!(ack_of(&sent), (31_999, MavResult::MAV_RESULT_UNSUPPORTED));
}

#[test]
fn command_int_is_handled_like_command_long() {
    let mut link = link();
    let mut mock = Mock::new();
    let cmd = common::COMMAND_INT_DATA {
        param1: 148.0,
        command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
        target_system: 1,
        target_component: 1,
        ..common::COMMAND_INT_DATA::DEFAULT
    };
    let sent = exchange(&mut link, &mut mock, &v2(&cmd), 0);
    assert_eq!(ack_of(&sent), (MavCmd::MAV_CMD_REQUEST_MESSAGE as u16, MavResult::MAV_RESULT_ACCEPTED));
    assert!(sent.iter().any(|s| matches!(s.message, MavMessage::AUTOPILOT_VERSION(_))));
}

#[test]
fn autopilot_version_on_request_after_the_ack() {
    let mut link = link();
    let mut mock = Mock::new();
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_REQUEST_MESSAGE, [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert!(matches!(sent[0].message, MavMessage::COMMAND_ACK(_)));
    match &sent[1].message {
        MavMessage::AUTOPILOT_VERSION(v) => {
            assert_eq!(
                v.capabilities,
                MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2
                    | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
            );
            assert_eq!(v.flight_sw_version, LinkConfig::DEFAULT.flight_sw_version);
        }
        other => panic!("{other:?}"),
    }
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_REQUEST_MESSAGE, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_UNSUPPORTED);
    assert_eq!(sent.len(), 1);
}

#[test]
fn arm_and_disarm_are_decoded_and_the_vehicle_decides() {
    let mut link = link();
    let mut mock = Mock::new();
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_ACCEPTED, "the link has no rule of its own");
    let disarm = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    command(&mut link, &mut mock, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, disarm);
    command(&mut link, &mut mock, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0, 21195.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    command(&mut link, &mut mock, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0, FORCE_DISARM, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let disarms = [Request::Disarm { forced: false }, Request::Disarm { forced: false }, Request::Disarm { forced: true }];
    assert_eq!(mock.requests[..], [[Request::Arm].as_slice(), &disarms].concat()[..]);
    // Neither arm nor disarm: refused here, never asked.
    mock.requests.clear();
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_DENIED);
    assert!(mock.requests.is_empty());
}

#[test]
fn a_refusal_for_now_is_temporarily_rejected_and_any_other_denied_each_with_its_rule() {
    let cases: [([f32; 7], MavCmd, Request, &str); 8] = [
        ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, Request::Arm, "Arm refused"),
        ([0.0; 7], MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, Request::Disarm { forced: false }, "Disarm refused"),
        ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, Request::CalibrateImu, "Calibration refused"),
        ([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, Request::CalibrateImu, "Calibration refused"),
        ([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, Request::CalibrateRadio, "Calibration refused"),
        ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_STORAGE, Request::SaveParams, "Storage refused"),
        ([2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_STORAGE, Request::ResetParams, "Storage refused"),
        ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, Request::Reboot, "Reboot refused"),
    ];
    for (params, cmd, request, what) in cases {
        for (refused, result) in [
            (Refused::for_now("disarmed only"), MavResult::MAV_RESULT_TEMPORARILY_REJECTED),
            (Refused::denied("calibrating"), MavResult::MAV_RESULT_DENIED),
        ] {
            let mut link = link();
            let mut mock = Mock::new();
            mock.refuse_requests = Some(refused);
            let sent = command(&mut link, &mut mock, cmd, params);
            assert_eq!(ack_of(&sent), (cmd as u16, result), "{request:?}");
            assert_eq!(texts(&sent), [format!("{what}: {}", refused.rule)], "{request:?}");
            assert_eq!(mock.requests, [request]);
            assert!(!link.reboot_ready());
        }
    }
}

#[test]
fn an_armed_state_alone_refuses_nothing_the_vehicle_accepts() {
    // The flight state the link reports (armed, in failsafe) is for telemetry: the rules are the
    // vehicle's, and a vehicle that accepts is obeyed.
    for state in [FlightState::Arming, FlightState::Armed, FlightState::FailsafeLevel] {
        for (params, cmd) in [
            ([0.0; 7], MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
            ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION),
            ([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], MavCmd::MAV_CMD_PREFLIGHT_STORAGE),
        ] {
            let mut link = link();
            let mut mock = Mock::new();
            mock.state.state = state;
            let sent = command(&mut link, &mut mock, cmd, params);
            assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_ACCEPTED, "{state:?} {cmd:?}");
            assert_eq!(mock.requests.len(), 1);
        }
    }
}

#[test]
fn calibration_decoding() {
    // Every parameter 0 ends a calibration (PX4's cancel).
    let mut link = link();
    let mut mock = Mock::new();
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, [0.0; 7]);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(mock.requests, [Request::EndCalibration]);
    // Magnetometer, baro, two at once: unsupported.
    for params in [[0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]] {
        let mut link = self::link();
        let mut mock = Mock::new();
        let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION, params);
        assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_UNSUPPORTED);
        assert!(mock.requests.is_empty());
    }
}

#[test]
fn reboot_comes_after_the_ack_and_only_when_accepted() {
    let mut link = link();
    let mut mock = Mock::new();
    mock.refuse_requests = Some(Refused::for_now("disarmed only"));
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    assert!(!link.reboot_ready());

    mock.refuse_requests = None;
    mock.requests.clear();
    let frame = v2(&command_long(MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
    link.receive(&frame, 0, &mut mock);
    assert_eq!(mock.requests, [Request::Reboot]);
    assert!(!link.reboot_ready(), "the ACK has not left yet");
    let sent = drain(&mut link);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_ACCEPTED);
    assert!(link.reboot_ready());
    // Shutdown is not something this board does.
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_UNSUPPORTED);
}

fn motor_test(motor: f32, throttle_pct: f32, seconds: f32) -> [f32; 7] {
    [motor, 0.0, throttle_pct, seconds, 1.0, 0.0, 0.0]
}

#[test]
fn a_motor_test_is_passed_on_as_asked_and_the_link_never_ends_it_on_time() {
    let mut link = link();
    let mut mock = Mock::new();
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_DO_MOTOR_TEST, motor_test(3.0, 80.0, 10.0));
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_ACCEPTED);
    // Uncapped: the cap, the longest duration and the deadline are the flight controller's.
    assert_eq!(mock.requests, [Request::MotorTest { motor: 2, throttle_pct: 80.0, duration_ms: 10_000 }]);
    let heartbeat = v2(&common::HEARTBEAT_DATA::DEFAULT);
    for now in (0..20_000).step_by(10) {
        if now % 1000 == 0 {
            link.receive(&heartbeat, now, &mut mock);
        }
        link.tick(now, &mut mock);
        drain(&mut link);
    }
    assert_eq!(mock.requests.len(), 1, "{:?}", mock.requests);
    // A duration past u32's milliseconds saturates, for the flight controller to cap.
    let mut mock = Mock::new();
    command(&mut link, &mut mock, MavCmd::MAV_CMD_DO_MOTOR_TEST, motor_test(1.0, 5.0, 1e30));
    assert_eq!(mock.requests, [Request::MotorTest { motor: 0, throttle_pct: 5.0, duration_ms: u32::MAX }]);
}

#[test]
fn motor_test_stops_on_another_command_and_once_on_silence() {
    let start = |link: &mut TestLink, mock: &mut Mock| {
        let sent = command(link, mock, MavCmd::MAV_CMD_DO_MOTOR_TEST, motor_test(1.0, 10.0, 3.0));
        assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_ACCEPTED);
        mock.requests.clear();
    };
    // Another command, accepted.
    let mut link = link();
    let mut mock = Mock::new();
    start(&mut link, &mut mock);
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_REQUEST_MESSAGE, [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(mock.requests, [Request::StopMotorTest]);
    assert!(texts(&sent).contains(&"Motor test stopped: another command".to_string()));
    // None runs (the flight controller ended it): nothing to stop.
    mock.requests.clear();
    command(&mut link, &mut mock, MavCmd::MAV_CMD_REQUEST_MESSAGE, [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert!(mock.requests.is_empty());

    // Silence: nothing heard for 1.5 s.
    let mut link = self::link();
    let mut mock = Mock::new();
    start(&mut link, &mut mock);
    link.tick(1500, &mut mock);
    assert!(mock.requests.is_empty());
    link.tick(1501, &mut mock);
    assert_eq!(mock.requests, [Request::StopMotorTest]);
    assert!(texts(&drain(&mut link)).contains(&"Motor test stopped: link silent".to_string()));
    // The flight controller's report lags the stop: asked once per silence.
    mock.state.motor_test = true;
    link.tick(1510, &mut mock);
    assert_eq!(mock.requests, [Request::StopMotorTest]);
}

#[test]
fn motor_test_decoding() {
    let cases: [[f32; 7]; 7] = [
        motor_test(0.0, 10.0, 1.0),
        motor_test(1.5, 10.0, 1.0),
        motor_test(300.0, 10.0, 1.0),
        motor_test(1.0, f32::NAN, 1.0),
        motor_test(1.0, -1.0, 1.0),
        motor_test(1.0, 10.0, 0.0),
        [1.0, 0.0, 10.0, 1.0, 4.0, 0.0, 0.0],
    ];
    for params in cases {
        let mut link = link();
        let mut mock = Mock::new();
        let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_DO_MOTOR_TEST, params);
        assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_DENIED, "{params:?}");
        assert_eq!(texts(&sent).len(), 1);
        assert!(mock.requests.is_empty() && !mock.state.motor_test);
    }
    // PWM throttle type.
    let mut link = link();
    let mut mock = Mock::new();
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_DO_MOTOR_TEST, [1.0, 1.0, 1100.0, 1.0, 1.0, 0.0, 0.0]);
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_DENIED);
    // Which motors there are, and whether one may spin now, the vehicle says.
    mock.refuse_requests = Some(Refused::denied("motor must be 1 to 4"));
    let sent = command(&mut link, &mut mock, MavCmd::MAV_CMD_DO_MOTOR_TEST, motor_test(5.0, 10.0, 1.0));
    assert_eq!(ack_of(&sent).1, MavResult::MAV_RESULT_DENIED);
    assert_eq!(texts(&sent), ["Motor test: motor must be 1 to 4"]);
    assert_eq!(mock.requests, [Request::MotorTest { motor: 4, throttle_pct: 10.0, duration_ms: 1000 }]);
}

#[test]
fn send_text_goes_out_in_50_byte_chunks() {
    let mut link = link();
    assert!(link.send_text(Severity::Info, b"Armed"));
    let long = "x".repeat(80);
    assert!(link.send_text(Severity::Warning, long.as_bytes()));
    let sent = drain(&mut link);
    assert_eq!(texts(&sent), ["Armed".to_string(), "x".repeat(50), "x".repeat(30)]);
    match &sent[0].message {
        MavMessage::STATUSTEXT(t) => assert_eq!(t.severity, common::MavSeverity::MAV_SEVERITY_INFO),
        _ => unreachable!(),
    }
}

#[test]
fn a_full_queue_drops_whole_frames_and_counts_them() {
    // A STATUSTEXT of three characters is a 16-byte frame.
    let mut link: Link<40> = Link::new(LinkConfig::DEFAULT);
    assert!(link.send_text(Severity::Info, b"one"));
    assert!(link.send_text(Severity::Info, b"two"));
    assert!(!link.send_text(Severity::Info, b"three is one too many"));
    assert_eq!(link.stats().tx_dropped, 1);
    // Drained a few bytes at a time, the frames come out whole.
    let mut bytes = Vec::new();
    let mut buf = [0u8; 3];
    loop {
        let n = link.poll_tx(&mut buf);
        if n == 0 {
            break;
        }
        bytes.extend_from_slice(&buf[..n]);
    }
    let sent = decode_all(&bytes);
    assert_eq!(texts(&sent), ["one", "two"]);
    // The dropped frame's sequence number is skipped, so a ground station counts it lost.
    assert_eq!(sent[1].sequence, sent[0].sequence + 1);
    assert!(link.send_text(Severity::Info, b"four"));
    let four = drain(&mut link);
    assert_eq!(four[0].sequence, sent[1].sequence + 2);
}

#[test]
fn a_greeting_is_said_at_once_and_again_to_each_station_that_connects_later() {
    use fcu_link::STATION_GONE_MS;
    let mut link = link();
    let mut mock = Mock::new();
    assert!(link.greet(Severity::Info, b"parameters loaded from flash"));
    assert_eq!(texts(&drain(&mut link)), ["parameters loaded from flash"]);
    let heartbeat = v2(&common::HEARTBEAT_DATA::DEFAULT);
    // The first station's first heartbeat: said again; its next ones: not.
    assert_eq!(texts(&exchange(&mut link, &mut mock, &heartbeat, 10_000)), ["parameters loaded from flash"]);
    assert!(texts(&exchange(&mut link, &mut mock, &heartbeat, 11_000)).is_empty());
    assert!(texts(&exchange(&mut link, &mut mock, &heartbeat, 11_000 + STATION_GONE_MS)).is_empty());
    // Silence past STATION_GONE_MS, then a heartbeat: a station that (re)connected.
    let back = 11_000 + 2 * STATION_GONE_MS + 1;
    assert_eq!(texts(&exchange(&mut link, &mut mock, &heartbeat, back)), ["parameters loaded from flash"]);
    // Any other frame keeps the line alive without a greeting of its own.
    let later = back + STATION_GONE_MS + 1;
    assert!(texts(&exchange(&mut link, &mut mock, &v2(&common::PARAM_REQUEST_LIST_DATA { target_system: 1, target_component: 1 }), later))
        .is_empty());
    assert!(texts(&exchange(&mut link, &mut mock, &heartbeat, later + 1000)).is_empty());
}

#[test]
fn without_a_greeting_a_heartbeat_gets_no_text() {
    let mut link = link();
    let mut mock = Mock::new();
    let sent = exchange(&mut link, &mut mock, &v2(&common::HEARTBEAT_DATA::DEFAULT), 0);
    assert!(texts(&sent).is_empty(), "{:?}", texts(&sent));
}
