//! `fcu-sim fly` and `fcu-sim compare`: fly a scenario against the simulated STEVAL-DRONE01.
//!
//! Exit codes: 0 the scenario's criteria passed, 1 they did not, 2 bad usage or input
//! (returned as a [`CliError`] for the dispatcher to print).

use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use super::CliError;
use crate::sim::metrics::{self, Metrics, Verdict};
use crate::sim::scenario::{self, Scenario, Timeline};
use crate::sim::{self as sim, FlightLog, LogRow, Profile, RunOptions};

#[derive(clap::Args, Debug)]
pub struct FlyArgs {
    #[arg(long, help = scenario::help())]
    pub scenario: String,
    /// Flight-controller profile: `default` (the product) or `reference` (ST's firmware).
    #[arg(long, default_value = "default")]
    pub profile: String,
    /// Seed for sensor noise, radio jitter and (with --spread) the airframe.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Stick timeline CSV (`t_s,ail_us,ele_us,thr_us,rud_us,link`) replacing the scenario's.
    #[arg(long)]
    pub sticks: Option<PathBuf>,
    /// Simulated duration in seconds (default: the scenario's own).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Randomise every airframe parameter by ±this fraction from the seed (0 = nominal drone).
    #[arg(long, default_value_t = 0.0)]
    pub spread: f64,
    /// A parameter file in MAVProxy's `param save` format (`NAME VALUE` lines, as
    /// `fcu-ground params pull` or MAVProxy's `param save` write it), over the default
    /// profile's values: the flight core flies with what a board would have saved.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Output directory for flight.csv and flight.svg (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    #[arg(long, help = scenario::help())]
    pub scenario: String,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Randomise every airframe parameter by ±this fraction from the seed (0 = nominal drone).
    #[arg(long, default_value_t = 0.0)]
    pub spread: f64,
}

fn scenario_named(name: &str) -> Result<Scenario, CliError> {
    scenario::by_name(name).ok_or_else(|| CliError(format!("--scenario: unknown scenario `{name}`; known: {}", scenario::names_list())))
}

/// `--spread` checked: a fraction in [0, 0.9]. Shared with `fcu-pil fly`.
pub fn check_spread(spread: f64) -> Result<f64, CliError> {
    if spread.is_finite() && (0.0..=0.9).contains(&spread) {
        Ok(spread)
    } else {
        Err(CliError(format!("--spread: {spread} must be a fraction between 0 and 0.9")))
    }
}

/// The configuration a `--params` file makes of `profile`'s. The reference profile keeps no
/// parameters (it reproduces ST's firmware number for number); a bad line is named.
pub fn config_with_params(profile: Profile, path: &Path) -> Result<fcu_core::Config, CliError> {
    let named = |what: String| CliError(format!("--params {}: {what}", path.display()));
    if profile == Profile::Reference {
        return Err(named(
            "the reference profile keeps no parameters (it is ST's firmware, number for number); fly --profile default".into(),
        ));
    }
    let text = crate::csv::read_text(path).map_err(|e| named(e.to_string()))?;
    fcu_params::apply_file(&profile.config(), &text).map_err(|e| named(describe_file_error(e)))
}

/// A refused parameter file in words: its line and the rule, or the rule the set as a whole
/// breaks (line 0).
pub fn describe_file_error(e: fcu_params::FileError) -> String {
    match e.line {
        0 => format!("the set is refused: {}", e.rule),
        line => format!("line {line}: {}", e.rule),
    }
}

/// The shortest flight: one control tick at 800 Hz.
pub const MIN_DURATION_S: f64 = 0.00125;

/// The scenario a `fly` command asks for: a named scenario, its stick timeline replaced by
/// `sticks` when given, its length by `duration_s`. Shared with `fcu-pil fly`.
pub fn prepare_scenario(name: &str, sticks: Option<&Path>, duration_s: Option<f64>) -> Result<Scenario, CliError> {
    let mut sc = scenario_named(name)?;
    if let Some(d) = duration_s {
        // At least one control tick (1.25 ms at 800 Hz), at most an hour.
        if !(d.is_finite() && (MIN_DURATION_S..=3600.0).contains(&d)) {
            return Err(CliError(format!(
                "--duration: {d:.3e} must be a number of seconds between {MIN_DURATION_S} (one control tick) and 3600"
            )));
        }
    }
    if let Some(path) = sticks {
        let text = crate::csv::read_text(path).map_err(|e| CliError(format!("--sticks {}: {e}", path.display())))?;
        let tl = Timeline::parse_csv(&text).map_err(|e| CliError(format!("--sticks {}: {e}", path.display())))?;
        let last_row_s = tl.rows.last().map_or(0.0, |r| r.t_s);
        let name = format!("{} + sticks from {}", sc.name, path.display());
        // A file replaces the pilot; the scenario keeps its world (gusts, weak motor, hand).
        let world = sc.clone();
        sc = scenario::from_timeline(&name, tl, (last_row_s + 2.0).max(duration_s.unwrap_or(0.0)));
        sc.gusts = world.gusts;
        sc.hand = world.hand;
        sc.motor_thrust_scale = world.motor_thrust_scale;
        sc.radio = world.radio;
        sc.baro_freeze_s = world.baro_freeze_s;
        sc.settings = world.settings;
    }
    Ok(sc)
}

pub fn run(a: &FlyArgs) -> Result<ExitCode, CliError> {
    let profile = Profile::parse(&a.profile)
        .ok_or_else(|| CliError(format!("--profile: unknown profile `{}`; known: default, reference", a.profile)))?;
    let spread = check_spread(a.spread)?;
    let sc = prepare_scenario(&a.scenario, a.sticks.as_deref(), a.duration)?;
    let cfg = match &a.params {
        Some(path) => config_with_params(profile, path)?,
        None => profile.config(),
    };
    // The scenario's own settings (altitude hold's ALT_MODE) over the file's.
    let cfg = sc.configure(cfg).map_err(CliError)?;
    let out = OutputDir::prepare(&a.out).map_err(CliError)?;
    let mut csv = FlightCsv::create(&a.out).map_err(|e| out.abandon(e))?;

    let opts = RunOptions { seed: a.seed, plant_spread: spread, duration_s: a.duration, progress: true, ..RunOptions::default() };
    let mut computer = sim::InProcess::new(cfg).map_err(|e| out.abandon(CliError(e.to_string())))?;
    let flown = sim::run_streaming(&mut computer, &sc, profile, &opts, &mut |r| csv.row(r));
    let log = flown.map_err(|e| out.abandon(csv.abandon(CliError(e.to_string()))))?;
    let title = format!("fcu-sim fly: {} — profile {}, seed {}", sc.name, profile.name(), a.seed);
    report(&a.out, &title, &sc, &log, csv).map_err(|e| out.abandon(e))
}

/// `flight.csv`, written row by row as the flight runs (a long flight never holds its whole
/// CSV in memory) under a temporary name, renamed by [`report`] once its plot is written too.
pub struct FlightCsv {
    path: PathBuf,
    partial: PathBuf,
    file: BufWriter<File>,
}

impl FlightCsv {
    /// Opens `out/.flight.csv.partial` and writes the header.
    pub fn create(out: &Path) -> Result<FlightCsv, CliError> {
        let path = out.join("flight.csv");
        let partial = out.join(".flight.csv.partial");
        let opened = File::create(&partial).map(BufWriter::new);
        let mut csv = match opened {
            Ok(file) => FlightCsv { path, partial, file },
            Err(e) => return Err(CliError(format!("writing {}: {e}", path.display()))),
        };
        if let Err(e) = csv.file.write_all(sim::CSV_HEADER.as_bytes()) {
            return Err(csv.abandon(CliError(format!("writing {}: {e}", csv.path.display()))));
        }
        Ok(csv)
    }

    /// One more row; the error names the file.
    pub fn row(&mut self, r: &LogRow) -> Result<(), String> {
        r.write_csv(&mut self.file).map_err(|e| format!("writing {}: {e}", self.path.display()))
    }

    /// Every row of `log` (for a flight whose rows are known only at its end).
    pub fn rows(&mut self, log: &FlightLog) -> Result<(), CliError> {
        log.rows.iter().try_for_each(|r| self.row(r)).map_err(CliError)
    }

    /// Flushed and renamed to `flight.csv`.
    fn finish(mut self) -> Result<PathBuf, CliError> {
        let done = self.file.flush().and_then(|()| std::fs::rename(&self.partial, &self.path));
        match done {
            Ok(()) => Ok(self.path),
            Err(e) => {
                let e = CliError(format!("writing {}: {e}", self.path.display()));
                Err(self.abandon(e))
            }
        }
    }

    /// The flight failed: the partial file goes, the error is handed on.
    pub fn abandon(&self, e: CliError) -> CliError {
        let _ = std::fs::remove_file(&self.partial);
        e
    }
}

pub use fcu_log::OutputDir;

/// Completes `flight.csv` (streamed into `csv` as the flight ran) and writes `flight.svg` into
/// `out`, prints the metrics and the criteria, and returns exit status 0 if every criterion
/// passed, 1 if not. Shared with `fcu-pil fly`.
pub fn report(out: &Path, title: &str, sc: &Scenario, log: &FlightLog, csv: FlightCsv) -> Result<ExitCode, CliError> {
    let m = metrics::compute(log, sc);
    let verdicts = metrics::check_all(log, sc);
    let svg_path = out.join("flight.svg");
    // The plot under a temporary name first, both renamed once both are complete: never a CSV
    // without its plot.
    let svg_tmp = out.join(".flight.svg.partial");
    if let Err(e) = sim::plot::write_svg(&log.rows, title, &svg_tmp) {
        let _ = std::fs::remove_file(&svg_tmp);
        return Err(csv.abandon(CliError(e)));
    }
    let csv_path = match csv.finish() {
        Ok(p) => p,
        Err(e) => {
            let _ = std::fs::remove_file(&svg_tmp);
            return Err(e);
        }
    };
    if let Err(e) = std::fs::rename(&svg_tmp, &svg_path) {
        let _ = std::fs::remove_file(&svg_tmp);
        let _ = std::fs::remove_file(&csv_path);
        return Err(CliError(format!("writing {}: {e}", svg_path.display())));
    }

    print_summary(sc, log, &m, &verdicts);
    println!("wrote {} ({} rows at {:.2} Hz) and {}", csv_path.display(), log.rows.len(), log.tick_hz, svg_path.display());
    let passed = verdicts.iter().all(|v| v.passed);
    println!("{}", if passed { "PASS" } else { "FAIL" });
    Ok(if passed { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

fn print_summary(sc: &Scenario, log: &FlightLog, m: &Metrics, verdicts: &[Verdict]) {
    println!("scenario {}: {}", sc.name, sc.about);
    println!(
        "profile {}, seed {}, {:.1} s at {:.2} Hz; drone {:.1} g, F_max {:.3} N/motor",
        log.profile.name(),
        log.seed,
        log.rows.last().map_or(0.0, |r| r.t_s),
        log.tick_hz,
        log.plant.mass_kg * 1000.0,
        log.plant.motor_max_thrust_n
    );
    println!("metrics:");
    for (name, value) in metrics::lines(m) {
        println!("  {name:<38} {value}");
    }
    if verdicts.is_empty() {
        println!("criteria: none (stick file)");
    } else {
        println!("criteria:");
    }
    for v in verdicts {
        println!("  [{}] {} — {}", if v.passed { "pass" } else { "FAIL" }, v.criterion, v.detail);
    }
}

pub fn run_compare(a: &CompareArgs) -> Result<ExitCode, CliError> {
    let sc = scenario_named(&a.scenario)?;
    let spread = check_spread(a.spread)?;
    let opts = RunOptions { seed: a.seed, plant_spread: spread, progress: true, ..RunOptions::default() };
    let mut results = Vec::new();
    for profile in [Profile::Reference, Profile::Default] {
        let log = sim::run(&sc, profile, &opts).map_err(|e| CliError(e.to_string()))?;
        let m = metrics::compute(&log, &sc);
        let v = metrics::check_all(&log, &sc);
        results.push((profile, m, v));
    }
    println!("scenario {} (seed {}): {}", sc.name, a.seed, sc.about);
    println!("{:<40} {:>14} {:>14}", "metric", "reference", "default");
    let cols: Vec<Vec<(&str, String)>> = results.iter().map(|(_, m, _)| metrics::lines(m)).collect();
    if let [r, d] = cols.as_slice() {
        for ((name, rv), (_, dv)) in r.iter().zip(d) {
            println!("{name:<40} {rv:>14} {dv:>14}");
        }
    }
    println!("{:<40} {:>14} {:>14}", "criteria", "reference", "default");
    for (i, c) in sc.criteria.iter().enumerate() {
        let cell = |k: usize| {
            results
                .get(k)
                .and_then(|(_, _, v)| v.get(i))
                .map_or("n/a".to_string(), |v| if v.passed { "pass".into() } else { "FAIL".into() })
        };
        println!("  {:<38} {:>14} {:>14}", truncate(&scenario::describe(c), 38), cell(0), cell(1));
    }
    for (p, _, v) in &results {
        let failed: Vec<&Verdict> = v.iter().filter(|v| !v.passed).collect();
        for f in failed {
            println!("{} failed: {} — {}", p.name(), f.criterion, f.detail);
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn truncate(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        s.chars().take(n.saturating_sub(1)).chain(std::iter::once('…')).collect()
    }
}
