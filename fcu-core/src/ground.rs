//! What a ground station may ask of the flight controller besides parameters, and the rules for
//! it: a disarm, a motor test, an IMU calibration, a radio calibration, and that arming waits
//! while a flash save runs.
//!
//! The ground station's side (fcu-gcs's station) checks a request with the same rules
//! ([`disarm_rule`], [`ground_test_rule`], [`MotorTest::checked`]) to answer it, then hands a [`GroundInput`] to the
//! control tick ([`crate::flight::ControlTick::take_ground`], between ticks). The tick decides
//! again with the state it is in when the input arrives: the station's view may be a few
//! milliseconds old.
//!
//! - **Disarm**: through the supervisor's state table (a condition of its own). Arming is
//!   always abandoned; armed, only with the throttle low (the motors are stopped then) or
//!   forced (MAVLink's force value); in the failsafe's level stage only forced, since it flies
//!   on the held throttle whatever the stick says, and a forced disarm there is the stage-2 cut.
//! - **Motor test**: disarmed only. Exactly one motor at the asked duty, capped to
//!   [`MOTOR_TEST_MAX_DUTY_PCT`], for at most [`MOTOR_TEST_MAX_MS`]. It stops at its deadline,
//!   on a stop request, as soon as a radio stick leaves its rest (throttle low, the other
//!   sticks centred) and whenever the supervisor leaves `Disarmed`.
//! - **IMU calibration**: the boot's gyro/accelerometer average again, disarmed only (the
//!   calibration itself restarts while the board moves).
//! - **Radio calibration**: while it runs the ground station reads the radio's widths and
//!   writes the endpoints and trims as parameters; arming is blocked meanwhile. It ends on
//!   request or after [`RADIO_CALIBRATION_MAX_MS`].
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
/// Rule: a test or calibration only while disarmed.
pub const RULE_DISARMED_ONLY: &str = "disarmed only";
/// Rule: not while the supervisor calibrates.
pub const RULE_CALIBRATING: &str = "calibrating";
/// Rule: not with a sensor fault latched, nor after the failsafe cut (the link must return).
pub const RULE_NOT_READY: &str = "fault or failsafe";
/// Rule: the reference's supervisor takes nothing from a ground station.
pub const RULE_REFERENCE: &str = "not with the reference supervisor";
/// Rule: the motor index.
pub const RULE_NO_SUCH_MOTOR: &str = "motor must be 1 to 4";

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
    /// The test as it runs when it may start in `state`: disarmed ([`ground_test_rule`]), one of
    /// the board's [`MOTORS`], the duty capped ([`capped_duty_pct`]) and the time to
    /// [`MOTOR_TEST_MAX_MS`]. The one place these rules are written: the ground station's side
    /// answers with it, and the tick applies it again with the state it is in.
    pub fn checked(self, state: FlightState) -> Result<MotorTest, &'static str> {
        ground_test_rule(state)?;
        if self.motor >= MOTORS {
            return Err(RULE_NO_SUCH_MOTOR);
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
pub struct GroundInput {
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

impl GroundInput {
    /// This input followed by `newer`, for a carrier that got a second one before the tick took
    /// the first: the newer wins where both ask, a forced disarm stays forced, and nothing
    /// asked is lost.
    pub fn then(self, newer: GroundInput) -> GroundInput {
        let disarm = match (self.disarm, newer.disarm) {
            (Some(a), Some(b)) => Some(Disarm { forced: a.forced || b.forced }),
            (a, b) => b.or(a),
        };
        GroundInput {
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
pub struct GroundCommands {
    /// What holds arming back, each an arming blocker of its own.
    pub holds: Holds,
    /// A disarm, taken once.
    pub disarm: Option<Disarm>,
    /// An IMU calibration, taken once.
    pub calibrate: bool,
}

impl GroundCommands {
    pub const NONE: GroundCommands = GroundCommands { holds: Holds::NONE, disarm: None, calibrate: false };
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

/// Whether a disarm asked from the ground may act in `state`, with the radio's throttle low or
/// not (see the module docs). A state with nothing to disarm accepts it: it is done already.
pub fn disarm_rule(state: FlightState, throttle_low: bool, forced: bool) -> Result<(), &'static str> {
    match state {
        FlightState::Armed if !(forced || throttle_low) => Err(RULE_THROTTLE_NOT_LOW),
        FlightState::FailsafeLevel if !forced => Err(RULE_FAILSAFE_LEVEL),
        _ => Ok(()),
    }
}

/// Whether a motor test, an IMU calibration or a radio calibration may start in `state`:
/// disarmed only, and not while calibrating, faulted or after the failsafe cut.
pub fn ground_test_rule(state: FlightState) -> Result<(), &'static str> {
    match state {
        FlightState::Disarmed => Ok(()),
        FlightState::Arming | FlightState::Armed | FlightState::FailsafeLevel => Err(RULE_DISARMED_ONLY),
        FlightState::Calibrating => Err(RULE_CALIBRATING),
        FlightState::FailsafeOff | FlightState::Fault => Err(RULE_NOT_READY),
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
        assert_eq!(disarm_rule(FlightState::Armed, true, false), Ok(()));
        assert_eq!(disarm_rule(FlightState::Armed, false, false), Err(RULE_THROTTLE_NOT_LOW));
        assert_eq!(disarm_rule(FlightState::Armed, false, true), Ok(()));
        assert_eq!(disarm_rule(FlightState::Arming, false, false), Ok(()));
        // The level stage flies the held throttle whatever the stick says.
        assert_eq!(disarm_rule(FlightState::FailsafeLevel, true, false), Err(RULE_FAILSAFE_LEVEL));
        assert_eq!(disarm_rule(FlightState::FailsafeLevel, true, true), Ok(()));
        assert_eq!(disarm_rule(FlightState::Disarmed, false, false), Ok(()));
    }

    #[test]
    fn tests_and_calibrations_start_disarmed_only() {
        for state in FlightState::ALL {
            assert_eq!(ground_test_rule(state).is_ok(), state == FlightState::Disarmed, "{state:?}");
        }
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
        assert_eq!(asked(4, 5.0, 1500).checked(FlightState::Disarmed), Err(RULE_NO_SUCH_MOTOR));
        assert_eq!(asked(0, 5.0, 1500).checked(FlightState::Armed), Err(RULE_DISARMED_ONLY));
        assert_eq!(asked(0, 5.0, 1500).checked(FlightState::Calibrating), Err(RULE_CALIBRATING));
    }

    #[test]
    fn a_second_input_before_the_first_is_taken_loses_nothing() {
        let first = GroundInput {
            disarm: Some(Disarm { forced: true }),
            calibrate_imu: true,
            motor_test: Some(MotorTestChange::Stop),
            radio_calibration: Some(true),
            saving: true,
            rebooting: true,
        };
        let second = GroundInput { disarm: Some(Disarm { forced: false }), ..GroundInput::default() };
        let both = first.then(second);
        assert_eq!(both.disarm, Some(Disarm { forced: true }));
        assert!(both.calibrate_imu);
        assert_eq!(both.motor_test, Some(MotorTestChange::Stop));
        assert_eq!(both.radio_calibration, Some(true));
        assert!(!both.saving && !both.rebooting, "the levels are the newer one's");
        let start = MotorTestChange::Start(MotorTest { motor: 1, duty_pct: 5.0, duration_ms: 1000 });
        let newer = GroundInput { motor_test: Some(start), radio_calibration: Some(false), ..GroundInput::default() };
        assert_eq!(first.then(newer).motor_test, Some(start));
        assert_eq!(first.then(newer).radio_calibration, Some(false));
    }
}
