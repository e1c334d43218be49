//! Answers that tell a ground station what this board does not have, so that it stops asking:
//! no mission (MISSION_COUNT 0) and no file transfer (an FTP NAK).

use mavlink::dialects::common::{FILE_TRANSFER_PROTOCOL_DATA, MISSION_COUNT_DATA};

use crate::link::{bump, for_us, Core, Room};
use crate::reader::Frame;

/// MISSION_REQUEST_LIST's `mission_type` offset, and MISSION_COUNT's.
const REQUEST_TYPE_AT: usize = 2;
const COUNT_TYPE_AT: usize = 4;

/// FTP's opcodes of the answers, and the error of a NAK.
const FTP_ACK: u8 = 128;
const FTP_NAK: u8 = 129;
/// FTP error `UnknownCommand`: no FTP command is implemented.
pub const FTP_ERR_UNKNOWN_COMMAND: u8 = 7;

impl<const TX: usize> Core<TX> {
    /// MISSION_COUNT 0, of the mission type asked (fence and rally too: QGroundControl asks
    /// for all three while connecting).
    pub(crate) fn mission_request_list(&mut self, frame: &Frame<'_>) {
        // target_system, target_component, then mission_type, an extension field read raw (any
        // value is echoed).
        if !for_us(frame.byte(0), frame.byte(1)) {
            bump(&mut self.stats.not_for_us);
            return;
        }
        let mission_type = frame.byte(REQUEST_TYPE_AT);
        let count = MISSION_COUNT_DATA { count: 0, target_system: frame.system_id, target_component: frame.component_id };
        // mission_type is an extension field (see `reader::handled`), written raw.
        self.send_patched(&count, &[(COUNT_TYPE_AT, mission_type)], Room::Answer);
    }

    /// Any FTP request gets a NAK with `UnknownCommand`.
    pub(crate) fn file_transfer(&mut self, frame: &Frame<'_>) {
        // target_network, target_system, target_component, then the FTP payload, read as
        // bytes: seq u16, session, opcode, size, req_opcode, burst_complete, padding, offset
        // u32, data.
        let target_system = frame.byte(1);
        if target_system != 0 && target_system != crate::SYSTEM_ID {
            bump(&mut self.stats.not_for_us);
            return;
        }
        let [seq_lo, seq_hi, session, opcode] = [3, 4, 5, 6].map(|at| frame.byte(at));
        if opcode == FTP_ACK || opcode == FTP_NAK {
            return;
        }
        let seq = u16::from_le_bytes([seq_lo, seq_hi]).wrapping_add(1).to_le_bytes();
        let mut payload = [0u8; 251];
        payload[..6].copy_from_slice(&[seq[0], seq[1], session, FTP_NAK, 1, opcode]);
        payload[12] = FTP_ERR_UNKNOWN_COMMAND;
        let nak = FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: frame.system_id,
            target_component: frame.component_id,
            payload,
        };
        self.send(&nak, Room::Answer);
    }
}
