//! Any bytes into fcu-link's frame reader and handler, in chunks with telemetry ticks between:
//! no panic, every frame sent out is well formed, and nothing changes without a frame that
//! asks for it: each parameter set must match a PARAM_SET frame with a good CRC somewhere in
//! the bytes given to the link (found by a scan independent of the reader), and the vehicle
//! gets a request only when those bytes hold a COMMAND_LONG, COMMAND_INT or SET_MODE with a
//! good CRC.
//!
//! Input: byte 0 the vehicle's state (bit 0 armed, bit 1 refuses every request, bit 2 refuses
//! it for now, bit 3 a motor test runs), then
//! chunks, each followed by one tick, and a chunk starts with a byte `k`:
//! - `k < 0xC0`: the next `(k & 63) + 1` bytes go to the link as they are; the tick comes
//!   `(k >> 6) · 500 + 7` ms later;
//! - `k >= 0xC0`: a byte `m` picks one of the handled messages (`(m & 127) % 9`) and the version (bit 7:
//!   MAVLink 1), and the next `(k & 63) + 1` bytes are wrapped as its payload in a frame with a
//!   good CRC (so that the handler, not only the reader, sees arbitrary payloads); 7 ms later.
#![no_main]

use fcu_core::supervisor::FlightState;
use fcu_link::{command, Altitude, Attitude, Battery, Health, Link, LinkConfig, Param, ParamMask, Refused, Request, Vehicle, VehicleState};
use libfuzzer_sys::fuzz_target;
use mavlink::dialects::common::{MavResult, COMMAND_ACK_DATA, COMMAND_INT_DATA, COMMAND_LONG_DATA, PARAM_SET_DATA};
use mavlink::MessageData;

const NAMES: [&str; 4] = ["RCMAP_ROLL", "RC1_MIN", "ANGLE_MAX_DEG", "RATE_ROLL_P_GAIN"];

struct Mock {
    flags: u8,
    values: [f32; 4],
    sets: Vec<(u16, f32)>,
    requests: Vec<Request>,
}

impl Vehicle for Mock {
    fn state(&self) -> VehicleState {
        VehicleState {
            state: if self.flags & 1 != 0 { FlightState::Armed } else { FlightState::Disarmed },
            attitude: Attitude::default(),
            rc_widths_us: [1500; 8],
            rc_channel_count: 8,
            motor_outputs_us: [1000; 4],
            battery: Battery { voltage_mv: 3900, current_ca: -1, remaining_pct: -1 },
            health: Health { imu: true, radio: true, estimator: true, battery: true, prearm: true },
            load_permille: 0,
            motor_test: self.flags & 8 != 0,
            altitude: Altitude::default(),
        }
    }
    fn param_count(&self) -> u16 {
        NAMES.len() as u16
    }
    fn param(&self, index: u16) -> Option<Param> {
        let i = usize::from(index);
        Some(Param { name: NAMES.get(i)?, value: *self.values.get(i)? })
    }
    fn param_index(&self, name: &[u8]) -> Option<u16> {
        NAMES.iter().position(|n| n.as_bytes() == name).map(|i| i as u16)
    }
    fn set_param(&mut self, index: u16, value: f32) -> Result<ParamMask, &'static str> {
        assert!(value.is_finite(), "non-finite value passed on");
        if !(-1000.0..=1000.0).contains(&value) {
            return Err("out of range");
        }
        let slot = self.values.get_mut(usize::from(index)).ok_or("index")?;
        *slot = value;
        self.sets.push((index, value));
        // Parameter 0 moves parameter 1 with it (as a channel map does), so that the echo of
        // the others a set changed is fuzzed too.
        let mut others = ParamMask::EMPTY;
        if index == 0 && self.values[1] != -value {
            self.values[1] = -value;
            others.insert(1);
        }
        Ok(others)
    }
    fn request(&mut self, request: Request) -> Result<ParamMask, Refused> {
        self.requests.push(request);
        match self.flags & 6 {
            // A set-mode reports parameter 3 as set (the station's is ALT_MODE), so that the
            // echo after its ACK is fuzzed too.
            0 if matches!(request, Request::SetMode(_)) => {
                let mut set = ParamMask::EMPTY;
                set.insert(3);
                Ok(set)
            }
            0 => Ok(ParamMask::EMPTY),
            2 => Err(Refused::denied("fuzz")),
            _ => Err(Refused::for_now("fuzz")),
        }
    }
}

/// Every (message id, payload) with a good CRC at any offset of `data`, MAVLink 1 or 2, for the
/// messages listed.
fn good_frames(data: &[u8], wanted: &[(u32, u8)]) -> Vec<(u32, Vec<u8>)> {
    let mut found = Vec::new();
    for at in 0..data.len() {
        let rest = &data[at..];
        let (header, id) = match rest {
            [0xFD, _, _, _, _, _, _, a, b, c, ..] => (10, u32::from_le_bytes([*a, *b, *c, 0])),
            [0xFE, _, _, _, _, id, ..] => (6, u32::from(*id)),
            _ => continue,
        };
        let len = usize::from(rest[1]);
        let Some(&(_, extra)) = wanted.iter().find(|(w, _)| *w == id) else { continue };
        if rest.len() < header + len + 2 {
            continue;
        }
        let crc = u16::from_le_bytes([rest[header + len], rest[header + len + 1]]);
        if mavlink::calculate_crc(&rest[1..header + len], extra) == crc {
            found.push((id, rest[header..header + len].to_vec()));
        }
    }
    found
}

/// `payload` in a frame with a good CRC for the handled message `(m & 127) % 9`, MAVLink 1 when bit 7
/// of `m` is set.
fn wrap(m: u8, payload: &[u8]) -> Vec<u8> {
    let handled = &fcu_link::reader::HANDLED[usize::from(m & 0x7F) % fcu_link::reader::HANDLED.len()];
    let mut f = if m & 0x80 != 0 {
        vec![0xFE, payload.len() as u8, 0, 255, 190, handled.id as u8]
    } else {
        let id = handled.id.to_le_bytes();
        vec![0xFD, payload.len() as u8, 0, 0, 0, 255, 190, id[0], id[1], id[2]]
    };
    f.extend_from_slice(payload);
    let crc = mavlink::calculate_crc(&f[1..], handled.extra_crc);
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

fuzz_target!(|data: &[u8]| {
    let Some((&flags, mut rest)) = data.split_first() else { return };
    let mut mock = Mock { flags, values: [1.0, 1000.0, 30.0, 0.5], sets: Vec::new(), requests: Vec::new() };
    let mut link: Link<512> = Link::new(LinkConfig::DEFAULT);
    let mut now = 0u32;
    let mut out = Vec::new();
    let mut buf = [0u8; 128];
    // The bytes the link was given, in order (the length bytes are not among them).
    let mut fed = Vec::new();
    while let Some((&k, tail)) = rest.split_first() {
        if k >= 0xC0 {
            let Some((&m, tail)) = tail.split_first() else { break };
            let n = (usize::from(k & 63) + 1).min(tail.len());
            let frame = wrap(m, &tail[..n]);
            link.receive(&frame, now, &mut mock);
            fed.extend_from_slice(&frame);
            now = now.wrapping_add(7);
            rest = &tail[n..];
        } else {
            let n = (usize::from(k & 63) + 1).min(tail.len());
            link.receive(&tail[..n], now, &mut mock);
            fed.extend_from_slice(&tail[..n]);
            now = now.wrapping_add(u32::from(k >> 6) * 500 + 7);
            rest = &tail[n..];
        }
        link.tick(now, &mut mock);
        loop {
            let got = link.poll_tx(&mut buf);
            if got == 0 {
                break;
            }
            out.extend_from_slice(&buf[..got]);
        }
    }

    // What went out is whole MAVLink 2 frames from us, back to back.
    let mut at = 0;
    let mut acks = Vec::new();
    while at < out.len() {
        assert_eq!(out[at], 0xFD, "frame start");
        let len = usize::from(out[at + 1]);
        assert_eq!((out[at + 5], out[at + 6]), (1, 1), "our system and component");
        assert!(out.len() >= at + 12 + len, "a frame cut short");
        let id = u32::from_le_bytes([out[at + 7], out[at + 8], out[at + 9], 0]);
        if id == COMMAND_ACK_DATA::ID {
            // MAVLink 2 drops a payload's trailing zeros.
            let mut payload = out[at + 10..at + 10 + len].to_vec();
            payload.resize(3, 0);
            acks.push((u16::from_le_bytes([payload[0], payload[1]]), payload[2]));
        }
        at += 12 + len;
    }
    assert_eq!(at, out.len(), "a frame cut short");
    // The link answers with the vehicle's verdict: a vehicle that refuses every request never
    // has one of its commands acknowledged as accepted.
    if mock.flags & 6 != 0 {
        let vehicles = [
            command::COMPONENT_ARM_DISARM,
            command::PREFLIGHT_CALIBRATION,
            command::PREFLIGHT_STORAGE,
            command::PREFLIGHT_REBOOT_SHUTDOWN,
            command::DO_MOTOR_TEST,
            command::DO_SET_MODE,
            command::SET_MODE_ACK,
        ];
        let accepted = MavResult::MAV_RESULT_ACCEPTED as u8;
        assert!(
            !acks.iter().any(|&(c, r)| vehicles.contains(&c) && r == accepted),
            "command {acks:?} acknowledged as accepted by a vehicle that refused it"
        );
    }

    let body = &fed[..];
    if !mock.sets.is_empty() {
        let sets = good_frames(body, &[(PARAM_SET_DATA::ID, PARAM_SET_DATA::EXTRA_CRC)]);
        for &(index, value) in &mock.sets {
            let name = NAMES[usize::from(index)].as_bytes();
            let asked = sets.iter().any(|(_, p)| {
                let mut p = p.clone();
                p.resize(23, 0);
                let id_end = p[6..22].iter().position(|&b| b == 0).map_or(22, |z| 6 + z);
                f32::from_le_bytes([p[0], p[1], p[2], p[3]]).to_bits() == value.to_bits() && &p[6..id_end] == name
            });
            assert!(asked, "{} set to {value} without a PARAM_SET asking for it", NAMES[usize::from(index)]);
        }
    }
    // A running test (the mock says so with flag 8) is stopped by the link itself when the
    // ground station falls silent: the one request no command frame has to ask for.
    let asked: Vec<&Request> = mock.requests.iter().filter(|r| !matches!(r, Request::StopMotorTest)).collect();
    if mock.flags & 8 == 0 {
        assert!(!mock.requests.contains(&Request::StopMotorTest), "a motor test stopped while none ran");
    }
    if !asked.is_empty() {
        let set_mode = fcu_link::reader::handled_message(command::SET_MODE_ID).map_or(0, |h| h.extra_crc);
        let commands = good_frames(
            body,
            &[
                (COMMAND_LONG_DATA::ID, COMMAND_LONG_DATA::EXTRA_CRC),
                (COMMAND_INT_DATA::ID, COMMAND_INT_DATA::EXTRA_CRC),
                (command::SET_MODE_ID, set_mode),
            ],
        );
        assert!(!commands.is_empty(), "{asked:?} without a command frame");
    }
    // Whether a request may be carried out in the state the board is in is not the link's to
    // say: fcu_core::gcs owns those rules, and the station applies them (its tests, and the
    // `boundaries` target through the whole board, check a request refused while armed). The
    // link passes every command on, armed or not, and answers with the vehicle's verdict.
});
