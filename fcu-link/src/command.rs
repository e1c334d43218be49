//! COMMAND_LONG and COMMAND_INT: every command gets a COMMAND_ACK, UNSUPPORTED unless it is
//! one of these. The link decodes a command into a [`Request`] and the vehicle decides it with
//! fcu-core's rules ([`fcu_core::gcs`]: arming is the stick gesture's, a disarm with the
//! throttle up needs MAVLink's force value, calibrations, saves and reboots wait for the
//! disarm...):
//!
//! | command | request |
//! |---|---|
//! | COMPONENT_ARM_DISARM | param1 = 1: [`Request::Arm`]; 0: [`Request::Disarm`], forced with param2 = [`FORCE_DISARM`], MAVLink's force value |
//! | PREFLIGHT_CALIBRATION | gyro (param1 = 1) or accelerometer (param5 ≠ 0): [`Request::CalibrateImu`]; radio (param4 = 1): [`Request::CalibrateRadio`]; one at a time; every parameter 0: [`Request::EndCalibration`] (PX4's cancel); magnetometer, baro and the rest UNSUPPORTED |
//! | PREFLIGHT_STORAGE | param1 = 1 save, 2 reset to defaults |
//! | PREFLIGHT_REBOOT_SHUTDOWN | param1 = 1 reboot; the host reboots when [`crate::Link::reboot_ready`] |
//! | DO_MOTOR_TEST | one motor; the flight controller decides, caps and stops it ([`crate::motor_test`]) |
//! | DO_SET_MODE | param1 with `MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`, param2 a custom mode naming a [`VerticalMode`] a ground station may ask for: 0 manual (ArduCopter's STABILIZE), 2 altitude hold (ALT_HOLD); [`Request::SetMode`]; the PARAM_VALUEs of what it set after the ACK. param3 (a sub-mode) is ignored |
//! | REQUEST_MESSAGE | AUTOPILOT_VERSION (param1 = 148) after the ACK; any other message UNSUPPORTED |
//! | REQUEST_AUTOPILOT_CAPABILITIES | AUTOPILOT_VERSION after the ACK |
//!
//! A running motor test is stopped by any other command that is ACCEPTED (after the vehicle
//! took it, before its ACK); a command answered UNSUPPORTED or refused leaves it running:
//! MAVProxy asks for GET_HOME_POSITION every 2 s, which this board answers UNSUPPORTED, and
//! a test must survive that. A DO_MOTOR_TEST accepted replaces the test. A refusal by the
//! vehicle is TEMPORARILY_REJECTED when the flight state of the moment refuses it
//! ([`crate::Refused::for_now`]: armed, the throttle up), DENIED otherwise, both with a
//! STATUSTEXT naming the rule; a parameter the link cannot decode is DENIED with its text.
//!
//! SET_MODE (message 11) is taken as DO_SET_MODE with its `base_mode` and `custom_mode`, and
//! answered the same way, with a COMMAND_ACK whose command is 11, as ArduPilot answers it
//! (SET_MODE has no target component: any of ours). A set-mode without the custom-mode flag
//! (a base mode alone: manual, stabilize, armed...) and a custom mode naming no mode a ground
//! station may ask for (anything but 0 and 2, the failsafe's descent 9 included) are DENIED
//! with a STATUSTEXT naming the modes there are.

use mavlink::dialects::common::{MavCmd, MavModeFlag, MavResult, COMMAND_ACK_DATA, COMMAND_INT_DATA, COMMAND_LONG_DATA};
use mavlink::MessageData;

use crate::link::{Core, Room};
use crate::reader::Frame;
use crate::text::{Severity, Text};
use crate::vehicle::{AltMode, ParamMask, Refused, Request, Vehicle, VehicleState, VerticalMode};

/// MAVLink's value of COMPONENT_ARM_DISARM's param2 that forces a disarm in flight.
pub const FORCE_DISARM: f32 = 21196.0;

/// Command numbers handled (`MAV_CMD`).
pub const COMPONENT_ARM_DISARM: u16 = MavCmd::MAV_CMD_COMPONENT_ARM_DISARM as u16;
/// `MAV_CMD_PREFLIGHT_CALIBRATION`.
pub const PREFLIGHT_CALIBRATION: u16 = MavCmd::MAV_CMD_PREFLIGHT_CALIBRATION as u16;
/// `MAV_CMD_PREFLIGHT_STORAGE`.
pub const PREFLIGHT_STORAGE: u16 = MavCmd::MAV_CMD_PREFLIGHT_STORAGE as u16;
/// `MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN`.
pub const PREFLIGHT_REBOOT_SHUTDOWN: u16 = MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN as u16;
/// `MAV_CMD_DO_MOTOR_TEST`.
pub const DO_MOTOR_TEST: u16 = MavCmd::MAV_CMD_DO_MOTOR_TEST as u16;
/// `MAV_CMD_DO_SET_MODE`.
pub const DO_SET_MODE: u16 = MavCmd::MAV_CMD_DO_SET_MODE as u16;
/// SET_MODE's message id. The dialect marks the message deprecated (MAVLink prefers
/// DO_SET_MODE), but ground stations still send it.
#[allow(deprecated)]
pub const SET_MODE_ID: u32 = mavlink::dialects::common::SET_MODE_DATA::ID;
/// SET_MODE's payload length.
#[allow(deprecated)]
const SET_MODE_LEN: usize = mavlink::dialects::common::SET_MODE_DATA::ENCODED_LEN;
/// The command number a SET_MODE is answered with: its message id (11, no `MAV_CMD`).
pub const SET_MODE_ACK: u16 = SET_MODE_ID as u16;
/// `MAV_CMD_REQUEST_MESSAGE`.
pub const REQUEST_MESSAGE: u16 = MavCmd::MAV_CMD_REQUEST_MESSAGE as u16;
/// `MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES`.
#[allow(deprecated)]
pub const REQUEST_AUTOPILOT_CAPABILITIES: u16 = MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES as u16;
/// AUTOPILOT_VERSION's message id.
pub const AUTOPILOT_VERSION_ID: u32 = mavlink::dialects::common::AUTOPILOT_VERSION_DATA::ID;

/// Offset of the command number in COMMAND_LONG's and COMMAND_INT's payloads (the targets
/// follow it), and of the targets in COMMAND_ACK's.
const COMMAND_AT: usize = 28;
const ACK_TARGET_AT: usize = 8;

/// A command from either message, with its number as sent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Command {
    /// `MAV_CMD` number (any, listed by the dialect or not).
    pub id: u16,
    /// param1..param7 (COMMAND_INT's x and y converted from their integers).
    pub params: [f32; 7],
    /// Sender.
    pub system_id: u8,
    /// Sender's component.
    pub component_id: u8,
    /// Addressee.
    pub target_system: u8,
    /// Addressee's component.
    pub target_component: u8,
}

impl Command {
    /// The command in a COMMAND_LONG or COMMAND_INT frame.
    ///
    /// Read field by field rather than with the crate's `deser`: that validates the command
    /// number against the dialect's `MavCmd` list, a 1.7 KB match on the Cortex-M4, only for
    /// the link to set the number aside (an unlisted one must be answered UNSUPPORTED). The two
    /// messages share the layout: param1..4 (f32), then param5..7 (f32) or x, y (i32) and z
    /// (f32), the command (u16), target system and component.
    pub fn decode(frame: &Frame<'_>) -> Option<Self> {
        // Zero-padded: MAVLink 2 drops trailing zero bytes.
        let mut p = [0u8; COMMAND_INT_DATA::ENCODED_LEN];
        for (dst, &src) in p.iter_mut().zip(frame.payload) {
            *dst = src;
        }
        let word = |i: usize| -> [u8; 4] {
            let mut w = [0u8; 4];
            if let Some(bytes) = p.get(4 * i..4 * i + 4) {
                w.copy_from_slice(bytes);
            }
            w
        };
        let real = |i: usize| f32::from_le_bytes(word(i));
        let int = |i: usize| i32::from_le_bytes(word(i)) as f32;
        let (p5, p6) = if frame.message_id == COMMAND_INT_DATA::ID {
            (int(4), int(5))
        } else if frame.message_id == COMMAND_LONG_DATA::ID {
            (real(4), real(5))
        } else {
            return None;
        };
        Some(Self {
            id: u16::from_le_bytes([p[COMMAND_AT], p[COMMAND_AT + 1]]),
            params: [real(0), real(1), real(2), real(3), p5, p6, real(6)],
            system_id: frame.system_id,
            component_id: frame.component_id,
            target_system: p[COMMAND_AT + 2],
            target_component: p[COMMAND_AT + 3],
        })
    }

    /// A SET_MODE frame as the DO_SET_MODE it asks for, numbered [`SET_MODE_ACK`]: param1 its
    /// `base_mode`, param2 its `custom_mode`, addressed to any component of its target system.
    /// Read by hand as [`Command::decode`] is (`custom_mode` u32, `target_system`,
    /// `base_mode`; zero-padded): the crate's `deser` would refuse a base mode with bits its
    /// `MavModeFlag` does not list, which must get a COMMAND_ACK too.
    pub fn decode_set_mode(frame: &Frame<'_>) -> Option<Self> {
        if frame.message_id != SET_MODE_ID {
            return None;
        }
        let mut p = [0u8; SET_MODE_LEN];
        for (dst, &src) in p.iter_mut().zip(frame.payload) {
            *dst = src;
        }
        let [c0, c1, c2, c3, target_system, base_mode] = p;
        let mut params = [0.0; 7];
        params[0] = f32::from(base_mode);
        // Exact for every mode number there is; a larger one rounds to another that is no mode
        // either.
        params[1] = u32::from_le_bytes([c0, c1, c2, c3]) as f32;
        Some(Self {
            id: SET_MODE_ACK,
            params,
            system_id: frame.system_id,
            component_id: frame.component_id,
            target_system,
            target_component: 0,
        })
    }
}

/// What follows an accepted command's ACK.
pub(crate) enum Then {
    /// The PARAM_VALUEs of the parameters the command set (none: nothing follows).
    SendParams(ParamMask),
    SendVersion,
}

/// A refusal: the ACK's result and the STATUSTEXT naming the rule (none when empty).
/// The text is kept as its pieces, put together when it is sent: a [`Text`] holds a long
/// text, too much to return by value from every rule.
pub(crate) struct Refusal(pub(crate) MavResult, pub(crate) [&'static str; 3]);

impl Refusal {
    fn text(&self) -> Text {
        let [a, b, c] = self.1;
        Text::new().push(a).push(b).push(c)
    }
}

fn unsupported() -> Refusal {
    Refusal(MavResult::MAV_RESULT_UNSUPPORTED, [""; 3])
}

pub(crate) fn denied(what: &'static str, rule: &'static str) -> Refusal {
    Refusal(MavResult::MAV_RESULT_DENIED, [what, ": ", rule])
}

/// The vehicle's verdict as MAVLink says it: TEMPORARILY_REJECTED when the flight state of the
/// moment refuses, DENIED otherwise, with the rule after `what`.
pub(crate) fn refusal(what: &'static str, refused: Refused) -> Refusal {
    let result = if refused.for_now { MavResult::MAV_RESULT_TEMPORARILY_REJECTED } else { MavResult::MAV_RESULT_DENIED };
    Refusal(result, [what, ": ", refused.rule])
}

/// Passes a request on to the vehicle and answers with its verdict.
fn ask<V: Vehicle>(vehicle: &mut V, request: Request, what: &'static str) -> Result<Then, Refusal> {
    vehicle.request(request).map(Then::SendParams).map_err(|refused| refusal(what, refused))
}

/// The text of a set-mode that names no mode a ground station may ask for.
const MODES_THERE_ARE: &str = "0 (STABILIZE) or 2 (ALT_HOLD) only";

/// The mode a set-mode's `base_mode` and `custom_mode` name, if a ground station may ask for
/// it (see the module docs).
pub fn mode_asked(base_mode: f32, custom_mode: f32) -> Result<AltMode, &'static str> {
    // Both arrive as floats: a whole number in range converts back unchanged (NaN never does).
    let base = base_mode as u8;
    if f32::from(base) != base_mode || base & MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits() == 0 {
        return Err(MODES_THERE_ARE);
    }
    let number = custom_mode as u32;
    if number as f32 != custom_mode {
        return Err(MODES_THERE_ARE);
    }
    VerticalMode::from_number(number).and_then(VerticalMode::alt_mode).ok_or(MODES_THERE_ARE)
}

fn set_mode<V: Vehicle>(command: &Command, vehicle: &mut V) -> Result<Then, Refusal> {
    let [base_mode, custom_mode, ..] = command.params;
    let mode = mode_asked(base_mode, custom_mode).map_err(|rule| denied("Mode refused", rule))?;
    ask(vehicle, Request::SetMode(mode), "Mode refused")
}

impl<const TX: usize> Core<TX> {
    pub(crate) fn command<V: Vehicle>(&mut self, command: &Command, vehicle: &mut V) {
        let state = vehicle.state();
        let outcome = match command.id {
            COMPONENT_ARM_DISARM => arm_disarm(command, vehicle),
            PREFLIGHT_CALIBRATION => calibration(command, vehicle),
            PREFLIGHT_STORAGE => storage(command, vehicle),
            PREFLIGHT_REBOOT_SHUTDOWN => {
                let outcome = reboot(command, vehicle);
                if outcome.is_ok() {
                    self.reboot_pending = true;
                }
                outcome
            }
            DO_MOTOR_TEST => self.start_motor_test(command, vehicle),
            DO_SET_MODE => set_mode(command, vehicle),
            REQUEST_MESSAGE if command.params[0] == AUTOPILOT_VERSION_ID as f32 => Ok(Then::SendVersion),
            REQUEST_AUTOPILOT_CAPABILITIES if command.params[0] == 1.0 => Ok(Then::SendVersion),
            _ => Err(unsupported()),
        };
        self.answer(command, outcome, &state, vehicle);
    }

    /// A SET_MODE ([`Command::decode_set_mode`]): decided and answered as DO_SET_MODE.
    pub(crate) fn set_mode_message<V: Vehicle>(&mut self, command: &Command, vehicle: &mut V) {
        let state = vehicle.state();
        let outcome = set_mode(command, vehicle);
        self.answer(command, outcome, &state, vehicle);
    }

    /// The ACK of a command decided, what follows it, or the text of its refusal.
    fn answer<V: Vehicle>(&mut self, command: &Command, outcome: Result<Then, Refusal>, state: &VehicleState, vehicle: &mut V) {
        match outcome {
            Ok(then) => {
                if command.id != DO_MOTOR_TEST {
                    self.stop_motor_test(state, vehicle, "another command");
                }
                self.ack(command, MavResult::MAV_RESULT_ACCEPTED);
                match then {
                    Then::SendVersion => self.autopilot_version(),
                    Then::SendParams(params) => {
                        self.params_owed = self.params_owed.union(params);
                        self.send_owed_params(vehicle);
                    }
                }
            }
            Err(refusal) => {
                self.ack(command, refusal.0);
                let text = refusal.text();
                if !text.as_bytes().is_empty() {
                    self.text(Severity::Warning, text, Room::Answer);
                }
            }
        }
    }

    fn ack(&mut self, command: &Command, result: MavResult) {
        let ack = COMMAND_ACK_DATA { command: MavCmd::MAV_CMD_NAV_WAYPOINT, result };
        // The number as sent, and the extension fields target_system and target_component
        // (the crate's struct has neither, see `reader::handled`).
        let [lo, hi] = command.id.to_le_bytes();
        let patches = [(0, lo), (1, hi), (ACK_TARGET_AT, command.system_id), (ACK_TARGET_AT + 1, command.component_id)];
        // The whole queue, not an answer's share: a ground station that misses the ACK of a
        // reboot or a save sends the command again, and a flood of parameter requests must not
        // cost it. Commands come far slower than the line drains their ACKs (22 bytes each),
        // so they cannot starve the telemetry, which stays due until it has room.
        self.send_patched(&ack, &patches, Room::Event);
    }
}

fn arm_disarm<V: Vehicle>(command: &Command, vehicle: &mut V) -> Result<Then, Refusal> {
    let [action, force, ..] = command.params;
    if action == 1.0 {
        return ask(vehicle, Request::Arm, "Arm refused");
    }
    if action != 0.0 {
        return Err(denied("Arm/disarm", "param1 must be 0 or 1"));
    }
    ask(vehicle, Request::Disarm { forced: force == FORCE_DISARM }, "Disarm refused")
}

fn calibration<V: Vehicle>(command: &Command, vehicle: &mut V) -> Result<Then, Refusal> {
    let [gyro, mag, baro, radio, accel, p6, p7] = command.params;
    if command.params == [0.0; 7] {
        return ask(vehicle, Request::EndCalibration, "Calibration end refused");
    }
    let imu = gyro == 1.0 || accel != 0.0;
    let radio = radio == 1.0;
    if mag != 0.0 || baro != 0.0 || p6 != 0.0 || p7 != 0.0 || imu == radio {
        return Err(unsupported());
    }
    let request = if imu { Request::CalibrateImu } else { Request::CalibrateRadio };
    ask(vehicle, request, "Calibration refused")
}

fn storage<V: Vehicle>(command: &Command, vehicle: &mut V) -> Result<Then, Refusal> {
    let request = if command.params[0] == 1.0 {
        Request::SaveParams
    } else if command.params[0] == 2.0 {
        Request::ResetParams
    } else {
        return Err(unsupported());
    };
    ask(vehicle, request, "Storage refused")
}

fn reboot<V: Vehicle>(command: &Command, vehicle: &mut V) -> Result<Then, Refusal> {
    if command.params[0] != 1.0 {
        return Err(unsupported());
    }
    ask(vehicle, Request::Reboot, "Reboot refused")
}
