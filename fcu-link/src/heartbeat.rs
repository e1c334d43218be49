//! The flight state and the vertical mode in HEARTBEAT, both ways, from one table: what the
//! board sends for each of the supervisor's states and each vertical mode, and what a ground
//! station reads back from a HEARTBEAT.
//!
//! `custom_mode` is a bit field: bits 0–7 the flight state, bits 8–15 the vertical mode,
//! bits 16–31 zero.
//!
//! | state | `system_status` | `MAV_MODE_FLAG_SAFETY_ARMED` | `custom_mode` bits 0–7 |
//! |---|---|---|---|
//! | Disarmed | STANDBY | no | 1 |
//! | Arming | ACTIVE | yes | 2 |
//! | Armed | ACTIVE | yes | 3 |
//! | FailsafeLevel | CRITICAL | yes | 4 |
//! | FailsafeOff | CRITICAL | no | 5 |
//! | Calibrating | BOOT | no | 6 |
//! | Fault | CRITICAL | no | 7 |
//!
//! | vertical mode | `custom_mode` bits 8–15 |
//! |---|---|
//! | manual throttle | 0 (ArduCopter's STABILIZE) |
//! | altitude hold | 2 (ArduCopter's ALT_HOLD) |
//! | failsafe descent | 9 (ArduCopter's LAND) |
//!
//! The vertical mode's numbers are those a set-mode takes ([`VerticalMode::number`]): what
//! MAVProxy's `mode ALT_HOLD` and pymavlink's `set_mode` send for a quadrotor. An image from
//! before altitude hold sends bits 8–15 zero: manual, which is what it flies.
//!
//! `system_status` and the armed bit are what every ground station reads; they cannot tell
//! Arming from Armed, nor a fault from the failsafe's motors-off stage. `custom_mode` names the
//! state and the vertical mode exactly, without `MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`: ground
//! stations that read a quadrotor's custom mode as ArduCopter's flight modes (MAVProxy's
//! prompt) would otherwise show a mode this board is not in (the whole field, state bits
//! included, is no ArduCopter mode: `Armed` in manual reads as ArduCopter's AUTO, 3). A
//! HEARTBEAT whose `custom_mode` is not of this layout (another autopilot; 0, an older image
//! before the custom mode) is read from `system_status` and the armed bit alone, with no
//! vertical mode. The armed bit is set whenever changes are restricted (arming, armed, the
//! failsafe's level stage): a ground station must not, say, save parameters then.

use fcu_core::supervisor::FlightState;
use mavlink::dialects::common::{MavAutopilot, MavModeFlag, MavState, MavType, HEARTBEAT_DATA};

use crate::vehicle::VerticalMode;

/// Where the vertical mode sits in `custom_mode`.
const VERTICAL_SHIFT: u32 = 8;

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

/// The board's HEARTBEAT in `state`, flying `vertical`.
pub fn heartbeat(state: FlightState, vertical: VerticalMode) -> HEARTBEAT_DATA {
    let said = said(state);
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED;
    if said.armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    HEARTBEAT_DATA {
        custom_mode: said.custom_mode | u32::from(vertical.number()) << VERTICAL_SHIFT,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_GENERIC,
        base_mode,
        system_status: said.status,
        mavlink_version: 3,
    }
}

/// The flight state and the vertical mode a `custom_mode` of this board's layout names.
fn ours(custom_mode: u32) -> Option<(FlightState, VerticalMode)> {
    let vertical = VerticalMode::from_number(custom_mode >> VERTICAL_SHIFT)?;
    let state = READ_ORDER.iter().find(|&&s| said(s).custom_mode == custom_mode & 0xFF)?;
    Some((*state, vertical))
}

/// The vertical mode a HEARTBEAT says; `None` when its custom mode is not of this board's
/// layout (see the module docs).
pub fn vertical_mode(heartbeat: &HEARTBEAT_DATA) -> Option<VerticalMode> {
    ours(heartbeat.custom_mode).map(|(_, vertical)| vertical)
}

/// The flight state a HEARTBEAT says (see the module docs).
pub fn flight_state(heartbeat: &HEARTBEAT_DATA) -> FlightState {
    let armed = heartbeat.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
    if let Some((state, _)) = ours(heartbeat.custom_mode) {
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
    fn every_flight_state_and_vertical_mode_comes_back_from_its_heartbeat() {
        for state in FlightState::ALL {
            for vertical in VerticalMode::ALL {
                let sent = heartbeat(state, vertical);
                assert_eq!(flight_state(&sent), state, "{state:?} {vertical:?}");
                assert_eq!(vertical_mode(&sent), Some(vertical), "{state:?} {vertical:?}");
                // The vertical mode changes nothing else a ground station reads.
                let manual = heartbeat(state, VerticalMode::Manual);
                assert_eq!((sent.system_status, sent.base_mode), (manual.system_status, manual.base_mode));
            }
        }
        assert!(READ_ORDER.iter().all(|s| FlightState::ALL.contains(s)) && FlightState::ALL.iter().all(|s| READ_ORDER.contains(s)));
    }

    #[test]
    fn a_heartbeat_without_a_custom_mode_is_read_from_its_status_and_armed_bit() {
        let without_mode = |state: FlightState| HEARTBEAT_DATA { custom_mode: 0, ..heartbeat(state, VerticalMode::Manual) };
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
    fn the_custom_mode_is_the_state_in_the_low_byte_and_the_vertical_mode_above_it() {
        assert_eq!(heartbeat(FlightState::Disarmed, VerticalMode::Manual).custom_mode, 1);
        assert_eq!(heartbeat(FlightState::Armed, VerticalMode::AltitudeHold).custom_mode, 0x0203);
        assert_eq!(heartbeat(FlightState::FailsafeLevel, VerticalMode::FailsafeDescent).custom_mode, 0x0904);
        // Never flagged as a custom mode: the whole field is no ArduCopter mode.
        for state in FlightState::ALL {
            let base_mode = heartbeat(state, VerticalMode::AltitudeHold).base_mode;
            assert!(!base_mode.contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), "{state:?}");
        }
    }

    #[test]
    fn a_custom_mode_of_another_layout_names_no_vertical_mode_and_the_state_comes_from_the_status() {
        let with_mode = |custom_mode| HEARTBEAT_DATA { custom_mode, ..heartbeat(FlightState::Armed, VerticalMode::Manual) };
        // A vertical mode this board does not have, a state byte it does not have, high bits.
        for custom_mode in [0x0303, 0x0100 | 3, 0x0000_0008, 0x0001_0003, 0] {
            assert_eq!(vertical_mode(&with_mode(custom_mode)), None, "{custom_mode:#x}");
            assert_eq!(flight_state(&with_mode(custom_mode)), FlightState::Armed, "{custom_mode:#x}");
        }
        let arming = HEARTBEAT_DATA { custom_mode: 0x0302, ..heartbeat(FlightState::Arming, VerticalMode::Manual) };
        assert_eq!(flight_state(&arming), FlightState::Armed, "read from the status: Armed before Arming");
    }

    #[test]
    fn the_armed_bit_is_set_whenever_changes_are_restricted() {
        for state in FlightState::ALL {
            let armed = heartbeat(state, VerticalMode::Manual).base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
            assert_eq!(armed, state.changes_restricted(), "{state:?}");
        }
    }
}
