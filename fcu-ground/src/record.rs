//! `record`: the board's telemetry as `flight.csv` and `flight.svg`, the files `fcu-sim fly`
//! writes, so a flight on the board and one in the simulator are read the same way.
//!
//! One row per ATTITUDE (25 Hz at the board's default rate), carrying the latest of the other
//! messages. The header is fcu-log's [`CSV_HEADER`] and each row goes through fcu-log's
//! writer ([`LogRow::write_csv`]), then the columns this row has no value for are emptied.
//! The columns, and where each comes from:
//!
//! | column | from |
//! |---|---|
//! | `t_s` | ATTITUDE's `time_boot_ms`, from the first row (a reboot continues the count) |
//! | `state` | HEARTBEAT, read as fcu-link writes it ([`fcu_link::heartbeat`]) |
//! | `armed` | HEARTBEAT: `MAV_MODE_FLAG_SAFETY_ARMED` |
//! | `link` | SYS_STATUS: the radio receiver's health bit (the board's own verdict); empty before the first SYS_STATUS |
//! | `est_roll_deg`, `est_pitch_deg` | ATTITUDE: the board's estimate |
//! | `m1`..`m4` | SERVO_OUTPUT_RAW, back to TIM4 compare counts: (value − 1000) × 2 on the 1000–2000 scale; empty before the first |
//! | `battery_v` | SYS_STATUS `voltage_battery`; empty before the first or when the board does not measure it |
//! | `thr_us` | RC_CHANNELS, the channel the board's `RCMAP_THROTTLE` names (read when recording starts); empty without it |
//! | `roll_deg`, `pitch_deg`, `yaw_deg`, `yaw_rate_dps`, `alt_m` | **absent, always empty**: the simulator's truth (the airframe's attitude, rate and height), which no board measures |
//! | `roll_target_deg`, `pitch_target_deg`, `yaw_target_deg` | **absent, always empty**: the link carries no attitude target |
//!
//! On the plot an empty value is not drawn: the "true" and "target" lines and the altitude are
//! missing, the estimate, motors, state and radio link are there.
//!
//! STATUSTEXTs go to `statustext.txt` beside them (`t_s severity text` lines, `t_s` on the CSV's
//! clock) and to the terminal as they come.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use fcu_core::supervisor::FlightState;
use fcu_log::{LogRow, CSV_HEADER};
use mavlink::dialects::common::{MavMessage, MavModeFlag, MavSysStatusSensor};

/// The columns a recording never has: the simulator's truth and the targets.
pub const ALWAYS_ABSENT: [&str; 8] =
    ["roll_deg", "pitch_deg", "yaw_deg", "roll_target_deg", "pitch_target_deg", "yaw_target_deg", "yaw_rate_dps", "alt_m"];

/// Compare counts per step of SERVO_OUTPUT_RAW's 1000–2000 scale: TIM4 counts to 2000 for 100 %
/// duty in the brushed-motor build, whose compare values the CSV's motor columns carry.
const COUNTS_PER_SERVO_STEP: u32 = 2;

/// One row of the recording: what the link said up to one ATTITUDE.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub t_s: f64,
    pub state: FlightState,
    pub armed: bool,
    pub radio_link: Option<bool>,
    pub est_roll_deg: f64,
    pub est_pitch_deg: f64,
    pub motors: Option<[u16; 4]>,
    pub battery_v: Option<f64>,
    pub thr_us: Option<f64>,
}

impl Sample {
    /// The row as fcu-log logs it: absent values are NaN (not drawn on the plot).
    pub fn log_row(&self) -> LogRow {
        LogRow {
            t_s: self.t_s,
            state: self.state,
            armed: self.armed,
            link_tx: self.radio_link.unwrap_or(true),
            link_core: self.radio_link.unwrap_or(true),
            roll_deg: f64::NAN,
            pitch_deg: f64::NAN,
            yaw_deg: f64::NAN,
            yaw_rate_dps: f64::NAN,
            est_roll_deg: self.est_roll_deg,
            est_pitch_deg: self.est_pitch_deg,
            roll_target_deg: f64::NAN,
            pitch_target_deg: f64::NAN,
            yaw_target_deg: f64::NAN,
            yaw_rate_cmd_dps: f64::NAN,
            motors: self.motors.unwrap_or([0; 4]),
            alt_m: f64::NAN,
            battery_v: self.battery_v.unwrap_or(f64::NAN),
            thr_us: self.thr_us.unwrap_or(f64::NAN),
            calibrated: !matches!(self.state, FlightState::Calibrating),
            calibrating: matches!(self.state, FlightState::Calibrating),
            calibration_restarts: 0,
            vertical: fcu_log::Vertical::ABSENT,
        }
    }

    /// The columns this row has no value for.
    pub fn absent(&self) -> Vec<&'static str> {
        let mut out: Vec<&'static str> = ALWAYS_ABSENT.to_vec();
        if self.radio_link.is_none() {
            out.push("link");
        }
        if self.motors.is_none() {
            out.extend(["m1", "m2", "m3", "m4"]);
        }
        if self.battery_v.is_none() {
            out.push("battery_v");
        }
        if self.thr_us.is_none() {
            out.push("thr_us");
        }
        out
    }

    /// The row's CSV line (with its newline) under [`CSV_HEADER`].
    pub fn csv_line(&self) -> String {
        let mut bytes = Vec::new();
        // Writing to a Vec cannot fail.
        let _ = self.log_row().write_csv(&mut bytes);
        let line = String::from_utf8_lossy(&bytes);
        let absent = self.absent();
        let fields: Vec<&str> =
            line.trim_end().split(',').zip(header_names()).map(|(field, name)| if absent.contains(&name) { "" } else { field }).collect();
        let mut out = fields.join(",");
        out.push('\n');
        out
    }
}

fn header_names() -> impl Iterator<Item = &'static str> {
    CSV_HEADER.trim_end().split(',')
}

/// Turns the board's messages into [`Sample`]s, one per ATTITUDE.
#[derive(Clone, Debug, Default)]
pub struct Recorder {
    /// 0-based RC_CHANNELS channel of the throttle.
    throttle_channel: Option<usize>,
    heartbeat: Option<(FlightState, bool)>,
    radio_link: Option<bool>,
    battery_v: Option<f64>,
    motors: Option<[u16; 4]>,
    thr_us: Option<f64>,
    /// `time_boot_ms` of the row that set the clock's base, and the time it stood for.
    base: Option<(u32, f64)>,
    last_ms: u32,
    last_t_s: f64,
}

impl Recorder {
    /// `throttle_channel`: the board's `RCMAP_THROTTLE` (1-based), if known.
    pub fn new(throttle_channel: Option<u8>) -> Recorder {
        Recorder { throttle_channel: throttle_channel.and_then(|c| usize::from(c).checked_sub(1)), ..Recorder::default() }
    }

    /// The time of the latest row, s (0 before the first).
    pub fn now_s(&self) -> f64 {
        self.last_t_s
    }

    /// Takes one message; an ATTITUDE gives a row once a HEARTBEAT has said the state.
    pub fn on_message(&mut self, msg: &MavMessage) -> Option<Sample> {
        match msg {
            MavMessage::HEARTBEAT(h) => {
                let armed = h.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
                self.heartbeat = Some((fcu_link::heartbeat::flight_state(h), armed));
            }
            MavMessage::SYS_STATUS(s) => {
                let rc = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER;
                self.radio_link = Some(s.onboard_control_sensors_health.contains(rc));
                // UINT16_MAX: the sender does not measure it.
                self.battery_v = (s.voltage_battery != u16::MAX).then(|| f64::from(s.voltage_battery) / 1000.0);
            }
            MavMessage::SERVO_OUTPUT_RAW(s) => {
                let counts = |v: u16| (u32::from(v.clamp(1000, 2000)) - 1000) * COUNTS_PER_SERVO_STEP;
                self.motors = Some([s.servo1_raw, s.servo2_raw, s.servo3_raw, s.servo4_raw].map(|v| counts(v) as u16));
            }
            MavMessage::RC_CHANNELS(r) => {
                let widths = [r.chan1_raw, r.chan2_raw, r.chan3_raw, r.chan4_raw, r.chan5_raw, r.chan6_raw, r.chan7_raw, r.chan8_raw];
                self.thr_us = self
                    .throttle_channel
                    .filter(|&c| c < usize::from(r.chancount))
                    .and_then(|c| widths.get(c).copied())
                    // UINT16_MAX: no pulses on that channel.
                    .filter(|&w| w != u16::MAX)
                    .map(f64::from);
            }
            MavMessage::ATTITUDE(a) => {
                let (state, armed) = self.heartbeat?;
                let t_s = self.clock(a.time_boot_ms);
                return Some(Sample {
                    t_s,
                    state,
                    armed,
                    radio_link: self.radio_link,
                    est_roll_deg: f64::from(a.roll).to_degrees(),
                    est_pitch_deg: f64::from(a.pitch).to_degrees(),
                    motors: self.motors,
                    battery_v: self.battery_v,
                    thr_us: self.thr_us,
                });
            }
            _ => {}
        }
        None
    }

    /// Seconds since the first row; a board clock that goes back (a reboot) continues from the
    /// last row.
    fn clock(&mut self, ms: u32) -> f64 {
        let (base_ms, base_t) = match self.base {
            Some(b) if ms >= self.last_ms => b,
            Some(_) => {
                let b = (ms, self.last_t_s);
                self.base = Some(b);
                b
            }
            None => {
                let b = (ms, 0.0);
                self.base = Some(b);
                b
            }
        };
        self.last_ms = ms;
        self.last_t_s = base_t + f64::from(ms - base_ms) / 1000.0;
        self.last_t_s
    }
}

/// `flight.csv` written row by row under a temporary name, renamed by [`Recording::finish`].
pub struct Recording {
    dir: PathBuf,
    partial: PathBuf,
    csv: BufWriter<File>,
    texts: Vec<String>,
    rows: Vec<LogRow>,
}

impl Recording {
    /// Starts `dir/flight.csv` (the directory exists and is writable).
    pub fn create(dir: &Path) -> Result<Recording, String> {
        let partial = dir.join(".flight.csv.partial");
        let file = File::create(&partial).map_err(|e| format!("writing {}: {e}", partial.display()))?;
        let mut csv = BufWriter::new(file);
        csv.write_all(CSV_HEADER.as_bytes()).map_err(|e| format!("writing {}: {e}", partial.display()))?;
        Ok(Recording { dir: dir.to_path_buf(), partial, csv, texts: Vec::new(), rows: Vec::new() })
    }

    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    pub fn row(&mut self, s: &Sample) -> Result<(), String> {
        self.csv.write_all(s.csv_line().as_bytes()).map_err(|e| format!("writing {}: {e}", self.partial.display()))?;
        self.rows.push(s.log_row());
        Ok(())
    }

    pub fn text(&mut self, t_s: f64, severity: &str, text: &str) {
        self.texts.push(format!("{t_s:.3} {severity} {text}"));
    }

    /// Writes `flight.svg` and `statustext.txt` and puts `flight.csv` in place; the paths.
    pub fn finish(mut self, title: &str) -> Result<[PathBuf; 3], String> {
        let csv_path = self.dir.join("flight.csv");
        let svg_path = self.dir.join("flight.svg");
        let text_path = self.dir.join("statustext.txt");
        self.csv.flush().map_err(|e| format!("writing {}: {e}", csv_path.display()))?;
        std::fs::rename(&self.partial, &csv_path).map_err(|e| format!("writing {}: {e}", csv_path.display()))?;
        fcu_log::plot::write_svg(&self.rows, title, &svg_path)?;
        let mut text = self.texts.join("\n");
        if !text.is_empty() {
            text.push('\n');
        }
        std::fs::write(&text_path, text).map_err(|e| format!("writing {}: {e}", text_path.display()))?;
        Ok([csv_path, svg_path, text_path])
    }

    /// The recording failed: the partial file goes.
    pub fn abandon(self) {
        let _ = std::fs::remove_file(&self.partial);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_messages::heartbeat;
    use fcu_log::csv::{data_lines, Header, Row};
    use mavlink::dialects::common::{ATTITUDE_DATA, RC_CHANNELS_DATA, SERVO_OUTPUT_RAW_DATA, SYS_STATUS_DATA};

    fn attitude(ms: u32, roll_rad: f32, pitch_rad: f32) -> MavMessage {
        MavMessage::ATTITUDE(ATTITUDE_DATA { time_boot_ms: ms, roll: roll_rad, pitch: pitch_rad, ..ATTITUDE_DATA::default() })
    }

    fn rc(widths: [u16; 4]) -> MavMessage {
        MavMessage::RC_CHANNELS(RC_CHANNELS_DATA {
            chan1_raw: widths[0],
            chan2_raw: widths[1],
            chan3_raw: widths[2],
            chan4_raw: widths[3],
            chancount: 4,
            ..RC_CHANNELS_DATA::default()
        })
    }

    fn servo(m: [u16; 4]) -> MavMessage {
        MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
            servo1_raw: m[0],
            servo2_raw: m[1],
            servo3_raw: m[2],
            servo4_raw: m[3],
            ..SERVO_OUTPUT_RAW_DATA::default()
        })
    }

    fn sys_status(mv: u16, radio_ok: bool) -> MavMessage {
        let mut health = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO;
        if radio_ok {
            health |= MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER;
        }
        MavMessage::SYS_STATUS(SYS_STATUS_DATA {
            voltage_battery: mv,
            onboard_control_sensors_health: health,
            ..SYS_STATUS_DATA::default()
        })
    }

    #[test]
    fn no_row_before_the_state_is_known() {
        let mut r = Recorder::new(Some(3));
        assert_eq!(r.on_message(&attitude(100, 0.0, 0.0)), None);
        r.on_message(&heartbeat(FlightState::Disarmed));
        assert!(r.on_message(&attitude(140, 0.0, 0.0)).is_some());
    }

    #[test]
    fn rows_carry_the_latest_of_each_message_in_the_simulators_units() {
        let mut r = Recorder::new(Some(3));
        r.on_message(&heartbeat(FlightState::Armed));
        r.on_message(&rc([1500, 1480, 1234, 1510]));
        r.on_message(&servo([1000, 1500, 2000, 1250]));
        r.on_message(&sys_status(3712, true));
        let s = r.on_message(&attitude(1000, 10f32.to_radians(), -5f32.to_radians())).unwrap();
        assert_eq!((s.state, s.armed, s.radio_link), (FlightState::Armed, true, Some(true)));
        assert_eq!(s.motors, Some([0, 1000, 2000, 500]));
        assert_eq!(s.thr_us, Some(1234.0));
        assert_eq!(s.battery_v, Some(3.712));
        assert!((s.est_roll_deg - 10.0).abs() < 1e-4 && (s.est_pitch_deg + 5.0).abs() < 1e-4);

        let line = s.csv_line();
        let header = Header::parse(CSV_HEADER.trim_end());
        let row = Row::split(2, line.trim_end(), &header).unwrap();
        let [t, state, armed, link, est_roll, m3, batt, thr] =
            header.indices(["t_s", "state", "armed", "link", "est_roll_deg", "m3", "battery_v", "thr_us"]).unwrap();
        assert_eq!(row.get::<f64>(t).unwrap(), 0.0);
        assert_eq!(row.get::<String>(state).unwrap(), "armed");
        assert!(row.flag(armed).unwrap());
        assert!(row.flag(link).unwrap());
        assert_eq!(row.get::<f64>(est_roll).unwrap(), 10.0);
        assert_eq!(row.get::<u16>(m3).unwrap(), 2000);
        assert_eq!(row.get::<f64>(batt).unwrap(), 3.712);
        assert_eq!(row.get::<f64>(thr).unwrap(), 1234.0);
        // The simulator's truth and the targets are empty, never a number.
        for name in ALWAYS_ABSENT {
            let [i] = header.indices([name]).unwrap();
            assert_eq!(row.get::<String>(i).unwrap(), "", "{name}");
        }
    }

    #[test]
    fn what_has_not_come_yet_is_empty_and_says_so() {
        let mut r = Recorder::new(None);
        r.on_message(&heartbeat(FlightState::Disarmed));
        r.on_message(&rc([1500, 1500, 1000, 1500]));
        let s = r.on_message(&attitude(5, 0.0, 0.0)).unwrap();
        let line = s.csv_line();
        let header = Header::parse(CSV_HEADER.trim_end());
        let row = Row::split(2, line.trim_end(), &header).unwrap();
        for name in ["link", "m1", "m4", "battery_v", "thr_us"] {
            let [i] = header.indices([name]).unwrap();
            assert_eq!(row.get::<String>(i).unwrap(), "", "{name}");
        }
        let [state, armed] = header.indices(["state", "armed"]).unwrap();
        assert_eq!(row.get::<String>(state).unwrap(), "disarmed");
        assert!(!row.flag(armed).unwrap());
        // A channel the receiver does not deliver is no throttle either.
        let mut r = Recorder::new(Some(3));
        r.on_message(&heartbeat(FlightState::Disarmed));
        r.on_message(&rc([1500, 1500, u16::MAX, 1500]));
        assert_eq!(r.on_message(&attitude(5, 0.0, 0.0)).unwrap().thr_us, None);
    }

    #[test]
    fn the_clock_starts_at_zero_and_survives_a_reboot() {
        let mut r = Recorder::new(None);
        r.on_message(&heartbeat(FlightState::Disarmed));
        let t: Vec<f64> = [5000, 5040, 5080, 20, 60].iter().map(|&ms| r.on_message(&attitude(ms, 0.0, 0.0)).unwrap().t_s).collect();
        let expected = [0.0, 0.04, 0.08, 0.08, 0.12];
        for (got, want) in t.iter().zip(expected) {
            assert!((got - want).abs() < 1e-9, "{t:?}");
        }
    }

    #[test]
    fn a_recording_writes_the_simulators_files() {
        let dir = std::env::temp_dir().join(format!("fcu-ground-record-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut rec = Recording::create(&dir).unwrap();
        let mut r = Recorder::new(Some(3));
        r.on_message(&heartbeat(FlightState::Disarmed));
        r.on_message(&servo([1000; 4]));
        for i in 0..50u32 {
            let s = r.on_message(&attitude(1000 + 40 * i, (i as f32 * 0.01).sin(), 0.0)).unwrap();
            rec.row(&s).unwrap();
        }
        rec.text(0.5, "info", "parameters loaded from flash");
        let [csv, svg, texts] = rec.finish("test").unwrap();
        let text = std::fs::read_to_string(&csv).unwrap();
        assert!(text.starts_with(CSV_HEADER));
        assert_eq!(data_lines(&text).count(), 50);
        let plot = std::fs::read_to_string(&svg).unwrap();
        assert!(plot.contains("<svg") && !plot.contains("NaN"));
        // What the recording has no value for is not drawn: the true attitude (blue, 2 px) and
        // the target (red, 2 px) are their legends' two-point samples only, and no altitude dot
        // (green). The motors' lines are 1 px.
        for line in plot.lines().filter(|l| l.starts_with("<polyline")) {
            if line.contains("stroke=\"#1F77B4\" stroke-width=\"2\"") || line.contains("stroke=\"#D62728\" stroke-width=\"2\"") {
                let points = line.split('"').skip_while(|f| !f.ends_with("points=")).nth(1).unwrap_or("").split_whitespace().count();
                assert!(points <= 2, "{line}");
            }
        }
        assert!(!plot.contains("fill=\"#2CA02C\""));
        // The estimate is drawn.
        assert!(plot.lines().any(|l| l.contains("stroke=\"#FF7F0E\"") && l.split_whitespace().count() > 20));
        assert_eq!(std::fs::read_to_string(&texts).unwrap(), "0.500 info parameters loaded from flash\n");
        assert!(!dir.join(".flight.csv.partial").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
