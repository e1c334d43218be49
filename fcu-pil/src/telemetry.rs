//! What the firmware says on its UART, read back: the STATUS line (every change of flight
//! state, with the control tick it was taken at), the reference's TAB-separated debug line
//! (25 Hz: sticks, motor 1, attitude and targets) and the FATAL boot line. The harness knows
//! the firmware only through its pins and these lines, as someone with a serial cable does.

use fcu_core::supervisor::FlightState;

/// One parsed STATUS line.
#[derive(Clone, Debug, PartialEq)]
pub struct StatusLine {
    pub state: &'static str,
    pub armed: bool,
    pub blockers: Vec<String>,
    pub cal: String,
    pub failsafe: String,
    pub fault: String,
    pub vbat_v: f64,
    pub overruns: u32,
    /// Fields the firmware appends after `overruns` (e.g. `bus_errors`, `uart_dropped`, `rc_muted`).
    pub counters: Vec<(String, u64)>,
    /// Control ticks completed since boot when the snapshot was taken, if the line has it.
    pub tick: Option<u64>,
}

impl StatusLine {
    pub fn counter(&self, name: &str) -> Option<u64> {
        self.counters.iter().find(|(n, _)| n == name).map(|&(_, v)| v)
    }
}

/// One parsed debug line (angles in degrees, as printed: the reference's 57.3 per radian).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DebugLine {
    pub ele: i32,
    pub ail: i32,
    pub rud: i32,
    pub thr: i32,
    pub motor1_cmd: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    pub pitch_target_deg: f64,
    pub roll_target_deg: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Line {
    Status(StatusLine),
    Debug(DebugLine),
    Fatal(String),
    /// Banner, "... initialized and enabled", anything else.
    Other(String),
}

const STATES: [FlightState; 7] = [
    FlightState::Disarmed,
    FlightState::Arming,
    FlightState::Armed,
    FlightState::FailsafeLevel,
    FlightState::FailsafeOff,
    FlightState::Calibrating,
    FlightState::Fault,
];

/// The core's name for a state, as a `'static` string (the log's `state` column).
pub fn state_name(s: &str) -> Option<&'static str> {
    STATES.iter().map(|st| st.name()).find(|n| *n == s)
}

/// Parses one line (without its newline). A STATUS line with a field missing, out of order or
/// unparsable is an error naming it: the firmware's format is part of what is tested.
pub fn parse(line: &str) -> Result<Line, String> {
    if let Some(rest) = line.strip_prefix("STATUS ") {
        return parse_status(rest).map(Line::Status).map_err(|e| format!("STATUS line `{line}`: {e}"));
    }
    if line.starts_with("FATAL") {
        return Ok(Line::Fatal(line.to_string()));
    }
    let fields: Vec<&str> = line.split('\t').collect();
    if fields.len() == 9 {
        let int = |i: usize| {
            fields[i].trim().parse::<i32>().map_err(|_| format!("debug line `{line}`: field {} `{}` is not an integer", i + 1, fields[i]))
        };
        let float = |i: usize| {
            fields[i].trim().parse::<f64>().map_err(|_| format!("debug line `{line}`: field {} `{}` is not a number", i + 1, fields[i]))
        };
        return Ok(Line::Debug(DebugLine {
            ele: int(0)?,
            ail: int(1)?,
            rud: int(2)?,
            thr: int(3)?,
            motor1_cmd: float(4)?,
            pitch_deg: float(5)?,
            roll_deg: float(6)?,
            pitch_target_deg: float(7)?,
            roll_target_deg: float(8)?,
        }));
    }
    Ok(Line::Other(line.to_string()))
}

fn parse_status(rest: &str) -> Result<StatusLine, String> {
    let mut it = rest.split(' ');
    let mut field = |name: &str| -> Result<String, String> {
        let f = it.next().ok_or_else(|| format!("missing `{name}=`"))?;
        f.strip_prefix(name).and_then(|v| v.strip_prefix('=')).map(str::to_string).ok_or_else(|| format!("expected `{name}=`, found `{f}`"))
    };
    let state_word = field("state")?;
    let state = state_name(&state_word).ok_or_else(|| format!("unknown state `{state_word}`"))?;
    let armed = match field("armed")?.as_str() {
        "0" => false,
        "1" => true,
        other => return Err(format!("armed=`{other}`")),
    };
    let blockers_word = field("blockers")?;
    let blockers = if blockers_word == "none" { Vec::new() } else { blockers_word.split(',').map(str::to_string).collect() };
    let cal = field("cal")?;
    let failsafe = field("failsafe")?;
    let fault = field("fault")?;
    let vbat = field("vbat")?;
    let vbat_v = vbat.strip_suffix('V').and_then(|v| v.parse::<f64>().ok()).ok_or_else(|| format!("vbat=`{vbat}`"))?;
    let overruns = field("overruns")?.parse::<u32>().map_err(|_| "overruns is not a count".to_string())?;
    let mut counters = Vec::new();
    let mut tick = None;
    for f in it {
        let (k, v) = f.split_once('=').ok_or_else(|| format!("`{f}` is not name=value"))?;
        let v: u64 = v.parse().map_err(|_| format!("{k}=`{v}` is not a count"))?;
        if k == "tick" {
            tick = Some(v);
        } else {
            counters.push((k.to_string(), v));
        }
    }
    if armed != (state == FlightState::Armed.name() || state == FlightState::FailsafeLevel.name()) {
        return Err(format!("armed={} disagrees with state={state}", u8::from(armed)));
    }
    Ok(StatusLine { state, armed, blockers, cal, failsafe, fault, vbat_v, overruns, counters, tick })
}

/// Splits a byte stream into lines (LF-terminated; CR dropped), keeping a partial line.
#[derive(Clone, Debug, Default)]
pub struct LineSplitter {
    partial: Vec<u8>,
}

impl LineSplitter {
    pub fn push(&mut self, byte: u8) -> Option<String> {
        match byte {
            b'\n' => Some(String::from_utf8_lossy(&std::mem::take(&mut self.partial)).into_owned()),
            b'\r' => None,
            b => {
                // A line longer than any the firmware writes is garbage: cut it.
                if self.partial.len() < 4096 {
                    self.partial.push(b);
                }
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_status_line_parses_with_its_counters_and_tick() {
        let l = parse("STATUS state=armed armed=1 blockers=none cal=passed failsafe=none fault=none vbat=3.912V overruns=0 bus_errors=2 uart_dropped=0 tick=4000").unwrap();
        let Line::Status(s) = l else { panic!("not a status line") };
        assert_eq!(s.state, "armed");
        assert!(s.armed);
        assert_eq!(s.tick, Some(4000));
        assert_eq!(s.counter("bus_errors"), Some(2));
        assert!((s.vbat_v - 3.912).abs() < 1e-9);
    }

    #[test]
    fn a_status_line_with_a_wrong_armed_flag_is_refused() {
        assert!(parse("STATUS state=disarmed armed=1 blockers=none cal=passed failsafe=none fault=none vbat=3.912V overruns=0").is_err());
    }

    #[test]
    fn the_debug_line_parses_as_nine_fields() {
        let Line::Debug(d) = parse("-4\t0\t2\t120\t1100.500000\t0.100000\t-0.200000\t0.000000\t0.000000").unwrap() else { panic!() };
        assert_eq!(d.thr, 120);
        assert!((d.roll_deg + 0.2).abs() < 1e-9);
    }
}
