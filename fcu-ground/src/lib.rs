//! fcu-ground: what the ground stations do not do for an fcu board, over its MAVLink 2 link.
//!
//! ```text
//! fcu-ground --link tcp:127.0.0.1:5760 params pull tune.param
//! fcu-ground --link serial:/dev/ttyUSB0 params push tune.param
//! fcu-ground --link serial:/dev/ttyUSB0:115200 params diff tune.param
//! fcu-ground --link tcp:127.0.0.1:5760 record --out out/bench --duration 30
//! fcu-ground --link serial:/dev/ttyUSB0 watch
//! ```
//!
//! - `--link tcp:HOST:PORT` is the emulated board under `cargo pil serve --link tcp:…`;
//!   `--link serial:PATH[:BAUD]` a board on a USB-UART adapter (115200 baud by default).
//! - It is a ground station: system 255, component 190, HEARTBEAT `MAV_TYPE_GCS` at 1 Hz; it
//!   talks to system 1, component 1 (the board), in MAVLink 2.
//! - `--timeout S` (10 s by default) bounds the wait for the board's first HEARTBEAT (and the
//!   TCP connection): a board that does not answer is named as such.
//!
//! Commands ([`cli`]):
//! - `params pull FILE`: every parameter into FILE, in MAVProxy's `param save` format
//!   ([`param_file`], [`params`]);
//! - `params push FILE`: sets the parameters whose values differ from the board's; a refused
//!   one is reported with the rule the board named;
//! - `params diff FILE`: what differs between FILE and the board;
//! - `record --out DIR [--duration S]`: `flight.csv` and `flight.svg` as `fcu-sim fly` writes
//!   them, and `statustext.txt` ([`record`]: which columns a recording carries and which stay
//!   empty);
//! - `watch [--duration S]`: a live view of state, attitude, radio, motors and battery
//!   ([`watch`]).
//!
//! `record` and `watch` end after `--duration` or on Ctrl-C (a recording is written either
//! way).
//!
//! Exit status: 0 done (and, for `diff`, no difference); 1 `diff` found differences or `push`
//! had a set refused; 2 anything else that went wrong (a bad argument, a bad file line, no
//! answer from the board, the link lost), with a message that names it.

pub mod address;
pub mod cli;
pub mod connection;
#[cfg(test)]
mod mock_board;
pub mod param_file;
pub mod params;
pub mod record;
#[cfg(test)]
mod test_messages;
pub mod watch;
