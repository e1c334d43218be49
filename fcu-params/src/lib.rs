//! The parameter table: every setting a ground station may read and change, one definition
//! for the firmware, the simulator and the tests.
//!
//! Each parameter is a name (at most [`NAME_LEN`] characters, upper case, as MAVLink's
//! `param_id` carries it and MAVProxy writes it), a unit, bounds, a step (any value, whole
//! numbers, or quarter microseconds, the capture clock's resolution), when a change may apply
//! ([`Applies`]), and the setting of [`Config`] it reads and writes. Every value is an `f32` (MAVLink's
//! `REAL32`); whole-number parameters stay far below 2^24, so they are exact. Each is kept in
//! the units the table shows (an angle in degrees, not radians), so the value a set takes is the
//! value read back, saved and loaded, bit for bit (a proptest checks every parameter).
//!
//! A change goes through [`set`]: a value that is not finite, out of bounds, off its step, not
//! allowed while changes are restricted, or that makes [`Config::validate`] fail is refused
//! with the rule it breaks (a short text for a `STATUSTEXT`), and the configuration is left as
//! it was. The configuration is only the source of the values: the flight controller takes a
//! changed one through [`apply`] ([`check_change`], then
//! [`FlightController::take_change`]).
//!
//! This crate is cold code, run on a ground station's request and at boot, never in the control
//! tick: the firmware builds it for size (opt-level "z") while fcu-core keeps opt-level 3.
//!
//! [`Config::default()`] is the default set. The reference profile keeps no parameters: its
//! values are the C code's, some of them (the 31.25 ms radio timeout, the Mahony filter's
//! constants) not on the table's steps.
//!
//! [`snapshot`] is the whole set as it is kept in flash.
//!
//! # For a link
//!
//! - `PARAM_REQUEST_LIST` / `PARAM_REQUEST_READ`: [`count`], [`name`], [`value`] by index,
//!   [`index_of`] for a `param_id` (16 bytes, NUL-terminated when shorter).
//! - `PARAM_SET`: copy the configuration in force, [`set`] it with changes restricted or not
//!   ([`FlightController::changes_restricted`]); taken, give the copy to [`apply`] (or, with
//!   the halves in two tasks, [`check_change`] and the change to each half's `take_config`),
//!   echo [`Applied::value`] and, if [`Applied::also_changed`] names one, that
//!   parameter too; refused, echo [`Refusal::value_in_force`] and send the name and
//!   [`Refusal::rule`] as a `STATUSTEXT`. An unknown name has no value to echo.
//! - Saving: [`values`] into [`snapshot::plan_save`]; at boot [`snapshot::load_config`].
//! - Files in MAVProxy's format: [`write_file`]; MAVProxy's and QGroundControl's: [`apply_file`],
//!   every reader's lines through [`file::lines`].

#![no_std]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]

#[cfg(test)]
extern crate std;

mod field;
pub mod file;
pub mod snapshot;

use fcu_core::config::{Config, ConfigError};
use fcu_core::filter::BiquadCoeffs;
use fcu_core::flight::{ChangeKind, ConfigChange, TakeError};
use fcu_core::rc::{Function, StickCounts, COUNTS_PER_US};
use fcu_core::supervisor::{SafetyConfig, SupervisorConfig};
use fcu_core::FlightController;
use field::{Alt, Axis, Endpoint, Field, Gain, SafetyTime, Stick};

/// The longest name: MAVLink's `param_id` is 16 bytes, NUL-terminated only when shorter.
pub const NAME_LEN: usize = 16;

/// When a change may be made and when it takes effect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Applies {
    /// At any time, armed too, at once (in RAM; saved after disarming): gains, angle and rate
    /// limits, telemetry rates.
    Anytime,
    /// Only while disarmed, at once: the radio, gestures, failsafe times, filters, battery.
    /// Changing how the sticks read or when the failsafe acts mid-flight could move the
    /// motors in ways the pilot did not command.
    Disarmed,
    /// Only while disarmed, in force from the next boot: the link's protocol.
    Reboot,
}

impl Applies {
    /// What a change of a parameter that applies so reaches: only [`Applies::Anytime`] is an
    /// in-flight change.
    pub fn kind(self) -> ChangeKind {
        match self {
            Applies::Anytime => ChangeKind::InFlight,
            Applies::Disarmed | Applies::Reboot => ChangeKind::GroundOnly,
        }
    }

    /// As the parameter list says it.
    pub fn describe(self) -> &'static str {
        match self {
            Applies::Anytime => "any time",
            Applies::Disarmed => "disarmed",
            Applies::Reboot => "after reboot",
        }
    }
}

/// The values a parameter may take between its bounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    Any,
    /// Whole numbers.
    Integer,
    /// Multiples of a quarter microsecond: one radio capture count.
    QuarterUs,
}

/// A parameter's unit, as the list prints it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    None,
    Microseconds,
    Milliseconds,
    Hertz,
    Degrees,
    DegreesPerSecond,
    MetresPerSecond,
    Seconds,
    Pascals,
    PerSecond,
}

impl Unit {
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::None => "",
            Unit::Microseconds => "us",
            Unit::Milliseconds => "ms",
            Unit::Hertz => "Hz",
            Unit::Degrees => "deg",
            Unit::DegreesPerSecond => "deg/s",
            Unit::MetresPerSecond => "m/s",
            Unit::Seconds => "s",
            Unit::Pascals => "Pa",
            Unit::PerSecond => "1/s",
        }
    }
}

/// A setter's own refusal (bounds and steps are checked before it runs).
type SetResult = Result<(), &'static str>;

/// One parameter.
#[derive(Clone, Copy)]
pub struct Param {
    pub name: &'static str,
    pub unit: Unit,
    pub min: f32,
    pub max: f32,
    pub step: Step,
    pub applies: Applies,
    field: Field,
    /// One line for the parameter list. Only with the `descriptions` feature, which the
    /// firmware leaves off (docs/performance.md, «descriptions on the host»).
    #[cfg(feature = "descriptions")]
    pub description: &'static str,
}

impl core::fmt::Debug for Param {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Param").field("name", &self.name).finish_non_exhaustive()
    }
}

impl Param {
    /// The value in `cfg`.
    pub fn get(&self, cfg: &Config) -> f32 {
        self.field.get(cfg)
    }
}

/// Why a set was refused. Every rule is at most [`RULE_LEN`] characters, so that a
/// `STATUSTEXT` (50) holds the parameter's name, ": " and the rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refusal {
    pub rule: &'static str,
    /// The parameter's value in force (unchanged), `None` for an unknown parameter.
    pub value_in_force: Option<f32>,
}

/// The longest refusal rule, characters.
pub const RULE_LEN: usize = 32;

/// A set that was taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Applied {
    /// The value now in force (what a `PARAM_VALUE` echoes).
    pub value: f32,
    /// Another parameter the set moved with it (a radio map entry gives its input to the
    /// function that had it, which takes the old one): the ground station must be told.
    pub also_changed: Option<usize>,
}

pub const RULE_NOT_FINITE: &str = "not a finite number";
pub const RULE_BELOW_MIN: &str = "below the minimum";
pub const RULE_ABOVE_MAX: &str = "above the maximum";
pub const RULE_NOT_WHOLE: &str = "not a whole number";
pub const RULE_NOT_QUARTER_US: &str = "not a multiple of 0.25 us";
pub const RULE_UNKNOWN: &str = "unknown parameter";
pub const RULE_ARMED: &str = "only while disarmed";
pub const RULE_NOT_TICKS: &str = "not a whole number of ticks";
pub const RULE_REV: &str = "REV must be 1 or -1";
pub const RULE_NO_SAFETY: &str = "not used by this profile";
pub const RULE_FILTER: &str = "cut-off: 40..300 Hz in 10s";
pub const RULE_FILTER_TICK: &str = "cut-offs are for an 800 Hz tick";

/// The number of parameters.
pub fn count() -> usize {
    TABLE.len()
}

/// The parameter at `index`.
pub fn param(index: usize) -> Option<&'static Param> {
    TABLE.get(index)
}

/// One line on what the parameter at `index` does (for the parameter list).
#[cfg(feature = "descriptions")]
pub fn description(index: usize) -> Option<&'static str> {
    param(index).map(|p| p.description)
}

/// The name of the parameter at `index`.
pub fn name(index: usize) -> Option<&'static str> {
    param(index).map(|p| p.name)
}

/// The value of the parameter at `index` in `cfg`.
pub fn value(cfg: &Config, index: usize) -> Option<f32> {
    param(index).map(|p| p.get(cfg))
}

/// The index of the parameter named `id`: MAVLink's `param_id` as it arrives (up to 16 bytes,
/// ended by the first NUL if shorter) or a plain name. Names are matched exactly (upper case).
/// An id longer than 16 bytes with no NUL in its first 16 is no name: `None`.
pub fn index_of(id: &[u8]) -> Option<usize> {
    let end = id.iter().position(|&b| b == 0).unwrap_or(id.len());
    if end > NAME_LEN {
        return None;
    }
    let name = id.get(..end)?;
    TABLE.iter().position(|p| p.name.as_bytes() == name)
}

/// Set the parameter at `index` to `value` in `cfg`, with changes restricted or not
/// ([`FlightController::changes_restricted`]): the value in force afterwards, or the rule that
/// refused it (and `cfg` as it was). The value a parameter already reads is taken at any time,
/// and changes nothing.
pub fn set(cfg: &mut Config, index: usize, value: f32, changes_restricted: bool) -> Result<Applied, Refusal> {
    let Some(p) = param(index) else {
        return Err(Refusal { rule: RULE_UNKNOWN, value_in_force: None });
    };
    let refuse = |rule| Refusal { rule, value_in_force: Some(p.get(cfg)) };
    check_value(p, value).map_err(refuse)?;
    if value.to_bits() == p.get(cfg).to_bits() {
        // Nothing moves (a file pushed whole while armed sets every value it already has).
        return Ok(Applied { value, also_changed: None });
    }
    if !p.applies.kind().allowed(changes_restricted) {
        return Err(refuse(RULE_ARMED));
    }
    let mut next = *cfg;
    p.field.set(&mut next, value).map_err(refuse)?;
    if let Err(e) = next.validate() {
        let rule = match e {
            fcu_core::ConfigError::Rc => next.rc.problem().unwrap_or(e.rule()),
            _ => e.rule(),
        };
        return Err(refuse(rule));
    }
    let also_changed = TABLE.iter().enumerate().position(|(i, q)| i != index && q.get(&next).to_bits() != q.get(cfg).to_bits());
    *cfg = next;
    Ok(Applied { value: p.get(cfg), also_changed })
}

/// [`set`] by name (see [`index_of`]).
pub fn set_by_name(cfg: &mut Config, id: &[u8], value: f32, changes_restricted: bool) -> Result<Applied, Refusal> {
    match index_of(id) {
        Some(i) => set(cfg, i, value, changes_restricted),
        None => Err(Refusal { rule: RULE_UNKNOWN, value_in_force: None }),
    }
}

/// Finite, within bounds, on the step.
fn check_value(p: &Param, v: f32) -> Result<(), &'static str> {
    if !v.is_finite() {
        return Err(RULE_NOT_FINITE);
    }
    if v < p.min {
        return Err(RULE_BELOW_MIN);
    }
    if v > p.max {
        return Err(RULE_ABOVE_MAX);
    }
    let (steps, rule) = match p.step {
        Step::Any => return Ok(()),
        Step::Integer => (v, RULE_NOT_WHOLE),
        Step::QuarterUs => (v * 4.0, RULE_NOT_QUARTER_US),
    };
    // Within bounds, |steps| < 2^24: it converts to i32 and back unchanged only if whole.
    if (steps as i32) as f32 != steps {
        return Err(rule);
    }
    Ok(())
}

/// Every parameter's value in `cfg`, in table order.
pub fn values(cfg: &Config) -> [f32; COUNT] {
    core::array::from_fn(|i| value(cfg, i).unwrap_or(0.0))
}

/// `base` with every parameter set to `values` (table order), checked as a whole: the
/// configuration, or the first rule broken (a value off its bounds or step, a radio map that
/// is not a permutation, or a whole that does not validate). For a snapshot loaded at boot:
/// one parameter at a time could pass through invalid combinations.
pub fn with_values(base: &Config, values: &[f32; COUNT]) -> Result<Config, &'static str> {
    with_values_at(base, values).map_err(|(_, rule)| rule)
}

/// [`with_values`], with the index of the parameter at fault when one value is (`None` when
/// only the whole set breaks a rule).
pub fn with_values_at(base: &Config, values: &[f32; COUNT]) -> Result<Config, (Option<usize>, &'static str)> {
    for (i, (p, &v)) in TABLE.iter().zip(values).enumerate() {
        check_value(p, v).map_err(|rule| (Some(i), rule))?;
    }
    // Set one at a time, a radio map entry gives its input to the function that had it: a
    // map that is not a permutation would come out silently rearranged.
    if let Some(i) = repeated_map_entry(values) {
        return Err((Some(i), RULE_RCMAP));
    }
    let mut cfg = *base;
    for (i, (p, &v)) in TABLE.iter().zip(values).enumerate() {
        p.field.set(&mut cfg, v).map_err(|rule| (Some(i), rule))?;
    }
    cfg.validate().map_err(|e| {
        let rule = match e {
            fcu_core::ConfigError::Rc => cfg.rc.problem().unwrap_or(e.rule()),
            _ => e.rule(),
        };
        (None, rule)
    })?;
    Ok(cfg)
}

/// The radio map's rule, as [`RcConfig::problem`](fcu_core::rc::RcConfig::problem) words it.
pub use fcu_core::rc::RULE_RCMAP;

/// The first radio map entry (`RCMAP_*`, in table order) that names an input an earlier one
/// already names, if any.
fn repeated_map_entry(values: &[f32; COUNT]) -> Option<usize> {
    let mut seen = [false; fcu_core::rc::CHANNELS + 1];
    for (i, (p, &v)) in TABLE.iter().zip(values).enumerate() {
        if let Field::RcMap(_) = p.field {
            // Checked whole, 1..4.
            let slot = seen.get_mut(v as usize)?;
            if *slot {
                return Some(i);
            }
            *slot = true;
        }
    }
    None
}

/// A parameter file's line that could not be taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FileError {
    /// 1-based; 0 when the lines are each fine but the set they make is refused.
    pub line: usize,
    pub rule: &'static str,
}

/// The set in MAVProxy's `param save` format: a `NAME VALUE` line per parameter, in table
/// order, each value as the shortest text that reads back as the same `f32`.
pub fn write_file(out: &mut impl core::fmt::Write, cfg: &Config) -> core::fmt::Result {
    for p in TABLE.iter() {
        writeln!(out, "{} {}", p.name, p.get(cfg))?;
    }
    Ok(())
}

/// `base` with the parameters a file names ([`mod@file`]'s formats: MAVProxy's `NAME VALUE`
/// lines or QGroundControl's `.params`), checked as a whole as [`with_values`] does: a file
/// sets a whole radio, whose endpoints are valid together but not necessarily one at a time.
/// A line that does not read, an unknown name, a name set twice, a value off its own bounds
/// or step, and a radio map entry that makes the map no permutation are refused with their
/// line; a set refused as a whole with line 0.
pub fn apply_file(base: &Config, text: &str) -> Result<Config, FileError> {
    let mut v = values(base);
    let mut from_line = [0usize; COUNT];
    for entry in file::lines(text) {
        let entry = entry.map_err(|e| FileError { line: e.line, rule: e.problem.rule() })?;
        let err = |rule| FileError { line: entry.line, rule };
        let i = index_of(entry.name.as_bytes()).ok_or(err(RULE_UNKNOWN))?;
        let (Some(p), Some(slot), Some(line)) = (TABLE.get(i), v.get_mut(i), from_line.get_mut(i)) else {
            return Err(err(RULE_UNKNOWN));
        };
        if *line != 0 {
            return Err(err(file::RULE_TWICE));
        }
        // A value out of its own bounds is this line's fault, whatever the others say.
        check_value(p, entry.value).map_err(err)?;
        *slot = entry.value;
        *line = entry.line;
    }
    if let Some(line) = file::repeated_map_line(&v, &from_line) {
        return Err(FileError { line, rule: RULE_RCMAP });
    }
    with_values(base, &v).map_err(|rule| FileError { line: 0, rule })
}

/// Why a new configuration may not replace the one in force.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ApplyError {
    /// The new configuration cannot fly.
    Invalid(ConfigError),
    /// Changes are restricted (arming, flying or in the failsafe's level stage), and a
    /// parameter that may change only on the ground would change.
    Armed,
    /// A setting no parameter reaches changed (timing, sensors, estimator, mixer, pulse
    /// rules, the kind of supervisor...): it needs a new controller.
    NeedsRestart,
}

impl ApplyError {
    /// The rule, short enough for a ground station's status line (at most [`RULE_LEN`]).
    pub fn rule(self) -> &'static str {
        match self {
            ApplyError::Invalid(e) => e.rule(),
            ApplyError::Armed => RULE_ARMED,
            ApplyError::NeedsRestart => "needs a restart",
        }
    }
}

impl From<TakeError> for ApplyError {
    fn from(e: TakeError) -> Self {
        match e {
            TakeError::Restricted => ApplyError::Armed,
            TakeError::OtherSupervisor => ApplyError::NeedsRestart,
        }
    }
}

/// What a change from `old` to `new` reaches, by the table alone: [`ChangeKind::GroundOnly`]
/// when a parameter the table marks as not changeable in flight differs (bit for bit),
/// [`ChangeKind::InFlight`] otherwise. [`check_change`] gives it after its checks; a caller
/// whose `new` comes from `old` through the table's own setters ([`set`], [`with_values`]) has
/// those by construction, and need not link `check_change`'s field-by-field comparison of two
/// configurations (about 2 KB of flash on the board).
pub fn change_kind(old: &Config, new: &Config) -> ChangeKind {
    TABLE.iter().filter(|p| p.get(new).to_bits() != p.get(old).to_bits()).fold(ChangeKind::InFlight, |kind, p| kind.max(p.applies.kind()))
}

/// Whether `new` may replace `old` at run time, with changes restricted or not
/// ([`FlightController::changes_restricted`]), and what it reaches: the change to hand to the
/// flight controller ([`FlightController::take_change`], or each half's `take_config`).
///
/// Derived from the table alone. `new` must be valid and reachable from `old` through the
/// parameters: `old` with every parameter whose value differs set to `new`'s must be `new`,
/// field for field (anything else, or a value no setter takes, is [`ApplyError::NeedsRestart`]).
/// The change is [`ChangeKind::GroundOnly`] when a parameter the table marks as not
/// changeable in flight differs, and refused as [`ApplyError::Armed`] by the rule the tick
/// owns ([`ChangeKind::allowed`]), which the tick applies again when it takes the change.
pub fn check_change(old: &Config, new: &Config, changes_restricted: bool) -> Result<ConfigChange, ApplyError> {
    new.validate().map_err(ApplyError::Invalid)?;
    let mut reached = *old;
    let kind = change_kind(old, new);
    for p in TABLE.iter() {
        let v = p.get(new);
        // Against what the sets so far made: a radio map entry moves the one it swaps with.
        if v.to_bits() != p.get(&reached).to_bits() {
            p.field.set(&mut reached, v).map_err(|_| ApplyError::NeedsRestart)?;
        }
    }
    if reached != *new {
        return Err(ApplyError::NeedsRestart);
    }
    if !kind.allowed(changes_restricted) {
        return Err(ApplyError::Armed);
    }
    Ok(ConfigChange { cfg: *new, kind })
}

/// Give `fc` the configuration `cfg` at run time: [`check_change`] against the one in force,
/// then [`FlightController::take_change`]. Refused with nothing changed.
pub fn apply(fc: &mut FlightController, cfg: &Config) -> Result<(), ApplyError> {
    let change = check_change(fc.config(), cfg, fc.changes_restricted())?;
    fc.take_change(&change)?;
    Ok(())
}

/// The parameter list as Markdown, with `cfg`'s values as the defaults: what
/// `docs/parameters.md` holds (a test regenerates it and compares).
#[cfg(feature = "descriptions")]
pub fn write_markdown(out: &mut impl core::fmt::Write, cfg: &Config) -> core::fmt::Result {
    writeln!(out, "| Name | Default | Unit | Range | Step | Change | Meaning |")?;
    writeln!(out, "|---|---|---|---|---|---|---|")?;
    for p in TABLE.iter() {
        let step = match p.step {
            Step::Any => "any",
            Step::Integer => "1",
            Step::QuarterUs => "0.25",
        };
        writeln!(
            out,
            "| `{}` | {} | {} | {} .. {} | {} | {} | {} |",
            p.name,
            p.get(cfg),
            p.unit.symbol(),
            p.min,
            p.max,
            step,
            p.applies.describe(),
            p.description
        )?;
    }
    Ok(())
}

/// A hash of the table's names in order (FNV-1a, 32 bits, each name followed by a NUL): a
/// snapshot saved by a firmware with another table is refused, never read into the wrong
/// parameters.
pub const LAYOUT_HASH: u32 = layout_hash(&TABLE);

/// FNV-1a over the names of `table`, each followed by a NUL.
// Evaluated by the compiler for the table: an index out of bounds would fail the build.
#[allow(clippy::indexing_slicing)]
const fn layout_hash(table: &[Param]) -> u32 {
    let mut h: u32 = 0x811c_9dc5;
    let mut i = 0;
    while i < table.len() {
        let name = table[i].name.as_bytes();
        let mut j = 0;
        while j <= name.len() {
            let b = if j < name.len() { name[j] } else { 0 };
            h = (h ^ b as u32).wrapping_mul(0x0100_0193);
            j += 1;
        }
        i += 1;
    }
    h
}

// --- conversions -------------------------------------------------------------------------

fn us_from_counts(c: u16) -> f32 {
    f32::from(c) / COUNTS_PER_US as f32
}

/// The endpoint `which` of radio input `input` (from 0) to `us`.
fn set_endpoint_us(cfg: &mut Config, input: usize, us: f32, which: Endpoint) -> SetResult {
    if let Some(e) = cfg.rc.inputs.get_mut(input) {
        *field::endpoint_mut(e, which) = counts_from_us(us);
    }
    Ok(())
}

/// Bounds and step checked: `us` is a multiple of 0.25 within 16 384 µs.
fn counts_from_us(us: f32) -> u16 {
    (us * COUNTS_PER_US as f32) as u16
}

fn stick_us(s: StickCounts) -> f32 {
    f32::from(s.0) / COUNTS_PER_US as f32
}

fn stick_from_us(us: f32) -> StickCounts {
    StickCounts((us * COUNTS_PER_US as f32) as i16)
}

/// The whole integration rate (`Timing::integration_hz`, the rate every per-tick integration
/// assumes, not the timer's real [`tick_hz`](fcu_core::config::Timing::tick_hz)) as a whole
/// number, for exact conversions (validated configurations integrate at a whole rate; 0
/// otherwise, which no conversion accepts).
fn whole_integration_hz(cfg: &Config) -> u32 {
    let hz = cfg.timing.integration_hz;
    // Between 0 and 10^6, so finite, and whole if it converts to u32 and back unchanged.
    if hz > 0.0 && hz < 1.0e6 && (hz as u32) as f32 == hz {
        hz as u32
    } else {
        0
    }
}

fn ms_from_ticks(cfg: &Config, ticks: u32) -> f32 {
    let hz = whole_integration_hz(cfg);
    if hz == 0 {
        return 0.0;
    }
    (ticks as f32 * 1000.0) / hz as f32
}

/// Whole milliseconds (checked, within the parameters' bounds) to ticks, refused unless exact.
/// In u32: ms·hz = (ms / 1000)·hz·1000 + (ms % 1000)·hz, the second under 10^9 for hz < 10^6.
fn ticks_from_ms(cfg: &Config, ms: f32) -> Result<u32, &'static str> {
    let (ms, hz) = (ms as u32, whole_integration_hz(cfg));
    let rest = (ms % 1000) * hz;
    if ms == 0 || hz == 0 || rest % 1000 != 0 {
        return Err(RULE_NOT_TICKS);
    }
    (ms / 1000).checked_mul(hz).and_then(|t| t.checked_add(rest / 1000)).ok_or(RULE_NOT_TICKS)
}

fn safety(cfg: &Config) -> SafetyConfig {
    match cfg.supervisor {
        SupervisorConfig::Safe(s) => s,
        SupervisorConfig::Reference => SafetyConfig::DEFAULT,
    }
}

/// The safe supervisor's time `which`, in milliseconds.
fn safety_ms(cfg: &Config, which: SafetyTime) -> f32 {
    ms_from_ticks(cfg, field::safety_ticks(&safety(cfg), which))
}

/// The safe supervisor's time `which` to `ms` (checked whole).
fn set_safety_ms(cfg: &mut Config, ms: f32, which: SafetyTime) -> SetResult {
    let ticks = ticks_from_ms(cfg, ms)?;
    match &mut cfg.supervisor {
        SupervisorConfig::Safe(s) => {
            *field::safety_ticks_mut(s, which) = ticks;
            Ok(())
        }
        SupervisorConfig::Reference => Err(RULE_NO_SAFETY),
    }
}

/// The gyro filter's cut-off: the table's for a design it lists, else the Butterworth cut-off
/// its coefficients give, whole hertz (for a design at `fs` with `k = tan(π·fc/fs)`,
/// `(1 − a1 − a2) / (1 + a1 − a2) = k²`, the stored `a` being pre-negated).
fn gyro_cutoff_hz(cfg: &Config) -> f32 {
    let c = &cfg.gyro_filter;
    let listed = GYRO_DESIGNS_800_HZ.iter().find(|d| d.1 == c.a1.to_bits() && d.2 == c.a2.to_bits());
    if let (Some(d), true) = (listed, cfg.timing.integration_hz == 800.0) {
        return f32::from(d.0);
    }
    let k2 = (1.0 - c.a1 - c.a2) / (1.0 + c.a1 - c.a2);
    if !(k2 > 0.0 && k2.is_finite()) {
        return 0.0;
    }
    libm::roundf(libm::atanf(libm::sqrtf(k2)) * cfg.timing.integration_hz / core::f32::consts::PI)
}

fn set_gyro_cutoff(cfg: &mut Config, hz: f32) -> SetResult {
    if cfg.timing.integration_hz != 800.0 {
        return Err(RULE_FILTER_TICK);
    }
    cfg.gyro_filter = gyro_design_800_hz(hz).ok_or(RULE_FILTER)?;
    Ok(())
}

/// The gyro low-pass a cut-off of `hz` gives at an 800 Hz tick, from [`GYRO_DESIGNS_800_HZ`].
fn gyro_design_800_hz(hz: f32) -> Option<BiquadCoeffs> {
    let &(_, a1, a2, b0) = GYRO_DESIGNS_800_HZ.iter().find(|d| f32::from(d.0) == hz)?;
    let b0 = f32::from_bits(b0);
    Some(BiquadCoeffs { a1: f32::from_bits(a1), a2: f32::from_bits(a2), b0, b1: 2.0 * b0, b2: b0 })
}

/// The cut-offs `GYRO_LPF_HZ` offers at the 800 Hz tick, with the bits of what
/// [`BiquadCoeffs::butterworth_lowpass`] designs for them (`a1`, `a2`, `b0`; `b1 = 2·b0`,
/// `b2 = b0`): tested equal, bit for bit. A table, because the design's double-precision
/// tangent would bring the soft-double routines into the firmware (some 8 KB of flash).
const GYRO_DESIGNS_800_HZ: [(u16, u32, u32, u32); 27] = [
    (40, 0x3fc7cf71, 0xbf242f9d, 0x3ca485d8),
    (50, 0x3fba24a7, 0xbf12f5b9, 0x3cf56358),
    (60, 0x3facaafa, 0xbf039451, 0x3d28f974),
    (70, 0x3f9f6355, 0xbeebbd1e, 0x3d5c5f94),
    (80, 0x3f924d2f, 0xbed35abb, 0x3d8a25ff),
    (90, 0x3f8566e2, 0xbebdbd8a, 0x3da82202),
    (100, 0x3f715bef, 0xbeaaaaab, 0x3dc7f2cd),
    (110, 0x3f583eb9, 0xbe99ef4b, 0x3de971d9),
    (120, 0x3f3f6f1d, 0xbe8b5fc2, 0x3e0640c4),
    (130, 0x3f26e570, 0xbe7dad98, 0x3e1885f6),
    (140, 0x3f0e9995, 0xbe6869d4, 0x3e2b80e0),
    (150, 0x3eed0636, 0xbe56bf9f, 0x3e3f2ccd),
    (160, 0x3ebd32b1, 0xbe4883ea, 0x3e5387a2),
    (170, 0x3e8da6fc, 0xbe3d946a, 0x3e68919c),
    (180, 0x3e3ca28b, 0xbe35d70a, 0x3e7e4d20),
    (190, 0x3dbc7e75, 0xbe313975, 0x3e8a5f47),
    (200, 0x2515f61a, 0xbe2fb0cd, 0x3e95f61a),
    (210, 0xbdbc7e75, 0xbe313975, 0x3ea1ef16),
    (220, 0xbe3ca28b, 0xbe35d70a, 0x3eae4f33),
    (230, 0xbe8da6fc, 0xbe3d946a, 0x3ebb1c4c),
    (240, 0xbebd32b1, 0xbe4883ea, 0x3ec85d2a),
    (250, 0xbeed0636, 0xbe56bf9f, 0x3ed61981),
    (260, 0xbf0e9995, 0xbe6869d4, 0x3ee45a05),
    (270, 0xbf26e570, 0xbe7dad98, 0x3ef3286b),
    (280, 0xbf3f6f1d, 0xbe8b5fc2, 0x3f0147c0),
    (290, 0xbf583eb9, 0xbe99ef4b, 0x3f094d98),
    (300, 0xbf715bef, 0xbeaaaaab, 0x3f11ac51),
];

// --- the table ----------------------------------------------------------------------------

macro_rules! rc_map {
    ($name:literal, $f:expr, $what:literal) => {
        Param {
            name: $name,
            unit: Unit::None,
            min: 1.0,
            max: 4.0,
            step: Step::Integer,
            applies: Applies::Disarmed,
            field: Field::RcMap($f),
            #[cfg(feature = "descriptions")]
            description: concat!("radio input (1-4) carrying ", $what, "; the function that had it takes the old one"),
        }
    };
}

macro_rules! rc_endpoint {
    ($name:literal, $input:literal, $which:ident, $what:literal) => {
        Param {
            name: $name,
            unit: Unit::Microseconds,
            min: 500.0,
            max: 2500.0,
            step: Step::QuarterUs,
            applies: Applies::Disarmed,
            field: Field::RcEndpoint($input - 1, Endpoint::$which),
            #[cfg(feature = "descriptions")]
            description: concat!("radio input ", $input, ": ", $what),
        }
    };
}

macro_rules! rc_rev {
    ($name:literal, $input:literal) => {
        Param {
            name: $name,
            unit: Unit::None,
            min: -1.0,
            max: 1.0,
            step: Step::Integer,
            applies: Applies::Disarmed,
            field: Field::RcReversed($input - 1),
            #[cfg(feature = "descriptions")]
            description: concat!("radio input ", $input, ": 1 normal, -1 reversed"),
        }
    };
}

/// The three endpoints of radio input `$input`, in table order.
macro_rules! rc_min {
    ($name:literal, $input:literal) => {
        rc_endpoint!($name, $input, Min, "shortest pulse (a full deflection, or the throttle's bottom)")
    };
}

macro_rules! rc_trim {
    ($name:literal, $input:literal) => {
        rc_endpoint!($name, $input, Trim, "centre pulse (unused on the throttle)")
    };
}

macro_rules! rc_max {
    ($name:literal, $input:literal) => {
        rc_endpoint!($name, $input, Max, "longest pulse (a full deflection, or full throttle)")
    };
}

macro_rules! gain {
    ($name:literal, $axis:ident, $gain:ident, $max:literal, $what:literal) => {
        Param {
            name: $name,
            unit: Unit::None,
            min: 0.0,
            max: $max,
            step: Step::Any,
            applies: Applies::Anytime,
            field: Field::Gain(Axis::$axis, Gain::$gain),
            #[cfg(feature = "descriptions")]
            description: $what,
        }
    };
}

macro_rules! safety_ms {
    ($name:literal, $which:ident, $min:literal, $max:literal, $what:literal) => {
        Param {
            name: $name,
            unit: Unit::Milliseconds,
            min: $min,
            max: $max,
            step: Step::Integer,
            applies: Applies::Disarmed,
            field: Field::Safety(SafetyTime::$which),
            #[cfg(feature = "descriptions")]
            description: $what,
        }
    };
}

macro_rules! alt {
    ($name:literal, $which:ident, $unit:ident, $min:literal, $max:literal, $step:ident, $applies:ident, $what:literal) => {
        Param {
            name: $name,
            unit: Unit::$unit,
            min: $min,
            max: $max,
            step: Step::$step,
            applies: Applies::$applies,
            field: Field::Alt(Alt::$which),
            #[cfg(feature = "descriptions")]
            description: $what,
        }
    };
}

macro_rules! stick_us {
    ($name:literal, $which:ident, $min:literal, $max:literal, $what:literal) => {
        Param {
            name: $name,
            unit: Unit::Microseconds,
            min: $min,
            max: $max,
            step: Step::QuarterUs,
            applies: Applies::Disarmed,
            field: Field::Stick(Stick::$which),
            #[cfg(feature = "descriptions")]
            description: $what,
        }
    };
}

/// The number of parameters.
pub const COUNT: usize = 60;

/// The table, in the order of indices, of `PARAM_VALUE`'s `param_index` and of a snapshot.
/// Appending keeps every index; any change of names or order changes [`LAYOUT_HASH`].
pub static TABLE: [Param; COUNT] = [
    rc_map!("RCMAP_ROLL", Function::Roll, "roll (aileron)"),
    rc_map!("RCMAP_PITCH", Function::Pitch, "pitch (elevator)"),
    rc_map!("RCMAP_THROTTLE", Function::Throttle, "throttle"),
    rc_map!("RCMAP_YAW", Function::Yaw, "yaw (rudder)"),
    rc_min!("RC1_MIN", 1),
    rc_trim!("RC1_TRIM", 1),
    rc_max!("RC1_MAX", 1),
    rc_rev!("RC1_REV", 1),
    rc_min!("RC2_MIN", 2),
    rc_trim!("RC2_TRIM", 2),
    rc_max!("RC2_MAX", 2),
    rc_rev!("RC2_REV", 2),
    rc_min!("RC3_MIN", 3),
    rc_trim!("RC3_TRIM", 3),
    rc_max!("RC3_MAX", 3),
    rc_rev!("RC3_REV", 3),
    rc_min!("RC4_MIN", 4),
    rc_trim!("RC4_TRIM", 4),
    rc_max!("RC4_MAX", 4),
    rc_rev!("RC4_REV", 4),
    Param {
        name: "RC_TIMEOUT_MS",
        unit: Unit::Milliseconds,
        min: 25.0,
        max: 500.0,
        step: Step::Integer,
        applies: Applies::Disarmed,
        field: Field::RcTimeoutMs,
        #[cfg(feature = "descriptions")]
        description: "a channel without a valid pulse this long loses the link (failsafe stage 1)",
    },
    stick_us!(
        "GESTURE_US",
        GestureThreshold,
        100.0,
        449.0,
        "stick travel from centre (or the throttle's bottom) that counts for a gesture"
    ),
    stick_us!("THR_MIN_US", MinThrottle, 0.0, 400.0, "throttle travel below which the throttle is low (motors stop, disarm gesture)"),
    stick_us!("YAW_DEADBAND_US", YawDeadband, 0.0, 300.0, "yaw stick travel from centre that asks for no turn"),
    safety_ms!("ARM_HOLD_MS", ArmHold, 100.0, 5000.0, "the arm gesture must be held this long, then released"),
    safety_ms!("DISARM_HOLD_MS", DisarmHold, 100.0, 5000.0, "the disarm gesture must be held this long"),
    safety_ms!("DISARM_DELAY_MS", AutoDisarm, 1000.0, 60000.0, "armed with the throttle low this long disarms"),
    safety_ms!("FS_OFF_MS", FailsafeOff, 200.0, 10000.0, "lost radio time over a flight that stops the motors (failsafe stage 2)"),
    safety_ms!("FS_RECOVER_MS", Recovery, 200.0, 10000.0, "a good link must last this long to hand control back"),
    Param {
        name: "ANGLE_MAX",
        unit: Unit::Degrees,
        min: 5.0,
        max: 60.0,
        step: Step::Any,
        applies: Applies::Anytime,
        field: Field::AngleMaxDeg,
        #[cfg(feature = "descriptions")]
        description: "roll and pitch at full stick",
    },
    Param {
        name: "YAW_RATE_MAX",
        unit: Unit::DegreesPerSecond,
        min: 10.0,
        max: 720.0,
        step: Step::Any,
        applies: Applies::Anytime,
        field: Field::YawRateMaxDegS,
        #[cfg(feature = "descriptions")]
        description: "yaw rate at full stick",
    },
    gain!("ANG_RLL_P", Roll, OuterP, 20.0, "roll angle loop: rate demand per angle error, 1/s"),
    gain!("ANG_PIT_P", Pitch, OuterP, 20.0, "pitch angle loop: rate demand per angle error, 1/s"),
    gain!("ANG_YAW_P", Yaw, OuterP, 20.0, "heading loop: yaw rate demand per heading error, 1/s"),
    gain!("RATE_RLL_P", Roll, InnerP, 5000.0, "roll rate loop P, compare counts per rad/s"),
    gain!("RATE_RLL_I", Roll, InnerI, 5000.0, "roll rate loop I, counts per rad"),
    gain!("RATE_RLL_D", Roll, InnerD, 500.0, "roll rate loop D, counts per rad/s^2"),
    gain!("RATE_PIT_P", Pitch, InnerP, 5000.0, "pitch rate loop P, compare counts per rad/s"),
    gain!("RATE_PIT_I", Pitch, InnerI, 5000.0, "pitch rate loop I, counts per rad"),
    gain!("RATE_PIT_D", Pitch, InnerD, 500.0, "pitch rate loop D, counts per rad/s^2"),
    gain!("RATE_YAW_P", Yaw, InnerP, 5000.0, "yaw rate loop P, compare counts per rad/s"),
    gain!("RATE_YAW_I", Yaw, InnerI, 5000.0, "yaw rate loop I, counts per rad"),
    gain!("RATE_YAW_D", Yaw, InnerD, 500.0, "yaw rate loop D, counts per rad/s^2"),
    Param {
        name: "YAW_FF",
        unit: Unit::None,
        min: 0.0,
        max: 1.5,
        step: Step::Any,
        applies: Applies::Anytime,
        field: Field::YawFeedforward,
        #[cfg(feature = "descriptions")]
        description: "share of the yaw stick's rate fed straight to the yaw rate loop",
    },
    Param {
        name: "GYRO_LPF_HZ",
        unit: Unit::Hertz,
        min: 40.0,
        max: 300.0,
        step: Step::Integer,
        applies: Applies::Disarmed,
        field: Field::GyroCutoffHz,
        #[cfg(feature = "descriptions")]
        description: "gyro low-pass cut-off, 40..300 Hz in steps of 10 (second-order Butterworth at the 800 Hz tick)",
    },
    Param {
        name: "RATE_D_LPF_K",
        unit: Unit::None,
        min: 0.01,
        max: 1.0,
        step: Step::Any,
        applies: Applies::Disarmed,
        field: Field::RateDFilterK,
        #[cfg(feature = "descriptions")]
        description: "rate loop D low-pass: share of each new sample, 1 = unfiltered (0.4: ~65 Hz at 800 Hz)",
    },
    Param {
        name: "BATT_VOLT_MULT",
        unit: Unit::None,
        min: 1.0,
        max: 10.0,
        step: Step::Any,
        applies: Applies::Disarmed,
        field: Field::BatteryVoltMult,
        #[cfg(feature = "descriptions")]
        description: "battery volts per volt at the ADC pin (the board's divider: 1.5)",
    },
    Param {
        name: "LINK_PROTOCOL",
        unit: Unit::None,
        min: 0.0,
        max: 1.0,
        step: Step::Integer,
        applies: Applies::Reboot,
        field: Field::LinkProtocol,
        #[cfg(feature = "descriptions")]
        description: "USART1: 0 text lines (serial plotter), 1 MAVLink",
    },
    Param {
        name: "LINK_ATT_HZ",
        unit: Unit::Hertz,
        min: 1.0,
        max: 50.0,
        step: Step::Integer,
        applies: Applies::Anytime,
        field: Field::LinkAttitudeHz,
        #[cfg(feature = "descriptions")]
        description: "attitude messages per second",
    },
    Param {
        name: "LINK_RC_HZ",
        unit: Unit::Hertz,
        min: 1.0,
        max: 50.0,
        step: Step::Integer,
        applies: Applies::Anytime,
        field: Field::LinkRcHz,
        #[cfg(feature = "descriptions")]
        description: "radio input and motor output messages per second",
    },
    alt!(
        "ALT_MODE",
        Mode,
        None,
        0.0,
        1.0,
        Integer,
        Anytime,
        "0 manual: the throttle stick sets the thrust; 1 altitude hold: the stick centred holds the height, beyond its dead band it climbs or descends"
    ),
    alt!("CLIMB_RATE_MAX", ClimbRateMax, MetresPerSecond, 0.1, 5.0, Any, Anytime, "altitude hold: climb and descent rate at full throttle stick"),
    alt!(
        "FS_DESCENT_RATE",
        FsDescentRate,
        MetresPerSecond,
        0.1,
        3.0,
        Any,
        Disarmed,
        "descent rate to a landing: the link-loss failsafe's (with a healthy height estimate), and altitude hold's stick descent below 0.5 m"
    ),
    alt!(
        "ALT_DEADBAND_US",
        Deadband,
        Microseconds,
        0.0,
        400.0,
        QuarterUs,
        Disarmed,
        "altitude hold: throttle stick travel either side of its centre that holds the height"
    ),
    alt!("ALT_POS_P", PosP, PerSecond, 0.0, 10.0, Any, Anytime, "altitude hold: climb rate asked per metre of height error, 1/s"),
    alt!("ALT_VEL_P", VelP, None, 0.0, 2500.0, Any, Anytime, "altitude hold: throttle (us of stick) per m/s of climb-rate error"),
    alt!("ALT_VEL_I", VelI, None, 0.0, 2500.0, Any, Anytime, "altitude hold: throttle (us of stick) per metre of integrated climb-rate error"),
    alt!(
        "ALT_HOVER_US",
        Hover,
        Microseconds,
        1.0,
        900.0,
        QuarterUs,
        Anytime,
        "throttle stick travel above its bottom that hovers: the hold's first guess (it learns the airframe's in flight)"
    ),
    alt!(
        "ALT_EST_TAU",
        EstimatorTau,
        Seconds,
        0.2,
        10.0,
        Any,
        Disarmed,
        "height estimate: below 1/(2 pi tau) Hz the barometer is trusted, above it the accelerometer"
    ),
    alt!(
        "BARO_THRUST_PA",
        ThrustScale,
        Pascals,
        -100.0,
        100.0,
        Any,
        Disarmed,
        "prop wash: pressure error at full thrust, taken off the barometer in proportion to the thrust (measured per airframe)"
    ),
];

#[cfg(test)]
mod tests;
