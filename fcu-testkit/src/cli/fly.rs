//! `fcu-sim fly` and `fcu-sim compare` (being built: see the simulator issue).

use std::process::ExitCode;

use super::CliError;

#[derive(clap::Args, Debug)]
pub struct FlyArgs {}

#[derive(clap::Args, Debug)]
pub struct CompareArgs {}

pub fn run(_a: &FlyArgs) -> Result<ExitCode, CliError> {
    Err(CliError("`fly` is not available in this build yet".into()))
}

pub fn run_compare(_a: &CompareArgs) -> Result<ExitCode, CliError> {
    Err(CliError("`compare` is not available in this build yet".into()))
}
