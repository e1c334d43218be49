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

pub mod imu_model;
pub mod loop_id;
pub mod metrics;
pub mod plant;
pub mod plot;
pub mod radio_model;
pub mod rng;
pub mod scenario;
pub mod stick_rate;

use std::time::{Duration, Instant};

use fcu_core::imu::CalibrationPhase;
use fcu_core::supervisor::FlightState;
use fcu_core::{Config, FlightController};

use imu_model::{ImuModel, ImuModelParams, Vibration};
use plant::{Disturbance, Plant, PlantParams};
use radio_model::{RadioModel, TimedEdge, TxFrame};
use scenario::{Scenario, Throttle};
use stick_rate::StickRate;

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

/// One logged control tick.
#[derive(Clone, Debug, PartialEq)]
pub struct LogRow {
    pub t_s: f64,
    pub state: FlightState,
    pub armed: bool,
    /// The transmitter's link flag from the timeline (what the receiver is sending).
    pub link_tx: bool,
    /// The core's own link verdict.
    pub link_core: bool,
    /// True attitude (reference convention: roll about body Y, pitch about body X).
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    pub yaw_rate_dps: f64,
    pub est_roll_deg: f64,
    pub est_pitch_deg: f64,
    pub roll_target_deg: f64,
    pub pitch_target_deg: f64,
    pub yaw_target_deg: f64,
    /// The yaw rate the pilot's stick asks for on this tick, °/s ([`StickRate`]; not written
    /// to the CSV): what the yaw metric compares the airframe's rate with.
    pub yaw_rate_cmd_dps: f64,
    pub motors: [u16; 4],
    pub alt_m: f64,
    pub battery_v: f64,
    pub thr_us: f64,
    pub calibrated: bool,
    pub calibrating: bool,
    pub calibration_restarts: u16,
}

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

/// The simulated pilot on the throttle stick: knows roughly where hover is and holds a height.
#[derive(Clone, Debug, Default)]
struct Pilot {
    integral: f64,
}

impl Pilot {
    /// Throttle pulse (µs) to hold `alt_m`, from what a pilot sees (height, climb rate, tilt).
    fn throttle_us(&mut self, alt_target_m: f64, plant: &Plant, cfg: &Config, dt_s: f64) -> f64 {
        let p = &plant.params;
        let s = &plant.state;
        let alt_err = alt_target_m - s.pos_earth_m[2];
        let vz_wanted = (1.2 * alt_err).clamp(-0.4, 0.6);
        let vz_err = vz_wanted - s.vel_earth_m_s[2];
        if !s.on_ground {
            self.integral = (self.integral + 0.3 * alt_err * dt_s).clamp(-0.2, 0.2);
        }
        let factor = (1.0 + 0.6 * vz_err + self.integral).clamp(0.5, 1.5);
        let up = plant::quat_rotate(s.quat, [0.0, 0.0, 1.0])[2].max(0.5);
        let frac = p.hover_fraction(s.battery_v) * factor / up;
        let ccr = p.duty_for_fraction(frac) * p.pwm_full_scale_counts;
        let m = &cfg.mixer;
        let g_thr = if m.throttle_slope > 0.0 { (ccr - f64::from(m.throttle_offset)) / f64::from(m.throttle_slope) } else { 0.0 };
        // Never below MIN_THR + margin: below it the core cuts the motors (a pilot flying
        // knows not to pull the stick to the bottom).
        let g_thr = g_thr.max(f64::from(cfg.rc.min_throttle.get()) + 40.0);
        (f64::from(cfg.rc.input_for(fcu_core::rc::Function::Throttle).min_counts) + g_thr) / 4.0
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
    /// What the computer reports about itself now.
    fn view(&self) -> ComputerView;
}

/// The flight core in this process, one [`crate::harness::tick`] per step.
pub struct InProcess {
    fc: FlightController,
    decoder: fcu_core::rc::EdgeDecoder,
}

impl InProcess {
    pub fn new(cfg: Config) -> Result<InProcess, SimError> {
        let fc = FlightController::new(cfg).map_err(|e| SimError::Config(e.to_string()))?;
        let decoder = fc.edge_decoder();
        Ok(InProcess { fc, decoder })
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
        }
    }
}

/// Fly `scenario` with `profile`'s flight core in this process. Deterministic for a given seed.
pub fn run(scenario: &Scenario, profile: Profile, opts: &RunOptions) -> Result<FlightLog, SimError> {
    run_streaming(&mut InProcess::new(profile.config())?, scenario, profile, opts, &mut |_| Ok(()))
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
    let cfg = profile.config();
    let mut params = if opts.plant_spread > 0.0 { PlantParams::randomized(opts.seed, opts.plant_spread) } else { PlantParams::default() };
    for (s, w) in params.motor_thrust_scale.iter_mut().zip(scenario.motor_thrust_scale) {
        *s *= w;
    }
    let mut plant = Plant::new(params.clone());
    let mut imu = ImuModel::new(ImuModelParams::default(), opts.seed);
    let mut radio = RadioModel::new(scenario.radio.clone(), opts.seed);
    let mut air = Air::new(scenario.turbulence, opts.seed);
    let mut pilot = Pilot::default();
    let mut stick = StickRate::new(&cfg);

    let tick_hz = computer.tick_hz();
    let tick_s = 1.0 / tick_hz;
    let substeps = opts.substeps.clamp(1, 100);
    let sub_s = tick_s / f64::from(substeps);
    let duration_s = opts.duration_s.unwrap_or(scenario.duration_s).max(0.0);
    let n_ticks = (duration_s * tick_hz).round() as u64;
    let vibration = Vibration { amplitude_g_at_full_speed: params.vibration_accel_g, full_speed_hz: params.motor_full_speed_hz };

    // Grown as the flight goes, never sized from the duration up front.
    let mut rows = Vec::new();
    // Compare values on their way to the plant with `extra_delay_ticks` (motors off before).
    let mut late: std::collections::VecDeque<[u16; 4]> = std::collections::VecDeque::new();
    let mut edges: Vec<TimedEdge> = Vec::with_capacity(32);
    let mut last_thr_us = scenario::THR_LOW_US;
    let started = Instant::now();
    let mut next_progress = Duration::from_secs(2);

    for k in 0..n_ticks {
        let t0 = k as f64 * tick_s;
        let t1 = t0 + tick_s;

        // 1. Radio: the transmitter frame uses the pilot's sticks at the frame's start.
        edges.clear();
        radio.advance(
            t1,
            |tf| {
                let row = scenario.timeline.at(tf);
                let thr_us = match row.thr {
                    Throttle::Us(u) => u,
                    Throttle::HoldAltitude { alt_m } => pilot.throttle_us(alt_m, &plant, &cfg, 0.02),
                };
                last_thr_us = thr_us;
                TxFrame { width_us: [row.ail_us, row.ele_us, thr_us, row.rud_us], link: row.link }
            },
            &mut edges,
        );

        let yaw_rate_cmd_dps = stick.yaw_rate_dps(edges.iter().map(|e| e.edge));

        // 2. Plant and sensor over the tick, motors held.
        for j in 0..substeps {
            let t = t0 + f64::from(j) * sub_s;
            match scenario.hand.filter(|h| t >= h.start_s && t < h.end_s) {
                Some(h) => {
                    let ph = std::f64::consts::TAU * h.freq_hz * (t - h.start_s);
                    plant.carry(sub_s, [h.peak_rate_rad_s * ph.sin(), 0.5 * h.peak_rate_rad_s * ph.cos(), 0.0]);
                }
                None => {
                    let mut dist = air.disturbance();
                    for g in &scenario.gusts {
                        if t >= g.start_s && t < g.start_s + g.duration_s {
                            for i in 0..3 {
                                dist.wind_earth_m_s[i] += g.push.wind_earth_m_s[i];
                                dist.force_earth_n[i] += g.push.force_earth_n[i];
                                dist.torque_body_nm[i] += g.push.torque_body_nm[i];
                            }
                        }
                    }
                    plant.step(sub_s, &dist);
                }
            }
            imu.step(sub_s, &plant.kinematics(), vibration);
        }

        air.advance(tick_s);

        // 3. The flight computer's tick: edges and the IMU's words in, compare values out.
        let compare = computer.step(t1, &edges, imu.read(), plant.state.battery_v)?;
        let to_plant = opts.excitation.as_ref().map_or(compare, |x| x.add_to(compare, t1));
        if opts.extra_delay_ticks == 0 {
            plant.set_compare(to_plant);
        } else {
            late.push_back(to_plant);
            while late.len() > opts.extra_delay_ticks as usize {
                plant.set_compare(late.pop_front().unwrap_or(to_plant));
            }
        }

        let v = computer.view();
        let (pitch, roll, yaw) = plant.euler_rad();
        let row = scenario.timeline.at(t1);
        let logged = LogRow {
            t_s: t1,
            state: v.state,
            armed: v.armed,
            link_tx: row.link,
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
            yaw_rate_cmd_dps,
            motors: compare,
            alt_m: plant.state.pos_earth_m[2],
            battery_v: plant.state.battery_v,
            thr_us: last_thr_us,
            calibrated: v.calibrated,
            calibrating: v.calibrating,
            calibration_restarts: v.calibration_restarts,
        };
        on_row(&logged).map_err(SimError::Output)?;
        rows.push(logged);

        if opts.progress && started.elapsed() >= next_progress {
            next_progress += Duration::from_secs(1);
            eprint!("\r{} ({}): {:.1} / {:.1} s simulated", scenario.name, profile.name(), t1, duration_s);
            if k + 1 == n_ticks {
                eprintln!();
            }
        }
    }
    if opts.progress && started.elapsed() >= Duration::from_secs(2) {
        eprintln!("\r{} ({}): {:.1} s simulated in {:.1} s", scenario.name, profile.name(), duration_s, started.elapsed().as_secs_f64());
    }

    Ok(FlightLog { scenario: scenario.name.clone(), profile, seed: opts.seed, tick_hz, plant: params, rows })
}

/// The header of a flight's CSV, one row per control tick ([`LogRow::write_csv`]).
pub const CSV_HEADER: &str = "t_s,state,armed,link,roll_deg,pitch_deg,yaw_deg,est_roll_deg,est_pitch_deg,roll_target_deg,\
                              pitch_target_deg,yaw_target_deg,yaw_rate_dps,m1,m2,m3,m4,alt_m,battery_v,thr_us\n";

impl LogRow {
    /// This row as one line of the flight's CSV (under [`CSV_HEADER`]).
    pub fn write_csv(&self, w: &mut impl std::io::Write) -> std::io::Result<()> {
        let r = self;
        writeln!(
            w,
            "{:.5},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.2},{},{},{},{},{:.4},{:.3},{:.1}",
            r.t_s,
            r.state.name(),
            u8::from(r.armed),
            u8::from(r.link_tx),
            r.roll_deg,
            r.pitch_deg,
            r.yaw_deg,
            r.est_roll_deg,
            r.est_pitch_deg,
            r.roll_target_deg,
            r.pitch_target_deg,
            r.yaw_target_deg,
            r.yaw_rate_dps,
            r.motors[0],
            r.motors[1],
            r.motors[2],
            r.motors[3],
            r.alt_m,
            r.battery_v,
            r.thr_us
        )
    }
}

impl FlightLog {
    /// The whole flight as CSV text (what `fcu-sim fly` streams to `flight.csv`).
    pub fn to_csv(&self) -> String {
        let mut bytes = CSV_HEADER.as_bytes().to_vec();
        for r in &self.rows {
            // Writing to a Vec cannot fail.
            let _ = r.write_csv(&mut bytes);
        }
        String::from_utf8_lossy(&bytes).into_owned()
    }
}

/// The scenario's turbulence as it evolves: first-order Gauss–Markov processes, advanced once
/// per control tick (their correlation time is hundreds of ticks).
struct Air {
    turbulence: Option<scenario::Turbulence>,
    rng: rng::Rng,
    /// Wind east, north; torque about body X, Y (unit-variance states, scaled on use).
    state: [f64; 4],
}

impl Air {
    fn new(turbulence: Option<scenario::Turbulence>, seed: u64) -> Air {
        Air { turbulence, rng: rng::Rng::fork(seed, 0x7475_7262), state: [0.0; 4] }
    }

    fn advance(&mut self, dt_s: f64) {
        if let Some(t) = self.turbulence {
            let a = (-dt_s / t.correlation_s).exp();
            let b = (1.0 - a * a).sqrt();
            for x in &mut self.state {
                *x = a * *x + b * self.rng.gaussian();
            }
        }
    }

    fn disturbance(&self) -> Disturbance {
        let Some(t) = self.turbulence else {
            return Disturbance::default();
        };
        let [we, wn, tx, ty] = self.state;
        Disturbance {
            wind_earth_m_s: [t.wind_rms_m_s * we, t.wind_rms_m_s * wn, 0.0],
            force_earth_n: [0.0; 3],
            torque_body_nm: [t.torque_rms_nm * tx, t.torque_rms_nm * ty, 0.0],
        }
    }
}
