//! Height and vertical speed above the take-off point, from the barometer and the
//! accelerometer: a third-order complementary filter with an accelerometer bias state
//! (`docs/altitude.md` has the equations and the reasons).
//!
//! The outer step's vertical half ([`crate::althold::Vertical`]) runs it; altitude hold and the
//! failsafe's descent fly on it.
//!
//! One [`AltitudeEstimator::update`] per outer step: the vertical acceleration of that step
//! (the accelerometer rotated to earth by the attitude estimate, [`vertical_accel_m_s2`]) and
//! the barometer's pressure when the part made a new sample since the last step.

use crate::math::{Quat, Vec3};

/// Standard gravity, m/s².
pub const GRAVITY_M_S2: f32 = 9.80665;

/// The ISA troposphere's barometric formula, `h = 44330.77 · (1 − (p/p0)^0.190263)`: height
/// above the level where the pressure is `p0`.
pub const ISA_HEIGHT_SCALE_M: f32 = 44_330.77;
pub const ISA_EXPONENT: f32 = 0.190_263;

/// Height in metres of pressure `pressure_pa` above the level of `reference_pa` (ISA). NaN
/// for a non-positive pressure or reference (the caller skips non-finite heights).
///
/// The power `(1 + x)^k`, `x = p/p0 − 1`, by its binomial series to the fifth power of `x`
/// rather than `powf`: the first term left out, `0.02·x⁶` of the scale, is under 0.01 mm within
/// some 400 m of the reference level (`|x|` < 0.05) and 1 mm at 850 m (`|x|` = 0.1), far below
/// f32's own rounding. A drone flies within a few hundred metres of its take-off level; the
/// series costs a fraction of `powf`'s instructions and of its 900 bytes of flash.
pub fn baro_height_m(pressure_pa: f32, reference_pa: f32) -> f32 {
    if !(pressure_pa > 0.0 && reference_pa > 0.0) {
        return f32::NAN;
    }
    let x = pressure_pa / reference_pa - 1.0;
    let k = ISA_EXPONENT;
    // Horner's form of 1 + kx + k(k−1)/2 x² + … + k(k−1)(k−2)(k−3)(k−4)/120 x⁵.
    let tail = 1.0 + x * (k - 4.0) / 5.0;
    let tail = 1.0 + x * (k - 3.0) / 4.0 * tail;
    let tail = 1.0 + x * (k - 2.0) / 3.0 * tail;
    let tail = 1.0 + x * (k - 1.0) / 2.0 * tail;
    -ISA_HEIGHT_SCALE_M * k * x * tail
}

/// The upward acceleration in the earth frame, m/s², from the accelerometer's body reading in
/// milli-g (offsets removed, so a level board at rest reads (0, 0, 1000)) and the attitude
/// quaternion (body to earth). Only the earth Z row of the rotation is needed:
/// `(q ⊗ a ⊗ q*)·ẑ = up_in_body(q)·a`. The accelerometer measures specific force, so gravity,
/// 1 g, is taken off.
pub fn vertical_accel_m_s2(q: Quat, accel_body_mg: Vec3) -> f32 {
    (q.up_in_body().dot(accel_body_mg) * 0.001 - 1.0) * GRAVITY_M_S2
}

/// The vertical mode the pilot chose (parameter `ALT_MODE`, or a ground station's set-mode).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AltMode {
    /// The throttle stick sets the collective thrust, as the reference does.
    #[default]
    Manual = 0,
    /// Altitude hold: the stick centred holds the height, outside its deadband it asks for a
    /// climb rate, at the bottom on the ground it idles.
    Hold = 1,
}

/// What the vertical half reports ([`crate::flight::Status::altitude`]): the estimate, the
/// barometer's last reading and health, and what the hold is doing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AltitudeStatus {
    /// The mode chosen.
    pub mode: AltMode,
    /// The hold sets the collective thrust now (the mode is Hold, or the failsafe descends,
    /// and the estimate is healthy).
    pub holding: bool,
    /// The link-loss failsafe is descending on the height estimate.
    pub failsafe_descent: bool,
    /// Above the take-off point (the last re-zero), m.
    pub height_m: f32,
    /// Upward, m/s.
    pub climb_m_s: f32,
    /// The height the hold holds or moves to, m (`None` when not holding).
    pub target_m: Option<f32>,
    /// The last healthy barometer sample, Pa (`None` before the first).
    pub pressure_pa: Option<f32>,
    /// The barometer's temperature with that sample, °C.
    pub temperature_c: f32,
    /// The barometer's fault, if it has one now.
    pub baro_fault: Option<crate::baro::BaroFault>,
    /// The height estimate may be flown on (referenced, fed by a healthy barometer).
    pub estimate_healthy: bool,
}

/// The estimator's tunables.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AltitudeConfig {
    /// The outer step's period, s ([`crate::config::Timing::outer_dt_s`]).
    pub step_dt_s: f32,
    /// Time constant of the complementary filter, s: the barometer is trusted below about
    /// `1/(2π·τ)` Hz, the accelerometer above. All three poles sit at `−1/τ`.
    pub time_constant_s: f32,
    /// Prop wash: the pressure error the motors cause at full collective thrust, Pa, taken off
    /// the reading in proportion to the thrust (a parameter, as ArduPilot's barometer thrust
    /// scale, measured per airframe from a log; 0 = no compensation). Not learned: in a hold the
    /// thrust barely changes, so the wash looks exactly like a height offset (`docs/altitude.md`).
    pub thrust_scale_pa: f32,
    /// Below this estimated height with the motors above [`Self::ground_effect_min_thrust`],
    /// the rotor wash off the floor raises the pressure under the drone, so the barometer reads
    /// too low: there, a barometric height up to [`Self::ground_effect_dead_zone_m`] below the
    /// estimate is taken as no news (only the part beyond counts), while one above the
    /// estimate (the climb of a take-off) counts fully, m.
    ///
    /// A dead zone rather than smaller gains: scaling all three gains of a third-order loop
    /// by a weight `w` leaves `s³ + w·k1·s² + w·k2·s + w·k3`, which is unstable for `w` below
    /// 1/9 (Routh: `w·k1·k2 > k3`); the dead zone keeps the loop as it is outside the zone.
    pub ground_effect_height_m: f32,
    pub ground_effect_min_thrust: f32,
    pub ground_effect_dead_zone_m: f32,
    /// A barometric height further than this from the estimate is not used, m; after
    /// [`Self::gate_reset_samples`] such samples in a row the estimate jumps to the barometer
    /// (the estimate was wrong, not the sensor).
    pub innovation_gate_m: f32,
    pub gate_reset_samples: u16,
    /// Largest accelerometer bias the filter may learn, m/s².
    pub max_accel_bias_m_s2: f32,
    /// Time constant of the pressure average a re-zero takes as the take-off level, s.
    pub zero_average_s: f32,
}

impl AltitudeConfig {
    /// The defaults at the 160 Hz outer step:
    /// - τ = 4 s: the barometer's 6 cm of noise per sample averaged to under a centimetre and
    ///   kept out of the hold's throttle (at 1.5 s it moved the throttle three times as much as
    ///   a pilot's hand in the 1–5 Hz band), gusts' pressure transients left to the
    ///   accelerometer; the accelerometer bias learned in flight within some 30 s (on the floor
    ///   before the take-off against the floor);
    /// - ground effect: within 0.3 m of the floor (some four rotor diameters) with the motors
    ///   over 10 %, a reading up to 0.5 m low is ignored (the wash's overpressure on a drone
    ///   this size, a few pascals, is some tenths of a metre);
    /// - gate 1.5 m: three times what the prop wash and a gust together do to the reading;
    ///   a second (75 samples) of disagreement moves the estimate to the barometer;
    /// - bias up to 1 m/s² (0.1 g, more than the LSM6DSL's ±40 mg offset after calibration).
    pub const DEFAULT: AltitudeConfig = AltitudeConfig {
        step_dt_s: 1.0 / 160.0,
        time_constant_s: 4.0,
        thrust_scale_pa: 0.0,
        ground_effect_height_m: 0.3,
        ground_effect_min_thrust: 0.1,
        ground_effect_dead_zone_m: 0.5,
        innovation_gate_m: 1.5,
        gate_reset_samples: 75,
        max_accel_bias_m_s2: 1.0,
        zero_average_s: 0.5,
    };
}

/// Longest gap between two barometer corrections treated as such, s: a correction after a
/// longer gap is applied as if this long, so `k1·dt` stays well below 1 and the filter cannot
/// overshoot on the first sample after an outage.
const MAX_CORRECTION_DT_S: f32 = 0.05;

/// After a lift-off the estimate is the accelerometer's alone (the bias learned on the floor,
/// the floor's height known) until it has been above [`LIFTOFF_CLEAR_M`], clear of ground
/// effect, for [`LIFTOFF_AVERAGE_S`] (twice the average's time constant), comparing it with
/// the barometer there; then the barometer is re-referenced to agree with it. After
/// [`LIFTOFF_INERTIAL_MAX_S`] above [`LIFTOFF_OFF_FLOOR_M`], or [`LIFTOFF_INERTIAL_LIMIT_S`] in
/// all (a lift-off declared on a throttle that does not lift this airframe), it ends with what
/// it has: the accelerometer's drift would grow past what it corrects.
pub const LIFTOFF_CLEAR_M: f32 = 0.6;
pub const LIFTOFF_AVERAGE_S: f32 = 1.0;
pub const LIFTOFF_OFF_FLOOR_M: f32 = 0.1;
pub const LIFTOFF_INERTIAL_MAX_S: f32 = 4.0;
pub const LIFTOFF_INERTIAL_LIMIT_S: f32 = 10.0;

/// What the estimate says.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AltitudeEstimate {
    /// Above the level of the last re-zero, m.
    pub height_m: f32,
    /// Upward, m/s.
    pub vertical_speed_m_s: f32,
    /// The accelerometer's learned vertical bias, m/s².
    pub accel_bias_m_s2: f32,
    /// False until the first barometer sample set a reference.
    pub referenced: bool,
}

/// The complementary filter's state.
#[derive(Clone, Debug)]
pub struct AltitudeEstimator {
    cfg: AltitudeConfig,
    /// Correction gains, 1/s, 1/s², 1/s³: `3/τ`, `3/τ²`, `1/τ³`, poles at `−1/τ`.
    k: [f32; 3],
    height_m: f32,
    speed_m_s: f32,
    bias_m_s2: f32,
    /// The take-off level's pressure, Pa.
    reference_pa: Option<f32>,
    /// The recent pressure (compensated), for a re-zero.
    average_pa: f32,
    steps_since_baro: u32,
    gated_in_a_row: u16,
    /// The last step's `on_ground`, to see the lift-off.
    on_ground: bool,
    /// Steps since the lift-off while the estimate is the accelerometer's alone (0: not), and
    /// of those, the steps off the floor and the steps clear of ground effect.
    inertial_steps: u32,
    off_floor_steps: u32,
    clear_steps: u32,
    /// Over those steps: the height estimate less the barometer's, averaged as the take-off
    /// level's pressure is (NaN before the first sample), m.
    inertial_less_baro_m: f32,
    /// Added to the barometer's height: the re-reference at the end of those steps, m.
    baro_offset_m: f32,
}

impl AltitudeEstimator {
    pub fn new(cfg: AltitudeConfig) -> Self {
        AltitudeEstimator {
            cfg,
            k: Self::gains(&cfg),
            height_m: 0.0,
            speed_m_s: 0.0,
            bias_m_s2: 0.0,
            reference_pa: None,
            average_pa: 0.0,
            steps_since_baro: 0,
            gated_in_a_row: 0,
            on_ground: false,
            inertial_steps: 0,
            off_floor_steps: 0,
            clear_steps: 0,
            inertial_less_baro_m: f32::NAN,
            baro_offset_m: 0.0,
        }
    }

    /// `3/τ`, `3/τ²`, `1/τ³`: all three poles at `−1/τ`.
    fn gains(cfg: &AltitudeConfig) -> [f32; 3] {
        let tau = cfg.time_constant_s;
        [3.0 / tau, 3.0 / (tau * tau), 1.0 / (tau * tau * tau)]
    }

    /// New tunables, the state kept (a parameter change on the ground: the take-off's re-zero
    /// and the floor settle what a new time constant or thrust scale moves).
    pub fn set_config(&mut self, cfg: &AltitudeConfig) {
        self.k = Self::gains(cfg);
        self.cfg = *cfg;
    }

    /// The barometer's own height of `pressure_pa` above the reference (the take-off level once
    /// re-zeroed), with the thrust's compensation, m; NaN before a reference.
    pub fn baro_height_m(&self, pressure_pa: f32, thrust: f32) -> f32 {
        let thrust = if thrust.is_finite() { crate::math::limit(thrust, 0.0, 1.0) } else { 0.0 };
        self.reference_pa.map_or(f32::NAN, |r| baro_height_m(pressure_pa - self.cfg.thrust_scale_pa * thrust, r) + self.baro_offset_m)
    }

    /// Found flying at `height_m` (the barometer's, well above the take-off level) while it was
    /// taken for on the ground: the estimate starts from there, and the lift-off's
    /// re-reference, made for a lift-off from the floor, is not made.
    pub fn airborne_at(&mut self, height_m: f32) {
        if height_m.is_finite() {
            self.height_m = height_m;
        }
        self.on_ground = false;
        self.inertial_steps = 0;
    }

    pub fn estimate(&self) -> AltitudeEstimate {
        AltitudeEstimate {
            height_m: self.height_m,
            vertical_speed_m_s: self.speed_m_s,
            accel_bias_m_s2: self.bias_m_s2,
            referenced: self.reference_pa.is_some(),
        }
    }

    /// The take-off point is here: the recent average pressure becomes the reference, height
    /// and speed zero (at arming, on the ground). The learned accelerometer bias is kept: it
    /// belongs to the sensor, not to the flight. False (and nothing changes) before any sample.
    pub fn rezero(&mut self) -> bool {
        if self.reference_pa.is_none() {
            return false;
        }
        self.reference_pa = Some(self.average_pa);
        self.height_m = 0.0;
        self.speed_m_s = 0.0;
        self.gated_in_a_row = 0;
        self.baro_offset_m = 0.0;
        self.inertial_steps = 0;
        true
    }

    /// One outer step: `accel_up_m_s2` from [`vertical_accel_m_s2`], `pressure_pa` when the
    /// barometer made a new, healthy sample since the last step, `thrust` the collective
    /// command (0 stopped … 1 full), `on_ground` while the drone sits on the floor (armed before
    /// the take-off, or landed: the supervisor's verdict).
    ///
    /// On the ground the floor is the height measurement (height 0, which also teaches the
    /// accelerometer's bias), and the barometer's reading, loaded by the spinning props' wash
    /// and ground effect, is only averaged. At lift-off (the first step off the ground) that
    /// loaded average becomes the reference: the take-off thrust's pressure error is taken out
    /// instead of reading as a jump.
    pub fn update(&mut self, accel_up_m_s2: f32, pressure_pa: Option<f32>, thrust: f32, on_ground: bool) -> AltitudeEstimate {
        let dt = self.cfg.step_dt_s;
        // A non-finite acceleration (a fault the IMU's checks report) is coasted through.
        let accel = if accel_up_m_s2.is_finite() { accel_up_m_s2 - self.bias_m_s2 } else { 0.0 };
        self.height_m += (self.speed_m_s + 0.5 * accel * dt) * dt;
        self.speed_m_s += accel * dt;
        self.steps_since_baro = self.steps_since_baro.saturating_add(1);

        let thrust = if thrust.is_finite() { crate::math::limit(thrust, 0.0, 1.0) } else { 0.0 };
        let pressure = pressure_pa.filter(|p| p.is_finite() && *p > 0.0).map(|p| p - self.cfg.thrust_scale_pa * thrust);
        let sample = pressure.and_then(|p| self.track(p).map(|dt_b| (p, dt_b)));
        if on_ground {
            self.apply(-self.height_m, dt);
            self.inertial_steps = 0;
        } else {
            if self.on_ground {
                self.reference_pa = self.reference_pa.map(|_| self.average_pa);
                self.baro_offset_m = 0.0;
                self.inertial_steps = 1;
                self.off_floor_steps = 0;
                self.clear_steps = 0;
                self.inertial_less_baro_m = f32::NAN;
            }
            if self.inertial_steps > 0 {
                self.inertial(sample);
            } else if let Some((p, dt_b)) = sample {
                self.correct(p, dt_b, thrust);
            }
        }
        self.on_ground = on_ground;
        if !(self.height_m.is_finite() && self.speed_m_s.is_finite() && self.bias_m_s2.is_finite()) {
            // Only a configuration of absurd numbers gets here; start again from the reference.
            self.height_m = 0.0;
            self.speed_m_s = 0.0;
            self.bias_m_s2 = 0.0;
        }
        self.estimate()
    }

    /// Average a new (compensated) pressure for the re-zero; the very first sets the reference.
    /// The time since the previous sample, s, when there is a reference to correct against.
    fn track(&mut self, pressure_pa: f32) -> Option<f32> {
        let dt_b = (self.steps_since_baro as f32 * self.cfg.step_dt_s).min(MAX_CORRECTION_DT_S);
        self.steps_since_baro = 0;
        if self.reference_pa.is_none() {
            // Its level is the reference until a re-zero says otherwise.
            self.reference_pa = Some(pressure_pa);
            self.average_pa = pressure_pa;
            return None;
        }
        let alpha = dt_b / (self.cfg.zero_average_s + dt_b);
        self.average_pa += alpha * (pressure_pa - self.average_pa);
        Some(dt_b)
    }

    /// The first seconds after a lift-off: the barometer's height is off the true height by
    /// the props' wash at the thrust flown and by ground effect (which fades on the way up),
    /// some tenths of a metre either way on this airframe, while the accelerometer, its bias
    /// learned against the floor, drifts by `½·b·t²`, a centimetre or two in those seconds.
    /// So the estimate flies on the accelerometer alone (never below the floor), and once the
    /// drone is clear of the floor and settled, the barometer's height is offset to agree
    /// with it: the wash at the hover's thrust and what is left of ground effect taken out
    /// together. The thrust compensation parameter then covers changes of thrust.
    fn inertial(&mut self, sample: Option<(f32, f32)>) {
        if self.height_m < 0.0 {
            self.height_m = 0.0;
            self.speed_m_s = self.speed_m_s.max(0.0);
        }
        let clear = self.height_m >= LIFTOFF_CLEAR_M;
        if let (Some((p, dt_b)), true) = (sample, clear) {
            let diff = self.height_m - self.reference_pa.map_or(f32::NAN, |r| baro_height_m(p, r));
            if diff.is_finite() {
                let alpha = dt_b / (self.cfg.zero_average_s + dt_b);
                let avg = self.inertial_less_baro_m;
                self.inertial_less_baro_m = if avg.is_finite() { avg + alpha * (diff - avg) } else { diff };
            }
        }
        self.off_floor_steps += u32::from(self.height_m >= LIFTOFF_OFF_FLOOR_M);
        self.clear_steps += u32::from(clear);
        let dt = self.cfg.step_dt_s;
        let [t_s, off_s, clear_s] = [self.inertial_steps, self.off_floor_steps, self.clear_steps].map(|n| n as f32 * dt);
        if clear_s >= LIFTOFF_AVERAGE_S || off_s >= LIFTOFF_INERTIAL_MAX_S || t_s >= LIFTOFF_INERTIAL_LIMIT_S {
            if self.inertial_less_baro_m.is_finite() {
                self.baro_offset_m = self.inertial_less_baro_m;
            }
            self.inertial_steps = 0;
        } else {
            self.inertial_steps += 1;
        }
    }

    fn correct(&mut self, pressure_pa: f32, dt_b: f32, thrust: f32) {
        let Some(reference) = self.reference_pa else {
            return;
        };
        let baro_height = baro_height_m(pressure_pa, reference) + self.baro_offset_m;
        let innovation = baro_height - self.height_m;
        // NaN (a reference of absurd numbers) counts as outside.
        let inside_gate = innovation.abs() <= self.cfg.innovation_gate_m;
        if !inside_gate {
            self.gated_in_a_row = self.gated_in_a_row.saturating_add(1);
            if self.gated_in_a_row >= self.cfg.gate_reset_samples && baro_height.is_finite() {
                self.height_m = baro_height;
                self.gated_in_a_row = 0;
            }
            return;
        }
        self.gated_in_a_row = 0;
        let in_ground_effect = self.height_m < self.cfg.ground_effect_height_m && thrust >= self.cfg.ground_effect_min_thrust;
        let innovation =
            if in_ground_effect && innovation < 0.0 { (innovation + self.cfg.ground_effect_dead_zone_m).min(0.0) } else { innovation };
        self.apply(innovation, dt_b);
    }

    /// The filter's correction by a height innovation, m, over `dt_s`.
    fn apply(&mut self, innovation_m: f32, dt_s: f32) {
        let e = innovation_m * dt_s;
        let [k1, k2, k3] = self.k;
        self.height_m += k1 * e;
        self.speed_m_s += k2 * e;
        let max_bias = self.cfg.max_accel_bias_m_s2;
        self.bias_m_s2 = crate::math::limit(self.bias_m_s2 - k3 * e, -max_bias, max_bias);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P0: f32 = 101_325.0;
    const STEPS_PER_S: usize = 160;

    /// The pressure at height `h` above the P0 level (the formula solved for p).
    fn pressure_at(h_m: f32) -> f32 {
        (f64::from(P0) * (1.0 - f64::from(h_m) / 44_330.77).powf(1.0 / 0.190_263)) as f32
    }

    /// Deterministic noise, uniform in ±amp (an LCG's high bits).
    struct Noise(u32);
    impl Noise {
        fn next(&mut self, amp: f32) -> f32 {
            self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            ((self.0 >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0) * amp
        }
    }

    /// A barometer sample on 75 of the 160 steps a second, as the part's ODR gives them.
    fn baro_due(step: usize) -> bool {
        (step * 75) / 160 != ((step + 1) * 75) / 160
    }

    /// An estimator referenced at the P0 level and at rest there.
    fn at_ground() -> AltitudeEstimator {
        let mut est = AltitudeEstimator::new(AltitudeConfig::DEFAULT);
        for _ in 0..16 {
            est.update(0.0, Some(P0), 0.0, false);
        }
        assert!(est.rezero());
        est
    }

    #[test]
    fn the_isa_height_matches_the_formula_and_pascals_per_metre() {
        assert_eq!(baro_height_m(P0, P0), 0.0);
        // Near the ground a metre is about 12 Pa.
        let h = baro_height_m(P0 - 12.01, P0);
        assert!((h - 1.0).abs() < 0.01, "{h}");
        let h = baro_height_m(pressure_at(100.0), P0);
        assert!((h - 100.0).abs() < 0.05, "{h}");
        assert!(baro_height_m(-1.0, P0).is_nan());
        assert!(baro_height_m(P0, 0.0).is_nan());
        // The series against the formula in f64, from 500 m below to 1000 m above.
        for h in [-500.0f32, -100.0, -1.0, 0.5, 10.0, 100.0, 500.0, 1000.0] {
            let p = pressure_at(h);
            let exact = 44_330.77 * (1.0 - (f64::from(p) / f64::from(P0)).powf(0.190_263));
            let got = f64::from(baro_height_m(p, P0));
            assert!((got - exact).abs() < 0.02 + 1e-5 * exact.abs(), "{h}: {got} {exact}");
        }
    }

    #[test]
    fn vertical_acceleration_is_the_earth_z_of_the_rotated_accelerometer() {
        // Level at rest: no acceleration.
        assert!(vertical_accel_m_s2(Quat::IDENTITY, Vec3::new(0.0, 0.0, 1000.0)).abs() < 1e-6);
        // Tilted 30° about X, hovering with 1.2 g of thrust along body Z: 1.2·cos 30° − 1 g up.
        let q = Quat::from_axis_angle(Vec3::new(1.0, 0.0, 0.0), 30f32.to_radians());
        let a = vertical_accel_m_s2(q, Vec3::new(0.0, 0.0, 1200.0));
        let expected = (1.2 * 30f32.to_radians().cos() - 1.0) * GRAVITY_M_S2;
        assert!((a - expected).abs() < 1e-4, "{a} {expected}");
        // The same as rotating the whole vector.
        let q = Quat::new(0.9, 0.2, -0.3, 0.25).normalized();
        let v = Vec3::new(120.0, -340.0, 950.0);
        let full = (q.rotate(v).z * 0.001 - 1.0) * GRAVITY_M_S2;
        assert!((vertical_accel_m_s2(q, v) - full).abs() < 1e-5);
    }

    #[test]
    fn the_first_sample_references_and_rezero_needs_one() {
        let mut est = AltitudeEstimator::new(AltitudeConfig::DEFAULT);
        assert!(!est.rezero());
        assert!(!est.estimate().referenced);
        est.update(0.0, Some(P0), 0.0, false);
        assert!(est.estimate().referenced);
        assert!(est.rezero());
    }

    #[test]
    fn converges_on_a_step_of_the_barometer() {
        let mut est = at_ground();
        let p = pressure_at(1.0);
        let mut at_5_tau = 0.0;
        let tau = AltitudeConfig::DEFAULT.time_constant_s;
        for step in 0..(12.0 * tau) as usize * STEPS_PER_S {
            let e = est.update(0.0, baro_due(step).then_some(p), 0.5, false);
            if step == (5.0 * tau * STEPS_PER_S as f32) as usize {
                at_5_tau = e.height_m;
            }
        }
        // Three poles at −1/τ: within a tenth after 5τ, settled after 12τ.
        assert!((at_5_tau - 1.0).abs() < 0.1, "after 5τ: {at_5_tau}");
        let e = est.estimate();
        assert!((e.height_m - 1.0).abs() < 0.005 && e.vertical_speed_m_s.abs() < 0.005, "{e:?}");
    }

    #[test]
    fn tracks_a_climb_with_a_noisy_barometer() {
        let mut est = at_ground();
        let mut noise = Noise(7);
        let (mut h, mut v) = (0.0f32, 0.0f32);
        let dt = 1.0 / STEPS_PER_S as f32;
        let mut worst = 0.0f32;
        for step in 0..10 * STEPS_PER_S {
            let t = step as f32 * dt;
            // 1 s accelerating at 1 m/s², 3 s at 1 m/s, 1 s braking, then hovering at 4 m.
            let a = if t < 1.0 {
                1.0
            } else if (4.0..5.0).contains(&t) {
                -1.0
            } else {
                0.0
            };
            h += (v + 0.5 * a * dt) * dt;
            v += a * dt;
            // The datasheet's 0.75 Pa RMS: uniform ±1.3 Pa has that RMS.
            let p = baro_due(step).then(|| pressure_at(h) + noise.next(1.3));
            let e = est.update(a + noise.next(0.05), p, 0.4, false);
            worst = worst.max((e.height_m - h).abs());
        }
        let e = est.estimate();
        assert!(worst < 0.08, "worst height error {worst}");
        assert!((h - 4.0).abs() < 1e-3, "{h}");
        assert!((e.height_m - h).abs() < 0.05 && e.vertical_speed_m_s.abs() < 0.05, "{e:?}");
    }

    #[test]
    fn a_baro_spike_is_rejected_and_a_lasting_jump_is_followed() {
        let mut est = at_ground();
        for step in 0..STEPS_PER_S {
            let p = if step == 80 { pressure_at(10.0) } else { P0 };
            est.update(0.0, baro_due(step).then_some(p), 0.5, false);
        }
        assert!(est.estimate().height_m.abs() < 1e-3, "{:?}", est.estimate());
        // The same 10 m held for over a second: the estimate was wrong, it moves.
        for step in 0..2 * STEPS_PER_S {
            est.update(0.0, baro_due(step).then_some(pressure_at(10.0)), 0.5, false);
        }
        assert!((est.estimate().height_m - 10.0).abs() < 0.5, "{:?}", est.estimate());
    }

    #[test]
    fn an_accelerometer_bias_is_learned() {
        let mut est = at_ground();
        // The accelerometer says 0.3 m/s² up while the drone stays at the P0 level (motors
        // stopped: no ground effect either).
        for step in 0..60 * STEPS_PER_S {
            est.update(0.3, baro_due(step).then_some(P0), 0.0, false);
        }
        let e = est.estimate();
        assert!((e.accel_bias_m_s2 - 0.3).abs() < 0.01, "{e:?}");
        assert!(e.height_m.abs() < 0.01 && e.vertical_speed_m_s.abs() < 0.01, "{e:?}");
        // Kept by a re-zero.
        assert!(est.rezero());
        assert!((est.estimate().accel_bias_m_s2 - 0.3).abs() < 0.01);
    }

    #[test]
    fn the_thrust_scale_takes_the_prop_wash_off_the_reading() {
        // The props raise the pressure at the sensor by 6 Pa at full thrust: at half thrust an
        // uncompensated estimate sinks by a quarter metre.
        let wash = |thrust: f32| P0 + 6.0 * thrust;
        let run = |scale: f32| {
            // Ground-effect handling off (thrust never reaches 2), so only the wash is seen.
            let cfg = AltitudeConfig { thrust_scale_pa: scale, ground_effect_min_thrust: 2.0, ..AltitudeConfig::DEFAULT };
            let mut est = AltitudeEstimator::new(cfg);
            for step in 0..16 {
                est.update(0.0, baro_due(step).then_some(wash(0.0)), 0.0, false);
            }
            est.rezero();
            for step in 0..20 * STEPS_PER_S {
                est.update(0.0, baro_due(step).then_some(wash(0.5)), 0.5, false);
            }
            est.estimate().height_m
        };
        assert!(run(0.0) < -0.2, "{}", run(0.0));
        assert!(run(6.0).abs() < 0.005, "{}", run(6.0));
    }

    #[test]
    fn near_the_floor_with_motors_running_a_low_reading_is_ignored_and_a_climb_is_not() {
        // Ground effect: at the floor the wash raises the pressure as if 0.25 m lower.
        let after_2_s = |p: f32, thrust: f32| {
            let mut est = at_ground();
            for step in 0..2 * STEPS_PER_S {
                est.update(0.0, baro_due(step).then_some(p), thrust, false);
            }
            est.estimate().height_m
        };
        let sink = pressure_at(-0.25);
        let stopped = after_2_s(sink, 0.0);
        let spinning = after_2_s(sink, 0.5);
        assert!(stopped < -0.2, "motors stopped: the barometer is believed, {stopped}");
        assert_eq!(spinning, 0.0, "in ground effect");
        // A reading beyond the dead zone counts for the part beyond it (inside the zone the
        // accelerometer alone carries the estimate, so the speed the correction gave carries on
        // a little).
        let deep = after_2_s(pressure_at(-0.75), 0.5);
        assert!((-0.6..-0.2).contains(&deep), "{deep}");
        assert!(deep > after_2_s(pressure_at(-0.75), 0.0) + 0.1, "{deep}");
        // The barometer rising (a take-off) is followed as ever (up to the overshoot back
        // down, which the zone leaves alone).
        let rise = after_2_s(pressure_at(0.25), 0.5);
        assert!((rise - after_2_s(pressure_at(0.25), 0.0)).abs() < 0.1 && rise > 0.2, "{rise}");
        // Above the ground-effect height the barometer counts fully again.
        let mut est = at_ground();
        for step in 0..(12.0 * AltitudeConfig::DEFAULT.time_constant_s) as usize * STEPS_PER_S {
            est.update(0.0, baro_due(step).then_some(pressure_at(1.0)), 0.5, false);
        }
        assert!((est.estimate().height_m - 1.0).abs() < 0.01, "{:?}", est.estimate());
    }

    /// Spin-up on the floor then a climb to 1 m, with the props' wash making the barometer
    /// read 5 Pa low (0.4 m high) from the spin-up on. Returns the worst height error after
    /// the spin-up and the largest height seen while on the floor.
    fn take_off(tell_on_ground: bool) -> (f32, f32) {
        let mut est = at_ground();
        let mut on_floor_max = 0.0f32;
        for step in 0..2 * STEPS_PER_S {
            let e = est.update(0.0, baro_due(step).then_some(P0 - 5.0), 0.4, tell_on_ground);
            on_floor_max = on_floor_max.max(e.height_m.abs());
        }
        let (mut h, mut v, mut worst) = (0.0f32, 0.0f32, 0.0f32);
        let dt = 1.0 / STEPS_PER_S as f32;
        for step in 0..6 * STEPS_PER_S {
            let a = match step / STEPS_PER_S {
                0 => 1.0,
                1 => -1.0,
                _ => 0.0,
            };
            h += (v + 0.5 * a * dt) * dt;
            v += a * dt;
            let e = est.update(a, baro_due(step).then_some(pressure_at(h) - 5.0), 0.4, false);
            worst = worst.max((e.height_m - h).abs());
        }
        (worst, on_floor_max)
    }

    #[test]
    fn on_the_ground_the_floor_is_the_height_and_lift_off_takes_the_wash_out() {
        let (told, told_on_floor) = take_off(true);
        assert!(told_on_floor < 1e-3, "{told_on_floor}");
        assert!(told < 0.02, "{told}");
        // Without the hint the wash reads as a jump on the floor and stays in the height.
        let (blind, blind_on_floor) = take_off(false);
        assert!(blind_on_floor > 0.3 && blind > 0.3, "{blind_on_floor} {blind}");
    }

    /// The simulator's barometer errors with the thrust: a prop wash of `wash_pa` at full
    /// thrust (either sign) and a ground effect of `ground_pa` at full thrust on the floor,
    /// fading within 0.1 m. Spin-up on the floor at 20 % thrust, a lift-off and a climb to 1 m
    /// at the hover's 40 %, then 20 s of hover: the estimate's mean error over the hover, m,
    /// and the barometer's own (referenced at the lift-off) for comparison.
    fn hover_after_lift_off(wash_pa: f32, ground_pa: f32) -> (f32, f32) {
        let mut est = at_ground();
        let mut noise = Noise(5);
        let reading = |h: f32, u: f32, n: f32| pressure_at(h) + wash_pa * u + ground_pa * u / (1.0 + (h / 0.1) * (h / 0.1)) + n;
        for step in 0..2 * STEPS_PER_S {
            est.update(noise.next(0.05), baro_due(step).then_some(reading(0.0, 0.2, noise.next(1.0))), 0.2, true);
        }
        let (mut h, mut v) = (0.0f32, 0.0f32);
        let dt = 1.0 / STEPS_PER_S as f32;
        let (mut est_error, mut baro_error, mut n) = (0.0, 0.0, 0.0);
        for step in 0..24 * STEPS_PER_S {
            // 1 m/s² for 0.5 s, 0.5 m/s for 1.5 s, −1 m/s² for 0.5 s: 1 m.
            let a = match step * 2 / STEPS_PER_S {
                0 => 1.0,
                1..=3 => 0.0,
                4 => -1.0,
                _ => 0.0,
            };
            h += (v + 0.5 * a * dt) * dt;
            v += a * dt;
            let p = reading(h, 0.4, noise.next(1.0));
            let e = est.update(a + noise.next(0.05), baro_due(step).then_some(p), 0.4, false);
            if step >= 4 * STEPS_PER_S {
                est_error += e.height_m - h;
                baro_error += baro_height_m(p, est.reference_pa.unwrap_or(f32::NAN)) - h;
                n += 1.0;
            }
        }
        (est_error / n, baro_error / n)
    }

    #[test]
    fn after_the_lift_off_the_barometer_is_re_referenced_to_the_accelerometers_height() {
        for (wash, ground) in [(15.0, 10.0), (-15.0, 10.0), (3.0, 0.0), (-3.0, 2.0)] {
            let (est, baro) = hover_after_lift_off(wash, ground);
            // The wash at hover against the spin-up's and the ground effect in the lift-off's
            // reference: tenths of a metre for the barometer alone; the estimate a centimetre.
            assert!(est.abs() < 0.02, "wash {wash} Pa, ground {ground} Pa: estimate {est} m off (barometer {baro} m)");
            if wash == 15.0 || wash == -15.0 {
                assert!(baro.abs() > 0.05, "wash {wash} Pa: the barometer alone only {baro} m off");
            }
        }
    }

    #[test]
    fn a_lift_off_declared_on_the_floor_keeps_the_height_at_the_floor() {
        // The hold's take-off ramp says airborne at three quarters of its hover throttle; a
        // heavy airframe is still on the floor there, while the wash grows with the ramp.
        let mut est = at_ground();
        for step in 0..STEPS_PER_S {
            est.update(0.0, baro_due(step).then_some(P0), 0.1, true);
        }
        let mut noise = Noise(9);
        let mut highest = 0.0f32;
        for step in 0..3 * STEPS_PER_S {
            let u = 0.1 + 0.3 * step as f32 / (3 * STEPS_PER_S) as f32;
            let e = est.update(noise.next(0.05), baro_due(step).then_some(P0 - 12.0 * u), u, false);
            highest = highest.max(e.height_m);
        }
        // The barometer alone would say 0.3 m.
        assert!(highest < 0.03, "{highest}");
    }

    #[test]
    fn on_the_ground_the_accelerometer_bias_is_learned_from_the_floor() {
        let mut est = at_ground();
        // No barometer at all: the floor alone teaches the bias.
        for _ in 0..60 * STEPS_PER_S {
            est.update(0.3, None, 0.0, true);
        }
        let e = est.estimate();
        assert!((e.accel_bias_m_s2 - 0.3).abs() < 0.01 && e.height_m.abs() < 0.01, "{e:?}");
    }

    #[test]
    fn rezero_makes_the_current_level_zero() {
        let mut est = at_ground();
        for step in 0..20 * STEPS_PER_S {
            est.update(0.0, baro_due(step).then_some(pressure_at(2.0)), 0.0, false);
        }
        assert!((est.estimate().height_m - 2.0).abs() < 0.01);
        assert!(est.rezero());
        for step in 0..STEPS_PER_S {
            est.update(0.0, baro_due(step).then_some(pressure_at(2.0)), 0.0, false);
        }
        let e = est.estimate();
        assert!(e.height_m.abs() < 0.01 && e.vertical_speed_m_s.abs() < 0.01, "{e:?}");
    }

    #[test]
    fn a_new_time_constant_keeps_the_estimate_and_moves_the_poles() {
        let mut est = at_ground();
        for step in 0..20 * STEPS_PER_S {
            est.update(0.0, baro_due(step).then_some(pressure_at(1.0)), 0.0, false);
        }
        let before = est.estimate();
        est.set_config(&AltitudeConfig { time_constant_s: 3.0, ..AltitudeConfig::DEFAULT });
        assert_eq!(est.estimate(), before);
        assert_eq!(est.k, AltitudeEstimator::new(AltitudeConfig { time_constant_s: 3.0, ..AltitudeConfig::DEFAULT }).k);
    }

    #[test]
    fn bad_inputs_never_make_the_estimate_non_finite() {
        let mut est = at_ground();
        for (a, p, u) in
            [(f32::NAN, Some(P0), 0.5), (0.0, Some(f32::NAN), f32::NAN), (0.0, Some(-5.0), 2.0), (f32::INFINITY, Some(0.0), -1.0)]
        {
            for _ in 0..10 {
                let e = est.update(a, p, u, false);
                assert!(e.height_m.is_finite() && e.vertical_speed_m_s.is_finite() && e.accel_bias_m_s2.is_finite(), "{e:?}");
            }
        }
        // A configuration of zeros (τ = 0 gives infinite gains) still gives finite numbers.
        let mut est = AltitudeEstimator::new(AltitudeConfig { time_constant_s: 0.0, ..AltitudeConfig::DEFAULT });
        for step in 0..100 {
            let e = est.update(1.0, baro_due(step).then_some(P0 + step as f32), 0.5, false);
            assert!(e.height_m.is_finite() && e.vertical_speed_m_s.is_finite(), "{e:?}");
        }
    }
}
