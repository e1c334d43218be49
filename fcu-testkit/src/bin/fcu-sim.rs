//! `fcu-sim`: fly, replay and score the fcu flight core on a laptop.
use std::process::ExitCode;

fn main() -> ExitCode {
    fcu_testkit::cli::main()
}
