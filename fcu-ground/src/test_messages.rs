//! Messages as the board sends them, for the tests of what reads them (`record`, `watch`).

use mavlink::dialects::common::{MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA};

/// The board's HEARTBEAT: a generic quadrotor in `status`, armed or not.
pub fn heartbeat(status: MavState, armed: bool) -> MavMessage {
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED;
    if armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_GENERIC,
        base_mode,
        system_status: status,
        mavlink_version: 3,
    })
}
