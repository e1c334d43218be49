//! DO_MOTOR_TEST: one motor at a time, to check order and direction with the propellers off.
//!
//! - disarmed only (TEMPORARILY_REJECTED armed);
//! - param1 the motor, 1 to 4; param2 the throttle type, percent (0) only; param3 the
//!   throttle, capped to [`MOTOR_TEST_THROTTLE_CAP_PCT`] %; param4 the time in s, capped to
//!   [`MOTOR_TEST_MAX_MS`]; param5 the motor count, 0 or 1 (one motor at a time);
//! - stopped ([`Request::StopMotorTest`]) when its time is up, by any other command that is
//!   accepted (not by one answered UNSUPPORTED or refused: see [`crate::command`]), when no
//!   frame came for [`MOTOR_TEST_SILENCE_MS`] (a ground station sends a HEARTBEAT every
//!   second) and when a radio channel moves more than [`MOTOR_TEST_STICK_MOVE_US`] from where it
//!   was at the start;
//! - a new DO_MOTOR_TEST replaces the running one.
//!
//! The link only reports that a test runs ([`crate::Link::motor_test`]); refusing to arm while
//! it does is the flight controller's rule.

use crate::command::{denied, while_armed, Command, Refusal, Then};
use crate::link::{Core, Room};
use crate::text::{Severity, Text};
use crate::vehicle::{Request, Vehicle, VehicleState};

/// The motor test's throttle cap, percent of full output: the flight controller's
/// ([`fcu_core::ground::MOTOR_TEST_MAX_DUTY_PCT`]), which caps it again.
pub const MOTOR_TEST_THROTTLE_CAP_PCT: f32 = fcu_core::ground::MOTOR_TEST_MAX_DUTY_PCT;
/// The longest motor test, ms ([`fcu_core::ground::MOTOR_TEST_MAX_MS`]).
pub const MOTOR_TEST_MAX_MS: u16 = fcu_core::ground::MOTOR_TEST_MAX_MS as u16;
/// A test stops when no frame came for this long, ms.
pub const MOTOR_TEST_SILENCE_MS: u32 = 1500;
/// A test stops when a radio channel moves more than this from its width at the start, µs.
pub const MOTOR_TEST_STICK_MOVE_US: u16 = 50;
/// Motors on the board.
pub const MOTOR_COUNT: u8 = 4;

/// A motor test the link has started.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MotorTest {
    motor: u8,
    throttle_pct: f32,
    end_ms: u32,
    start_widths_us: [u16; 8],
}

/// A running motor test as the host sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorTestState {
    /// Motor index, 0-based.
    pub motor: u8,
    /// Throttle, percent (capped).
    pub throttle_pct: f32,
    /// Time left, ms.
    pub remaining_ms: u32,
}

impl MotorTest {
    pub(crate) fn state(&self, now_ms: u32) -> MotorTestState {
        let left = self.end_ms.wrapping_sub(now_ms);
        MotorTestState { motor: self.motor, throttle_pct: self.throttle_pct, remaining_ms: if (left as i32) < 0 { 0 } else { left } }
    }
}

const WHAT: &str = "Motor test";

impl<const TX: usize> Core<TX> {
    pub(crate) fn start_motor_test<V: Vehicle>(
        &mut self,
        command: &Command,
        state: &VehicleState,
        vehicle: &mut V,
    ) -> Result<Then, Refusal> {
        let [motor, throttle_type, throttle, timeout_s, count, ..] = command.params;
        if state.armed {
            return Err(while_armed(WHAT));
        }
        if !(1.0..=f32::from(MOTOR_COUNT)).contains(&motor) || motor != (motor as u8) as f32 {
            return Err(denied(WHAT, "motor must be 1 to 4"));
        }
        if throttle_type != 0.0 {
            return Err(denied(WHAT, "throttle type must be percent"));
        }
        if !(throttle >= 0.0 && throttle.is_finite()) {
            return Err(denied(WHAT, "bad throttle"));
        }
        if !(timeout_s > 0.0 && timeout_s.is_finite()) {
            return Err(denied(WHAT, "bad timeout"));
        }
        if count != 0.0 && count != 1.0 {
            return Err(denied(WHAT, "one motor at a time"));
        }
        let motor = motor as u8 - 1;
        let throttle_pct = throttle.min(MOTOR_TEST_THROTTLE_CAP_PCT);
        let duration_ms = (timeout_s * 1000.0).min(f32::from(MOTOR_TEST_MAX_MS)) as u16;
        vehicle.request(Request::MotorTest { motor, throttle_pct, duration_ms }).map_err(|rule| denied(WHAT, rule))?;
        self.motor_test = Some(MotorTest {
            motor,
            throttle_pct,
            end_ms: self.now_ms.wrapping_add(u32::from(duration_ms)),
            start_widths_us: state.rc_widths_us,
        });
        Ok(Then::Nothing)
    }

    /// Ends a running test for `reason` (nothing when none runs).
    pub(crate) fn stop_motor_test<V: Vehicle>(&mut self, vehicle: &mut V, reason: &str) {
        if self.motor_test.take().is_none() {
            return;
        }
        // The vehicle stops the motor whatever it answers: a refusal here has no rule to keep.
        let _ = vehicle.request(Request::StopMotorTest);
        let text = Text::new().push("Motor test stopped: ").push(reason);
        self.text(Severity::Info, text, Room::Event);
    }

    /// The limits of a running test, once per tick.
    pub(crate) fn check_motor_test<V: Vehicle>(&mut self, state: &VehicleState, vehicle: &mut V) {
        let Some(test) = self.motor_test else {
            return;
        };
        let now = self.now_ms;
        let reason = if (now.wrapping_sub(test.end_ms) as i32) >= 0 {
            Some("time up")
        } else if self.last_rx_ms.is_none_or(|last| now.wrapping_sub(last) > MOTOR_TEST_SILENCE_MS) {
            Some("link silent")
        } else if test.start_widths_us.iter().zip(state.rc_widths_us.iter()).any(|(&a, &b)| a.abs_diff(b) > MOTOR_TEST_STICK_MOVE_US) {
            Some("stick moved")
        } else if state.armed {
            Some("armed")
        } else {
            None
        };
        if let Some(reason) = reason {
            self.stop_motor_test(vehicle, reason);
        }
    }
}

#[cfg(test)]
mod tests {
    use mavlink::dialects::common::{MavCmd, MavResult, COMMAND_LONG_DATA};
    use mavlink::MessageData;

    use crate::test_support::*;
    use crate::{Link, LinkConfig, Request};

    /// MAV_CMD_GET_HOME_POSITION, which MAVProxy sends every 2 s.
    const GET_HOME_POSITION: f32 = 410.0;

    fn command(link: &mut TestLink, mock: &mut Mock, cmd: MavCmd, params: [f32; 7], now_ms: u32) -> MavResult {
        link.receive(&v2(&command_long(cmd, params)), now_ms, mock);
        let acks = acks(&drain(link));
        assert_eq!(acks.len(), 1);
        acks[0].1
    }

    #[test]
    fn a_motor_test_survives_unsupported_and_refused_commands() {
        let mut link: TestLink = Link::new(LinkConfig::DEFAULT);
        let mut mock = Mock::new();
        let start = [1.0, 0.0, 10.0, 3.0, 1.0, 0.0, 0.0];
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_DO_MOTOR_TEST, start, 0), MavResult::MAV_RESULT_ACCEPTED);
        mock.requests.clear();
        // Unsupported: a number the dialect lists, one it does not, and an unsupported variant.
        let get_home = command_long(MavCmd::MAV_CMD_NAV_WAYPOINT, [0.0; 7]);
        let mut frame = v2(&get_home);
        let mut payload = frame[10..frame.len() - 2].to_vec();
        payload.resize(33, 0);
        payload[28..30].copy_from_slice(&(GET_HOME_POSITION as u16).to_le_bytes());
        frame = v2_raw(COMMAND_LONG_DATA::ID, COMMAND_LONG_DATA::EXTRA_CRC, &payload);
        link.receive(&frame, 100, &mut mock);
        assert_eq!(acks(&drain(&mut link)), [(410, MavResult::MAV_RESULT_UNSUPPORTED)]);
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_NAV_TAKEOFF, [0.0; 7], 200), MavResult::MAV_RESULT_UNSUPPORTED);
        let shutdown = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(
            command(&mut link, &mut mock, MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, shutdown, 300),
            MavResult::MAV_RESULT_UNSUPPORTED
        );
        // Refused by the link (arming is the stick gesture's) and by the vehicle.
        let arm = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, arm, 400), MavResult::MAV_RESULT_DENIED);
        mock.refuse_requests = Some("busy");
        let save = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_PREFLIGHT_STORAGE, save, 500), MavResult::MAV_RESULT_DENIED);
        mock.refuse_requests = None;
        assert!(link.motor_test().is_some(), "still running");
        assert!(!mock.requests.contains(&Request::StopMotorTest), "{:?}", mock.requests);

        // An accepted command ends it.
        let version = [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_REQUEST_MESSAGE, version, 600), MavResult::MAV_RESULT_ACCEPTED);
        assert!(link.motor_test().is_none());
        assert_eq!(mock.requests.last(), Some(&Request::StopMotorTest));
    }
}
