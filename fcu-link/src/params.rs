//! The parameter protocol: download, read, set.

use mavlink::dialects::common::{MavParamType, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, PARAM_VALUE_DATA};
use mavlink::types::CharArray;

use crate::frame;
use crate::link::{bump, for_us, Core};
use crate::text::{Severity, Text};
use crate::vehicle::Vehicle;

/// Offset of PARAM_SET's `param_type` in its payload.
const PARAM_SET_TYPE_AT: usize = 22;
/// A PARAM_VALUE frame at its longest.
const PARAM_VALUE_FRAME: usize = 12 + PARAM_VALUE_DATA::ENCODED_LEN;

/// A name as PARAM_REQUEST_READ and PARAM_SET carry it, up to its first NUL. Bytes, not a
/// `str`: the link never needs the UTF-8 check (see [`crate::Link::send_text`]).
fn name_in(id: &CharArray<16>) -> &[u8] {
    let bytes: &[u8] = id.as_slice();
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    bytes.get(..end).unwrap_or_default()
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
    /// Queues the PARAM_VALUE of `index` with `value` (the value in force); false when there
    /// is no such parameter or no room.
    fn param_value<V: Vehicle>(&mut self, index: u16, value: Option<f32>, vehicle: &V) -> bool {
        let Some(param) = vehicle.param(index) else {
            return false;
        };
        let data = PARAM_VALUE_DATA {
            param_value: value.unwrap_or(param.value),
            param_count: vehicle.param_count(),
            param_index: index,
            param_id: name_bytes(param.name),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        };
        self.send(&data)
    }

    /// The next PARAM_VALUE of a download, when its slot is due and the queue has room (a
    /// download waits rather than drops).
    pub(crate) fn param_download<V: Vehicle>(&mut self, vehicle: &V) {
        let Some(index) = self.param_cursor else {
            return;
        };
        if index >= vehicle.param_count() {
            self.param_cursor = None;
            return;
        }
        if self.tx.free() < PARAM_VALUE_FRAME {
            return;
        }
        let period = self.config.rates.param_ms;
        if self.schedule.param.due(self.now_ms, period.max(1)) {
            self.param_value(index, None, vehicle);
            self.param_cursor = Some(index + 1);
        }
    }

    pub(crate) fn param_request_read<V: Vehicle>(&mut self, m: &PARAM_REQUEST_READ_DATA, vehicle: &V) {
        if !for_us(m.target_system, m.target_component) {
            bump(&mut self.stats.not_for_us);
            return;
        }
        let index = match u16::try_from(m.param_index) {
            Ok(index) => Some(index),
            Err(_) => vehicle.param_index(name_in(&m.param_id)),
        };
        let sent = index.is_some_and(|index| self.param_value(index, None, vehicle));
        if !sent && index.is_none_or(|i| i >= vehicle.param_count()) {
            bump(&mut self.stats.param_unknown);
        }
    }

    /// PARAM_SET: the value in force always goes back, taken or refused.
    pub(crate) fn param_set<V: Vehicle>(&mut self, payload: &[u8], vehicle: &mut V) {
        let real32 = MavParamType::MAV_PARAM_TYPE_REAL32 as u32;
        let Some((m, [param_type])) = frame::decode_with_raw::<PARAM_SET_DATA, 1>(payload, [(PARAM_SET_TYPE_AT, 1, real32)]) else {
            bump(&mut self.stats.bad_payload);
            return;
        };
        if !for_us(m.target_system, m.target_component) {
            bump(&mut self.stats.not_for_us);
            return;
        }
        let name = name_in(&m.param_id);
        let Some(index) = vehicle.param_index(name) else {
            // Echoed only when it is ASCII: a STATUSTEXT is text, and no parameter's name is
            // anything else.
            let shown: &[u8] = if name.is_ascii() { name } else { &[] };
            let text = Text::new().push("PARAM_SET: no parameter ").push_bytes(shown);
            self.text(Severity::Warning, text);
            return;
        };
        let outcome = if param_type != real32 {
            Err("type must be REAL32")
        } else if !m.param_value.is_finite() {
            Err("value must be finite")
        } else {
            vehicle.set_param(index, m.param_value)
        };
        match outcome {
            Ok(in_force) => {
                self.param_value(index, Some(in_force), vehicle);
            }
            Err(rule) => {
                self.param_value(index, None, vehicle);
                self.text(Severity::Warning, Text::new().push_bytes(name).push(": ").push(rule));
            }
        }
    }
}
