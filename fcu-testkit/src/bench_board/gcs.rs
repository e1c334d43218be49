//! The ground station's side of the wire: the frames it sends (built byte by byte with the
//! `mavlink` crate's ids and extra CRCs, not with fcu-link's encoder, so that any command number
//! and any parameter value can be sent), and the board's answers read back from the bytes it
//! sends.

use mavlink::dialects::common::{
    COMMAND_ACK_DATA, COMMAND_INT_DATA, COMMAND_LONG_DATA, HEARTBEAT_DATA, PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA,
    PARAM_SET_DATA, PARAM_VALUE_DATA, STATUSTEXT_DATA,
};
use mavlink::MessageData;

/// The ground station's system and component ids.
pub const GCS_SYSTEM: u8 = 255;
pub const GCS_COMPONENT: u8 = 190;

/// `MAV_PARAM_TYPE_REAL32`.
const REAL32: u8 = 9;

/// Command numbers the bench sends ([`GcsFrame::Command`]).
pub mod cmd {
    pub const PREFLIGHT_CALIBRATION: u16 = 241;
    pub const PREFLIGHT_STORAGE: u16 = 245;
    pub const PREFLIGHT_REBOOT_SHUTDOWN: u16 = 246;
    pub const DO_MOTOR_TEST: u16 = 209;
    pub const COMPONENT_ARM_DISARM: u16 = 400;
    pub const GET_HOME_POSITION: u16 = 410;
}

/// One message from the ground station.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GcsFrame {
    Heartbeat,
    /// PARAM_SET of the parameter named `name` (any bytes, up to 16) to `value` (any bits).
    ParamSet {
        name: [u8; 16],
        value: f32,
    },
    /// PARAM_REQUEST_READ by index, or by name when `index` is -1.
    ParamRead {
        index: i16,
        name: [u8; 16],
    },
    ParamList,
    /// COMMAND_LONG (or COMMAND_INT when `int`; then params 5 and 6 are sent as integers).
    Command {
        command: u16,
        params: [f32; 7],
        int: bool,
    },
}

/// A parameter name as MAVLink's 16-byte `param_id` (cut at 16, NUL-padded).
pub fn name16(name: &str) -> [u8; 16] {
    let mut out = [0u8; 16];
    for (o, b) in out.iter_mut().zip(name.bytes()) {
        *o = b;
    }
    out
}

impl GcsFrame {
    /// The frame as MAVLink 2 bytes, with a good CRC, sequence `sequence`, addressed to the
    /// board (system 1, component 1).
    pub fn encode(&self, sequence: u8) -> Vec<u8> {
        let (id, extra, payload) = match *self {
            GcsFrame::Heartbeat => {
                // GCS type, invalid autopilot, no mode, active, MAVLink 3.
                (HEARTBEAT_DATA::ID, HEARTBEAT_DATA::EXTRA_CRC, vec![0, 0, 0, 0, 6, 8, 0, 4, 3])
            }
            GcsFrame::ParamSet { name, value } => {
                let mut p = value.to_le_bytes().to_vec();
                p.extend_from_slice(&[1, 1]);
                p.extend_from_slice(&name);
                p.push(REAL32);
                (PARAM_SET_DATA::ID, PARAM_SET_DATA::EXTRA_CRC, p)
            }
            GcsFrame::ParamRead { index, name } => {
                let mut p = index.to_le_bytes().to_vec();
                p.extend_from_slice(&[1, 1]);
                p.extend_from_slice(&name);
                (PARAM_REQUEST_READ_DATA::ID, PARAM_REQUEST_READ_DATA::EXTRA_CRC, p)
            }
            GcsFrame::ParamList => (PARAM_REQUEST_LIST_DATA::ID, PARAM_REQUEST_LIST_DATA::EXTRA_CRC, vec![1, 1]),
            GcsFrame::Command { command, params, int: false } => {
                let mut p: Vec<u8> = params.iter().flat_map(|v| v.to_le_bytes()).collect();
                p.extend_from_slice(&command.to_le_bytes());
                p.extend_from_slice(&[1, 1, 0]);
                (COMMAND_LONG_DATA::ID, COMMAND_LONG_DATA::EXTRA_CRC, p)
            }
            GcsFrame::Command { command, params, int: true } => {
                let mut p: Vec<u8> = params[..4].iter().flat_map(|v| v.to_le_bytes()).collect();
                p.extend_from_slice(&(params[4] as i32).to_le_bytes());
                p.extend_from_slice(&(params[5] as i32).to_le_bytes());
                p.extend_from_slice(&params[6].to_le_bytes());
                p.extend_from_slice(&command.to_le_bytes());
                // Targets, frame (MAV_FRAME_GLOBAL), current, autocontinue.
                p.extend_from_slice(&[1, 1, 0, 0, 0]);
                (COMMAND_INT_DATA::ID, COMMAND_INT_DATA::EXTRA_CRC, p)
            }
        };
        let id = id.to_le_bytes();
        let mut f = vec![0xFD, payload.len() as u8, 0, 0, sequence, GCS_SYSTEM, GCS_COMPONENT, id[0], id[1], id[2]];
        f.extend_from_slice(&payload);
        let crc = mavlink::calculate_crc(&f[1..], extra);
        f.extend_from_slice(&crc.to_le_bytes());
        f
    }
}

/// One answer of the board that the checks read.
#[derive(Clone, Debug, PartialEq)]
pub enum Answer {
    /// PARAM_VALUE: the parameter's name (NULs trimmed), value and index.
    ParamValue {
        name: String,
        value: f32,
        index: u16,
    },
    /// COMMAND_ACK: the command's number and `MAV_RESULT` (0 accepted).
    CommandAck {
        command: u16,
        result: u8,
    },
    StatusText {
        severity: u8,
        text: String,
    },
    /// Any other message the board sends (telemetry).
    Other {
        id: u32,
    },
}

/// Why the board's output is not whole MAVLink 2 frames.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Malformed(pub String);

/// Splits the board's output into frames as it arrives (frames may span calls) and reads the
/// answers the checks need. The board's output must be whole MAVLink 2 frames from system 1,
/// component 1, back to back, each with a good CRC where its message is one read here.
#[derive(Clone, Debug, Default)]
pub struct AnswerReader {
    buf: Vec<u8>,
}

impl AnswerReader {
    /// Takes `bytes` and returns the answers of the frames they complete.
    pub fn push(&mut self, bytes: &[u8]) -> Result<Vec<Answer>, Malformed> {
        self.buf.extend_from_slice(bytes);
        let mut out = Vec::new();
        let mut at = 0;
        while self.buf.len() >= at + 12 {
            let f = &self.buf[at..];
            if f[0] != 0xFD {
                return Err(Malformed(format!("frame start {:#04x}", f[0])));
            }
            let len = usize::from(f[1]);
            if f.len() < 12 + len {
                break;
            }
            if (f[5], f[6]) != (1, 1) {
                return Err(Malformed(format!("sender {}/{}", f[5], f[6])));
            }
            let id = u32::from_le_bytes([f[7], f[8], f[9], 0]);
            let payload = &f[10..10 + len];
            let crc = u16::from_le_bytes([f[10 + len], f[11 + len]]);
            let extra = match id {
                PARAM_VALUE_DATA::ID => Some(PARAM_VALUE_DATA::EXTRA_CRC),
                COMMAND_ACK_DATA::ID => Some(COMMAND_ACK_DATA::EXTRA_CRC),
                STATUSTEXT_DATA::ID => Some(STATUSTEXT_DATA::EXTRA_CRC),
                _ => None,
            };
            if let Some(extra) = extra {
                if mavlink::calculate_crc(&f[1..10 + len], extra) != crc {
                    return Err(Malformed(format!("bad CRC in message {id}")));
                }
            }
            // MAVLink 2 cuts trailing zeros off a payload.
            let mut p = payload.to_vec();
            p.resize(64, 0);
            let text = |b: &[u8]| String::from_utf8_lossy(&b[..b.iter().position(|&c| c == 0).unwrap_or(b.len())]).into_owned();
            out.push(match id {
                PARAM_VALUE_DATA::ID => Answer::ParamValue {
                    name: text(&p[8..24]),
                    value: f32::from_le_bytes([p[0], p[1], p[2], p[3]]),
                    index: u16::from_le_bytes([p[6], p[7]]),
                },
                COMMAND_ACK_DATA::ID => Answer::CommandAck { command: u16::from_le_bytes([p[0], p[1]]), result: p[2] },
                STATUSTEXT_DATA::ID => Answer::StatusText { severity: p[0], text: text(&p[1..51]) },
                _ => Answer::Other { id },
            });
            at += 12 + len;
        }
        self.buf.drain(..at);
        Ok(out)
    }

    /// Bytes of a frame not complete yet.
    pub fn partial(&self) -> usize {
        self.buf.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_built_here_are_read_by_the_links_reader() {
        let frames = [
            GcsFrame::Heartbeat,
            GcsFrame::ParamSet { name: name16("ANGLE_MAX"), value: 60.0 },
            GcsFrame::ParamRead { index: -1, name: name16("RCMAP_ROLL") },
            GcsFrame::ParamList,
            GcsFrame::Command { command: cmd::PREFLIGHT_REBOOT_SHUTDOWN, params: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], int: false },
            GcsFrame::Command { command: cmd::DO_MOTOR_TEST, params: [1.0, 0.0, 5.0, 2.0, 1.0, 0.0, 0.0], int: true },
        ];
        let mut reader = fcu_link::FrameReader::new();
        let mut ids = Vec::new();
        for (k, f) in frames.iter().enumerate() {
            for b in f.encode(k as u8) {
                if let Some(frame) = reader.push(b) {
                    ids.push(frame.message_id);
                }
            }
        }
        assert_eq!(ids, [0, 23, 20, 21, 76, 75]);
    }
}
