//! The default profile's attitude estimator: the 6D core of VQF (D. Laidig, T. Seel, "VQF:
//! Highly accurate IMU orientation estimation with bias estimation and magnetic disturbance
//! rejection", Information Fusion 91, 2023), implemented here in single precision.
//!
//! How it works: the gyro is integrated alone (strapdown) into a quasi-inertial frame; the
//! accelerometer, rotated into that frame, is low-passed there (2nd-order Butterworth, τ = 3 s),
//! where linear accelerations average out while gravity stays put; a separate inclination-only
//! correction tilts the filtered gravity onto the vertical. A rest detector and a small Kalman
//! filter estimate the gyro bias (at rest from the gyro itself, in motion from the inclination
//! corrections, horizontal axes only). No magnetometer, so the heading is free.
//!
//! Why this one: on the BROAD trials (every candidate measured in
//! `docs/estimator.md#why-this-estimator`), gating the accelerometer by its norm breaks the
//! zero-mean property the quasi-inertial low-pass relies on, so VQF's structure wins, and its
//! bias estimation is what beats a plain low-pass on the slow trials. [`VqfConfig::DEFAULT`]
//! changes two of VQF's bias parameters after a small sweep on those same trials: treat that
//! gain as tuning, not as a property of the method. A shorter forgetting time also suits the
//! drone, whose gyro bias moves with the board's temperature once the motors run.
//!
//! Why not the `vqf-rs` crate itself (MIT, no_std): its Butterworth filters always run in f64,
//! which the Cortex-M4 emulates in software, and its gyro step calls `sin`/`cos` every sample.
//! Here everything is f32: the filters use the state-variable form, accurate in f32 where the
//! direct form is not (poles within 1e-3 of z = 1), and the gyro exponential is a 4th-order
//! polynomial. Result identical to `vqf-rs` to 0.001° on all four trials.
//!
//! What an update costs, on the Cortex-M4 and as a proxy on the host, is in
//! `docs/performance.md`.
//!
//! The product runs it once per outer step at 160 Hz ([`VqfConfig::DEFAULT`]); any other rate is
//! [`VqfConfig::at_rate`]. Every time constant is in seconds, so the behaviour does not depend
//! on the rate.

use crate::math::{clamp_nan_low, Quat, Vec3};

/// mdps → rad/s: the one conversion of the crate (`ahrs::MDPS_TO_RAD_S`, the reference's constant), in f32.
const MDPS_TO_RAD_S: f32 = super::MDPS_TO_RAD_S as f32;
const DEG_TO_RAD: f32 = core::f32::consts::PI / 180.0;

/// VQF parameters. Times in seconds, rates in °/s, accelerations in mg.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VqfConfig {
    /// Sample period, s (one `update` per sample).
    pub dt_s: f32,
    /// Time constant of the accelerometer low-pass in the quasi-inertial frame, s: how long
    /// the filter averages linear accelerations away (VQF's default 3 s).
    pub tau_acc_s: f32,
    /// Estimate the gyro bias while at rest.
    pub rest_bias_estimation: bool,
    /// Time constant of the low-passes the rest detector compares samples with, s.
    pub rest_filter_tau_s: f32,
    /// Gyro deviation from its low-pass below which the IMU may be at rest, °/s.
    pub rest_th_gyr_dps: f32,
    /// Accelerometer deviation from its low-pass below which the IMU may be at rest, mg.
    pub rest_th_acc_mg: f32,
    /// How long both deviations must stay small before rest is declared, s.
    pub rest_min_s: f32,
    /// Largest gyro bias believed (and the clip of each bias update), °/s.
    pub bias_clip_dps: f32,
    /// Initial bias uncertainty (standard deviation), °/s.
    pub bias_sigma_init_dps: f32,
    /// Time in which the bias uncertainty grows from 0 to 0.1 °/s without updates, s.
    pub bias_forgetting_time_s: f32,
    /// Converged bias uncertainty from rest updates, °/s.
    pub bias_sigma_rest_dps: f32,
    /// Also estimate the bias while moving, from the inclination corrections (the horizontal
    /// components only: the vertical one is not observable without a magnetometer).
    pub motion_bias_estimation: bool,
    /// Converged bias uncertainty from motion updates, °/s.
    pub bias_sigma_motion_dps: f32,
    /// Relative weight of the artificial zero measurement that lets the unobservable vertical
    /// bias decay.
    pub bias_vertical_forgetting: f32,
}

impl VqfConfig {
    /// The product's configuration: one update per outer step at 160 Hz.
    pub const DEFAULT: VqfConfig = VqfConfig {
        dt_s: 0.00625,
        tau_acc_s: 3.0,
        rest_bias_estimation: true,
        rest_filter_tau_s: 0.5,
        rest_th_gyr_dps: 2.0,
        // VQF's 0.5 m/s².
        rest_th_acc_mg: 50.97,
        rest_min_s: 1.5,
        bias_clip_dps: 2.0,
        bias_sigma_init_dps: 0.5,
        // VQF's default is 100 s; 15 s lets the estimate follow a bias drifting with the
        // board's temperature and measured better on all four BROAD trials (module doc).
        bias_forgetting_time_s: 15.0,
        bias_sigma_rest_dps: 0.03,
        motion_bias_estimation: true,
        // VQF's default is 0.1 °/s; 0.15 trusts the motion updates a little less (module doc).
        bias_sigma_motion_dps: 0.15,
        bias_vertical_forgetting: 1e-4,
    };

    /// The default configuration at another sample period (BROAD: `at_rate(0.0035)`).
    pub const fn at_rate(dt_s: f32) -> VqfConfig {
        VqfConfig { dt_s, ..VqfConfig::DEFAULT }
    }

    pub fn is_valid(&self) -> bool {
        use crate::math::{above, within};
        let positive = |x: f32| above(x, 0.0, f32::MAX);
        positive(self.dt_s)
            && positive(self.tau_acc_s)
            && positive(self.rest_filter_tau_s)
            && positive(self.rest_th_gyr_dps)
            && positive(self.rest_th_acc_mg)
            && within(self.rest_min_s, 0.0, f32::MAX)
            && positive(self.bias_clip_dps)
            && positive(self.bias_sigma_init_dps)
            && positive(self.bias_forgetting_time_s)
            && positive(self.bias_sigma_rest_dps)
            && positive(self.bias_sigma_motion_dps)
            && positive(self.bias_vertical_forgetting)
            // The low-pass designs need their cut-off below Nyquist.
            && self.tau_acc_s > self.dt_s
            && self.rest_filter_tau_s > self.dt_s
    }
}

/// Second-order Butterworth low-pass (bilinear transform, the design VQF uses) in the
/// trapezoidal state-variable form. VQF evaluates its direct-form biquads in f64 because at a
/// 3 s time constant the poles sit within 1e-3 of z = 1, where f32 direct-form coefficients
/// are too coarse; the state-variable form keeps the small quantities (g, the states'
/// increments) explicit and is accurate in f32.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Svf {
    a1: f32,
    a2: f32,
    a3: f32,
}

impl Svf {
    fn new(tau_s: f32, dt_s: f32) -> Svf {
        // VQF: cut-off fc = √2 / (2π τ), the -3 dB point of a Butterworth whose step response
        // settles like a first-order lag of time constant τ.
        let fc_hz = core::f32::consts::SQRT_2 / (2.0 * core::f32::consts::PI * tau_s);
        let g = crate::math::tan_small(core::f32::consts::PI * fc_hz * dt_s);
        let k = core::f32::consts::SQRT_2;
        let a1 = 1.0 / (1.0 + g * (g + k));
        let a2 = g * a1;
        Svf { a1, a2, a3: g * a2 }
    }
}

/// A three-channel low-pass that starts from the mean of its first τ of samples (VQF's
/// initialisation: no dependence on a single first sample, no start-up transient).
#[derive(Clone, Copy, Debug, PartialEq)]
struct LowPass3 {
    coeffs: Svf,
    /// Samples needed before the filter takes over from the running mean.
    init_samples: u32,
    count: u32,
    /// The running sum while initialising, then the integrator states.
    ic1: Vec3,
    ic2: Vec3,
    out: Vec3,
}

impl LowPass3 {
    fn new(tau_s: f32, dt_s: f32) -> LowPass3 {
        // Saturating float → int cast; `is_valid` guarantees a sane ratio.
        let init_samples = libm::ceilf(tau_s / dt_s) as u32;
        LowPass3 {
            coeffs: Svf::new(tau_s, dt_s),
            init_samples: init_samples.max(1),
            count: 0,
            ic1: Vec3::ZERO,
            ic2: Vec3::ZERO,
            out: Vec3::ZERO,
        }
    }

    fn step(&mut self, x: Vec3) -> Vec3 {
        if self.count < self.init_samples {
            self.count += 1;
            self.ic2 = self.ic2.add(x);
            self.out = self.ic2.scale(1.0 / self.count as f32);
            if self.count == self.init_samples {
                // Steady state at the mean: no band-pass energy, low-pass state = mean.
                self.ic1 = Vec3::ZERO;
                self.ic2 = self.out;
            }
            return self.out;
        }
        let Svf { a1, a2, a3 } = self.coeffs;
        let chan = |x: f32, ic1: &mut f32, ic2: &mut f32| -> f32 {
            let v3 = x - *ic2;
            let v1 = a1 * *ic1 + a2 * v3;
            let v2 = *ic2 + a2 * *ic1 + a3 * v3;
            *ic1 = 2.0 * v1 - *ic1;
            *ic2 = 2.0 * v2 - *ic2;
            v2
        };
        self.out = Vec3::new(
            chan(x.x, &mut self.ic1.x, &mut self.ic2.x),
            chan(x.y, &mut self.ic1.y, &mut self.ic2.y),
            chan(x.z, &mut self.ic1.z, &mut self.ic2.z),
        );
        self.out
    }
}

/// A 3×3 matrix by rows (small, explicit, no indexing: the core must not panic).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Mat3 {
    r0: Vec3,
    r1: Vec3,
    r2: Vec3,
}

impl Mat3 {
    const IDENTITY: Mat3 = Mat3::diag(1.0, 1.0, 1.0);

    const fn diag(a: f32, b: f32, c: f32) -> Mat3 {
        Mat3 { r0: Vec3::new(a, 0.0, 0.0), r1: Vec3::new(0.0, b, 0.0), r2: Vec3::new(0.0, 0.0, c) }
    }

    /// The body → earth rotation matrix of a unit quaternion.
    fn from_quat(q: Quat) -> Mat3 {
        let Quat { w, x, y, z } = q;
        Mat3 {
            r0: Vec3::new(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (w * y + x * z)),
            r1: Vec3::new(2.0 * (w * z + x * y), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
            r2: Vec3::new(2.0 * (x * z - w * y), 2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)),
        }
    }

    fn transpose(self) -> Mat3 {
        let Mat3 { r0, r1, r2 } = self;
        Mat3 { r0: Vec3::new(r0.x, r1.x, r2.x), r1: Vec3::new(r0.y, r1.y, r2.y), r2: Vec3::new(r0.z, r1.z, r2.z) }
    }

    fn mul_vec(self, v: Vec3) -> Vec3 {
        Vec3::new(self.r0.dot(v), self.r1.dot(v), self.r2.dot(v))
    }

    fn mul(self, o: Mat3) -> Mat3 {
        let t = o.transpose();
        Mat3 { r0: t.mul_vec(self.r0), r1: t.mul_vec(self.r1), r2: t.mul_vec(self.r2) }
    }

    fn sub(self, o: Mat3) -> Mat3 {
        Mat3 { r0: self.r0.sub(o.r0), r1: self.r1.sub(o.r1), r2: self.r2.sub(o.r2) }
    }

    fn add_diag(self, d: Vec3) -> Mat3 {
        let Mat3 { r0, r1, r2 } = self;
        Mat3 { r0: Vec3::new(r0.x + d.x, r0.y, r0.z), r1: Vec3::new(r1.x, r1.y + d.y, r1.z), r2: Vec3::new(r2.x, r2.y, r2.z + d.z) }
    }

    /// The inverse by the adjugate; `None` when singular or not finite.
    fn inverse(self) -> Option<Mat3> {
        let Mat3 { r0, r1, r2 } = self;
        // Columns of the adjugate's transpose are the cross products of the rows.
        let c0 = r1.cross(r2);
        let c1 = r2.cross(r0);
        let c2 = r0.cross(r1);
        let det = r0.dot(c0);
        if !(det.is_finite() && det != 0.0) {
            return None;
        }
        let k = 1.0 / det;
        Some(Mat3 { r0: c0.scale(k), r1: c1.scale(k), r2: c2.scale(k) }.transpose())
    }
}

/// VQF state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vqf {
    cfg: VqfConfig,
    /// Pure gyro strapdown integration: body → quasi-inertial frame.
    gyr_q: Quat,
    /// Inclination correction: quasi-inertial → earth (z up).
    acc_q: Quat,
    /// `acc_q ⊗ gyr_q`, kept so `quat()` is free.
    q: Quat,
    /// Accelerometer low-pass in the quasi-inertial frame, mg.
    acc_lp: LowPass3,
    rest_gyr_lp: LowPass3,
    rest_acc_lp: LowPass3,
    /// The rotation matrix (by rows) and its product with the bias (x and y) low-passed like
    /// the accelerometer, so the motion bias update compares like with like.
    motion_r_lp: [LowPass3; 3],
    motion_bias_lp: LowPass3,
    rest_s: f32,
    rest: bool,
    /// Rest detection may run this update (the motors are off).
    rest_allowed: bool,
    /// Gyro bias estimate, rad/s.
    bias_rad_s: Vec3,
    /// Bias covariance, in (0.01 °/s)² (VQF's scaling: keeps the numbers near 1).
    bias_p: Mat3,
    bias_p0: f32,
    bias_v: f32,
    bias_rest_w: f32,
    bias_motion_w: f32,
    bias_vertical_w: f32,
}

impl Vqf {
    pub fn new(cfg: VqfConfig) -> Vqf {
        let sq = |x: f32| x * x;
        let bias_p0 = sq(cfg.bias_sigma_init_dps * 100.0);
        // The system noise raises the variance from 0 to (0.1 °/s)² in the forgetting time.
        let bias_v = sq(0.1 * 100.0) * cfg.dt_s / cfg.bias_forgetting_time_s;
        // Measurement variances chosen so the steady-state uncertainty is the configured σ.
        let p_rest = sq(cfg.bias_sigma_rest_dps * 100.0);
        let p_motion = sq(cfg.bias_sigma_motion_dps * 100.0);
        let bias_motion_w = sq(p_motion) / bias_v + p_motion;
        let acc_lp = LowPass3::new(cfg.tau_acc_s, cfg.dt_s);
        let rest_lp = LowPass3::new(cfg.rest_filter_tau_s, cfg.dt_s);
        Vqf {
            cfg,
            gyr_q: Quat::IDENTITY,
            acc_q: Quat::IDENTITY,
            q: Quat::IDENTITY,
            acc_lp,
            rest_gyr_lp: rest_lp,
            rest_acc_lp: rest_lp,
            motion_r_lp: [acc_lp; 3],
            motion_bias_lp: acc_lp,
            rest_s: 0.0,
            rest: false,
            rest_allowed: true,
            bias_rad_s: Vec3::ZERO,
            bias_p: Mat3::diag(bias_p0, bias_p0, bias_p0),
            bias_p0,
            bias_v,
            bias_rest_w: sq(p_rest) / bias_v + p_rest,
            bias_motion_w,
            bias_vertical_w: bias_motion_w / cfg.bias_vertical_forgetting.max(1e-10),
        }
    }

    /// Body-to-earth attitude, unit norm.
    pub fn quat(&self) -> Quat {
        self.q
    }

    /// Gyro bias estimate, rad/s.
    pub fn bias_rad_s(&self) -> Vec3 {
        self.bias_rad_s
    }

    /// Whether the rest detector currently sees the IMU at rest.
    pub fn rest_detected(&self) -> bool {
        self.rest
    }

    /// One update with the accelerometer (mg; only its direction and deviations matter) and the
    /// gyro (mdps), body axes. A non-finite or all-zero input leaves the state untouched.
    pub fn update(&mut self, accel_mg: [f32; 3], gyro_mdps: [f32; 3]) {
        self.update_gated(accel_mg, gyro_mdps, true);
    }

    /// [`update`](Vqf::update), with rest detection allowed only when `rest_possible`.
    ///
    /// On a multirotor the flight pipeline passes "throttle low" (motors stopped): a steady
    /// hover looks like rest to the detector (steady accelerometer, small gyro) while the craft
    /// may be turning slowly, and a rest update would take that real rotation for gyro bias
    /// (the drift it gives in flight is measured in `docs/estimator.md`).
    pub fn update_gated(&mut self, accel_mg: [f32; 3], gyro_mdps: [f32; 3], rest_possible: bool) {
        if !rest_possible {
            self.rest_s = 0.0;
            self.rest = false;
        }
        self.rest_allowed = rest_possible;
        let acc = Vec3::from_array(accel_mg);
        let gyr = Vec3::from_array(gyro_mdps).scale(MDPS_TO_RAD_S);
        if !(acc.is_finite() && gyr.is_finite()) || acc.norm_squared() == 0.0 {
            return;
        }
        // Snapshot only the attitude and the bias (docs/performance.md, «snapshot what can go
        // bad»); if a step ever goes non-finite, those come back and the low-pass filters
        // restart from their initial state.
        let (gyr_q, acc_q, q, bias, bias_p) = (self.gyr_q, self.acc_q, self.q, self.bias_rad_s, self.bias_p);
        self.step(acc, gyr);
        // The strapdown's own quaternion too: a finite but enormous rate makes it NaN while the
        // step returns before `q`, and every later step would keep it, the attitude frozen.
        if !(self.q.is_finite() && self.gyr_q.is_finite() && self.bias_rad_s.is_finite()) {
            let rest_allowed = self.rest_allowed;
            *self = Vqf::new(self.cfg);
            (self.gyr_q, self.acc_q, self.q, self.bias_rad_s, self.bias_p, self.rest_allowed) =
                (gyr_q, acc_q, q, bias, bias_p, rest_allowed);
        }
    }

    fn step(&mut self, acc: Vec3, gyr: Vec3) {
        let c = self.cfg;
        let dt = c.dt_s;
        let bias_estimation = c.rest_bias_estimation || c.motion_bias_estimation;

        // Rest detection: gyro and accelerometer both close to their recent low-pass, and the
        // gyro low-pass itself small enough to be a bias rather than a slow turn.
        if c.rest_bias_estimation && self.rest_allowed {
            let gyr_lp = self.rest_gyr_lp.step(gyr);
            let acc_lp = self.rest_acc_lp.step(acc);
            let th_gyr = c.rest_th_gyr_dps * DEG_TO_RAD;
            let clip = c.bias_clip_dps * DEG_TO_RAD;
            let moving = gyr.sub(gyr_lp).norm_squared() >= th_gyr * th_gyr
                || gyr_lp.x.abs() > clip
                || gyr_lp.y.abs() > clip
                || gyr_lp.z.abs() > clip
                || acc.sub(acc_lp).norm_squared() >= c.rest_th_acc_mg * c.rest_th_acc_mg;
            if moving {
                self.rest_s = 0.0;
                self.rest = false;
            } else {
                self.rest_s += dt;
                self.rest = self.rest_s >= c.rest_min_s;
            }
        }

        // Gyro strapdown: q ⊗ exp(ω dt / 2), the exponential as its Taylor series to 4th order
        // (per-step angle error θ⁵/3840: 4e-9 rad at 1000 °/s and 160 Hz) instead of sin/cos.
        let w = gyr.sub(self.bias_rad_s);
        let th2 = w.norm_squared() * dt * dt;
        let cos_half = 1.0 - th2 * (1.0 / 8.0) + th2 * th2 * (1.0 / 384.0);
        let sin_half_over_w = dt * (0.5 - th2 * (1.0 / 48.0) + th2 * th2 * (1.0 / 3840.0));
        let d = Quat::new(cos_half, w.x * sin_half_over_w, w.y * sin_half_over_w, w.z * sin_half_over_w);
        self.gyr_q = normalize(self.gyr_q.mul(d));

        // Accelerometer low-pass in the quasi-inertial frame: there, linear accelerations
        // average out over τ while gravity stays put, whatever the body does meanwhile.
        let acc_lp = self.acc_lp.step(self.gyr_q.rotate(acc));
        // Rotate the filtered gravity into the earth frame and tilt it fully onto +z: the
        // smallest rotation doing so has no vertical component.
        let e = self.acc_q.rotate(acc_lp);
        let n2 = e.norm_squared();
        if n2.is_nan() || n2 <= 0.0 {
            return;
        }
        let e = e.scale(1.0 / libm::sqrtf(n2));
        let qw = libm::sqrtf(0.5 * (e.z + 1.0));
        let corr = if qw > 1e-6 {
            let k = 0.5 / qw;
            Quat::new(qw, k * e.y, -k * e.x, 0.0)
        } else {
            // Filtered gravity pointing straight down: any horizontal axis does; VQF's choice.
            Quat::new(0.0, 1.0, 0.0, 0.0)
        };
        self.acc_q = normalize(corr.mul(self.acc_q));
        self.q = self.acc_q.mul(self.gyr_q);

        if bias_estimation {
            self.update_bias(e);
        }
    }

    /// VQF's gyro bias Kalman filter. At rest the measurement is the rest low-pass of the gyro;
    /// in motion it is the inclination correction rate (`e`, the filtered gravity direction
    /// before the correction, over dt), seen through the low-passed rotation matrix.
    fn update_bias(&mut self, e_acc: Vec3) {
        let c = self.cfg;
        let clip = c.bias_clip_dps * DEG_TO_RAD;
        let b = self.bias_rad_s;
        let (r, e, w) = if c.motion_bias_estimation {
            let r = Mat3::from_quat(self.q);
            let rb = Vec3::new(r.r0.dot(b), r.r1.dot(b), 0.0);
            let [lp0, lp1, lp2] = &mut self.motion_r_lp;
            let r_lp = Mat3 { r0: lp0.step(r.r0), r1: lp1.step(r.r1), r2: lp2.step(r.r2) };
            let rb_lp = self.motion_bias_lp.step(rb);
            if self.rest && c.rest_bias_estimation {
                self.rest_measurement()
            } else {
                let inv_dt = 1.0 / c.dt_s;
                let e =
                    Vec3::new(-e_acc.y * inv_dt + rb_lp.x - r_lp.r0.dot(b), e_acc.x * inv_dt + rb_lp.y - r_lp.r1.dot(b), -r_lp.r2.dot(b));
                (r_lp, e, Vec3::new(self.bias_motion_w, self.bias_motion_w, self.bias_vertical_w))
            }
        } else if self.rest {
            self.rest_measurement()
        } else {
            // No measurement: only the covariance grows.
            (Mat3::IDENTITY, Vec3::ZERO, Vec3::new(-1.0, -1.0, -1.0))
        };

        // P ← P + V (also without a measurement), up to the initial uncertainty.
        let grow = |p: f32| if p < self.bias_p0 { p + self.bias_v } else { p };
        let p = self.bias_p;
        let p = Mat3 {
            r0: Vec3::new(grow(p.r0.x), p.r0.y, p.r0.z),
            r1: Vec3::new(p.r1.x, grow(p.r1.y), p.r1.z),
            r2: Vec3::new(p.r2.x, p.r2.y, grow(p.r2.z)),
        };
        self.bias_p = p;
        if w.x < 0.0 {
            return;
        }
        // Clipping the disagreement also bounds the harm of the very first correction.
        let e = clip3(e, clip);
        // K = P Rᵀ (W + R P Rᵀ)⁻¹; b ← b + K e; P ← P − K R P.
        let prt = p.mul(r.transpose());
        let Some(s_inv) = r.mul(prt).add_diag(w).inverse() else {
            return;
        };
        let k = prt.mul(s_inv);
        self.bias_rad_s = clip3(b.add(k.mul_vec(e)), clip);
        self.bias_p = p.sub(k.mul(r).mul(p));
    }

    /// The rest measurement: the gyro's rest low-pass, directly (R = I).
    fn rest_measurement(&self) -> (Mat3, Vec3, Vec3) {
        let w = self.bias_rest_w;
        (Mat3::IDENTITY, self.rest_gyr_lp.out.sub(self.bias_rad_s), Vec3::new(w, w, w))
    }
}

/// Each component limited to ±`limit` (NaN-safe, never panics).
fn clip3(v: Vec3, limit: f32) -> Vec3 {
    Vec3::new(clamp_nan_low(v.x, -limit, limit), clamp_nan_low(v.y, -limit, limit), clamp_nan_low(v.z, -limit, limit))
}

/// Exact normalisation (one `sqrt`, one division); a degenerate quaternion is left as is and
/// caught by the caller's finiteness check.
fn normalize(q: Quat) -> Quat {
    q.scale(1.0 / libm::sqrtf(q.norm_squared()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::tilt_angle_rad;

    fn tilted_accel_mg(angle_rad: f32) -> [f32; 3] {
        // Rotated by +angle about body X: gravity (up) appears tilted towards +Y in the body.
        [0.0, 1000.0 * libm::sinf(angle_rad), 1000.0 * libm::cosf(angle_rad)]
    }

    #[test]
    fn levels_from_the_first_sample() {
        let mut v = Vqf::new(VqfConfig::DEFAULT);
        let t = 20f32.to_radians();
        v.update(tilted_accel_mg(t), [0.0; 3]);
        assert!((tilt_angle_rad(v.quat()) - t).abs() < 1e-4, "{}", tilt_angle_rad(v.quat()));
        let n = v.quat().norm();
        assert!((n - 1.0).abs() < 1e-6, "{n}");
    }

    #[test]
    fn integrates_a_fast_turn_accurately() {
        // 90° about the vertical in one second at 160 Hz: the heading follows, the tilt stays 0.
        let mut v = Vqf::new(VqfConfig::DEFAULT);
        for _ in 0..160 {
            v.update([0.0, 0.0, 1000.0], [0.0, 0.0, 90_000.0]);
        }
        let yaw = crate::math::quat_yaw_rad(v.quat());
        assert!((yaw - core::f32::consts::FRAC_PI_2).abs() < 1e-3, "{yaw}");
        assert!(tilt_angle_rad(v.quat()) < 1e-4);
    }

    #[test]
    fn learns_a_constant_gyro_bias_at_rest() {
        let mut v = Vqf::new(VqfConfig::DEFAULT);
        let bias_mdps = [500.0, -300.0, 200.0];
        for _ in 0..(160 * 10) {
            v.update([0.0, 0.0, 1000.0], bias_mdps);
        }
        assert!(v.rest_detected());
        let b = v.bias_rad_s().scale(1.0 / MDPS_TO_RAD_S);
        assert!((b.x - 500.0).abs() < 10.0 && (b.y + 300.0).abs() < 10.0 && (b.z - 200.0).abs() < 10.0, "{b:?}");
    }

    #[test]
    fn a_steady_slow_turn_in_flight_is_not_taken_for_gyro_bias() {
        // A hover turning at 0.5 °/s looks like rest to the detector; with the motors running
        // (rest not possible) the rotation must stay rotation, not become bias.
        let mut flying = Vqf::new(VqfConfig::DEFAULT);
        let mut still = Vqf::new(VqfConfig::DEFAULT);
        for _ in 0..(160 * 10) {
            flying.update_gated([0.0, 0.0, 1000.0], [0.0, 0.0, 500.0], false);
            still.update_gated([0.0, 0.0, 1000.0], [0.0, 0.0, 500.0], true);
        }
        assert!(!flying.rest_detected());
        assert!(flying.bias_rad_s().norm() < 1e-6, "{:?}", flying.bias_rad_s());
        assert!(still.rest_detected());
        assert!(still.bias_rad_s().z > 0.5 * 500.0 * MDPS_TO_RAD_S);
    }

    #[test]
    fn a_motionless_tilt_does_not_drift_with_a_biased_gyro() {
        // 1 °/s of roll-axis bias for a minute: the accelerometer and the bias estimate hold it.
        let mut v = Vqf::new(VqfConfig::DEFAULT);
        for _ in 0..(160 * 60) {
            v.update(tilted_accel_mg(0.2), [1000.0, 0.0, 0.0]);
        }
        assert!((tilt_angle_rad(v.quat()) - 0.2).abs() < 2e-3);
    }

    #[test]
    fn bad_samples_leave_the_state_untouched() {
        let mut v = Vqf::new(VqfConfig::DEFAULT);
        v.update([0.0, 100.0, 1000.0], [100.0, 0.0, 0.0]);
        let before = v;
        v.update([f32::NAN, 0.0, 1000.0], [0.0; 3]);
        v.update([0.0, 0.0, 1000.0], [f32::INFINITY, 0.0, 0.0]);
        v.update([0.0; 3], [0.0; 3]);
        assert_eq!(v, before);
    }

    #[test]
    fn a_finite_but_enormous_rate_does_not_freeze_the_attitude() {
        let mut v = Vqf::new(VqfConfig::DEFAULT);
        v.update([0.0, 0.0, 1000.0], [0.0; 3]);
        v.update([0.0, 0.0, 1000.0], [f32::MAX, 0.0, 0.0]);
        assert!(v.quat().is_finite());
        // The drone turns a quarter of a turn about the vertical: the attitude follows.
        for _ in 0..160 {
            v.update([0.0, 0.0, 1000.0], [0.0, 0.0, 90_000.0]);
        }
        let yaw = crate::math::quat_yaw_rad(v.quat());
        assert!((yaw - core::f32::consts::FRAC_PI_2).abs() < 1e-2, "the attitude froze: yaw {yaw}");
    }

    #[test]
    fn config_validation_and_rates() {
        assert!(VqfConfig::DEFAULT.is_valid());
        assert_eq!(VqfConfig::DEFAULT.dt_s, 0.00625);
        let broad = VqfConfig::at_rate(0.0035);
        assert!(broad.is_valid());
        assert_eq!(VqfConfig { dt_s: 0.00625, ..broad }, VqfConfig::DEFAULT);
        assert!(!VqfConfig::at_rate(0.0).is_valid());
        assert!(!VqfConfig::at_rate(f32::NAN).is_valid());
        assert!(!VqfConfig { tau_acc_s: 0.001, ..VqfConfig::DEFAULT }.is_valid());
        // Even an invalid configuration must not panic.
        let mut v = Vqf::new(VqfConfig::at_rate(0.0));
        v.update([0.0, 0.0, 1000.0], [0.0; 3]);
    }
}
