//! How low can the `yaw` scenario's error go on an airframe? Flies it with the default
//! profile, then again with an open-loop oracle taking over the motors at each of the two
//! stick steps inside the metric's window (the stop of the full-stick turn at 11 s, the start
//! of the 70 % turn at 13 s): from the tick the core sees the step, every motor at one end of
//! the compare range for `brake_s` (the whole range as yaw torque, the way the step asks), then
//! at the other end until `reverse_s` (to stop the acceleration the motors' lag would carry on),
//! then the core again. It searches both times for each step, so it knows the airframe and
//! the step's future, which no controller does: what it reaches is what a perfectly timed
//! bang-bang gets, a floor that a feedback loop can approach but not pass in practice.
//!
//! ```sh
//! cargo run --release -p fcu-testkit --example yaw_floor             # seeds 1..=5, ±30 %
//! cargo run --release -p fcu-testkit --example yaw_floor -- 1 5      # some seeds
//! ```
//!
//! About 30 s per seed on one core of this machine (two seeds run at once).

use fcu_core::config::Config;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::scenario::{self, Scenario};
use fcu_testkit::sim::stick_rate::StickRate;
use fcu_testkit::sim::{self, metrics, ComputerView, FlightComputer, InProcess, RunOptions, SimError};
use fcu_testkit::Profile;

const SPREAD: f64 = 0.3;
/// The metric's window ends at 16 s: nothing after it counts.
const FLIGHT_S: f64 = 16.2;
/// A step the oracle answers: the stick's rate moving by more than this, °/s.
const STEP_DPS: f64 = 20.0;

/// Seconds after a step: full torque the step's way until `brake_s`, the other way until
/// `reverse_s`.
#[derive(Clone, Copy, Debug, Default)]
struct Switches {
    brake_s: f64,
    reverse_s: f64,
}

/// The core, with its motor outputs replaced after each stick step per `plan`.
struct Oracle {
    core: InProcess,
    /// The stick's yaw rate, from the edges the core is given.
    stick: StickRate,
    plan: [Switches; 2],
    max_compare: u16,
    last_cmd_dps: f64,
    /// The step being answered: when the core saw it, its sign, its index in `plan`.
    step: Option<(f64, f64, usize)>,
    steps_seen: usize,
}

impl Oracle {
    fn new(plan: [Switches; 2]) -> Oracle {
        let cfg = Config::default();
        let max_compare = cfg.mixer.max_compare as u16;
        let core = InProcess::new(cfg).unwrap_or_else(|e| panic!("{e}"));
        Oracle { core, stick: StickRate::new(&cfg), plan, max_compare, last_cmd_dps: 0.0, step: None, steps_seen: 0 }
    }
}

impl FlightComputer for Oracle {
    fn tick_hz(&self) -> f64 {
        self.core.tick_hz()
    }

    fn step(&mut self, t_end_s: f64, edges: &[TimedEdge], imu: fcu_core::imu::RawImu, battery_v: f64) -> Result<[u16; 4], SimError> {
        let compare = self.core.step(t_end_s, edges, imu, battery_v)?;
        let cmd_dps = self.stick.yaw_rate_dps(edges.iter().map(|e| e.edge));
        // Only the steps inside the metric's window (8.5 s on): the turn's start at 8 s is
        // the core's.
        if t_end_s > 8.5 && (cmd_dps - self.last_cmd_dps).abs() > STEP_DPS && self.steps_seen < self.plan.len() {
            self.step = Some((t_end_s, (cmd_dps - self.last_cmd_dps).signum(), self.steps_seen));
            self.steps_seen += 1;
        }
        self.last_cmd_dps = cmd_dps;
        let Some((t0, sign, k)) = self.step else { return Ok(compare) };
        let s = self.plan[k];
        let since = t_end_s - t0;
        // Positive yaw raises M1 and M3 (the CW props), negative M2 and M4.
        let (hi, lo) = (self.max_compare, 0);
        let positive = [hi, lo, hi, lo];
        let negative = [lo, hi, lo, hi];
        let forward = sign > 0.0;
        Ok(if since < s.brake_s {
            if forward {
                positive
            } else {
                negative
            }
        } else if since < s.reverse_s {
            if forward {
                negative
            } else {
                positive
            }
        } else {
            compare
        })
    }

    fn view(&self) -> ComputerView {
        self.core.view()
    }
}

fn yaw_error(sc: &Scenario, seed: u64, computer: &mut dyn FlightComputer) -> f64 {
    let opts = RunOptions { seed, plant_spread: SPREAD, duration_s: Some(FLIGHT_S), ..RunOptions::default() };
    let log = sim::run_with(computer, sc, Profile::Default, &opts).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
    metrics::compute(&log, sc).yaw_rate_rms_dps.unwrap_or(f64::INFINITY)
}

/// The best switch times for step `k`, the other step's plan fixed.
fn search(sc: &Scenario, seed: u64, mut plan: [Switches; 2], k: usize) -> (f64, [Switches; 2]) {
    let mut best = (f64::INFINITY, plan);
    for i in 0..25 {
        let brake_s = 0.03 + 0.005 * f64::from(i);
        for j in 0..20 {
            plan[k] = Switches { brake_s, reverse_s: brake_s + 0.005 * f64::from(j) };
            let e = yaw_error(sc, seed, &mut Oracle::new(plan));
            if e < best.0 {
                best = (e, plan);
            }
        }
    }
    best
}

fn floor(seed: u64) -> String {
    let sc = scenario::by_name("yaw").unwrap_or_else(|| panic!("no yaw scenario"));
    let core = yaw_error(&sc, seed, &mut InProcess::new(Config::default()).unwrap_or_else(|e| panic!("{e}")));
    let (_, plan) = search(&sc, seed, [Switches::default(); 2], 0);
    let (oracle, plan) = search(&sc, seed, plan, 1);
    let ms = |s: Switches| format!("{:.0}/{:.0} ms", s.brake_s * 1e3, s.reverse_s * 1e3);
    format!("seed {seed}: default {core:.2} °/s, oracle {oracle:.2} °/s (stop {}, start {})", ms(plan[0]), ms(plan[1]))
}

fn main() {
    let mut seeds: Vec<u64> = Vec::new();
    for a in std::env::args().skip(1) {
        match a.parse() {
            Ok(s) => seeds.push(s),
            Err(_) => {
                eprintln!("yaw_floor: `{a}` is not a seed (a whole number)");
                std::process::exit(2);
            }
        }
    }
    if seeds.is_empty() {
        seeds = vec![1, 2, 3, 4, 5];
    }
    println!("yaw scenario, airframes ±30 %: RMS error against the stick, default profile and the oracle's floor");
    for pair in seeds.chunks(2) {
        let handles: Vec<_> = pair.iter().map(|&s| std::thread::spawn(move || floor(s))).collect();
        for h in handles {
            println!("{}", h.join().unwrap_or_else(|_| "a seed's search failed".into()));
        }
    }
}
