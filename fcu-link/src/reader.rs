//! The byte-at-a-time frame reader: MAVLink 1 and 2 in, whole checked frames out.
//!
//! It keeps only the frames of the messages the link handles ([`HANDLED`]): the CRC of a
//! frame covers its message's extra CRC, which only a known message has, so a frame of any
//! other message cannot be checked and is dropped as unknown. Every dropped frame is counted
//! by its reason ([`ReaderStats`]). Any byte sequence is safe: lengths come from the header
//! and are bounded by the buffer, and a bad frame sends the reader back to hunting for a start
//! byte.

use mavlink::dialects::common::{
    COMMAND_INT_DATA, COMMAND_LONG_DATA, FILE_TRANSFER_PROTOCOL_DATA, HEARTBEAT_DATA, MISSION_REQUEST_LIST_DATA, PARAM_REQUEST_LIST_DATA,
    PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
};
use mavlink::MessageData;

use crate::link::bump;

/// MAVLink 1 start byte.
pub const STX_V1: u8 = 0xFE;
/// MAVLink 2 start byte.
pub const STX_V2: u8 = 0xFD;
/// MAVLink 2 incompatibility flag: the frame carries a 13-byte signature.
pub const IFLAG_SIGNED: u8 = 0x01;

const V1_HEADER: usize = 6;
const V2_HEADER: usize = 10;
const CRC_LEN: usize = 2;
const SIGNATURE_LEN: usize = 13;
/// The longest frame kept: a MAVLink 2 header, 255 payload bytes and the CRC (a signature is
/// counted off, never stored).
pub const MAX_KEPT: usize = V2_HEADER + 255 + CRC_LEN;

/// A message the link handles: its id, extra CRC and the payload lengths it accepts.
#[derive(Clone, Copy, Debug)]
pub struct Handled {
    /// Message id.
    pub id: u32,
    /// The extra CRC byte of the message's definition.
    pub extra_crc: u8,
    /// MAVLink 1 payload length (no extension fields, no truncation): exact.
    pub v1_len: u8,
    /// MAVLink 2 payload length with every extension field; a frame may carry fewer bytes
    /// (trailing zeros are truncated), never more.
    pub v2_max_len: u8,
}

/// The crate is built without extension fields (its `mav2-message-extensions` feature pulls
/// std into the target build), so `ENCODED_LEN` is the MAVLink 1 length and the extension
/// bytes a MAVLink 2 frame may add are given here.
const fn handled<D: MessageData>(extension_bytes: u8) -> Handled {
    Handled { id: D::ID, extra_crc: D::EXTRA_CRC, v1_len: D::ENCODED_LEN as u8, v2_max_len: D::ENCODED_LEN as u8 + extension_bytes }
}

/// The messages whose frames are checked and kept. HEARTBEAT is kept (not decoded) because a
/// ground station's heartbeats are what tells the link it is still there.
// SET_MODE: marked deprecated by the dialect (see `command::SET_MODE_ID`).
#[allow(deprecated)]
pub const HANDLED: [Handled; 9] = [
    handled::<HEARTBEAT_DATA>(0),
    handled::<PARAM_REQUEST_READ_DATA>(0),
    handled::<PARAM_REQUEST_LIST_DATA>(0),
    handled::<PARAM_SET_DATA>(0),
    // mission_type, one byte.
    handled::<MISSION_REQUEST_LIST_DATA>(1),
    handled::<COMMAND_INT_DATA>(0),
    handled::<COMMAND_LONG_DATA>(0),
    handled::<FILE_TRANSFER_PROTOCOL_DATA>(0),
    handled::<mavlink::dialects::common::SET_MODE_DATA>(0),
];

/// The handled message with this id.
pub fn handled_message(id: u32) -> Option<&'static Handled> {
    HANDLED.iter().find(|h| h.id == id)
}

/// MAVLink protocol version of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Version {
    /// MAVLink 1 (start byte 0xFE).
    V1,
    /// MAVLink 2 (start byte 0xFD).
    V2,
}

/// A whole frame whose length and CRC checked out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame<'a> {
    /// Protocol version it came in.
    pub version: Version,
    /// Sender's sequence number.
    pub sequence: u8,
    /// Sender's system id.
    pub system_id: u8,
    /// Sender's component id.
    pub component_id: u8,
    /// Message id (one of [`HANDLED`]).
    pub message_id: u32,
    /// Payload as received (MAVLink 2 payloads may be truncated).
    pub payload: &'a [u8],
}

impl Frame<'_> {
    /// Payload byte `at`, 0 past the bytes received (MAVLink 2 drops a payload's trailing
    /// zeros). For messages whose fields the link reads as bytes: no decode through the
    /// crate's generated code, which is a copy of code for each message.
    pub fn byte(&self, at: usize) -> u8 {
        self.payload.get(at).copied().unwrap_or(0)
    }
}

/// Why frames were dropped, and how many were kept. Counters saturate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReaderStats {
    /// Frames kept (length and CRC good).
    pub frames: u32,
    /// Frames whose CRC did not match (noise, or a frame cut by a lost byte).
    pub bad_crc: u32,
    /// Frames of a handled message with a payload length its definition does not allow.
    pub bad_length: u32,
    /// Frames of a message the link does not handle (not checkable: no extra CRC).
    pub unknown_id: u32,
    /// Signed MAVLink 2 frames (the link does not do signing).
    pub signed: u32,
    /// MAVLink 2 frames with an incompatibility flag the link does not know.
    pub incompatible: u32,
    /// Bytes skipped while hunting for a start byte.
    pub noise_bytes: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// Hunting for a start byte.
    Idle,
    /// Collecting the header, payload and CRC into `buf` until `len == need`.
    Frame { need: usize },
    /// Counting off a signature, then deciding on the stored frame.
    Signature { left: usize },
}

/// Byte-at-a-time MAVLink 1/2 frame reader (see the module docs).
#[derive(Clone, Debug)]
pub struct FrameReader {
    buf: [u8; MAX_KEPT],
    len: usize,
    phase: Phase,
    stats: ReaderStats,
}

impl Default for FrameReader {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameReader {
    /// A reader hunting for a start byte.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_KEPT],
            len: 0,
            phase: Phase::Idle,
            stats: ReaderStats { frames: 0, bad_crc: 0, bad_length: 0, unknown_id: 0, signed: 0, incompatible: 0, noise_bytes: 0 },
        }
    }

    /// What was kept and dropped so far.
    pub fn stats(&self) -> ReaderStats {
        self.stats
    }

    /// Takes one byte; returns a frame when this byte completes a good one.
    pub fn push(&mut self, byte: u8) -> Option<Frame<'_>> {
        match self.phase {
            Phase::Idle => {
                let need = match byte {
                    STX_V1 => V1_HEADER,
                    STX_V2 => V2_HEADER,
                    _ => {
                        bump(&mut self.stats.noise_bytes);
                        return None;
                    }
                };
                self.buf[0] = byte;
                self.len = 1;
                self.phase = Phase::Frame { need };
                None
            }
            Phase::Frame { need } => {
                match self.buf.get_mut(self.len) {
                    Some(slot) => *slot = byte,
                    None => {
                        self.phase = Phase::Idle;
                        return None;
                    }
                }
                self.len += 1;
                if self.len == self.header_len() {
                    self.header_in();
                    return None;
                }
                if self.len < need {
                    return None;
                }
                if self.is_v2() && self.buf[2] & IFLAG_SIGNED != 0 {
                    self.phase = Phase::Signature { left: SIGNATURE_LEN };
                    return None;
                }
                self.phase = Phase::Idle;
                self.finish()
            }
            Phase::Signature { left } => {
                if left > 1 {
                    self.phase = Phase::Signature { left: left - 1 };
                    return None;
                }
                self.phase = Phase::Idle;
                self.finish()
            }
        }
    }

    fn is_v2(&self) -> bool {
        self.buf[0] == STX_V2
    }

    fn header_len(&self) -> usize {
        if self.is_v2() {
            V2_HEADER
        } else {
            V1_HEADER
        }
    }

    /// The header is in `buf`: it gives the frame's length, or shows that the candidate is no
    /// frame the link keeps (an unknown incompatibility flag, a message it does not handle, a
    /// length the message does not allow). Then the header's bytes after the start byte are
    /// read again: line noise holds start bytes followed by headers that claim any length, up
    /// to 255 bytes, and trusting that length swallowed the frames that followed it (after a
    /// burst of noise, a ground station's requests for seconds). A frame of a message the link
    /// does not handle has its payload hunted through the same way; a start byte in it rarely
    /// makes a header of a handled message, and a frame that begins within a header dropped is
    /// found by reading that header's bytes again. The header is at most 10 bytes and the
    /// shortest frame kept is longer, so reading them again never completes a frame.
    fn header_in(&mut self) {
        match self.header_verdict() {
            Ok(total) => self.phase = Phase::Frame { need: total },
            Err(counter) => {
                bump(counter);
                let mut again = [0u8; V2_HEADER];
                let n = self.len.saturating_sub(1);
                for (slot, &byte) in again.iter_mut().zip(self.buf.get(1..self.len).unwrap_or_default()) {
                    *slot = byte;
                }
                self.phase = Phase::Idle;
                self.len = 0;
                for &byte in again.get(..n).unwrap_or_default() {
                    // A header dropped among these reads its own bytes again before the rest
                    // (a recursion at most nine deep: each level holds fewer bytes).
                    let _never_whole = self.push(byte);
                }
            }
        }
    }

    /// The whole frame's length (header, payload, CRC) from the header in `buf`, or the
    /// counter of the reason it is no frame the link keeps.
    fn header_verdict(&mut self) -> Result<usize, &mut u32> {
        let v2 = self.is_v2();
        let payload_len = usize::from(self.buf[1]);
        if v2 && self.buf[2] & !IFLAG_SIGNED != 0 {
            // An unknown incompatibility flag may change the header's layout itself.
            return Err(&mut self.stats.incompatible);
        }
        let Some(handled) = handled_message(self.message_id()) else {
            return Err(&mut self.stats.unknown_id);
        };
        let length_ok = if v2 {
            payload_len >= 1 && payload_len <= usize::from(handled.v2_max_len)
        } else {
            payload_len == usize::from(handled.v1_len)
        };
        if !length_ok {
            return Err(&mut self.stats.bad_length);
        }
        Ok(self.header_len() + payload_len + CRC_LEN)
    }

    fn message_id(&self) -> u32 {
        if self.is_v2() {
            u32::from_le_bytes([self.buf[7], self.buf[8], self.buf[9], 0])
        } else {
            u32::from(self.buf[5])
        }
    }

    /// Decides on the complete frame in `buf[..len]`, whose header [`Self::header_in`] took.
    /// A bad CRC drops the whole candidate: its header named a message the link handles with
    /// a length it allows, which noise makes about once in 7,000 MAVLink 1 start bytes (and
    /// far less often for MAVLink 2, whose message ids are three bytes), so reading its bytes
    /// again is not worth a second buffer.
    fn finish(&mut self) -> Option<Frame<'_>> {
        let v2 = self.is_v2();
        let payload_len = usize::from(self.buf[1]);
        let message_id = self.message_id();
        let (sequence, system_id, component_id) =
            if v2 { (self.buf[4], self.buf[5], self.buf[6]) } else { (self.buf[2], self.buf[3], self.buf[4]) };
        let handled = handled_message(message_id)?;
        let header = self.header_len();
        let crc_at = header + payload_len;
        let (Some(covered), Some(&[lo, hi])) = (self.buf.get(1..crc_at), self.buf.get(crc_at..crc_at + 2)) else {
            return None;
        };
        let received = u16::from_le_bytes([lo, hi]);
        if crate::crc::checksum(covered, handled.extra_crc) != received {
            bump(&mut self.stats.bad_crc);
            return None;
        }
        if v2 && self.buf[2] & IFLAG_SIGNED != 0 {
            bump(&mut self.stats.signed);
            return None;
        }
        bump(&mut self.stats.frames);
        let payload = self.buf.get(header..crc_at)?;
        Some(Frame { version: if v2 { Version::V2 } else { Version::V1 }, sequence, system_id, component_id, message_id, payload })
    }
}
