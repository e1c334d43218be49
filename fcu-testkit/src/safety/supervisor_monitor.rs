//! [`SupervisorMonitor`]: the bare supervisor (`Inputs` → `Decision`) watched step by step.

use fcu_core::rc::Gesture;
use fcu_core::supervisor::{Decision, FlightState, Inputs, SafetyConfig};

use super::procedure::ProcedureTracker;
use super::{Invariant, Violation};

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
