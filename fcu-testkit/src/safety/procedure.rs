//! The arming procedure and the failsafe's lost-time budget, tracked from outside: what both
//! monitors need to judge an arming and a link loss, kept from what was fed and what state came
//! out, never from the supervisor's memory.

use fcu_core::rc::{Gesture, StickCounts, Sticks};
use fcu_core::supervisor::{FlightState, SafetyConfig};

/// Bookkeeping shared by both monitors: the arm-gesture run, the release rule and the
/// failsafe budgets, from what was fed and what state came out.
#[derive(Clone, Debug)]
pub(super) struct ProcedureTracker {
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
    pub(super) good_run: u32,
    /// Lost time since the arming, ticks: every tick of every silence that ended in a loss
    /// while flying, counted once, less what was forgotten.
    pub(super) lost_ticks: u32,
    /// Ticks flown under stick control (armed) since the arming or the last lost tick.
    flown_ticks: u32,
    /// The last throttle seen on a good link while armed (the failsafe may hold it, never more).
    pub(super) held_thr: StickCounts,
    pub(super) prev_state: FlightState,
}

impl ProcedureTracker {
    pub(super) fn new() -> Self {
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
    pub(super) fn before_checks(&mut self, link: bool, silence: u32, thr: StickCounts, state: FlightState, forget_ticks: u32) {
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
    pub(super) fn is_arming(&self, state: FlightState) -> bool {
        state.motors_may_run() && !self.prev_state.motors_may_run()
    }

    /// What is wrong with the arming procedure behind a tick that starts flying (see
    /// [`is_arming`](Self::is_arming)): the reasons both monitors share. Empty when the arm
    /// gesture was held long enough from a released start, is let go, and boot settling is over.
    pub(super) fn procedure_faults(
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
    pub(super) fn after_checks(&mut self, link: bool, gesture: Option<Gesture>, throttle_low: bool, state: FlightState) {
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
