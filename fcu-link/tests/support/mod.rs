//! Shared by the tests: a mock vehicle, frames built by the `mavlink` crate (not by fcu-link's
//! encoder), and a decoder of what the link sends, also the crate's.

#![allow(dead_code)]

use fcu_core::supervisor::FlightState;
use fcu_link::{
    AltMode, Altitude, Attitude, Battery, Health, Link, Param, ParamMask, Refused, Request, Vehicle, VehicleState, VerticalMode,
};
use mavlink::dialects::common::{self as common, MavMessage};
use mavlink::{MAVLinkV1MessageRaw, MAVLinkV2MessageRaw, MavHeader, Message, MessageData};

pub const GCS_SYSTEM: u8 = 255;
pub const GCS_COMPONENT: u8 = 190;

pub struct MockParam {
    pub name: &'static str,
    pub value: f32,
    pub min: f32,
    pub max: f32,
}

pub struct Mock {
    pub state: VehicleState,
    pub params: Vec<MockParam>,
    pub sets: Vec<(u16, f32)>,
    pub requests: Vec<Request>,
    /// The verdict the mock gives every request (it knows no rule of its own).
    pub refuse_requests: Option<Refused>,
    /// The parameter an accepted set-mode reports as set (the station's is ALT_MODE).
    pub mode_param: Option<u16>,
}

impl Mock {
    pub fn new() -> Self {
        Self {
            state: VehicleState {
                state: FlightState::Disarmed,
                attitude: Attitude {
                    roll_rad: 0.1,
                    pitch_rad: -0.2,
                    yaw_rad: 1.5,
                    roll_rate_rad_s: 0.01,
                    pitch_rate_rad_s: 0.02,
                    yaw_rate_rad_s: 0.03,
                },
                rc_widths_us: [1500, 1500, 1000, 1500, 1000, 2000, 0, 0],
                rc_channel_count: 6,
                motor_outputs_us: [1000, 1100, 1200, 1300],
                battery: Battery { voltage_mv: 3900, current_ca: -1, remaining_pct: 70 },
                health: Health { imu: true, radio: true, estimator: true, battery: true, prearm: true },
                load_permille: 420,
                motor_test: false,
                altitude: Altitude {
                    height_m: Some(1.25),
                    climb_m_s: Some(-0.5),
                    pressure_pa: Some(101_000.0),
                    temperature_c: 24.5,
                    mode: VerticalMode::AltitudeHold,
                },
            },
            params: vec![
                MockParam { name: "RCMAP_ROLL", value: 1.0, min: 1.0, max: 8.0 },
                MockParam { name: "RC1_MIN", value: 1000.0, min: 800.0, max: 1500.0 },
                MockParam { name: "ANGLE_MAX_DEG", value: 30.0, min: 5.0, max: 60.0 },
                // Exactly 16 characters: sent without a terminating NUL.
                MockParam { name: "RATE_ROLL_P_GAIN", value: 0.5, min: 0.0, max: 2.0 },
            ],
            sets: Vec::new(),
            requests: Vec::new(),
            refuse_requests: None,
            mode_param: None,
        }
    }

    pub fn value(&self, name: &str) -> f32 {
        self.params.iter().find(|p| p.name == name).unwrap().value
    }
}

impl Vehicle for Mock {
    fn state(&self) -> VehicleState {
        self.state
    }
    fn param_count(&self) -> u16 {
        self.params.len() as u16
    }
    fn param(&self, index: u16) -> Option<Param> {
        self.params.get(usize::from(index)).map(|p| Param { name: p.name, value: p.value })
    }
    fn param_index(&self, name: &[u8]) -> Option<u16> {
        self.params.iter().position(|p| p.name.as_bytes() == name).map(|i| i as u16)
    }
    fn set_param(&mut self, index: u16, value: f32) -> Result<ParamMask, &'static str> {
        assert!(value.is_finite(), "the link passed on a non-finite value");
        let p = self.params.get_mut(usize::from(index)).ok_or("no such index")?;
        if value < p.min || value > p.max {
            return Err("out of range");
        }
        p.value = value;
        self.sets.push((index, value));
        // The mock's parameters are independent: a set changes no other.
        Ok(ParamMask::EMPTY)
    }
    fn request(&mut self, request: Request) -> Result<ParamMask, Refused> {
        self.requests.push(request);
        if let Some(refused) = self.refuse_requests {
            return Err(refused);
        }
        // A test runs from an accepted start until a stop (a vehicle would also end it itself).
        let mut set = ParamMask::EMPTY;
        match request {
            Request::MotorTest { .. } => self.state.motor_test = true,
            Request::StopMotorTest => self.state.motor_test = false,
            Request::SetMode(mode) => {
                self.state.altitude.mode = if mode == AltMode::Hold { VerticalMode::AltitudeHold } else { VerticalMode::Manual };
                if let Some(index) = self.mode_param {
                    set.insert(index);
                }
            }
            _ => {}
        }
        Ok(set)
    }
}

pub type TestLink = Link<1024>;

/// A MAVLink 2 frame from the ground station, built by the crate.
pub fn v2<D: MessageData>(data: &D) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message_data(MavHeader { system_id: GCS_SYSTEM as u32, component_id: GCS_COMPONENT, sequence: 7 }, data);
    raw.raw_bytes().to_vec()
}

/// A MAVLink 1 frame from the ground station, built by the crate.
pub fn v1<D: MessageData>(data: &D) -> Vec<u8> {
    let mut raw = MAVLinkV1MessageRaw::new();
    raw.serialize_message_data(MavHeader { system_id: GCS_SYSTEM as u32, component_id: GCS_COMPONENT, sequence: 7 }, data);
    raw.raw_bytes().to_vec()
}

/// A MAVLink 2 frame with a payload given byte by byte (for values the dialect does not list).
pub fn v2_raw(id: u32, extra_crc: u8, payload: &[u8]) -> Vec<u8> {
    let id = id.to_le_bytes();
    let mut f = vec![0xFD, payload.len() as u8, 0, 0, 7, GCS_SYSTEM, GCS_COMPONENT, id[0], id[1], id[2]];
    f.extend_from_slice(payload);
    let crc = mavlink::calculate_crc(&f[1..], extra_crc);
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// A decoded frame the link sent.
#[derive(Debug, Clone)]
pub struct Sent {
    pub sequence: u8,
    pub system_id: u8,
    pub component_id: u8,
    pub payload: Vec<u8>,
    pub message: MavMessage,
}

/// Splits the link's output into frames, checks each one's CRC with the crate's extra CRC and
/// parses it with the crate; panics on anything malformed.
pub fn decode_all(bytes: &[u8]) -> Vec<Sent> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        assert_eq!(bytes[at], 0xFD, "frame start at {at}");
        let len = usize::from(bytes[at + 1]);
        assert_eq!(bytes[at + 2], 0, "incompat flags");
        let frame = &bytes[at..at + 12 + len];
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.as_mut_slice()[..frame.len()].copy_from_slice(frame);
        assert!(raw.has_valid_crc::<MavMessage>(), "bad CRC in {frame:?}");
        let mut payload = raw.payload().to_vec();
        if raw.message_id() == common::COMMAND_ACK_DATA::ID {
            // The ACK of a command the dialect does not list: parse it with a listed number
            // (the tests read the number from the payload).
            payload.resize(2, 0);
            payload[..2].copy_from_slice(&16u16.to_le_bytes());
            payload.extend_from_slice(&raw.payload()[2.min(raw.payload().len())..]);
        }
        let message = MavMessage::parse(mavlink::MavlinkVersion::V2, raw.message_id(), &payload).expect("parses");
        out.push(Sent {
            sequence: raw.sequence(),
            system_id: raw.system_id() as u8,
            component_id: raw.component_id(),
            payload: raw.payload().to_vec(),
            message,
        });
        at += frame.len();
    }
    out
}

/// Drains the link (of any queue size) and decodes what it sent.
pub fn drain<const N: usize>(link: &mut Link<N>) -> Vec<Sent> {
    let mut bytes = Vec::new();
    let mut buf = [0u8; 97];
    loop {
        let n = link.poll_tx(&mut buf);
        if n == 0 {
            break;
        }
        bytes.extend_from_slice(&buf[..n]);
    }
    decode_all(&bytes)
}

pub fn messages(sent: &[Sent]) -> Vec<MavMessage> {
    sent.iter().map(|s| s.message.clone()).collect()
}

pub fn command_long(command: common::MavCmd, params: [f32; 7]) -> common::COMMAND_LONG_DATA {
    common::COMMAND_LONG_DATA {
        param1: params[0],
        param2: params[1],
        param3: params[2],
        param4: params[3],
        param5: params[4],
        param6: params[5],
        param7: params[6],
        command,
        target_system: 1,
        target_component: 1,
        confirmation: 0,
    }
}

/// The COMMAND_ACKs among `sent`, as (command number, result).
pub fn acks(sent: &[Sent]) -> Vec<(u16, common::MavResult)> {
    sent.iter()
        .filter_map(|s| match &s.message {
            MavMessage::COMMAND_ACK(a) => Some((u16::from_le_bytes([s.payload[0], s.payload[1]]), a.result)),
            _ => None,
        })
        .collect()
}

/// The STATUSTEXTs among `sent`.
pub fn texts(sent: &[Sent]) -> Vec<String> {
    sent.iter()
        .filter_map(|s| match &s.message {
            MavMessage::STATUSTEXT(t) => Some(t.text.to_str().unwrap().to_string()),
            _ => None,
        })
        .collect()
}

/// The PARAM_VALUEs among `sent`, as (name, value, index, count).
pub fn param_values(sent: &[Sent]) -> Vec<(String, f32, u16, u16)> {
    sent.iter()
        .filter_map(|s| match &s.message {
            MavMessage::PARAM_VALUE(p) => Some((
                String::from_utf8(p.param_id.iter().copied().take_while(|&b| b != 0).collect()).unwrap(),
                p.param_value,
                p.param_index,
                p.param_count,
            )),
            _ => None,
        })
        .collect()
}

pub fn name16(name: &str) -> mavlink::types::CharArray<16> {
    let mut b = [0u8; 16];
    b[..name.len()].copy_from_slice(name.as_bytes());
    mavlink::types::CharArray::new(b)
}

pub fn param_set(name: &str, value: f32) -> common::PARAM_SET_DATA {
    common::PARAM_SET_DATA {
        param_value: value,
        target_system: 1,
        target_component: 1,
        param_id: name16(name),
        param_type: common::MavParamType::MAV_PARAM_TYPE_REAL32,
    }
}
