//! fcu-core: the whole flight controller of the STEVAL-FCU001V1 as pure, deterministic Rust.
//!
//! No hardware, no heap, no globals, no panics. The firmware feeds it raw sensor words and
//! radio capture edges and writes back the motor compare values it returns; the simulator and
//! the golden replay drive the very same [`flight::FlightController`].
//!
//! Frames and signs are the reference's (see [`math`]): body +X right, +Y forward, +Z up;
//! "pitch" is the rotation about X (nose up positive), "roll" about Y (right side down
//! positive), yaw about Z (counter-clockwise seen from above positive).
//!
//! # Where a rule lives
//!
//! | to change… | look at |
//! |---|---|
//! | the order of a tick, what runs when | [`flight::ControlTick`]'s `run` (one call per stage; the stages are `flight`'s submodules) and [`flight::OuterStep::run`] |
//! | what a configuration comes to for the tick, the gains that scale it in flight | [`flight::TickParams`] (worked out in one place, `flight/derived.rs`, a function of the configuration and the gains), [`control::Gains`], [`control::GainSchedule`] |
//! | arming, disarming, failsafe stages, blockers | [`supervisor`]: the conditions and the transition's actions in [`supervisor::Supervisor::decide`], the state table in [`supervisor::transitions`] (every rule has tests named after it, the table its own), the numbers in [`supervisor::SafetyConfig`] |
//! | what a ground station may ask (disarm, motor test, calibrations, a save) and its rules | [`gcs`], the tick's side in `flight/gcs.rs` |
//! | when the last decision may simply stand | [`supervisor::Supervisor::steady`] (the rule) and the tick's command stage (`flight/supervision.rs`, the cache) |
//! | what a valid pulse, a channel and the link are | [`rc::EdgeDecoder`], [`rc::Receiver`], [`rc::RcConfig`] |
//! | which input is which stick, endpoints, reversing | [`rc::RcMap`], [`rc::RcInput`] (`stick_from_width`) |
//! | the parameters: names, bounds, when a change applies, the refusal rules, the flash format | the `fcu-params` crate (the table, its snapshot and file formats, the change check), [`FlightController::take_change`], [`flight::ChangeKind::allowed`] (the rule while changes are restricted) |
//! | sticks to attitude and yaw targets, gestures | [`rc::RcConfig`] (`tilt_targets`, `yaw_step`, `gesture`) |
//! | sensor faults, calibration | [`imu::HealthMonitor`], [`imu::Calibrator`] |
//! | the attitude estimate | [`ahrs`] (the reference's Mahony, the default's VQF-style estimator) |
//! | the barometer, the height, altitude hold, landing detection, the failsafe's descent | [`baro`], [`altitude`], [`althold`] (the outer step's vertical half), the failsafe's rules in [`supervisor`] (`Inputs::descent_cap_ticks`, `Inputs::landed`) |
//! | gains, feedforward, battery compensation | [`control`] and the `control` field of [`Config::default`] |
//! | motor mixing and saturation | [`mixer`] |
//! | stick values and compare counts (both 16-bit counts, never mixed up) | [`rc::StickCounts`], [`mixer::CompareCounts`] |
//! | status lines, LEDs, boot checks | [`telemetry`], [`boot`] |
//! | what the default changes from the reference | [`config`]: each difference is a field with a comment |
//!
//! The reference's quirks are listed in `docs/reference.md#quirks`, the default's differences
//! with the test that shows each in `docs/profiles.md`, the safety rules in `docs/safety.md`.
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

#[cfg(test)]
extern crate std;

pub mod ahrs;
pub mod althold;
pub mod altitude;
pub mod baro;
pub mod boot;
pub mod config;
pub mod control;
pub mod filter;
pub mod flight;
pub mod gcs;
pub mod imu;
pub mod math;
pub mod mixer;
pub mod rc;
pub mod supervisor;
pub mod telemetry;

pub use config::{Config, ConfigError};
pub use flight::FlightController;
