//! The simulated LSM6DSL in the reference configuration (`docs/reference.md#sensors`):
//! accelerometer ±4 g at 0.122 mg/LSB behind its 16.65 Hz low-pass (LPF2, ODR/400), gyroscope
//! ±2000 dps at 70 mdps/LSB sampled at 416 Hz and held between samples, each with bias and noise,
//! motor vibration on the accelerometer, and the board's mount: the words come out in **sensor**
//! axes, exactly what the core reads off the SPI bus.

use fcu_core::imu::{Mount, RawImu};

use super::plant::{Kinematics, GRAVITY_M_S2};
use super::rng::Rng;

/// Sensor imperfections and rates. Defaults follow the LSM6DSL datasheet's typical values
/// (noise densities 80 µg/√Hz and 4 mdps/√Hz, zero-g offset ±40 mg, zero-rate level ±10 dps
/// max, here drawn smaller because a typical part is well inside the maximum).
#[derive(Clone, Debug, PartialEq)]
pub struct ImuModelParams {
    pub accel_mg_per_lsb: f64,
    pub gyro_mdps_per_lsb: f64,
    pub accel_lowpass_hz: f64,
    pub gyro_odr_hz: f64,
    /// Noise of one accel word (after the low-pass), mg rms.
    pub accel_noise_mg: f64,
    /// Noise of one gyro sample, mdps rms.
    pub gyro_noise_mdps: f64,
    /// Biases are drawn uniformly within ± these, per axis, from the seed.
    pub accel_bias_max_mg: f64,
    pub gyro_bias_max_mdps: f64,
    /// Scale of the plant's vibration amplitude (0 switches vibration off).
    pub vibration_gain: f64,
    pub mount: Mount,
}

impl Default for ImuModelParams {
    fn default() -> Self {
        ImuModelParams {
            accel_mg_per_lsb: 0.122,
            gyro_mdps_per_lsb: 70.0,
            accel_lowpass_hz: 16.65,
            gyro_odr_hz: 416.0,
            accel_noise_mg: 1.5,
            gyro_noise_mdps: 80.0,
            accel_bias_max_mg: 30.0,
            gyro_bias_max_mdps: 1500.0,
            vibration_gain: 1.0,
            mount: Mount::STEVAL_FCU001,
        }
    }
}

impl ImuModelParams {
    /// A perfect sensor (no noise, bias or vibration): for tests of the rest of the chain.
    pub fn ideal() -> Self {
        ImuModelParams {
            accel_noise_mg: 0.0,
            gyro_noise_mdps: 0.0,
            accel_bias_max_mg: 0.0,
            gyro_bias_max_mdps: 0.0,
            vibration_gain: 0.0,
            ..ImuModelParams::default()
        }
    }
}

/// How hard the motors shake the board (from the plant's parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vibration {
    /// Acceleration amplitude at full motor speed, g (before the sensor's low-pass).
    pub amplitude_g_at_full_speed: f64,
    /// Rotation frequency at full speed, Hz.
    pub full_speed_hz: f64,
}

impl Vibration {
    pub const NONE: Vibration = Vibration { amplitude_g_at_full_speed: 0.0, full_speed_hz: 0.0 };
}

/// The sensor's internal state between reads.
#[derive(Clone, Debug)]
pub struct ImuModel {
    params: ImuModelParams,
    rng: Rng,
    accel_bias_mg: [f64; 3],
    gyro_bias_mdps: [f64; 3],
    /// Output of the accelerometer low-pass, body axes, mg.
    accel_filtered_mg: [f64; 3],
    filter_primed: bool,
    vibration_phase_rad: f64,
    /// The last 416 Hz gyro sample, body axes, mdps.
    gyro_held_mdps: [f64; 3],
    time_to_next_gyro_sample_s: f64,
    /// Ones the test wants to break the sensor: words stop changing (a stuck sensor).
    frozen: Option<RawImu>,
}

impl ImuModel {
    pub fn new(params: ImuModelParams, seed: u64) -> Self {
        let mut rng = Rng::fork(seed, 0x0049_4D55);
        let accel_bias_mg = [0; 3].map(|_: i32| params.accel_bias_max_mg * rng.symmetric());
        let gyro_bias_mdps = [0; 3].map(|_: i32| params.gyro_bias_max_mdps * rng.symmetric());
        ImuModel {
            params,
            rng,
            accel_bias_mg,
            gyro_bias_mdps,
            accel_filtered_mg: [0.0; 3],
            filter_primed: false,
            vibration_phase_rad: 0.0,
            gyro_held_mdps: [0.0; 3],
            time_to_next_gyro_sample_s: 0.0,
            frozen: None,
        }
    }

    pub fn params(&self) -> &ImuModelParams {
        &self.params
    }

    /// Advance the sensor's own clocks and filters by `dt_s` with the plant's motion.
    /// Call once per plant substep, so the filter and the 416 Hz sampling see the motion at
    /// the plant's rate and not only at the control rate.
    pub fn step(&mut self, dt_s: f64, kin: &Kinematics, vibration: Vibration) {
        let p = &self.params;
        let to_mg = 1000.0 / GRAVITY_M_S2;
        // Vibration: the motors' imbalance shakes the board at their rotation frequency, mostly
        // vertically; amplitude grows with speed².
        let speed = kin.mean_motor_speed.clamp(0.0, 2.0);
        self.vibration_phase_rad =
            (self.vibration_phase_rad + std::f64::consts::TAU * vibration.full_speed_hz * speed * dt_s) % std::f64::consts::TAU;
        let vib_mg = 1000.0 * p.vibration_gain * vibration.amplitude_g_at_full_speed * speed * speed;
        let ph = self.vibration_phase_rad;
        let vibration = [0.3 * vib_mg * (ph + 1.0).sin(), 0.3 * vib_mg * (ph + 2.0).sin(), vib_mg * ph.sin()];

        let mut input = [0.0; 3];
        for k in 0..3 {
            input[k] = kin.specific_force_body_m_s2[k] * to_mg + vibration[k];
        }
        if !self.filter_primed {
            self.accel_filtered_mg = input;
            self.filter_primed = true;
        } else {
            let alpha = 1.0 - (-std::f64::consts::TAU * p.accel_lowpass_hz * dt_s).exp();
            for (f, i) in self.accel_filtered_mg.iter_mut().zip(input) {
                *f += alpha * (i - *f);
            }
        }

        self.time_to_next_gyro_sample_s -= dt_s;
        if self.time_to_next_gyro_sample_s <= 0.0 {
            self.time_to_next_gyro_sample_s += 1.0 / p.gyro_odr_hz.max(1.0);
            let noise = p.gyro_noise_mdps;
            for k in 0..3 {
                let mdps = kin.rate_body_rad_s[k].to_degrees() * 1000.0;
                self.gyro_held_mdps[k] = mdps + self.gyro_bias_mdps[k] + noise * self.rng.gaussian();
            }
        }
    }

    /// The words the core would read now: accel fresh (6.66 kHz ODR), gyro held.
    pub fn read(&mut self) -> RawImu {
        if let Some(w) = self.frozen {
            return w;
        }
        let p = &self.params;
        let mut accel_body = [0.0f32; 3];
        let mut gyro_body = [0.0f32; 3];
        for k in 0..3 {
            let a = self.accel_filtered_mg[k] + self.accel_bias_mg[k] + p.accel_noise_mg * self.rng.gaussian();
            accel_body[k] = (a / p.accel_mg_per_lsb) as f32;
            gyro_body[k] = (self.gyro_held_mdps[k] / p.gyro_mdps_per_lsb) as f32;
        }
        let accel = p.mount.body_to_sensor_f32(accel_body);
        let gyro = p.mount.body_to_sensor_f32(gyro_body);
        RawImu { accel: accel.map(quantize), gyro: gyro.map(quantize) }
    }

    /// Make the sensor stick at its current words (a fault-injection hook).
    pub fn freeze(&mut self) {
        let w = self.read();
        self.frozen = Some(w);
    }
}

/// Round to the nearest LSB and saturate at the i16 range, as the sensor's ADC does.
fn quantize(lsb: f32) -> i16 {
    if lsb.is_nan() {
        return 0;
    }
    // `as` saturates float→int casts.
    lsb.round() as i16
}

#[cfg(test)]
mod tests {
    use super::*;

    fn still() -> Kinematics {
        Kinematics { specific_force_body_m_s2: [0.0, 0.0, GRAVITY_M_S2], ..Kinematics::default() }
    }

    fn settle(m: &mut ImuModel, kin: &Kinematics, secs: f64) {
        for _ in 0..(secs * 4000.0) as usize {
            m.step(0.00025, kin, Vibration::NONE);
        }
    }

    #[test]
    fn level_and_still_reads_one_g_on_sensor_z() {
        let mut m = ImuModel::new(ImuModelParams::ideal(), 1);
        settle(&mut m, &still(), 0.2);
        let r = m.read();
        assert_eq!(r.accel[0], 0);
        assert_eq!(r.accel[1], 0);
        assert_eq!(r.accel[2], (1000.0f64 / 0.122).round() as i16);
        assert_eq!(r.gyro, [0; 3]);
    }

    #[test]
    fn mount_maps_body_axes_to_sensor_axes() {
        // body X = −sensor Y, body Y = +sensor X: a rate about body X shows on −sensor Y,
        // an acceleration along body Y on +sensor X.
        let mut m = ImuModel::new(ImuModelParams::ideal(), 1);
        let kin =
            Kinematics { specific_force_body_m_s2: [0.0, GRAVITY_M_S2, 0.0], rate_body_rad_s: [1.0, 0.0, 0.0], mean_motor_speed: 0.0 };
        settle(&mut m, &kin, 0.5);
        let r = m.read();
        let one_rad_s_lsb = (1.0f64.to_degrees() * 1000.0 / 70.0).round() as i16;
        assert_eq!(r.gyro, [0, -one_rad_s_lsb, 0]);
        assert!((i32::from(r.accel[0]) - 8197).abs() <= 1, "{:?}", r.accel);
        assert_eq!(r.accel[1], 0);
        // And the core's own mount turns it back.
        let body = fcu_core::imu::ImuConfig::REFERENCE.to_body(r);
        assert!(body.gyro_mdps[0] > 57_000 && body.accel_mg[1] > 990, "{body:?}");
    }

    #[test]
    fn words_saturate_at_the_full_scale() {
        let mut m = ImuModel::new(ImuModelParams::ideal(), 1);
        let kin = Kinematics {
            specific_force_body_m_s2: [0.0, 0.0, 10.0 * GRAVITY_M_S2],
            rate_body_rad_s: [0.0, 0.0, 100.0],
            mean_motor_speed: 0.0,
        };
        settle(&mut m, &kin, 0.5);
        let r = m.read();
        assert_eq!(r.accel[2], i16::MAX);
        assert_eq!(r.gyro[2], i16::MAX);
    }

    #[test]
    fn accel_low_pass_has_its_time_constant() {
        let mut m = ImuModel::new(ImuModelParams::ideal(), 1);
        settle(&mut m, &still(), 0.1);
        let step = Kinematics { specific_force_body_m_s2: [0.0, 0.0, 2.0 * GRAVITY_M_S2], ..still() };
        let tau_s = 1.0 / (std::f64::consts::TAU * 16.65);
        settle(&mut m, &step, tau_s);
        let mg = f64::from(m.read().accel[2]) * 0.122;
        // After one time constant: 1000 + 0.632·1000 mg.
        assert!((mg - 1632.0).abs() < 15.0, "{mg}");
    }

    #[test]
    fn gyro_is_sampled_at_416_hz_and_held() {
        let mut m = ImuModel::new(ImuModelParams::ideal(), 1);
        let mut changes = 0;
        let mut last = m.read().gyro;
        // A ramp of rate: every new sample differs, but only 416 of them arrive per second.
        for i in 0..4000 {
            let kin = Kinematics { rate_body_rad_s: [0.0, 0.0, f64::from(i) * 0.001], ..still() };
            m.step(0.00025, &kin, Vibration::NONE);
            let g = m.read().gyro;
            if g != last {
                changes += 1;
                last = g;
            }
        }
        assert!((410..=420).contains(&changes), "{changes} gyro updates in 1 s");
    }

    #[test]
    fn vibration_shakes_the_accel_only_when_motors_spin() {
        let spread = |speed: f64| {
            let mut m = ImuModel::new(ImuModelParams { accel_noise_mg: 0.0, ..ImuModelParams::ideal() }, 1);
            m.params.vibration_gain = 1.0;
            let kin = Kinematics { mean_motor_speed: speed, ..still() };
            settle(&mut m, &kin, 0.2);
            let mut lo = i16::MAX;
            let mut hi = i16::MIN;
            for _ in 0..400 {
                m.step(0.00025, &kin, Vibration { amplitude_g_at_full_speed: 0.3, full_speed_hz: 660.0 });
                let z = m.read().accel[2];
                lo = lo.min(z);
                hi = hi.max(z);
            }
            hi - lo
        };
        assert_eq!(spread(0.0), 0);
        assert!(spread(0.7) > 10, "vibration should reach the accel words");
    }

    #[test]
    fn seeds_change_bias_and_noise() {
        let mut a = ImuModel::new(ImuModelParams::default(), 1);
        let mut b = ImuModel::new(ImuModelParams::default(), 2);
        settle(&mut a, &still(), 0.05);
        settle(&mut b, &still(), 0.05);
        assert_ne!(a.read(), b.read());
    }
}
