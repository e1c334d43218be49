//! The parameter protocol: download, read, set.

use mavlink::dialects::common::{MavParamType, PARAM_VALUE_DATA};
use mavlink::types::CharArray;

use crate::link::{bump, for_us, Core, Room};
use crate::reader::Frame;
use crate::text::{Severity, Text};
use crate::vehicle::Vehicle;

/// Offset of PARAM_SET's `param_type` in its payload.
const PARAM_SET_TYPE_AT: usize = 22;
/// A PARAM_VALUE frame at its longest.
const PARAM_VALUE_FRAME: usize = 12 + PARAM_VALUE_DATA::ENCODED_LEN;

/// The name a PARAM_REQUEST_READ or PARAM_SET carries at `at` (16 bytes, NUL-padded; MAVLink 2
/// may have dropped trailing zeros), up to its first NUL. Bytes, not a `str`: the link never
/// needs the UTF-8 check (see [`crate::Link::send_text`]).
fn name_at(payload: &[u8], at: usize) -> &[u8] {
    let bytes = payload.get(at..).unwrap_or_default();
    let bytes = bytes.get(..16).unwrap_or(bytes);
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    bytes.get(..end).unwrap_or_default()
}

/// The little-endian word at `at`, zero-padded past the bytes received.
fn word_at(frame: &Frame<'_>, at: usize) -> [u8; 4] {
    [frame.byte(at), frame.byte(at + 1), frame.byte(at + 2), frame.byte(at + 3)]
}

/// A name as PARAM_VALUE carries it: 16 bytes, NUL-padded, no NUL when 16 long.
pub(crate) fn name_bytes(name: &str) -> CharArray<16> {
    let mut bytes = [0u8; 16];
    for (slot, &b) in bytes.iter_mut().zip(name.as_bytes()) {
        *slot = b;
    }
    CharArray::new(bytes)
}

impl<const TX: usize> Core<TX> {
    /// Queues the PARAM_VALUE of `index` with the value in force, as an answer; false when
    /// there is no such parameter or no room.
    fn param_value<V: Vehicle>(&mut self, index: u16, vehicle: &V) -> bool {
        let Some(param) = vehicle.param(index) else {
            return false;
        };
        let data = PARAM_VALUE_DATA {
            param_value: param.value,
            param_count: vehicle.param_count(),
            param_index: index,
            param_id: name_bytes(param.name),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        };
        self.send(&data, Room::Answer)
    }

    /// Room for one more PARAM_VALUE answer.
    fn param_value_fits(&self) -> bool {
        self.room(Room::Answer) >= PARAM_VALUE_FRAME
    }

    /// The PARAM_VALUE of `index` now, or, without room, owed: sent by a later tick.
    fn param_value_or_owe<V: Vehicle>(&mut self, index: u16, vehicle: &V) {
        if self.param_value_fits() {
            self.params_owed.remove(index);
            self.param_value(index, vehicle);
        } else {
            self.params_owed.insert(index);
        }
    }

    /// The PARAM_VALUEs owed to PARAM_SETs, in index order, as far as there is room.
    pub(crate) fn send_owed_params<V: Vehicle>(&mut self, vehicle: &V) {
        while self.param_value_fits() {
            let Some(index) = self.params_owed.first() else {
                return;
            };
            self.params_owed.remove(index);
            self.param_value(index, vehicle);
        }
    }

    /// The next PARAM_VALUE of a download, when its slot is due and the queue has room for an
    /// answer (a download waits rather than drops).
    pub(crate) fn param_download<V: Vehicle>(&mut self, vehicle: &V) {
        let Some(index) = self.param_cursor else {
            return;
        };
        if index >= vehicle.param_count() {
            self.param_cursor = None;
            return;
        }
        if !self.param_value_fits() {
            return;
        }
        let period = self.config.rates.param_ms;
        if self.schedule.param.due(self.now_ms, period.max(1)) {
            self.param_value(index, vehicle);
            self.param_cursor = Some(index + 1);
        }
    }

    /// PARAM_REQUEST_READ: by index, or by name when the index is -1 (MAVLink's rule; any other
    /// negative index is no parameter's).
    pub(crate) fn param_request_read<V: Vehicle>(&mut self, frame: &Frame<'_>, vehicle: &V) {
        // param_index (i16), target_system, target_component, param_id: read as bytes rather
        // than through the crate's generated decoder (a copy of code for each message).
        if !for_us(frame.byte(2), frame.byte(3)) {
            bump(&mut self.stats.not_for_us);
            return;
        }
        let param_index = i16::from_le_bytes([frame.byte(0), frame.byte(1)]);
        let index = match param_index {
            -1 => vehicle.param_index(name_at(frame.payload, 4)),
            index => match u16::try_from(index) {
                Ok(index) => Some(index),
                Err(_) => {
                    bump(&mut self.stats.param_bad_index);
                    return;
                }
            },
        };
        match index {
            Some(index) if index < vehicle.param_count() => {
                // No room: dropped and counted (`answers_dropped`); the station asks again.
                self.param_value(index, vehicle);
            }
            _ => bump(&mut self.stats.param_unknown),
        }
    }

    /// PARAM_SET: the value in force always goes back, taken or refused; a set taken also
    /// sends the value of every other parameter it changed, in index order. What the queue
    /// has no room for is owed and sent by the next ticks, never lost: a ground station that
    /// misses one keeps a table that is not the board's (and may save it).
    pub(crate) fn param_set<V: Vehicle>(&mut self, frame: &Frame<'_>, vehicle: &mut V) {
        // param_value (f32), target_system, target_component, param_id, param_type, read as
        // bytes (the type raw: any value gets an answer).
        if !for_us(frame.byte(4), frame.byte(5)) {
            bump(&mut self.stats.not_for_us);
            return;
        }
        let param_value = f32::from_le_bytes(word_at(frame, 0));
        let param_type = frame.byte(PARAM_SET_TYPE_AT);
        let name = name_at(frame.payload, 6);
        let Some(index) = vehicle.param_index(name) else {
            // Echoed only when it is ASCII: a STATUSTEXT is text, and no parameter's name is
            // anything else.
            let shown: &[u8] = if name.is_ascii() { name } else { &[] };
            let text = Text::new().push("PARAM_SET: no parameter ").push_bytes(shown);
            self.text(Severity::Warning, text, Room::Answer);
            return;
        };
        let outcome = if param_type != MavParamType::MAV_PARAM_TYPE_REAL32 as u8 {
            Err("type must be REAL32")
        } else if !param_value.is_finite() {
            Err("value must be finite")
        } else {
            vehicle.set_param(index, param_value)
        };
        self.param_value_or_owe(index, vehicle);
        match outcome {
            Ok(others) => {
                self.params_owed = self.params_owed.union(others);
                self.send_owed_params(vehicle);
            }
            Err(rule) => {
                self.text(Severity::Warning, Text::new().push_bytes(name).push(": ").push(rule), Room::Answer);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use mavlink::dialects::common::PARAM_REQUEST_READ_DATA;

    use crate::test_support::*;
    use crate::{Link, LinkConfig};

    #[test]
    fn a_negative_param_request_read_index_other_than_minus_one_is_not_looked_up_by_name() {
        let mut link: TestLink = Link::new(LinkConfig::DEFAULT);
        let mut mock = Mock::new();
        link.tick(0, &mut mock);
        drain(&mut link);
        for param_index in [-2, i16::MIN] {
            let read = PARAM_REQUEST_READ_DATA { param_index, target_system: 1, target_component: 1, param_id: name16("RC1_MIN") };
            link.receive(&v2(&read), 1, &mut mock);
            assert!(drain(&mut link).is_empty(), "index {param_index}: no answer");
        }
        assert_eq!(link.stats().param_bad_index, 2);
        assert_eq!(link.stats().param_unknown, 0);
        // -1 is "by name".
        let read = PARAM_REQUEST_READ_DATA { param_index: -1, target_system: 1, target_component: 1, param_id: name16("RC1_MIN") };
        link.receive(&v2(&read), 2, &mut mock);
        assert_eq!(param_values(&drain(&mut link)), [("RC1_MIN".to_string(), 1000.0, 1, 4)]);
    }

    #[test]
    fn requests_read_as_bytes_take_what_mavlink_2_truncated_as_zeros() {
        let mut link: TestLink = Link::new(LinkConfig::DEFAULT);
        let mut mock = Mock::new();
        link.tick(0, &mut mock);
        drain(&mut link);
        // Index 0 to every system, no name: all zeros, sent as one byte.
        let read = PARAM_REQUEST_READ_DATA { param_index: 0, target_system: 0, target_component: 0, param_id: name16("") };
        let frame = v2(&read);
        assert_eq!(frame[1], 1, "the payload truncated to its first byte");
        link.receive(&frame, 1, &mut mock);
        assert_eq!(param_values(&drain(&mut link)), [("RCMAP_ROLL".to_string(), 1.0, 0, 4)]);
        // A name of 16 bytes has no NUL; one shorter ends at its NUL.
        let mut set = param_set("RATE_ROLL_P_GAIN", 0.75);
        link.receive(&v2(&set), 2, &mut mock);
        assert_eq!(param_values(&drain(&mut link)), [("RATE_ROLL_P_GAIN".to_string(), 0.75, 3, 4)]);
        set.param_id = name16("RC1_MIN");
        set.param_value = 1100.0;
        link.receive(&v2(&set), 3, &mut mock);
        assert_eq!(param_values(&drain(&mut link)), [("RC1_MIN".to_string(), 1100.0, 1, 4)]);
        assert_eq!(link.stats().bad_payload, 0);
    }
}
