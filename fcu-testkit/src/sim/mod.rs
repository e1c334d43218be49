//! The simulated STEVAL-DRONE01 flown in closed loop by the real [`fcu_core::FlightController`].
//!
//! One control tick (800 Hz default, 807.69 Hz reference — whatever the profile's TIM9 really
//! produces) is, in order:
//! 1. the receiver emits the capture edges that happen during the tick; they go to the core's
//!    edge decoder in time order (the capture interrupt outranks the control tick);
//! 2. the plant integrates over the tick in `substeps` RK4 steps with the compare values the
//!    previous tick wrote (zero-order hold, like TIM4), and the IMU model follows each substep;
//! 3. at the end of the tick the core reads the IMU words and the pulses, returns compare
//!    values, and runs its outer step inline when one is due (as the replay does).

pub mod baro_model;
pub mod imu_model;
pub mod loop_id;
pub mod metrics;
mod pilot;
pub mod plant;
pub mod radio_model;
pub mod rng;
pub mod scenario;
pub mod stick_rate;
mod world;

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use fcu_core::imu::CalibrationPhase;
use fcu_core::supervisor::FlightState;
use fcu_core::{Config, FlightController};

use pilot::Transmitter;
use plant::{Plant, PlantParams};
use radio_model::TimedEdge;
use scenario::Scenario;
use world::World;

pub use crate::Profile;

/// How to run a scenario.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub seed: u64,
    /// ±fraction applied to every plant parameter from the seed (0 = the nominal drone).
    pub plant_spread: f64,
    /// Plant RK4 steps per control tick (5 at 800 Hz = 4 kHz).
    pub substeps: u32,
    /// Override of the scenario's length, s.
    pub duration_s: Option<f64>,
    /// Print a progress line on stderr once the run has taken more than a couple of seconds.
    pub progress: bool,
    /// Added to the compare values before the plant gets them (loop identification).
    pub excitation: Option<loop_id::Multisine>,
    /// Control ticks the plant gets the compare values late, beyond the zero-order hold of
    /// one tick (robustness: does the loop keep its margins with one more tick of delay?).
    pub extra_delay_ticks: u32,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions { seed: 1, plant_spread: 0.0, substeps: 5, duration_s: None, progress: false, excitation: None, extra_delay_ticks: 0 }
    }
}

pub use fcu_log::{plot, LogRow, Vertical, VerticalMode, CSV_HEADER};

/// Everything one flight produced.
#[derive(Clone, Debug)]
pub struct FlightLog {
    pub scenario: String,
    pub profile: Profile,
    pub seed: u64,
    pub tick_hz: f64,
    pub plant: PlantParams,
    pub rows: Vec<LogRow>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum SimError {
    Config(String),
    /// The flight computer failed (an emulated board's fault, for instance).
    Computer(String),
    /// A logged row could not be handed on (the CSV being written as the flight runs).
    Output(String),
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimError::Config(m) | SimError::Computer(m) | SimError::Output(m) => write!(f, "{m}"),
        }
    }
}

/// What a flight computer says about itself after a step: what the log records besides the
/// plant's truth. The in-process core fills it from its `Status`; an emulated board from what
/// it reports on its UART (which is why it is a small view).
#[derive(Clone, Debug, PartialEq)]
pub struct ComputerView {
    pub state: FlightState,
    pub armed: bool,
    /// The computer's own link verdict.
    pub link: bool,
    pub est_roll_deg: f64,
    pub est_pitch_deg: f64,
    pub roll_target_deg: f64,
    pub pitch_target_deg: f64,
    pub yaw_target_deg: f64,
    /// A calibration has passed since power-on.
    pub calibrated: bool,
    pub calibrating: bool,
    pub calibration_restarts: u16,
    /// The vertical half's report (`None`: the computer reports none).
    pub altitude: Option<fcu_core::altitude::AltitudeStatus>,
}

impl Default for ComputerView {
    fn default() -> Self {
        ComputerView {
            state: FlightState::Disarmed,
            armed: false,
            link: false,
            est_roll_deg: 0.0,
            est_pitch_deg: 0.0,
            roll_target_deg: 0.0,
            pitch_target_deg: 0.0,
            yaw_target_deg: 0.0,
            calibrated: false,
            calibrating: false,
            calibration_restarts: 0,
            altitude: None,
        }
    }
}

/// The seam between the simulated drone and what flies it: raw sensor words and capture
/// edges in, TIM4 compare values out. [`InProcess`] is the flight core called directly; the
/// `fcu-pil` crate implements it with the release firmware running in an emulated STM32F401,
/// so every scenario, criterion, CSV and plot works for both.
pub trait FlightComputer {
    /// Control ticks per second: the simulation advances one tick per [`FlightComputer::step`].
    fn tick_hz(&self) -> f64;
    /// One control period ending at `t_end_s` (scenario time): the capture edges the receiver
    /// produced during it (in time order, with their times), the IMU's raw words at its end
    /// and the battery voltage. Returns the compare values that drive the motors over the
    /// next period.
    fn step(&mut self, t_end_s: f64, edges: &[TimedEdge], imu: fcu_core::imu::RawImu, battery_v: f64) -> Result<[u16; 4], SimError>;
    /// The air at the drone for the [`FlightComputer::step`] that follows: its height above
    /// the take-off level, m. For a computer with a barometer model (fcu-pil's emulated
    /// LPS22HB); the others have none and ignore it.
    fn air(&mut self, _height_m: f64) -> Result<(), SimError> {
        Ok(())
    }
    /// [`FlightComputer::step`] for a computer that reads the simulated LPS22HB itself
    /// (`baro`, stepped with the plant). The in-process core reads its burst at each outer
    /// step, as the firmware does; the default ignores the part (a computer with a barometer
    /// model of its own gets the height through [`FlightComputer::air`]).
    fn step_with_baro(
        &mut self,
        t_end_s: f64,
        edges: &[TimedEdge],
        imu: fcu_core::imu::RawImu,
        battery_v: f64,
        _baro: &mut baro_model::BaroModel,
    ) -> Result<[u16; 4], SimError> {
        self.step(t_end_s, edges, imu, battery_v)
    }
    /// What the computer reports about itself now.
    fn view(&self) -> ComputerView;
}

/// The flight core in this process, one [`crate::harness::tick`] per step.
pub struct InProcess {
    fc: FlightController,
    decoder: fcu_core::rc::EdgeDecoder,
    /// Outer steps run, to read the barometer on every [`BARO_READ_EVERY_OUTER_STEPS`]th.
    outer_steps: u32,
}

/// The firmware reads the barometer on every second outer-job tick (80 Hz at the 160 Hz outer
/// step, for the part's 75 Hz output): so does the simulator, so it flies what the board flies.
pub const BARO_READ_EVERY_OUTER_STEPS: u32 = 2;

impl InProcess {
    pub fn new(cfg: Config) -> Result<InProcess, SimError> {
        let fc = FlightController::new(&cfg).map_err(|e| SimError::Config(e.to_string()))?;
        let decoder = fc.edge_decoder();
        Ok(InProcess { fc, decoder, outer_steps: 0 })
    }

    pub fn controller(&self) -> &FlightController {
        &self.fc
    }
}

impl FlightComputer for InProcess {
    fn tick_hz(&self) -> f64 {
        f64::from(self.fc.config().timing.tick_hz())
    }

    fn step(&mut self, _t_end_s: f64, edges: &[TimedEdge], imu: fcu_core::imu::RawImu, battery_v: f64) -> Result<[u16; 4], SimError> {
        // What the firmware's ADC reports (every tick here; every 100 ms on the board).
        self.fc.set_battery_mv((battery_v * 1000.0).round().clamp(0.0, f64::from(u32::MAX)) as u32);
        let ticked = crate::harness::tick(&mut self.fc, &mut self.decoder, imu, edges.iter().map(|e| e.edge));
        Ok(ticked.out.compare)
    }

    fn step_with_baro(
        &mut self,
        _t_end_s: f64,
        edges: &[TimedEdge],
        imu: fcu_core::imu::RawImu,
        battery_v: f64,
        baro: &mut baro_model::BaroModel,
    ) -> Result<[u16; 4], SimError> {
        self.fc.set_battery_mv((battery_v * 1000.0).round().clamp(0.0, f64::from(u32::MAX)) as u32);
        // The 6-byte burst as the firmware reads it, decoded by the core's own decoder, on
        // every second outer step (80 Hz for the part's 75 Hz), as the firmware's outer job
        // reads it.
        let steps = &mut self.outer_steps;
        let ticked = crate::harness::tick_reading_baro(&mut self.fc, &mut self.decoder, imu, edges.iter().map(|e| e.edge), || {
            *steps = steps.wrapping_add(1);
            (*steps % BARO_READ_EVERY_OUTER_STEPS == 0).then(|| fcu_core::baro::decode_burst(&baro.read_burst()))
        });
        Ok(ticked.out.compare)
    }

    fn view(&self) -> ComputerView {
        let st = self.fc.status();
        let (calibrating, restarts) = match st.calibration {
            CalibrationPhase::Averaging { restarts } => (true, restarts),
            _ => (false, 0),
        };
        let deg = |r: f32| f64::from(r).to_degrees();
        ComputerView {
            state: st.state,
            armed: st.state.motors_may_run(),
            link: st.link,
            est_roll_deg: deg(st.tilt.roll_rad),
            est_pitch_deg: deg(st.tilt.pitch_rad),
            // target_rad is (pitch about X, roll about Y, yaw) like the reference's thx/thy/thz.
            roll_target_deg: deg(st.target_rad[1]),
            pitch_target_deg: deg(st.target_rad[0]),
            yaw_target_deg: deg(st.target_rad[2]),
            calibrated: st.calibrated,
            calibrating,
            calibration_restarts: restarts,
            altitude: Some(st.altitude),
        }
    }
}

/// Fly `scenario` with `profile`'s flight core in this process, the scenario's parameter
/// settings applied ([`Scenario::configure`]). Deterministic for a given seed.
pub fn run(scenario: &Scenario, profile: Profile, opts: &RunOptions) -> Result<FlightLog, SimError> {
    let cfg = scenario.configure(profile.config()).map_err(SimError::Config)?;
    run_streaming(&mut InProcess::new(cfg)?, scenario, profile, opts, &mut |_| Ok(()))
}

/// Fly `scenario` with any [`FlightComputer`]; `profile` is the configuration it flies (the
/// simulated pilot's throttle mapping reads it). Deterministic for a given seed and computer.
pub fn run_with(
    computer: &mut dyn FlightComputer,
    scenario: &Scenario,
    profile: Profile,
    opts: &RunOptions,
) -> Result<FlightLog, SimError> {
    run_streaming(computer, scenario, profile, opts, &mut |_| Ok(()))
}

/// [`run_with`], handing every row to `on_row` as soon as it is logged (`fcu-sim fly` writes
/// its CSV this way, as the flight runs). An error from `on_row` stops the flight.
pub fn run_streaming(
    computer: &mut dyn FlightComputer,
    scenario: &Scenario,
    profile: Profile,
    opts: &RunOptions,
    on_row: &mut dyn FnMut(&LogRow) -> Result<(), String>,
) -> Result<FlightLog, SimError> {
    let mut params = if opts.plant_spread > 0.0 { PlantParams::randomized(opts.seed, opts.plant_spread) } else { PlantParams::default() };
    for (s, w) in params.motor_thrust_scale.iter_mut().zip(scenario.motor_thrust_scale) {
        *s *= w;
    }
    let mut world = World::new(scenario, &params, opts.seed, opts.substeps);
    let mut tx = Transmitter::new(scenario, profile.config(), opts.seed);
    let mut motors = MotorLine::new(opts);

    let tick_hz = computer.tick_hz();
    let tick_s = 1.0 / tick_hz;
    let duration_s = opts.duration_s.unwrap_or(scenario.duration_s).max(0.0);
    let n_ticks = (duration_s * tick_hz).round() as u64;
    let mut progress = Progress::new(opts.progress, format!("{} ({})", scenario.name, profile.name()), duration_s);

    // Grown as the flight goes, never sized from the duration up front.
    let mut rows = Vec::new();
    let mut edges: Vec<TimedEdge> = Vec::with_capacity(32);
    for k in 0..n_ticks {
        let t0 = k as f64 * tick_s;
        let t1 = t0 + tick_s;
        let yaw_rate_cmd_dps = tx.send(t1, &world.plant, &mut edges);
        world.advance(t0, tick_s);
        computer.air(world.plant.state.pos_earth_m[2])?;
        let compare = computer.step_with_baro(t1, &edges, world.imu.read(), world.plant.state.battery_v, &mut world.baro)?;
        motors.deliver(compare, t1, &mut world.plant);
        let sent = Sent { link: scenario.timeline.at(t1).link, thr_us: tx.last_thr_us, yaw_rate_cmd_dps };
        let logged = log_row(t1, &computer.view(), &world.plant, compare, sent);
        on_row(&logged).map_err(SimError::Output)?;
        rows.push(logged);
        progress.tick(t1, k + 1 == n_ticks);
    }
    progress.finish();

    Ok(FlightLog { scenario: scenario.name.clone(), profile, seed: opts.seed, tick_hz, plant: params, rows })
}

/// The compare values on their way to the motors: the loop identification's excitation added,
/// and held back `extra_delay_ticks` (motors off before the first arrives).
struct MotorLine<'o> {
    excitation: Option<&'o loop_id::Multisine>,
    extra_delay_ticks: usize,
    late: VecDeque<[u16; 4]>,
}

impl<'o> MotorLine<'o> {
    fn new(opts: &'o RunOptions) -> Self {
        MotorLine { excitation: opts.excitation.as_ref(), extra_delay_ticks: opts.extra_delay_ticks as usize, late: VecDeque::new() }
    }

    /// `compare`, written by the computer at `t_s`, on its way to the plant.
    fn deliver(&mut self, compare: [u16; 4], t_s: f64, plant: &mut Plant) {
        let to_plant = self.excitation.map_or(compare, |x| x.add_to(compare, t_s));
        if self.extra_delay_ticks == 0 {
            plant.set_compare(to_plant);
        } else {
            self.late.push_back(to_plant);
            while self.late.len() > self.extra_delay_ticks {
                plant.set_compare(self.late.pop_front().unwrap_or(to_plant));
            }
        }
    }
}

/// What the pilot's side sent by the end of a tick, as the log records it.
struct Sent {
    /// The timeline's link flag.
    link: bool,
    /// The last throttle pulse sent, µs.
    thr_us: f64,
    /// The yaw rate the stick asks for on this tick, °/s.
    yaw_rate_cmd_dps: f64,
}

/// The row of the tick ending at `t_s`: the plant's truth, what the computer says of itself and
/// the compare values it wrote.
fn log_row(t_s: f64, v: &ComputerView, plant: &Plant, compare: [u16; 4], sent: Sent) -> LogRow {
    let (pitch, roll, yaw) = plant.euler_rad();
    LogRow {
        t_s,
        state: v.state,
        armed: v.armed,
        link_tx: sent.link,
        link_core: v.link,
        roll_deg: roll.to_degrees(),
        pitch_deg: pitch.to_degrees(),
        yaw_deg: yaw.to_degrees(),
        yaw_rate_dps: plant.state.rate_body_rad_s[2].to_degrees(),
        est_roll_deg: v.est_roll_deg,
        est_pitch_deg: v.est_pitch_deg,
        roll_target_deg: v.roll_target_deg,
        pitch_target_deg: v.pitch_target_deg,
        yaw_target_deg: v.yaw_target_deg,
        yaw_rate_cmd_dps: sent.yaw_rate_cmd_dps,
        motors: compare,
        alt_m: plant.state.pos_earth_m[2],
        battery_v: plant.state.battery_v,
        thr_us: sent.thr_us,
        calibrated: v.calibrated,
        calibrating: v.calibrating,
        calibration_restarts: v.calibration_restarts,
        vertical: match &v.altitude {
            Some(a) => fcu_log::Vertical::from_status(a, plant.state.vel_earth_m_s[2]),
            None => fcu_log::Vertical { climb_m_s: plant.state.vel_earth_m_s[2], ..fcu_log::Vertical::ABSENT },
        },
    }
}

/// A progress line on stderr, once the run has taken more than a couple of seconds.
struct Progress {
    on: bool,
    label: String,
    duration_s: f64,
    started: Instant,
    next: Duration,
}

impl Progress {
    fn new(on: bool, label: String, duration_s: f64) -> Self {
        Progress { on, label, duration_s, started: Instant::now(), next: Duration::from_secs(2) }
    }

    fn tick(&mut self, t_s: f64, last: bool) {
        if self.on && self.started.elapsed() >= self.next {
            self.next += Duration::from_secs(1);
            eprint!("\r{}: {:.1} / {:.1} s simulated", self.label, t_s, self.duration_s);
            if last {
                eprintln!();
            }
        }
    }

    fn finish(&self) {
        if self.on && self.started.elapsed() >= Duration::from_secs(2) {
            let took_s = self.started.elapsed().as_secs_f64();
            eprintln!("\r{}: {:.1} s simulated in {:.1} s", self.label, self.duration_s, took_s);
        }
    }
}

impl FlightLog {
    /// The whole flight as CSV text (what `fcu-sim fly` streams to `flight.csv`).
    pub fn to_csv(&self) -> String {
        fcu_log::to_csv(&self.rows)
    }
}
