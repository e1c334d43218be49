//! fcu-gcs: the board's side of the ground-station link, fcu-link's protocol bound to
//! fcu-core's control tick.
//!
//! fcu-link speaks MAVLink and knows nothing of the flight controller behind it; fcu-core
//! decides everything about flight and knows nothing of MAVLink. This crate is the adapter the
//! firmware (and the host's models of the board) runs between them:
//!
//! - [`Station`]: fcu-core's parameter table, configuration and status as the link's
//!   [`fcu_link::Vehicle`], with the rules for what a ground station may ask (fcu-core's, in
//!   [`fcu_core::gcs`]) and the deferred save and reboot;
//! - [`Service`]: one period of the link task's work, the link and the station together, and
//!   the pacing that lets an acknowledgement out before the flash stalls or the board resets;
//! - [`Mailbox`]: what the link task hands the control loop (a configuration change, the
//!   commands), taken between ticks, the outer step following the tick.
// The unit tests run on the host with std (fcu-link's mock vehicle and decoder allocate).
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

// The unit tests drive the station through the link with fcu-link's own test decoder.
#[cfg(test)]
#[path = "../../fcu-link/tests/support/mod.rs"]
mod test_support;

pub mod mailbox;
pub mod service;
pub mod station;

pub use mailbox::Mailbox;
pub use service::{Observed, Service, ToControl};
pub use station::{Due, Station};
