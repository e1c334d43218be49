//! The safety layer, watched from outside: an invariant monitor and deterministic input
//! generators for the property tests (`tests/safety_props.rs`) and the fuzzers (`fuzz/`).
//!
//! - [`SafetyMonitor`] observes a [`FlightController`] tick by tick (what was fed: the raw IMU
//!   words and the [`PulseBatch`]; what came out: the compare values, the outer job and
//!   [`Status`]) and checks the rules of `docs/safety.md` that can be seen from outside. It keeps
//!   its own model of the radio (capture edges to pulses, per-channel validity, sticks,
//!   gestures), the calibration, the lost-time budget of the failsafe and the arming
//!   procedure; it never reads the supervisor's memory. A violation names the [`Invariant`]
//!   and the tick.
//! - [`SupervisorMonitor`] does the same for the bare [`Supervisor`](fcu_core::supervisor::Supervisor) (`Inputs` → `Decision`).
//! - [`PwmReceiver`] turns a stick timeline into TIM2 capture edges (50 Hz frames, channels one
//!   after the other, 15-bit 0.25 µs counter), [`LevelImu`] makes level LSM6DSL words with
//!   ±2 LSB noise, and [`Rig`] wires them to an [`EdgeDecoder`], a controller and a monitor.
//!
//! Everything is deterministic (seeded SplitMix64) and nothing here panics.

use core::fmt;

use fcu_core::config::{Config, ConfigError};
use fcu_core::flight::{FlightController, Status, TickOutput};
use fcu_core::imu::{CalibrationOutcome, CalibrationPhase, HealthConfig, RawImu};
use fcu_core::math::Quat;
use fcu_core::mixer::MixerConfig;
use fcu_core::rc::{
    CaptureEdge, EdgeDecoder, Gesture, PulseBatch, PulseRules, RcConfig, StickCounts, Sticks, CAPTURE_WRAP, CHANNELS, COUNTS_PER_US,
};
use fcu_core::supervisor::{Decision, FlightState, Inputs, SafetyConfig, SupervisorConfig};

use crate::sim::rng::Rng;

/// Motors must be off once the link has been gone this long in total, each loss counted from
/// the last pulse of the channel that fell silent first (`docs/safety.md#failsafe`).
pub const LINK_LOSS_OFF_S: f64 = 1.0;
/// Slack on [`LINK_LOSS_OFF_S`] for tick rounding.
pub const LINK_LOSS_MARGIN_S: f64 = 0.010;
/// Slack on the 25° arming tilt limit (the monitor computes the tilt in f64).
pub const TILT_MARGIN_RAD: f64 = 1e-3;

/// A rule the monitor checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Invariant {
    /// (1, 4) Armed (or flying) without a full arming procedure just before: the arm gesture
    /// for `arm_hold_ticks` on a good link with the throttle low, started from a released
    /// gesture, then released with no blocker holding.
    ArmedWithoutProcedure,
    /// (2) A compare value other than the off value in a state where the motors must not run,
    /// or while the throttle in force is low.
    MotorsNotOff,
    /// (3) A compare value outside `[min_compare, max_compare]`.
    CompareOutOfRange,
    /// (5) The motors may still run after the link was gone for more than 1.0 s in total:
    /// the silences since the arming, each from the last pulse of the channel that fell
    /// silent first and counted once, less what flying under stick control has forgotten
    /// (one tick per `loss_forget_ticks`). A brief recovery forgets nothing.
    MotorsOnAfterLinkLoss,
    /// Armed (motors following the sticks) without a good link.
    ArmedWithoutLink,
    /// Failsafe stage 1 handed control back before `recovery_ticks` of good link.
    EarlyRecovery,
    /// Failsafe stage 1 flies with sticks that are not level, or a throttle above the last
    /// good one.
    FailsafeSticks,
    /// A sensor fault did not stop the motors, or was forgotten.
    FaultNotLatched,
    /// Identical raw words for longer than the stuck limit without a fault.
    StuckSensorMissed,
    /// `status()` disagrees with the accepted pulses (link = every channel had a pulse in the
    /// last 100 ms; sticks = width minus centre).
    RadioView,
    /// A width outside the accepted pulse range reached the controller.
    PulseOutOfRange,
    /// A width reached the controller that no rising edge and next falling edge of its channel
    /// made within the capture wrap plus the shortest valid width: a pulse longer than the
    /// 15-bit capture clock's wrap read as a valid width (or a width from nowhere).
    PulseAliased,
    /// The yaw (heading) target is not 0 while the throttle in force is low.
    YawTargetWithThrottleLow,
    /// A calibration started while the motors could run.
    CalibrationWhileFlying,
    /// (Supervisor alone) `motors_enabled` disagrees with the state, a calibration was
    /// requested outside Disarmed, or `failsafe_throttle` is set outside stage 1.
    DecisionInconsistent,
}

impl Invariant {
    pub fn name(self) -> &'static str {
        match self {
            Invariant::ArmedWithoutProcedure => "armed-without-procedure",
            Invariant::MotorsNotOff => "motors-not-off",
            Invariant::CompareOutOfRange => "compare-out-of-range",
            Invariant::MotorsOnAfterLinkLoss => "motors-on-after-link-loss",
            Invariant::ArmedWithoutLink => "armed-without-link",
            Invariant::EarlyRecovery => "early-failsafe-recovery",
            Invariant::FailsafeSticks => "failsafe-sticks",
            Invariant::FaultNotLatched => "fault-not-latched",
            Invariant::StuckSensorMissed => "stuck-sensor-missed",
            Invariant::RadioView => "radio-view",
            Invariant::PulseOutOfRange => "pulse-out-of-range",
            Invariant::PulseAliased => "pulse-aliased",
            Invariant::YawTargetWithThrottleLow => "yaw-target-with-throttle-low",
            Invariant::CalibrationWhileFlying => "calibration-while-flying",
            Invariant::DecisionInconsistent => "decision-inconsistent",
        }
    }
}

/// A broken rule: which, at which tick (1 = the first tick observed), and what was seen.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Violation {
    pub tick: u64,
    pub invariant: Invariant,
    pub detail: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "tick {}: {}: {}", self.tick, self.invariant.name(), self.detail)
    }
}

impl std::error::Error for Violation {}

/// The gestures as `docs/safety.md` and the reference define them, written out again here so
/// the monitor does not trust `RcConfig::gesture`.
pub fn classify_gesture(rc: &RcConfig, s: &Sticks) -> Option<Gesture> {
    let th = i32::from(rc.gesture_threshold);
    let (ail, ele, thr, rud) = (i32::from(s.ail), i32::from(s.ele), i32::from(s.thr), i32::from(s.rud));
    if thr == 0 && ele < -th && ail > th && rud < -th {
        Some(Gesture::Calibrate)
    } else if thr == 0 && ele < -th && ail < -th && rud > th {
        Some(Gesture::Arm)
    } else if thr < i32::from(rc.min_throttle) && rud < -th && ele.abs() <= 300 && ail.abs() <= 300 {
        Some(Gesture::Disarm)
    } else {
        None
    }
}

/// Tilt from level of an attitude quaternion (body to earth), rad, in f64; a quaternion that
/// is not finite or has no length is "infinitely" tilted.
pub fn tilt_from_level_rad(q: Quat) -> f64 {
    let (w, x, y, z) = (f64::from(q.w), f64::from(q.x), f64::from(q.y), f64::from(q.z));
    let n = w * w + x * x + y * y + z * z;
    if !(n.is_finite() && n > 0.0) {
        return f64::INFINITY;
    }
    // Earth "up" seen in the body frame, z component, of the normalised rotation.
    ((w * w - x * x - y * y + z * z) / n).clamp(-1.0, 1.0).acos()
}

/// Bookkeeping shared by both monitors: the arm-gesture run, the release rule and the
/// failsafe budgets, from what was fed and what state came out.
#[derive(Clone, Debug)]
struct ProcedureTracker {
    /// Consecutive ticks, up to the previous one, of the arm gesture on a good link with the
    /// throttle low.
    arm_run: u32,
    /// Whether the gesture had been released (a good-link tick with no gesture) since the
    /// last arm/disarm/link loss when the current arm run began.
    arm_run_released: bool,
    /// The last completed arm run (and its released flag), kept after the gesture is let go
    /// while the sticks come back to centre: arming happens then, not at the first tick
    /// without the gesture. Dropped on a link loss, a throttle rise, an arm or a disarm.
    pending_run: u32,
    pending_released: bool,
    released: bool,
    /// Consecutive good-link ticks, including the current one.
    good_run: u32,
    /// Lost time since the arming, ticks: every tick of every silence that ended in a loss
    /// while flying, counted once, less what was forgotten.
    lost_ticks: u32,
    /// Ticks flown under stick control (armed) since the arming or the last lost tick.
    flown_ticks: u32,
    /// The last throttle seen on a good link while armed (the failsafe may hold it, never more).
    held_thr: StickCounts,
    prev_state: FlightState,
}

impl ProcedureTracker {
    fn new() -> Self {
        ProcedureTracker {
            arm_run: 0,
            arm_run_released: false,
            pending_run: 0,
            pending_released: false,
            released: false,
            good_run: 0,
            lost_ticks: 0,
            flown_ticks: 0,
            held_thr: StickCounts::ZERO,
            prev_state: FlightState::Calibrating,
        }
    }

    /// Before the checks of a tick: the link run and the failsafe budgets. `silence` is the
    /// age of the stalest channel's last pulse (read only without a good link).
    fn before_checks(&mut self, link: bool, silence: u32, thr: StickCounts, state: FlightState, forget_ticks: u32) {
        let good_before = self.good_run;
        self.good_run = if link { self.good_run.saturating_add(1) } else { 0 };
        if state == FlightState::FailsafeLevel && self.prev_state == FlightState::Armed {
            self.held_thr = self.held_thr.min(thr);
        }
        if self.is_arming(state) {
            self.lost_ticks = 0;
            self.flown_ticks = 0;
        }
        if !link && self.prev_state.motors_may_run() {
            // The silence up to this tick, from the stalest channel's last pulse, except the
            // part before the previous tick without a link (already counted). Forgetting only
            // happens while flying under stick control, so a brief recovery forgets nothing.
            let new = silence.min(good_before.saturating_add(1)).max(1);
            let forgotten = self.flown_ticks / forget_ticks.max(1);
            self.lost_ticks = self.lost_ticks.saturating_sub(forgotten).saturating_add(new);
            self.flown_ticks = 0;
        }
        if state == FlightState::Armed && link {
            self.held_thr = thr;
            self.flown_ticks = self.flown_ticks.saturating_add(1);
        }
    }

    /// True when this tick starts flying from a state that could not.
    fn is_arming(&self, state: FlightState) -> bool {
        state.motors_may_run() && !self.prev_state.motors_may_run()
    }

    /// What is wrong with the arming procedure behind a tick that starts flying (see
    /// [`is_arming`](Self::is_arming)): the reasons both monitors share. Empty when the arm
    /// gesture was held long enough from a released start, is let go, and boot settling is over.
    fn procedure_faults(
        &self,
        state: FlightState,
        gesture: Option<Gesture>,
        sticks: &Sticks,
        safety: &SafetyConfig,
        tick: u64,
    ) -> Vec<String> {
        let mut why = Vec::new();
        if state != FlightState::Armed {
            why.push(format!("entered {} from {}", state.name(), self.prev_state.name()));
        }
        let (run, released) =
            if self.arm_run > 0 { (self.arm_run, self.arm_run_released) } else { (self.pending_run, self.pending_released) };
        if run < safety.arm_hold_ticks {
            why.push(format!("arm gesture held {run} ticks (need {})", safety.arm_hold_ticks));
        }
        if !released {
            why.push("arm gesture not released since the last arm/disarm/link loss".into());
        }
        if gesture == Some(Gesture::Arm) {
            why.push("arm gesture still held".into());
        }
        if !sticks.attitude_sticks_centred() {
            why.push(format!("armed with the sticks deflected {sticks:?}"));
        }
        if tick < u64::from(safety.boot_settle_ticks) {
            why.push(format!("tick {tick} inside boot settling"));
        }
        why
    }

    /// After the checks: the release rule and the arm run (this tick becomes "before").
    fn after_checks(&mut self, link: bool, gesture: Option<Gesture>, throttle_low: bool, state: FlightState) {
        let arming = self.is_arming(state);
        let disarming = !state.motors_may_run() && self.prev_state.motors_may_run();
        if arming || disarming {
            // A gesture held through an arm or a disarm must be let go before it acts again.
            self.released = false;
            self.arm_run = 0;
            self.pending_run = 0;
        }
        if !link {
            self.released = false;
            self.pending_run = 0;
        }
        if link && gesture == Some(Gesture::Arm) && throttle_low {
            if self.arm_run == 0 {
                self.arm_run_released = self.released;
            }
            self.arm_run = self.arm_run.saturating_add(1);
        } else {
            // A later, shorter run (the gesture taken up again while waiting) does not undo a
            // completed hold: the supervisor keeps counting from it. A run that did not start
            // released could never arm, so any later run replaces it.
            if self.arm_run > 0 && (self.arm_run >= self.pending_run || !self.pending_released) {
                self.pending_run = self.arm_run;
                self.pending_released = self.arm_run_released;
            }
            if !throttle_low {
                self.pending_run = 0;
            }
            self.arm_run = 0;
            if link && gesture.is_none() {
                self.released = true;
            }
        }
        self.prev_state = state;
    }
}

/// What the monitor checks for a configuration.
#[derive(Clone, Debug)]
enum Mode {
    /// The product's safety layer: every invariant.
    Safe(SafetyConfig),
    /// The reference's latch (`Config::reference()`): only the compare range.
    RangeOnly,
}

/// One tick as the monitor sees it.
#[derive(Clone, Copy, Debug)]
pub struct Observation<'a> {
    /// The raw sensor words fed this tick (enables the stuck-sensor check).
    pub imu: Option<RawImu>,
    /// The pulses fed this tick (enables the radio model; give it every tick from boot or never).
    pub batch: Option<&'a PulseBatch>,
    /// The capture edges fed to the decoder before this tick's `take` (enables the check that
    /// every width comes from one pulse shorter than the capture wrap; with `batch`, every
    /// tick from boot or never).
    pub edges: Option<&'a [CaptureEdge]>,
    pub out: &'a TickOutput,
    /// `status()` taken after the tick *and* its outer step (as `FlightController::tick_and_run_outer`).
    pub status: &'a Status,
}

/// Watches a [`FlightController`] from its first tick; see the module documentation.
#[derive(Clone, Debug)]
pub struct SafetyMonitor {
    mode: Mode,
    rc: RcConfig,
    mixer: MixerConfig,
    health: Option<HealthConfig>,
    link_off_ticks: u64,
    /// Capture counts in a control tick.
    counts_per_tick: f64,
    tick: u64,
    // The radio model.
    channel_age: [u32; CHANNELS],
    sticks: Sticks,
    /// Per channel, the last rising edge not yet followed by a falling one: counts and tick.
    rise: [Option<(u16, u64)>; CHANNELS],
    // Procedure and failsafe.
    proc: ProcedureTracker,
    prev_quat: Quat,
    prev_phase: CalibrationPhase,
    calibrated_once: bool,
    // Sensor.
    last_imu: Option<RawImu>,
    same_imu: u32,
    fault_seen: bool,
}

impl SafetyMonitor {
    /// A monitor for a controller built from `cfg`, to be fed from that controller's first tick.
    pub fn new(cfg: &Config) -> Self {
        let dt = cfg.timing.tick_dt_s_f64();
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { 1.0 / 800.0 };
        SafetyMonitor {
            mode: match cfg.supervisor {
                SupervisorConfig::Safe(s) => Mode::Safe(s),
                SupervisorConfig::Reference => Mode::RangeOnly,
            },
            rc: cfg.rc,
            mixer: cfg.mixer,
            health: cfg.health,
            link_off_ticks: ((LINK_LOSS_OFF_S + LINK_LOSS_MARGIN_S) / dt).ceil() as u64,
            counts_per_tick: f64::from(COUNTS_PER_US) * 1e6 * dt,
            tick: 0,
            channel_age: [u32::MAX; CHANNELS],
            sticks: Sticks::default(),
            rise: [None; CHANNELS],
            proc: ProcedureTracker::new(),
            prev_quat: Quat::IDENTITY,
            prev_phase: CalibrationPhase::Settling,
            calibrated_once: false,
            last_imu: None,
            same_imu: 0,
            fault_seen: false,
        }
    }

    /// Ticks observed so far.
    pub fn ticks(&self) -> u64 {
        self.tick
    }

    fn fail(&self, invariant: Invariant, detail: String) -> Result<(), Violation> {
        Err(Violation { tick: self.tick, invariant, detail })
    }

    /// Check one tick.
    pub fn observe(&mut self, o: &Observation<'_>) -> Result<(), Violation> {
        self.tick = self.tick.saturating_add(1);
        let compare = o.out.compare;
        let lo = self.mixer.min_compare.floor();
        let hi = self.mixer.max_compare;
        if let Some(c) = compare.iter().find(|&&c| !(f32::from(c) >= lo && f32::from(c) <= hi)) {
            return self.fail(Invariant::CompareOutOfRange, format!("compare {compare:?}: {c} outside [{lo}, {hi}]"));
        }
        if compare != o.status.compare {
            return self.fail(Invariant::CompareOutOfRange, format!("tick output {compare:?} but status says {:?}", o.status.compare));
        }
        let Mode::Safe(safety) = self.mode.clone() else {
            return Ok(());
        };
        let st = o.status;
        let off = self.mixer.off_compare();
        let motors_off = compare.iter().all(|&c| c == off);

        // The radio, from the accepted pulses alone (and the edges they came from).
        if let Some(batch) = o.batch {
            if let Some(edges) = o.edges {
                self.pulses(edges, batch)?;
            }
            self.radio(batch)?;
        }
        let link = st.link;
        let sticks = st.sticks;
        let throttle_low = sticks.thr < self.rc.min_throttle;
        let gesture = if link { classify_gesture(&self.rc, &sticks) } else { None };

        // Sensor faults: motors off at once, latched.
        self.sensor(o.imu, st, motors_off)?;

        // Calibration.
        let averaging = matches!(st.calibration, CalibrationPhase::Averaging { .. });
        if averaging && !matches!(self.prev_phase, CalibrationPhase::Averaging { .. }) && self.proc.prev_state.motors_may_run() {
            return self.fail(Invariant::CalibrationWhileFlying, format!("calibration started in {}", self.proc.prev_state.name()));
        }
        if st.calibration == (CalibrationPhase::Idle { last: Some(CalibrationOutcome::Passed) }) {
            self.calibrated_once = true;
        }

        // Without the radio model, assume the link was declared lost at the channel timeout.
        let silence = match o.batch {
            Some(_) => self.channel_age.iter().copied().max().unwrap_or(u32::MAX),
            None => self.rc.link_timeout_ticks,
        };
        self.proc.before_checks(link, silence, sticks.thr, st.state, safety.loss_forget_ticks);

        // (1) Arming.
        if self.proc.is_arming(st.state) {
            self.check_arming(&safety, st, link, gesture, throttle_low)?;
        }
        if st.state == FlightState::Armed
            && self.proc.prev_state == FlightState::FailsafeLevel
            && self.proc.good_run < safety.recovery_ticks
        {
            return self.fail(
                Invariant::EarlyRecovery,
                format!("control handed back after {} good ticks (need {})", self.proc.good_run, safety.recovery_ticks),
            );
        }
        if st.state == FlightState::Armed && !link {
            return self.fail(Invariant::ArmedWithoutLink, "armed while the link is not good".into());
        }

        // (2) Motors off where they must be.
        let thr_in_force = match st.state {
            FlightState::FailsafeLevel => Some(self.proc.held_thr),
            FlightState::Armed => Some(sticks.thr),
            _ => None,
        };
        if !motors_off {
            match thr_in_force {
                None => return self.fail(Invariant::MotorsNotOff, format!("compare {compare:?} in {}", st.state.name())),
                Some(t) if t < self.rc.min_throttle => {
                    return self.fail(Invariant::MotorsNotOff, format!("compare {compare:?} in {} with throttle {t} low", st.state.name()))
                }
                Some(_) => {}
            }
        }
        if thr_in_force.is_some_and(|t| t < self.rc.min_throttle) && st.target_rad[2] != 0.0 {
            return self.fail(
                Invariant::YawTargetWithThrottleLow,
                format!("yaw target {} rad in {} with the throttle low", st.target_rad[2], st.state.name()),
            );
        }
        if st.state == FlightState::FailsafeLevel {
            if let Some(job) = &o.out.outer_job {
                let s = job.sticks;
                if s.ail != StickCounts::ZERO || s.ele != StickCounts::ZERO || s.rud != StickCounts::ZERO || s.thr > self.proc.held_thr {
                    return self.fail(Invariant::FailsafeSticks, format!("stage 1 flies {s:?}; last good throttle {}", self.proc.held_thr));
                }
            }
        }

        // (5) Link loss: 1.0 s in total, each loss from the last pulse.
        let gone = u64::from(self.proc.lost_ticks);
        if gone > self.link_off_ticks && (st.state.motors_may_run() || !motors_off) {
            return self.fail(
                Invariant::MotorsOnAfterLinkLoss,
                format!("link gone {gone} ticks in total, state {}, compare {compare:?}", st.state.name()),
            );
        }

        self.proc.after_checks(link, gesture, throttle_low, st.state);
        self.prev_quat = st.quat;
        self.prev_phase = st.calibration;
        Ok(())
    }

    /// Every width the decoder handed over comes from a rising edge and the next falling edge
    /// of its channel, fed at most so many ticks apart that the pulse was shorter than the
    /// capture wrap plus the shortest valid width: then its counts cannot have wrapped into a
    /// valid width. (Independent of the decoder's own window, which is tighter.)
    fn pulses(&mut self, edges: &[CaptureEdge], batch: &PulseBatch) -> Result<(), Violation> {
        let PulseRules::Validated { min_counts, .. } = self.rc.pulses else {
            return Ok(());
        };
        let wrap = u64::from(CAPTURE_WRAP);
        let mut made: [Vec<u32>; CHANNELS] = Default::default();
        for e in edges {
            let (Some(rise), Some(made)) = (self.rise.get_mut(e.channel), made.get_mut(e.channel)) else {
                continue;
            };
            let counts = e.capture_counts & 0x7FFF;
            if e.level_high {
                *rise = Some((counts, self.tick));
            } else if let Some((r, at)) = rise.take() {
                // Longest the pulse can have been: from the start of the rise's tick to the end of this one.
                let longest = (self.tick - at + 1) as f64 * self.counts_per_tick;
                if longest < (wrap + u64::from(min_counts)) as f64 {
                    let w = (u64::from(counts) + wrap - u64::from(r) - 1) % wrap + 1;
                    made.push(w as u32);
                }
            }
        }
        for (ch, (w, made)) in batch.width_counts.iter().zip(&made).enumerate() {
            if let Some(w) = w {
                if !made.contains(&u32::from(*w)) {
                    return self
                        .fail(Invariant::PulseAliased, format!("channel {ch} width {w} counts, but its pulses this tick made {made:?}"));
                }
            }
        }
        Ok(())
    }

    fn radio(&mut self, batch: &PulseBatch) -> Result<(), Violation> {
        let (min, max) = match self.rc.pulses {
            PulseRules::Validated { min_counts, max_counts, .. } => (min_counts, max_counts),
            PulseRules::Reference { .. } => (0, u16::MAX),
        };
        for ch in 0..CHANNELS {
            match batch.width_counts.get(ch).copied().flatten() {
                Some(w) => {
                    if !(min..=max).contains(&w) {
                        return self.fail(Invariant::PulseOutOfRange, format!("channel {ch} width {w} counts outside {min}..={max}"));
                    }
                    if let Some(a) = self.channel_age.get_mut(ch) {
                        *a = 0;
                    }
                    // The core's own mapping (radio map, endpoints, senses): the monitor
                    // checks what the sticks lead to, not how a width becomes one.
                    self.rc.apply_width(&mut self.sticks, ch, w);
                }
                None => {
                    if let Some(a) = self.channel_age.get_mut(ch) {
                        *a = a.saturating_add(1);
                    }
                }
            }
        }
        Ok(())
    }

    fn sensor(&mut self, imu: Option<RawImu>, st: &Status, motors_off: bool) -> Result<(), Violation> {
        if st.fault.is_some() {
            self.fault_seen = true;
        } else if self.fault_seen {
            return self.fail(Invariant::FaultNotLatched, "a sensor fault was forgotten".into());
        }
        if self.fault_seen && (st.state != FlightState::Fault || !motors_off) {
            return self
                .fail(Invariant::FaultNotLatched, format!("fault {:?} but state {} compare {:?}", st.fault, st.state.name(), st.compare));
        }
        match imu {
            Some(raw) if self.last_imu == Some(raw) => self.same_imu = self.same_imu.saturating_add(1),
            _ => self.same_imu = 0,
        }
        self.last_imu = imu;
        if let Some(h) = self.health {
            if self.same_imu >= h.stuck_ticks && st.fault.is_none() {
                return self.fail(Invariant::StuckSensorMissed, format!("{} identical samples without a fault", self.same_imu + 1));
            }
        }
        Ok(())
    }

    fn check_arming(
        &self,
        safety: &SafetyConfig,
        st: &Status,
        link: bool,
        gesture: Option<Gesture>,
        throttle_low: bool,
    ) -> Result<(), Violation> {
        let tilt = tilt_from_level_rad(self.prev_quat);
        let mut why = self.proc.procedure_faults(st.state, gesture, &st.sticks, safety, self.tick);
        if !st.blockers.is_empty() {
            let names: Vec<&str> = st.blockers.iter().map(|b| b.name()).collect();
            why.push(format!("blockers {names:?}"));
        }
        if !link {
            why.push("link not good".into());
        }
        if !throttle_low {
            why.push(format!("throttle {} not low", st.sticks.thr));
        }
        if !self.calibrated_once || matches!(st.calibration, CalibrationPhase::Averaging { .. } | CalibrationPhase::Settling) {
            why.push(format!("calibration {:?}", st.calibration));
        }
        if tilt.is_nan() || tilt > f64::from(safety.max_arm_tilt_rad) + TILT_MARGIN_RAD {
            why.push(format!("tilt {tilt} rad"));
        }
        if self.fault_seen {
            why.push("sensor fault".into());
        }
        if why.is_empty() {
            Ok(())
        } else {
            self.fail(Invariant::ArmedWithoutProcedure, why.join("; "))
        }
    }

    /// Check that `status()` agrees with the monitor's radio model (call after `observe`).
    fn radio_view(&self, st: &Status) -> Result<(), Violation> {
        let link = self.channel_age.iter().all(|&a| a < self.rc.link_timeout_ticks);
        if st.link != link || st.sticks != self.sticks {
            return self.fail(
                Invariant::RadioView,
                format!("status link {} sticks {:?}; pulses give link {link} sticks {:?}", st.link, st.sticks, self.sticks),
            );
        }
        Ok(())
    }

    /// [`observe`](Self::observe) and, when a batch was given, the radio-view check.
    pub fn check(&mut self, o: &Observation<'_>) -> Result<(), Violation> {
        self.observe(o)?;
        if o.batch.is_some() && matches!(self.mode, Mode::Safe(_)) {
            self.radio_view(o.status)?;
        }
        Ok(())
    }
}

/// Watches a bare [`Supervisor`](fcu_core::supervisor::Supervisor) (`Inputs` → `Decision`)
/// from its first step.
#[derive(Clone, Debug)]
pub struct SupervisorMonitor {
    cfg: SafetyConfig,
    tick: u64,
    proc: ProcedureTracker,
    fault_seen: bool,
}

impl SupervisorMonitor {
    pub fn new(cfg: SafetyConfig) -> Self {
        SupervisorMonitor { cfg, tick: 0, proc: ProcedureTracker::new(), fault_seen: false }
    }

    /// Steps observed so far.
    pub fn ticks(&self) -> u64 {
        self.tick
    }

    fn fail(&self, invariant: Invariant, detail: String) -> Result<(), Violation> {
        Err(Violation { tick: self.tick, invariant, detail })
    }

    /// Check one step: the inputs given and the decision returned.
    pub fn observe(&mut self, i: &Inputs, d: &Decision) -> Result<(), Violation> {
        self.tick = self.tick.saturating_add(1);
        let cfg = self.cfg;
        let state = d.state;
        let gesture = if i.link { i.gesture } else { None };
        if d.motors_enabled != state.motors_may_run() {
            return self.fail(Invariant::DecisionInconsistent, format!("motors_enabled {} in {}", d.motors_enabled, state.name()));
        }
        if d.failsafe_throttle.is_some() != (state == FlightState::FailsafeLevel) {
            return self.fail(Invariant::DecisionInconsistent, format!("failsafe throttle {:?} in {}", d.failsafe_throttle, state.name()));
        }
        if d.request_calibration && !(self.proc.prev_state == FlightState::Disarmed && gesture == Some(Gesture::Calibrate)) {
            return self.fail(
                Invariant::CalibrationWhileFlying,
                format!("calibration requested from {} with gesture {gesture:?}", self.proc.prev_state.name()),
            );
        }
        if i.sensor_fault.is_some() {
            self.fault_seen = true;
        }
        if self.fault_seen && (state != FlightState::Fault || d.motors_enabled) {
            return self.fail(Invariant::FaultNotLatched, format!("after a fault: {}", state.name()));
        }

        self.proc.before_checks(i.link, i.silence_ticks, i.sticks.thr, state, cfg.loss_forget_ticks);
        if self.proc.is_arming(state) {
            let mut why = self.proc.procedure_faults(state, gesture, &i.sticks, &cfg, self.tick);
            if !d.blockers.is_empty() {
                why.push(format!("blockers {:#x}", d.blockers.0));
            }
            if !(i.link && i.throttle_low && i.calibrated && !i.calibrating && !self.fault_seen) {
                why.push(format!("inputs {i:?}"));
            }
            if !(i.tilt_rad.is_finite() && i.tilt_rad <= cfg.max_arm_tilt_rad) {
                why.push(format!("tilt {}", i.tilt_rad));
            }
            if !why.is_empty() {
                return self.fail(Invariant::ArmedWithoutProcedure, why.join("; "));
            }
        }
        if state == FlightState::Armed && self.proc.prev_state == FlightState::FailsafeLevel && self.proc.good_run < cfg.recovery_ticks {
            return self.fail(Invariant::EarlyRecovery, format!("handed back after {} good ticks", self.proc.good_run));
        }
        if state == FlightState::Armed && !i.link {
            return self.fail(Invariant::ArmedWithoutLink, "armed without a good link".into());
        }
        if let Some(t) = d.failsafe_throttle {
            if t > self.proc.held_thr {
                return self.fail(Invariant::FailsafeSticks, format!("failsafe throttle {t} above the last good {}", self.proc.held_thr));
            }
        }
        if self.proc.lost_ticks >= cfg.failsafe_off_ticks && state.motors_may_run() {
            return self.fail(
                Invariant::MotorsOnAfterLinkLoss,
                format!("link gone {} ticks (limit {}), state {}", self.proc.lost_ticks, cfg.failsafe_off_ticks, state.name()),
            );
        }
        self.proc.after_checks(i.link, gesture, i.throttle_low, state);
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------
// Generators
// ---------------------------------------------------------------------------------------

/// TIM2 counts per control tick (1.25 ms at 4 MHz).
pub const COUNTS_PER_TICK: u64 = 5_000;
/// TIM2 counts per receiver frame (20 ms, 50 Hz).
pub const COUNTS_PER_FRAME: u64 = 80_000;

/// What the transmitter sends for a while: a pulse width per channel, TIM2 counts
/// (0 = that channel stays low), or nothing at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RadioFrame {
    pub width_counts: [u16; CHANNELS],
    pub link: bool,
}

impl RadioFrame {
    /// No signal.
    pub const OFF: RadioFrame = RadioFrame { width_counts: [0; CHANNELS], link: false };

    /// The widths that decode to `s` (throttle 0 is sent at the bottom of the range).
    pub fn from_sticks(rc: &RcConfig, s: Sticks) -> RadioFrame {
        RadioFrame { width_counts: core::array::from_fn(|input| rc.width_for_sticks(input, &s)), link: true }
    }
}

/// Stick positions of the gestures, reference counts.
pub mod sticks {
    use fcu_core::rc::Sticks;

    pub const NEUTRAL: Sticks = Sticks::new(0, 0, 0, 0);
    pub const ARM: Sticks = Sticks::new(-1500, -1500, 0, 1500);
    pub const DISARM: Sticks = Sticks::new(0, 0, 0, -1500);
    pub const CALIBRATE: Sticks = Sticks::new(1500, -1500, 0, -1500);
    /// Level flight at a mid throttle.
    pub const FLY: Sticks = Sticks::new(0, 0, 1500, 0);
}

/// How a receiver lays the four channels' pulses out in a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelLayout {
    /// One after the other: each channel rises when the previous one falls (most PPM-derived
    /// receivers).
    Sequential,
    /// Channel `k` rises `k × offset_counts` after the frame starts, whatever the widths (0: all
    /// four together, as some receivers do).
    Spaced { offset_counts: u64 },
}

/// The one PWM receiver of the tests, and the TIM2 capture behind it, in integer counts: every
/// 20 ms frame the four channels pulse ([`ChannelLayout`]), and every edge is timestamped on the
/// 15-bit 0.25 µs counter. Optional glitches: spikes of 2–30 µs on a random channel at a random
/// time of the frame; and edges injected by hand ([`PwmReceiver::inject`]). (The simulator's
/// `sim::radio_model` is the physical receiver, with jitter, for flights; this one is exact, for
/// rules checked to the tick.)
#[derive(Clone, Debug)]
pub struct PwmReceiver {
    now: u64,
    next_frame: u64,
    layout: ChannelLayout,
    /// Scheduled edges at their absolute time in counts (their capture value is set when they
    /// are delivered), in time order.
    pending: Vec<(u64, CaptureEdge)>,
    /// Edges for the next tick only, at their offset from its start.
    injected: Vec<(u64, CaptureEdge)>,
    rng: Rng,
}

impl PwmReceiver {
    /// `seed` sets the frame phase against the control ticks and the glitches; sequential
    /// channels.
    pub fn new(seed: u64) -> Self {
        let mut rng = Rng::fork(seed, 0x0050_574D);
        let next_frame = rng.next_u64() % COUNTS_PER_FRAME;
        PwmReceiver { now: 0, next_frame, layout: ChannelLayout::Sequential, pending: Vec::new(), injected: Vec::new(), rng }
    }

    /// A receiver whose first frame starts `first_frame_counts` after the first tick starts.
    pub fn with_layout(first_frame_counts: u64, layout: ChannelLayout, seed: u64) -> Self {
        PwmReceiver { next_frame: first_frame_counts, layout, ..PwmReceiver::new(seed) }
    }

    /// Frames from now on are laid out this way.
    pub fn set_layout(&mut self, layout: ChannelLayout) {
        self.layout = layout;
    }

    /// Absolute time, TIM2 counts since the receiver started.
    pub fn now_counts(&self) -> u64 {
        self.now
    }

    /// An edge delivered with the next tick, timestamped `offset_counts` after its start (an
    /// offset past the tick's end still comes with it, stamped as the counter would show it:
    /// 32 768 counts later reads the same, which is how a glitch as long as the wrap looks).
    pub fn inject(&mut self, channel: usize, offset_counts: u64, level_high: bool) {
        self.injected.push((offset_counts, CaptureEdge { channel, capture_counts: 0, level_high }));
    }

    /// The edges of the next control tick, appended to `out` oldest first. `frame` is what
    /// frames starting during this tick carry; `glitches` spikes are added to each of them.
    pub fn tick(&mut self, frame: &RadioFrame, glitches: u8, out: &mut Vec<CaptureEdge>) {
        let end = self.now + COUNTS_PER_TICK;
        while self.next_frame < end {
            let start = self.next_frame;
            self.next_frame += COUNTS_PER_FRAME;
            if frame.link {
                let mut t = start;
                for (channel, &w) in frame.width_counts.iter().enumerate() {
                    if let ChannelLayout::Spaced { offset_counts } = self.layout {
                        t = start + channel as u64 * offset_counts;
                    }
                    if w > 0 {
                        self.pending.push((t, CaptureEdge::rising(channel, 0)));
                        self.pending.push((t + u64::from(w), CaptureEdge::falling(channel, 0)));
                        t += u64::from(w);
                    }
                }
            }
            for _ in 0..glitches {
                let channel = (self.rng.next_u64() % CHANNELS as u64) as usize;
                let at = start + self.rng.next_u64() % COUNTS_PER_FRAME;
                let len = 8 + self.rng.next_u64() % 113;
                self.pending.push((at, CaptureEdge::rising(channel, 0)));
                self.pending.push((at + len, CaptureEdge::falling(channel, 0)));
            }
            self.pending.sort_by_key(|&(t, _)| t);
        }
        let due = self.pending.iter().take_while(|&&(t, _)| t < end).count();
        let mut now: Vec<(u64, CaptureEdge)> = self.pending.drain(..due).collect();
        now.extend(self.injected.drain(..).map(|(offset, e)| (self.now + offset, e)));
        now.sort_by_key(|&(t, _)| t);
        for (t, e) in now {
            out.push(CaptureEdge { capture_counts: (t % u64::from(CAPTURE_WRAP)) as u16, ..e });
        }
        self.now = end;
    }
}

/// The one level, still LSM6DSL of the tests: raw words in sensor axes, accel z = 8197 LSB
/// (1 g at 0.122 mg/LSB), ±`noise_lsb` on every word, never two identical samples in a row,
/// unless `stuck` (then every sample is the last one: a sensor that stopped converting). (The
/// simulator's `sim::imu_model` is the physical sensor on a flying airframe.)
#[derive(Clone, Debug)]
pub struct LevelImu {
    rng: Rng,
    last: RawImu,
    pub noise_lsb: i16,
    pub stuck: bool,
}

impl LevelImu {
    pub fn new(seed: u64) -> Self {
        LevelImu { rng: Rng::fork(seed, 0x0049_4D55), last: RawImu::default(), noise_lsb: 2, stuck: false }
    }

    pub fn sample(&mut self) -> RawImu {
        if self.stuck && self.last != RawImu::default() {
            return self.last;
        }
        let span = (2 * i64::from(self.noise_lsb.clamp(0, 100)) + 1) as u64;
        let mut n = || (self.rng.next_u64() % span) as i16 - self.noise_lsb.clamp(0, 100);
        let mut s = RawImu { accel: [n(), n(), 8197 + n()], gyro: [n(), n(), n()] };
        if s == self.last {
            s.accel[0] = if s.accel[0] > 0 { s.accel[0] - 1 } else { s.accel[0] + 1 };
        }
        self.last = s;
        s
    }
}

/// A controller wired to an edge decoder, a receiver, a level IMU and a monitor.
#[derive(Clone, Debug)]
pub struct Rig {
    pub fc: FlightController,
    pub monitor: SafetyMonitor,
    pub decoder: EdgeDecoder,
    pub radio: PwmReceiver,
    pub imu: LevelImu,
    edges: Vec<CaptureEdge>,
}

impl Rig {
    pub fn new(cfg: Config, seed: u64) -> Result<Rig, ConfigError> {
        let fc = FlightController::new(cfg)?;
        Ok(Rig {
            monitor: SafetyMonitor::new(&cfg),
            decoder: fc.edge_decoder(),
            fc,
            radio: PwmReceiver::new(seed),
            imu: LevelImu::new(seed),
            edges: Vec::new(),
        })
    }

    pub fn state(&self) -> FlightState {
        self.fc.status().state
    }

    /// One tick from given edges and sensor words ([`crate::harness::tick`]), then the
    /// monitor.
    pub fn tick_with(&mut self, imu: RawImu, edges: &[CaptureEdge]) -> Result<TickOutput, Violation> {
        let ticked = crate::harness::tick(&mut self.fc, &mut self.decoder, imu, edges.iter().copied());
        let status = self.fc.status();
        let (out, batch) = (ticked.out, ticked.pulses);
        self.monitor.check(&Observation { imu: Some(imu), batch: Some(&batch), edges: Some(edges), out: &out, status: &status })?;
        Ok(out)
    }

    /// One tick of the receiver sending `frame` (plus `glitches` spikes per frame), with
    /// the given sensor words.
    pub fn tick_frame_imu(&mut self, frame: &RadioFrame, glitches: u8, imu: RawImu) -> Result<TickOutput, Violation> {
        let mut edges = core::mem::take(&mut self.edges);
        edges.clear();
        self.radio.tick(frame, glitches, &mut edges);
        let r = self.tick_with(imu, &edges);
        self.edges = edges;
        r
    }

    /// One tick of the receiver sending `frame`, with the level IMU.
    pub fn tick_frame(&mut self, frame: &RadioFrame, glitches: u8) -> Result<TickOutput, Violation> {
        let imu = self.imu.sample();
        self.tick_frame_imu(frame, glitches, imu)
    }

    /// `ticks` ticks of `frame` with the level IMU.
    pub fn run(&mut self, frame: &RadioFrame, ticks: u32, glitches: u8) -> Result<(), Violation> {
        for _ in 0..ticks {
            self.tick_frame(frame, glitches)?;
        }
        Ok(())
    }

    /// `ticks` ticks of the sticks `s` on a clean link.
    pub fn sticks(&mut self, s: Sticks, ticks: u32) -> Result<(), Violation> {
        let frame = RadioFrame::from_sticks(&self.fc.config().rc, s);
        self.run(&frame, ticks, 0)
    }

    /// Boot with neutral sticks on a clean link until the start-up calibration has passed
    /// and the boot settling is over (the default profile is then Disarmed, released).
    pub fn booted(cfg: Config, seed: u64) -> Result<Rig, String> {
        let mut rig = Rig::new(cfg, seed).map_err(|e| e.to_string())?;
        let settle = match cfg.supervisor {
            SupervisorConfig::Safe(s) => s.boot_settle_ticks,
            SupervisorConfig::Reference => 0,
        };
        let limit = cfg.calibration.settle_ticks + cfg.calibration.samples + settle + 100;
        for _ in 0..limit {
            rig.sticks(sticks::NEUTRAL, 1).map_err(|v| v.to_string())?;
            let st = rig.fc.status();
            if matches!(st.calibration, CalibrationPhase::Idle { last: Some(CalibrationOutcome::Passed) })
                && rig.monitor.ticks() > u64::from(settle) + 1
                && st.link
            {
                return Ok(rig);
            }
        }
        Err(format!("not booted after {limit} ticks: {:?}", rig.fc.status().state))
    }

    /// Arm with the gesture (hold `arm_hold_ticks` + 16, release to neutral) on a clean link.
    pub fn arm(&mut self) -> Result<(), String> {
        let hold = match self.fc.config().supervisor {
            SupervisorConfig::Safe(s) => s.arm_hold_ticks,
            SupervisorConfig::Reference => 1,
        };
        self.sticks(sticks::ARM, hold + 16).map_err(|v| v.to_string())?;
        for _ in 0..64 {
            self.sticks(sticks::NEUTRAL, 1).map_err(|v| v.to_string())?;
            if self.state() == FlightState::Armed {
                return Ok(());
            }
        }
        Err(format!("not armed: {:?}", self.fc.status().blockers))
    }
}
