//! The reference's Mahony complementary filter (`ahrs_fusion_ag`), with switches for its
//! quirks so the same code serves the bit-exact reference profile and a cleaner variant.
//! The filter is compiled in by the crate's `reference` feature; its configuration always is.

use crate::math::InvSqrt;
#[cfg(feature = "reference")]
use crate::math::{Quat, Vec3};

/// The reference's mdps → rad/s factor (a C double constant).
pub const MDPS_TO_RAD_S: f64 = 1.745_329_252e-5;

/// Mahony gains and numerics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MahonyConfig {
    /// Proportional gain while the throttle is low (fast levelling on the ground): 10.
    pub kp_low_throttle: f32,
    /// Proportional gain in flight: 0.4.
    pub kp_flight: f32,
    /// Integral gain: 0.1 (a C double literal in the reference, hence f64).
    pub ki: f64,
    /// Integration step, s: the reference's nominal 0.00625 (a C double).
    pub dt_s: f64,
    pub inv_sqrt: InvSqrt,
    /// The reference's sequential update: each quaternion component is integrated with the
    /// ones already updated above it.
    pub sequential_update: bool,
    /// Evaluate the reference's double-precision spots in f64 (gyro conversion, integral).
    pub reference_arithmetic: bool,
}

impl MahonyConfig {
    pub const REFERENCE: MahonyConfig = MahonyConfig {
        kp_low_throttle: 10.0,
        kp_flight: 0.4,
        ki: 0.1,
        dt_s: 0.00625,
        inv_sqrt: InvSqrt::Fast,
        sequential_update: true,
        reference_arithmetic: true,
    };

    pub fn is_valid(&self) -> bool {
        let finite = self.kp_low_throttle.is_finite() && self.kp_flight.is_finite() && self.ki.is_finite();
        finite && self.kp_low_throttle >= 0.0 && self.kp_flight >= 0.0 && self.ki >= 0.0 && self.dt_s > 0.0 && self.dt_s.is_finite()
    }
}

/// Mahony filter state: attitude and the integral of the correction (never reset, never
/// clamped in the reference).
#[cfg(feature = "reference")]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mahony {
    cfg: MahonyConfig,
    q: Quat,
    integral: Vec3,
    half_dt: f32,
}

#[cfg(feature = "reference")]
impl Mahony {
    pub fn new(cfg: MahonyConfig) -> Self {
        Mahony { cfg, q: Quat::IDENTITY, integral: Vec3::ZERO, half_dt: (0.5 * cfg.dt_s) as f32 }
    }

    pub fn quat(&self) -> Quat {
        self.q
    }

    pub fn integral(&self) -> Vec3 {
        self.integral
    }

    /// One update with the block-averaged accelerometer (mg, any scale) and gyro (mdps).
    /// `low_throttle` selects the big gain as the reference does (`gTHR < MIN_THR`).
    pub fn update(&mut self, accel_mg: [f32; 3], gyro_mdps: [f32; 3], low_throttle: bool) {
        let c = self.cfg;
        let kp = if low_throttle { c.kp_low_throttle } else { c.kp_flight };
        let to_rad = |v: f32| -> f32 {
            if c.reference_arithmetic {
                (f64::from(v) * MDPS_TO_RAD_S) as f32
            } else {
                v * (MDPS_TO_RAD_S as f32)
            }
        };
        let [gx0, gy0, gz0] = gyro_mdps.map(to_rad);
        let [mut ax, mut ay, mut az] = accel_mg;
        let recip = c.inv_sqrt.eval(ax * ax + ay * ay + az * az);
        ax *= recip;
        ay *= recip;
        az *= recip;

        let Quat { w: mut q0, x: mut q1, y: mut q2, z: mut q3 } = self.q;
        let q0q0 = q0 * q0;
        let q0q1 = q0 * q1;
        let q0q2 = q0 * q2;
        let q1q1 = q1 * q1;
        let q1q3 = q1 * q3;
        let q2q2 = q2 * q2;
        let q2q3 = q2 * q3;
        let q3q3 = q3 * q3;
        let vx = 2.0 * (q1q3 - q0q2);
        let vy = 2.0 * (q0q1 + q2q3);
        let vz = q0q0 - q1q1 - q2q2 + q3q3;
        let ex = ay * vz - az * vy;
        let ey = az * vx - ax * vz;
        let ez = ax * vy - ay * vx;

        let integrate = |i: f32, e: f32| -> f32 {
            if c.reference_arithmetic {
                (f64::from(i) + (f64::from(e) * c.ki) * c.dt_s) as f32
            } else {
                i + e * ((c.ki * c.dt_s) as f32)
            }
        };
        let ix = integrate(self.integral.x, ex);
        let iy = integrate(self.integral.y, ey);
        let iz = integrate(self.integral.z, ez);
        // A non-finite input must not poison the state: keep the last good one.
        if !(ix.is_finite() && iy.is_finite() && iz.is_finite()) {
            return;
        }

        let gx = gx0 + kp * ex + ix;
        let gy = gy0 + kp * ey + iy;
        let gz = gz0 + kp * ez + iz;
        let h = self.half_dt;
        if c.sequential_update {
            q0 += (-q1 * gx - q2 * gy - q3 * gz) * h;
            q1 += (q0 * gx + q2 * gz - q3 * gy) * h;
            q2 += (q0 * gy - q1 * gz + q3 * gx) * h;
            q3 += (q0 * gz + q1 * gy - q2 * gx) * h;
        } else {
            let (p0, p1, p2, p3) = (q0, q1, q2, q3);
            q0 = p0 + (-p1 * gx - p2 * gy - p3 * gz) * h;
            q1 = p1 + (p0 * gx + p2 * gz - p3 * gy) * h;
            q2 = p2 + (p0 * gy - p1 * gz + p3 * gx) * h;
            q3 = p3 + (p0 * gz + p1 * gy - p2 * gx) * h;
        }
        let recip = c.inv_sqrt.eval(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3);
        let q = Quat::new(q0 * recip, q1 * recip, q2 * recip, q3 * recip);
        if q.is_finite() && q.norm_squared() > 0.5 {
            self.q = q;
            self.integral = Vec3::new(ix, iy, iz);
        }
    }
}

#[cfg(all(test, feature = "reference"))]
mod tests {
    use super::*;
    use crate::math::quat_to_tilt;

    #[test]
    fn one_level_step_gives_the_reference_q0() {
        let mut m = Mahony::new(MahonyConfig::REFERENCE);
        m.update([0.0, 0.0, 1000.0], [0.0; 3], true);
        assert_eq!(m.quat().w, 0.998_307_17);
    }

    #[test]
    fn big_gain_levels_to_a_static_tilt() {
        // docs/reference.md#examples: 200 updates at kp 10 with a 10° tilt about X.
        let mut m = Mahony::new(MahonyConfig::REFERENCE);
        let t = 10f32.to_radians();
        for _ in 0..200 {
            m.update([0.0, 1000.0 * libm::sinf(t), 1000.0 * libm::cosf(t)], [0.0; 3], true);
        }
        let e = quat_to_tilt(m.quat());
        assert!((e.pitch_rad.to_degrees() - 10.01).abs() < 0.02, "{}", e.pitch_rad.to_degrees());
        assert!(e.roll_rad.abs() < 1e-6);
        assert!((m.integral().x - 0.00173).abs() < 0.0001, "{}", m.integral().x);
    }

    #[test]
    fn accel_pulls_back_a_pure_gyro_integral() {
        let mut m = Mahony::new(MahonyConfig::REFERENCE);
        for _ in 0..160 {
            m.update([0.0, 0.0, 1000.0], [10_000.0, 0.0, 0.0], false);
        }
        let p = quat_to_tilt(m.quat()).pitch_rad.to_degrees();
        assert!((p - 8.1).abs() < 0.1, "{p}");
    }

    #[test]
    fn a_nan_sample_leaves_the_state_untouched() {
        let mut m = Mahony::new(MahonyConfig::REFERENCE);
        m.update([0.0, 0.0, 1000.0], [100.0, 0.0, 0.0], false);
        let before = m;
        m.update([f32::NAN, 0.0, 1000.0], [0.0; 3], false);
        assert_eq!(m, before);
    }
}
