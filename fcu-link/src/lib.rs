//! fcu-link: the MAVLink 2 side of the flight controller's serial link, pure and testable.
//!
//! The firmware runs it on USART1 from a low-priority task, fcu-pil runs the same code inside
//! the emulated board, and the tests drive it on the host. It owns no configuration and no
//! hardware: the host application implements [`Vehicle`] (a view of the flight state, the
//! parameter table and the commands it may take), feeds received bytes to [`Link::receive`],
//! calls [`Link::tick`] for the telemetry schedule and drains [`Link::poll_tx`] into the UART.
//! Nothing blocks and nothing allocates; what does not fit is dropped and counted
//! ([`LinkStats`]).
//!
//! # Protocol
//!
//! - Identity: system [`SYSTEM_ID`], component [`COMPONENT_ID`], `MAV_TYPE_QUADROTOR`,
//!   `MAV_AUTOPILOT_GENERIC`.
//! - Receives MAVLink 1 and 2 ([`FrameReader`]), sends MAVLink 2 only. pymavlink starts in
//!   MAVLink 1 and switches to 2 when the first byte it reads is a MAVLink 2 start byte; a test
//!   that connects mid-stream sets `MAVLINK20=1` (MAVProxy does by default).
//! - Each message is serialized and parsed on its own with the `mavlink` crate's `*_DATA`
//!   structs and their extra CRC ([`frame`]); the dialect's `MavMessage` enum, which would
//!   link every message of the common dialect, is never built.
//! - Sent, handled and refused: see [`Link`], the rules of the commands in [`command`].
//! - Rates and the byte budget at 115200 baud: [`Rates`].
#![no_std]
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

pub mod command;
mod fallbacks;
pub mod frame;
mod link;
mod motor_test;
mod params;
pub mod rates;
pub mod reader;
mod telemetry;
pub mod text;
pub mod tx;
pub mod vehicle;

pub use link::{Link, LinkConfig, LinkStats};
pub use motor_test::{MotorTestState, MOTOR_TEST_MAX_MS, MOTOR_TEST_THROTTLE_CAP_PCT};
pub use rates::Rates;
pub use reader::{Frame, FrameReader, ReaderStats, Version};
pub use text::Severity;
pub use vehicle::{Attitude, Battery, Health, Param, Request, SystemStatus, Vehicle, VehicleState};

/// Our MAVLink system id.
pub const SYSTEM_ID: u8 = 1;
/// Our MAVLink component id (`MAV_COMP_ID_AUTOPILOT1`).
pub const COMPONENT_ID: u8 = 1;
