//! `FlightController`: the whole per-tick pipeline and the outer step, with no hardware.
//!
//! The firmware and the simulator drive this one type. It has two halves so the firmware can
//! run the outer step in a lower-priority task:
//! - [`Inner`] runs every control tick: radio → supervisor → sensor conditioning → rate loop
//!   → mixer → guard. Every fifth tick it hands out an [`OuterJob`] (a snapshot of the five
//!   samples and the sticks).
//! - [`Outer`] runs the job: block average → estimator → Euler → stick targets → angle loop,
//!   and returns an [`OuterResult`] that the inner half applies at its next tick.
//!
//! The simulator and the replay run the outer step inline with
//! [`FlightController::run_outer`], right after the tick that made the job.

use crate::ahrs::{Estimator, EstimatorConfig, MDPS_TO_RAD_S};
use crate::config::{Config, ConfigError};
use crate::control::{AngleLoop, ControlConfig, RateLoop, Saturation};
use crate::filter::{block_average, BiquadBank, BLOCK};
use crate::imu::{BodyImu, CalibrationPhase, Calibrator, Decoder, HealthMonitor, Offsets, RawImu, SensorFault, MAX_MISSING_SAMPLES};
use crate::math::{quat_to_tilt_with, tilt_angle_rad, Quat, Tilt};
use crate::rc::{EdgeDecoder, PulseBatch, RadioState, RcConfig, Receiver, Sticks, CHANNELS};
use crate::supervisor::{Blockers, Decision, FlightState, Inputs, Supervisor, SupervisorConfig};

/// What one control tick produces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickOutput {
    /// TIM4 CCR1..CCR4, always inside the mixer's compare range.
    pub compare: [u16; 4],
    /// Set every fifth tick: run the outer step on it.
    pub outer_job: Option<OuterJob>,
}

/// A snapshot for the outer step: the five conditioned samples and what the sticks said.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OuterJob {
    /// Offset-corrected accelerometer, mg, body axes.
    pub accel_mg: [[f32; 3]; BLOCK],
    /// Low-passed gyro, mdps, body axes.
    pub gyro_mdps: [[f32; 3]; BLOCK],
    /// The sticks in force (the failsafe's level sticks while it holds).
    pub sticks: Sticks,
    pub throttle_low: bool,
    /// The yaw estimate at the end of the tick, rad.
    pub yaw_est_rad: f32,
    /// The throttle was low on some tick since the last job: the yaw target restarts at 0.
    pub yaw_target_reset: bool,
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
    pub fault: Option<SensorFault>,
    pub quat: Quat,
    pub tilt: Tilt,
    pub target_rad: [f32; 3],
    pub yaw_est_rad: f32,
    pub rate_demand_rad_s: [f32; 3],
    /// Motor commands before the compare clamp (the reference prints motor 1's).
    pub motor_command: [f32; 4],
    pub compare: [u16; 4],
}

/// The per-tick half.
#[derive(Clone, Debug)]
pub struct Inner {
    cfg: Config,
    decoder: Decoder,
    receiver: Receiver,
    supervisor: Supervisor,
    decision: Decision,
    radio: RadioState,
    calibrator: Calibrator,
    cal_pending: bool,
    offsets: Offsets,
    /// `None` when the configuration has no health checks (the reference).
    health: Option<HealthMonitor>,
    fault: Option<SensorFault>,
    last_raw: RawImu,
    missing_samples: u32,
    gyro_lpf: BiquadBank<3>,
    fifo_k: usize,
    accel_fifo: [[f32; 3]; BLOCK],
    gyro_fifo: [[f32; 3]; BLOCK],
    gyro_rad_s: [f32; 3],
    yaw_est_rad: f32,
    /// Tilt from level of the latest estimate, rad: computed once per outer result, not per tick.
    tilt_rad: f32,
    /// `cfg.timing.tick_dt_s` rounded to f32 once (the f64 → f32 conversion is a library call).
    tick_dt_s: f32,
    yaw_target_rad: f32,
    yaw_target_reset: bool,
    rate_loop: RateLoop,
    saturation: [Saturation; 3],
    outer: OuterResult,
    motor_command: [f32; 4],
    compare: [u16; 4],
}

/// The outer-step half.
#[derive(Clone, Debug)]
pub struct Outer {
    estimator: Estimator,
    rc: RcConfig,
    control: ControlConfig,
    reference_arithmetic: bool,
    angle_loop: AngleLoop,
    yaw_target_rad: f32,
}

/// The whole flight controller: both halves, for callers that run the outer step inline.
#[derive(Clone, Debug)]
pub struct FlightController {
    inner: Inner,
    outer: Outer,
}

impl FlightController {
    /// Build from a configuration; an invalid one is refused with the field that is wrong.
    pub fn new(cfg: Config) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(FlightController { inner: Inner::new(cfg), outer: Outer::new(cfg.estimator, cfg.rc, cfg.control, cfg.reference_arithmetic) })
    }

    pub fn config(&self) -> &Config {
        &self.inner.cfg
    }

    /// The edge decoder the capture interrupt should feed for this configuration.
    pub fn edge_decoder(&self) -> EdgeDecoder {
        EdgeDecoder::new(self.inner.cfg.rc.pulses)
    }

    /// One control tick from a sensor reading and the pulses of that tick.
    pub fn tick(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        self.inner.tick(imu, pulses)
    }

    /// One control tick with the radio state given directly (golden replay).
    pub fn tick_forced(&mut self, imu: RawImu, radio: &ForcedRadio) -> TickOutput {
        self.inner.tick_forced(imu, radio)
    }

    /// One control tick when the sensor read failed (see [`Inner::tick_without_sample`]).
    pub fn tick_without_sample(&mut self, pulses: &PulseBatch) -> TickOutput {
        self.inner.tick_without_sample(pulses)
    }

    /// Run an outer step now and apply its result.
    pub fn run_outer(&mut self, job: &OuterJob) {
        let r = self.outer.step(job);
        self.inner.apply_outer(&r);
    }

    /// One tick followed by its outer step when one is due (simulator, replay).
    pub fn step(&mut self, imu: RawImu, pulses: &PulseBatch) -> [u16; 4] {
        let out = self.tick(imu, pulses);
        if let Some(job) = out.outer_job {
            self.run_outer(&job);
        }
        self.inner.compare
    }

    pub fn status(&self) -> Status {
        self.inner.status()
    }

    /// Split for a firmware that runs the outer step in its own task.
    pub fn into_parts(self) -> (Inner, Outer) {
        (self.inner, self.outer)
    }
}

/// The sticks the failsafe flies with: centred (level, no yaw) and the held throttle.
fn failsafe_sticks(throttle: i16) -> Sticks {
    Sticks { ail: 0, ele: 0, thr: throttle, rud: 0 }
}

impl Inner {
    fn new(cfg: Config) -> Self {
        Inner {
            cfg,
            decoder: Decoder::new(&cfg.imu),
            receiver: Receiver::new(),
            supervisor: Supervisor::new(),
            decision: Decision {
                state: FlightState::Calibrating,
                motors_enabled: false,
                failsafe_throttle: None,
                request_calibration: false,
                blockers: Blockers::default(),
            },
            radio: RadioState::NONE,
            calibrator: Calibrator::new(cfg.calibration),
            cal_pending: false,
            offsets: Offsets::UNCALIBRATED,
            health: cfg.health.map(|h| HealthMonitor::new(h, &cfg.imu)),
            fault: None,
            last_raw: RawImu::default(),
            missing_samples: 0,
            gyro_lpf: BiquadBank::new(cfg.gyro_filter),
            fifo_k: 0,
            accel_fifo: [[0.0; 3]; BLOCK],
            gyro_fifo: [[0.0; 3]; BLOCK],
            gyro_rad_s: [0.0; 3],
            yaw_est_rad: 0.0,
            tilt_rad: 0.0,
            tick_dt_s: cfg.timing.tick_dt_s as f32,
            yaw_target_rad: 0.0,
            yaw_target_reset: false,
            rate_loop: RateLoop::default(),
            saturation: [Saturation::default(); 3],
            outer: OuterResult { quat: Quat::IDENTITY, tilt: Tilt::default(), target_rad: [0.0; 3], rate_demand_rad_s: [0.0; 3] },
            motor_command: [0.0; 4],
            compare: [0; 4],
        }
    }

    /// One control tick: the radio from capture pulses.
    pub fn tick(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        self.missing_samples = 0;
        self.last_raw = imu;
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
        self.tick_with(self.last_raw, pulses)
    }

    fn tick_with(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        let rc = &self.cfg.rc;
        let mut cal_gesture = false;
        let radio = match self.cfg.supervisor {
            SupervisorConfig::Reference => {
                let supervisor = &mut self.supervisor;
                // The reference evaluates its gestures after every single-channel update.
                self.receiver.update(rc, pulses, |s| cal_gesture |= supervisor.reference_gesture(rc.gesture(s)))
            }
            SupervisorConfig::Safe(_) => self.receiver.update(rc, pulses, |_| {}),
        };
        self.run(imu, radio, None, cal_gesture)
    }

    /// One control tick with the radio state given directly (golden replay).
    pub fn tick_forced(&mut self, imu: RawImu, forced: &ForcedRadio) -> TickOutput {
        let radio = self.receiver.force(&self.cfg.rc, forced.width_counts, forced.link);
        self.run(imu, radio, Some(forced.armed), forced.cal_request)
    }

    /// Take in an outer step's result (at the start of the next tick in the firmware).
    pub fn apply_outer(&mut self, r: &OuterResult) {
        self.outer = *r;
        // Only the safe supervisor's arming check reads it (sqrt + acos: ~300 instructions).
        if let SupervisorConfig::Safe(_) = self.cfg.supervisor {
            self.tilt_rad = tilt_angle_rad(r.quat);
        }
        self.yaw_target_rad = r.target_rad[2];
    }

    /// The pipeline, top to bottom. Every decision that touches a motor is in this function.
    fn run(&mut self, imu: RawImu, radio: RadioState, armed_override: Option<bool>, cal_request: bool) -> TickOutput {
        // No `let cfg = self.cfg`: copying the whole Config costs ~350 instructions per tick.
        self.radio = radio;
        let body = self.decoder.to_body(imu);

        // 1. Supervise: sensor health, then the state machine decides whether motors may run.
        self.check_health(imu, &body);
        if cal_request {
            self.cal_pending = true;
        }
        self.decision = self.supervise(armed_override);
        if self.decision.request_calibration {
            self.cal_pending = true;
        }
        let sticks = self.decision.failsafe_throttle.map_or(radio.sticks, failsafe_sticks);
        let throttle_low = self.cfg.rc.throttle_low(&sticks);

        // 2. Start-up calibration: nothing else runs until the first offsets exist.
        if self.calibrator.in_startup() {
            if self.calibrator.settle() {
                return self.motors_off();
            }
            match self.calibrator.feed(body) {
                Some(o) => self.offsets = o, // and this tick goes on, as the reference's does
                None => return self.motors_off(),
            }
        }

        // 3. Condition the sensors: re-calibration, offsets, FIFO, gyro low-pass.
        self.fifo_k += 1;
        if self.cal_pending && !self.calibrator.is_averaging() {
            self.calibrator.request();
        }
        self.cal_pending = false;
        if self.calibrator.is_averaging() {
            if let Some(o) = self.calibrator.feed(body) {
                self.offsets = o;
            }
        }
        let s = self.offsets.apply(body);
        let slot = self.fifo_k.saturating_sub(1).min(BLOCK - 1);
        let mut gyro_f = self.gyro_lpf.update(s.gyro_mdps.map(|g| g as f32));
        if !(gyro_f[0].is_finite() && gyro_f[1].is_finite() && gyro_f[2].is_finite()) {
            // Integer inputs cannot make this happen; if it ever did, restart the filters and
            // (in the product) treat it as the sensor fault it would be.
            self.gyro_lpf.reset_to(0.0);
            gyro_f = [0.0; 3];
            if self.cfg.health.is_some() {
                self.fault.get_or_insert(SensorFault::NotFinite);
            }
        }
        if let (Some(a), Some(g)) = (self.accel_fifo.get_mut(slot), self.gyro_fifo.get_mut(slot)) {
            *a = s.accel_mg.map(|v| v as f32);
            *g = gyro_f;
        }
        let job_due = self.fifo_k >= BLOCK;
        if job_due {
            self.fifo_k = 0;
        }
        self.gyro_rad_s =
            gyro_f.map(|g| if self.cfg.reference_arithmetic { (f64::from(g) * MDPS_TO_RAD_S) as f32 } else { g * (MDPS_TO_RAD_S as f32) });

        // 4. Yaw: gyro-integrated heading, reset with the target while the throttle is low.
        self.yaw_est_rad = if self.cfg.reference_arithmetic {
            (f64::from(self.yaw_est_rad) + f64::from(self.gyro_rad_s[2]) * self.cfg.timing.tick_dt_s) as f32
        } else {
            self.yaw_est_rad + self.gyro_rad_s[2] * self.tick_dt_s
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
        if self.decision.motors_enabled {
            let s2 = self.rate_loop.step(&self.cfg.control, self.outer.rate_demand_rad_s, self.gyro_rad_s, throttle_low, self.saturation);
            let (cmd, sat) = self.cfg.mixer.mix(self.cfg.mixer.throttle_counts(sticks.thr), s2);
            self.motor_command = cmd;
            self.saturation = sat;
        } else {
            self.motor_command = [0.0; 4];
        }
        if throttle_low {
            // The reference's only throttle cut: the motors stop with the stick at the bottom.
            self.motor_command = [0.0; 4];
        }

        // 6. Guard, last and unconditional: compare values come from here only.
        let range = self.cfg.mixer.compare_range();
        self.compare = self.motor_command.map(|c| range.to_compare(c));
        if !self.decision.motors_enabled || self.fault.is_some() {
            self.compare = [self.cfg.mixer.off_compare(); 4];
        }

        // Built in place: a 144-byte `Option<OuterJob>` moved into the output was copied
        // (memcpy) on every tick, job or not.
        let yaw_target_reset = self.yaw_target_reset;
        if job_due {
            self.yaw_target_reset = false;
            TickOutput {
                compare: self.compare,
                outer_job: Some(OuterJob {
                    accel_mg: self.accel_fifo,
                    gyro_mdps: self.gyro_fifo,
                    sticks,
                    throttle_low,
                    yaw_est_rad: self.yaw_est_rad,
                    yaw_target_reset,
                }),
            }
        } else {
            TickOutput { compare: self.compare, outer_job: None }
        }
    }

    fn check_health(&mut self, raw: RawImu, body: &BodyImu) {
        if let Some(h) = &mut self.health {
            if let Some(f) = h.check(raw, body) {
                self.fault.get_or_insert(f);
            }
        }
    }

    fn supervise(&mut self, armed_override: Option<bool>) -> Decision {
        let calibrating = self.calibrator.in_startup() || self.calibrator.is_averaging();
        match self.cfg.supervisor {
            SupervisorConfig::Reference => self.supervisor.step_reference(self.radio.link, armed_override, calibrating),
            SupervisorConfig::Safe(safety) => {
                let sticks = self.radio.sticks;
                let inputs = Inputs {
                    link: self.radio.link,
                    sticks,
                    gesture: self.radio.gesture,
                    throttle_low: self.cfg.rc.throttle_low(&sticks),
                    calibrated: self.calibrator.has_passed(),
                    calibrating,
                    sensor_fault: self.fault,
                    tilt_rad: self.tilt_rad,
                };
                self.supervisor.step(&safety, &inputs)
            }
        }
    }

    fn motors_off(&mut self) -> TickOutput {
        self.motor_command = [0.0; 4];
        self.compare = [self.cfg.mixer.off_compare(); 4];
        TickOutput { compare: self.compare, outer_job: None }
    }

    pub fn status(&self) -> Status {
        Status {
            state: self.decision.state,
            blockers: self.decision.blockers,
            link: self.radio.link,
            sticks: self.radio.sticks,
            calibration: self.calibrator.phase(),
            fault: self.fault,
            quat: self.outer.quat,
            tilt: self.outer.tilt,
            target_rad: [self.outer.target_rad[0], self.outer.target_rad[1], self.yaw_target_rad],
            yaw_est_rad: self.yaw_est_rad,
            rate_demand_rad_s: self.outer.rate_demand_rad_s,
            motor_command: self.motor_command,
            compare: self.compare,
        }
    }
}

impl Outer {
    fn new(estimator: EstimatorConfig, rc: RcConfig, control: ControlConfig, reference_arithmetic: bool) -> Self {
        Outer {
            estimator: Estimator::new(estimator),
            rc,
            control,
            reference_arithmetic,
            angle_loop: AngleLoop::default(),
            yaw_target_rad: 0.0,
        }
    }

    /// The outer step: block average → estimator → Euler → stick targets → angle loop.
    pub fn step(&mut self, job: &OuterJob) -> OuterResult {
        let accel = block_average(&job.accel_mg, self.reference_arithmetic);
        let gyro = block_average(&job.gyro_mdps, self.reference_arithmetic);
        self.estimator.update(accel, gyro, job.throttle_low);
        let quat = self.estimator.quat();
        let tilt = quat_to_tilt_with(quat, self.reference_arithmetic);

        let (pitch_target, roll_target) = self.rc.tilt_targets(&job.sticks);
        if job.yaw_target_reset {
            self.yaw_target_rad = 0.0;
        }
        let yaw_step = self.rc.yaw_step(&job.sticks);
        if yaw_step != 0.0 {
            self.yaw_target_rad += yaw_step;
        }
        if job.throttle_low || !self.yaw_target_rad.is_finite() {
            self.yaw_target_rad = 0.0;
        }
        let target_rad = [pitch_target, roll_target, self.yaw_target_rad];
        let estimate = [tilt.pitch_rad, tilt.roll_rad, job.yaw_est_rad];
        let rate_demand_rad_s = self.angle_loop.step(&self.control, target_rad, estimate, job.throttle_low);
        OuterResult { quat, tilt, target_rad, rate_demand_rad_s }
    }
}
