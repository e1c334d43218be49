//! One message in and out: MAVLink 2 frames from the `mavlink` crate's `*_DATA` structs, and
//! those structs from a checked frame's payload.
//!
//! Going per message keeps the dialect's `MavMessage` enum (and with it every message of the
//! common dialect) out of the image. Two things the crate does not do for us:
//! - its decoder refuses an enum field whose value the dialect does not list, where the link
//!   must still answer (a PARAM_SET of another type gets its echo), so such fields are read raw
//!   and swapped for a listed value before decoding ([`decode_with_raw`]);
//! - its structs carry no extension fields (see [`crate::reader::HANDLED`]) and cannot hold a
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

/// Decodes a payload, first reading the raw value of each listed enum field (`(offset,
/// width)`, little-endian, zero where the payload was truncated) and writing in its place a
/// value the dialect lists (`stand_in`), so that an unlisted value does not fail the decode.
/// Returns the message and the raw values in the order of `fields`.
pub fn decode_with_raw<D: MessageData, const F: usize>(payload: &[u8], fields: [(usize, usize, u32); F]) -> Option<(D, [u32; F])> {
    let mut padded = [0u8; MAX_PAYLOAD];
    let mut raw = [0u32; F];
    let len = pad_with_raw(payload, D::ENCODED_LEN, &fields, &mut raw, &mut padded)?;
    let message = D::deser(MavlinkVersion::V2, padded.get(..len)?).ok()?;
    Some((message, raw))
}

/// The part of [`decode_with_raw`] that does not depend on the message: not generic, one
/// copy for every message decoded so. Returns the length to decode.
fn pad_with_raw(
    payload: &[u8],
    encoded_len: usize,
    fields: &[(usize, usize, u32)],
    raw: &mut [u32],
    padded: &mut [u8; MAX_PAYLOAD],
) -> Option<usize> {
    let n = payload.len().min(MAX_PAYLOAD);
    if let (Some(dst), Some(src)) = (padded.get_mut(..n), payload.get(..n)) {
        dst.copy_from_slice(src);
    }
    for (value, &(at, width, stand_in)) in raw.iter_mut().zip(fields.iter()) {
        let field = padded.get_mut(at..at + width)?;
        let mut le = [0u8; 4];
        le.get_mut(..width)?.copy_from_slice(field);
        *value = u32::from_le_bytes(le);
        field.copy_from_slice(stand_in.to_le_bytes().get(..width)?);
    }
    Some(payload.len().max(encoded_len).min(MAX_PAYLOAD))
}

/// Decodes a payload whose enum fields are all checked by the crate.
pub fn decode<D: MessageData>(payload: &[u8]) -> Option<D> {
    D::deser(MavlinkVersion::V2, payload).ok()
}
