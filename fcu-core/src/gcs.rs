//! What a ground station may ask of the flight controller besides parameters, and the rules for
//! it: an arm (refused), a disarm, a motor test, an IMU calibration, a radio calibration, a save,
//! a reset to defaults and a reboot, and that arming waits while a save or a reboot is pending.
//!
//! Every rule for these requests is written here, once, as a function of the flight state that
//! returns the rule that refuses ([`Refused`]): [`arm_rule`], [`Disarm::checked`],
//! [`test_or_calibration_rule`], [`MotorTest::checked`], [`save_rule`] and [`disarmed_rule`]
//! (a reset to defaults and a reboot). The ground station's side (fcu-gcs's station) answers a
//! request with that verdict, and the link only maps it to MAVLink's result and a text; then
//! the station hands a [`GcsInput`] to the control tick
//! ([`crate::flight::ControlTick::take_gcs`], between ticks), which decides again with the
//! state it is in when the input arrives: the station's view may be a few milliseconds old.
//!
//! - **Arm**: never from a ground station: arming stays the stick gesture's.
//! - **Disarm**: through the supervisor's state table (a condition of its own). Arming is
//!   always abandoned; armed, only with the throttle low (the motors are stopped then) or
//!   forced (MAVLink's force value); in the failsafe's level stage only forced, since it flies
//!   on the held throttle whatever the stick says, and a forced disarm there is the stage-2 cut.
//! - **Motor test**: disarmed only. Exactly one motor at the asked duty, capped to
//!   [`MOTOR_TEST_MAX_DUTY_PCT`], for at most [`MOTOR_TEST_MAX_MS`]. It stops at its deadline,
//!   on a stop request, as soon as a radio stick leaves its rest (throttle low, the other
//!   sticks centred) and whenever the supervisor leaves `Disarmed`.
//! - **Save, reset to defaults, reboot**: disarmed only (changes are restricted while arming,
//!   armed and in the failsafe's level stage); a save also not while a motor test runs (the
//!   motor would keep its duty through the erase).
//! - **IMU calibration**: the boot's gyro/accelerometer average again, disarmed only (the
//!   calibration itself restarts while the board moves).
//! - **Radio calibration**: while it runs the ground station reads the radio's widths and
//!   writes the endpoints and trims as parameters; arming is blocked meanwhile. It ends on
//!   request or after [`RADIO_CALIBRATION_MAX_MS`].
//! - **Set-mode** (manual throttle or altitude hold): a set of the parameter `ALT_MODE`, by
//!   name, with that parameter's checks (it may change in flight); refused with
//!   [`RULE_NO_ALTITUDE_HOLD`] where the table has no such parameter.
//! - **Saving and rebooting**: the ground station says when a flash save or a reboot it accepted
//!   is pending and when it is done or dropped; arming is blocked meanwhile, since an erase
//!   stalls every instruction fetch and a reset stops the motors. The station carries either out
//!   only once a status shows the block in force with the board disarmed, checks that again at
//!   the instant it acts, and drops it (saying why) when it cannot within its time.
//!
//! Each shows as an arming blocker of its own ([`crate::supervisor::Blocker`]): `motor-test`,
//! `radio-calibration`, `saving`, `reboot-pending`.

use crate::supervisor::FlightState;

/// The motor test's duty cap, percent of full output: enough to see a brushed motor turn and
/// which way, little enough that a forgotten propeller does not lift the board.
pub const MOTOR_TEST_MAX_DUTY_PCT: f32 = 15.0;
/// The longest motor test, ms.
pub const MOTOR_TEST_MAX_MS: u32 = 3000;
/// The longest radio calibration, ms: time enough to move every stick to both ends, short
/// enough that a ground station that went away does not block arming for long.
pub const RADIO_CALIBRATION_MAX_MS: u32 = 120_000;
/// Motors on the board.
pub const MOTORS: u8 = 4;

/// Rule: armed with the throttle up, a disarm needs the force value.
pub const RULE_THROTTLE_NOT_LOW: &str = "throttle not low (force 21196)";
/// Rule: in the failsafe's level stage, a disarm needs the force value.
pub const RULE_FAILSAFE_LEVEL: &str = "in failsafe (force 21196)";
/// Rule: arming is the stick gesture's, never a ground station's.
pub const RULE_ARM_WITH_STICKS: &str = "arm with the stick gesture";
/// Rule: a test, a calibration, a save, a reset or a reboot only while disarmed.
pub const RULE_DISARMED_ONLY: &str = "disarmed only";
/// Rule: a save is refused while a motor test runs.
pub const RULE_MOTOR_TEST_RUNNING: &str = "motor test running";
/// Rule: not while the supervisor calibrates.
pub const RULE_CALIBRATING: &str = "calibrating";
/// Rule: not with a sensor fault latched, nor after the failsafe cut (the link must return).
pub const RULE_NOT_READY: &str = "fault or failsafe";
/// Rule: the reference's supervisor takes nothing from a ground station.
pub const RULE_REFERENCE: &str = "not with the reference supervisor";
/// Rule: the motor index.
pub const RULE_NO_SUCH_MOTOR: &str = "motor must be 1 to 4";
/// Rule: a set-mode is the parameter `ALT_MODE`'s set (the same checks apply), refused on a
/// board whose parameter table has no such parameter.
pub const RULE_NO_ALTITUDE_HOLD: &str = "no altitude hold on this board";

/// A request refused: the rule, and whether the flight state of the moment refuses it (armed,
/// the throttle up: the same request may pass later, MAVLink's TEMPORARILY_REJECTED) or the
/// request itself does (DENIED).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Refused {
    /// The rule, short: a ground station shows it after what was refused.
    pub rule: &'static str,
    /// The flight state of the moment refuses it.
    pub for_now: bool,
}

impl Refused {
    /// Refused as asked, whatever the state.
    pub const fn denied(rule: &'static str) -> Refused {
        Refused { rule, for_now: false }
    }

    /// Refused in the flight state of the moment.
    pub const fn for_now(rule: &'static str) -> Refused {
        Refused { rule, for_now: true }
    }
}

/// A disarm asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Disarm {
    /// Sent with MAVLink's force value.
    pub forced: bool,
}

/// A motor test as asked ([`MotorTest::checked`] says how it runs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorTest {
    /// Motor index, 0-based.
    pub motor: u8,
    /// Duty, percent of full output.
    pub duty_pct: f32,
    /// How long, ms.
    pub duration_ms: u32,
}

impl MotorTest {
    /// The test as it runs when it may start in `state`: disarmed ([`test_or_calibration_rule`]), one of
    /// the board's [`MOTORS`], the duty capped ([`capped_duty_pct`]) and the time to
    /// [`MOTOR_TEST_MAX_MS`]. The one place these rules are written: the ground station's side
    /// answers with it, and the tick applies it again with the state it is in.
    pub fn checked(self, state: FlightState) -> Result<MotorTest, Refused> {
        test_or_calibration_rule(state)?;
        if self.motor >= MOTORS {
            return Err(Refused::denied(RULE_NO_SUCH_MOTOR));
        }
        Ok(MotorTest { motor: self.motor, duty_pct: capped_duty_pct(self.duty_pct), duration_ms: self.duration_ms.min(MOTOR_TEST_MAX_MS) })
    }
}

/// A motor test to start, or the running one to stop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MotorTestChange {
    Start(MotorTest),
    Stop,
}

/// What the ground station asked since the control tick last took its input, and whether a
/// flash save runs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GcsInput {
    pub disarm: Option<Disarm>,
    pub calibrate_imu: bool,
    pub motor_test: Option<MotorTestChange>,
    /// Start (`true`) or end the radio calibration.
    pub radio_calibration: Option<bool>,
    /// A flash save is due or running: arming waits (a level, not a request).
    pub saving: bool,
    /// A reboot is pending: arming waits (a level, not a request).
    pub rebooting: bool,
}

impl GcsInput {
    /// This input followed by `newer`, for a carrier that got a second one before the tick took
    /// the first: the newer wins where both ask, a forced disarm stays forced, and nothing
    /// asked is lost.
    pub fn then(self, newer: GcsInput) -> GcsInput {
        let disarm = match (self.disarm, newer.disarm) {
            (Some(a), Some(b)) => Some(Disarm { forced: a.forced || b.forced }),
            (a, b) => b.or(a),
        };
        GcsInput {
            disarm,
            calibrate_imu: self.calibrate_imu || newer.calibrate_imu,
            motor_test: newer.motor_test.or(self.motor_test),
            radio_calibration: newer.radio_calibration.or(self.radio_calibration),
            saving: newer.saving,
            rebooting: newer.rebooting,
        }
    }
}

/// What the supervisor reads of the ground station on one tick ([`crate::supervisor::Inputs`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GcsCommands {
    /// What holds arming back, each an arming blocker of its own.
    pub holds: Holds,
    /// A disarm, taken once.
    pub disarm: Option<Disarm>,
    /// An IMU calibration, taken once.
    pub calibrate: bool,
}

impl GcsCommands {
    pub const NONE: GcsCommands = GcsCommands { holds: Holds::NONE, disarm: None, calibrate: false };
}

/// The ground station's work that holds arming back while it runs or is pending.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Holds {
    /// A motor test runs, or a stick that ended one has not come back to rest.
    pub motor_test: bool,
    pub radio_calibration: bool,
    /// A flash save is due or runs.
    pub saving: bool,
    pub rebooting: bool,
}

impl Holds {
    pub const NONE: Holds = Holds { motor_test: false, radio_calibration: false, saving: false, rebooting: false };
}

impl Disarm {
    /// Whether this disarm may act in `state`, with the radio's throttle low or not (see the
    /// module docs). A state with nothing to disarm accepts it: it is done already.
    pub fn checked(self, state: FlightState, throttle_low: bool) -> Result<(), Refused> {
        match state {
            FlightState::Armed if !(self.forced || throttle_low) => Err(Refused::for_now(RULE_THROTTLE_NOT_LOW)),
            FlightState::FailsafeLevel if !self.forced => Err(Refused::for_now(RULE_FAILSAFE_LEVEL)),
            _ => Ok(()),
        }
    }
}

/// Whether a ground station may arm the board: never (see the module docs).
pub fn arm_rule() -> Result<(), Refused> {
    Err(Refused::denied(RULE_ARM_WITH_STICKS))
}

/// Whether a change that needs the board disarmed may be made in `state` (a reset to defaults,
/// a reboot; a save through [`save_rule`]): not while changes are restricted
/// ([`FlightState::changes_restricted`]).
pub fn disarmed_rule(state: FlightState) -> Result<(), Refused> {
    if state.changes_restricted() {
        Err(Refused::for_now(RULE_DISARMED_ONLY))
    } else {
        Ok(())
    }
}

/// Whether the parameters may be saved to flash in `state`, with a motor test running or not.
pub fn save_rule(state: FlightState, motor_test_running: bool) -> Result<(), Refused> {
    disarmed_rule(state)?;
    if motor_test_running {
        return Err(Refused::denied(RULE_MOTOR_TEST_RUNNING));
    }
    Ok(())
}

/// Whether a motor test, an IMU calibration or a radio calibration may start in `state`:
/// disarmed only, and not while calibrating, faulted or after the failsafe cut.
pub fn test_or_calibration_rule(state: FlightState) -> Result<(), Refused> {
    disarmed_rule(state)?;
    match state {
        FlightState::Calibrating => Err(Refused::denied(RULE_CALIBRATING)),
        FlightState::FailsafeOff | FlightState::Fault => Err(Refused::denied(RULE_NOT_READY)),
        FlightState::Disarmed | FlightState::Arming | FlightState::Armed | FlightState::FailsafeLevel => Ok(()),
    }
}

/// A motor test's duty, capped to [`MOTOR_TEST_MAX_DUTY_PCT`] (NaN and negatives: 0).
pub fn capped_duty_pct(duty_pct: f32) -> f32 {
    if duty_pct > 0.0 {
        duty_pct.min(MOTOR_TEST_MAX_DUTY_PCT)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_disarm_needs_the_force_value_only_with_the_motors_driven_by_the_throttle() {
        let disarm = |state, throttle_low, forced| Disarm { forced }.checked(state, throttle_low);
        assert_eq!(disarm(FlightState::Armed, true, false), Ok(()));
        assert_eq!(disarm(FlightState::Armed, false, false), Err(Refused::for_now(RULE_THROTTLE_NOT_LOW)));
        assert_eq!(disarm(FlightState::Armed, false, true), Ok(()));
        // Arming is abandoned whatever the stick says.
        assert_eq!(disarm(FlightState::Arming, false, false), Ok(()));
        // The level stage flies the held throttle whatever the stick says.
        assert_eq!(disarm(FlightState::FailsafeLevel, true, false), Err(Refused::for_now(RULE_FAILSAFE_LEVEL)));
        assert_eq!(disarm(FlightState::FailsafeLevel, true, true), Ok(()));
        assert_eq!(disarm(FlightState::Disarmed, false, false), Ok(()));
    }

    #[test]
    fn a_ground_station_never_arms() {
        assert_eq!(arm_rule(), Err(Refused::denied(RULE_ARM_WITH_STICKS)));
    }

    #[test]
    fn tests_and_calibrations_start_disarmed_only_and_armed_is_refused_for_now() {
        for state in FlightState::ALL {
            let verdict = test_or_calibration_rule(state);
            assert_eq!(verdict.is_ok(), state == FlightState::Disarmed, "{state:?}");
            assert_eq!(verdict.is_err_and(|r| r.for_now), state.changes_restricted(), "{state:?}");
        }
        assert_eq!(test_or_calibration_rule(FlightState::Calibrating), Err(Refused::denied(RULE_CALIBRATING)));
        assert_eq!(test_or_calibration_rule(FlightState::Fault), Err(Refused::denied(RULE_NOT_READY)));
    }

    #[test]
    fn saves_resets_and_reboots_wait_for_the_disarm_and_a_save_for_the_motor_test() {
        for state in FlightState::ALL {
            let refused = state.changes_restricted().then_some(Refused::for_now(RULE_DISARMED_ONLY));
            assert_eq!(disarmed_rule(state).err(), refused, "{state:?}");
            assert_eq!(save_rule(state, false).err(), refused, "{state:?}");
        }
        assert_eq!(save_rule(FlightState::Disarmed, true), Err(Refused::denied(RULE_MOTOR_TEST_RUNNING)));
        assert_eq!(save_rule(FlightState::Armed, true), Err(Refused::for_now(RULE_DISARMED_ONLY)));
        // Calibrating or faulted, the parameters may still be saved and the board rebooted.
        assert_eq!(save_rule(FlightState::Fault, false), Ok(()));
        assert_eq!(disarmed_rule(FlightState::Calibrating), Ok(()));
    }

    #[test]
    fn the_duty_is_capped_and_nan_is_nothing() {
        assert_eq!(capped_duty_pct(100.0), MOTOR_TEST_MAX_DUTY_PCT);
        assert_eq!(capped_duty_pct(7.5), 7.5);
        assert_eq!(capped_duty_pct(-3.0), 0.0);
        assert_eq!(capped_duty_pct(f32::NAN), 0.0);
        const { assert!(MOTOR_TEST_MAX_DUTY_PCT <= 15.0 && MOTOR_TEST_MAX_MS <= 3000) };
    }

    #[test]
    fn a_motor_test_runs_disarmed_on_a_motor_the_board_has_capped_in_duty_and_time() {
        let asked = |motor, duty_pct, duration_ms| MotorTest { motor, duty_pct, duration_ms };
        let runs = asked(3, 80.0, 60_000).checked(FlightState::Disarmed);
        assert_eq!(runs, Ok(asked(3, MOTOR_TEST_MAX_DUTY_PCT, MOTOR_TEST_MAX_MS)));
        assert_eq!(asked(0, 5.0, 1500).checked(FlightState::Disarmed), Ok(asked(0, 5.0, 1500)));
        assert_eq!(asked(4, 5.0, 1500).checked(FlightState::Disarmed), Err(Refused::denied(RULE_NO_SUCH_MOTOR)));
        assert_eq!(asked(0, 5.0, 1500).checked(FlightState::Armed), Err(Refused::for_now(RULE_DISARMED_ONLY)));
        assert_eq!(asked(0, 5.0, 1500).checked(FlightState::Calibrating), Err(Refused::denied(RULE_CALIBRATING)));
    }

    #[test]
    fn a_second_input_before_the_first_is_taken_loses_nothing() {
        let first = GcsInput {
            disarm: Some(Disarm { forced: true }),
            calibrate_imu: true,
            motor_test: Some(MotorTestChange::Stop),
            radio_calibration: Some(true),
            saving: true,
            rebooting: true,
        };
        let second = GcsInput { disarm: Some(Disarm { forced: false }), ..GcsInput::default() };
        let both = first.then(second);
        assert_eq!(both.disarm, Some(Disarm { forced: true }));
        assert!(both.calibrate_imu);
        assert_eq!(both.motor_test, Some(MotorTestChange::Stop));
        assert_eq!(both.radio_calibration, Some(true));
        assert!(!both.saving && !both.rebooting, "the levels are the newer one's");
        let start = MotorTestChange::Start(MotorTest { motor: 1, duty_pct: 5.0, duration_ms: 1000 });
        let newer = GcsInput { motor_test: Some(start), radio_calibration: Some(false), ..GcsInput::default() };
        assert_eq!(first.then(newer).motor_test, Some(start));
        assert_eq!(first.then(newer).radio_calibration, Some(false));
    }
}
