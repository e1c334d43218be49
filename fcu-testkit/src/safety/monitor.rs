//! [`SafetyMonitor`]: a [`FlightController`](fcu_core::flight::FlightController) watched tick
//! by tick from outside, with its own model of the radio, the calibration, the failsafe's
//! lost-time budget and the arming procedure.

use fcu_core::config::Config;
use fcu_core::flight::{Status, TickOutput};
use fcu_core::imu::{CalibrationOutcome, CalibrationPhase, HealthConfig, RawImu};
use fcu_core::math::Quat;
use fcu_core::mixer::MixerConfig;
use fcu_core::rc::{CaptureEdge, Gesture, PulseBatch, PulseRules, RcConfig, StickCounts, Sticks, CAPTURE_WRAP, CHANNELS, COUNTS_PER_US};
use fcu_core::supervisor::{FlightState, SafetyConfig, SupervisorConfig};

use super::procedure::ProcedureTracker;
use super::{Invariant, Violation};

/// Motors must be off once the link has been gone this long in total, each loss counted from
/// the last pulse of the channel that fell silent first (`docs/safety.md#failsafe`).
pub const LINK_LOSS_OFF_S: f64 = 1.0;
/// Slack on [`LINK_LOSS_OFF_S`] for tick rounding.
pub const LINK_LOSS_MARGIN_S: f64 = 0.010;
/// Slack on the 25° arming tilt limit (the monitor computes the tilt in f64).
pub const TILT_MARGIN_RAD: f64 = 1e-3;

/// The gestures as `docs/safety.md` and the reference define them, written out again here so
/// the monitor does not trust `RcConfig::gesture`.
pub fn classify_gesture(rc: &RcConfig, s: &Sticks) -> Option<Gesture> {
    let th = i32::from(rc.gesture_threshold);
    let (ail, ele, thr, rud) = (i32::from(s.ail), i32::from(s.ele), i32::from(s.thr), i32::from(s.rud));
    // The reference wants the throttle at its very bottom; the product, low (D18).
    let down = match rc.gesture_throttle {
        fcu_core::rc::GestureThrottle::AtBottom => thr == 0,
        fcu_core::rc::GestureThrottle::Low => thr < i32::from(rc.min_throttle),
    };
    if down && ele < -th && ail > th && rud < -th {
        Some(Gesture::Calibrate)
    } else if down && ele < -th && ail < -th && rud > th {
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

/// Watches a [`FlightController`](fcu_core::flight::FlightController) from its first tick; see
/// the module documentation.
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

/// One tick's status as the checks read it.
struct Seen<'a> {
    st: &'a Status,
    compare: [u16; 4],
    /// Every compare value is the off value.
    motors_off: bool,
    /// The controller's link verdict (the radio model checks it against the pulses).
    link: bool,
    throttle_low: bool,
    /// The gesture the sticks make, on a good link only.
    gesture: Option<Gesture>,
}

impl<'a> Seen<'a> {
    fn of(o: &Observation<'a>, rc: &RcConfig, off_compare: u16) -> Seen<'a> {
        let st = o.status;
        let link = st.link;
        Seen {
            st,
            compare: o.out.compare,
            motors_off: o.out.compare.iter().all(|&c| c == off_compare),
            link,
            throttle_low: st.sticks.thr < rc.min_throttle,
            gesture: if link { classify_gesture(rc, &st.sticks) } else { None },
        }
    }
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

    /// Check one tick: the compare values against their range, then (with the safety layer)
    /// the radio model, the sensor, the calibration, the state change, the motors and the
    /// link's lost time, in that order; the first broken rule is the answer.
    pub fn observe(&mut self, o: &Observation<'_>) -> Result<(), Violation> {
        self.tick = self.tick.saturating_add(1);
        self.compare_in_range(o)?;
        let Mode::Safe(safety) = self.mode.clone() else {
            return Ok(());
        };
        // The radio, from the accepted pulses alone (and the edges they came from).
        if let Some(batch) = o.batch {
            if let Some(edges) = o.edges {
                self.pulses(edges, batch)?;
            }
            self.radio(batch)?;
        }
        let seen = Seen::of(o, &self.rc, self.mixer.off_compare());
        // Sensor faults: motors off at once, latched.
        self.sensor(o.imu, seen.st, seen.motors_off)?;
        self.calibration(seen.st)?;
        // Without the radio model, assume the link was declared lost at the channel timeout.
        let silence = match o.batch {
            Some(_) => self.channel_age.iter().copied().max().unwrap_or(u32::MAX),
            None => self.rc.link_timeout_ticks,
        };
        self.proc.before_checks(seen.link, silence, seen.st.sticks.thr, seen.st.state, safety.loss_forget_ticks);
        self.state_change(&safety, &seen)?;
        self.motors_off_where_due(&seen, o.out)?;
        self.link_loss(&seen)?;
        self.proc.after_checks(seen.link, seen.gesture, seen.throttle_low, seen.st.state);
        self.prev_quat = seen.st.quat;
        self.prev_phase = seen.st.calibration;
        Ok(())
    }

    /// Every compare value within the mixer's range, and the one the status reports.
    fn compare_in_range(&self, o: &Observation<'_>) -> Result<(), Violation> {
        let compare = o.out.compare;
        let lo = self.mixer.min_compare.floor();
        let hi = self.mixer.max_compare;
        if let Some(c) = compare.iter().find(|&&c| !(f32::from(c) >= lo && f32::from(c) <= hi)) {
            return self.fail(Invariant::CompareOutOfRange, format!("compare {compare:?}: {c} outside [{lo}, {hi}]"));
        }
        if compare != o.status.compare {
            return self.fail(Invariant::CompareOutOfRange, format!("tick output {compare:?} but status says {:?}", o.status.compare));
        }
        Ok(())
    }

    /// A calibration starts only where the motors could not run; remembers that one passed.
    fn calibration(&mut self, st: &Status) -> Result<(), Violation> {
        let averaging = matches!(st.calibration, CalibrationPhase::Averaging { .. });
        if averaging && !matches!(self.prev_phase, CalibrationPhase::Averaging { .. }) && self.proc.prev_state.motors_may_run() {
            return self.fail(Invariant::CalibrationWhileFlying, format!("calibration started in {}", self.proc.prev_state.name()));
        }
        if st.calibration == (CalibrationPhase::Idle { last: Some(CalibrationOutcome::Passed) }) {
            self.calibrated_once = true;
        }
        Ok(())
    }

    /// The state this tick entered (`docs/safety.md#arming`, `#failsafe`): an arming needs the whole procedure, control comes
    /// back from failsafe stage 1 only after the recovery time, and armed needs a good link.
    fn state_change(&self, safety: &SafetyConfig, seen: &Seen<'_>) -> Result<(), Violation> {
        let state = seen.st.state;
        if self.proc.is_arming(state) {
            self.check_arming(safety, seen)?;
        }
        if state == FlightState::Armed && self.proc.prev_state == FlightState::FailsafeLevel && self.proc.good_run < safety.recovery_ticks {
            return self.fail(
                Invariant::EarlyRecovery,
                format!("control handed back after {} good ticks (need {})", self.proc.good_run, safety.recovery_ticks),
            );
        }
        if state == FlightState::Armed && !seen.link {
            return self.fail(Invariant::ArmedWithoutLink, "armed while the link is not good".into());
        }
        Ok(())
    }

    /// Motors off where they must be (`docs/safety.md#motors`): in every state but armed and failsafe stage 1, and
    /// while the throttle in force is low (then the heading target is 0 too); stage 1 flies
    /// level sticks and no more than the last good throttle.
    fn motors_off_where_due(&self, seen: &Seen<'_>, out: &TickOutput) -> Result<(), Violation> {
        let (st, compare) = (seen.st, seen.compare);
        let thr_in_force = match st.state {
            FlightState::FailsafeLevel => Some(self.proc.held_thr),
            FlightState::Armed => Some(st.sticks.thr),
            _ => None,
        };
        if !seen.motors_off {
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
            if let Some(job) = &out.outer_job {
                let s = job.sticks;
                if s.ail != StickCounts::ZERO || s.ele != StickCounts::ZERO || s.rud != StickCounts::ZERO || s.thr > self.proc.held_thr {
                    return self.fail(Invariant::FailsafeSticks, format!("stage 1 flies {s:?}; last good throttle {}", self.proc.held_thr));
                }
            }
        }
        Ok(())
    }

    /// Link loss (`docs/safety.md#failsafe`): motors off once the link has been gone 1.0 s in total, each loss from
    /// the last pulse.
    fn link_loss(&self, seen: &Seen<'_>) -> Result<(), Violation> {
        let gone = u64::from(self.proc.lost_ticks);
        if gone > self.link_off_ticks && (seen.st.state.motors_may_run() || !seen.motors_off) {
            return self.fail(
                Invariant::MotorsOnAfterLinkLoss,
                format!("link gone {gone} ticks in total, state {}, compare {:?}", seen.st.state.name(), seen.compare),
            );
        }
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

    /// What is wrong with an arming on this tick: the procedure, the blockers, the link, the
    /// throttle, the calibration, the tilt before it and any sensor fault.
    fn check_arming(&self, safety: &SafetyConfig, seen: &Seen<'_>) -> Result<(), Violation> {
        let (st, link, gesture, throttle_low) = (seen.st, seen.link, seen.gesture, seen.throttle_low);
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

#[cfg(test)]
mod tests {
    use super::*;
    use fcu_core::rc::StickCounts;
    use fcu_core::Config;

    /// The arm gesture with the throttle at `thr` counts.
    fn arm(thr: i16) -> Sticks {
        Sticks::new(-1500, -1500, thr, 1500)
    }

    #[test]
    fn the_monitors_arm_gesture_takes_the_throttle_as_each_profile_does() {
        // A fuzzed stream found it: the product arms with the throttle a few counts above its
        // bottom (D18), and a monitor that wanted 0 restarted its count of the hold there.
        let (r, d) = (Config::reference().rc, Config::default().rc);
        assert_eq!(classify_gesture(&r, &arm(0)), Some(Gesture::Arm));
        assert_eq!(classify_gesture(&r, &arm(3)), None);
        for thr in [0, 3, 199] {
            assert_eq!(classify_gesture(&d, &arm(thr)), Some(Gesture::Arm), "throttle {thr}");
            assert_eq!(classify_gesture(&d, &arm(thr)), d.gesture(&arm(thr)), "the monitor and the core agree at {thr}");
        }
        assert_eq!(d.min_throttle, StickCounts(200));
        assert_eq!(classify_gesture(&d, &arm(200)), None, "at MIN_THR the throttle is not low");
    }
}
