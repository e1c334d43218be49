//! What the firmware says on its UART, read back: the STATUS line (every change of flight
//! state, with the control tick it was taken at), the reference's TAB-separated debug line
//! (25 Hz: sticks, motor 1, attitude and targets) and the FATAL boot line. The harness knows
//! the firmware only through its pins and these lines, as someone with a serial cable does.

use fcu_core::telemetry::{parse_status_line, StatusFields};

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
    /// Read by fcu-core's own reader of the line it writes.
    Status(StatusFields),
    Debug(DebugLine),
    Fatal(String),
    /// Banner, "... initialized and enabled", anything else.
    Other(String),
}

/// Parses one line (without its newline). A STATUS line that is not exactly what fcu-core
/// writes (a field missing, out of order, unknown or contradicting the state) is an error
/// naming it: the firmware's format is part of what is tested.
pub fn parse(line: &str) -> Result<Line, String> {
    if line.starts_with("STATUS ") {
        return parse_status_line(line).map(Line::Status).map_err(|e| format!("STATUS line `{line}`: {e}"));
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

    /// The board was reset: the line being sent was cut there, and what follows is another
    /// line (the boot banner). Returns the cut part, if any.
    pub fn cut(&mut self) -> Option<String> {
        (!self.partial.is_empty()).then(|| String::from_utf8_lossy(&std::mem::take(&mut self.partial)).into_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fcu_core::baro::BaroFault;
    use fcu_core::supervisor::FlightState;
    use fcu_core::telemetry::VerticalMode;

    #[test]
    fn a_status_line_parses_with_its_counters_and_tick() {
        let l = parse("STATUS state=armed armed=1 blockers=none cal=passed failsafe=none fault=none vmode=hold alt_mode=1 target=1.250 baro=stuck vbat=3.912V overruns=0 bus_errors=2 uart_dropped=0 rc_muted=1 tick=4000").unwrap();
        let Line::Status(s) = l else { panic!("not a status line") };
        assert_eq!(s.state, FlightState::Armed);
        assert!(s.armed());
        assert_eq!((s.tick, s.bus_errors, s.radio_mutes, s.battery_mv), (4000, 2, 1, 3912));
        assert_eq!(
            (s.vertical.mode, s.vertical.target_mm, s.vertical.baro_fault),
            (VerticalMode::Hold, Some(1250), Some(BaroFault::Stuck))
        );
    }

    #[test]
    fn a_malformed_status_line_is_an_error_naming_the_field_and_quoting_the_line() {
        let line = "STATUS state=disarmed armed=1 blockers=none cal=passed failsafe=none fault=none vmode=manual alt_mode=0 target=none baro=ok vbat=3.912V overruns=0 bus_errors=0 uart_dropped=0 rc_muted=0 tick=1";
        let e = parse(line).unwrap_err();
        assert!(e.contains("`armed=` disagrees with the state") && e.contains(line), "{e}");
        let e = parse("STATUS state=armed armed=1 blockers=none cal=passed failsafe=none fault=none vmode=manual alt_mode=0 target=none baro=ok vbat=3.912V overruns=0").unwrap_err();
        assert!(e.contains("`bus_errors=` missing"), "{e}");
    }

    #[test]
    fn a_line_cut_by_a_reset_is_not_joined_to_the_next() {
        let mut sp = LineSplitter::default();
        let pushed = |sp: &mut LineSplitter, text: &str| text.bytes().filter_map(|b| sp.push(b)).collect::<Vec<_>>();
        assert!(pushed(&mut sp, "STATUS state=armed armed=1 b").is_empty());
        assert_eq!(sp.cut().as_deref(), Some("STATUS state=armed armed=1 b"));
        assert_eq!(sp.cut(), None);
        assert_eq!(pushed(&mut sp, "STEVAL banner\n"), ["STEVAL banner"]);
    }

    #[test]
    fn the_debug_line_parses_as_nine_fields() {
        let Line::Debug(d) = parse("-4\t0\t2\t120\t1100.500000\t0.100000\t-0.200000\t0.000000\t0.000000").unwrap() else { panic!() };
        assert_eq!(d.thr, 120);
        assert!((d.roll_deg + 0.2).abs() < 1e-9);
    }
}
