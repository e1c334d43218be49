//! The flight state in HEARTBEAT, both ways, from one table: what the board sends for each of
//! the supervisor's states, and the state a ground station reads back from a HEARTBEAT.
//!
//! | state | `system_status` | `MAV_MODE_FLAG_SAFETY_ARMED` | `custom_mode` |
//! |---|---|---|---|
//! | Disarmed | STANDBY | no | 1 |
//! | Arming | ACTIVE | yes | 2 |
//! | Armed | ACTIVE | yes | 3 |
//! | FailsafeLevel | CRITICAL | yes | 4 |
//! | FailsafeOff | CRITICAL | no | 5 |
//! | Calibrating | BOOT | no | 6 |
//! | Fault | CRITICAL | no | 7 |
//!
//! `system_status` and the armed bit are what every ground station reads; they cannot tell
//! Arming from Armed, nor a fault from the failsafe's motors-off stage. `custom_mode` names the
//! state exactly, without `MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`: ground stations that read a
//! quadrotor's custom mode as ArduCopter's flight modes (MAVProxy's prompt) would otherwise
//! show a mode this board does not have. A HEARTBEAT whose `custom_mode` names no state (0:
//! another autopilot, or an older image) is read from `system_status` and the armed bit alone.
//! The armed bit is set whenever changes are restricted (arming, armed, the failsafe's level
//! stage): a ground station must not, say, save parameters then.

use fcu_core::supervisor::FlightState;
use mavlink::dialects::common::{MavAutopilot, MavModeFlag, MavState, MavType, HEARTBEAT_DATA};

/// How HEARTBEAT says one flight state (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Said {
    status: MavState,
    armed: bool,
    custom_mode: u32,
}

/// The table of the module docs.
const fn said(state: FlightState) -> Said {
    let (status, armed, custom_mode) = match state {
        FlightState::Disarmed => (MavState::MAV_STATE_STANDBY, false, 1),
        FlightState::Arming => (MavState::MAV_STATE_ACTIVE, true, 2),
        FlightState::Armed => (MavState::MAV_STATE_ACTIVE, true, 3),
        FlightState::FailsafeLevel => (MavState::MAV_STATE_CRITICAL, true, 4),
        FlightState::FailsafeOff => (MavState::MAV_STATE_CRITICAL, false, 5),
        FlightState::Calibrating => (MavState::MAV_STATE_BOOT, false, 6),
        FlightState::Fault => (MavState::MAV_STATE_CRITICAL, false, 7),
    };
    Said { status, armed, custom_mode }
}

/// The states a HEARTBEAT without a custom mode is read as, first match first: where
/// `system_status` and the armed bit fit two states, the one listed first (Armed before
/// Arming, the failsafe's motors-off stage before a fault).
const READ_ORDER: [FlightState; 7] = [
    FlightState::Disarmed,
    FlightState::Armed,
    FlightState::Arming,
    FlightState::FailsafeLevel,
    FlightState::FailsafeOff,
    FlightState::Fault,
    FlightState::Calibrating,
];

/// The board's HEARTBEAT in `state`.
pub fn heartbeat(state: FlightState) -> HEARTBEAT_DATA {
    let said = said(state);
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED;
    if said.armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    HEARTBEAT_DATA {
        custom_mode: said.custom_mode,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_GENERIC,
        base_mode,
        system_status: said.status,
        mavlink_version: 3,
    }
}

/// The flight state a HEARTBEAT says (see the module docs).
pub fn flight_state(heartbeat: &HEARTBEAT_DATA) -> FlightState {
    let armed = heartbeat.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
    if let Some(&state) = READ_ORDER.iter().find(|&&s| said(s).custom_mode == heartbeat.custom_mode) {
        return state;
    }
    let status = heartbeat.system_status;
    if let Some(&state) = READ_ORDER.iter().find(|&&s| said(s).status == status && said(s).armed == armed) {
        return state;
    }
    // What this board never sends: the nearest state.
    match status {
        MavState::MAV_STATE_UNINIT | MavState::MAV_STATE_BOOT | MavState::MAV_STATE_CALIBRATING => FlightState::Calibrating,
        MavState::MAV_STATE_POWEROFF | MavState::MAV_STATE_FLIGHT_TERMINATION => FlightState::Fault,
        MavState::MAV_STATE_CRITICAL | MavState::MAV_STATE_EMERGENCY if armed => FlightState::FailsafeLevel,
        MavState::MAV_STATE_CRITICAL | MavState::MAV_STATE_EMERGENCY => FlightState::FailsafeOff,
        MavState::MAV_STATE_STANDBY | MavState::MAV_STATE_ACTIVE if armed => FlightState::Armed,
        MavState::MAV_STATE_STANDBY | MavState::MAV_STATE_ACTIVE => FlightState::Disarmed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_flight_state_comes_back_from_its_heartbeat() {
        for state in FlightState::ALL {
            assert_eq!(flight_state(&heartbeat(state)), state, "{state:?}");
        }
        assert!(READ_ORDER.iter().all(|s| FlightState::ALL.contains(s)) && FlightState::ALL.iter().all(|s| READ_ORDER.contains(s)));
    }

    #[test]
    fn a_heartbeat_without_a_custom_mode_is_read_from_its_status_and_armed_bit() {
        let without_mode = |state: FlightState| HEARTBEAT_DATA { custom_mode: 0, ..heartbeat(state) };
        for (sent, read) in [
            (FlightState::Disarmed, FlightState::Disarmed),
            (FlightState::Arming, FlightState::Armed),
            (FlightState::Armed, FlightState::Armed),
            (FlightState::FailsafeLevel, FlightState::FailsafeLevel),
            (FlightState::FailsafeOff, FlightState::FailsafeOff),
            (FlightState::Fault, FlightState::FailsafeOff),
            (FlightState::Calibrating, FlightState::Calibrating),
        ] {
            assert_eq!(flight_state(&without_mode(sent)), read, "{sent:?}");
        }
        let other = |system_status, armed: bool| HEARTBEAT_DATA {
            custom_mode: 0,
            base_mode: if armed { MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED } else { MavModeFlag::empty() },
            system_status,
            ..HEARTBEAT_DATA::DEFAULT
        };
        assert_eq!(flight_state(&other(MavState::MAV_STATE_STANDBY, true)), FlightState::Armed);
        assert_eq!(flight_state(&other(MavState::MAV_STATE_ACTIVE, false)), FlightState::Disarmed);
        assert_eq!(flight_state(&other(MavState::MAV_STATE_UNINIT, false)), FlightState::Calibrating);
        assert_eq!(flight_state(&other(MavState::MAV_STATE_EMERGENCY, true)), FlightState::FailsafeLevel);
        assert_eq!(flight_state(&other(MavState::MAV_STATE_POWEROFF, false)), FlightState::Fault);
    }

    #[test]
    fn the_armed_bit_is_set_whenever_changes_are_restricted() {
        for state in FlightState::ALL {
            let armed = heartbeat(state).base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
            assert_eq!(armed, state.changes_restricted(), "{state:?}");
        }
    }
}
