//! The simulated STEVAL-DRONE01 airframe: a rigid quad X with four brushed DC motors.
//!
//! Frames and signs are the core's (`docs/reference.md#frames`): body +X right, +Y forward, +Z up;
//! the attitude quaternion rotates body vectors into the earth frame (earth +Z up). Motor numbering
//! and spin follow the reference mixer (`docs/reference.md#motors`):
//!
//! ```text
//!            front (+Y)
//!      M3 (CW)      M2 (CCW)
//!            \      /
//!             +----+        +X right
//!            /      \
//!      M4 (CCW)     M1 (CW)
//! ```
//!
//! A propeller spinning clockwise (seen from above) pushes the airframe counter-clockwise, so
//! M1/M3 make a positive (CCW) yaw torque and M2/M4 a negative one.
//!
//! Everything runs in f64: the plant is the "truth", and its integration error must stay far
//! below anything the f32 controller could notice.

use super::rng::Rng;

pub type V3 = [f64; 3];

/// Standard gravity, m/s². Also the accelerometer's g.
pub const GRAVITY_M_S2: f64 = 9.80665;

/// The duty the motors run at with the throttle stick just off the bottom: the throttle
/// map's offset (633.3 of 2000 compare counts, the reference's DC build, which the default
/// profile keeps).
pub const LOWEST_RUNNING_DUTY: f64 = 633.333 / 2000.0;

/// Every physical constant of the simulated drone, in one place. Nominal values are the
/// estimates of `docs/simulation.md#the-drone`; [`PlantParams::randomized`] spreads them for
/// robustness tests.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantParams {
    pub mass_kg: f64,
    /// Centre to each motor axis (quad X: each motor sits at 45° between the body axes).
    pub arm_length_m: f64,
    /// Principal moments about body X, Y, Z.
    pub inertia_kg_m2: V3,
    /// Static thrust of one motor at 100 % duty on a full (4.2 V) battery.
    pub motor_max_thrust_n: f64,
    /// First-order lag of a brushed 8520 motor's speed.
    pub motor_tau_s: f64,
    /// Thrust fraction vs duty `d`: `quad·d² + lin·d` (fitted curve of the DC build).
    pub thrust_curve_quad: f64,
    pub thrust_curve_lin: f64,
    /// Reaction (yaw) torque per newton of thrust.
    pub yaw_torque_per_thrust_m: f64,
    /// Per-motor thrust multiplier (1.0 = healthy; 0.85 = a motor 15 % weaker).
    pub motor_thrust_scale: [f64; 4],
    /// Compare value at 100 % duty (TIM4 ARR + 1, DC build).
    pub pwm_full_scale_counts: f64,
    /// Battery open-circuit voltage when full and when empty.
    pub battery_full_v: f64,
    pub battery_empty_v: f64,
    pub battery_capacity_c: f64,
    pub battery_internal_resistance_ohm: f64,
    /// Current one motor draws at full thrust (current scales with its thrust).
    pub motor_current_at_max_thrust_a: f64,
    /// Linear air drag on the velocity relative to the air, N per m/s.
    pub drag_linear_n_per_m_s: f64,
    /// Rotational damping (props and air), N·m per rad/s.
    pub drag_angular_nm_per_rad_s: f64,
    /// Vibration on the accelerometer at full motor speed (before the sensor's low-pass), g.
    pub vibration_accel_g: f64,
    /// Motor electrical frequency at full speed (8520 motors: ~40 000 rpm), Hz.
    pub motor_full_speed_hz: f64,
    /// Propeller radius (ground effect), m.
    pub rotor_radius_m: f64,
    /// Height of the propeller discs above the floor when the drone sits on it, m.
    pub rotor_height_m: f64,
}

impl Default for PlantParams {
    fn default() -> Self {
        PlantParams {
            mass_kg: 0.065,
            arm_length_m: 0.065,
            inertia_kg_m2: [7.0e-5, 7.0e-5, 1.3e-4],
            motor_max_thrust_n: 0.33,
            motor_tau_s: 0.07,
            thrust_curve_quad: -0.33,
            thrust_curve_lin: 1.32,
            yaw_torque_per_thrust_m: 0.0084,
            motor_thrust_scale: [1.0; 4],
            pwm_full_scale_counts: 2000.0,
            battery_full_v: 4.2,
            battery_empty_v: 3.7,
            // A 250 mAh 1S pack.
            battery_capacity_c: 0.25 * 3600.0,
            battery_internal_resistance_ohm: 0.05,
            motor_current_at_max_thrust_a: 1.6,
            drag_linear_n_per_m_s: 0.02,
            drag_angular_nm_per_rad_s: 2.0e-6,
            vibration_accel_g: 0.3,
            motor_full_speed_hz: 660.0,
            // 65 mm propellers, their discs some 3 cm above the floor on the landing feet.
            rotor_radius_m: 0.0325,
            rotor_height_m: 0.03,
        }
    }
}

impl PlantParams {
    /// The nominal drone with each physical estimate scaled by an independent factor in
    /// `1 ± spread` (the tests use ±30 %, `docs/simulation.md#the-drone`). Same seed, same drone.
    ///
    /// Two guards, as a drone outside them tests the airframe, not the controller:
    /// - one that cannot hover on a sagging battery with 30 % margin: the motors' maximum
    ///   thrust is raised until it can;
    /// - one that climbs at the lowest running throttle: the throttle map runs the motors at
    ///   [`LOWEST_RUNNING_DUTY`] as soon as the stick leaves the bottom, and an airframe that
    ///   hovers below it (strong motors on a light frame) can only climb or cut its motors, with
    ///   the stick, altitude hold or the failsafe's descent alike. Its maximum thrust is lowered
    ///   until it hovers 10 % above that (on a full battery, where the hover needs least).
    pub fn randomized(seed: u64, spread: f64) -> Self {
        let spread = if spread.is_finite() { spread.clamp(0.0, 0.9) } else { 0.0 };
        let mut r = Rng::fork(seed, 0x0050_4C41_4E54);
        let mut k = || 1.0 + spread * r.symmetric();
        let n = PlantParams::default();
        let mut p = PlantParams {
            mass_kg: n.mass_kg * k(),
            arm_length_m: n.arm_length_m * k(),
            inertia_kg_m2: [n.inertia_kg_m2[0] * k(), n.inertia_kg_m2[1] * k(), n.inertia_kg_m2[2] * k()],
            motor_max_thrust_n: n.motor_max_thrust_n * k(),
            motor_tau_s: n.motor_tau_s * k(),
            yaw_torque_per_thrust_m: n.yaw_torque_per_thrust_m * k(),
            drag_linear_n_per_m_s: n.drag_linear_n_per_m_s * k(),
            drag_angular_nm_per_rad_s: n.drag_angular_nm_per_rad_s * k(),
            vibration_accel_g: n.vibration_accel_g * k(),
            ..n
        };
        let sagged = (p.battery_empty_v / p.battery_full_v).powi(2);
        let needed_n = 1.3 * p.mass_kg * GRAVITY_M_S2 / (4.0 * sagged);
        if p.motor_max_thrust_n < needed_n {
            p.motor_max_thrust_n = needed_n;
        }
        let lowest_running = 1.1 * p.thrust_fraction(LOWEST_RUNNING_DUTY);
        if p.hover_fraction(p.battery_full_v) < lowest_running {
            p.motor_max_thrust_n = p.mass_kg * GRAVITY_M_S2 / (4.0 * lowest_running);
        }
        p
    }

    /// Thrust multiplier of ground effect with the drone's reference point `height_m` above
    /// the floor: Cheeseman and Bennett's `1 / (1 − (R / 4z)²)`, `z` the rotor discs' height,
    /// with the formula's value at `z = 8R` (where it is 1.001) taken off its `(R / 4z)²` so
    /// that the effect ends there, continuously: the formula is an in-ground-effect fit, and
    /// beyond four diameters the air is the open air's. 1.08 sitting on the floor (nominal),
    /// 1.003 at 0.1 m, exactly 1 from some 0.23 m up. The formula's pole (z = R/4) lies far
    /// below the discs' lowest point; the ratio is bounded all the same so that no state can
    /// make the thrust infinite.
    pub fn ground_effect_factor(&self, height_m: f64) -> f64 {
        let r = self.rotor_radius_m.max(0.0);
        let z = (if height_m.is_finite() { height_m.max(0.0) } else { 0.0 } + self.rotor_height_m).max(1e-3);
        let ratio = |z: f64| (r / (4.0 * z)).powi(2);
        let excess = (ratio(z) - ratio(8.0 * r)).max(0.0);
        if excess.is_finite() {
            1.0 / (1.0 - excess.min(0.5))
        } else {
            1.0
        }
    }

    /// Motor positions in the body frame (x right, y forward), M1..M4.
    pub fn motor_positions_m(&self) -> [[f64; 2]; 4] {
        let a = self.arm_length_m * std::f64::consts::FRAC_1_SQRT_2;
        [[a, -a], [a, a], [-a, a], [-a, -a]]
    }

    /// Yaw reaction sign per motor: +1 for a clockwise prop (M1, M3), −1 for CCW (M2, M4).
    pub const MOTOR_YAW_SIGN: [f64; 4] = [1.0, -1.0, 1.0, -1.0];

    /// Steady-state thrust fraction of F_max at duty `d` on a full battery.
    pub fn thrust_fraction(&self, duty: f64) -> f64 {
        let d = if duty.is_finite() { duty.clamp(0.0, 1.0) } else { 0.0 };
        (self.thrust_curve_quad * d * d + self.thrust_curve_lin * d).max(0.0)
    }

    /// The duty at which one healthy motor carries a quarter of the weight at `battery_v`
    /// (used by the simulated pilot, who knows roughly where hover is).
    pub fn hover_duty(&self, battery_v: f64) -> f64 {
        self.duty_for_fraction(self.hover_fraction(battery_v))
    }

    /// Thrust fraction (of F_max on a full battery, before voltage scaling) one motor needs to
    /// carry a quarter of the weight at `battery_v`.
    pub fn hover_fraction(&self, battery_v: f64) -> f64 {
        let v = (battery_v / self.battery_full_v).max(0.1);
        self.mass_kg * GRAVITY_M_S2 / (4.0 * self.motor_max_thrust_n * v * v)
    }

    /// Inverse of [`thrust_fraction`](Self::thrust_fraction), clamped to duty 0..1.
    pub fn duty_for_fraction(&self, f: f64) -> f64 {
        let f = if f.is_finite() { f.max(0.0) } else { 0.0 };
        // Solve quad·d² + lin·d − f = 0 for the root in [0, 1].
        let (a, b) = (self.thrust_curve_quad, self.thrust_curve_lin);
        let disc = b * b + 4.0 * a * f;
        if a.abs() < 1e-12 {
            return (f / b).clamp(0.0, 1.0);
        }
        if disc < 0.0 {
            return 1.0;
        }
        ((-b + disc.sqrt()) / (2.0 * a)).clamp(0.0, 1.0)
    }
}

/// Outside pushes on the airframe: wind (drag acts on the velocity relative to it) and a
/// direct force and torque (a gust hitting one side of the props).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Disturbance {
    pub wind_earth_m_s: V3,
    pub force_earth_n: V3,
    pub torque_body_nm: V3,
}

/// The plant's state. Public so tests and scenarios can start it anywhere.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantState {
    pub pos_earth_m: V3,
    pub vel_earth_m_s: V3,
    /// Body-to-earth attitude quaternion (w, x, y, z), Hamilton.
    pub quat: [f64; 4],
    pub rate_body_rad_s: V3,
    /// Each motor's speed as a fraction of its full-battery, full-duty speed.
    pub motor_speed: [f64; 4],
    /// Charge drawn from the battery so far.
    pub battery_used_c: f64,
    /// Terminal voltage at the last step (sags with current).
    pub battery_v: f64,
    /// Sitting on the ground (z = 0, not climbing).
    pub on_ground: bool,
}

/// What the sensors need from the last step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Kinematics {
    /// Specific force (what an accelerometer measures) in body axes, m/s².
    pub specific_force_body_m_s2: V3,
    pub rate_body_rad_s: V3,
    /// Mean motor speed fraction (drives the vibration model).
    pub mean_motor_speed: f64,
}

/// The simulated airframe, motors and battery.
#[derive(Clone, Debug)]
pub struct Plant {
    pub params: PlantParams,
    pub state: PlantState,
    /// Duty of each motor, held constant between control ticks (the TIM4 compare register).
    duty: [f64; 4],
    kin: Kinematics,
    /// A touchdown being felt by the accelerometer.
    impact: Option<Impact>,
}

/// How long the landing feet take to stop a touchdown, s: the plant stops at once on its
/// rigid floor, the accelerometer feels the stop spread over this (a few millimetres of the
/// feet's give at landing speeds), so that what it integrates is the true change of speed.
pub const IMPACT_S: f64 = 0.02;

/// A touchdown's deceleration still to be felt.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Impact {
    remaining_s: f64,
    /// Upward, m/s².
    up_m_s2: f64,
}

/// Derivative of the integrated part of the state (position, velocity, attitude, rates, motors).
#[derive(Clone, Copy, Debug)]
struct Deriv {
    pos: V3,
    vel: V3,
    quat: [f64; 4],
    rate: V3,
    motor: [f64; 4],
}

impl Plant {
    /// A level drone resting on the ground with a full battery and stopped motors.
    pub fn new(params: PlantParams) -> Self {
        let v = params.battery_full_v;
        Plant {
            params,
            state: PlantState {
                pos_earth_m: [0.0; 3],
                vel_earth_m_s: [0.0; 3],
                quat: [1.0, 0.0, 0.0, 0.0],
                rate_body_rad_s: [0.0; 3],
                motor_speed: [0.0; 4],
                battery_used_c: 0.0,
                battery_v: v,
                on_ground: true,
            },
            duty: [0.0; 4],
            kin: Kinematics { specific_force_body_m_s2: [0.0, 0.0, GRAVITY_M_S2], ..Kinematics::default() },
            impact: None,
        }
    }

    /// Latch new compare values (0..full scale, as written to TIM4); held until the next call.
    pub fn set_compare(&mut self, compare: [u16; 4]) {
        for (d, c) in self.duty.iter_mut().zip(compare) {
            *d = (f64::from(c) / self.params.pwm_full_scale_counts).clamp(0.0, 1.0);
        }
    }

    pub fn duty(&self) -> [f64; 4] {
        self.duty
    }

    pub fn kinematics(&self) -> Kinematics {
        self.kin
    }

    /// Thrust of each motor now (ground effect included), N.
    pub fn motor_thrust_n(&self) -> [f64; 4] {
        self.thrusts(&self.state)
    }

    /// Advance by `dt_s` with one classic RK4 step (duty and disturbance held), then the
    /// battery and the ground contact.
    pub fn step(&mut self, dt_s: f64, dist: &Disturbance) {
        let s0 = self.state.clone();
        let volt_scale = (s0.battery_v / self.params.battery_full_v).max(0.0);
        let k1 = self.deriv(&s0, volt_scale, dist);
        let s1 = add_scaled(&s0, &k1, 0.5 * dt_s);
        let k2 = self.deriv(&s1, volt_scale, dist);
        let s2 = add_scaled(&s0, &k2, 0.5 * dt_s);
        let k3 = self.deriv(&s2, volt_scale, dist);
        let s3 = add_scaled(&s0, &k3, dt_s);
        let k4 = self.deriv(&s3, volt_scale, dist);
        let mut sum = k1;
        for (k, w) in [(&k2, 2.0), (&k3, 2.0), (&k4, 1.0)] {
            sum = deriv_axpy(&sum, k, w);
        }
        let mut s = add_scaled(&s0, &sum, dt_s / 6.0);
        s.quat = quat_normalize(s.quat);

        // Battery: charge drawn and the sag of the internal resistance.
        let thrust_frac: f64 = s.motor_speed.iter().map(|w| w * w).sum();
        let current_a = self.params.motor_current_at_max_thrust_a * thrust_frac;
        s.battery_used_c += current_a * dt_s;
        let soc = (1.0 - s.battery_used_c / self.params.battery_capacity_c).clamp(0.0, 1.0);
        let ocv = self.params.battery_empty_v + soc * (self.params.battery_full_v - self.params.battery_empty_v);
        s.battery_v = (ocv - current_a * self.params.battery_internal_resistance_ohm).max(0.0);

        // Ground: the drone rests flat on a rigid floor at z = 0 until its thrust lifts it.
        let deriv_end = self.deriv(&s, volt_scale, dist);
        s.on_ground = false;
        if s.pos_earth_m[2] <= 0.0 && (s.vel_earth_m_s[2] <= 0.0 || deriv_end.vel[2] <= 0.0) {
            if !s0.on_ground && s.vel_earth_m_s[2] < 0.0 {
                // The touchdown: the feet stop the fall over IMPACT_S, and the accelerometer
                // feels that deceleration (the whole change of speed), as a real one does.
                self.impact = Some(Impact { remaining_s: IMPACT_S, up_m_s2: -s.vel_earth_m_s[2] / IMPACT_S });
            }
            s.pos_earth_m[2] = 0.0;
            s.vel_earth_m_s = [0.0; 3];
            s.rate_body_rad_s = [0.0; 3];
            s.quat = yaw_only(s.quat);
            s.on_ground = true;
        }
        // Felt to the end even if the thrust lifts the drone off again at once (a bounce): the
        // floor took the whole fall's speed.
        let impact_m_s2 = match self.impact {
            Some(i) => {
                let felt = i.up_m_s2 * (i.remaining_s.min(dt_s) / dt_s);
                let remaining_s = i.remaining_s - dt_s;
                self.impact = (remaining_s > 0.0).then_some(Impact { remaining_s, ..i });
                felt
            }
            None => {
                self.impact = None;
                0.0
            }
        };

        // What the IMU feels: all non-gravitational forces, in body axes.
        let specific = if s.on_ground {
            quat_rotate_inverse(s.quat, [0.0, 0.0, GRAVITY_M_S2 + impact_m_s2])
        } else {
            let mut a_earth = self.non_gravity_force_earth(&s, dist).map(|f| f / self.params.mass_kg);
            a_earth[2] += impact_m_s2;
            quat_rotate_inverse(s.quat, a_earth)
        };
        self.kin = Kinematics {
            specific_force_body_m_s2: specific,
            rate_body_rad_s: s.rate_body_rad_s,
            mean_motor_speed: s.motor_speed.iter().sum::<f64>() / 4.0,
        };
        self.state = s;
    }

    /// Each motor's thrust in state `s`, ground effect included, N.
    fn thrusts(&self, s: &PlantState) -> [f64; 4] {
        let p = &self.params;
        let ground = p.ground_effect_factor(s.pos_earth_m[2]);
        let mut t = [0.0; 4];
        for ((t, &w), &k) in t.iter_mut().zip(&s.motor_speed).zip(&p.motor_thrust_scale) {
            *t = p.motor_max_thrust_n * k * w * w * ground;
        }
        t
    }

    /// The collective thrust as a fraction of full: the mean of the motors' speed² (each
    /// motor's thrust over its full-battery, full-duty thrust, before ground effect). What the
    /// barometer's prop-wash and ground-effect errors scale with.
    pub fn collective_thrust_fraction(&self) -> f64 {
        self.state.motor_speed.iter().map(|w| w * w).sum::<f64>() / 4.0
    }

    fn non_gravity_force_earth(&self, s: &PlantState, dist: &Disturbance) -> V3 {
        let total_thrust: f64 = self.thrusts(s).iter().sum();
        let thrust_earth = quat_rotate(s.quat, [0.0, 0.0, total_thrust]);
        let mut f = [0.0; 3];
        for i in 0..3 {
            let rel = s.vel_earth_m_s[i] - dist.wind_earth_m_s[i];
            f[i] = thrust_earth[i] - self.params.drag_linear_n_per_m_s * rel + dist.force_earth_n[i];
        }
        f
    }

    fn deriv(&self, s: &PlantState, volt_scale: f64, dist: &Disturbance) -> Deriv {
        let p = &self.params;
        let thrusts = self.thrusts(s);
        let f = self.non_gravity_force_earth(s, dist);
        let vel = [f[0] / p.mass_kg, f[1] / p.mass_kg, f[2] / p.mass_kg - GRAVITY_M_S2];

        // Torques: r × (0, 0, T) = (y·T, −x·T, 0), plus the props' reaction about Z.
        let mut torque = dist.torque_body_nm;
        for ((pos, &t), &sign) in p.motor_positions_m().iter().zip(&thrusts).zip(&PlantParams::MOTOR_YAW_SIGN) {
            torque[0] += pos[1] * t;
            torque[1] -= pos[0] * t;
            torque[2] += sign * p.yaw_torque_per_thrust_m * t;
        }
        let w = s.rate_body_rad_s;
        let i = p.inertia_kg_m2;
        let iw = [i[0] * w[0], i[1] * w[1], i[2] * w[2]];
        let gyro = cross(w, iw);
        let mut rate = [0.0; 3];
        for k in 0..3 {
            rate[k] = (torque[k] - gyro[k] - p.drag_angular_nm_per_rad_s * w[k]) / i[k];
        }

        let q = s.quat;
        let omega = [0.0, w[0], w[1], w[2]];
        let qd = quat_mul(q, omega).map(|c| 0.5 * c);

        // Brushed motor: speed settles where its thrust fraction matches the duty curve,
        // scaled by the battery voltage (thrust ∝ speed², speed ∝ voltage).
        let mut motor = [0.0; 4];
        for ((m, &spd), &d) in motor.iter_mut().zip(&s.motor_speed).zip(&self.duty) {
            let target = volt_scale * p.thrust_fraction(d).sqrt();
            *m = (target - spd) / p.motor_tau_s.max(1e-4);
        }
        Deriv { pos: s.vel_earth_m_s, vel, quat: qd, rate, motor }
    }

    /// Someone holds the drone and turns it at `rate_body_rad_s` (no flight physics: the hand
    /// wins). Used to disturb a calibration; the next [`step`](Plant::step) on the floor puts
    /// it back flat.
    pub fn carry(&mut self, dt_s: f64, rate_body_rad_s: V3) {
        let s = &mut self.state;
        let w = rate_body_rad_s;
        let angle = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt() * dt_s;
        if angle > 0.0 {
            s.quat = quat_normalize(quat_mul(s.quat, quat_from_axis_angle(w, angle)));
        }
        s.rate_body_rad_s = w;
        s.vel_earth_m_s = [0.0; 3];
        s.on_ground = true;
        self.kin = Kinematics {
            specific_force_body_m_s2: quat_rotate_inverse(s.quat, [0.0, 0.0, GRAVITY_M_S2]),
            rate_body_rad_s: w,
            mean_motor_speed: s.motor_speed.iter().sum::<f64>() / 4.0,
        };
    }

    /// Attitude as the core reports it: (pitch about X, roll about Y, yaw about Z), rad.
    pub fn euler_rad(&self) -> (f64, f64, f64) {
        euler_of(self.state.quat)
    }
}

/// Pitch (about body X), roll (about body Y) with the reference's formulas, and the heading.
pub fn euler_of(q: [f64; 4]) -> (f64, f64, f64) {
    let [q0, q1, q2, q3] = q;
    let pitch = (2.0 * (q0 * q1 + q2 * q3)).atan2(q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3);
    let roll = (2.0 * (q0 * q2 - q1 * q3)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (q1 * q2 + q0 * q3)).atan2(q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3);
    (pitch, roll, yaw)
}

/// `s + h·d` for the integrated parts of the state.
fn add_scaled(s: &PlantState, d: &Deriv, h: f64) -> PlantState {
    let mut o = s.clone();
    axpy_fields([&mut o.pos_earth_m, &mut o.vel_earth_m_s, &mut o.rate_body_rad_s], [&d.pos, &d.vel, &d.rate], h);
    axpy_fields([&mut o.quat, &mut o.motor_speed], [&d.quat, &d.motor], h);
    o
}

/// `a + w·b` for derivatives (the RK4 weighted sum).
fn deriv_axpy(a: &Deriv, b: &Deriv, w: f64) -> Deriv {
    let mut o = *a;
    axpy_fields([&mut o.pos, &mut o.vel, &mut o.rate], [&b.pos, &b.vel, &b.rate], w);
    axpy_fields([&mut o.quat, &mut o.motor], [&b.quat, &b.motor], w);
    o
}

/// `y += h·x`, field by field, element by element.
fn axpy_fields<const N: usize, const F: usize>(ys: [&mut [f64; N]; F], xs: [&[f64; N]; F], h: f64) {
    for (y, x) in ys.into_iter().zip(xs) {
        for (y, x) in y.iter_mut().zip(x) {
            *y += h * x;
        }
    }
}

pub fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

pub fn quat_normalize(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    if n > 1e-12 && n.is_finite() {
        q.map(|c| c / n)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    }
}

/// Body vector → earth.
pub fn quat_rotate(q: [f64; 4], v: V3) -> V3 {
    let p = quat_mul(quat_mul(q, [0.0, v[0], v[1], v[2]]), [q[0], -q[1], -q[2], -q[3]]);
    [p[1], p[2], p[3]]
}

/// Earth vector → body.
pub fn quat_rotate_inverse(q: [f64; 4], v: V3) -> V3 {
    quat_rotate([q[0], -q[1], -q[2], -q[3]], v)
}

pub fn quat_from_axis_angle(axis: V3, angle_rad: f64) -> [f64; 4] {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt().max(1e-12);
    let (s, c) = (0.5 * angle_rad).sin_cos();
    [c, s * axis[0] / n, s * axis[1] / n, s * axis[2] / n]
}

/// The heading part of an attitude (what is left when the drone sits flat on the floor).
fn yaw_only(q: [f64; 4]) -> [f64; 4] {
    let (_, _, yaw) = euler_of(q);
    quat_from_axis_angle([0.0, 0.0, 1.0], yaw)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn airborne(params: PlantParams) -> Plant {
        let mut p = Plant::new(params);
        p.state.pos_earth_m = [0.0, 0.0, 10.0];
        p.state.on_ground = false;
        p
    }

    /// Fly `secs` with fixed compare values, starting with motors at their steady speed.
    fn fly(p: &mut Plant, compare: [u16; 4], secs: f64) {
        p.set_compare(compare);
        for (spd, d) in p.state.motor_speed.iter_mut().zip(p.duty) {
            *spd = p.params.thrust_fraction(d).sqrt();
        }
        let dt = 1.0 / 4000.0;
        for _ in 0..(secs / dt) as usize {
            p.step(dt, &Disturbance::default());
        }
    }

    #[test]
    fn thrust_curve_matches_product_spec() {
        let p = PlantParams::default();
        assert!((p.thrust_fraction(0.5) - (-0.33 * 0.25 + 0.66)).abs() < 1e-12);
        assert_eq!(p.thrust_fraction(0.0), 0.0);
        assert_eq!(p.thrust_fraction(f64::NAN), 0.0);
        let d = p.hover_duty(4.2);
        let f = p.thrust_fraction(d) * 4.0 * p.motor_max_thrust_n;
        assert!((f - p.mass_kg * GRAVITY_M_S2).abs() < 1e-9, "hover thrust {f}");
        assert!(d > 0.3 && d < 0.5, "nominal hover duty {d}");
    }

    #[test]
    fn resting_drone_stays_on_the_ground_and_feels_one_g() {
        let mut p = Plant::new(PlantParams::default());
        for _ in 0..4000 {
            p.step(0.00025, &Disturbance::default());
        }
        assert!(p.state.on_ground);
        assert_eq!(p.state.pos_earth_m, [0.0; 3]);
        let f = p.kinematics().specific_force_body_m_s2;
        assert!((f[2] - GRAVITY_M_S2).abs() < 1e-9 && f[0].abs() < 1e-9);
    }

    #[test]
    fn full_throttle_lifts_off_and_zero_throttle_falls() {
        let mut p = Plant::new(PlantParams::default());
        p.set_compare([1900; 4]);
        for _ in 0..4000 {
            p.step(0.00025, &Disturbance::default());
        }
        assert!(p.state.pos_earth_m[2] > 0.5, "climbed to {}", p.state.pos_earth_m[2]);
        let mut q = airborne(PlantParams::default());
        q.step(0.00025, &Disturbance::default());
        assert!(q.state.vel_earth_m_s[2] < 0.0);
    }

    #[test]
    fn motor_speed_lags_with_its_time_constant() {
        let mut p = airborne(PlantParams::default());
        p.set_compare([2000; 4]);
        let tau = p.params.motor_tau_s;
        let dt = 0.00025;
        for _ in 0..(tau / dt).round() as usize {
            p.step(dt, &Disturbance::default());
        }
        let target = p.params.thrust_fraction(1.0).sqrt() * p.state.battery_v / p.params.battery_full_v;
        let frac = p.state.motor_speed[0] / target;
        // 1 − e⁻¹ = 0.632 after one time constant (battery sag moves the target a little).
        assert!((frac - 0.632).abs() < 0.03, "fraction after τ: {frac}");
    }

    /// The reference mixer (`docs/reference.md#motors`): positive roll demand raises M3/M4 and
    /// must roll right side down (positive about body Y); positive pitch raises M2/M3 → nose up
    /// (positive about X); positive yaw raises M1/M3 (CW props) → counter-clockwise (positive
    /// about Z).
    #[test]
    fn motor_numbering_and_spin_match_the_reference_mixer() {
        let base = 900.0;
        let delta = 60.0;
        // (pitch s2x, roll s2y, yaw s2z) → M1..M4 as the reference mixer writes them.
        let mix = |x: f64, y: f64, z: f64| -> [u16; 4] {
            [base - x - y + z, base + x - y - z, base + x + y + z, base - x + y - z].map(|m| m as u16)
        };
        let cases = [((0.0, delta, 0.0), 1usize), ((delta, 0.0, 0.0), 0), ((0.0, 0.0, delta), 2)];
        for ((x, y, z), axis) in cases {
            let mut p = airborne(PlantParams::default());
            fly(&mut p, mix(x, y, z), 0.3);
            let w = p.state.rate_body_rad_s;
            assert!(w[axis] > 0.05, "demand on axis {axis}: body rates {w:?}");
            for (k, &wk) in w.iter().enumerate() {
                if k != axis {
                    assert!(wk.abs() < 0.05 * w[axis].abs() + 1e-6, "cross-coupling on {k}: {w:?}");
                }
            }
            let (pitch, roll, yaw) = p.euler_rad();
            match axis {
                0 => assert!(pitch > 0.0, "nose up expected, pitch {pitch}"),
                1 => assert!(roll > 0.0, "right side down expected, roll {roll}"),
                _ => assert!(yaw > 0.0, "counter-clockwise expected, yaw {yaw}"),
            }
        }
    }

    #[test]
    fn weak_motor_makes_a_steady_torque() {
        let mut params = PlantParams::default();
        // M1 (rear-right, CW) weak: the rear drops (nose up), the right side drops (roll
        // positive) and the CCW props win the yaw (negative).
        params.motor_thrust_scale[0] = 0.85;
        let mut p = airborne(params);
        fly(&mut p, [900; 4], 0.2);
        let w = p.state.rate_body_rad_s;
        assert!(w[0] > 0.0 && w[1] > 0.0 && w[2] < 0.0, "rates {w:?}");
    }

    #[test]
    fn ground_effect_lifts_near_the_floor_and_fades_within_a_few_rotor_radii() {
        let p = PlantParams::default();
        let on_floor = p.ground_effect_factor(0.0);
        assert!(on_floor > 1.05 && on_floor < 1.15, "{on_floor}");
        assert!(p.ground_effect_factor(0.1) < on_floor && p.ground_effect_factor(0.1) > 1.002);
        assert_eq!(p.ground_effect_factor(0.3), 1.0, "the open air's thrust a few diameters up");
        assert!(p.ground_effect_factor(0.2) > 1.0 && p.ground_effect_factor(0.2) < 1.0005, "and it fades there continuously");
        assert_eq!(p.ground_effect_factor(-1.0), on_floor, "below the floor is the floor");
        assert!(p.ground_effect_factor(f64::NAN).is_finite());
        // The same duty lifts more at 5 cm than at 2 m.
        let accel_at = |h: f64| {
            let mut q = airborne(PlantParams::default());
            q.state.pos_earth_m[2] = h;
            fly(&mut q, [850; 4], 0.0);
            q.step(0.00025, &Disturbance::default());
            q.state.vel_earth_m_s[2]
        };
        assert!(accel_at(0.05) > accel_at(2.0) + 1e-5);
    }

    #[test]
    fn a_falling_drone_stops_on_the_floor_and_never_sinks_through_it() {
        let mut p = airborne(PlantParams::default());
        p.state.pos_earth_m[2] = 1.0;
        let dt = 0.00025;
        let mut fastest_down = 0.0f64;
        let (mut felt_m_s, mut hardest_m_s2) = (0.0, 0.0f64);
        for _ in 0..8000 {
            p.step(dt, &Disturbance::default());
            assert!(p.state.pos_earth_m[2] >= 0.0, "below the floor: {}", p.state.pos_earth_m[2]);
            fastest_down = fastest_down.max(-p.state.vel_earth_m_s[2]);
            let up = p.kinematics().specific_force_body_m_s2[2] - GRAVITY_M_S2;
            felt_m_s += up * dt;
            hardest_m_s2 = hardest_m_s2.max(up);
        }
        assert!(p.state.on_ground && p.state.pos_earth_m[2] == 0.0 && p.state.vel_earth_m_s == [0.0; 3]);
        // What the accelerometer felt over the fall and the stop (less the 1 g it feels at rest)
        // adds up to no change of speed: the touchdown's deceleration is in it, spread over the
        // feet's 20 ms.
        assert!(felt_m_s.abs() < 0.01, "the accelerometer integrates to {felt_m_s} m/s");
        assert!((hardest_m_s2 - fastest_down / IMPACT_S).abs() < 1.0, "{hardest_m_s2} m/s² at the stop");
        // A fall from 1 m less the drag: just under √(2 g h) = 4.43 m/s when it touches.
        assert!(fastest_down > 3.5 && fastest_down < 4.43, "{fastest_down}");
    }

    #[test]
    fn a_touchdown_that_bounces_off_at_once_is_still_felt_whole() {
        // Descending at 0.5 m/s onto the floor with more thrust than the weight (the hold near
        // the floor, ground effect on top): the floor takes the speed, the thrust lifts it again
        // within a substep, and what the accelerometer integrates is still the speed's change.
        let mut p = airborne(PlantParams::default());
        p.state.pos_earth_m[2] = 0.01;
        let duty = p.params.duty_for_fraction(1.1 * p.params.hover_fraction(p.state.battery_v));
        fly(&mut p, [(duty * 2000.0) as u16; 4], 0.0);
        p.state.vel_earth_m_s[2] = -0.5;
        let dt = 0.00025;
        let mut felt_m_s = 0.0;
        let mut touched = false;
        for _ in 0..400 {
            p.step(dt, &Disturbance::default());
            touched |= p.state.pos_earth_m[2] == 0.0;
            let k = p.kinematics().specific_force_body_m_s2;
            felt_m_s += (k[2] - GRAVITY_M_S2) * dt;
        }
        assert!(touched, "never reached the floor");
        let change = p.state.vel_earth_m_s[2] + 0.5;
        assert!((felt_m_s - change).abs() < 0.02, "felt {felt_m_s:.3} m/s, the speed changed by {change:.3} m/s");
    }

    #[test]
    fn randomized_is_seeded_bounded_and_can_hover() {
        let a = PlantParams::randomized(3, 0.3);
        assert_eq!(a, PlantParams::randomized(3, 0.3));
        assert_ne!(a, PlantParams::randomized(4, 0.3));
        for seed in 0..50 {
            let p = PlantParams::randomized(seed, 0.3);
            let n = PlantParams::default();
            assert!(p.mass_kg >= 0.7 * n.mass_kg && p.mass_kg <= 1.3 * n.mass_kg);
            assert!(p.hover_duty(p.battery_empty_v) < 0.95, "seed {seed} cannot hover");
            assert!(p.hover_duty(p.battery_full_v) > LOWEST_RUNNING_DUTY, "seed {seed} climbs at the lowest running throttle");
        }
    }

    #[test]
    fn energy_is_conserved_in_free_rotation() {
        // No torque, no damping: the rotational kinetic energy of a tumbling body is constant,
        // which checks the RK4 step and the gyroscopic term together.
        let params = PlantParams { drag_angular_nm_per_rad_s: 0.0, inertia_kg_m2: [5e-5, 7e-5, 1.3e-4], ..PlantParams::default() };
        let mut p = airborne(params);
        p.state.rate_body_rad_s = [3.0, 0.2, 1.0];
        p.state.pos_earth_m[2] = 1000.0; // it falls freely meanwhile; keep it off the floor
        let energy = |p: &Plant| -> f64 {
            let (w, i) = (p.state.rate_body_rad_s, p.params.inertia_kg_m2);
            0.5 * (i[0] * w[0] * w[0] + i[1] * w[1] * w[1] + i[2] * w[2] * w[2])
        };
        let e0 = energy(&p);
        for _ in 0..8000 {
            p.step(0.00025, &Disturbance::default());
        }
        let w = p.state.rate_body_rad_s;
        assert!((energy(&p) - e0).abs() / e0 < 1e-6, "energy drift");
        assert!((w[1] - 0.2).abs() > 1e-3, "the gyroscopic term did nothing: {w:?}");
    }
}
