//! A board on a local TCP port for the protocol's unit tests: a parameter table with bounds and
//! one ordering rule, answering as fcu-link does (a set always echoed with the value in force, a
//! refusal named in a STATUSTEXT `NAME: rule`), and able to lose one PARAM_VALUE of a download.

use std::io::Write;
use std::net::{TcpListener, TcpStream};
use std::sync::{Arc, Mutex};

use mavlink::dialects::common::{MavMessage, MavParamType, MavSeverity, PARAM_VALUE_DATA, STATUSTEXT_DATA};
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MavlinkReader};

use crate::connection::Io;

/// One parameter: name, value, bounds.
#[derive(Clone, Debug)]
pub struct MockParam {
    pub name: &'static str,
    pub value: f32,
    pub min: f32,
    pub max: f32,
}

/// What the board holds and what it was asked.
#[derive(Debug, Default)]
pub struct MockState {
    pub params: Vec<MockParam>,
    /// The index the first download leaves out.
    pub drop_index: Option<u16>,
    /// Indices asked for by PARAM_REQUEST_READ.
    pub reads_by_index: Vec<u16>,
    /// PARAM_SETs received (name, value).
    pub sets: Vec<(String, f32)>,
}

impl MockState {
    /// The rule a value breaks: its bounds, or `LO <= HI` between the parameters named so.
    fn refusal(&self, index: usize, value: f32) -> Option<&'static str> {
        let p = self.params.get(index)?;
        if value < p.min {
            return Some("below the minimum");
        }
        if value > p.max {
            return Some("above the maximum");
        }
        let get = |n: &str| self.params.iter().find(|q| q.name == n).map(|q| q.value);
        let (lo, hi) = match p.name {
            "LO" => (value, get("HI")?),
            "HI" => (get("LO")?, value),
            _ => return None,
        };
        (lo > hi).then_some("need LO <= HI")
    }
}

/// Serves one client on a free port; the port and the shared state.
pub fn serve(state: MockState) -> (u16, Arc<Mutex<MockState>>) {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("port").port();
    let state = Arc::new(Mutex::new(state));
    let shared = Arc::clone(&state);
    std::thread::spawn(move || {
        if let Ok((stream, _)) = listener.accept() {
            run(stream, &shared);
        }
    });
    (port, state)
}

fn send(out: &mut TcpStream, seq: &mut u8, msg: &MavMessage) {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(MavHeader { system_id: 1, component_id: 1, sequence: *seq }, msg);
    *seq = seq.wrapping_add(1);
    let _ = out.write_all(raw.raw_bytes());
}

fn value_msg(state: &MockState, index: usize) -> Option<MavMessage> {
    let p = state.params.get(index)?;
    Some(MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
        param_value: p.value,
        param_count: state.params.len() as u16,
        param_index: index as u16,
        param_id: p.name.into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    }))
}

fn run(stream: TcpStream, state: &Mutex<MockState>) {
    let Ok(mut out) = stream.try_clone() else { return };
    let mut reader = MavlinkReader::new(Io { inner: Box::new(stream), error: None });
    let mut seq = 0u8;
    let mut downloads = 0;
    while let Ok((_, msg)) = reader.read_any_message::<MavMessage>() {
        let Ok(mut st) = state.lock() else { return };
        let mut answers = Vec::new();
        match msg {
            MavMessage::HEARTBEAT(_) => {
                answers.push(MavMessage::HEARTBEAT(fcu_link::heartbeat::heartbeat(
                    fcu_core::supervisor::FlightState::Disarmed,
                    fcu_link::VerticalMode::Manual,
                )));
            }
            MavMessage::PARAM_REQUEST_LIST(_) => {
                downloads += 1;
                for i in 0..st.params.len() {
                    if downloads == 1 && st.drop_index == Some(i as u16) {
                        continue;
                    }
                    answers.extend(value_msg(&st, i));
                }
            }
            MavMessage::PARAM_REQUEST_READ(r) => {
                if let Ok(i) = u16::try_from(r.param_index) {
                    st.reads_by_index.push(i);
                    answers.extend(value_msg(&st, usize::from(i)));
                } else if let Some(i) = st.params.iter().position(|p| Ok(p.name) == r.param_id.to_str()) {
                    answers.extend(value_msg(&st, i));
                }
            }
            MavMessage::PARAM_SET(s) => {
                let name = s.param_id.to_str().unwrap_or("").to_string();
                st.sets.push((name.clone(), s.param_value));
                if let Some(i) = st.params.iter().position(|p| p.name == name) {
                    match st.refusal(i, s.param_value) {
                        None => {
                            if let Some(p) = st.params.get_mut(i) {
                                p.value = s.param_value;
                            }
                            answers.extend(value_msg(&st, i));
                        }
                        Some(rule) => {
                            answers.extend(value_msg(&st, i));
                            answers.push(MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                                severity: MavSeverity::MAV_SEVERITY_WARNING,
                                text: format!("{name}: {rule}").as_str().into(),
                            }));
                        }
                    }
                }
            }
            _ => {}
        }
        drop(st);
        for a in &answers {
            send(&mut out, &mut seq, a);
        }
    }
}
