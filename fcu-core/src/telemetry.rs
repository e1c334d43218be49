//! Telemetry text and LED codes: what the firmware prints on the debug UART and shows on the
//! two LEDs, decided here so the firmware only moves the bytes and drives the pins.
//!
//! Two lines:
//! * the reference's TAB-separated debug line (`docs/reference.md#telemetry`): gELE, gAIL, gRUD,
//!   gTHR as integers, motor 1 command, then pitch, roll, pitch target and roll target in
//!   degrees (×57.3, as the reference), each with six decimals like C's `%f`, ending in LF;
//! * a status line, printed on every change of flight state or of the vertical report, naming
//!   the state, the arming blockers, the calibration result, the failsafe stage and any fault,
//!   the vertical mode, the hold's target and the barometer's fault, with the battery voltage
//!   and the firmware's counters ([`StatusFields`]; written and read back in
//!   `status_line`).
//!
//! Formatting is fixed-point into a fixed byte buffer: no float formatting machinery, no heap.

use core::fmt::{self, Write};

use crate::flight::Status;
use crate::imu::registers::Sensor;
use crate::imu::CalibrationPhase;
use crate::supervisor::FlightState;

mod status_line;

pub use status_line::{
    baro_fault_name, failsafe_name, fault_from_name, fault_name, parse_status_line, write_status_line, CalibrationReport, StatusFields,
    StatusKey, StatusLineError, VerticalMode, VerticalReport, STATUS_LINE_MAX,
};

/// A line being built in a fixed buffer. Text that does not fit is dropped and the line is
/// marked truncated (it still ends in LF, see [`LineBuf::finish_line`]); formatting never fails.
pub struct LineBuf<const N: usize> {
    bytes: [u8; N],
    len: usize,
    truncated: bool,
}

impl<const N: usize> Default for LineBuf<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> LineBuf<N> {
    pub const fn new() -> Self {
        LineBuf { bytes: [0; N], len: 0, truncated: false }
    }

    pub fn clear(&mut self) {
        self.len = 0;
        self.truncated = false;
    }

    pub fn as_bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }

    /// The text so far (always valid UTF-8: only whole `str`s are ever appended).
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("")
    }

    pub fn is_truncated(&self) -> bool {
        self.truncated
    }

    pub fn push_str(&mut self, s: &str) {
        let room = N.saturating_sub(self.len);
        if s.len() > room {
            self.truncated = true;
            return;
        }
        if let Some(dst) = self.bytes.get_mut(self.len..self.len + s.len()) {
            dst.copy_from_slice(s.as_bytes());
            self.len += s.len();
        }
    }

    /// Ends the line with LF, overwriting the last byte if the buffer is full, so a line on
    /// the wire is always terminated even when its text was cut.
    pub fn finish_line(&mut self) {
        if self.len >= N {
            self.truncated = true;
            self.len = N.saturating_sub(1);
        }
        if let Some(b) = self.bytes.get_mut(self.len) {
            *b = b'\n';
            self.len += 1;
        }
    }

    /// Signed decimal integer, like C's `%d`.
    pub fn push_int(&mut self, v: i32) {
        if v < 0 {
            self.push_str("-");
        }
        self.push_uint(v.unsigned_abs());
    }

    /// Unsigned decimal integer.
    pub fn push_uint(&mut self, v: u32) {
        let mut digits = [0u8; 10];
        let mut n = v;
        let mut start = digits.len();
        loop {
            start -= 1;
            if let Some(d) = digits.get_mut(start) {
                *d = b'0' + (n % 10) as u8;
            }
            n /= 10;
            if n == 0 || start == 0 {
                break;
            }
        }
        self.push_ascii(digits.get(start..).unwrap_or(&[]));
    }

    /// Appends ASCII bytes (the only non-`str` input, so the buffer stays valid UTF-8).
    fn push_ascii(&mut self, ascii: &[u8]) {
        let room = N.saturating_sub(self.len);
        if ascii.len() > room || !ascii.is_ascii() {
            self.truncated = true;
            return;
        }
        if let Some(dst) = self.bytes.get_mut(self.len..self.len + ascii.len()) {
            dst.copy_from_slice(ascii);
            self.len += ascii.len();
        }
    }

    /// Fixed-point decimal with `decimals` digits after the point (at most 6), rounded half
    /// away from zero, like C's `%.Nf` for values in range. Not-finite values print as `nan`,
    /// `inf`, `-inf`; magnitudes of 2³¹ or more as `ovf` (they cannot be a stick, motor or
    /// angle value, so they only show that something upstream went wrong).
    pub fn push_fixed(&mut self, v: f32, decimals: u32) {
        let decimals = decimals.min(6);
        if v.is_nan() {
            self.push_str("nan");
            return;
        }
        if v.is_infinite() {
            self.push_str(if v > 0.0 { "inf" } else { "-inf" });
            return;
        }
        let magnitude = if v < 0.0 { -v } else { v };
        if magnitude >= 2_147_483_648.0 {
            self.push_str("ovf");
            return;
        }
        let scale = 10u32.pow(decimals);
        // Integer part and fraction are rounded together so 0.9999996 prints as 1.000000.
        let mut whole = magnitude as u32;
        let frac_f = (magnitude - whole as f32) * scale as f32 + 0.5;
        let mut frac = frac_f as u32;
        if frac >= scale {
            frac -= scale;
            whole = whole.saturating_add(1);
        }
        if v < 0.0 && (whole != 0 || frac != 0) {
            self.push_str("-");
        }
        self.push_uint(whole);
        if decimals > 0 {
            self.push_str(".");
            // Exactly `decimals` digits, leading zeros included.
            let mut place = scale / 10;
            while place > 0 {
                let digit = (frac / place) % 10;
                self.push_uint(digit);
                place /= 10;
            }
        }
    }
}

impl<const N: usize> Write for LineBuf<N> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.push_str(s);
        Ok(())
    }
}

/// Radians to the reference's printed degrees (it multiplies by 57.3, not 180/π).
pub const REFERENCE_DEG_PER_RAD: f32 = 57.3;

/// Decimals of the debug line's float fields (C's `%f`).
pub const DEBUG_DECIMALS: u32 = 6;

/// Longest debug line: 4 integers of up to 6 characters, 5 floats of up to 18, 8 TABs, LF.
pub const DEBUG_LINE_MAX: usize = 128;

/// The fields of the reference's debug line.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DebugFields {
    pub ele: i16,
    pub ail: i16,
    pub rud: i16,
    pub thr: i16,
    /// Motor 1 command before clamping, in compare counts.
    pub motor1_cmd: f32,
    pub pitch_rad: f32,
    pub roll_rad: f32,
    pub pitch_target_rad: f32,
    pub roll_target_rad: f32,
}

/// The reference's TAB-separated line: `gELE gAIL gRUD gTHR motor1 pitch roll pitchT rollT`.
pub fn write_debug_line<const N: usize>(out: &mut LineBuf<N>, f: &DebugFields) {
    out.clear();
    for stick in [f.ele, f.ail, f.rud, f.thr] {
        out.push_int(i32::from(stick));
        out.push_str("\t");
    }
    out.push_fixed(f.motor1_cmd, DEBUG_DECIMALS);
    for angle_rad in [f.pitch_rad, f.roll_rad, f.pitch_target_rad, f.roll_target_rad] {
        out.push_str("\t");
        out.push_fixed(angle_rad * REFERENCE_DEG_PER_RAD, DEBUG_DECIMALS);
    }
    out.finish_line();
}

/// The fatal boot message for a sensor that did not answer `WHO_AM_I` (`docs/safety.md#boot`).
pub fn write_sensor_missing_line<const N: usize>(out: &mut LineBuf<N>, sensor: &str, who_am_i: u8, expected: u8) {
    out.clear();
    out.push_str("FATAL sensor ");
    out.push_str(sensor);
    out.push_str(" WHO_AM_I=");
    push_hex_u8(out, who_am_i);
    out.push_str(" expected ");
    push_hex_u8(out, expected);
    out.push_str(": motors off, no flight until reset");
    out.finish_line();
}

fn push_hex_u8<const N: usize>(out: &mut LineBuf<N>, v: u8) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let hi = HEX.get(usize::from(v >> 4)).copied().unwrap_or(b'?');
    let lo = HEX.get(usize::from(v & 0xF)).copied().unwrap_or(b'?');
    out.push_ascii(&[b'0', b'x', hi, lo]);
}

/// The reference's boot banner, then the sensor lines.
pub const BOOT_BANNER: &str = "STEVAL-FCU001V1 fcu (Rust) - reference rev.1.0 behaviour\n\n";

pub use crate::control::{BATTERY_ADC_FULL_SCALE, BATTERY_ADC_REF_MV, BATTERY_DIVIDER_DEN, BATTERY_DIVIDER_NUM};

/// Battery voltage in millivolts from a raw 12-bit conversion (rounded to nearest).
pub fn battery_mv(adc_counts: u16) -> u32 {
    let counts = u32::from(adc_counts).min(BATTERY_ADC_FULL_SCALE);
    let den = BATTERY_ADC_FULL_SCALE * BATTERY_DIVIDER_DEN;
    (counts * BATTERY_ADC_REF_MV * BATTERY_DIVIDER_NUM + den / 2) / den
}

/// The LED codes of `docs/safety.md#leds`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LedPattern {
    /// Both off (before the first status is known).
    Off,
    /// Disarmed and ready to arm: LED2 blinking at 10 Hz.
    Ready,
    /// Arming blocked: LED2 slow blink (1 Hz).
    Blocked,
    /// Armed: LED2 solid.
    Armed,
    /// Calibrating: LED1 and LED2 alternating (2 Hz).
    Calibrating,
    /// Failsafe: LED1 fast (10 Hz), LED2 off.
    Failsafe,
    /// Fatal boot fault: both on, and every [`FAULT_CYCLE_MS`] LED1 goes dark `blinks` times
    /// (1 = LSM6DSL, 2 = LIS2MDL, 3 = LPS22HB, see `imu::registers::Sensor::blink_count`;
    /// 4 = HSE crystal, 5 = watchdog clock, see `boot::ClockFault::blink_count`).
    SensorFault { blinks: u8 },
}

/// The two LED levels (true = lit; the firmware maps lit to the active-low pin level).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Leds {
    pub led1: bool,
    pub led2: bool,
}

pub const FAST_BLINK_PERIOD_MS: u32 = 100;
pub const SLOW_BLINK_PERIOD_MS: u32 = 1000;
pub const ALTERNATE_PERIOD_MS: u32 = 500;
pub const FAULT_CYCLE_MS: u32 = 3000;
/// One dark + one lit phase of the fault blink count.
pub const FAULT_BLINK_MS: u32 = 400;

impl LedPattern {
    /// LED levels at time `t_ms` (any free-running millisecond clock; wraps harmlessly).
    pub fn leds_at(self, t_ms: u32) -> Leds {
        let first_half = |period: u32| t_ms % period < period / 2;
        match self {
            LedPattern::Off => Leds { led1: false, led2: false },
            LedPattern::Ready => Leds { led1: false, led2: first_half(FAST_BLINK_PERIOD_MS) },
            LedPattern::Blocked => Leds { led1: false, led2: first_half(SLOW_BLINK_PERIOD_MS) },
            LedPattern::Armed => Leds { led1: false, led2: true },
            LedPattern::Calibrating => {
                let a = first_half(ALTERNATE_PERIOD_MS);
                Leds { led1: a, led2: !a }
            }
            LedPattern::Failsafe => Leds { led1: first_half(FAST_BLINK_PERIOD_MS), led2: false },
            LedPattern::SensorFault { blinks } => {
                let t = t_ms % FAULT_CYCLE_MS;
                let blink_index = t / FAULT_BLINK_MS;
                let in_dark_phase = t % FAULT_BLINK_MS < FAULT_BLINK_MS / 2;
                let dark = blink_index < u32::from(blinks) && in_dark_phase;
                Leds { led1: !dark, led2: true }
            }
        }
    }
}

/// The debug line's fields from the core's status.
pub fn debug_fields(status: &Status) -> DebugFields {
    let [motor1_cmd, ..] = status.motor_command;
    let [pitch_target_rad, roll_target_rad, _yaw] = status.target_rad;
    DebugFields {
        ele: status.sticks.ele.get(),
        ail: status.sticks.ail.get(),
        rud: status.sticks.rud.get(),
        thr: status.sticks.thr.get(),
        motor1_cmd,
        pitch_rad: status.tilt.pitch_rad,
        roll_rad: status.tilt.roll_rad,
        pitch_target_rad,
        roll_target_rad,
    }
}

/// The LED code for a flight status (`docs/safety.md#leds`). An in-flight sensor fault is the
/// IMU's, so it blinks the LSM6DSL's count.
pub fn led_pattern(status: &Status) -> LedPattern {
    let calibrating = matches!(status.calibration, CalibrationPhase::Settling | CalibrationPhase::Averaging { .. });
    match status.state {
        FlightState::Fault => LedPattern::SensorFault { blinks: Sensor::Lsm6dsl.blink_count() },
        FlightState::FailsafeLevel | FlightState::FailsafeOff => LedPattern::Failsafe,
        FlightState::Armed => LedPattern::Armed,
        FlightState::Calibrating => LedPattern::Calibrating,
        _ if calibrating => LedPattern::Calibrating,
        FlightState::Disarmed | FlightState::Arming if status.blockers.is_empty() => LedPattern::Ready,
        FlightState::Disarmed | FlightState::Arming => LedPattern::Blocked,
    }
}

/// What to print for one status snapshot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Emit {
    /// The flight state changed (or this is the first snapshot): print the status line.
    pub status_line: bool,
    /// The debug line is due (every `debug_every`-th snapshot).
    pub debug_line: bool,
}

/// Control ticks between status snapshots to the telemetry task (800 Hz / 4 = 200 Hz), so a
/// flight-state change reaches the UART within 5 ms of the tick (the STATUS line carries the
/// tick it was taken at).
pub const SNAPSHOT_EVERY_TICKS: u16 = 4;
/// Snapshots per debug line: 200 Hz / 8 = 25 lines a second (~80 bytes each, 2 kB/s of the
/// UART's 11.5 kB/s).
pub const DEBUG_LINE_EVERY_SNAPSHOTS: u16 = 8;

/// Decides which lines a stream of status snapshots produces: the status line on every change
/// of flight state or of the vertical report (mode in force, mode chosen, the barometer's
/// fault, a hold that starts or ends; the hold's target when it moved by more than
/// [`TARGET_REPORT_STEP_MM`], at most every [`TARGET_REPORT_MIN_SNAPSHOTS`]), the debug line
/// at a bounded rate.
#[derive(Clone, Debug)]
pub struct Reporter {
    /// What the last status line said (`None` before the first).
    last: Option<(FlightState, VerticalReport)>,
    /// Snapshots since the last status line (saturating).
    since_status: u16,
    debug_every: u16,
    since_debug: u16,
}

/// A hold's target that moves by this much or less since the last status line does not print
/// another, mm: the height loop's own noise is smaller, a climb on the stick moves it faster.
pub const TARGET_REPORT_STEP_MM: u32 = 10;
/// Snapshots a moving target waits after the last status line (200 Hz / 50: 4 lines a second,
/// some 0.9 kB/s of the UART's 11.5 kB/s): a stick climb moves it on every snapshot, and a
/// line each time would overrun the UART queue.
pub const TARGET_REPORT_MIN_SNAPSHOTS: u16 = 50;

impl Reporter {
    /// The firmware's reporter: a debug line every [`DEBUG_LINE_EVERY_SNAPSHOTS`] snapshots.
    pub const fn firmware() -> Self {
        Reporter::new(DEBUG_LINE_EVERY_SNAPSHOTS)
    }

    /// `debug_every`: snapshots per debug line (0 is taken as 1).
    pub const fn new(debug_every: u16) -> Self {
        Reporter { last: None, since_status: 0, debug_every: if debug_every == 0 { 1 } else { debug_every }, since_debug: 0 }
    }

    pub fn observe(&mut self, status: &Status) -> Emit {
        let now = (status.state, VerticalReport::of(&status.altitude));
        self.since_status = self.since_status.saturating_add(1);
        let status_line = match self.last {
            None => true,
            Some((state, v)) => {
                state != now.0
                    || vertical_changed(&v, &now.1)
                    || (self.since_status >= TARGET_REPORT_MIN_SNAPSHOTS && target_moved(&v, &now.1))
            }
        };
        if status_line {
            self.last = Some(now);
            self.since_status = 0;
        }
        self.since_debug += 1;
        let debug_line = self.since_debug >= self.debug_every;
        if debug_line {
            self.since_debug = 0;
        }
        Emit { status_line, debug_line }
    }
}

/// The vertical report says something new: another mode or fault, a target that comes or goes.
fn vertical_changed(last: &VerticalReport, now: &VerticalReport) -> bool {
    last.mode != now.mode
        || last.chosen != now.chosen
        || last.baro_fault != now.baro_fault
        || last.target_mm.is_some() != now.target_mm.is_some()
}

/// The hold's target is more than [`TARGET_REPORT_STEP_MM`] from the one last printed.
fn target_moved(last: &VerticalReport, now: &VerticalReport) -> bool {
    match (last.target_mm, now.target_mm) {
        (Some(a), Some(b)) => a.abs_diff(b) > TARGET_REPORT_STEP_MM,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::supervisor::Blocker;

    fn line<const N: usize>(b: &LineBuf<N>) -> &str {
        b.as_str()
    }

    #[test]
    fn debug_line_matches_the_reference_printf_layout() {
        let mut b = LineBuf::<DEBUG_LINE_MAX>::new();
        let f = DebugFields {
            ele: -12,
            ail: 5,
            rud: 0,
            thr: 1234,
            motor1_cmd: 1045.5,
            pitch_rad: 0.0,
            roll_rad: 1.0,
            pitch_target_rad: -0.5,
            roll_target_rad: 0.25,
        };
        write_debug_line(&mut b, &f);
        assert_eq!(line(&b), "-12\t5\t0\t1234\t1045.500000\t0.000000\t57.299999\t-28.650000\t14.325000\n");
    }

    #[test]
    fn fixed_point_rounds_and_pads_like_printf() {
        let mut b = LineBuf::<64>::new();
        for (v, d) in [(0.05f32, 1u32), (1.0, 0), (-0.0004, 3), (2.0626, 3), (9.9999999, 6), (-3.25, 2), (0.000001, 6)] {
            b.push_fixed(v, d);
            b.push_str(" ");
        }
        assert_eq!(line(&b), "0.1 1 0.000 2.063 10.000000 -3.25 0.000001 ");
    }

    #[test]
    fn not_finite_values_print_as_words_not_garbage() {
        let mut b = LineBuf::<64>::new();
        b.push_fixed(f32::NAN, 6);
        b.push_str(" ");
        b.push_fixed(f32::NEG_INFINITY, 6);
        b.push_str(" ");
        b.push_fixed(3.0e12, 6);
        assert_eq!(line(&b), "nan -inf ovf");
    }

    #[test]
    fn integers_cover_the_extremes() {
        let mut b = LineBuf::<64>::new();
        b.push_int(i32::MIN);
        b.push_str(" ");
        b.push_uint(u32::MAX);
        b.push_str(" ");
        b.push_int(0);
        assert_eq!(line(&b), "-2147483648 4294967295 0");
    }

    #[test]
    fn a_full_buffer_truncates_but_still_ends_the_line() {
        let mut b = LineBuf::<8>::new();
        b.push_str("12345");
        b.push_str("6789");
        b.finish_line();
        assert!(b.is_truncated());
        assert_eq!(line(&b), "12345\n");
        let mut full = LineBuf::<4>::new();
        full.push_str("abcd");
        full.finish_line();
        assert_eq!(line(&full), "abc\n");
    }

    #[test]
    fn sensor_missing_line_names_the_sensor_and_both_ids() {
        let mut b = LineBuf::<96>::new();
        write_sensor_missing_line(&mut b, "LSM6DSL", 0xFF, 0x6A);
        assert_eq!(line(&b), "FATAL sensor LSM6DSL WHO_AM_I=0xFF expected 0x6A: motors off, no flight until reset\n");
    }

    #[test]
    fn battery_is_adc_times_3v3_over_4095_times_1_5() {
        assert_eq!(battery_mv(0), 0);
        assert_eq!(battery_mv(4095), 4950);
        assert_eq!(battery_mv(3309), 4000); // 3309 × 3.3 / 4095 × 1.5 = 3999.9
        assert_eq!(battery_mv(u16::MAX), 4950);
    }

    #[test]
    fn ready_blinks_led2_at_10_hz() {
        let p = LedPattern::Ready;
        assert_eq!(p.leds_at(0), Leds { led1: false, led2: true });
        assert_eq!(p.leds_at(50), Leds { led1: false, led2: false });
        assert_eq!(p.leds_at(100), Leds { led1: false, led2: true });
    }

    #[test]
    fn blocked_is_a_slow_blink_and_armed_is_solid() {
        assert!(LedPattern::Blocked.leds_at(499).led2);
        assert!(!LedPattern::Blocked.leds_at(500).led2);
        assert!((0..2000).step_by(7).all(|t| LedPattern::Armed.leds_at(t) == Leds { led1: false, led2: true }));
    }

    #[test]
    fn calibrating_alternates_the_two_leds() {
        assert!((0..2000).step_by(13).all(|t| {
            let l = LedPattern::Calibrating.leds_at(t);
            l.led1 != l.led2
        }));
    }

    #[test]
    fn failsafe_flashes_led1_fast() {
        assert!(LedPattern::Failsafe.leds_at(10).led1);
        assert!(!LedPattern::Failsafe.leds_at(60).led1);
        assert!(!LedPattern::Failsafe.leds_at(10).led2);
    }

    #[test]
    fn sensor_fault_keeps_both_on_and_counts_blinks_of_led1() {
        let p = LedPattern::SensorFault { blinks: 2 };
        let dark_phases = (0..FAULT_CYCLE_MS).filter(|&t| t % FAULT_BLINK_MS == 0 && !p.leds_at(t).led1).count();
        assert_eq!(dark_phases, 2);
        assert!((0..FAULT_CYCLE_MS).all(|t| p.leds_at(t).led2));
        assert_eq!(p.leds_at(FAULT_CYCLE_MS - 1), Leds { led1: true, led2: true });
    }

    #[test]
    fn reporter_prints_status_on_every_state_change_and_debug_at_its_rate() {
        let mut r = Reporter::new(3);
        let seq = [
            FlightState::Calibrating,
            FlightState::Calibrating,
            FlightState::Disarmed,
            FlightState::Disarmed,
            FlightState::Disarmed,
            FlightState::Arming,
        ];
        let mut st = boot_status();
        let got: [(bool, bool); 6] = seq.map(|s| {
            st.state = s;
            let e = r.observe(&st);
            (e.status_line, e.debug_line)
        });
        assert_eq!(got, [(true, false), (false, false), (true, true), (false, false), (false, false), (true, true)]);
    }

    #[test]
    fn reporter_prints_status_when_the_vertical_report_changes() {
        use crate::altitude::AltMode;
        use crate::baro::BaroFault;
        let mut r = Reporter::new(100);
        let mut st = boot_status();
        st.state = FlightState::Armed;
        let mut status_line = |st: &Status| r.observe(st).status_line;
        assert!(status_line(&st), "the first snapshot");
        assert!(!status_line(&st), "nothing new");
        st.altitude.mode = AltMode::Hold;
        assert!(status_line(&st), "the mode chosen");
        st.altitude.holding = true;
        st.altitude.target_m = Some(1.0);
        assert!(status_line(&st), "the hold takes over");
        let wait = |status_line: &mut dyn FnMut(&Status) -> bool, st: &Status| {
            for _ in 1..TARGET_REPORT_MIN_SNAPSHOTS {
                assert!(!status_line(st));
            }
        };
        st.altitude.target_m = Some(1.0099);
        wait(&mut status_line, &st);
        assert!(!status_line(&st), "the target within 1 cm of the one printed");
        st.altitude.target_m = Some(0.995);
        assert!(!status_line(&st));
        st.altitude.target_m = Some(1.0111);
        assert!(status_line(&st), "the target more than 1 cm from the one printed");
        st.altitude.target_m = Some(1.5);
        wait(&mut status_line, &st);
        assert!(status_line(&st), "a target that moves waits its turn: {TARGET_REPORT_MIN_SNAPSHOTS} snapshots");
        st.altitude.target_m = Some(1.509);
        wait(&mut status_line, &st);
        assert!(!status_line(&st), "measured from the last line's 1.5 m, not the first's");
        st.altitude.failsafe_descent = true;
        assert!(status_line(&st), "the failsafe descends");
        st.altitude.baro_fault = Some(BaroFault::Stuck);
        assert!(status_line(&st), "a barometer fault");
        assert!(!status_line(&st));
        st.altitude.baro_fault = None;
        st.altitude.holding = false;
        st.altitude.failsafe_descent = false;
        st.altitude.target_m = None;
        assert!(status_line(&st), "back to manual");
        st.altitude.height_m = 3.0;
        st.altitude.pressure_pa = Some(101_000.0);
        assert!(!status_line(&st), "the estimate itself is not news for the status line");
    }

    fn boot_status() -> Status {
        let fc = crate::FlightController::new(&crate::Config::default()).expect("default config is valid");
        fc.status()
    }

    #[test]
    fn led_pattern_follows_the_flight_state() {
        let mut st = boot_status();
        st.calibration = CalibrationPhase::Idle { last: Some(crate::imu::CalibrationOutcome::Passed) };
        st.state = FlightState::Disarmed;
        st.blockers = crate::supervisor::Blockers::default();
        assert_eq!(led_pattern(&st), LedPattern::Ready);
        st.blockers.insert(Blocker::LinkNotGood);
        assert_eq!(led_pattern(&st), LedPattern::Blocked);
        st.state = FlightState::Armed;
        assert_eq!(led_pattern(&st), LedPattern::Armed);
        st.state = FlightState::FailsafeLevel;
        assert_eq!(led_pattern(&st), LedPattern::Failsafe);
        st.state = FlightState::Fault;
        assert_eq!(led_pattern(&st), LedPattern::SensorFault { blinks: 1 });
        st.state = FlightState::Calibrating;
        assert_eq!(led_pattern(&st), LedPattern::Calibrating);
        st.state = FlightState::Disarmed;
        st.calibration = CalibrationPhase::Averaging { restarts: 0 };
        assert_eq!(led_pattern(&st), LedPattern::Calibrating);
    }

    #[test]
    fn debug_fields_come_from_sticks_motor1_tilt_and_targets() {
        let mut st = boot_status();
        st.motor_command = [12.5, 0.0, 0.0, 0.0];
        st.target_rad = [0.1, -0.2, 3.0];
        let f = debug_fields(&st);
        assert_eq!(f.motor1_cmd, 12.5);
        assert_eq!((f.pitch_target_rad, f.roll_target_rad), (0.1, -0.2));
    }
}
