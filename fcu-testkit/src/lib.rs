//! fcu-testkit: the flight core on a laptop.
//!
//! - [`replay`]: the golden replay format of `fcu-testkit/data/golden/README.md` (reference profile
//!   oracle);
//! - [`sim`]: a simulated STEVAL-DRONE01 (plant, IMU, radio) flown in closed loop;
//! - [`harness`]: one control tick of the core as the firmware runs it, for every driver here;
//! - [`bench_board`]: the board's link task, control loop and parameter flash composed, with
//!   power cuts, for the invariants where they meet;
//! - [`broad`]: attitude estimation scored on real BROAD recordings;
//! - [`cli`]: the `fcu-sim` command line.

pub mod bench_board;
pub mod broad;
pub mod cli;
pub mod harness;
pub mod profile;
pub mod replay;
pub mod safety;
pub mod sim;

/// The CSV reader, fcu-log's (the flight log's crate), under the path the readers here use.
pub use fcu_log::csv;
pub use profile::Profile;
