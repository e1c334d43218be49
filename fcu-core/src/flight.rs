//! `FlightController`: the whole per-tick pipeline and the outer step, with no hardware.
//!
//! The firmware and the simulator drive this one type. It has two halves so the firmware can
//! run the outer step in a lower-priority task:
//! - [`ControlTick`] runs every control tick: radio → supervisor → sensor conditioning → rate loop
//!   → mixer → guard. Every fifth tick it hands out an [`OuterJob`] (the block's
//!   accelerometer words and summed gyro, and the sticks).
//! - [`OuterStep`] runs the job: accelerometer conversion → block means → estimator → Euler →
//!   stick targets → angle loop, and returns an [`OuterResult`] that the control tick applies
//!   at its next tick ([`ControlTick::apply_outer`]).
//!
//! From a tick to the supervisor's rules: [`ControlTick::tick`] → `run` (the numbered stages)
//! → `supervise` → [`Supervisor::decide_or_repeat`] (the last decision stands in steady
//! flight with nothing new) → [`Supervisor::decide_inline`] (the steady-flight shortcut) → the
//! state table, `Supervisor::decide_by_table`.
//!
//! The 800 Hz half is written for a budget of 600 Cortex-M4 instructions (`scripts/bench-m4`):
//! work that only the outer step needs is left to it, what the configuration settles is
//! decided at construction, and steady flight takes shortcuts that are tested equal to the
//! general path.
//!
//! The simulator and the replay run the outer step inline with
//! [`FlightController::run_outer`], right after the tick that made the job.

use crate::ahrs::{Estimator, MDPS_TO_RAD_S};
use crate::config::{Config, ConfigError};
use crate::control::{AngleLoop, BatteryFilter, ControlConfig, RateLoop, Saturation, YawRateShaper};
use crate::filter::{accumulate, block_mean, BiquadBank, BLOCK};
use crate::imu::{CalibrationPhase, Calibrator, Decoder, HealthMonitor, Offsets, RawImu, SensorFault, MAX_MISSING_SAMPLES};
use crate::math::{quat_to_tilt_with, tilt_angle_rad, Quat, Tilt};
use crate::mixer::{CompareRange, MixerConfig};
use crate::rc::{EdgeDecoder, PulseBatch, RadioState, RcConfig, Receiver, StickCounts, Sticks, CHANNELS};
use crate::supervisor::{Blockers, Decision, FlightState, Inputs, Supervisor, SupervisorConfig};

/// What one control tick produces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickOutput {
    /// TIM4 CCR1..CCR4, always inside the mixer's compare range.
    pub compare: [u16; 4],
    /// Set every fifth tick: run the outer step on it.
    pub outer_job: Option<OuterJob>,
}

/// What the outer step needs of the last five ticks: the accelerometer words and the summed
/// gyro, and what the sticks said.
///
/// The tick stores the accelerometer's raw words and the outer step converts them (mount,
/// sensitivity, offsets: the tick's integer arithmetic, done at 160 Hz); the gyro arrives as
/// the sum its block mean is made of, accumulated in slot order (bit for bit the reference's
/// sum of five stored slots). Why: docs/performance.md, «accel words, not values».
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OuterJob {
    /// Accelerometer words, sensor axes, of the slots `first_raw_slot..`.
    pub accel_words: AccelWords,
    /// The offsets in force for those words.
    pub accel_offsets: Offsets,
    /// The slots before `first_raw_slot`, converted and corrected with the offsets they were
    /// taken under and summed (only a block that spans the end of a calibration has any).
    pub accel_sum_before_mg: [f32; 3],
    pub first_raw_slot: u8,
    /// Low-passed gyro summed over the block, mdps, body axes.
    pub gyro_sum_mdps: [f32; 3],
    /// The sticks in force (the failsafe's level sticks while it holds).
    pub sticks: Sticks,
    pub throttle_low: bool,
    /// The yaw estimate at the end of the tick, rad.
    pub yaw_est_rad: f32,
    /// The throttle was low on some tick since the last job: the yaw target restarts at 0.
    pub yaw_target_reset: bool,
}

/// The accelerometer words of a block, one per slot, aligned to 4 bytes (docs/performance.md,
/// «aligned words»).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, align(4))]
pub struct AccelWords(pub [[i16; 3]; BLOCK]);

impl OuterJob {
    /// The block's summed accelerometer, corrected mg, body axes.
    pub fn accel_sum_mg(&self, decoder: &Decoder) -> [f32; 3] {
        let mut sum = self.accel_sum_before_mg;
        let raw = self.accel_words.0.get(usize::from(self.first_raw_slot)..).unwrap_or(&[]);
        accumulate_accel_mg(&mut sum, raw, decoder, &self.accel_offsets);
        sum
    }
}

/// Add accelerometer words to a block sum, each converted and corrected as the tick would
/// have done it, in slot order.
fn accumulate_accel_mg(sum: &mut [f32; 3], words: &[[i16; 3]], decoder: &Decoder, offsets: &Offsets) {
    for w in words {
        accumulate(sum, offsets.accel(decoder.accel_mg(*w)).map(|v| v as f32));
    }
}

/// The outer step's result, applied by the inner half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OuterResult {
    pub quat: Quat,
    pub tilt: Tilt,
    /// Pitch, roll and (accumulated) yaw targets, rad.
    pub target_rad: [f32; 3],
    /// Rate demands for the inner loop, rad/s (`s1`).
    pub rate_demand_rad_s: [f32; 3],
    /// The battery compensation's thrust gain (1 without it; see
    /// [`BatteryCompensation`](crate::control::BatteryCompensation)): the throttle map's.
    pub thrust_gain: f32,
    /// The rate loop's gain: the thrust gain times the thrust curve's factor at the throttle
    /// flown (see [`ThrustCurve`](crate::control::ThrustCurve); the thrust gain without one).
    pub rate_gain: f32,
}

/// The radio state given directly (golden replay): the reference's `rc_connection_flag`,
/// `rc_enable_motor` and `rc_cal_flag` instead of capture edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ForcedRadio {
    pub width_counts: [u16; CHANNELS],
    pub link: bool,
    pub armed: bool,
    pub cal_request: bool,
}

/// What telemetry, LEDs and logs need to know.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Status {
    pub state: FlightState,
    pub blockers: Blockers,
    pub link: bool,
    /// Sticks as received.
    pub sticks: Sticks,
    pub calibration: CalibrationPhase,
    /// A calibration has passed since power-on (arming needs one).
    pub calibrated: bool,
    pub fault: Option<SensorFault>,
    pub quat: Quat,
    pub tilt: Tilt,
    pub target_rad: [f32; 3],
    pub yaw_est_rad: f32,
    pub rate_demand_rad_s: [f32; 3],
    /// Motor commands before the compare clamp (the reference prints motor 1's).
    pub motor_command: [f32; 4],
    pub compare: [u16; 4],
    /// The battery compensation's thrust gain in force (1 without it).
    pub thrust_gain: f32,
    /// The yaw rate the stick asks for, rad/s (0 with the throttle low): what the pilot
    /// commands, and what the simulator's yaw metric holds the airframe to. Without D16 the
    /// heading target moves at this rate and the yaw feedforward (D13) passes it on; with D16
    /// both follow its shaped version.
    pub yaw_rate_target_rad_s: f32,
}

/// The per-tick half.
#[derive(Clone, Debug)]
pub struct ControlTick {
    /// The configuration, except that its rate loop and throttle map are the ones in force:
    /// the rate loop scaled by `outer_result.rate_gain` (battery and thrust curve), the throttle
    /// map by `outer_result.thrust_gain` (battery), each rescaled only when its gain changes
    /// ([`ControlTick::apply_outer`]; docs/performance.md, «scaled in place»).
    cfg: Config,
    /// What the configuration settles, worked out once at construction.
    derived: Derived,
    receiver: Receiver,
    supervisor: Supervisor,
    /// The last decision and what the tick derives from it, written only by
    /// [`InForce::decided`], so the three cannot drift apart.
    in_force: InForce,
    calibrator: Calibrator,
    cal_pending: bool,
    offsets: Offsets,
    /// `None` when the configuration has no health checks (the reference).
    health: Option<HealthMonitor>,
    fault: Option<SensorFault>,
    /// The last reading the pipeline ran on (`None` before the first).
    last_raw: Option<RawImu>,
    missing_samples: u32,
    gyro_lpf: BiquadBank<3>,
    /// Samples of the current block written so far.
    block_len: usize,
    accel_words: AccelWords,
    accel_sum_before_mg: [f32; 3],
    first_raw_slot: u8,
    gyro_sum_mdps: [f32; 3],
    yaw_est_rad: f32,
    /// Tilt from level of the latest estimate, rad: computed once per outer result, not per tick.
    tilt_rad: f32,
    yaw_target_rad: f32,
    yaw_target_reset: bool,
    rate_loop: RateLoop,
    saturation: Saturation,
    outer_result: OuterResult,
    motor_command: [f32; 4],
    compare: [u16; 4],
}

/// The supervisor's last decision and what follows from it and the sticks, kept until the
/// supervisor decides again (on a repeat, [`Supervisor::decide_or_repeat`], it stands).
#[derive(Clone, Copy, Debug)]
struct InForce {
    decision: Decision,
    /// The sticks the pipeline flies with: the radio's, or the failsafe's while it holds.
    sticks: Sticks,
    /// Whether their throttle is low (motors stopped, integrators and yaw reset).
    throttle_low: bool,
}

impl InForce {
    /// A new decision, and what follows from it and the radio's sticks: the one writer of all
    /// three. (Written in place: building a new value and moving it in cost 12 instructions
    /// on every tick the table runs; docs/performance.md, «in place».)
    #[inline(always)]
    fn decided(&mut self, decision: Decision, radio_sticks: Sticks, rc: &RcConfig) {
        self.decision = decision;
        self.sticks = decision.failsafe_throttle.map_or(radio_sticks, failsafe_sticks);
        self.throttle_low = rc.throttle_low(&self.sticks);
    }
}

/// What [`ControlTick`] works out from its configuration once, at construction.
#[derive(Clone, Debug)]
struct Derived {
    /// Sensor words to body axes and physical units (mount, sensitivities).
    decoder: Decoder,
    /// The compare clamp as integers.
    compare_range: CompareRange,
    /// `cfg.timing.tick_dt_s` rounded to f32 once (the f64 → f32 conversion is a library call).
    tick_dt_s: f32,
}

impl Derived {
    fn new(cfg: &Config) -> Derived {
        Derived { decoder: Decoder::new(&cfg.imu), compare_range: cfg.mixer.compare_range(), tick_dt_s: cfg.timing.tick_dt_s as f32 }
    }
}

/// The outer-step half.
#[derive(Clone, Debug)]
pub struct OuterStep {
    decoder: Decoder,
    estimator: Estimator,
    rc: RcConfig,
    control: ControlConfig,
    reference_arithmetic: bool,
    angle_loop: AngleLoop,
    yaw_target_rad: f32,
    /// Outer steps per second (the yaw stick's step per outer step, times this, is its rate).
    outer_hz: f32,
    battery: BatteryFilter,
    /// The throttle map (unscaled), for the thrust curve's operating point (D17).
    mixer: MixerConfig,
    /// The stick's yaw rate shaped for the airframe (`None` without D16).
    yaw_shaper: Option<YawRateShaper>,
}

/// The whole flight controller: both halves, for callers that run the outer step inline.
#[derive(Clone, Debug)]
pub struct FlightController {
    control_tick: ControlTick,
    outer_step: OuterStep,
}

impl FlightController {
    /// Build from a configuration; an invalid one is refused with the field that is wrong.
    pub fn new(cfg: Config) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(FlightController { control_tick: ControlTick::new(cfg), outer_step: OuterStep::new(&cfg) })
    }

    pub fn config(&self) -> &Config {
        self.control_tick.config()
    }

    /// The edge decoder the capture interrupt should feed for this configuration.
    pub fn edge_decoder(&self) -> EdgeDecoder {
        EdgeDecoder::new(self.control_tick.cfg.rc.pulses)
    }

    /// One control tick from a sensor reading and the pulses of that tick.
    pub fn tick(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        self.control_tick.tick(imu, pulses)
    }

    /// One control tick with the radio state given directly (golden replay).
    pub fn tick_forced(&mut self, imu: RawImu, radio: &ForcedRadio) -> TickOutput {
        self.control_tick.tick_forced(imu, radio)
    }

    /// One control tick when the sensor read failed (see [`ControlTick::tick_without_sample`]).
    pub fn tick_without_sample(&mut self, pulses: &PulseBatch) -> TickOutput {
        self.control_tick.tick_without_sample(pulses)
    }

    /// The latest battery reading, mV (the battery compensation's input).
    pub fn set_battery_mv(&mut self, battery_mv: u32) {
        self.outer_step.set_battery_mv(battery_mv);
    }

    /// Run an outer step now and apply its result.
    pub fn run_outer(&mut self, job: &OuterJob) {
        let r = self.outer_step.run(job);
        self.control_tick.apply_outer(&r);
    }

    /// One tick followed by its outer step when one is due (simulator, replay).
    pub fn tick_and_run_outer(&mut self, imu: RawImu, pulses: &PulseBatch) -> [u16; 4] {
        let out = self.tick(imu, pulses);
        if let Some(job) = out.outer_job {
            self.run_outer(&job);
        }
        self.control_tick.compare
    }

    pub fn status(&self) -> Status {
        self.control_tick.status()
    }

    /// Tests only (feature `test-switches`): with `true`, the supervisor runs its full table
    /// every tick, without the steady-flight shortcut or the repeat of the last decision.
    #[cfg(feature = "test-switches")]
    pub fn set_table_only(&mut self, table_only: bool) {
        self.control_tick.supervisor.set_table_only(table_only);
    }

    /// Split for a firmware that runs the outer step in its own task.
    pub fn into_parts(self) -> (ControlTick, OuterStep) {
        (self.control_tick, self.outer_step)
    }
}

/// Whether the calibration let the tick go on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Calibration {
    TickGoesOn,
    /// Settling or averaging at start-up: motors off, nothing else this tick.
    StopsTheTick,
}

/// The sticks the failsafe flies with: centred (level, no yaw) and the held throttle.
fn failsafe_sticks(throttle: StickCounts) -> Sticks {
    Sticks { thr: throttle, ..Sticks::default() }
}

impl ControlTick {
    fn new(cfg: Config) -> Self {
        ControlTick {
            cfg,
            derived: Derived::new(&cfg),
            receiver: Receiver::new(),
            supervisor: Supervisor::new(),
            in_force: InForce {
                decision: Decision {
                    state: FlightState::Calibrating,
                    motors_enabled: false,
                    failsafe_throttle: None,
                    request_calibration: false,
                    blockers: Blockers::default(),
                },
                sticks: Sticks::default(),
                throttle_low: true,
            },
            calibrator: Calibrator::new(cfg.calibration),
            cal_pending: false,
            offsets: Offsets::UNCALIBRATED,
            health: cfg.health.map(|h| HealthMonitor::new(h, &cfg.imu)),
            fault: None,
            last_raw: None,
            missing_samples: 0,
            gyro_lpf: BiquadBank::new(cfg.gyro_filter),
            block_len: 0,
            accel_words: AccelWords::default(),
            accel_sum_before_mg: [0.0; 3],
            first_raw_slot: 0,
            gyro_sum_mdps: [0.0; 3],
            yaw_est_rad: 0.0,
            tilt_rad: 0.0,
            yaw_target_rad: 0.0,
            yaw_target_reset: false,
            rate_loop: RateLoop::default(),
            saturation: Saturation::NONE,
            outer_result: OuterResult {
                quat: Quat::IDENTITY,
                tilt: Tilt::default(),
                target_rad: [0.0; 3],
                rate_demand_rad_s: [0.0; 3],
                thrust_gain: 1.0,
                rate_gain: 1.0,
            },

            motor_command: [0.0; 4],
            compare: [0; 4],
        }
    }

    /// The configuration in force: its rate loop and throttle map scaled by the gains of the
    /// last outer result (battery, thrust curve).
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// One control tick: the radio from capture pulses.
    pub fn tick(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        self.missing_samples = 0;
        self.tick_with(imu, pulses)
    }

    /// One control tick when the sensor read failed: the last sample is held for up to
    /// [`MAX_MISSING_SAMPLES`] ticks (a single bus glitch must not drop the drone); after that
    /// the sensor is faulty, the motors stop and the fault latches, as for any sensor fault.
    pub fn tick_without_sample(&mut self, pulses: &PulseBatch) -> TickOutput {
        self.missing_samples = self.missing_samples.saturating_add(1);
        if self.missing_samples > MAX_MISSING_SAMPLES {
            self.fault.get_or_insert(SensorFault::NoData);
        }
        self.tick_with(self.last_raw.unwrap_or_default(), pulses)
    }

    fn tick_with(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        let rc = &self.cfg.rc;
        let mut cal_gesture = false;
        match self.cfg.supervisor {
            SupervisorConfig::Reference => {
                let supervisor = &mut self.supervisor;
                // The reference evaluates its gestures after every single-channel update.
                self.receiver.update(rc, pulses, |s| cal_gesture |= supervisor.reference_gesture(rc.gesture(s)))
            }
            SupervisorConfig::Safe(_) => self.receiver.update(rc, pulses, |_| {}),
        };
        self.run(imu, None, cal_gesture)
    }

    /// One control tick with the radio state given directly (golden replay).
    pub fn tick_forced(&mut self, imu: RawImu, forced: &ForcedRadio) -> TickOutput {
        self.receiver.force(&self.cfg.rc, forced.width_counts, forced.link);
        self.run(imu, Some(forced.armed), forced.cal_request)
    }

    /// Take in an outer step's result (at the start of the next tick in the firmware).
    pub fn apply_outer(&mut self, r: &OuterResult) {
        // Rescaled from what is in force: the ratio of the new gain to the old. Exact enough:
        // the gains move in steps of 1/512 (battery, `BatteryFilter`) and 1/256 (thrust curve,
        // `ThrustCurve::gain_at`), only when the battery or the throttle moves that far, and
        // each rescale rounds by 2^-24 (a thousand of them move a gain by less than 1e-4).
        if r.rate_gain != self.outer_result.rate_gain {
            self.cfg.control = self.cfg.control.scaled_rate_loop(r.rate_gain / self.outer_result.rate_gain);
        }
        if r.thrust_gain != self.outer_result.thrust_gain {
            self.cfg.mixer = self.cfg.mixer.scaled_throttle(r.thrust_gain / self.outer_result.thrust_gain);
        }
        self.outer_result = *r;
        // Only the safe supervisor's arming check reads it («tilt once per outer result»).
        if let SupervisorConfig::Safe(_) = self.cfg.supervisor {
            self.tilt_rad = tilt_angle_rad(r.quat);
        }
        self.yaw_target_rad = r.target_rad[2];
    }

    /// The pipeline, top to bottom. Every decision that touches a motor is in this function.
    fn run(&mut self, imu: RawImu, armed_override: Option<bool>, cal_request: bool) -> TickOutput {
        // `self.cfg.…` read in place, never copied (docs/performance.md, «no config copy»).
        let radio = self.receiver.state();

        // 1. Supervise: sensor health, then the state machine decides whether motors may run.
        let repeated = self.last_raw == Some(imu);
        self.last_raw = Some(imu);
        self.check_health(imu, repeated);
        // Steady flight with nothing new from the radio or the sensor repeats the last decision
        // and what follows from it (the rule is `Supervisor::decide_or_repeat`'s).
        if let Some(decision) = self.supervise(&radio, armed_override) {
            self.cal_pending |= decision.request_calibration;
            self.in_force.decided(decision, radio.sticks, &self.cfg.rc);
        }
        self.cal_pending |= cal_request;
        let (sticks, throttle_low) = (self.in_force.sticks, self.in_force.throttle_low);

        // 2. Calibration: start-up (nothing else runs until the first offsets exist) and
        // requested. Idle with nothing asked, it has nothing to do.
        if (self.cal_pending || !self.calibrator.is_idle()) && self.calibrate(imu) == Calibration::StopsTheTick {
            return self.motors_off();
        }

        // 3. Condition the sensors: offsets, FIFO, gyro low-pass.
        let gyro_mdps = self.offsets.gyro(self.derived.decoder.gyro_mdps(imu.gyro));
        let mut gyro_f = self.gyro_lpf.update(gyro_mdps.map(|g| g as f32));
        if !(gyro_f[0].is_finite() && gyro_f[1].is_finite() && gyro_f[2].is_finite()) {
            // Integer inputs cannot make this happen; if it ever did, restart the filters and
            // (in the product) treat it as the sensor fault it would be.
            self.gyro_lpf.reset_to(0.0);
            gyro_f = [0.0; 3];
            if self.cfg.health.is_some() {
                self.fault.get_or_insert(SensorFault::NotFinite);
            }
        }
        if let Some(words) = self.accel_words.0.get_mut(self.block_len) {
            *words = imu.accel;
        }
        accumulate(&mut self.gyro_sum_mdps, gyro_f);
        self.block_len += 1;
        let job_due = self.block_len >= BLOCK;
        let gyro_rad_s =
            gyro_f.map(|g| if self.cfg.reference_arithmetic { (f64::from(g) * MDPS_TO_RAD_S) as f32 } else { g * (MDPS_TO_RAD_S as f32) });

        // 4. Yaw: gyro-integrated heading, reset with the target while the throttle is low.
        self.yaw_est_rad = if self.cfg.reference_arithmetic {
            (f64::from(self.yaw_est_rad) + f64::from(gyro_rad_s[2]) * self.cfg.timing.tick_dt_s) as f32
        } else {
            self.yaw_est_rad + gyro_rad_s[2] * self.derived.tick_dt_s
        };
        if !self.yaw_est_rad.is_finite() {
            self.yaw_est_rad = 0.0;
        }
        if throttle_low {
            self.yaw_target_rad = 0.0;
            self.yaw_est_rad = 0.0;
            self.yaw_target_reset = true;
        }

        // 5. Rate loop and mixer, only while the supervisor lets the motors run.
        if self.in_force.decision.motors_enabled {
            let rate_commands =
                self.rate_loop.commands(&self.cfg.control, self.outer_result.rate_demand_rad_s, gyro_rad_s, throttle_low, self.saturation);
            let (cmd, sat) = self.cfg.mixer.mix(self.cfg.mixer.throttle_counts(sticks.thr), rate_commands);
            self.motor_command = cmd;
            self.saturation = sat;
        } else {
            self.motor_command = [0.0; 4];
        }
        if throttle_low {
            // The reference's only throttle cut: the motors stop with the stick at the bottom.
            self.motor_command = [0.0; 4];
        }

        // 6. Guard, last and unconditional. The one other writer of compare values is
        // `motors_off`, for a tick that a calibration in progress ends early: off values too.
        let range = self.derived.compare_range;
        self.compare = self.motor_command.map(|c| range.to_compare(c));
        if !self.in_force.decision.motors_enabled || self.fault.is_some() {
            self.compare = [self.cfg.mixer.off_compare(); 4];
        }

        // One output per branch (docs/performance.md, «one output per branch»).
        let yaw_target_reset = self.yaw_target_reset;
        if job_due {
            let job = OuterJob {
                accel_words: self.accel_words,
                accel_offsets: self.offsets,
                accel_sum_before_mg: self.accel_sum_before_mg,
                first_raw_slot: self.first_raw_slot,
                gyro_sum_mdps: self.gyro_sum_mdps,
                sticks,
                throttle_low,
                yaw_est_rad: self.yaw_est_rad,
                yaw_target_reset,
            };
            self.block_len = 0;
            self.accel_sum_before_mg = [0.0; 3];
            self.first_raw_slot = 0;
            self.gyro_sum_mdps = [0.0; 3];
            self.yaw_target_reset = false;
            TickOutput { compare: self.compare, outer_job: Some(job) }
        } else {
            TickOutput { compare: self.compare, outer_job: None }
        }
    }

    /// Steps 2 and 3 of the calibration: the start-up settling and average (the tick stops
    /// there until the first offsets exist) and a requested average. Out of line: the 800 Hz
    /// path only reaches it while a calibration is asked for or running.
    #[inline(never)]
    fn calibrate(&mut self, imu: RawImu) -> Calibration {
        if self.calibrator.in_startup() {
            if self.calibrator.settle() {
                return Calibration::StopsTheTick;
            }
            match self.calibrator.feed(self.derived.decoder.to_body(imu)) {
                Some(o) => self.set_offsets(o), // and this tick goes on, as the reference's does
                None => return Calibration::StopsTheTick,
            }
        }
        if self.cal_pending && !self.calibrator.is_averaging() {
            self.calibrator.request();
        }
        self.cal_pending = false;
        if self.calibrator.is_averaging() {
            if let Some(o) = self.calibrator.feed(self.derived.decoder.to_body(imu)) {
                self.set_offsets(o);
            }
        }
        Calibration::TickGoesOn
    }

    /// New offsets from a calibration. The samples of the current block taken before it keep
    /// the offsets they were taken under: they are converted now and join the sum before.
    fn set_offsets(&mut self, o: Offsets) {
        let taken = self.accel_words.0.get(usize::from(self.first_raw_slot)..self.block_len).unwrap_or(&[]);
        accumulate_accel_mg(&mut self.accel_sum_before_mg, taken, &self.derived.decoder, &self.offsets);
        // `block_len` < BLOCK here (a job resets it), so the cast is exact.
        self.first_raw_slot = self.block_len.min(BLOCK) as u8;
        self.offsets = o;
    }

    fn check_health(&mut self, raw: RawImu, repeated: bool) {
        if let Some(h) = &mut self.health {
            if let Some(f) = h.check(raw, repeated) {
                self.fault.get_or_insert(f);
            }
        }
    }

    /// This tick's decision, or `None` when the last one stands.
    #[inline(always)]
    fn supervise(&mut self, radio: &RadioState, armed_override: Option<bool>) -> Option<Decision> {
        let (cfg, calibrator, receiver, fault, tilt_rad) = (&self.cfg, &self.calibrator, &self.receiver, self.fault, self.tilt_rad);
        // Run only when the last decision cannot simply stand.
        let decide = |supervisor: &mut Supervisor| {
            let calibrating = calibrator.in_startup() || calibrator.is_averaging();
            match cfg.supervisor {
                SupervisorConfig::Reference => supervisor.decide_reference(radio.link, armed_override, calibrating),
                SupervisorConfig::Safe(ref safety) => {
                    let sticks = radio.sticks;
                    let inputs = Inputs {
                        link: radio.link,
                        // Only read without a good link.
                        silence_ticks: if radio.link { 0 } else { receiver.silence_ticks(&cfg.rc) },
                        sticks,
                        gesture: radio.gesture,
                        throttle_low: cfg.rc.throttle_low(&sticks),
                        calibrated: calibrator.has_passed(),
                        calibrating,
                        sensor_fault: fault,
                        tilt_rad,
                    };
                    supervisor.decide_inline(safety, inputs)
                }
            }
        };
        self.supervisor.decide_or_repeat(receiver.changed(), fault, decide)
    }

    fn motors_off(&mut self) -> TickOutput {
        self.motor_command = [0.0; 4];
        self.compare = [self.cfg.mixer.off_compare(); 4];
        TickOutput { compare: self.compare, outer_job: None }
    }

    pub fn status(&self) -> Status {
        let radio = self.receiver.state();
        Status {
            state: self.in_force.decision.state,
            blockers: self.in_force.decision.blockers,
            link: radio.link,
            sticks: radio.sticks,
            calibration: self.calibrator.phase(),
            calibrated: self.calibrator.has_passed(),
            fault: self.fault,
            quat: self.outer_result.quat,
            tilt: self.outer_result.tilt,
            target_rad: [self.outer_result.target_rad[0], self.outer_result.target_rad[1], self.yaw_target_rad],
            yaw_est_rad: self.yaw_est_rad,
            rate_demand_rad_s: self.outer_result.rate_demand_rad_s,
            motor_command: self.motor_command,
            compare: self.compare,
            thrust_gain: self.outer_result.thrust_gain,
            yaw_rate_target_rad_s: self.cfg.rc.yaw_rate_rad_s(&self.in_force.sticks, self.cfg.timing.outer_hz()),
        }
    }
}

impl OuterStep {
    fn new(cfg: &Config) -> Self {
        OuterStep {
            decoder: Decoder::new(&cfg.imu),
            estimator: Estimator::new(cfg.estimator),
            rc: cfg.rc,
            control: cfg.control,
            reference_arithmetic: cfg.reference_arithmetic,
            angle_loop: AngleLoop::default(),
            yaw_target_rad: 0.0,
            outer_hz: cfg.timing.outer_hz(),
            battery: BatteryFilter::default(),
            mixer: cfg.mixer,
            yaw_shaper: cfg.control.yaw_shaping.map(|y| YawRateShaper::new(&y, cfg.timing.outer_dt_s())),
        }
    }

    /// The outer step: block average → estimator → Euler → stick targets → angle loop.
    pub fn run(&mut self, job: &OuterJob) -> OuterResult {
        let accel = block_mean(job.accel_sum_mg(&self.decoder), self.reference_arithmetic);
        let gyro = block_mean(job.gyro_sum_mdps, self.reference_arithmetic);
        self.estimator.update(accel, gyro, job.throttle_low);
        let quat = self.estimator.quat();
        let tilt = quat_to_tilt_with(quat, self.reference_arithmetic);

        let (pitch_target, roll_target) = self.rc.tilt_targets(&job.sticks);
        if job.yaw_target_reset {
            self.yaw_target_rad = 0.0;
        }
        let yaw_step = self.rc.yaw_step(&job.sticks);
        // The heading target moves at the stick's rate, or at its shaped rate (D16), which
        // starts again from rest whenever the throttle has been low.
        let shaped = self.yaw_shaper.as_mut().map(|shaper| {
            if job.yaw_target_reset || job.throttle_low {
                shaper.reset();
            }
            // `RcConfig::yaw_rate_rad_s`, from the yaw step already worked out above.
            let stick_rate = if job.throttle_low { 0.0 } else { yaw_step * self.outer_hz };
            shaper.shape(stick_rate)
        });
        match shaped {
            Some(s) => self.yaw_target_rad += s.rate_rad_s / self.outer_hz,
            None if yaw_step != 0.0 => self.yaw_target_rad += yaw_step,
            None => {}
        }
        if job.throttle_low || !self.yaw_target_rad.is_finite() {
            self.yaw_target_rad = 0.0;
        }
        let target_rad = [pitch_target, roll_target, self.yaw_target_rad];
        let estimate = [tilt.pitch_rad, tilt.roll_rad, job.yaw_est_rad];
        let mut rate_demand_rad_s = self.angle_loop.rate_demands(&self.control, target_rad, estimate, job.throttle_low);
        let ff = self.control.yaw_rate_feedforward;
        if !job.throttle_low {
            match shaped {
                // The shaped rate and, ahead of it, what gets the torque its acceleration needs.
                Some(s) => rate_demand_rad_s[2] += ff * s.rate_rad_s + s.lead_rad_s,
                // The heading loop keeps correcting what the rate loop misses; the stick's
                // rate itself goes to the rate loop now, not once a heading error has built up.
                None if ff != 0.0 => rate_demand_rad_s[2] += ff * yaw_step * self.outer_hz,
                None => {}
            }
        }
        let thrust_gain = match self.control.battery {
            Some(b) => self.battery.update(&b, 1.0 / self.outer_hz),
            None => 1.0,
        };
        let rate_gain = match self.control.thrust_curve {
            Some(curve) => {
                // The duty the throttle stick flies at, through the map in force.
                let counts = f32::from(self.mixer.throttle_counts(job.sticks.thr).0) * thrust_gain;
                thrust_gain * curve.gain_at(counts / self.mixer.period_counts())
            }
            None => thrust_gain,
        };
        OuterResult { quat, tilt, target_rad, rate_demand_rad_s, thrust_gain, rate_gain }
    }

    /// The latest battery reading, mV (for the battery compensation; ignored without it).
    pub fn set_battery_mv(&mut self, battery_mv: u32) {
        self.battery.set_reading(battery_mv);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imu::ImuConfig;

    /// A reading whose accelerometer words change every tick.
    fn sample(k: usize) -> RawImu {
        let w = |m: usize, base: i16| base + (k * m % 211) as i16 - 105;
        RawImu { accel: [w(37, 0), w(53, 0), w(71, 8197)], gyro: [1, 2, 3] }
    }

    #[test]
    fn a_block_spanning_new_offsets_keeps_each_sample_under_its_own_offsets() {
        // What the reference does tick by tick: convert, correct with the offsets in force,
        // store, and average the five slots. The job's sum must be that, bit for bit, wherever
        // in the block the offsets change.
        let decoder = Decoder::new(&ImuConfig::REFERENCE);
        let radio = ForcedRadio { width_counts: [6000; 4], link: false, armed: false, cal_request: false };
        for change_at in 0..BLOCK {
            let mut fc = FlightController::new(Config::reference()).unwrap();
            let mut k = 0;
            // Start-up settling and calibration, up to the first job: a block starts next.
            while fc.tick_forced(sample(k), &radio).outer_job.is_none() {
                k += 1;
            }
            k += 1;
            let mut expected = [0.0f32; 3];
            let mut job = None;
            for slot in 0..BLOCK {
                if slot == change_at {
                    fc.control_tick.set_offsets(Offsets { accel_mg: [5, -7, 1020], gyro_mdps: [0; 3] });
                }
                let offsets = fc.control_tick.offsets;
                accumulate(&mut expected, offsets.accel(decoder.accel_mg(sample(k).accel)).map(|v| v as f32));
                job = fc.tick_forced(sample(k), &radio).outer_job;
                k += 1;
            }
            let job = job.expect("a job every five ticks");
            assert_eq!(job.first_raw_slot as usize, change_at);
            assert_eq!(job.accel_sum_mg(&decoder).map(f32::to_bits), expected.map(f32::to_bits), "change at slot {change_at}");
        }
    }
}
