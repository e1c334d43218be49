//! The safety layer, watched from outside: invariant monitors and the deterministic inputs
//! they are fed, for the property tests (`tests/safety_props.rs`) and the fuzzers (`fuzz/`).
//!
//! - [`monitor`]: [`SafetyMonitor`] observes a [`FlightController`](fcu_core::flight::FlightController)
//!   tick by tick (what was fed: the raw IMU words and the pulses; what came out: the compare
//!   values, the outer job and the status) and checks the rules of `docs/safety.md` that can be
//!   seen from outside. It keeps its own model of the radio (capture edges to pulses,
//!   per-channel validity, sticks, gestures), the calibration, the lost-time budget of the
//!   failsafe and the arming procedure; it never reads the supervisor's memory. A violation
//!   names the [`Invariant`] and the tick.
//! - [`supervisor_monitor`]: [`SupervisorMonitor`] does the same for the bare
//!   [`Supervisor`](fcu_core::supervisor::Supervisor) (`Inputs` → `Decision`).
//! - [`inputs`]: [`PwmReceiver`] turns a stick timeline into TIM2 capture edges (50 Hz frames,
//!   channels one after the other, 15-bit 0.25 µs counter), [`LevelImu`] makes level LSM6DSL
//!   words with ±2 LSB noise.
//! - [`rig`]: [`Rig`] wires those inputs to an edge decoder, a controller and a monitor.
//!
//! Everything is deterministic (seeded SplitMix64) and nothing here panics.

pub mod inputs;
mod invariant;
pub mod monitor;
mod procedure;
pub mod rig;
pub mod supervisor_monitor;

pub use inputs::{sticks, ChannelLayout, LevelImu, PwmReceiver, RadioFrame, COUNTS_PER_FRAME, COUNTS_PER_TICK};
pub use invariant::{Invariant, Violation};
pub use monitor::{
    classify_gesture, tilt_from_level_rad, Observation, SafetyMonitor, LINK_LOSS_MARGIN_S, LINK_LOSS_OFF_S, TILT_MARGIN_RAD,
};
pub use rig::Rig;
pub use supervisor_monitor::SupervisorMonitor;
