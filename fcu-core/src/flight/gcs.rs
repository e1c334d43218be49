//! The tick's side of a ground station's requests ([`crate::gcs`]): the motor test and the
//! radio calibration that run, the disarm and calibration waiting for the supervisor, and the
//! flash save the station says is running.
//!
//! Everything here runs while disarmed, on the supervisor's path (which steady flight skips), or
//! between ticks when an input arrives: the tick's only cost in flight is the guard's branch for
//! motors that may not run, where the motor test's one compare value is written.

use super::derived::TickParams;
use crate::gcs::{test_or_calibration_rule, Disarm, GcsCommands, GcsInput, Holds, MotorTestChange, RADIO_CALIBRATION_MAX_MS};
use crate::rc::{RcConfig, Sticks};
use crate::supervisor::FlightState;

/// A motor test running: one motor, its compare value, until a tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct TestOutput {
    /// Motor index, below [`crate::gcs::MOTORS`].
    pub(super) motor: u8,
    pub(super) compare: u16,
    /// The first tick the test no longer runs.
    pub(super) until_tick: u32,
}

#[derive(Clone, Debug, Default)]
pub(super) struct Gcs {
    saving: bool,
    rebooting: bool,
    disarm: Option<Disarm>,
    calibrate: bool,
    motor_test: Option<TestOutput>,
    /// A stick ended the motor test and has not come back to rest: arming stays blocked, so a
    /// gesture begun during a test never arms.
    moved_during_test: bool,
    /// The first tick the radio calibration no longer runs.
    radio_calibration_until: Option<u32>,
}

/// Control ticks in `ms` milliseconds (whole ticks, at least one).
fn ticks_in(ms: u32, p: &TickParams) -> u32 {
    ((ms as f32 * 0.001 / p.tick_dt_s) as u32).max(1)
}

impl Gcs {
    /// Takes what the station asked, at tick `now` in `state`. A test or calibration that may
    /// not start in `state` ([`test_or_calibration_rule`], [`crate::gcs::MotorTest::checked`]) is dropped: the station answered with an
    /// older view of the state. A save stops a motor test and refuses a new one: an erase
    /// stalls the tick, and the motor would keep its duty through it.
    pub(super) fn take(&mut self, input: &GcsInput, now: u32, state: FlightState, p: &TickParams) {
        self.saving = input.saving;
        self.rebooting = input.rebooting;
        if input.disarm.is_some() {
            self.disarm = input.disarm;
        }
        let may_start = test_or_calibration_rule(state).is_ok();
        self.calibrate |= input.calibrate_imu && may_start;
        let start = match input.motor_test {
            Some(MotorTestChange::Start(asked)) if !input.saving => asked.checked(state).ok(),
            _ => None,
        };
        match (start, input.motor_test) {
            (Some(t), _) => {
                let range = p.compare_range;
                let span = (range.max_counts - range.min_counts) as f32;
                let compare = range.to_compare(range.min_counts as f32 + span * t.duty_pct * 0.01);
                let until_tick = now.wrapping_add(ticks_in(t.duration_ms, p));
                self.motor_test = Some(TestOutput { motor: t.motor, compare, until_tick });
            }
            (None, Some(_)) => self.motor_test = None,
            (None, None) if input.saving => self.motor_test = None,
            (None, None) => {}
        }
        match input.radio_calibration {
            Some(true) if may_start => self.radio_calibration_until = Some(now.wrapping_add(ticks_in(RADIO_CALIBRATION_MAX_MS, p))),
            Some(_) => self.radio_calibration_until = None,
            None => {}
        }
    }

    /// Whether a disarm waits: the supervisor must decide the next tick.
    pub(super) fn disarm_pending(&self) -> bool {
        self.disarm.is_some()
    }

    /// Before the supervisor decides tick `now`: what ran out ends (the motor test also when a
    /// stick leaves its rest), and what the supervisor reads of the ground station, the one-shot
    /// requests taken.
    pub(super) fn commands(&mut self, now: u32, sticks: &Sticks, rc: &RcConfig) -> GcsCommands {
        let ended = |until: u32| (now.wrapping_sub(until) as i32) >= 0;
        // The sticks are looked at only while a test runs or a stick that ended one is still away.
        let at_rest = || rc.throttle_low(sticks) && sticks.attitude_sticks_centred();
        if let Some(t) = self.motor_test {
            let moved = !at_rest();
            self.moved_during_test = moved;
            if moved || ended(t.until_tick) {
                self.motor_test = None;
            }
        } else if self.moved_during_test {
            self.moved_during_test = !at_rest();
        }
        if self.radio_calibration_until.is_some_and(ended) {
            self.radio_calibration_until = None;
        }
        GcsCommands {
            holds: Holds {
                motor_test: self.motor_test.is_some() || self.moved_during_test,
                radio_calibration: self.radio_calibration_until.is_some(),
                saving: self.saving,
                rebooting: self.rebooting,
            },
            disarm: self.disarm.take(),
            calibrate: core::mem::take(&mut self.calibrate),
        }
    }

    /// After the supervisor decided `state`: a motor test runs only while disarmed.
    pub(super) fn decided(&mut self, state: FlightState) {
        if state != FlightState::Disarmed {
            self.motor_test = None;
        }
    }

    /// The motor test's output, while one runs.
    pub(super) fn test_output(&self) -> Option<TestOutput> {
        self.motor_test
    }

    /// A radio calibration runs.
    pub(super) fn radio_calibration(&self) -> bool {
        self.radio_calibration_until.is_some()
    }
}
