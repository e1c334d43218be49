//! `params pull`, `push`, `diff`: MAVLink's parameter protocol from the ground station's side.
//!
//! - The download: PARAM_REQUEST_LIST, every PARAM_VALUE kept by its index; when the stream
//!   falls quiet, each missing index is asked for again with PARAM_REQUEST_READ (a frame lost
//!   on a serial line costs one request, not a new download).
//! - A set: PARAM_SET, and the PARAM_VALUE echo of that name carries the value in force. A
//!   refused set echoes the old value, and the board names the rule in a STATUSTEXT
//!   `NAME: rule`.
//! - A push sets, in file order, every parameter whose value differs from the board's, and
//!   sets the refused ones again while a pass makes progress: a file may hold a whole radio
//!   whose endpoints are valid together, not in every order one at a time (a minimum above
//!   the old maximum is refused until the maximum has moved).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use mavlink::dialects::common::{
    MavMessage, MavParamType, PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, PARAM_VALUE_DATA,
};

use crate::connection::{Connection, LinkError, BOARD_COMPONENT, BOARD_SYSTEM};
use crate::param_file::Entry;

/// How long the download may be quiet before the missing indices are asked for one by one.
const QUIET: Duration = Duration::from_millis(1500);
/// How long one PARAM_REQUEST_READ or PARAM_SET waits for its PARAM_VALUE.
const ANSWER: Duration = Duration::from_millis(1000);
/// Requests per parameter before it counts as unanswered.
const TRIES: usize = 3;
/// How long a refused set waits for the STATUSTEXT that names the rule.
const RULE_WAIT: Duration = Duration::from_millis(1000);

/// The board's parameters, in its index order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoardParams {
    pub list: Vec<(String, f32)>,
}

impl BoardParams {
    pub fn by_name(&self) -> BTreeMap<String, f32> {
        self.list.iter().cloned().collect()
    }
}

fn name_of(p: &PARAM_VALUE_DATA) -> String {
    p.param_id.to_str().unwrap_or("").to_string()
}

/// Downloads every parameter; `first_answer` bounds the wait for the first PARAM_VALUE.
pub fn pull(conn: &mut Connection, first_answer: Duration) -> Result<BoardParams, LinkError> {
    conn.send(&MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA { target_system: BOARD_SYSTEM, target_component: BOARD_COMPONENT }))?;
    let mut got: BTreeMap<u16, (String, f32)> = BTreeMap::new();
    let mut count: Option<u16> = None;
    // The stream of the download, until it is complete or no PARAM_VALUE has come for a while
    // (telemetry keeps coming meanwhile: the quiet is the parameters').
    let mut quiet_until = Instant::now() + first_answer.max(QUIET);
    while count.is_none_or(|c| got.len() < usize::from(c)) {
        let Some(left) = quiet_until.checked_duration_since(Instant::now()) else { break };
        if let Some(MavMessage::PARAM_VALUE(p)) = conn.recv(left)? {
            count = Some(p.param_count);
            if p.param_index < p.param_count {
                got.insert(p.param_index, (name_of(&p), p.param_value));
            }
            quiet_until = Instant::now() + QUIET;
        }
    }
    let Some(count) = count else {
        return Err(LinkError(format!(
            "--link {}: the board sent no PARAM_VALUE within {:.0} s of PARAM_REQUEST_LIST",
            conn.address(),
            first_answer.max(QUIET).as_secs_f64()
        )));
    };
    // The indices the stream lost, one by one.
    for index in 0..count {
        if got.contains_key(&index) {
            continue;
        }
        for _ in 0..TRIES {
            conn.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                param_index: i16::try_from(index).unwrap_or(i16::MAX),
                target_system: BOARD_SYSTEM,
                target_component: BOARD_COMPONENT,
                param_id: [0u8; 16].into(),
            }))?;
            let answered = wait_for(conn, ANSWER, |p| p.param_index == index, &mut |p| {
                if p.param_index < count {
                    got.insert(p.param_index, (name_of(p), p.param_value));
                }
            })?;
            if answered.is_some() {
                break;
            }
        }
    }
    let missing: Vec<String> = (0..count).filter(|i| !got.contains_key(i)).map(|i| i.to_string()).collect();
    if !missing.is_empty() {
        return Err(LinkError(format!(
            "--link {}: the board did not send parameter {} of {count}, asked {TRIES} times each",
            conn.address(),
            missing.join(", ")
        )));
    }
    Ok(BoardParams { list: got.into_values().collect() })
}

/// Waits up to `timeout` for a PARAM_VALUE matching `want`; every PARAM_VALUE on the way goes
/// to `seen` (an echo of another parameter that a set moved with it, a late download frame).
fn wait_for(
    conn: &mut Connection,
    timeout: Duration,
    want: impl Fn(&PARAM_VALUE_DATA) -> bool,
    seen: &mut dyn FnMut(&PARAM_VALUE_DATA),
) -> Result<Option<PARAM_VALUE_DATA>, LinkError> {
    let deadline = Instant::now() + timeout;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        if let Some(MavMessage::PARAM_VALUE(p)) = conn.recv(left)? {
            seen(&p);
            if want(&p) {
                return Ok(Some(p));
            }
        }
    }
    Ok(None)
}

/// What became of one set.
#[derive(Clone, Debug, PartialEq)]
pub enum SetOutcome {
    /// The board took the value.
    Taken,
    /// The board kept `in_force`; `rule` is what its STATUSTEXT named, if one came.
    Refused { in_force: f32, rule: Option<String> },
}

/// Sets `name` to `value` and reads the echo; `board` follows every PARAM_VALUE seen.
pub fn set(conn: &mut Connection, name: &str, value: f32, board: &mut BTreeMap<String, f32>) -> Result<SetOutcome, LinkError> {
    for _ in 0..TRIES {
        conn.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: value,
            target_system: BOARD_SYSTEM,
            target_component: BOARD_COMPONENT,
            param_id: name.into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }))?;
        let echo = wait_for(conn, ANSWER, |p| name_of(p) == name, &mut |p| {
            board.insert(name_of(p), p.param_value);
        })?;
        let Some(echo) = echo else { continue };
        if echo.param_value == value {
            return Ok(SetOutcome::Taken);
        }
        let prefix = format!("{name}: ");
        let deadline = Instant::now() + RULE_WAIT;
        let mut rule = None;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match conn.recv(left)? {
                Some(MavMessage::STATUSTEXT(t)) => {
                    let text = t.text.to_str().unwrap_or("").trim_end().to_string();
                    if let Some(r) = text.strip_prefix(&prefix) {
                        rule = Some(r.to_string());
                        break;
                    }
                }
                Some(MavMessage::PARAM_VALUE(p)) => {
                    board.insert(name_of(&p), p.param_value);
                }
                _ => {}
            }
        }
        return Ok(SetOutcome::Refused { in_force: echo.param_value, rule });
    }
    Err(LinkError(format!("--link {}: no PARAM_VALUE echo for {name} after {TRIES} PARAM_SETs", conn.address())))
}

/// One refused entry of a push.
#[derive(Clone, Debug, PartialEq)]
pub struct Refused {
    pub entry: Entry,
    pub in_force: f32,
    pub rule: Option<String>,
}

/// What a push did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PushReport {
    /// (name, old value, new value).
    pub taken: Vec<(String, f32, f32)>,
    pub refused: Vec<Refused>,
    /// Entries that already held the file's value.
    pub unchanged: usize,
}

/// Sets every entry whose value differs from `board` (which follows the echoes), retrying the
/// refused ones while a pass takes at least one; `progress` hears of each taken set.
pub fn push(
    conn: &mut Connection,
    entries: &[Entry],
    board: &mut BTreeMap<String, f32>,
    progress: &mut dyn FnMut(&str, f32, f32),
) -> Result<PushReport, LinkError> {
    let mut report = PushReport::default();
    let mut pending: Vec<&Entry> = entries.iter().filter(|e| board.get(&e.name) != Some(&e.value)).collect();
    report.unchanged = entries.len() - pending.len();
    loop {
        let mut refused = Vec::new();
        let mut took_one = false;
        for e in pending {
            let Some(&old) = board.get(&e.name) else { continue };
            if old == e.value {
                // An earlier set moved it there (a radio map entry swaps with the one it takes).
                continue;
            }
            match set(conn, &e.name, e.value, board)? {
                SetOutcome::Taken => {
                    took_one = true;
                    board.insert(e.name.clone(), e.value);
                    progress(&e.name, old, e.value);
                    report.taken.push((e.name.clone(), old, e.value));
                }
                SetOutcome::Refused { in_force, rule } => refused.push((e, in_force, rule)),
            }
        }
        if refused.is_empty() || !took_one {
            report.refused = refused.into_iter().map(|(e, in_force, rule)| Refused { entry: e.clone(), in_force, rule }).collect();
            return Ok(report);
        }
        pending = refused.into_iter().map(|(e, _, _)| e).collect();
    }
}

/// Reads one parameter by name: its value, `None` when the board did not answer.
pub fn read_by_name(conn: &mut Connection, name: &str) -> Result<Option<f32>, LinkError> {
    for _ in 0..TRIES {
        conn.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system: BOARD_SYSTEM,
            target_component: BOARD_COMPONENT,
            param_id: name.into(),
        }))?;
        if let Some(p) = wait_for(conn, ANSWER, |p| name_of(p) == name, &mut |_| {})? {
            return Ok(Some(p.param_value));
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::address::LinkAddress;
    use crate::mock_board::{serve, MockParam, MockState};
    use crate::param_file;

    fn table() -> Vec<MockParam> {
        ["A", "B", "C", "D", "E"]
            .iter()
            .enumerate()
            .map(|(i, &name)| MockParam { name, value: i as f32, min: 0.0, max: 100.0 })
            .chain([
                MockParam { name: "LO", value: 10.0, min: 0.0, max: 100.0 },
                MockParam { name: "HI", value: 20.0, min: 0.0, max: 100.0 },
            ])
            .collect()
    }

    fn connect(port: u16) -> Connection {
        let link = LinkAddress::Tcp { host: "127.0.0.1".into(), port };
        let mut conn = Connection::open(&link, Duration::from_secs(5)).unwrap();
        conn.wait_for_board(Duration::from_secs(5)).unwrap();
        conn
    }

    #[test]
    fn a_value_the_download_lost_is_asked_for_by_its_index() {
        let (port, state) = serve(MockState { params: table(), drop_index: Some(2), ..MockState::default() });
        let mut conn = connect(port);
        let board = pull(&mut conn, Duration::from_secs(5)).unwrap();
        let names: Vec<&str> = board.list.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["A", "B", "C", "D", "E", "LO", "HI"]);
        assert_eq!(board.list[2], ("C".to_string(), 2.0));
        assert_eq!(state.lock().unwrap().reads_by_index, [2]);
    }

    #[test]
    fn a_push_names_refusals_and_retries_what_the_order_refused() {
        let (port, state) = serve(MockState { params: table(), ..MockState::default() });
        let mut conn = connect(port);
        let mut board = pull(&mut conn, Duration::from_secs(5)).unwrap().by_name();
        // LO above the old HI is refused until HI has moved; A is out of range; B is unchanged.
        let entries = param_file::parse("LO 30\nHI 40\nA 500\nB 1\n").unwrap();
        let mut seen = Vec::new();
        let report = push(&mut conn, &entries, &mut board, &mut |n, old, new| seen.push((n.to_string(), old, new))).unwrap();
        assert_eq!(report.unchanged, 1);
        assert_eq!(seen, [("HI".to_string(), 20.0, 40.0), ("LO".to_string(), 10.0, 30.0)]);
        assert_eq!(report.refused.len(), 1);
        let r = &report.refused[0];
        assert_eq!((r.entry.name.as_str(), r.entry.line, r.in_force, r.rule.as_deref()), ("A", 3, 0.0, Some("above the maximum")));
        let st = state.lock().unwrap();
        let values: Vec<(&str, f32)> = st.params.iter().map(|p| (p.name, p.value)).collect();
        assert_eq!(values, [("A", 0.0), ("B", 1.0), ("C", 2.0), ("D", 3.0), ("E", 4.0), ("LO", 30.0), ("HI", 40.0)]);
        // B, already in force, was never sent.
        assert!(st.sets.iter().all(|(n, _)| n != "B"));
    }
}
