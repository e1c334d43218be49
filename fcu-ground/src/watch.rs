//! `watch`: the board's state and vertical mode, attitude, height, radio, motors and battery on
//! one screen, redrawn in
//! place (plain ANSI: cursor home, clear to the end) on a terminal, or printed as a block once a
//! second when the output is not a terminal (a log, a test).

use std::collections::VecDeque;
use std::fmt::Write as _;

use fcu_core::supervisor::FlightState;
use fcu_link::VerticalMode;
use mavlink::dialects::common::{MavMessage, MavModeFlag, MavSeverity, MavSysStatusSensor};

/// STATUSTEXT lines kept on screen.
const TEXTS_SHOWN: usize = 6;
/// What a line shows before its message came.
const WAITING: &str = "(nothing received yet)";
/// A HEARTBEAT older than this is called out: the board (or the link) has gone quiet.
const STALE_S: f64 = 3.0;

/// What the screen shows, from the board's messages.
#[derive(Clone, Debug, Default)]
pub struct View {
    /// (armed, flight state, when) of the latest HEARTBEAT.
    heartbeat: Option<(bool, FlightState, f64)>,
    /// The vertical mode the latest HEARTBEAT says (None: it says none, another autopilot).
    vertical: Option<VerticalMode>,
    /// From VFR_HUD: height above take-off, m, and climb, m/s (NaN: not known), throttle, %.
    height: Option<(f32, f32, u16)>,
    /// From SCALED_PRESSURE: pressure, hPa, and temperature, °C.
    pressure: Option<(f32, f32)>,
    /// Roll, pitch, yaw, degrees.
    attitude_deg: Option<[f64; 3]>,
    /// Channel widths, µs (None: no pulses on it).
    radio_us: Option<Vec<Option<u16>>>,
    motors: Option<[u16; 4]>,
    /// (voltage, V, if measured; remaining %, if estimated).
    battery: Option<(Option<f64>, Option<i8>)>,
    /// (present and healthy) per SYS_STATUS sensor group shown.
    health: Option<[(&'static str, bool); 4]>,
    texts: VecDeque<String>,
}

/// The severity's short name.
pub fn severity_name(s: MavSeverity) -> &'static str {
    match s {
        MavSeverity::MAV_SEVERITY_EMERGENCY => "emergency",
        MavSeverity::MAV_SEVERITY_ALERT => "alert",
        MavSeverity::MAV_SEVERITY_CRITICAL => "critical",
        MavSeverity::MAV_SEVERITY_ERROR => "error",
        MavSeverity::MAV_SEVERITY_WARNING => "warning",
        MavSeverity::MAV_SEVERITY_NOTICE => "notice",
        MavSeverity::MAV_SEVERITY_INFO => "info",
        MavSeverity::MAV_SEVERITY_DEBUG => "debug",
    }
}

impl View {
    /// Takes one message received at `now_s` (the watch's clock).
    pub fn on_message(&mut self, msg: &MavMessage, now_s: f64) {
        match msg {
            MavMessage::HEARTBEAT(h) => {
                let armed = h.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
                self.heartbeat = Some((armed, fcu_link::heartbeat::flight_state(h), now_s));
                self.vertical = fcu_link::heartbeat::vertical_mode(h);
            }
            MavMessage::VFR_HUD(v) => {
                self.height = Some((v.alt, v.climb, v.throttle));
            }
            MavMessage::SCALED_PRESSURE(p) => {
                self.pressure = Some((p.press_abs, f32::from(p.temperature) / 100.0));
            }
            MavMessage::ATTITUDE(a) => {
                self.attitude_deg = Some([a.roll, a.pitch, a.yaw].map(|r| f64::from(r).to_degrees()));
            }
            MavMessage::RC_CHANNELS(r) => {
                let all = [r.chan1_raw, r.chan2_raw, r.chan3_raw, r.chan4_raw, r.chan5_raw, r.chan6_raw, r.chan7_raw, r.chan8_raw];
                let n = usize::from(r.chancount).min(all.len());
                self.radio_us = Some(all.iter().take(n).map(|&w| (w != u16::MAX).then_some(w)).collect());
            }
            MavMessage::SERVO_OUTPUT_RAW(s) => {
                self.motors = Some([s.servo1_raw, s.servo2_raw, s.servo3_raw, s.servo4_raw]);
            }
            MavMessage::SYS_STATUS(s) => {
                let v = (s.voltage_battery != u16::MAX).then(|| f64::from(s.voltage_battery) / 1000.0);
                let pct = (s.battery_remaining >= 0).then_some(s.battery_remaining);
                self.battery = Some((v, pct));
                let ok = |bits: MavSysStatusSensor| s.onboard_control_sensors_health.contains(bits);
                self.health = Some([
                    ("imu", ok(MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL)),
                    ("radio", ok(MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)),
                    ("attitude estimate", ok(MavSysStatusSensor::MAV_SYS_STATUS_AHRS)),
                    ("battery", ok(MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY)),
                ]);
            }
            MavMessage::STATUSTEXT(t) => {
                let text = t.text.to_str().unwrap_or("(not UTF-8)").trim_end();
                self.texts.push_back(format!("{now_s:7.1} s  [{}] {text}", severity_name(t.severity)));
                while self.texts.len() > TEXTS_SHOWN {
                    self.texts.pop_front();
                }
            }
            _ => {}
        }
    }

    /// The screen at `now_s`, one line per `\n`.
    pub fn render(&self, title: &str, now_s: f64) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "{title}");
        self.write_state(&mut out, now_s);
        self.write_radio(&mut out);
        self.write_outputs(&mut out);
        let _ = writeln!(out, "messages");
        if self.texts.is_empty() {
            let _ = writeln!(out, "  (none yet)");
        }
        for t in &self.texts {
            let _ = writeln!(out, "  {t}");
        }
        out
    }

    /// The flight state (and how old it is) and the attitude.
    fn write_state(&self, out: &mut String, now_s: f64) {
        match self.heartbeat {
            Some((armed, state, at)) => {
                let armed = if armed { "ARMED" } else { "disarmed" };
                let _ = write!(out, "state      {armed:<9} flight state {}", state.name());
                match self.vertical {
                    Some(mode) => {
                        let _ = write!(out, "   mode {}", mode.name());
                    }
                    None => out.push_str("   mode not said"),
                }
                let age = now_s - at;
                if age > STALE_S {
                    let _ = write!(out, "   NO HEARTBEAT FOR {age:.0} s");
                }
                out.push('\n');
            }
            None => {
                let _ = writeln!(out, "state      {WAITING}");
            }
        }
        match self.attitude_deg {
            Some([r, p, y]) => {
                let _ = writeln!(out, "attitude   roll {r:+7.1}°   pitch {p:+7.1}°   yaw {y:+7.1}°");
            }
            None => {
                let _ = writeln!(out, "attitude   {WAITING}");
            }
        }
        match self.height {
            Some((alt, climb, throttle)) if alt.is_finite() && climb.is_finite() => {
                let _ = write!(out, "height     {alt:+7.2} m   climb {climb:+6.2} m/s   throttle {throttle:3} %");
            }
            Some((_, _, throttle)) => {
                let _ = write!(out, "height     not known (no barometer estimate)   throttle {throttle:3} %");
            }
            None => {
                let _ = write!(out, "height     {WAITING}");
            }
        }
        if let Some((hpa, c)) = self.pressure {
            let _ = write!(out, "   baro {hpa:.2} hPa {c:.1} °C");
        }
        out.push('\n');
    }

    /// The radio's channels.
    fn write_radio(&self, out: &mut String) {
        match &self.radio_us {
            Some(ch) if !ch.is_empty() => {
                let _ = write!(out, "radio µs  ");
                for (i, w) in ch.iter().enumerate() {
                    match w {
                        Some(w) => {
                            let _ = write!(out, " ch{} {w:4}", i + 1);
                        }
                        None => {
                            let _ = write!(out, " ch{}  ---", i + 1);
                        }
                    }
                }
                out.push('\n');
            }
            Some(_) => {
                let _ = writeln!(out, "radio µs   no channels");
            }
            None => {
                let _ = writeln!(out, "radio µs   {WAITING}");
            }
        }
    }

    /// The motors, the battery and the sensors' health.
    fn write_outputs(&self, out: &mut String) {
        match self.motors {
            Some(m) => {
                let _ = writeln!(out, "motors     m1 {:4}  m2 {:4}  m3 {:4}  m4 {:4}   (1000 off .. 2000 full)", m[0], m[1], m[2], m[3]);
            }
            None => {
                let _ = writeln!(out, "motors     {WAITING}");
            }
        }
        match self.battery {
            Some((v, pct)) => {
                let v = v.map_or("not measured".to_string(), |v| format!("{v:.2} V"));
                let pct = pct.map_or(String::new(), |p| format!(", {p} % left"));
                let _ = writeln!(out, "battery    {v}{pct}");
            }
            None => {
                let _ = writeln!(out, "battery    {WAITING}");
            }
        }
        match self.health {
            Some(h) => {
                let parts: Vec<String> = h.iter().map(|(name, ok)| format!("{name} {}", if *ok { "ok" } else { "NOT OK" })).collect();
                let _ = writeln!(out, "health     {}", parts.join(", "));
            }
            None => {
                let _ = writeln!(out, "health     {WAITING}");
            }
        }
    }
}

/// The screen as a terminal redraw: cursor home, each line cleared to its end, then the rest
/// of the screen cleared (no flicker from a full clear).
pub fn redraw(screen: &str) -> String {
    let mut out = String::from("\x1b[H");
    for line in screen.lines() {
        out.push_str(line);
        out.push_str("\x1b[K\n");
    }
    out.push_str("\x1b[J");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_messages::{heartbeat, heartbeat_in};
    use mavlink::dialects::common::{
        ATTITUDE_DATA, HEARTBEAT_DATA, RC_CHANNELS_DATA, SCALED_PRESSURE_DATA, SERVO_OUTPUT_RAW_DATA, STATUSTEXT_DATA, SYS_STATUS_DATA,
        VFR_HUD_DATA,
    };

    fn text(s: &str) -> MavMessage {
        MavMessage::STATUSTEXT(STATUSTEXT_DATA { severity: MavSeverity::MAV_SEVERITY_WARNING, text: s.into() })
    }

    #[test]
    fn the_screen_shows_what_came() {
        let mut v = View::default();
        let empty = v.render("t", 0.0);
        assert!(empty.contains("state      (nothing received yet)"), "{empty}");
        v.on_message(&heartbeat(FlightState::Armed), 1.0);
        v.on_message(&MavMessage::ATTITUDE(ATTITUDE_DATA { roll: 0.1, pitch: -0.2, yaw: 3.0, ..ATTITUDE_DATA::default() }), 1.0);
        v.on_message(
            &MavMessage::RC_CHANNELS(RC_CHANNELS_DATA {
                chan1_raw: 1500,
                chan2_raw: 1499,
                chan3_raw: 1100,
                chan4_raw: u16::MAX,
                chancount: 4,
                ..RC_CHANNELS_DATA::default()
            }),
            1.0,
        );
        v.on_message(
            &MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
                servo1_raw: 1200,
                servo2_raw: 1300,
                servo3_raw: 1400,
                servo4_raw: 1500,
                ..SERVO_OUTPUT_RAW_DATA::default()
            }),
            1.0,
        );
        v.on_message(
            &MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                voltage_battery: 3800,
                battery_remaining: -1,
                onboard_control_sensors_health: MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER,
                ..SYS_STATUS_DATA::default()
            }),
            1.0,
        );
        v.on_message(&text("RC1_MIN: below the minimum"), 1.5);
        let s = v.render("t", 2.0);
        assert!(s.contains("state      ARMED     flight state armed   mode manual throttle"), "{s}");
        assert!(s.contains("roll    +5.7°   pitch   -11.5°   yaw  +171.9°"), "{s}");
        assert!(s.contains(" ch1 1500 ch2 1499 ch3 1100 ch4  ---"), "{s}");
        assert!(s.contains("m1 1200  m2 1300  m3 1400  m4 1500"), "{s}");
        assert!(s.contains("battery    3.80 V\n"), "{s}");
        assert!(s.contains("imu NOT OK, radio ok"), "{s}");
        assert!(s.contains("[warning] RC1_MIN: below the minimum"), "{s}");
        assert!(!s.contains("NO HEARTBEAT"), "{s}");
        // A board gone quiet is called out.
        assert!(v.render("t", 10.0).contains("NO HEARTBEAT FOR 9 s"));
    }

    #[test]
    fn the_screen_shows_the_height_climb_and_vertical_mode() {
        let mut v = View::default();
        assert!(v.render("t", 0.0).contains("height     (nothing received yet)"));
        v.on_message(&heartbeat_in(FlightState::Armed, VerticalMode::AltitudeHold), 1.0);
        let hud = VFR_HUD_DATA { alt: 1.25, climb: -0.5, throttle: 42, ..VFR_HUD_DATA::default() };
        v.on_message(&MavMessage::VFR_HUD(hud.clone()), 1.0);
        v.on_message(
            &MavMessage::SCALED_PRESSURE(SCALED_PRESSURE_DATA { press_abs: 1001.5, temperature: 2450, ..SCALED_PRESSURE_DATA::default() }),
            1.0,
        );
        let s = v.render("t", 1.5);
        assert!(s.contains("flight state armed   mode altitude hold"), "{s}");
        assert!(s.contains("height       +1.25 m   climb  -0.50 m/s   throttle  42 %   baro 1001.50 hPa 24.5 °C"), "{s}");
        // The failsafe's descent, an unknown height, and another autopilot's heartbeat.
        v.on_message(&heartbeat_in(FlightState::FailsafeLevel, VerticalMode::FailsafeDescent), 2.0);
        v.on_message(&MavMessage::VFR_HUD(VFR_HUD_DATA { alt: f32::NAN, climb: f32::NAN, ..hud }), 2.0);
        let s = v.render("t", 2.5);
        assert!(s.contains("mode failsafe descent"), "{s}");
        assert!(s.contains("height     not known (no barometer estimate)   throttle  42 %"), "{s}");
        v.on_message(&MavMessage::HEARTBEAT(HEARTBEAT_DATA { custom_mode: 0x0003_0000, ..HEARTBEAT_DATA::default() }), 3.0);
        assert!(v.render("t", 3.5).contains("mode not said"));
    }

    #[test]
    fn only_the_latest_texts_stay() {
        let mut v = View::default();
        for i in 0..10 {
            v.on_message(&text(&format!("line {i}")), f64::from(i));
        }
        let s = v.render("t", 10.0);
        assert!(!s.contains("line 3") && s.contains("line 4") && s.contains("line 9"), "{s}");
    }

    #[test]
    fn a_redraw_overwrites_in_place() {
        assert_eq!(redraw("a\nb\n"), "\x1b[Ha\x1b[K\nb\x1b[K\n\x1b[J");
    }
}
