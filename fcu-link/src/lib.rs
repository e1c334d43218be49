//! fcu-link: the MAVLink 2 side of the flight controller's serial link, pure and testable.
//!
//! The firmware runs it on USART1 from a low-priority task, fcu-pil runs the same code inside
//! the emulated board, and the tests drive it on the host. It owns no configuration and no
//! hardware, and of the flight controller it knows only the supervisor's states (which
//! HEARTBEAT says: [`heartbeat`]). The host application (fcu-gcs's station on the board)
//! implements [`Vehicle`] (a view of the flight state, the
//! parameter table and the commands it may take), feeds received bytes to [`Link::receive`],
//! calls [`Link::tick`] for the telemetry schedule and drains [`Link::poll_tx`] into the UART.
//! Nothing blocks and nothing allocates; an answer or event that does not fit is dropped and
//! counted ([`LinkStats`]), telemetry that does not fit stays due, and answers leave room for
//! telemetry ([`TELEMETRY_RESERVE`]).
//!
//! # Protocol
//!
//! - Identity: system [`SYSTEM_ID`], component [`COMPONENT_ID`], `MAV_TYPE_QUADROTOR`,
//!   `MAV_AUTOPILOT_GENERIC`.
//! - Receives MAVLink 1 and 2 ([`FrameReader`]), sends MAVLink 2 only. MAVLink 2 signing is
//!   not supported: a signed frame is counted ([`ReaderStats::signed`]) and dropped, so a
//!   ground station that signs gets no answer at all. pymavlink starts in
//!   MAVLink 1 and switches to 2 (and sends 2 from then on) when a read of its port begins with
//!   the MAVLink 2 start byte; until a read begins with a start byte it keeps looking, so a
//!   connection that opens mid-frame switches at a later read. `MAVLINK20=1` in its environment
//!   starts it in MAVLink 2 outright.
//! - Each message is serialized on its own with the `mavlink` crate's `*_DATA` structs and
//!   their extra CRC ([`frame`]); what is received is checked with the crate's extra CRCs and
//!   read as bytes at its fields' offsets. The dialect's `MavMessage` enum, which would link
//!   every message of the common dialect, is never built.
//! - Sent, handled and refused: see [`Link`], the rules of the commands in [`command`].
//! - Rates and the byte budget at 115200 baud: [`Rates`].
//!
//! # What it costs in flash
//!
//! In the firmware's image built with the link, `scripts/size-by-part` counts about 15 KB for
//! the ground-station link (docs/ground-station.md has the table): this crate, fcu-gcs's
//! station and link task with what they inline of fcu-core's parameter table (the save plan, a
//! set and its checks), the firmware's link task, its receive ring and its flash store. What keeps it there: each message is serialized by its own `*_DATA`
//! struct, over one non-generic copy of everything that does not depend on the message
//! (framing, queueing, padding a payload: [`frame`]); the checksum is computed without a
//! table ([`crc`]); names and texts are bytes, so no UTF-8 check is linked. Parsing and
//! serializing one message through the dialect's `MavMessage` enum instead costs 91,434 +
//! 7,980 B (measured in a probe binary holding nothing else); no `MavMessage` symbol is in the
//! link's image.
// The unit tests run on the host with std (their mock vehicle and decoder allocate).
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]

// The unit tests share the integration tests' mock vehicle and decoder, which name the crate.
#[cfg(test)]
extern crate self as fcu_link;
#[cfg(test)]
#[path = "../tests/support/mod.rs"]
mod test_support;

pub mod command;
pub mod crc;
mod fallbacks;
pub mod frame;
pub mod heartbeat;
mod link;
pub mod motor_test;
mod params;
pub mod rates;
pub mod reader;
mod telemetry;
pub mod text;
pub mod tx;
pub mod vehicle;

pub use link::{Link, LinkConfig, LinkStats, STATION_GONE_MS, TELEMETRY_RESERVE};
pub use rates::Rates;
pub use reader::{Frame, FrameReader, ReaderStats, Version};
pub use text::Severity;
pub use vehicle::{AltMode, Altitude, Attitude, Battery, Health, Param, ParamMask, Refused, Request, Vehicle, VehicleState, VerticalMode};

/// Our MAVLink system id.
pub const SYSTEM_ID: u8 = 1;
/// Our MAVLink component id (`MAV_COMP_ID_AUTOPILOT1`).
pub const COMPONENT_ID: u8 = 1;
