//! Every tunable in one value, with the two profiles.
//!
//! - [`Config::reference()`] is the ST reference's R release, number for number, including
//!   where it computes in double (`reference_arithmetic`); with it the core reproduces the
//!   reference's golden vectors bit for bit.
//! - [`Config::default()`] is the product: the same structure, pins, rates, sensor settings
//!   and stick mapping, with the documented differences D1–D18 of `docs/profiles.md` (D13–D18:
//!   yaw feedforward, battery compensation, gains from the measured loop, shaped yaw turns,
//!   thrust linearisation, gestures with a low throttle), each a field here so a test can switch it on its own.
//!
//! A `Config` is checked by [`Config::validate`] (and by `FlightController::new`): a negative
//! gain, a zero sample time or a non-finite value is a [`ConfigError`] naming the field.

use crate::ahrs::{EstimatorConfig, EstimatorError, MahonyConfig, VqfConfig};
use crate::althold::AltitudeSettings;
use crate::control::{AxisGains, BatteryCompensation, BatterySense, ControlConfig, Derivative, ThrustCurve, YawShaping};
use crate::filter::BiquadCoeffs;
use crate::imu::{CalibrationConfig, HealthConfig, ImuConfig, MotionCheck};
use crate::math::above;
use crate::mixer::{MixerConfig, Saturate};
use crate::rc::{GestureThrottle, PulseRules, RcConfig, StickCounts, YawStick, CAPTURE_WRAP, COUNTS_PER_US};
use crate::supervisor::{SafetyConfig, SupervisorConfig};

/// The control tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// TIM9 prescaler and auto-reload: the tick is 84 MHz / ((psc + 1)(arr + 1)).
    pub tick_timer_psc: u16,
    pub tick_timer_arr: u16,
    /// The tick rate every per-tick integration assumes, Hz: their dt is its reciprocal. Kept
    /// as a rate because 800 gives every form of that dt exactly: the reference's C double
    /// `0.00125` is `1.0 / 800.0` in f64, bit for bit, and the f32 dt, outer rate and outer
    /// period below are the correctly rounded 1/800, 160 and 1/160.
    pub integration_hz: f32,
}

/// The timers' input clock, Hz (APB2 timers at 84 MHz).
pub const TIMER_CLOCK_HZ: u32 = 84_000_000;

/// Timer clock cycles per radio capture count (the capture clock is `COUNTS_PER_US` MHz).
const TIMER_CYCLES_PER_COUNT: u32 = TIMER_CLOCK_HZ / (COUNTS_PER_US * 1_000_000);
// The pulse-window check counts in whole cycles per count.
const _: () = assert!(TIMER_CYCLES_PER_COUNT * COUNTS_PER_US * 1_000_000 == TIMER_CLOCK_HZ);

impl Timing {
    /// The tick rate the timer really produces, Hz.
    pub fn tick_hz(&self) -> f32 {
        TIMER_CLOCK_HZ as f32 / self.tick_divider() as f32
    }

    /// Timer clock cycles per tick, (PSC + 1)·(ARR + 1): in u64, since it reaches 2^32 at
    /// PSC = ARR = 65 535.
    pub fn tick_divider(&self) -> u64 {
        (u64::from(self.tick_timer_psc) + 1) * (u64::from(self.tick_timer_arr) + 1)
    }

    /// The dt every per-tick integration assumes, s.
    pub fn tick_dt_s(&self) -> f32 {
        1.0 / self.integration_hz
    }

    /// The same dt as the reference's C double (its heading integration).
    pub fn tick_dt_s_f64(&self) -> f64 {
        1.0 / f64::from(self.integration_hz)
    }

    /// Outer steps per second as the integrations assume them: one per
    /// [`BLOCK`](crate::filter::BLOCK) ticks.
    pub fn outer_hz(&self) -> f32 {
        self.integration_hz / crate::filter::BLOCK as f32
    }

    /// The outer step's period as the integrations assume it, s.
    pub fn outer_dt_s(&self) -> f32 {
        crate::filter::BLOCK as f32 / self.integration_hz
    }
}

/// What USART1 speaks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkProtocol {
    /// The reference's text: the TAB-separated debug line and the STATUS lines, for a serial
    /// plotter or a terminal.
    TextLines,
    /// MAVLink 2 (MAVLink 1 accepted), for QGroundControl, MAVProxy and pymavlink.
    Mavlink,
}

/// The telemetry link on USART1: which protocol, and how often the streamed messages go out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkConfig {
    /// Takes effect at the next boot: a link never changes its protocol under a ground station.
    pub protocol: LinkProtocol,
    /// Attitude messages per second.
    pub attitude_hz: u8,
    /// Radio input and motor output messages per second (each).
    pub rc_hz: u8,
}

impl LinkConfig {
    /// The default's link: MAVLink, attitude at 25 Hz, radio and motors at 10 Hz each (at
    /// 115200 baud, ATTITUDE 25 × 40 B, RC_CHANNELS and SERVO_OUTPUT_RAW 10 × (54 + 49) B and
    /// the 1 Hz messages about 150 B: some 2.2 kB/s of the link's 11.5).
    pub const DEFAULT: LinkConfig = LinkConfig { protocol: LinkProtocol::Mavlink, attitude_hz: 25, rc_hz: 10 };
    /// The reference's: its text lines.
    pub const REFERENCE: LinkConfig = LinkConfig { protocol: LinkProtocol::TextLines, ..LinkConfig::DEFAULT };
    /// The fastest stream rate: 50 Hz of every streamed message fits 115200 baud (some 9 kB/s).
    pub const MAX_HZ: u8 = 50;

    pub fn is_valid(&self) -> bool {
        (1..=Self::MAX_HZ).contains(&self.attitude_hz) && (1..=Self::MAX_HZ).contains(&self.rc_hz)
    }
}

/// Every tunable of the flight core.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    pub timing: Timing,
    pub imu: ImuConfig,
    pub calibration: CalibrationConfig,
    /// In-flight sensor health checks (`None` in the reference).
    pub health: Option<HealthConfig>,
    /// The gyro low-pass run every tick.
    pub gyro_filter: BiquadCoeffs,
    pub estimator: EstimatorConfig,
    pub rc: RcConfig,
    pub control: ControlConfig,
    pub mixer: MixerConfig,
    pub supervisor: SupervisorConfig,
    /// The battery voltage's divider, from ADC counts to millivolts.
    pub battery_sense: BatterySense,
    /// The telemetry link.
    pub link: LinkConfig,
    /// The barometer, the height estimate and altitude hold (`None` in the reference, which
    /// never reads the barometer: its tick flies the stick's throttle).
    pub altitude: Option<AltitudeSettings>,
    /// Evaluate the reference's double-precision expressions in f64 (bit-exact replay; needs
    /// the crate's `reference` feature). Off, everything is f32 (much cheaper on the Cortex-M4,
    /// whose FPU is single only).
    pub reference_arithmetic: bool,
}

/// A configuration value that cannot fly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    /// `reference_arithmetic` without the crate's `reference` feature, which compiles it in.
    ReferenceArithmetic,
    /// The reference's Mahony filter without the crate's `reference` feature.
    ReferenceEstimator,
    /// The reference's rate loop (derivative on the error, integrators that wind up against a
    /// saturated motor) without the crate's `reference` feature.
    ReferenceRateLoop,
    Timing,
    ImuSensitivity,
    Mount,
    Calibration,
    Health,
    GyroFilter,
    Estimator,
    Rc,
    Control,
    Mixer,
    Supervisor,
    BatterySense,
    Link,
    Altitude,
}

impl ConfigError {
    /// The offending part of the configuration, for a message.
    pub fn field(self) -> &'static str {
        match self {
            ConfigError::ReferenceArithmetic => "reference arithmetic (fcu-core built without its `reference` feature)",
            ConfigError::ReferenceEstimator => "estimator: the reference's Mahony (fcu-core built without its `reference` feature)",
            ConfigError::ReferenceRateLoop => {
                "rate loop: the reference's derivative on error or wind-up (fcu-core built without its `reference` feature)"
            }
            ConfigError::Timing => "timing (tick timer and dt)",
            ConfigError::ImuSensitivity => "imu sensitivity",
            ConfigError::Mount => "imu mount",
            ConfigError::Calibration => "calibration",
            ConfigError::Health => "sensor health limits",
            ConfigError::GyroFilter => "gyro filter",
            ConfigError::Estimator => "estimator",
            ConfigError::Rc => "radio",
            ConfigError::Control => "control gains and limits",
            ConfigError::Mixer => "mixer",
            ConfigError::Supervisor => "supervisor",
            ConfigError::BatterySense => "battery sense",
            ConfigError::Link => "telemetry link",
            ConfigError::Altitude => "altitude hold",
        }
    }

    /// The rule broken, short enough for a ground station's status line (at most 32
    /// characters) when no part of the configuration names a finer one.
    pub fn rule(self) -> &'static str {
        match self {
            ConfigError::ReferenceArithmetic | ConfigError::ReferenceEstimator | ConfigError::ReferenceRateLoop => {
                "reference profile not built in"
            }
            ConfigError::Timing => "tick timing invalid",
            ConfigError::ImuSensitivity | ConfigError::Mount => "IMU settings invalid",
            ConfigError::Calibration => "calibration settings invalid",
            ConfigError::Health => "sensor limits invalid",
            ConfigError::GyroFilter => "gyro filter invalid",
            ConfigError::Estimator => "estimator settings invalid",
            ConfigError::Rc => "radio settings invalid",
            ConfigError::Control => "gains or limits invalid",
            ConfigError::Mixer => "mixer settings invalid",
            ConfigError::Supervisor => "FS_* must exceed RC_TIMEOUT_MS",
            ConfigError::BatterySense => "battery scale invalid",
            ConfigError::Link => "link rates invalid",
            ConfigError::Altitude => "altitude settings invalid",
        }
    }
}

impl From<EstimatorError> for ConfigError {
    fn from(e: EstimatorError) -> Self {
        match e {
            EstimatorError::NotCompiledIn => ConfigError::ReferenceEstimator,
        }
    }
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "invalid configuration: {}", self.field())
    }
}

impl Config {
    /// The ST reference firmware, R release (221117), DC motors, Devo 7E radio.
    pub const fn reference() -> Config {
        Config {
            // B2: TIM9 ticks at 807.69 Hz, every integration assumes 800 Hz (its dt is the C
            // double 0.00125).
            timing: Timing { tick_timer_psc: 51, tick_timer_arr: 1999, integration_hz: 800.0 },
            imu: ImuConfig::REFERENCE,
            calibration: CalibrationConfig::REFERENCE,
            health: None,
            gyro_filter: BiquadCoeffs::REFERENCE_GYRO,
            estimator: EstimatorConfig::Mahony(MahonyConfig::REFERENCE),
            rc: RcConfig::REFERENCE,
            control: ControlConfig::REFERENCE,
            mixer: MixerConfig::REFERENCE_DC,
            supervisor: SupervisorConfig::Reference,
            battery_sense: BatterySense::BOARD,
            link: LinkConfig::REFERENCE,
            altitude: None,
            reference_arithmetic: true,
        }
    }

    /// The ESC build of the product: TIM4 at 400 Hz, idle 850, max 1700, MIN_THR 20. No
    /// battery compensation (D14) and no thrust curve (D17): its compare values are pulse
    /// widths an ESC reads as a command, not a duty on a brushed motor, and scaling them would
    /// move the idle pulse itself.
    pub const fn esc() -> Config {
        let d = Config::DEFAULT;
        Config {
            mixer: MixerConfig { saturate: Saturate::AttitudePriority, ..MixerConfig::REFERENCE_ESC },
            rc: RcConfig { min_throttle: StickCounts(20), ..d.rc },
            control: ControlConfig { battery: None, thrust_curve: None, ..d.control },
            ..d
        }
    }

    /// Check every field; the error names the first part that cannot fly.
    pub fn validate(&self) -> Result<(), ConfigError> {
        // Without the `reference` feature the reference's double-precision paths and its Mahony
        // filter are not compiled in: a configuration that asks for them is refused, never
        // flown with something else.
        if !cfg!(feature = "reference") {
            if self.reference_arithmetic {
                return Err(ConfigError::ReferenceArithmetic);
            }
            if matches!(self.estimator, EstimatorConfig::Mahony(_)) {
                return Err(ConfigError::ReferenceEstimator);
            }
            if self.control.derivative != Derivative::OnMeasurement || !self.control.anti_windup {
                return Err(ConfigError::ReferenceRateLoop);
            }
        }
        // A dt in (0, 0.1) s.
        if !above(self.timing.integration_hz, 10.0, f32::MAX) {
            return Err(ConfigError::Timing);
        }
        let sens = [self.imu.accel_mg_per_lsb, self.imu.gyro_mdps_per_lsb];
        if !sens.iter().all(|&s| above(s, 0.0, f32::MAX)) {
            return Err(ConfigError::ImuSensitivity);
        }
        if !self.imu.mount.is_valid() {
            return Err(ConfigError::Mount);
        }
        let cal = &self.calibration;
        let check_ok =
            cal.motion_check.is_none_or(|m| above(m.gyro_max_dev_mdps, 0.0, f32::MAX) && above(m.accel_norm_tol_mg, 0.0, f32::MAX));
        if cal.samples == 0 || !check_ok {
            return Err(ConfigError::Calibration);
        }
        if let Some(h) = self.health {
            let ok = h.stuck_ticks > 0 && h.accel_limit_mg > 0 && h.gyro_limit_mdps > 0;
            if !ok {
                return Err(ConfigError::Health);
            }
        }
        if !self.gyro_filter.is_stable() || (self.gyro_filter.dc_gain() - 1.0).abs() > 0.01 {
            return Err(ConfigError::GyroFilter);
        }
        if !self.estimator.is_valid() {
            return Err(ConfigError::Estimator);
        }
        if !self.rc.is_valid() || !self.pulse_window_cannot_alias() {
            return Err(ConfigError::Rc);
        }
        if !self.control.is_valid() {
            return Err(ConfigError::Control);
        }
        if !self.mixer.is_valid() {
            return Err(ConfigError::Mixer);
        }
        if let SupervisorConfig::Safe(s) = self.supervisor {
            // One frame keeps the link good for the channel timeout: a recovery time no longer
            // than that would hand control back to a link that delivers a single frame, and a
            // stage-2 budget no longer than that would skip stage 1.
            let timeout = self.rc.link_timeout_ticks;
            if !s.is_valid() || s.recovery_ticks <= timeout || s.failsafe_off_ticks <= timeout {
                return Err(ConfigError::Supervisor);
            }
        }
        if !self.battery_sense.is_valid() {
            return Err(ConfigError::BatterySense);
        }
        if !self.link.is_valid() {
            return Err(ConfigError::Link);
        }
        if !self.altitude.is_none_or(|a| a.is_valid() && (a.estimator.step_dt_s - self.timing.outer_dt_s()).abs() < 1e-6) {
            return Err(ConfigError::Altitude);
        }
        Ok(())
    }

    /// With validated pulses, the edges of a pulse may be at most `max_pulse_ticks` control
    /// ticks apart. That must let every valid width through, delivered up to one tick late
    /// (the capture interrupt can be held off past a tick's `take`), and must stop any pulse
    /// longer than the 15-bit capture wrap, whose counts would alias into a valid width: its
    /// edges are at least (wrap + shortest width) / tick − 1 ticks apart, one less if the rise
    /// came late.
    fn pulse_window_cannot_alias(&self) -> bool {
        let PulseRules::Validated { min_counts, max_counts, max_pulse_ticks } = self.rc.pulses else {
            return true;
        };
        // Ticks spanned by `counts`: counts × timer clock / (capture clock × tick divider), that
        // is counts × TIMER_CYCLES_PER_COUNT / divider, in 32 bits (no 64-bit division linked):
        // counts × 21 stays under 2^22, so the one divider past 32 bits (2^32) spans as u32::MAX.
        let divider = u32::try_from(self.timing.tick_divider()).unwrap_or(u32::MAX);
        let ticks_ceil = |counts: u32| (counts * TIMER_CYCLES_PER_COUNT).div_ceil(divider);
        let ticks_floor = |counts: u32| counts * TIMER_CYCLES_PER_COUNT / divider;
        let longest_valid = ticks_ceil(u32::from(max_counts)) + 1;
        let shortest_alias = ticks_floor(CAPTURE_WRAP + u32::from(min_counts)).saturating_sub(2);
        let window = u32::from(max_pulse_ticks);
        longest_valid <= window && window <= shortest_alias
    }
}

impl Default for Config {
    /// The product: [`Config::DEFAULT`].
    fn default() -> Config {
        Config::DEFAULT
    }
}

impl Config {
    /// The product: the reference's structure with differences D1–D18. A constant, so that a
    /// firmware keeps it in flash (a `static`) instead of building it field by field in RAM.
    pub const DEFAULT: Config = Config::product();

    const fn product() -> Config {
        let r = Config::reference();
        let tick_hz: f32 = 800.0;
        Config {
            // D1: TIM9 at exactly 800 Hz (84 MHz / 105 / 1000), so dt is the real period.
            timing: Timing { tick_timer_psc: 104, tick_timer_arr: 999, integration_hz: tick_hz },
            imu: r.imu,
            // D11: calibration with a motion check, retried for 10 s.
            calibration: CalibrationConfig {
                motion_check: Some(MotionCheck { gyro_max_dev_mdps: 2000.0, accel_norm_tol_mg: 100.0, timeout_ticks: 8000 }),
                ..r.calibration
            },
            // docs/safety.md#sensor-faults: non-finite, impossible or stuck (100 ms) sensor values
            // are faults.
            health: Some(HealthConfig { stuck_ticks: 80, accel_limit_mg: 4100, gyro_limit_mdps: 2_300_000 }),
            // D15: the gyro low-pass at 150 Hz instead of 100 Hz: phase for the faster loop.
            gyro_filter: BiquadCoeffs::GYRO_150_HZ_AT_800_HZ,
            // D4 and D5: a VQF-style estimator (exact normalisation, accelerometer low-passed
            // in a quasi-inertial frame, rest detection, gyro bias estimation); see `ahrs::vqf`.
            estimator: EstimatorConfig::Vqf(VqfConfig::DEFAULT),
            rc: RcConfig {
                // D9: 800..2200 µs pulses from both edges of one pulse, the edges at most 3 ticks
                // apart (a 2.2 ms pulse spans 2 at 800 Hz, 3 if an edge comes a tick late; a
                // pulse past the 8.192 ms capture wrap at least 6), so no width aliases
                // (`Config::validate` checks the window); 100 ms channel timeout.
                pulses: PulseRules::Validated { min_counts: 3200, max_counts: 8800, max_pulse_ticks: 3 },
                link_timeout_ticks: 80,
                // D8: yaw rate proportional to the stick beyond the dead band.
                yaw_stick: YawStick::Proportional,
                // D18: the gestures take a low throttle, as every other throttle rule does.
                gesture_throttle: GestureThrottle::Low,
                ..r.rc
            },
            control: ControlConfig {
                // D15: gains chosen with `fcu-sim margins` (at least 45° and 6 dB with one tick
                // more delay, on the nominal airframe and ±30 % ones) for the gusts, steps and
                // weak motors of `fcu-testkit/tests/control_quality.rs`. Roll and pitch: the D
                // term's zero (kp/kd ≈ 29 rad/s) near the motors' lag (1/70 ms ≈ 14 rad/s), so
                // past it the loop falls like an integrator; twice the integral for gusts and a
                // weak motor; the angle loop at 6.5/s. (The reference's D on the error also
                // acted through the angle loop's demand, as kd·outer_kp = 30 counts per rad/s of
                // extra rate gain; D on measurement, D7, dropped that: why the earlier default
                // tilted more than the reference in a gust.)
                pitch: AxisGains { outer_kp: 6.5, inner_kp: 200.0, inner_ki: 300.0, inner_kd: 7.0, ..r.control.pitch },
                roll: AxisGains { outer_kp: 6.5, inner_kp: 200.0, inner_ki: 300.0, inner_kd: 7.0, ..r.control.roll },
                // D3: the same D low-pass on yaw. D15: a damped yaw rate loop with the whole
                // compare range (a quad's yaw torque is small: a full-stick turn needs all of it
                // to start and stop) and a softer heading loop now that the stick's rate goes
                // straight to the rate loop (D13).
                yaw: AxisGains { outer_kp: 2.0, inner_kp: 1500.0, inner_kd: 60.0, output_limit: 2000.0, d_lowpass: true, ..r.control.yaw },
                // D15: the derivative's low-pass at ~65 Hz (0.4 at 800 Hz) instead of 3.2 Hz: it
                // damps up to the crossover instead of lagging behind it.
                d_filter_k: 0.4,
                // D7: derivative on measurement.
                derivative: Derivative::OnMeasurement,
                // D2: the outer integrator steps by the real outer period.
                outer_integrator_dt_s: 5.0 / tick_hz,
                inner_dt_s: 1.0 / tick_hz,
                // D6: anti-windup against mixer saturation.
                anti_windup: true,
                // D13: the yaw stick's rate straight into the yaw rate demand.
                yaw_rate_feedforward: 0.9,
                // D16: the stick's yaw rate through two 20 ms stages (a stop from full stick
                // takes ~0.1 s of full braking on the weakest ±30 % airframe) and the demand
                // 80 ms ahead of it: the P term (1500) then gives 120 counts per rad/s² of
                // acceleration, for the yaw inertia (~22 nominal, up to ~40 on a ±30 %
                // airframe) and the D term on measurement (60), which opposes every change of
                // rate. The lead that flew best on the five ±30 % airframes (0.05–0.1 s fly
                // within 2 % of each other); outside the loop, so the margins do not move.
                yaw_shaping: Some(YawShaping { stage_s: 0.02, lead_s: 0.08 }),
                // D14: thrust kept as the battery sags.
                battery: Some(BatteryCompensation::LIPO_1S),
                // D17: the rate loop's gain follows the motors' thrust curve at the throttle
                // flown, so a correction makes the same torque at any throttle.
                thrust_curve: Some(ThrustCurve::MOTOR_8520),
            },
            // D6: attitude priority when a motor saturates.
            mixer: MixerConfig { saturate: Saturate::AttitudePriority, ..r.mixer },
            // D10, D11: the safety layer.
            supervisor: SupervisorConfig::Safe(SafetyConfig::DEFAULT),
            battery_sense: BatterySense::BOARD,
            // MAVLink: QGroundControl and MAVProxy find the board with nothing set up.
            link: LinkConfig::DEFAULT,
            // The barometer's height, the failsafe's descent, and altitude hold for who sets
            // `ALT_MODE` (manual throttle by default: `AltitudeSettings::DEFAULT`).
            altitude: Some(AltitudeSettings::DEFAULT),
            reference_arithmetic: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window check as first written, in 64 bits: the 32-bit one must agree with it.
    fn pulse_window_in_u64(psc: u16, arr: u16, min_counts: u16, max_counts: u16, max_pulse_ticks: u16) -> bool {
        let divider = (u64::from(psc) + 1) * (u64::from(arr) + 1);
        let per = u64::from(COUNTS_PER_US) * 1_000_000 * divider;
        let ticks_ceil = |counts: u64| (counts * u64::from(TIMER_CLOCK_HZ)).div_ceil(per);
        let ticks_floor = |counts: u64| counts * u64::from(TIMER_CLOCK_HZ) / per;
        let longest_valid = ticks_ceil(u64::from(max_counts)) + 1;
        let shortest_alias = ticks_floor(u64::from(CAPTURE_WRAP) + u64::from(min_counts)).saturating_sub(2);
        let window = u64::from(max_pulse_ticks);
        longest_valid <= window && window <= shortest_alias
    }

    proptest::proptest! {
        #[test]
        fn the_pulse_window_check_in_32_bits_is_the_64_bit_one(
            psc in proptest::prop_oneof![0u16..200, proptest::num::u16::ANY],
            arr in proptest::prop_oneof![0u16..2000, proptest::num::u16::ANY],
            min_counts in proptest::num::u16::ANY,
            max_counts in proptest::num::u16::ANY,
            max_pulse_ticks in proptest::prop_oneof![1u16..10, 1u16..],
        ) {
            let mut cfg = Config::DEFAULT;
            cfg.timing.tick_timer_psc = psc;
            cfg.timing.tick_timer_arr = arr;
            cfg.rc.pulses = PulseRules::Validated { min_counts, max_counts, max_pulse_ticks };
            proptest::prop_assert_eq!(
                cfg.pulse_window_cannot_alias(),
                pulse_window_in_u64(psc, arr, min_counts, max_counts, max_pulse_ticks)
            );
        }
    }

    #[test]
    fn the_pulse_window_check_at_the_largest_divider_and_where_a_window_fits() {
        // A window that fits (random inputs rarely make one): the longest valid pulse spans
        // 1 tick, the shortest alias far more.
        let mut fits = Config::DEFAULT;
        (fits.timing.tick_timer_psc, fits.timing.tick_timer_arr) = (27, 1451);
        fits.rc.pulses = PulseRules::Validated { min_counts: 0, max_counts: 1, max_pulse_ticks: 2 };
        assert!(fits.pulse_window_cannot_alias());
        assert!(pulse_window_in_u64(27, 1451, 0, 1, 2));
        for (min_counts, max_counts, ticks) in [(0, 0, 1), (3200, 8800, 3), (u16::MAX, u16::MAX, u16::MAX)] {
            let mut cfg = Config::DEFAULT;
            cfg.timing.tick_timer_psc = u16::MAX;
            cfg.timing.tick_timer_arr = u16::MAX;
            cfg.rc.pulses = PulseRules::Validated { min_counts, max_counts, max_pulse_ticks: ticks };
            assert_eq!(cfg.pulse_window_cannot_alias(), pulse_window_in_u64(u16::MAX, u16::MAX, min_counts, max_counts, ticks));
        }
    }

    #[test]
    fn both_profiles_are_valid() {
        #[cfg(feature = "reference")]
        assert_eq!(Config::reference().validate(), Ok(()));
        assert_eq!(Config::default().validate(), Ok(()));
        assert_eq!(Config::esc().validate(), Ok(()));
    }

    /// `cargo test -p fcu-core --no-default-features`: the build the firmware ships.
    #[test]
    #[cfg(not(feature = "reference"))]
    fn without_the_reference_feature_its_arithmetic_and_estimator_are_refused() {
        assert_eq!(Config::reference().validate(), Err(ConfigError::ReferenceArithmetic));
        let arithmetic = Config { reference_arithmetic: true, ..Config::default() };
        assert_eq!(arithmetic.validate(), Err(ConfigError::ReferenceArithmetic));
        let estimator = Config { estimator: Config::reference().estimator, ..Config::default() };
        assert_eq!(estimator.validate(), Err(ConfigError::ReferenceEstimator));
        assert!(ConfigError::ReferenceEstimator.field().contains("`reference` feature"));
        assert!(matches!(crate::ahrs::Estimator::new(estimator.estimator), Err(crate::ahrs::EstimatorError::NotCompiledIn)));
        let reference_loop =
            Config { control: ControlConfig { derivative: Derivative::OnError, ..Config::default().control }, ..Config::default() };
        assert_eq!(reference_loop.validate(), Err(ConfigError::ReferenceRateLoop));
        let winding = Config { control: ControlConfig { anti_windup: false, ..Config::default().control }, ..Config::default() };
        assert_eq!(winding.validate(), Err(ConfigError::ReferenceRateLoop));
        assert!(ConfigError::ReferenceRateLoop.field().contains("`reference` feature"));
    }

    #[test]
    fn the_integration_rate_gives_the_reference_dt_and_its_f32_forms_bit_for_bit() {
        // What the reference computes from its C double dt (0.00125) and what the pipeline
        // uses: the double itself, and its f32 roundings.
        let dt = 0.00125f64;
        for t in [Config::reference().timing, Config::default().timing] {
            assert_eq!(t.tick_dt_s_f64().to_bits(), dt.to_bits());
            assert_eq!(t.tick_dt_s().to_bits(), (dt as f32).to_bits());
            assert_eq!(t.outer_dt_s().to_bits(), ((dt * 5.0) as f32).to_bits());
            assert_eq!(t.outer_hz().to_bits(), ((1.0 / (dt * 5.0)) as f32).to_bits());
        }
    }

    #[test]
    fn reference_tick_is_807_hz_and_default_is_exactly_800() {
        assert!((Config::reference().timing.tick_hz() - 807.6923).abs() < 1e-3);
        assert_eq!(Config::default().timing.tick_hz(), 800.0);
    }

    #[test]
    #[allow(clippy::approx_constant)] // 3.141592654 is the reference's own PI literal
    fn reference_constants_round_to_the_golden_bit_patterns() {
        let r = Config::reference();
        // Kept in degrees (the parameters' units), derived as the reference's radians.
        assert_eq!(r.rc.max_tilt_rad().to_bits(), 0x3eb2_b8c2);
        assert_eq!(r.rc.yaw_max_step_rad(r.timing.outer_hz()).to_bits(), 0x3c56_7750);
        let d = Config::default();
        assert_eq!(d.rc.max_tilt_rad().to_bits(), 0x3eb2_b8c2);
        assert_eq!(d.rc.yaw_max_step_rad(d.timing.outer_hz()).to_bits(), 0x3c56_7750);
        assert_eq!(((3.141_592_654f64 * 20.0 / 180.0) as f32).to_bits(), 0x3eb2_b8c2);
        assert_eq!(r.control.inner_dt_s.to_bits(), 0x3aa3_d70a);
        assert_eq!((1.0 / r.control.inner_dt_s).to_bits(), 0x4448_0000);
        assert_eq!(r.mixer.throttle_slope.to_bits(), 0x3eaa_aa3b);
        assert_eq!(r.mixer.throttle_offset.to_bits(), 0x441e_5550);
        assert_eq!(r.gyro_filter.a1.to_bits(), 0x3f71_5bef);
        assert_eq!(r.gyro_filter.b1.to_bits(), 0x3e47_f2cd);
    }

    #[test]
    fn a_pulse_window_that_lets_a_pulse_past_the_capture_wrap_through_is_an_error() {
        let with_window = |max_pulse_ticks| {
            let mut c = Config::default();
            c.rc.pulses = PulseRules::Validated { min_counts: 3200, max_counts: 8800, max_pulse_ticks };
            c.validate()
        };
        // 2.2 ms spans 2 ticks (3 with a late edge); 8.992 ms (wrap + 0.8 ms) at least 7 (5 with
        // a late rise and rounding): 3..=5 both accept every valid pulse and stop every alias.
        assert_eq!(with_window(2), Err(ConfigError::Rc));
        for ok in 3..=5 {
            assert_eq!(with_window(ok), Ok(()), "{ok}");
        }
        assert_eq!(with_window(6), Err(ConfigError::Rc));
    }

    #[test]
    fn a_recovery_time_a_single_frame_could_satisfy_is_an_error() {
        // One frame keeps the link good for the 100 ms channel timeout.
        let with = |f: &dyn Fn(&mut SafetyConfig)| {
            let mut s = SafetyConfig::DEFAULT;
            f(&mut s);
            Config { supervisor: SupervisorConfig::Safe(s), ..Config::default() }.validate()
        };
        assert_eq!(with(&|s| s.recovery_ticks = 80), Err(ConfigError::Supervisor));
        assert_eq!(with(&|s| s.recovery_ticks = 81), Ok(()));
        assert_eq!(with(&|s| s.recovery_ticks = 0), Err(ConfigError::Supervisor));
        assert_eq!(with(&|s| s.failsafe_off_ticks = 80), Err(ConfigError::Supervisor));
        assert_eq!(with(&|s| s.loss_forget_ticks = 0), Err(ConfigError::Supervisor));
    }

    #[test]
    fn a_negative_gain_is_an_error_not_a_crash() {
        let mut c = Config::default();
        c.control.roll.inner_kp = -1.0;
        assert_eq!(c.validate(), Err(ConfigError::Control));
    }

    #[test]
    fn a_zero_sample_time_is_an_error() {
        for hz in [f32::INFINITY, 0.0, 10.0, -800.0, f32::NAN] {
            let mut c = Config::default();
            c.timing.integration_hz = hz;
            assert_eq!(c.validate(), Err(ConfigError::Timing), "{hz}");
        }
        let mut c = Config::default();
        c.control.inner_dt_s = 0.0;
        assert_eq!(c.validate(), Err(ConfigError::Control));
    }

    #[test]
    fn a_non_finite_value_is_an_error() {
        let mut c = Config::default();
        c.rc.max_tilt_deg = f32::NAN;
        assert_eq!(c.validate(), Err(ConfigError::Rc));
        let mut c = Config::default();
        c.mixer.max_compare = f32::INFINITY;
        assert_eq!(c.validate(), Err(ConfigError::Mixer));
        let mut c = Config::default();
        c.gyro_filter.b0 = f32::NAN;
        assert_eq!(c.validate(), Err(ConfigError::GyroFilter));
    }

    #[test]
    fn a_yaw_shaping_that_cannot_shape_is_an_error() {
        let with = |stage_s: f32, lead_s: f32| {
            let mut c = Config::default();
            c.control.yaw_shaping = Some(YawShaping { stage_s, lead_s });
            c.validate()
        };
        assert_eq!(with(0.02, 0.08), Ok(()));
        assert_eq!(with(0.001, 0.0), Ok(()));
        assert_eq!(with(1.0, 0.5), Ok(()));
        // A zero or tiny stage would divide the acceleration by (nearly) nothing.
        for stage_s in [0.0, 0.0005, -0.02, 1.5, f32::NAN, f32::INFINITY] {
            assert_eq!(with(stage_s, 0.08), Err(ConfigError::Control), "stage {stage_s}");
        }
        for lead_s in [-0.01, 0.6, f32::NAN, f32::INFINITY] {
            assert_eq!(with(0.02, lead_s), Err(ConfigError::Control), "lead {lead_s}");
        }
    }

    #[test]
    fn the_tick_rate_of_the_largest_timer_settings_does_not_overflow() {
        let t = Timing { tick_timer_psc: u16::MAX, tick_timer_arr: u16::MAX, integration_hz: 1.0 };
        let hz = t.tick_hz();
        assert!(hz.is_finite() && hz > 0.0 && hz < 0.02, "{hz}");
    }
}
