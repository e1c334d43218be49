//! The parameter protocol: download, read, set.

use mavlink::dialects::common::{MavParamType, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, PARAM_VALUE_DATA};
use mavlink::types::CharArray;

use crate::frame;
use crate::link::{bump, for_us, Core, Room};
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
    pub(crate) fn param_request_read<V: Vehicle>(&mut self, m: &PARAM_REQUEST_READ_DATA, vehicle: &V) {
        if !for_us(m.target_system, m.target_component) {
            bump(&mut self.stats.not_for_us);
            return;
        }
        let index = match m.param_index {
            -1 => vehicle.param_index(name_in(&m.param_id)),
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
            self.text(Severity::Warning, text, Room::Answer);
            return;
        };
        let outcome = if param_type != real32 {
            Err("type must be REAL32")
        } else if !m.param_value.is_finite() {
            Err("value must be finite")
        } else {
            vehicle.set_param(index, m.param_value)
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
    use fcu_core::Config;
    use fcu_params as parameters;
    use mavlink::dialects::common::PARAM_REQUEST_READ_DATA;

    use crate::station::Station;
    use crate::test_support::*;
    use crate::{Link, LinkConfig, Rates, Severity, Vehicle};

    /// Telemetry off but for a heartbeat a minute apart: what goes out is the answers.
    fn quiet_link() -> Link<512> {
        let rates = Rates {
            attitude_ms: 0,
            sys_status_ms: 0,
            battery_ms: 0,
            rc_channels_ms: 0,
            servo_output_ms: 0,
            heartbeat_ms: 60_000,
            param_ms: 10,
        };
        Link::new(LinkConfig { rates, ..LinkConfig::DEFAULT })
    }

    fn station() -> Station {
        Station::new(Config::default(), &Config::DEFAULT)
    }

    fn index(name: &str) -> usize {
        parameters::index_of(name.as_bytes()).unwrap()
    }

    const RCMAP: [&str; 4] = ["RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW"];

    /// The ground station's copy of the table, from a download, as it shows and saves it.
    fn downloaded(st: &Station) -> Vec<f32> {
        (0..st.param_count()).map(|i| st.param(i).unwrap().value).collect()
    }

    fn apply(copy: &mut [f32], sent: &[Sent]) {
        for (_, value, index, _) in param_values(sent) {
            copy[usize::from(index)] = value;
        }
    }

    #[test]
    fn a_param_set_that_changes_other_parameters_reports_them_too() {
        let mut link = quiet_link();
        let mut st = station();
        let mut copy = downloaded(&st);
        let before: Vec<f32> = RCMAP.iter().map(|n| copy[index(n)]).collect();
        assert_eq!(before, [1.0, 2.0, 3.0, 4.0]);
        link.receive(&v2(&param_set("RCMAP_ROLL", 3.0)), 0, &mut st);
        let sent = drain(&mut link);
        let echoed: Vec<(String, f32)> = param_values(&sent).into_iter().map(|p| (p.0, p.1)).collect();
        // The one set first, then the one it swapped with.
        assert_eq!(echoed, [("RCMAP_ROLL".to_string(), 3.0), ("RCMAP_THROTTLE".to_string(), 1.0)]);
        apply(&mut copy, &sent);
        assert_eq!(copy, downloaded(&st), "the ground station's copy is the board's table");
        let mut map: Vec<f32> = RCMAP.iter().map(|n| copy[index(n)]).collect();
        map.sort_by(f32::total_cmp);
        assert_eq!(map, [1.0, 2.0, 3.0, 4.0], "a permutation");
    }

    #[test]
    fn param_values_a_set_owes_go_out_on_the_next_tick_when_the_queue_is_full() {
        // A STATUSTEXT of 50 bytes is a 63-byte frame, of 10 bytes a 23-byte one; answers may
        // fill the queue up to its size less the telemetry's reserve.
        let fifty = [b'x'; 50];
        for (texts, sent_at_once) in [(&[&fifty[..], &fifty, &fifty, &fifty][..], 0), (&[&fifty[..], &fifty, &fifty, b"0123456789"][..], 1)]
        {
            let mut link = quiet_link();
            let mut st = station();
            link.tick(0, &mut st);
            for text in texts {
                assert!(link.send_text(Severity::Info, text));
            }
            let mut copy = downloaded(&st);
            link.receive(&v2(&param_set("RCMAP_ROLL", 3.0)), 1, &mut st);
            let at_once = drain(&mut link);
            assert_eq!(param_values(&at_once).len(), sent_at_once);
            link.tick(2, &mut st);
            let later = drain(&mut link);
            let names: Vec<String> = param_values(&at_once).into_iter().chain(param_values(&later)).map(|p| p.0).collect();
            assert_eq!(names, ["RCMAP_ROLL", "RCMAP_THROTTLE"]);
            apply(&mut copy, &at_once);
            apply(&mut copy, &later);
            assert_eq!(copy, downloaded(&st));
            let stats = link.stats();
            assert_eq!((stats.tx_dropped, stats.answers_dropped), (0, 0), "nothing lost");
        }
    }

    #[test]
    fn a_negative_param_request_read_index_other_than_minus_one_is_not_looked_up_by_name() {
        let mut link = quiet_link();
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
}
