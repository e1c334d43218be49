//! `fcu-sim replay`: the golden replay format through the flight core.

use std::path::PathBuf;
use std::process::ExitCode;

use super::CliError;
use crate::{replay, Profile};

#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    /// Configuration to run. The golden files are the reference's; the default profile's
    /// own safety layer ignores the file's `armed` column.
    #[arg(long, value_enum, default_value = "reference")]
    pub profile: Profile,
    /// Write the output here instead of stdout.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Compare with this golden output file and report the differences (exit 1 if any value
    /// is outside the tolerances).
    #[arg(long)]
    pub expect: Option<PathBuf>,
    /// Replay input file (`tick,acc_x,…,cal_request`), plain or `.gz`.
    pub input: PathBuf,
}

/// Read an input file (plain or gzip) for the replay, as a message-ready error.
fn read_text(path: &std::path::Path) -> Result<String, CliError> {
    crate::csv::read_text(path).map_err(|e| CliError(format!("cannot read {}: {e}", path.display())))
}

pub fn run(a: &ReplayArgs) -> Result<ExitCode, CliError> {
    let text = read_text(&a.input)?;
    let rows = replay::parse_input(&text).map_err(|e| CliError(format!("{}: {e}", a.input.display())))?;
    let out = replay::run(a.profile.config(), &rows).map_err(|e| CliError(e.to_string()))?;
    // The expected file is read first: a broken one stops the run before anything is written.
    let want = match &a.expect {
        Some(p) => Some(replay::parse_output(&read_text(p)?).map_err(|e| CliError(format!("{}: {e}", p.display())))?),
        None => None,
    };
    let csv = replay::format_output(&out);
    super::write_output(a.out.as_deref(), csv.as_bytes())?;
    if let Some(want) = want {
        let c = replay::compare(&out, &want);
        eprintln!(
            "{} rows: {} compare values and {} floats not bit-identical, {} outside tolerance",
            c.rows,
            c.inexact_ccr,
            c.inexact_floats,
            c.out_of_tolerance.len()
        );
        for m in c.out_of_tolerance.iter().take(20) {
            eprintln!("  {m}");
        }
        if !c.out_of_tolerance.is_empty() {
            return Ok(ExitCode::from(1));
        }
    }
    Ok(ExitCode::SUCCESS)
}
