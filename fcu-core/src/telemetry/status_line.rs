//! The STATUS line: what it says ([`StatusFields`]), how the firmware prints it
//! ([`write_status_line`]) and how a host reads it back ([`parse_status_line`]), side by side so
//! that the two cannot drift apart (a property test holds every written line to parse back to
//! the fields it was written from).
//!
//! `STATUS state=… armed=0|1 blockers=a,b|none cal=… failsafe=none|stage1|stage2 fault=…
//! vmode=manual|hold|descent alt_mode=0|1 target=1.234|none baro=ok|no-data|stuck|out-of-range|spike
//! vbat=3.912V overruns=N bus_errors=N uart_dropped=N rc_muted=N tick=N`, one space between
//! fields, ending in LF.

use core::fmt;

use super::LineBuf;
use crate::altitude::{AltMode, AltitudeStatus};
use crate::baro::BaroFault;
use crate::flight::Status;
use crate::imu::{CalibrationOutcome, CalibrationPhase, SensorFault};
use crate::supervisor::{Blocker, Blockers, FlightState};

/// Longest status line: with the longest state, calibration, fault and vertical words, every
/// blocker and every number at its 32-bit extreme it is 452 bytes.
pub const STATUS_LINE_MAX: usize = 458;

/// The word a status line starts with.
const TAG: &str = "STATUS";

/// What the status line says: the flight status the core reports and the firmware's own
/// counters. `armed=` and `failsafe=` are not fields of their own: both follow from the state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StatusFields {
    pub state: FlightState,
    /// The arming blockers that hold now.
    pub blockers: Blockers,
    pub calibration: CalibrationReport,
    pub fault: Option<SensorFault>,
    /// The vertical report: who sets the collective thrust, the mode the pilot chose
    /// (`ALT_MODE`), the hold's target and the barometer's fault.
    pub vertical: VerticalReport,
    pub battery_mv: u32,
    /// Outer steps that could not start because the previous one was still running.
    pub outer_overruns: u32,
    /// Sensor reads that failed on the bus (the tick ran without a sample).
    pub bus_errors: u32,
    /// Telemetry bytes dropped because the UART queue was full.
    pub uart_dropped_bytes: u32,
    /// Times a radio pin raised more edges in one capture wrap than a receiver can and was
    /// muted for the rest of it (interference or a broken wire: the link is then lost for it).
    pub radio_mutes: u32,
    /// Control ticks completed since boot when the snapshot was taken: dates the line to the
    /// tick, however long it waited in the UART queue.
    pub tick: u32,
}

impl StatusFields {
    /// The core's part of the line from its status; the firmware's counters start at 0 for it
    /// to fill in (`StatusFields { battery_mv, .., ..StatusFields::of(&status) }`).
    pub fn of(status: &Status) -> StatusFields {
        StatusFields {
            state: status.state,
            blockers: status.blockers,
            calibration: CalibrationReport::of(status.calibration),
            fault: status.fault,
            vertical: VerticalReport::of(&status.altitude),
            battery_mv: 0,
            outer_overruns: 0,
            bus_errors: 0,
            uart_dropped_bytes: 0,
            radio_mutes: 0,
            tick: 0,
        }
    }

    /// The `armed=` flag: the motors may turn in this state.
    pub fn armed(&self) -> bool {
        self.state.motors_may_run()
    }

    /// The failsafe stage of the state (1 = level and hold throttle, 2 = motors off).
    pub fn failsafe_stage(&self) -> Option<u8> {
        match self.state {
            FlightState::FailsafeLevel => Some(1),
            FlightState::FailsafeOff => Some(2),
            _ => None,
        }
    }
}

/// Who sets the collective thrust (`vmode=`, and the flight log's `vmode` column): the one
/// rule for the core's [`AltitudeStatus`], which fcu-log uses too.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VerticalMode {
    /// The throttle stick (mode manual, or the hold chosen but not in force: on the floor
    /// before take-off, no healthy height estimate).
    Manual,
    /// Altitude hold.
    Hold,
    /// The link-loss failsafe's descent on the height estimate.
    Descent,
}

impl VerticalMode {
    /// Every mode, in declaration order.
    pub const ALL: [VerticalMode; 3] = [VerticalMode::Manual, VerticalMode::Hold, VerticalMode::Descent];

    /// The mode in force that `status` reports.
    pub fn of(status: &AltitudeStatus) -> VerticalMode {
        if status.failsafe_descent {
            VerticalMode::Descent
        } else if status.holding {
            VerticalMode::Hold
        } else {
            VerticalMode::Manual
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            VerticalMode::Manual => "manual",
            VerticalMode::Hold => "hold",
            VerticalMode::Descent => "descent",
        }
    }

    pub fn from_name(name: &str) -> Option<VerticalMode> {
        VerticalMode::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// Every barometer fault, in declaration order.
const BARO_FAULTS: [BaroFault; 4] = [BaroFault::NoData, BaroFault::Stuck, BaroFault::OutOfRange, BaroFault::Spike];

/// A barometer fault's name (`baro=` on the status line, the flight log's `baro_fault`).
pub fn baro_fault_name(f: BaroFault) -> &'static str {
    match f {
        BaroFault::NoData => "no-data",
        BaroFault::Stuck => "stuck",
        BaroFault::OutOfRange => "out-of-range",
        BaroFault::Spike => "spike",
    }
}

/// `baro=`: `ok`, or the fault's name.
fn baro_word(f: Option<BaroFault>) -> &'static str {
    f.map_or("ok", baro_fault_name)
}

/// The vertical half as the status line says it: integers only (the target in millimetres),
/// so a line parses back to exactly what it was written from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VerticalReport {
    pub mode: VerticalMode,
    /// `ALT_MODE`, whether or not it is in force.
    pub chosen: AltMode,
    /// The height the hold holds or moves to, mm (`None` when not holding).
    pub target_mm: Option<i32>,
    pub baro_fault: Option<BaroFault>,
}

impl VerticalReport {
    /// What the core's report says (the target rounded to the millimetre).
    pub fn of(a: &AltitudeStatus) -> VerticalReport {
        VerticalReport { mode: VerticalMode::of(a), chosen: a.mode, target_mm: a.target_m.map(metres_to_mm), baro_fault: a.baro_fault }
    }

    /// The target in metres.
    pub fn target_m(&self) -> Option<f32> {
        self.target_mm.map(|mm| mm as f32 / 1000.0)
    }
}

impl Default for VerticalReport {
    /// What a core without altitude hold reports: manual, nothing held, the barometer fine.
    fn default() -> Self {
        VerticalReport::of(&AltitudeStatus::default())
    }
}

/// Metres to whole millimetres, rounded half away from zero (saturating; NaN is 0).
fn metres_to_mm(m: f32) -> i32 {
    let mm = m * 1000.0;
    (if mm < 0.0 { mm - 0.5 } else { mm + 0.5 }) as i32
}

/// The calibration as the status line words it: the calibrator's phase, with the last outcome
/// while idle (the number of motion-check restarts is not printed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationReport {
    /// The boot settling before the first calibration.
    Settling,
    /// Averaging.
    Running,
    /// Idle, and no calibration has ended yet.
    NotRun,
    /// Idle after a calibration that passed.
    Passed,
    /// Idle after a calibration the motion check never let finish.
    FailedMotion,
}

impl CalibrationReport {
    /// Every report, in declaration order.
    pub const ALL: [CalibrationReport; 5] = [
        CalibrationReport::Settling,
        CalibrationReport::Running,
        CalibrationReport::NotRun,
        CalibrationReport::Passed,
        CalibrationReport::FailedMotion,
    ];

    pub fn of(phase: CalibrationPhase) -> CalibrationReport {
        match phase {
            CalibrationPhase::Settling => CalibrationReport::Settling,
            CalibrationPhase::Averaging { .. } => CalibrationReport::Running,
            CalibrationPhase::Idle { last: None } => CalibrationReport::NotRun,
            CalibrationPhase::Idle { last: Some(CalibrationOutcome::Passed) } => CalibrationReport::Passed,
            CalibrationPhase::Idle { last: Some(CalibrationOutcome::FailedMotion) } => CalibrationReport::FailedMotion,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            CalibrationReport::Settling => "settling",
            CalibrationReport::Running => "running",
            CalibrationReport::NotRun => "none",
            CalibrationReport::Passed => "passed",
            CalibrationReport::FailedMotion => "failed-motion",
        }
    }

    pub fn from_name(name: &str) -> Option<CalibrationReport> {
        CalibrationReport::ALL.into_iter().find(|c| c.name() == name)
    }

    /// Settling or averaging: a calibration is under way.
    pub fn in_progress(self) -> bool {
        matches!(self, CalibrationReport::Settling | CalibrationReport::Running)
    }
}

/// What `fault=` says: every value, `none` first.
const FAULTS: [Option<SensorFault>; 5] =
    [None, Some(SensorFault::NotFinite), Some(SensorFault::OutOfRange), Some(SensorFault::Stuck), Some(SensorFault::NoData)];

pub fn fault_name(fault: Option<SensorFault>) -> &'static str {
    match fault {
        None => "none",
        Some(SensorFault::NotFinite) => "not-finite",
        Some(SensorFault::OutOfRange) => "out-of-range",
        Some(SensorFault::Stuck) => "stuck",
        Some(SensorFault::NoData) => "no-data",
    }
}

/// The fault a [`fault_name`] names (`Some(None)` for `none`), or `None` for any other word.
pub fn fault_from_name(name: &str) -> Option<Option<SensorFault>> {
    FAULTS.into_iter().find(|f| fault_name(*f) == name)
}

/// `failsafe=`: the failsafe stage the state is (1 = level and hold throttle, 2 = motors off).
pub fn failsafe_name(state: FlightState) -> &'static str {
    match state {
        FlightState::FailsafeLevel => "stage1",
        FlightState::FailsafeOff => "stage2",
        _ => "none",
    }
}

/// Every word `failsafe=` can say.
const FAILSAFE_NAMES: [&str; 3] = ["none", "stage1", "stage2"];

/// The line's fields, in the order it prints them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StatusKey {
    State,
    Armed,
    Blockers,
    Calibration,
    Failsafe,
    Fault,
    VerticalMode,
    AltMode,
    Target,
    Baro,
    Battery,
    OuterOverruns,
    BusErrors,
    UartDropped,
    RadioMutes,
    Tick,
}

impl StatusKey {
    /// How the field starts on the line: a space, its name, `=` (one string, so the writer
    /// puts each in with one copy).
    fn opening(self) -> &'static str {
        match self {
            StatusKey::State => " state=",
            StatusKey::Armed => " armed=",
            StatusKey::Blockers => " blockers=",
            StatusKey::Calibration => " cal=",
            StatusKey::Failsafe => " failsafe=",
            StatusKey::Fault => " fault=",
            StatusKey::VerticalMode => " vmode=",
            StatusKey::AltMode => " alt_mode=",
            StatusKey::Target => " target=",
            StatusKey::Baro => " baro=",
            StatusKey::Battery => " vbat=",
            StatusKey::OuterOverruns => " overruns=",
            StatusKey::BusErrors => " bus_errors=",
            StatusKey::UartDropped => " uart_dropped=",
            StatusKey::RadioMutes => " rc_muted=",
            StatusKey::Tick => " tick=",
        }
    }

    /// The field's name, before its `=`.
    pub fn key(self) -> &'static str {
        self.opening().trim_start_matches(' ').trim_end_matches('=')
    }
}

/// Why a line is not a status line as [`write_status_line`] writes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StatusLineError {
    /// The line does not start with `STATUS `.
    NotStatus,
    /// The field is not where it belongs: the line ends before it, or another word stands in
    /// its place.
    Missing(StatusKey),
    /// The field's value is none the writer prints: an unknown name, a blocker named twice, a
    /// count that is not a decimal number or does not fit 32 bits, a voltage not in `V.mmmV`.
    BadValue(StatusKey),
    /// The field contradicts the state (`armed=` and `failsafe=` follow from it).
    Disagrees(StatusKey),
    /// Text after the last field.
    TrailingText,
}

impl fmt::Display for StatusLineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StatusLineError::NotStatus => write!(f, "not a {TAG} line"),
            StatusLineError::Missing(k) => write!(f, "`{}=` missing where it belongs", k.key()),
            StatusLineError::BadValue(k) => write!(f, "`{}=` has a value the firmware never prints", k.key()),
            StatusLineError::Disagrees(k) => write!(f, "`{}=` disagrees with the state", k.key()),
            StatusLineError::TrailingText => write!(f, "text after the last field"),
        }
    }
}

/// Starts the field `key`.
fn push_key<const N: usize>(out: &mut LineBuf<N>, key: StatusKey) {
    out.push_str(key.opening());
}

/// Whole thousandths as `W.ttt` (the voltage in volts, the target in metres: fixed point,
/// no float formatting).
fn push_thousandths<const N: usize>(out: &mut LineBuf<N>, v: u32) {
    out.push_uint(v / 1000);
    out.push_str(".");
    let frac = v % 1000;
    if frac < 100 {
        out.push_str("0");
    }
    if frac < 10 {
        out.push_str("0");
    }
    out.push_uint(frac);
}

/// Prints the status line (blockers in [`Blocker::ALL`] order, the voltage in volts and the
/// target in metres with three decimals).
pub fn write_status_line<const N: usize>(out: &mut LineBuf<N>, f: &StatusFields) {
    out.clear();
    out.push_str(TAG);
    push_key(out, StatusKey::State);
    out.push_str(f.state.name());
    push_key(out, StatusKey::Armed);
    out.push_str(if f.armed() { "1" } else { "0" });
    push_key(out, StatusKey::Blockers);
    let mut any_blocker = false;
    for blocker in f.blockers.iter() {
        if any_blocker {
            out.push_str(",");
        }
        out.push_str(blocker.name());
        any_blocker = true;
    }
    if !any_blocker {
        out.push_str("none");
    }
    push_key(out, StatusKey::Calibration);
    out.push_str(f.calibration.name());
    push_key(out, StatusKey::Failsafe);
    out.push_str(failsafe_name(f.state));
    push_key(out, StatusKey::Fault);
    out.push_str(fault_name(f.fault));
    let v = &f.vertical;
    push_key(out, StatusKey::VerticalMode);
    out.push_str(v.mode.name());
    push_key(out, StatusKey::AltMode);
    out.push_str(alt_mode_word(v.chosen));
    push_key(out, StatusKey::Target);
    match v.target_mm {
        Some(mm) => {
            if mm < 0 {
                out.push_str("-");
            }
            push_thousandths(out, mm.unsigned_abs());
        }
        None => out.push_str("none"),
    }
    push_key(out, StatusKey::Baro);
    out.push_str(baro_word(v.baro_fault));
    push_key(out, StatusKey::Battery);
    push_thousandths(out, f.battery_mv);
    out.push_str("V");
    push_key(out, StatusKey::OuterOverruns);
    out.push_uint(f.outer_overruns);
    push_key(out, StatusKey::BusErrors);
    out.push_uint(f.bus_errors);
    push_key(out, StatusKey::UartDropped);
    out.push_uint(f.uart_dropped_bytes);
    push_key(out, StatusKey::RadioMutes);
    out.push_uint(f.radio_mutes);
    push_key(out, StatusKey::Tick);
    out.push_uint(f.tick);
    out.finish_line();
}

/// Reads a status line back (with or without its LF). Strict: every field in the writer's
/// order, each value one the writer prints, `armed=` and `failsafe=` agreeing with the state,
/// nothing after `tick=`.
pub fn parse_status_line(line: &str) -> Result<StatusFields, StatusLineError> {
    use StatusLineError::{BadValue, Disagrees, Missing};
    let line = line.strip_suffix('\n').unwrap_or(line);
    let rest = line.strip_prefix(TAG).and_then(|r| r.strip_prefix(' ')).ok_or(StatusLineError::NotStatus)?;
    let mut words = rest.split(' ');
    let mut value =
        |key: StatusKey| words.next().and_then(|w| w.strip_prefix(key.key())).and_then(|w| w.strip_prefix('=')).ok_or(Missing(key));
    let state = FlightState::from_name(value(StatusKey::State)?).ok_or(BadValue(StatusKey::State))?;
    let armed = match value(StatusKey::Armed)? {
        "0" => false,
        "1" => true,
        _ => return Err(BadValue(StatusKey::Armed)),
    };
    let blockers = parse_blockers(value(StatusKey::Blockers)?).ok_or(BadValue(StatusKey::Blockers))?;
    let calibration = CalibrationReport::from_name(value(StatusKey::Calibration)?).ok_or(BadValue(StatusKey::Calibration))?;
    let failsafe = value(StatusKey::Failsafe)?;
    if !FAILSAFE_NAMES.contains(&failsafe) {
        return Err(BadValue(StatusKey::Failsafe));
    }
    let fault = fault_from_name(value(StatusKey::Fault)?).ok_or(BadValue(StatusKey::Fault))?;
    let mode = VerticalMode::from_name(value(StatusKey::VerticalMode)?).ok_or(BadValue(StatusKey::VerticalMode))?;
    let chosen = match value(StatusKey::AltMode)? {
        "0" => AltMode::Manual,
        "1" => AltMode::Hold,
        _ => return Err(BadValue(StatusKey::AltMode)),
    };
    let target_mm = match value(StatusKey::Target)? {
        "none" => None,
        text => Some(parse_millimetres(text).ok_or(BadValue(StatusKey::Target))?),
    };
    let baro = value(StatusKey::Baro)?;
    let baro_fault = match baro {
        "ok" => None,
        name => Some(BARO_FAULTS.into_iter().find(|&b| baro_fault_name(b) == name).ok_or(BadValue(StatusKey::Baro))?),
    };
    let vertical = VerticalReport { mode, chosen, target_mm, baro_fault };
    let battery_mv = parse_millivolts(value(StatusKey::Battery)?).ok_or(BadValue(StatusKey::Battery))?;
    let mut count = |key: StatusKey| value(key).and_then(|v| parse_count(v).ok_or(BadValue(key)));
    let outer_overruns = count(StatusKey::OuterOverruns)?;
    let bus_errors = count(StatusKey::BusErrors)?;
    let uart_dropped_bytes = count(StatusKey::UartDropped)?;
    let radio_mutes = count(StatusKey::RadioMutes)?;
    let tick = count(StatusKey::Tick)?;
    if words.next().is_some() {
        return Err(StatusLineError::TrailingText);
    }
    if armed != state.motors_may_run() {
        return Err(Disagrees(StatusKey::Armed));
    }
    if failsafe != failsafe_name(state) {
        return Err(Disagrees(StatusKey::Failsafe));
    }
    Ok(StatusFields {
        state,
        blockers,
        calibration,
        fault,
        vertical,
        battery_mv,
        outer_overruns,
        bus_errors,
        uart_dropped_bytes,
        radio_mutes,
        tick,
    })
}

/// `alt_mode=`: the parameter's value.
fn alt_mode_word(m: AltMode) -> &'static str {
    match m {
        AltMode::Manual => "0",
        AltMode::Hold => "1",
    }
}

/// `W.ttt` or `-W.ttt` metres (exactly three decimals, no `-0.000`) in millimetres that fit
/// an `i32`.
fn parse_millimetres(text: &str) -> Option<i32> {
    let (negative, magnitude) = match text.strip_prefix('-') {
        Some(m) => (true, m),
        None => (false, text),
    };
    let mm = i64::from(parse_thousandths(magnitude)?);
    match (negative, mm) {
        (true, 0) => None,
        (true, mm) => i32::try_from(-mm).ok(),
        (false, mm) => i32::try_from(mm).ok(),
    }
}

/// `W.ttt` (whole units, exactly three decimals) in thousandths that fit 32 bits.
fn parse_thousandths(text: &str) -> Option<u32> {
    let (whole, thousandths) = text.split_once('.')?;
    if thousandths.len() != 3 {
        return None;
    }
    parse_count(whole)?.checked_mul(1000)?.checked_add(parse_count(thousandths)?)
}

/// `none`, or blocker names separated by commas, each once.
fn parse_blockers(text: &str) -> Option<Blockers> {
    let mut set = Blockers::default();
    if text == "none" {
        return Some(set);
    }
    for name in text.split(',') {
        let blocker = Blocker::ALL.into_iter().find(|b| b.name() == name)?;
        if set.contains(blocker) {
            return None;
        }
        set.insert(blocker);
    }
    Some(set)
}

/// A decimal count of one or more digits that fits 32 bits.
fn parse_count(text: &str) -> Option<u32> {
    if text.is_empty() {
        return None;
    }
    text.bytes().try_fold(0u32, |n, b| {
        let digit = if b.is_ascii_digit() { u32::from(b - b'0') } else { return None };
        n.checked_mul(10)?.checked_add(digit)
    })
}

/// `V.mmmV` (whole volts, exactly three decimals) in millivolts.
fn parse_millivolts(text: &str) -> Option<u32> {
    parse_thousandths(text.strip_suffix('V')?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn written(f: &StatusFields) -> LineBuf<STATUS_LINE_MAX> {
        let mut b = LineBuf::new();
        write_status_line(&mut b, f);
        b
    }

    fn fields() -> StatusFields {
        let mut blockers = Blockers::default();
        blockers.insert(Blocker::NotCalibrated);
        blockers.insert(Blocker::LinkNotGood);
        StatusFields {
            state: FlightState::Disarmed,
            blockers,
            calibration: CalibrationReport::Running,
            fault: None,
            vertical: VerticalReport::default(),
            battery_mv: 4005,
            outer_overruns: 2,
            bus_errors: 3,
            uart_dropped_bytes: 4,
            radio_mutes: 5,
            tick: 1234,
        }
    }

    const LINE: &str = "STATUS state=disarmed armed=0 blockers=not-calibrated,link-not-good cal=running failsafe=none fault=none \
                        vmode=manual alt_mode=0 target=none baro=ok vbat=4.005V overruns=2 bus_errors=3 uart_dropped=4 rc_muted=5 tick=1234\n";

    #[test]
    fn the_line_names_state_blockers_and_counters() {
        assert_eq!(written(&fields()).as_str(), LINE);
        assert_eq!(parse_status_line(LINE), Ok(fields()));
    }

    #[test]
    fn no_blockers_print_as_none_and_armed_follows_the_state() {
        let f = StatusFields {
            state: FlightState::Armed,
            blockers: Blockers::default(),
            calibration: CalibrationReport::Passed,
            battery_mv: 3700,
            outer_overruns: 0,
            bus_errors: 0,
            uart_dropped_bytes: 0,
            radio_mutes: 0,
            tick: 0,
            ..fields()
        };
        let line = "STATUS state=armed armed=1 blockers=none cal=passed failsafe=none fault=none vmode=manual alt_mode=0 \
                    target=none baro=ok vbat=3.700V overruns=0 bus_errors=0 uart_dropped=0 rc_muted=0 tick=0\n";
        assert_eq!(written(&f).as_str(), line);
        assert_eq!(parse_status_line(line.trim_end()), Ok(f), "without its LF too");
    }

    #[test]
    fn failsafe_and_fault_have_their_words() {
        let f = StatusFields { state: FlightState::FailsafeOff, fault: Some(SensorFault::Stuck), battery_mv: 50, ..fields() };
        let b = written(&f);
        assert!(
            b.as_str().contains(" failsafe=stage2 fault=stuck vmode=manual alt_mode=0 target=none baro=ok vbat=0.050V "),
            "{}",
            b.as_str()
        );
        assert_eq!(failsafe_name(FlightState::FailsafeLevel), "stage1");
        assert_eq!(CalibrationReport::of(CalibrationPhase::Averaging { restarts: 3 }), CalibrationReport::Running);
        assert_eq!(CalibrationReport::of(CalibrationPhase::Idle { last: Some(CalibrationOutcome::FailedMotion) }).name(), "failed-motion");
    }

    #[test]
    fn the_vertical_report_has_its_words_and_the_target_its_millimetres() {
        let mut a = AltitudeStatus { mode: AltMode::Hold, holding: true, target_m: Some(1.2345), ..AltitudeStatus::default() };
        let f = StatusFields { vertical: VerticalReport::of(&a), ..fields() };
        assert!(written(&f).as_str().contains(" fault=none vmode=hold alt_mode=1 target=1.235 baro=ok vbat="), "{}", written(&f).as_str());
        assert_eq!(parse_status_line(written(&f).as_str()), Ok(f));
        assert_eq!(f.vertical.target_m(), Some(1.235));
        a.failsafe_descent = true;
        a.target_m = Some(-0.0504);
        a.baro_fault = Some(BaroFault::NoData);
        let f = StatusFields { vertical: VerticalReport::of(&a), ..fields() };
        assert!(written(&f).as_str().contains(" vmode=descent alt_mode=1 target=-0.050 baro=no-data "), "{}", written(&f).as_str());
        assert_eq!(parse_status_line(written(&f).as_str()), Ok(f));
        a.holding = false;
        a.failsafe_descent = false;
        a.target_m = Some(-0.0004);
        a.baro_fault = Some(BaroFault::Spike);
        let f = StatusFields { vertical: VerticalReport::of(&a), ..fields() };
        assert!(
            written(&f).as_str().contains(" vmode=manual alt_mode=1 target=0.000 baro=spike "),
            "no `-0.000`: {}",
            written(&f).as_str()
        );
        assert_eq!(
            VerticalMode::of(&AltitudeStatus { mode: AltMode::Hold, ..AltitudeStatus::default() }),
            VerticalMode::Manual,
            "chosen, not in force"
        );
        assert_eq!(baro_fault_name(BaroFault::OutOfRange), "out-of-range");
        assert_eq!(baro_fault_name(BaroFault::Stuck), "stuck");
    }

    #[test]
    fn the_longest_line_fits() {
        let mut blockers = Blockers::default();
        for b in Blocker::ALL {
            blockers.insert(b);
        }
        let mut longest = 0;
        let longest_vertical = VerticalReport {
            mode: VerticalMode::Descent,
            chosen: AltMode::Hold,
            target_mm: Some(i32::MIN),
            baro_fault: Some(BaroFault::OutOfRange),
        };
        for state in FlightState::ALL {
            for calibration in CalibrationReport::ALL {
                for fault in FAULTS {
                    let f = StatusFields {
                        state,
                        blockers,
                        calibration,
                        fault,
                        vertical: longest_vertical,
                        battery_mv: u32::MAX,
                        outer_overruns: u32::MAX,
                        bus_errors: u32::MAX,
                        uart_dropped_bytes: u32::MAX,
                        radio_mutes: u32::MAX,
                        tick: u32::MAX,
                    };
                    let b = written(&f);
                    assert!(!b.is_truncated(), "{}", b.as_str());
                    assert_eq!(parse_status_line(b.as_str()), Ok(f));
                    longest = longest.max(b.as_bytes().len());
                }
            }
        }
        assert_eq!(longest, 452);
        let b = written(&StatusFields { blockers, ..fields() });
        assert!(b.as_str().contains(
            " blockers=not-calibrated,calibrating,link-not-good,throttle-not-low,not-level,failsafe,sensor-fault,boot-settling,gesture-not-released,motor-test,radio-calibration,saving,reboot-pending "
        ));
    }

    #[test]
    fn the_cores_status_at_boot_with_the_firmwares_counters() {
        let fc = crate::FlightController::new(&crate::Config::default()).expect("default config is valid");
        let f = StatusFields {
            battery_mv: 3950,
            outer_overruns: 1,
            bus_errors: 2,
            uart_dropped_bytes: 3,
            radio_mutes: 4,
            tick: u32::MAX,
            ..StatusFields::of(&fc.status())
        };
        let b = written(&f);
        assert_eq!(
            b.as_str(),
            "STATUS state=calibrating armed=0 blockers=none cal=settling failsafe=none \
             fault=none vmode=manual alt_mode=0 target=none baro=ok vbat=3.950V overruns=1 bus_errors=2 uart_dropped=3 rc_muted=4 tick=4294967295\n"
        );
        assert_eq!(parse_status_line(b.as_str()), Ok(f));
    }

    #[test]
    fn every_name_parses_back_to_what_it_names() {
        for s in FlightState::ALL {
            assert_eq!(FlightState::from_name(s.name()), Some(s));
        }
        for c in CalibrationReport::ALL {
            assert_eq!(CalibrationReport::from_name(c.name()), Some(c));
        }
        for f in FAULTS {
            assert_eq!(fault_from_name(fault_name(f)), Some(f));
        }
        for m in VerticalMode::ALL {
            assert_eq!(VerticalMode::from_name(m.name()), Some(m));
        }
        assert_eq!(FlightState::from_name("landed"), None);
        assert_eq!(FlightState::from_name("Armed"), None);
    }

    /// `LINE` with `from` replaced by `to` (once), parsed.
    fn edited(from: &str, to: &str) -> Result<StatusFields, StatusLineError> {
        let (head, tail) = LINE.split_once(from).unwrap_or_else(|| panic!("{from} is not in the line"));
        let mut b = LineBuf::<STATUS_LINE_MAX>::new();
        b.push_str(head);
        b.push_str(to);
        b.push_str(tail);
        parse_status_line(b.as_str())
    }

    #[test]
    fn a_malformed_line_is_refused_naming_what_is_wrong() {
        use StatusLineError::*;
        assert_eq!(parse_status_line("STATUS"), Err(NotStatus));
        assert_eq!(parse_status_line("-4\t0\t2"), Err(NotStatus));
        assert_eq!(parse_status_line("STATUS "), Err(Missing(StatusKey::State)));
        assert_eq!(edited("state=disarmed", "state=landed"), Err(BadValue(StatusKey::State)));
        assert_eq!(edited("armed=0", "armed=yes"), Err(BadValue(StatusKey::Armed)));
        assert_eq!(edited("armed=0", "armed=1"), Err(Disagrees(StatusKey::Armed)));
        assert_eq!(edited("link-not-good", "link-not-good,not-calibrated"), Err(BadValue(StatusKey::Blockers)));
        assert_eq!(edited("link-not-good", "link-lost"), Err(BadValue(StatusKey::Blockers)));
        assert_eq!(edited("not-calibrated,link-not-good", ""), Err(BadValue(StatusKey::Blockers)));
        assert_eq!(edited("cal=running", "cal=done"), Err(BadValue(StatusKey::Calibration)));
        assert_eq!(edited("failsafe=none", "failsafe=stage1"), Err(Disagrees(StatusKey::Failsafe)));
        assert_eq!(edited("failsafe=none", "failsafe=stage3"), Err(BadValue(StatusKey::Failsafe)));
        assert_eq!(edited("fault=none", "fault=broken"), Err(BadValue(StatusKey::Fault)));
        assert_eq!(edited("vbat=4.005V", "vbat=4.05V"), Err(BadValue(StatusKey::Battery)));
        assert_eq!(edited("vbat=4.005V", "vbat=4.005"), Err(BadValue(StatusKey::Battery)));
        assert_eq!(edited("vbat=4.005V", "vbat=4294968.000V"), Err(BadValue(StatusKey::Battery)));
        assert_eq!(edited("overruns=2", "overruns=-2"), Err(BadValue(StatusKey::OuterOverruns)));
        assert_eq!(edited("rc_muted=5", "rc_muted=4294967296"), Err(BadValue(StatusKey::RadioMutes)));
        assert_eq!(edited("tick=1234", "tick="), Err(BadValue(StatusKey::Tick)));
        assert_eq!(edited("vmode=manual", "vmode=auto"), Err(BadValue(StatusKey::VerticalMode)));
        assert_eq!(edited("alt_mode=0", "alt_mode=2"), Err(BadValue(StatusKey::AltMode)));
        assert_eq!(edited("target=none", "target=1.5"), Err(BadValue(StatusKey::Target)));
        assert_eq!(edited("target=none", "target=-0.000"), Err(BadValue(StatusKey::Target)));
        assert_eq!(edited("target=none", "target=2147483.648"), Err(BadValue(StatusKey::Target)));
        assert_eq!(edited("target=none", "target=--1.000"), Err(BadValue(StatusKey::Target)));
        assert_eq!(edited("baro=ok", "baro=none"), Err(BadValue(StatusKey::Baro)));
        assert_eq!(edited(" alt_mode=0", ""), Err(Missing(StatusKey::AltMode)));
        assert_eq!(edited(" bus_errors=3", ""), Err(Missing(StatusKey::BusErrors)));
        assert_eq!(edited("cal=running failsafe=none", "failsafe=none cal=running"), Err(Missing(StatusKey::Calibration)));
        assert_eq!(edited(" tick=1234", ""), Err(Missing(StatusKey::Tick)));
        assert_eq!(edited("tick=1234", "tick=1234 extra=1"), Err(TrailingText));
        assert_eq!(edited("armed=0 ", "armed=0  "), Err(Missing(StatusKey::Blockers)));
    }

    proptest::proptest! {
        #[test]
        fn every_status_written_parses_back_to_itself(
            state in 0..FlightState::ALL.len(),
            blocker_bits in 0u16..(1 << Blocker::ALL.len()),
            calibration in 0..CalibrationReport::ALL.len(),
            fault in 0..FAULTS.len(),
            vmode in 0..VerticalMode::ALL.len(),
            hold: bool,
            target_mm: Option<i32>,
            baro_fault in 0..=BARO_FAULTS.len(),
            battery_mv: u32,
            counters: [u32; 5],
        ) {
            let [outer_overruns, bus_errors, uart_dropped_bytes, radio_mutes, tick] = counters;
            let f = StatusFields {
                state: FlightState::ALL[state],
                blockers: Blockers(blocker_bits),
                calibration: CalibrationReport::ALL[calibration],
                fault: FAULTS[fault],
                vertical: VerticalReport {
                    mode: VerticalMode::ALL[vmode],
                    chosen: if hold { AltMode::Hold } else { AltMode::Manual },
                    target_mm,
                    baro_fault: BARO_FAULTS.get(baro_fault).copied(),
                },
                battery_mv,
                outer_overruns,
                bus_errors,
                uart_dropped_bytes,
                radio_mutes,
                tick,
            };
            let b = written(&f);
            proptest::prop_assert!(!b.is_truncated());
            proptest::prop_assert_eq!(parse_status_line(b.as_str()), Ok(f));
        }

        #[test]
        fn no_text_makes_the_parser_panic(text in ".{0,200}", cut in 0usize..400) {
            let _ = parse_status_line(&text);
            // Pieces of a real line, where the parser gets furthest.
            let mut at = cut.min(LINE.len());
            while !LINE.is_char_boundary(at) {
                at -= 1;
            }
            let _ = parse_status_line(&LINE[..at]);
            let _ = parse_status_line(&LINE[at..]);
        }
    }
}
