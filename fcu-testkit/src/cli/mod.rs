//! The `fcu-sim` command line: one subcommand per job, each in its own module.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub mod estimate;
pub mod fly;
pub mod margins;
pub mod replay;

#[derive(Parser, Debug)]
#[command(name = "fcu-sim", version, about = "Fly, replay and score the fcu flight core on a laptop")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Fly a scenario against the simulated STEVAL-DRONE01 and draw what happened.
    Fly(fly::FlyArgs),
    /// Fly one scenario and seed under both profiles and print their metrics side by side.
    Compare(fly::CompareArgs),
    /// Run the golden replay format (one row per control tick) and print the output rows.
    Replay(replay::ReplayArgs),
    /// Run the attitude estimator over a BROAD-format IMU recording.
    Estimate(estimate::EstimateArgs),
    /// Measure the attitude loops' frequency response in hover: gain and phase margins, Bode plot.
    Margins(margins::MarginsArgs),
}

/// Parse the arguments, run the subcommand, and turn any error into a message and exit 2
/// (exit 1 is kept for "ran fine, but the scenario's criteria failed").
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fly(a) => fly::run(&a),
        Command::Compare(a) => fly::run_compare(&a),
        Command::Replay(a) => replay::run(&a),
        Command::Estimate(a) => estimate::run(&a),
        Command::Margins(a) => margins::run(&a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("fcu-sim: error: {e}");
            ExitCode::from(2)
        }
    }
}

/// Writes a command's output: to `path` through a temporary file in the same directory,
/// renamed when complete (a failure leaves nothing half-written), or to standard output, where
/// a closed pipe (`| head`) is the reader's choice, not an error.
pub fn write_output(path: Option<&std::path::Path>, bytes: &[u8]) -> Result<(), CliError> {
    use std::io::Write;
    match path {
        Some(p) => {
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
            let tmp = p.with_file_name(format!(".{name}.partial"));
            let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, p));
            written.map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                CliError(format!("cannot write {}: {e}", p.display()))
            })
        }
        None => {
            let mut out = std::io::stdout().lock();
            match out.write_all(bytes).and_then(|()| out.flush()) {
                Ok(()) => Ok(()),
                Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
                Err(e) => Err(CliError(format!("cannot write to standard output: {e}"))),
            }
        }
    }
}

/// A CLI error: a message meant for the person at the terminal.
#[derive(Debug)]
pub struct CliError(pub String);

impl std::fmt::Display for CliError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for CliError {}

impl From<String> for CliError {
    fn from(s: String) -> Self {
        CliError(s)
    }
}

impl From<std::io::Error> for CliError {
    fn from(e: std::io::Error) -> Self {
        CliError(e.to_string())
    }
}
