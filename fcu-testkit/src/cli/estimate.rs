//! `fcu-sim estimate` (being built: see the estimator issue).

use std::process::ExitCode;

use super::CliError;

#[derive(clap::Args, Debug)]
pub struct EstimateArgs {}

pub fn run(_a: &EstimateArgs) -> Result<ExitCode, CliError> {
    Err(CliError("`estimate` is not available in this build yet".into()))
}
