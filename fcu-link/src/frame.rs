//! One message out: MAVLink 2 frames from the `mavlink` crate's `*_DATA` structs.
//!
//! Going per message keeps the dialect's `MavMessage` enum (and with it every message of the
//! common dialect) out of the image. What the link receives it reads as bytes at the fields'
//! offsets ([`crate::reader::Frame::byte`], [`crate::command::Command::decode`]): the crate's
//! decoder is a copy of code for each message, and refuses an enum field whose value the
//! dialect does not list, where the link must still answer (a PARAM_SET of another type gets
//! its echo). Its structs carry no extension fields (see [`crate::reader::HANDLED`]) and cannot hold a
//!   command number the dialect does not list, so a payload can be patched before the CRC is
//!   taken ([`encode_patched`]).

use mavlink::{MavlinkVersion, MessageData};

use crate::{COMPONENT_ID, SYSTEM_ID};

/// MAVLink 2 header length (start byte included).
pub const V2_HEADER: usize = 10;
/// The longest payload.
pub const MAX_PAYLOAD: usize = 255;
/// The longest unsigned MAVLink 2 frame.
pub const MAX_FRAME: usize = V2_HEADER + MAX_PAYLOAD + 2;

/// A byte to write at an offset of a serialized payload.
pub type Patch = (usize, u8);

/// Encodes `data` as an unsigned MAVLink 2 frame from us into `out`; returns its length.
pub fn encode<D: MessageData>(sequence: u8, data: &D, out: &mut [u8; MAX_FRAME]) -> usize {
    encode_patched(sequence, data, &[], out)
}

/// [`encode`], with `patches` written into the payload before truncation and CRC; a patch
/// past the message's length writes an extension field the crate's struct does not have.
pub fn encode_patched<D: MessageData>(sequence: u8, data: &D, patches: &[Patch], out: &mut [u8; MAX_FRAME]) -> usize {
    let mut payload = [0u8; MAX_PAYLOAD];
    serialize(data, &mut payload);
    encode_payload(sequence, Header::of::<D>(), &mut payload, patches, out)
}

/// Writes `data`'s fields into `payload` (the rest stays as it was).
pub(crate) fn serialize<D: MessageData>(data: &D, payload: &mut [u8; MAX_PAYLOAD]) {
    // The crate panics on a buffer shorter than the message: MAX_PAYLOAD holds any message.
    // Its structs have no extension fields, so both versions write the same bytes; asked for
    // MAVLink 1 it skips its own trim of trailing zeros, which `encode_payload` does anyway.
    data.ser(MavlinkVersion::V1, payload);
}

/// What a frame's header and CRC need of its message's definition.
#[derive(Clone, Copy, Debug)]
pub struct Header {
    /// Message id.
    pub id: u32,
    /// The extra CRC byte of the message's definition.
    pub extra_crc: u8,
    /// The payload's length with every field the crate's struct has.
    pub encoded_len: usize,
}

impl Header {
    /// `D`'s.
    pub const fn of<D: MessageData>() -> Self {
        Header { id: D::ID, extra_crc: D::EXTRA_CRC, encoded_len: D::ENCODED_LEN }
    }
}

/// Frames a serialized payload (see [`encode_patched`]). Not generic, so the patching,
/// truncation, header and CRC exist once however many messages are sent.
pub fn encode_payload(
    sequence: u8,
    header: Header,
    payload: &mut [u8; MAX_PAYLOAD],
    patches: &[Patch],
    out: &mut [u8; MAX_FRAME],
) -> usize {
    for &(at, byte) in patches {
        if let Some(slot) = payload.get_mut(at) {
            *slot = byte;
        }
    }
    let patched_len = patches.iter().map(|&(at, _)| at + 1).max().unwrap_or(0);
    let len = payload_len(payload, header.encoded_len.max(patched_len));
    let id = header.id.to_le_bytes();
    let start = [crate::reader::STX_V2, len as u8, 0, 0, sequence, SYSTEM_ID, COMPONENT_ID, id[0], id[1], id[2]];
    out[..V2_HEADER].copy_from_slice(&start);
    let end = V2_HEADER + len;
    if let (Some(dst), Some(src)) = (out.get_mut(V2_HEADER..end), payload.get(..len)) {
        dst.copy_from_slice(src);
    }
    let crc = out.get(1..end).map_or(0, |covered| crate::crc::checksum(covered, header.extra_crc));
    if let Some(dst) = out.get_mut(end..end + 2) {
        dst.copy_from_slice(&crc.to_le_bytes());
    }
    end + 2
}

/// The payload length sent of the first `full` bytes of `payload`: MAVLink 2 drops trailing
/// zero bytes of the payload but always keeps the first.
fn payload_len(payload: &[u8; MAX_PAYLOAD], full: usize) -> usize {
    let full = payload.get(..full).unwrap_or(payload);
    full.iter().rposition(|&b| b != 0).map_or(1, |last| last + 1)
}

/// The length of the frame [`encode_payload`] makes of `payload` (patches written in).
pub fn frame_len(header: Header, payload: &[u8; MAX_PAYLOAD]) -> usize {
    V2_HEADER + payload_len(payload, header.encoded_len) + 2
}
