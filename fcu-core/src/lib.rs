//! fcu-core: the whole flight controller of the STEVAL-FCU001V1 as pure, deterministic Rust.
//!
//! No hardware, no heap, no globals, no panics. The firmware feeds it raw sensor words and
//! radio capture edges and writes back the motor compare values it returns; the simulator and
//! the golden replay drive the very same [`flight::FlightController`].
//!
//! Frames and signs are the reference's (see [`math`]): body +X right, +Y forward, +Z up;
//! "pitch" is the rotation about X (nose up positive), "roll" about Y (right side down
//! positive), yaw about Z (counter-clockwise seen from above positive).
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

pub mod ahrs;
pub mod boot;
pub mod config;
pub mod control;
pub mod filter;
pub mod flight;
pub mod imu;
pub mod math;
pub mod mixer;
pub mod rc;
pub mod supervisor;
pub mod telemetry;

pub use config::{Config, ConfigError};
pub use flight::FlightController;
