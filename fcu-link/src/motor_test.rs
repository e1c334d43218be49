//! DO_MOTOR_TEST: one motor at a time, to check order and direction with the propellers off.
//!
//! The link decodes the command and passes it on ([`Request::MotorTest`]); the flight
//! controller owns every rule of the test: whether it may start (disarmed, not calibrating),
//! which motors there are, the throttle cap, the longest duration, and the stops (its deadline,
//! a stick leaving its rest, arming, a save). Its answer goes back in the COMMAND_ACK, and
//! whether a test runs comes back in [`VehicleState::motor_test`].
//!
//! - param1 the motor, a whole number from 1; param2 the throttle type, percent (0) only;
//!   param3 the throttle, percent, not negative; param4 the time in s, above 0; param5 the
//!   motor count, 0 or 1 (one motor at a time). Anything else is DENIED here, with a text.
//! - The link stops a running test ([`Request::StopMotorTest`]) only for what it alone knows of
//!   the ground station: another command ACCEPTED (not one answered UNSUPPORTED or refused:
//!   see [`crate::command`]), and no frame for [`MOTOR_TEST_SILENCE_MS`] (a ground station
//!   sends a HEARTBEAT every second). A new DO_MOTOR_TEST replaces the running one.

use crate::command::{denied, refusal, Command, Refusal, Then};
use crate::link::{Core, Room};
use crate::text::{Severity, Text};
use crate::vehicle::{Request, Vehicle, VehicleState};

/// A test stops when no frame came for this long, ms.
pub const MOTOR_TEST_SILENCE_MS: u32 = 1500;

const WHAT: &str = "Motor test";

/// DO_MOTOR_TEST's parameters as the request they make (see the module docs).
fn decode(command: &Command) -> Result<Request, Refusal> {
    let [motor, throttle_type, throttle_pct, timeout_s, count, ..] = command.params;
    if motor < 1.0 || motor != f32::from(motor as u8) {
        return Err(denied(WHAT, "motor must be a whole number from 1"));
    }
    if throttle_type != 0.0 {
        return Err(denied(WHAT, "throttle type must be percent"));
    }
    if !(throttle_pct >= 0.0 && throttle_pct.is_finite()) {
        return Err(denied(WHAT, "bad throttle"));
    }
    if !(timeout_s > 0.0 && timeout_s.is_finite()) {
        return Err(denied(WHAT, "bad timeout"));
    }
    if count != 0.0 && count != 1.0 {
        return Err(denied(WHAT, "one motor at a time"));
    }
    // Saturating: the flight controller caps the duration.
    Ok(Request::MotorTest { motor: motor as u8 - 1, throttle_pct, duration_ms: (timeout_s * 1000.0) as u32 })
}

impl<const TX: usize> Core<TX> {
    pub(crate) fn start_motor_test<V: Vehicle>(&mut self, command: &Command, vehicle: &mut V) -> Result<Then, Refusal> {
        let request = decode(command)?;
        let params = vehicle.request(request).map_err(|refused| refusal(WHAT, refused))?;
        self.motor_test_silence_stop = false;
        Ok(Then::SendParams(params))
    }

    /// Ends a running test for `reason` (nothing when none runs).
    pub(crate) fn stop_motor_test<V: Vehicle>(&mut self, state: &VehicleState, vehicle: &mut V, reason: &str) {
        if !state.motor_test {
            return;
        }
        // The vehicle stops the motor whatever it answers: a refusal here has no rule to keep.
        let _ = vehicle.request(Request::StopMotorTest);
        let text = Text::new().push("Motor test stopped: ").push(reason);
        self.text(Severity::Info, text, Room::Event);
    }

    /// Once per tick: a running test stops when the ground station fell silent (asked once per
    /// silence: the flight controller's report may lag the stop by a period).
    pub(crate) fn check_motor_test<V: Vehicle>(&mut self, state: &VehicleState, vehicle: &mut V) {
        let now = self.now_ms;
        let silent = self.last_rx_ms.is_none_or(|last| now.wrapping_sub(last) > MOTOR_TEST_SILENCE_MS);
        if silent && !self.motor_test_silence_stop && state.motor_test {
            self.motor_test_silence_stop = true;
            self.stop_motor_test(state, vehicle, "link silent");
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
        // Refused by the link (a malformed command) and by the vehicle.
        let neither = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, neither, 400), MavResult::MAV_RESULT_DENIED);
        mock.refuse_requests = Some(crate::Refused::denied("busy"));
        let save = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_PREFLIGHT_STORAGE, save, 500), MavResult::MAV_RESULT_DENIED);
        mock.refuse_requests = None;
        assert!(mock.state.motor_test, "still running");
        assert!(!mock.requests.contains(&Request::StopMotorTest), "{:?}", mock.requests);

        // An accepted command ends it.
        let version = [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(command(&mut link, &mut mock, MavCmd::MAV_CMD_REQUEST_MESSAGE, version, 600), MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!(mock.requests.last(), Some(&Request::StopMotorTest));
    }
}
