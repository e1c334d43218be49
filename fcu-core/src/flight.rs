//! `FlightController`: the whole per-tick pipeline and the outer step, with no hardware.
//!
//! The firmware and the simulator drive this one type. It has two halves so the firmware can
//! run the outer step in a lower-priority task:
//! - [`ControlTick`] runs every control tick, as a chain of stages that each own their state:
//!   the command stage (radio → supervisor → the decision in force), the sensor front end
//!   (health, calibration, offsets, gyro low-pass), the block of five samples, the heading
//!   estimate, and the output (rate loop → mixer → guard). Every fifth tick it hands out an
//!   [`OuterJob`] (the block's accelerometer words and summed gyro, and the sticks).
//! - [`OuterStep`] runs the job: accelerometer conversion → block means → estimator → Euler and
//!   tilt → stick targets and the heading target → angle loop → the run-time [`Gains`] → the
//!   vertical half (the barometer burst given by [`OuterStep::set_baro`], the height estimate,
//!   altitude hold: [`crate::althold::Vertical`]), and returns an [`OuterResult`] that the
//!   control tick applies at its next tick ([`ControlTick::apply_outer`]). The outer step is the
//!   only owner of the heading target, the tilt, the gains and the height; the tick takes one
//!   value from the vertical half, the throttle the hold flies instead of the stick's.
//!
//! The configuration is never changed: what both halves read is worked out from it once (the
//! tick's [`TickParams`]), and the gains scale only the tick's rate loop and throttle map.
//!
//! The 800 Hz half is written for a budget of 600 Cortex-M4 instructions (`scripts/bench-m4`):
//! work that only the outer step needs is left to it, what the configuration settles is
//! decided at construction, and steady flight takes shortcuts that are tested equal to the
//! general path.
//!
//! The simulator and the replay run the outer step inline with
//! [`FlightController::run_outer`], right after the tick that made the job.

mod block;
mod derived;
mod gcs;
#[cfg(test)]
mod gcs_tests;
mod heading;
mod in_force;
mod output;
mod sensors;
mod supervision;

pub use block::{AccelWords, OuterJob};
pub use derived::TickParams;
pub use supervision::ForcedRadio;

use self::block::Block;
use self::derived::{Derived, OuterParams, Unscaled};
use self::heading::{HeadingEstimate, HeadingTarget};
use self::output::{MotorsAllowed, Output};
use self::sensors::{AfterCalibration, Sensors};
use self::supervision::{RadioFlags, Supervision};
use crate::ahrs::{Estimator, MDPS_TO_RAD_S};
use crate::althold::{Vertical, VerticalCommand, VerticalInput};
use crate::altitude::AltitudeStatus;
use crate::baro::RawBaro;
use crate::config::{Config, ConfigError};
use crate::control::{AngleLoop, GainSchedule, Gains, YawRateShaper};
use crate::filter::block_mean;
use crate::gcs::GcsInput;
use crate::imu::{CalibrationPhase, RawImu, SensorFault};
use crate::math::{quat_to_tilt_with, tilt_angle_rad, Quat, Tilt, Vec3};
use crate::rc::{EdgeDecoder, PulseBatch, Sticks};
use crate::supervisor::{Blockers, FlightState};

/// What one control tick produces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickOutput {
    /// TIM4 CCR1..CCR4, always inside the mixer's compare range.
    pub compare: [u16; 4],
    /// Set every fifth tick: run the outer step on it.
    pub outer_job: Option<OuterJob>,
}

/// The outer step's result, applied by the inner half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OuterResult {
    pub quat: Quat,
    pub tilt: Tilt,
    /// Tilt from level, rad, for the safe supervisor's arming check (0 with the reference's,
    /// which has none).
    pub tilt_from_level_rad: f32,
    /// Pitch, roll and (accumulated) yaw targets, rad.
    pub target_rad: [f32; 3],
    /// Rate demands for the inner loop, rad/s: the angle loop's output.
    pub rate_demand_rad_s: [f32; 3],
    /// The gains the tick's rate loop and throttle map are to be scaled by.
    pub gains: Gains,
    /// The vertical half's report, for [`Status::altitude`].
    pub altitude: AltitudeStatus,
    /// What the vertical half hands the tick (the hold's throttle) and the supervisor (the
    /// failsafe descent's cap, a landing).
    pub vertical: VerticalCommand,
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
    /// commands, and what the simulator's yaw metric holds the airframe to. Without yaw shaping
    /// the heading target moves at this rate and the yaw feedforward passes it on; with it,
    /// both follow its shaped version.
    pub yaw_rate_target_rad_s: f32,
    /// Height, barometer and altitude hold.
    pub altitude: AltitudeStatus,
}

/// What a configuration change reaches, as the parameter table classifies it
/// (`fcu_params::check_change`, which compares every parameter the table marks as not
/// changeable in flight).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum ChangeKind {
    /// Only what may change in flight: gains, angle and yaw-rate limits, telemetry rates.
    InFlight,
    /// Something that may change only on the ground: the radio, gestures, failsafe times,
    /// filters, the battery divider, the link's protocol.
    GroundOnly,
}

impl ChangeKind {
    /// The rule, owned here and nowhere else: while changes are restricted
    /// ([`FlightState::changes_restricted`]: arming, armed, or the failsafe's level stage) only
    /// an in-flight change is taken. Changing how the sticks read or when the failsafe acts
    /// mid-flight could move the motors in ways the pilot did not command.
    pub fn allowed(self, changes_restricted: bool) -> bool {
        self == ChangeKind::InFlight || !changes_restricted
    }
}

/// A new configuration with what it reaches: what the tick takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConfigChange {
    pub cfg: Config,
    pub kind: ChangeKind,
}

/// Why the tick did not take a change (it changed nothing).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TakeError {
    /// A ground-only change while changes are restricted (asked for disarmed, carried out
    /// after arming).
    Restricted,
    /// Another kind of supervisor: that needs a new controller.
    OtherSupervisor,
}

/// The per-tick half: the stages, in the order its `run` calls them.
#[derive(Clone, Debug)]
pub struct ControlTick {
    /// What the configuration comes to for the tick, the rate loop and throttle map scaled by
    /// the gains of `outer`.
    params: TickParams,
    /// Radio, supervisor, and the decision in force.
    supervision: Supervision,
    /// Health, calibration, offsets, gyro low-pass.
    sensors: Sensors,
    /// The five samples of the next outer job.
    block: Block,
    /// The gyro-integrated heading.
    heading: HeadingEstimate,
    /// The last outer result, in force until the next.
    outer: OuterResult,
    /// Rate loop, mixer, compare values.
    output: Output,
    /// What the gains scale, for when they move.
    unscaled: Unscaled,
}

/// The outer-step half.
#[derive(Clone, Debug)]
pub struct OuterStep {
    params: OuterParams,
    estimator: Estimator,
    angle_loop: AngleLoop,
    heading: HeadingTarget,
    gains: GainSchedule,
    /// The barometer burst read since the last step, if any ([`OuterStep::set_baro`]).
    baro: Option<RawBaro>,
    /// Barometer, height, altitude hold (`None`: a profile without, the reference's).
    vertical: Option<Vertical>,
}

/// The whole flight controller: both halves, for callers that run the outer step inline.
///
/// The tick first, at offset 0 (docs/performance.md, «tick first»).
#[derive(Clone, Debug)]
#[repr(C)]
pub struct FlightController {
    control_tick: ControlTick,
    outer_step: OuterStep,
    /// The configuration as given.
    cfg: Config,
}

impl FlightController {
    /// Build from a configuration; an invalid one is refused with the field that is wrong.
    pub fn new(cfg: &Config) -> Result<Self, ConfigError> {
        cfg.validate()?;
        let derived = Derived::new(cfg);
        let outer_step = OuterStep::new(cfg, derived.outer)?;
        Ok(FlightController { control_tick: ControlTick::new(cfg, derived.tick), outer_step, cfg: *cfg })
    }

    /// The configuration in force: the one given to [`new`](Self::new), or the last one
    /// [`take_change`](Self::take_change) took.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Whether changes are restricted ([`FlightState::changes_restricted`]): the motors may be
    /// running or about to. Only in-flight changes are taken then ([`ChangeKind::allowed`]).
    pub fn changes_restricted(&self) -> bool {
        self.control_tick.changes_restricted()
    }

    /// Take a changed configuration at run time, as a real autopilot takes a parameter change:
    /// what the tick and the outer step work with is made again from it and the gains in force,
    /// the gyro low-pass gets its new coefficients and the supervisor its new numbers, and every
    /// stage keeps its state (integrators, filters, estimate, heading, supervisor). Refused,
    /// with nothing changed, as [`ControlTick::take_config`] refuses. Whether `change.cfg` may
    /// replace the configuration at all (valid, differing only in parameters) and what it
    /// reaches is the parameter table's to say (`fcu_params::check_change`).
    pub fn take_change(&mut self, change: &ConfigChange) -> Result<(), TakeError> {
        self.control_tick.take_config(change)?;
        self.outer_step.take_config(&change.cfg);
        self.cfg = change.cfg;
        Ok(())
    }

    /// The edge decoder the capture interrupt should feed for this configuration.
    pub fn edge_decoder(&self) -> EdgeDecoder {
        EdgeDecoder::new(self.cfg.rc.pulses)
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

    /// The barometer burst read since the last outer step (see [`OuterStep::set_baro`]).
    pub fn set_baro(&mut self, raw: Option<RawBaro>) {
        self.outer_step.set_baro(raw);
    }

    /// A ground station's input (see [`ControlTick::take_gcs`]).
    pub fn take_gcs(&mut self, input: &GcsInput) {
        self.control_tick.take_gcs(input);
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
        out.compare
    }

    pub fn status(&self) -> Status {
        self.control_tick.status()
    }

    /// Tests only (feature `test-switches`): with `true`, the supervisor decides every tick; the
    /// decision in force never stands in steady flight.
    #[cfg(feature = "test-switches")]
    pub fn set_table_only(&mut self, table_only: bool) {
        self.control_tick.supervision.set_table_only(table_only);
    }

    /// Split for a firmware that runs the outer step in its own task.
    pub fn into_parts(self) -> (ControlTick, OuterStep) {
        (self.control_tick, self.outer_step)
    }
}

impl ControlTick {
    fn new(cfg: &Config, params: TickParams) -> Self {
        ControlTick {
            params,
            supervision: Supervision::new(cfg.supervisor),
            sensors: Sensors::new(cfg),
            block: Block::default(),
            heading: HeadingEstimate::default(),
            outer: OuterResult {
                quat: Quat::IDENTITY,
                tilt: Tilt::default(),
                tilt_from_level_rad: 0.0,
                target_rad: [0.0; 3],
                rate_demand_rad_s: [0.0; 3],
                gains: Gains::UNITY,
                altitude: AltitudeStatus::default(),
                vertical: VerticalCommand::default(),
            },
            output: Output::new(),
            unscaled: Unscaled::new(cfg),
        }
    }

    /// See [`FlightController::changes_restricted`].
    pub fn changes_restricted(&self) -> bool {
        self.supervision.in_force().decision.state.changes_restricted()
    }

    /// The tick's half of a change: its values made again from the configuration and the gains
    /// in force, the gyro low-pass's coefficients and the supervisor's numbers replaced, every
    /// state kept. Refused (nothing changed) for a ground-only change while changes are
    /// restricted ([`ChangeKind::allowed`]: checked here, between ticks, because a change asked
    /// for disarmed may arrive after arming), and for another kind of supervisor. A firmware
    /// that runs the outer step in its own task hands it a change only after this took it.
    pub fn take_config(&mut self, change: &ConfigChange) -> Result<(), TakeError> {
        if !change.kind.allowed(self.changes_restricted()) {
            return Err(TakeError::Restricted);
        }
        let cfg = &change.cfg;
        if !self.supervision.set_config(cfg.supervisor) {
            return Err(TakeError::OtherSupervisor);
        }
        self.params = TickParams::new(cfg, self.outer.gains);
        self.unscaled = Unscaled::new(cfg);
        self.sensors.set_gyro_filter(cfg.gyro_filter);
        Ok(())
    }

    /// What the tick works with: the configuration's values, the rate loop and throttle map
    /// scaled by the gains in force.
    pub fn params(&self) -> &TickParams {
        &self.params
    }

    /// One control tick: the radio from capture pulses.
    pub fn tick(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        self.sensors.sample_arrived();
        self.tick_with(imu, pulses)
    }

    /// One control tick when the sensor read failed: the last sample is held for up to
    /// [`MAX_MISSING_SAMPLES`](crate::imu::MAX_MISSING_SAMPLES) ticks (a single bus glitch must
    /// not drop the drone); after that the sensor is faulty, the motors stop and the fault
    /// latches, as for any sensor fault.
    pub fn tick_without_sample(&mut self, pulses: &PulseBatch) -> TickOutput {
        let imu = self.sensors.sample_missing();
        self.tick_with(imu, pulses)
    }

    fn tick_with(&mut self, imu: RawImu, pulses: &PulseBatch) -> TickOutput {
        let flags = self.supervision.receive(&self.params, pulses);
        self.run(imu, flags)
    }

    /// One control tick with the radio state given directly (golden replay).
    pub fn tick_forced(&mut self, imu: RawImu, forced: &ForcedRadio) -> TickOutput {
        let flags = self.supervision.receive_forced(&self.params, forced);
        self.run(imu, flags)
    }

    /// A ground station's input ([`crate::gcs`]), between ticks as a configuration change
    /// is: a disarm and an IMU calibration go to the supervisor's next decision, a motor test
    /// or a radio calibration starts (if the state still allows it) or ends, the save's level
    /// is kept. The reference's supervisor takes none of it.
    pub fn take_gcs(&mut self, input: &GcsInput) {
        self.supervision.take_gcs(input, &self.params);
    }

    /// A ground station's radio calibration runs (arming is blocked meanwhile).
    pub fn radio_calibration(&self) -> bool {
        self.supervision.radio_calibration()
    }

    /// Take in an outer step's result (at the start of the next tick in the firmware): its
    /// attitude, targets, rate demands and gains are in force from now on.
    pub fn apply_outer(&mut self, r: &OuterResult) {
        if r.gains != self.outer.gains {
            self.params.set_gains(&self.unscaled, r.gains);
        }
        self.supervision.set_vertical(r.vertical, &self.params);
        self.outer = *r;
        self.heading.result_applied();
    }

    /// The pipeline, top to bottom: one call per stage. Every decision that touches a motor is
    /// in this function.
    fn run(&mut self, imu: RawImu, flags: RadioFlags) -> TickOutput {
        let p = &self.params;

        // 1. Supervise: sensor health, then the supervisor decides whether the motors may run.
        self.sensors.check(imu);
        let asked = self.supervision.decide(p, &self.sensors, self.outer.tilt_from_level_rad, flags);
        self.sensors.ask_calibration(asked | flags.calibrate);
        let in_force = *self.supervision.in_force();

        // 2. Calibration: start-up (nothing else runs until the first offsets exist) and
        // requested. Idle with nothing asked, it has nothing to do.
        if self.sensors.calibration_due() && self.sensors.calibrate(imu, &p.decoder, &mut self.block) == AfterCalibration::NoOffsetsYet {
            return TickOutput { compare: self.output.off(p), outer_job: None };
        }

        // 3. Condition the sensors: offsets, gyro low-pass, into the block.
        let gyro_mdps = self.sensors.gyro_mdps(imu.gyro, &p.decoder);
        let job_due = self.block.add(imu.accel, gyro_mdps);
        let gyro_rad_s =
            gyro_mdps.map(|g| if p.reference_arithmetic() { (f64::from(g) * MDPS_TO_RAD_S) as f32 } else { g * (MDPS_TO_RAD_S as f32) });

        // 4. Heading: gyro-integrated, restarted with its target while the throttle is low.
        self.heading.integrate(gyro_rad_s[2], in_force.throttle_low, p);

        // 5. Rate loop, mixer and guard.
        let allowed = MotorsAllowed {
            enabled: in_force.decision.motors_enabled,
            throttle: in_force.sticks.thr,
            throttle_low: in_force.throttle_low,
            fault: self.sensors.fault().is_some(),
        };
        let supervision = &self.supervision;
        let compare = self.output.run(p, self.outer.rate_demand_rad_s, gyro_rad_s, allowed, || supervision.test_output());

        // One output per branch (docs/performance.md, «one output per branch»).
        if job_due {
            let reset = self.heading.take_target_reset();
            let job = self.block.take_job(self.sensors.offsets(), &in_force, self.heading.yaw_est_rad(), reset);
            TickOutput { compare, outer_job: Some(job) }
        } else {
            TickOutput { compare, outer_job: None }
        }
    }

    pub fn status(&self) -> Status {
        let radio = self.supervision.radio();
        let in_force = self.supervision.in_force();
        let [pitch_target, roll_target, yaw_target] = self.outer.target_rad;
        Status {
            state: in_force.decision.state,
            blockers: in_force.decision.blockers,
            link: radio.link,
            sticks: radio.sticks,
            calibration: self.sensors.phase(),
            calibrated: self.sensors.calibrated(),
            fault: self.sensors.fault(),
            quat: self.outer.quat,
            tilt: self.outer.tilt,
            target_rad: [pitch_target, roll_target, self.heading.target_rad(yaw_target)],
            yaw_est_rad: self.heading.yaw_est_rad(),
            rate_demand_rad_s: self.outer.rate_demand_rad_s,
            motor_command: self.output.motor_command(),
            compare: self.output.compare(),
            thrust_gain: self.outer.gains.thrust,
            yaw_rate_target_rad_s: self.params.rc.yaw_rate_rad_s(&in_force.sticks, self.params.outer_hz),
            altitude: self.outer.altitude,
        }
    }
}

impl OuterStep {
    fn new(cfg: &Config, params: OuterParams) -> Result<Self, ConfigError> {
        Ok(OuterStep {
            estimator: Estimator::new(cfg.estimator)?,
            angle_loop: AngleLoop::default(),
            heading: HeadingTarget::new(cfg.control.yaw_shaping.map(|y| YawRateShaper::new(&y, cfg.timing.outer_dt_s()))),
            gains: GainSchedule::new(&cfg.control, &cfg.mixer, params.outer_hz),
            baro: None,
            vertical: cfg.altitude.map(|a| Vertical::new(a, cfg.timing.integration_hz, &cfg.mixer)),
            params,
        })
    }

    /// The outer step: block average → estimator → Euler and tilt → stick targets and the
    /// heading target → angle loop → gains.
    pub fn run(&mut self, job: &OuterJob) -> OuterResult {
        let p = &self.params;
        let accel = block_mean(job.accel_sum_mg(&p.decoder), p.reference_arithmetic());
        let gyro = block_mean(job.gyro_sum_mdps, p.reference_arithmetic());
        self.estimator.update(accel, gyro, job.throttle_low);
        let quat = self.estimator.quat();
        let tilt = quat_to_tilt_with(quat, p.reference_arithmetic());
        // Only the safe supervisor's arming check reads it: sqrt and acos, here at the outer
        // rate rather than in the tick.
        let tilt_from_level_rad = if p.arming_tilt { tilt_angle_rad(quat) } else { 0.0 };

        let (pitch_target, roll_target) = p.rc.tilt_targets(&job.sticks);
        let (yaw_target, yaw_feedforward) = self.heading.step(p, job);
        let target_rad = [pitch_target, roll_target, yaw_target];
        let estimate = [tilt.pitch_rad, tilt.roll_rad, job.yaw_est_rad];
        let mut rate_demand_rad_s = self.angle_loop.rate_demands(&p.control, target_rad, estimate, job.throttle_low);
        if let Some(ff) = yaw_feedforward {
            rate_demand_rad_s[2] += ff;
        }
        let gains = self.gains.update(job.sticks.thr);
        // The burst is this step's only: the next step has its own.
        let baro = self.baro.take();
        let (vertical, altitude) = match &mut self.vertical {
            Some(v) => {
                let input = VerticalInput {
                    motors_enabled: job.state.motors_may_run(),
                    failsafe: job.state == FlightState::FailsafeLevel,
                    command: job.command_throttle,
                    flown: job.sticks.thr,
                    full_scale: p.rc.full_scale,
                    min_throttle: p.rc.min_throttle,
                };
                v.step(baro, quat, Vec3::new(accel[0], accel[1], accel[2]), &input)
            }
            None => (VerticalCommand::default(), AltitudeStatus::default()),
        };
        OuterResult { quat, tilt, tilt_from_level_rad, target_rad, rate_demand_rad_s, gains, altitude, vertical }
    }

    /// The latest battery reading, mV (for the battery compensation; ignored without it).
    pub fn set_battery_mv(&mut self, battery_mv: u32) {
        self.gains.set_battery_mv(battery_mv);
    }

    /// The barometer burst read since the last outer step (`None`: none was read, or the bus
    /// read failed), for the next [`run`](Self::run). The firmware reads it in the control
    /// tick's bus slot and hands it over with the job.
    pub fn set_baro(&mut self, raw: Option<RawBaro>) {
        self.baro = raw;
    }

    /// The outer step's half of a change the tick took ([`ControlTick::take_config`]): its
    /// values made again from the configuration (the angle loop's gains, the stick limits), its
    /// state kept.
    pub fn take_config(&mut self, cfg: &Config) {
        self.params = Derived::new(cfg).outer;
        match (&mut self.vertical, &cfg.altitude) {
            (Some(v), Some(a)) => v.set_config(a),
            (v, a) => *v = a.map(|a| Vertical::new(a, cfg.timing.integration_hz, &cfg.mixer)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reading whose accelerometer words change every tick.
    fn sample(k: usize) -> RawImu {
        let w = |m: usize, base: i16| base + (k * m % 211) as i16 - 105;
        RawImu { accel: [w(37, 0), w(53, 0), w(71, 8197)], gyro: [1, 2, 3] }
    }

    #[test]
    fn the_configuration_read_back_is_the_one_given_while_the_gains_scale_the_tick() {
        // A sagged battery: the outer step's first result carries a thrust gain of (4.0/3.4)².
        let cfg = Config::default();
        let mut fc = FlightController::new(&cfg).unwrap();
        fc.set_battery_mv(3400);
        let radio = ForcedRadio { width_counts: [6000, 6000, 8000, 6000], link: true, armed: false, cal_request: false };
        let mut k = 0;
        while fc.control_tick.outer.gains == Gains::UNITY {
            if let Some(job) = fc.tick_forced(sample(k), &radio).outer_job {
                fc.run_outer(&job);
            }
            k += 1;
            assert!(k < 5000, "no gain after {k} ticks");
        }
        let g = fc.control_tick.outer.gains;
        assert!(g.thrust > 1.3 && g.rate > 1.3, "{g:?}");
        assert_eq!(fc.config(), &cfg);
        // The tick flies the scaled rate loop and throttle map; what a parameter change would
        // derive again, at unity gains, is the configuration's.
        let params = fc.control_tick.params();
        assert_eq!(params.rate_loop().roll.inner_kp, cfg.control.roll.inner_kp * g.rate);
        assert_eq!(params.mixer().throttle_slope, cfg.mixer.throttle_slope * g.thrust);
        let derived = Derived::new(&cfg).tick;
        assert_eq!((derived.rate_loop(), derived.mixer()), (&cfg.control, &cfg.mixer));
    }

    #[test]
    fn the_tick_values_are_the_configuration_scaled_by_the_gains_in_force_whatever_came_before() {
        let cfg = Config::default();
        let mut fc = FlightController::new(&cfg).unwrap();
        let mut r = fc.control_tick.outer;
        for (thrust, rate) in [(1.1, 1.3), (1.27, 0.93), (0.81, 1.117), (1.05, 1.01), (1.173, 0.997)] {
            r.gains = Gains { thrust, rate };
            fc.control_tick.apply_outer(&r);
        }
        let fresh = TickParams::new(&cfg, r.gains);
        let bits = |c: &crate::control::ControlConfig| {
            [c.pitch, c.roll, c.yaw].map(|a| [a.inner_kp, a.inner_ki, a.inner_kd, a.output_limit].map(f32::to_bits))
        };
        assert_eq!(bits(fc.control_tick.params().rate_loop()), bits(fresh.rate_loop()));
        let m = |m: &crate::mixer::MixerConfig| [m.throttle_slope, m.throttle_offset].map(f32::to_bits);
        assert_eq!(m(fc.control_tick.params().mixer()), m(fresh.mixer()));
        // Back at unity: the configuration's own values.
        r.gains = Gains::UNITY;
        fc.control_tick.apply_outer(&r);
        assert_eq!((fc.control_tick.params().rate_loop(), fc.control_tick.params().mixer()), (&cfg.control, &cfg.mixer));
    }

    /// The default with the reference's supervisor (armed by the replay's flag) and no gain
    /// schedule (the gains stay at one): a controller that can be flown by `ForcedRadio`.
    fn flown() -> Config {
        let d = Config::default();
        Config {
            supervisor: crate::supervisor::SupervisorConfig::Reference,
            control: crate::control::ControlConfig { battery: None, thrust_curve: None, ..d.control },
            ..d
        }
    }

    const FLYING: ForcedRadio = ForcedRadio { width_counts: [6100, 5900, 8000, 6300], link: true, armed: true, cal_request: false };

    /// Ticks `from..to`: at rest for the start-up calibration (2000 ticks), then a bumpy
    /// flight, a reading that changes every tick.
    fn fly(fc: &mut FlightController, from: usize, to: usize, radio: &ForcedRadio) -> std::vec::Vec<[u16; 4]> {
        (from..to)
            .map(|k| {
                let imu = if k < 2000 {
                    let n = (k % 3) as i16 - 1;
                    RawImu { accel: sample(k).accel, gyro: [n, -n, n] }
                } else {
                    RawImu {
                        accel: sample(k).accel,
                        gyro: [(k % 17) as i16 * 40 - 320, (k % 13) as i16 * 30 - 180, (k % 7) as i16 * 20 - 60],
                    }
                };
                let out = fc.tick_forced(imu, radio);
                if let Some(job) = out.outer_job {
                    fc.run_outer(&job);
                }
                out.compare
            })
            .collect()
    }

    fn in_flight(cfg: Config) -> ConfigChange {
        ConfigChange { cfg, kind: ChangeKind::InFlight }
    }

    fn ground_only(cfg: Config) -> ConfigChange {
        ConfigChange { cfg, kind: ChangeKind::GroundOnly }
    }

    #[test]
    fn the_same_configuration_applied_in_flight_changes_nothing() {
        // Every stage keeps its state: a controller given its own configuration again flies on
        // bit for bit as one that was not.
        let mut a = FlightController::new(&flown()).unwrap();
        let mut b = a.clone();
        assert!(fly(&mut a, 0, 3000, &FLYING) == fly(&mut b, 0, 3000, &FLYING));
        assert!(a.changes_restricted(), "{:?}", a.status().state);
        assert!(a.control_tick.output.rate_integrators().iter().any(|&i| i != 0.0));
        let st = a.status();
        assert!(
            st.compare.iter().all(|&c| c > 0),
            "the motors run: {:?} {:?} {:?} {:?} {:?}",
            st.state,
            st.compare,
            st.motor_command,
            st.calibration,
            st.fault
        );
        assert_eq!(a.take_change(&in_flight(flown())), Ok(()));
        assert!(fly(&mut a, 3000, 4000, &FLYING) == fly(&mut b, 3000, 4000, &FLYING), "applying the same configuration changed the flight");
    }

    #[test]
    fn a_gain_change_in_flight_applies_at_once_and_keeps_the_integrators() {
        let mut a = FlightController::new(&flown()).unwrap();
        fly(&mut a, 0, 3000, &FLYING);
        let mut b = a.clone();
        let mut cfg = flown();
        cfg.control.roll.inner_kp = 260.0;
        let integrators = a.control_tick.output.rate_integrators();
        assert_eq!(a.take_change(&in_flight(cfg)), Ok(()));
        assert_eq!(a.config(), &cfg);
        assert_eq!(a.control_tick.params().rate_loop().roll.inner_kp, 260.0);
        assert_eq!(a.outer_step.params.control.roll.inner_kp, 260.0);
        assert_eq!(a.control_tick.output.rate_integrators(), integrators);
        assert!(fly(&mut a, 3000, 3100, &FLYING) != fly(&mut b, 3000, 3100, &FLYING), "the new gain flies");
    }

    #[test]
    fn a_ground_only_change_asked_for_disarmed_and_carried_out_armed_is_refused() {
        let mut fc = FlightController::new(&flown()).unwrap();
        fly(&mut fc, 0, 1990, &ForcedRadio { armed: false, ..FLYING });
        assert!(!fc.changes_restricted(), "{:?}", fc.status().state);
        // Asked for while disarmed (the parameters crate classified it then), carried out by
        // the tick after arming.
        let mut radio = flown();
        radio.rc.inputs[0].trim_counts = 5880;
        let change = ground_only(radio);
        fly(&mut fc, 1990, 3000, &FLYING);
        assert!(fc.changes_restricted(), "{:?}", fc.status().state);
        let before = fc.clone();
        assert_eq!(fc.take_change(&change), Err(TakeError::Restricted));
        assert_eq!(fc.config(), before.config());
        let (mut fc2, mut before2) = (fc.clone(), before.clone());
        assert!(fly(&mut fc2, 3000, 3200, &FLYING) == fly(&mut before2, 3000, 3200, &FLYING), "a refusal changed the flight");
        // An in-flight change is taken armed.
        let mut gains = flown();
        gains.control.pitch.outer_kp = 8.0;
        assert_eq!(fc.take_change(&in_flight(gains)), Ok(()));

        // Disarmed again, the ground-only change applies, and reaches the tick.
        let landed = ForcedRadio { armed: false, ..FLYING };
        fly(&mut fc, 3000, 3010, &landed);
        assert!(!fc.changes_restricted(), "{:?}", fc.status().state);
        let mut filter = radio;
        filter.gyro_filter = crate::filter::BiquadCoeffs::butterworth_lowpass(80.0, 800.0).unwrap();
        let mut twin = fc.clone();
        assert_eq!(fc.take_change(&change), Ok(()));
        assert_eq!(fc.control_tick.params().rc.inputs[0].trim_counts, 5880);
        assert_eq!(fc.take_change(&ground_only(filter)), Ok(()));
        assert_eq!(fc.config(), &filter);
        // The gyro low-pass moved: armed again, the two fly differently.
        assert!(fly(&mut fc, 3010, 3400, &FLYING) != fly(&mut twin, 3010, 3400, &FLYING), "the new filter flies");
    }

    #[test]
    fn only_an_in_flight_change_is_allowed_while_changes_are_restricted() {
        assert!(ChangeKind::InFlight.allowed(true));
        assert!(ChangeKind::InFlight.allowed(false));
        assert!(!ChangeKind::GroundOnly.allowed(true));
        assert!(ChangeKind::GroundOnly.allowed(false));
    }

    #[test]
    fn the_split_halves_take_a_change_as_the_whole_controller_does() {
        let mut whole = FlightController::new(&flown()).unwrap();
        fly(&mut whole, 0, 3000, &FLYING);
        let (mut tick, mut outer) = whole.clone().into_parts();
        let mut cfg = flown();
        cfg.control.pitch.outer_kp = 8.0;
        cfg.control.yaw.inner_kd = 40.0;
        tick.take_config(&in_flight(cfg)).unwrap();
        outer.take_config(&cfg);
        whole.take_change(&in_flight(cfg)).unwrap();
        let mut split = FlightController { control_tick: tick, outer_step: outer, cfg };
        assert!(fly(&mut whole, 3000, 3500, &FLYING) == fly(&mut split, 3000, 3500, &FLYING));
    }

    #[test]
    fn the_safe_supervisor_takes_new_failsafe_times_disarmed() {
        let mut fc = FlightController::new(&Config::default()).unwrap();
        fly(&mut fc, 0, 100, &ForcedRadio { armed: false, ..FLYING });
        let mut cfg = Config::default();
        if let crate::supervisor::SupervisorConfig::Safe(s) = &mut cfg.supervisor {
            s.failsafe_off_ticks = 1600;
        }
        assert_eq!(fc.take_change(&ground_only(cfg)), Ok(()));
        assert_eq!(fc.control_tick.supervision.safety().map(|s| s.failsafe_off_ticks), Some(1600));
        // Another kind of supervisor is no parameter: a new controller.
        let reference = Config { supervisor: crate::supervisor::SupervisorConfig::Reference, ..cfg };
        assert_eq!(fc.take_change(&ground_only(reference)), Err(TakeError::OtherSupervisor));
        assert_eq!(fc.config(), &cfg);
    }

    /// `flown()` with the altitude mode `mode`, flown with a barometer burst before every outer
    /// step (a new sample on 75 of 160, at 1013.25 hPa), or none from `baro_until` on.
    fn fly_with_baro(fc: &mut FlightController, from: usize, to: usize, radio: &ForcedRadio, baro_until: usize) {
        for k in from..to {
            let imu = RawImu { accel: sample(k).accel, gyro: [0, 0, 0] };
            let out = fc.tick_forced(imu, radio);
            if let Some(job) = out.outer_job {
                let n = k / 5;
                let due = (n * 75) / 160 != ((n + 1) * 75) / 160;
                let burst = RawBaro {
                    status: crate::baro::registers::status::P_DA,
                    pressure_counts: 4_150_272 + (k % 7) as i32 * 10,
                    temperature_counts: 2500,
                };
                fc.set_baro((due && k < baro_until).then_some(burst));
                fc.run_outer(&job);
            }
        }
    }

    fn with_alt_mode(mode: crate::altitude::AltMode) -> Config {
        let mut cfg = flown();
        if let Some(a) = &mut cfg.altitude {
            a.mode = mode;
        }
        cfg
    }

    #[test]
    fn the_outer_step_reports_the_height_and_the_barometer_and_names_its_fault() {
        let mut fc = FlightController::new(&with_alt_mode(crate::altitude::AltMode::Manual)).unwrap();
        fly_with_baro(&mut fc, 0, 2500, &ForcedRadio { armed: false, ..FLYING }, usize::MAX);
        fly_with_baro(&mut fc, 2500, 4000, &FLYING, usize::MAX);
        let a = fc.status().altitude;
        assert_eq!(a.mode, crate::altitude::AltMode::Manual);
        assert!(a.estimate_healthy && !a.holding && a.target_m.is_none() && a.baro_fault.is_none(), "{a:?}");
        assert!(a.pressure_pa.is_some_and(|p| (p - 101_325.0).abs() < 1.0) && a.temperature_c == 25.0, "{a:?}");
        // Re-zeroed at the arming: the take-off point is 0.
        assert!(a.height_m.abs() < 0.3 && a.climb_m_s.abs() < 0.2, "{a:?}");
        // The part stops answering: NoData within 0.1 s, the estimate no longer healthy.
        fly_with_baro(&mut fc, 4000, 4200, &FLYING, 0);
        let a = fc.status().altitude;
        assert_eq!(a.baro_fault, Some(crate::baro::BaroFault::NoData));
        assert!(!a.estimate_healthy, "{a:?}");
    }

    #[test]
    fn the_holds_throttle_reaches_the_mixer_in_place_of_the_sticks() {
        // The same flight in both modes: armed on the ground with the stick in the hold's dead
        // band. Manual: the stick's throttle runs the motors. Hold: on the ground, centred, the
        // hold idles (the throttle cut stops the motors) until the stick asks for a climb.
        let centred = ForcedRadio { width_counts: [6100, 5900, 6150, 6300], ..FLYING };
        let mut manual = FlightController::new(&with_alt_mode(crate::altitude::AltMode::Manual)).unwrap();
        let mut hold = FlightController::new(&with_alt_mode(crate::altitude::AltMode::Hold)).unwrap();
        // Armed with the throttle low (as the safe supervisor arms), then the stick centred.
        let disarmed = ForcedRadio { armed: false, width_counts: [6100, 5900, 4400, 6300], ..centred };
        let armed_low = ForcedRadio { armed: true, ..disarmed };
        for fc in [&mut manual, &mut hold] {
            fly_with_baro(fc, 0, 2500, &disarmed, usize::MAX);
            fly_with_baro(fc, 2500, 2600, &armed_low, usize::MAX);
            fly_with_baro(fc, 2600, 4000, &centred, usize::MAX);
        }
        let (m, h) = (manual.status(), hold.status());
        assert!(m.compare.iter().all(|&c| c > 0), "{:?}", m.compare);
        assert!(h.altitude.holding, "{:?}", h.altitude);
        assert_eq!(h.compare, [0; 4], "{:?}", h.altitude);
        assert_eq!(hold.control_tick.supervision.in_force().sticks.thr, crate::rc::StickCounts(0));
        // The stick up: the take-off ramp runs the motors.
        let up = ForcedRadio { width_counts: [6100, 5900, 8400, 6300], ..FLYING };
        fly_with_baro(&mut hold, 4000, 4400, &up, usize::MAX);
        let h = hold.status();
        assert!(h.compare.iter().all(|&c| c > 0), "{:?} {:?}", h.compare, h.altitude);
    }

    #[test]
    #[cfg(feature = "reference")]
    fn a_block_spanning_new_offsets_keeps_each_sample_under_its_own_offsets() {
        use crate::filter::{accumulate, BLOCK};
        use crate::imu::{Decoder, ImuConfig, Offsets};
        // What the reference does tick by tick: convert, correct with the offsets in force,
        // store, and average the five slots. The job's sum must be that, bit for bit, wherever
        // in the block the offsets change.
        let decoder = Decoder::new(&ImuConfig::REFERENCE);
        let radio = ForcedRadio { width_counts: [6000; 4], link: false, armed: false, cal_request: false };
        for change_at in 0..BLOCK {
            let mut fc = FlightController::new(&Config::reference()).unwrap();
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
                    let tick = &mut fc.control_tick;
                    tick.sensors.set_offsets(Offsets { accel_mg: [5, -7, 1020], gyro_mdps: [0; 3] }, &tick.params.decoder, &mut tick.block);
                }
                let offsets = fc.control_tick.sensors.offsets();
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
