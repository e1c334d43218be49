//! Messages as the board sends them, for the tests of what reads them (`record`, `watch`).

use fcu_core::supervisor::FlightState;
use mavlink::dialects::common::MavMessage;

/// The board's HEARTBEAT in `state` with the throttle manual, as fcu-link sends it.
pub fn heartbeat(state: FlightState) -> MavMessage {
    heartbeat_in(state, fcu_link::VerticalMode::Manual)
}

/// The board's HEARTBEAT in `state` flying `vertical`, as fcu-link sends it.
pub fn heartbeat_in(state: FlightState, vertical: fcu_link::VerticalMode) -> MavMessage {
    MavMessage::HEARTBEAT(fcu_link::heartbeat::heartbeat(state, vertical))
}
