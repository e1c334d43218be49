//! Messages as the board sends them, for the tests of what reads them (`record`, `watch`).

use fcu_core::supervisor::FlightState;
use mavlink::dialects::common::MavMessage;

/// The board's HEARTBEAT in `state`, as fcu-link sends it.
pub fn heartbeat(state: FlightState) -> MavMessage {
    MavMessage::HEARTBEAT(fcu_link::heartbeat::heartbeat(state))
}
