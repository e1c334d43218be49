//! `fcu-ground`: see the crate's documentation (`cargo doc -p fcu-ground --open`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};

use fcu_ground::address::LinkAddress;
use fcu_ground::cli::{self, Target};

#[derive(Parser)]
#[command(name = "fcu-ground", about = "Parameters, recordings and a live view of an fcu board over MAVLink 2")]
struct Args {
    /// The board: tcp:HOST:PORT (the emulated board under `cargo pil serve`) or
    /// serial:PATH[:BAUD] (a board on a USB-UART adapter; 115200 baud by default).
    #[arg(long, global = true, value_name = "LINK", value_parser = LinkAddress::parse)]
    link: Option<LinkAddress>,
    /// Seconds to wait for the board's first HEARTBEAT.
    #[arg(long, global = true, value_name = "S", default_value = "10", value_parser = cli::parse_seconds)]
    timeout: Duration,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Parameter files in MAVProxy's `param save` format (NAME VALUE lines).
    Params {
        #[command(subcommand)]
        action: ParamsAction,
    },
    /// Record the board's telemetry into DIR/flight.csv and DIR/flight.svg (as fcu-sim fly writes them).
    Record {
        /// Output directory (created if missing).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Seconds to record; without it, until Ctrl-C.
        #[arg(long, value_name = "S", value_parser = cli::parse_seconds)]
        duration: Option<Duration>,
    },
    /// A live view of state, attitude, radio, motors and battery.
    Watch {
        /// Seconds to watch; without it, until Ctrl-C.
        #[arg(long, value_name = "S", value_parser = cli::parse_seconds)]
        duration: Option<Duration>,
    },
}

#[derive(Subcommand)]
enum ParamsAction {
    /// Every parameter of the board into FILE.
    Pull { file: PathBuf },
    /// Set the parameters of FILE whose values differ from the board's (exit 1 if one is refused).
    Push { file: PathBuf },
    /// The differences between FILE and the board (exit 1 if any).
    Diff { file: PathBuf },
}

fn main() -> ExitCode {
    let args = Args::parse();
    let Some(link) = args.link else {
        eprintln!(
            "fcu-ground: --link is missing: give tcp:HOST:PORT (the emulated board) or serial:PATH[:BAUD] (a board on a USB-UART adapter)"
        );
        return ExitCode::from(2);
    };
    let target = Target { link, timeout: args.timeout };
    let done = match &args.command {
        Command::Params { action: ParamsAction::Pull { file } } => cli::pull(&target, file),
        Command::Params { action: ParamsAction::Push { file } } => cli::push(&target, file),
        Command::Params { action: ParamsAction::Diff { file } } => cli::diff(&target, file),
        Command::Record { out, duration } => cli::record(&target, out, *duration),
        Command::Watch { duration } => cli::watch(&target, *duration),
    };
    match done {
        Ok(code) => code,
        Err(e) => {
            eprintln!("fcu-ground: {}", e.0);
            ExitCode::from(2)
        }
    }
}
