//! `fcu-pil`: the release firmware ELF in an emulated STM32F401, flown against the simulated
//! drone of fcu-testkit (`cargo pil fly --scenario hover --out out/pil-hover`), and measured
//! on the image (`cargo pil measure`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use fcu_pil::timing::TimingProfile;
use fcu_pil::{firmware, measure, rig};

#[derive(Parser, Debug)]
#[command(name = "fcu-pil", version, about = "Fly and measure the release firmware ELF in an emulated STM32F401")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Fly a scenario with the firmware image in the loop; writes flight.csv, flight.svg and
    /// uart.log, prints the metrics and criteria of `fcu-sim fly`.
    Fly(FlyArgs),
    /// Fly a scenario and print what the image costs: instructions per control interrupt,
    /// latencies, the longest stretch with the radio capture interrupt masked, CPU load,
    /// stack, and the harness's own speed.
    Measure(MeasureArgs),
    /// Run the board at real time on the bench (level; the scenario's sticks, or centred with
    /// the throttle low) with USART1 bridged to TCP clients: every client's bytes enter USART1
    /// RX (PA10) at 115200 baud, USART1's TX bytes go to every client (several ground stations
    /// at once, as SITL serves them). Reboots keep the flash; --flash FILE loads it at power-on
    /// and saves it as it changes. Ctrl-C ends it with a summary.
    Serve(ServeArgs),
}

#[derive(clap::Args, Debug)]
struct ServeArgs {
    /// Where to listen: tcp:HOST:PORT (e.g. tcp:127.0.0.1:5760).
    #[arg(long)]
    link: String,
    /// A scenario whose sticks the simulated pilot plays (default: centred, throttle low).
    #[arg(long, help = format!("{} whose sticks the simulated pilot plays (default: centred, throttle low)", fcu_testkit::sim::scenario::help()))]
    scenario: Option<String>,
    /// The flash memory's contents: loaded at power-on if the file exists, saved as it changes.
    #[arg(long)]
    flash: Option<PathBuf>,
    /// Cut the power at a fraction of a flash operation to come: erase|program:FRACTION[@N]
    /// (e.g. erase:3/8, program:1/2@4 for the fourth word programmed); the board powers on
    /// again with what the cut left in flash.
    #[arg(long)]
    power_cut: Option<String>,
    /// Boot with these parameters (MAVProxy's `param save` format: NAME VALUE lines) as the
    /// board's only saved set, over the defaults; an error names a line the set refuses.
    #[arg(long)]
    params: Option<PathBuf>,
    /// Emulated seconds to serve after boot (default one hour).
    #[arg(long, default_value_t = 3600.0)]
    duration: f64,
    /// The LSI's frequency in Hz, 17000 to 47000 (DS9716's range; default its nominal 32000):
    /// the independent watchdog's timeout scales with it.
    #[arg(long, value_name = "17000..=47000", value_parser = fcu_pil::serve::parse_lsi_hz)]
    lsi_hz: Option<u64>,
    #[arg(long)]
    /// The firmware ELF (default: FCU_PIL_ELF, else the release firmware, built now, as
    /// `cargo fw` does).
    elf: Option<PathBuf>,
    #[command(flatten)]
    timing: TimingArg,
}

#[derive(clap::Args, Debug)]
struct FlyArgs {
    #[arg(long, help = fcu_testkit::sim::scenario::help())]
    scenario: String,
    /// Seed for sensor noise, radio jitter and (with --spread) the airframe.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Stick timeline CSV (`t_s,ail_us,ele_us,thr_us,rud_us,link`) replacing the scenario's.
    #[arg(long)]
    sticks: Option<PathBuf>,
    /// Simulated duration in seconds (default: the scenario's own).
    #[arg(long)]
    duration: Option<f64>,
    /// Randomise every airframe parameter by ±this fraction from the seed.
    #[arg(long, default_value_t = 0.0)]
    spread: f64,
    /// The firmware ELF (default: build the release firmware, as `cargo fw` does).
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Output directory for flight.csv, flight.svg and uart.log (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Boot with these parameters (MAVProxy's `param save` format: NAME VALUE lines, as
    /// `fcu-sim fly --params` takes) saved in flash, over the defaults (or over --flash's set).
    /// Its UART is set to text lines, which the harness reads the board's state from.
    #[arg(long)]
    params: Option<PathBuf>,
    /// Boot from this flash image (as `cargo pil serve --flash` saves it: the parameters a
    /// ground station set and saved), its UART set to text lines as with --params; the file
    /// is only read.
    #[arg(long)]
    flash: Option<PathBuf>,
    #[command(flatten)]
    timing: TimingArg,
}

#[derive(clap::Args, Debug)]
struct TimingArg {
    /// How the emulator prices time: optimistic (one cycle per instruction, register accesses
    /// early in their block) or pessimistic (instruction classes, flash wait states, APB
    /// stalls, accesses at the end of their block). Default: FCU_PIL_TIMING, else optimistic.
    #[arg(long, value_name = "optimistic|pessimistic")]
    timing: Option<TimingProfile>,
}

impl TimingArg {
    fn setup(&self) -> Result<rig::BoardSetup, String> {
        let timing = match self.timing {
            Some(t) => t,
            None => TimingProfile::from_env()?,
        };
        Ok(rig::BoardSetup { timing: Some(timing), ..rig::BoardSetup::default() })
    }
}

#[derive(clap::Args, Debug)]
struct MeasureArgs {
    #[arg(long, default_value = "hover", help = fcu_testkit::sim::scenario::help())]
    scenario: String,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[arg(long)]
    duration: Option<f64>,
    #[arg(long)]
    elf: Option<PathBuf>,
    #[command(flatten)]
    timing: TimingArg,
    /// Exit 1 if the image misses a latency target (TIM9 update to the last motor compare
    /// write ≤ 25 µs median, TIM2 capture to its read ≤ 5 µs max, TIM2 masked ≤ 5 µs).
    #[arg(long)]
    check: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fly(a) => fly(&a),
        Command::Measure(a) => measure_cmd(&a),
        Command::Serve(a) => serve_cmd(&a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("fcu-pil: error: {e}");
            ExitCode::from(2)
        }
    }
}

fn fly(a: &FlyArgs) -> Result<ExitCode, String> {
    use fcu_testkit::cli::fly as host;
    let spread = host::check_spread(a.spread).map_err(|e| e.0)?;
    let sc = host::prepare_scenario(&a.scenario, a.sticks.as_deref(), a.duration).map_err(|e| e.0)?;
    let mut setup = a.timing.setup()?;
    let saved = a.params.is_some() || a.flash.is_some();
    let elf = firmware::resolve_elf(a.elf.as_deref())?;
    if saved {
        let flash = match &a.flash {
            Some(path) => std::fs::read(path).map_err(|e| format!("--flash {}: {e}", path.display()))?,
            None => Vec::new(),
        };
        let text = match &a.params {
            Some(path) => Some(std::fs::read_to_string(path).map_err(|e| format!("--params {}: {e}", path.display()))?),
            None => None,
        };
        let named = |e| match e {
            fcu_pil::serve::FlightFlashError::SavedSetRefused(rule) => {
                format!(
                    "--flash {}: the flash's saved parameters are refused ({rule})",
                    a.flash.as_deref().unwrap_or(std::path::Path::new("")).display()
                )
            }
            fcu_pil::serve::FlightFlashError::File(e) => match &a.params {
                Some(p) => format!("--params {}: {e}", p.display()),
                None => e,
            },
        };
        setup.flash_contents = Some(fcu_pil::serve::flash_for_flight(flash, text.as_deref()).map_err(named)?);
    }
    std::fs::create_dir_all(&a.out).map_err(|e| format!("--out {}: {e}", a.out.display()))?;
    let opts =
        fcu_testkit::sim::RunOptions { seed: a.seed, plant_spread: spread, duration_s: a.duration, progress: true, ..Default::default() };
    let flight = rig::fly_with(&elf, &sc, &opts, &setup)?;
    let uart_path = a.out.join("uart.log");
    std::fs::write(&uart_path, &flight.uart_log).map_err(|e| format!("writing {}: {e}", uart_path.display()))?;
    let timing = setup.timing_profile()?;
    // The image's file name, not its path: a full path is cut at the plot's left edge.
    let image = elf.file_name().map_or_else(|| elf.display().to_string(), |n| n.to_string_lossy().into_owned());
    let title = format!("fcu-pil fly: {} — firmware image {image}, seed {}, {timing} timing", sc.name, a.seed);
    // The board's rows are retimed from its own tick count once the flight is over: written then.
    let mut csv = host::FlightCsv::create(&a.out).map_err(|e| e.0)?;
    csv.rows(&flight.log).map_err(|e| csv.abandon(e).0)?;
    let code = host::report(&a.out, &title, &sc, &flight.log, csv).map_err(|e| e.0)?;
    println!("wrote {}", uart_path.display());
    println!(
        "emulated {:.1} s of the board ({timing} timing) in {:.1} s ({:.1}× real time), {} instructions",
        flight.emulated_s,
        flight.wall_s,
        flight.emulated_s / flight.wall_s.max(1e-9),
        flight.instructions
    );
    Ok(code)
}

fn measure_cmd(a: &MeasureArgs) -> Result<ExitCode, String> {
    let setup = a.timing.setup()?;
    let elf = firmware::resolve_elf(a.elf.as_deref())?;
    let sc = fcu_testkit::cli::fly::prepare_scenario(&a.scenario, None, a.duration).map_err(|e| e.0)?;
    let opts = fcu_testkit::sim::RunOptions { seed: a.seed, duration_s: a.duration, progress: true, ..Default::default() };
    let report = measure::measure(&elf, &sc, &opts, &setup)?;
    print!("{report}");
    if !a.check {
        return Ok(ExitCode::SUCCESS);
    }
    let missed = report.missed_targets();
    for line in &missed {
        eprintln!("fcu-pil: target missed: {line}");
    }
    if missed.is_empty() {
        println!("  targets: all {} met", measure::TARGETS.len());
        Ok(ExitCode::SUCCESS)
    } else {
        Ok(ExitCode::from(1))
    }
}

fn serve_cmd(a: &ServeArgs) -> Result<ExitCode, String> {
    let setup = rig::BoardSetup { lsi_hz: a.lsi_hz, ..a.timing.setup()? };
    // Every argument is checked before the firmware is built (a build takes minutes).
    if let Some(name) = &a.scenario {
        fcu_testkit::cli::fly::prepare_scenario(name, None, None).map_err(|e| e.0)?;
    }
    let elf = firmware::resolve_elf(a.elf.as_deref())?;
    let listener = fcu_pil::serve::listen(&a.link)?;
    println!("fcu-pil serve: listening on {}, booting {}", a.link, elf.display());
    let power_cut = a.power_cut.as_deref().map(fcu_pil::serve::parse_power_cut).transpose()?;
    let opts = fcu_pil::serve::ServeOptions {
        elf,
        scenario: a.scenario.clone(),
        flash: a.flash.clone(),
        duration_s: a.duration,
        setup,
        power_cut,
        params: a.params.clone(),
    };
    // Ctrl-C ends the session at the next control period, with the summary a full one prints.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, std::sync::atomic::Ordering::Relaxed)).map_err(|e| format!("Ctrl-C handler: {e}"))?;
    let report = fcu_pil::serve::serve_until(listener, &opts, stop)?;
    print!("{report}");
    Ok(ExitCode::SUCCESS)
}
