//! Vectors, quaternions, the two inverse square roots and an arcsine in single precision.
//!
//! Quaternions are Hamilton, `w + xi + yj + zk`, and rotate **body** vectors into the **earth**
//! frame (z up): `v_earth = q ⊗ v_body ⊗ q*`. Kinematics: `q̇ = ½ q ⊗ (0, ω_body)`.

mod asin;

pub use asin::asinf;

/// A 3-vector of f32.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

// Named methods rather than operator overloading: in this code the evaluation order of f32
// expressions is part of the contract (bit-exact reference), and calls keep it visible.
#[allow(clippy::should_implement_trait)]
impl Vec3 {
    pub const ZERO: Vec3 = Vec3 { x: 0.0, y: 0.0, z: 0.0 };

    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Vec3 { x, y, z }
    }

    pub const fn from_array(a: [f32; 3]) -> Self {
        Vec3 { x: a[0], y: a[1], z: a[2] }
    }

    pub const fn to_array(self) -> [f32; 3] {
        [self.x, self.y, self.z]
    }

    pub fn dot(self, o: Vec3) -> f32 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    pub fn cross(self, o: Vec3) -> Vec3 {
        Vec3 { x: self.y * o.z - self.z * o.y, y: self.z * o.x - self.x * o.z, z: self.x * o.y - self.y * o.x }
    }

    pub fn scale(self, k: f32) -> Vec3 {
        Vec3 { x: self.x * k, y: self.y * k, z: self.z * k }
    }

    pub fn add(self, o: Vec3) -> Vec3 {
        Vec3 { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
    }

    pub fn sub(self, o: Vec3) -> Vec3 {
        Vec3 { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
    }

    pub fn norm_squared(self) -> f32 {
        self.dot(self)
    }

    pub fn norm(self) -> f32 {
        libm::sqrtf(self.norm_squared())
    }

    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
}

/// A quaternion `(w, x, y, z)`; the reference calls the components `q0..q3`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quat {
    pub w: f32,
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

impl Default for Quat {
    fn default() -> Self {
        Quat::IDENTITY
    }
}

#[allow(clippy::should_implement_trait)]
impl Quat {
    pub const IDENTITY: Quat = Quat { w: 1.0, x: 0.0, y: 0.0, z: 0.0 };

    pub const fn new(w: f32, x: f32, y: f32, z: f32) -> Self {
        Quat { w, x, y, z }
    }

    pub fn conj(self) -> Quat {
        Quat { w: self.w, x: -self.x, y: -self.y, z: -self.z }
    }

    /// Hamilton product `self ⊗ o`.
    pub fn mul(self, o: Quat) -> Quat {
        let (a0, a1, a2, a3) = (self.w, self.x, self.y, self.z);
        let (b0, b1, b2, b3) = (o.w, o.x, o.y, o.z);
        Quat {
            w: a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            x: a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            y: a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            z: a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
        }
    }

    pub fn norm_squared(self) -> f32 {
        self.w * self.w + self.x * self.x + self.y * self.y + self.z * self.z
    }

    pub fn norm(self) -> f32 {
        libm::sqrtf(self.norm_squared())
    }

    pub fn scale(self, k: f32) -> Quat {
        Quat { w: self.w * k, x: self.x * k, y: self.y * k, z: self.z * k }
    }

    /// Exact normalisation; a zero or non-finite quaternion becomes the identity, so
    /// nothing downstream ever sees a NaN from here.
    pub fn normalized(self) -> Quat {
        let n2 = self.norm_squared();
        if !(n2.is_finite() && n2 > 1e-30) {
            return Quat::IDENTITY;
        }
        self.scale(inv_sqrt_exact(n2))
    }

    pub fn is_finite(self) -> bool {
        self.w.is_finite() && self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }

    /// Rotate a body vector into the earth frame (`q ⊗ v ⊗ q*`).
    pub fn rotate(self, v: Vec3) -> Vec3 {
        let u = Vec3::new(self.x, self.y, self.z);
        let t = u.cross(v).scale(2.0);
        v.add(t.scale(self.w)).add(u.cross(t))
    }

    /// Rotate an earth vector into the body frame (`q* ⊗ v ⊗ q`), the reference's `Rotation`.
    pub fn rotate_inverse(self, v: Vec3) -> Vec3 {
        self.conj().rotate(v)
    }

    /// The quaternion of a rotation by `angle_rad` about the unit `axis`.
    pub fn from_axis_angle(axis: Vec3, angle_rad: f32) -> Quat {
        let h = 0.5 * angle_rad;
        let s = libm::sinf(h);
        Quat { w: libm::cosf(h), x: axis.x * s, y: axis.y * s, z: axis.z * s }
    }

    /// The earth "up" axis seen in the body frame: third row of the rotation matrix
    /// (the reference's `v` in the Mahony update).
    pub fn up_in_body(self) -> Vec3 {
        let (q0, q1, q2, q3) = (self.w, self.x, self.y, self.z);
        Vec3 { x: 2.0 * (q1 * q3 - q0 * q2), y: 2.0 * (q0 * q1 + q2 * q3), z: q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3 }
    }
}

/// `v` limited to `lo..=hi`: `clamp` without its panic when `lo > hi`. The bounds where this
/// is used come from the validated configuration, so the panic could never fire, but `clamp`
/// still puts a panic call on the control tick's path, and the image should carry none. The
/// same result as `clamp` whenever `lo <= hi`, NaN included (it comes back as NaN).
pub fn limit<T: PartialOrd>(v: T, lo: T, hi: T) -> T {
    if v < lo {
        lo
    } else if v > hi {
        hi
    } else {
        v
    }
}

/// Pitch (about body X) and roll (about body Y), rad, the reference's `QuaternionToEuler`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Tilt {
    /// Rotation about body X, nose up positive (`thx`).
    pub pitch_rad: f32,
    /// Rotation about body Y, right side down positive (`thy`).
    pub roll_rad: f32,
}

/// The reference's `QuaternionToEuler`, bit-exact: f32 products, then double-precision
/// `atan2`/`asin` on the f32 arguments, rounded to f32.
///
/// Unlike the reference, the `asin` argument is clamped to [−1, 1], so a quaternion whose norm
/// exceeds 1 near ±90° roll gives ±π/2 instead of NaN (the only rows of `quat2euler.csv` where
/// this port differs, on purpose).
pub fn quat_to_tilt(q: Quat) -> Tilt {
    quat_to_tilt_with(q, true)
}

/// `quat_to_tilt`, or with `reference_arithmetic == false` the same expressions in f32.
/// Always inlined, so that a caller's constant `false` leaves no f64 code behind (the
/// firmware, built without the `reference` feature).
#[inline(always)] // docs/performance.md, «inlined into the tick».
pub fn quat_to_tilt_with(q: Quat, reference_arithmetic: bool) -> Tilt {
    let (q0, q1, q2, q3) = (q.w, q.x, q.y, q.z);
    let q0q0 = q0 * q0;
    let q1q1 = q1 * q1;
    let q2q2 = q2 * q2;
    let q3q3 = q3 * q3;
    let dq0 = 2.0 * q0;
    let dq1 = 2.0 * q1;
    let dq2 = 2.0 * q2;
    let dq0q1 = dq0 * q1;
    let dq2q3 = dq2 * q3;
    let dq0q2 = dq0 * q2;
    let dq1q3 = dq1 * q3;
    if !reference_arithmetic {
        let pitch = libm::atan2f(dq0q1 + dq2q3, ((q0q0 + q3q3) - q1q1) - q2q2);
        return Tilt { pitch_rad: pitch, roll_rad: asinf((dq0q2 - dq1q3).clamp(-1.0, 1.0)) };
    }
    let pitch = libm::atan2(f64::from(dq0q1 + dq2q3), f64::from(((q0q0 + q3q3) - q1q1) - q2q2));
    let s = f64::from(dq0q2 - dq1q3).clamp(-1.0, 1.0);
    Tilt { pitch_rad: pitch as f32, roll_rad: libm::asin(s) as f32 }
}

/// Tilt of the body z axis from the earth vertical, rad (0 = level, π = upside down).
pub fn tilt_angle_rad(q: Quat) -> f32 {
    let up = q.normalized().up_in_body();
    let c = up.z.clamp(-1.0, 1.0);
    libm::acosf(c)
}

/// Heading (yaw about earth z), rad, for plotting; ZYX convention on the same quaternion.
pub fn quat_yaw_rad(q: Quat) -> f32 {
    let (q0, q1, q2, q3) = (q.w, q.x, q.y, q.z);
    libm::atan2f(2.0 * (q1 * q2 + q0 * q3), q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3)
}

/// The reference's fast inverse square root, bit-exact: `0x5F3759DF − (bits >> 1)` on a
/// signed 32-bit integer, then one Newton step with `(0.5·x·y)·y`.
///
/// Maximum relative error ≈ 0.175 %; `inv_sqrt_fast(1.0) = 0.99830717`, which is why the
/// reference quaternion settles at a norm of 0.9983124. `inv_sqrt_fast(0.0)` is a large
/// finite number, so a zero vector stays zero.
pub fn inv_sqrt_fast(x: f32) -> f32 {
    let halfx = 0.5 * x;
    let i = 0x5F37_59DF_i32.wrapping_sub((x.to_bits() as i32) >> 1);
    let y = f32::from_bits(i as u32);
    y * (1.5 - (halfx * y * y))
}

/// Exact `1/√x`; 0 for `x ≤ 0` or non-finite `x`, so a zero vector stays zero without NaN.
pub fn inv_sqrt_exact(x: f32) -> f32 {
    if x > 0.0 && x.is_finite() {
        1.0 / libm::sqrtf(x)
    } else {
        0.0
    }
}

/// Which inverse square root an algorithm uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InvSqrt {
    /// The reference's one-Newton-step approximation.
    Fast,
    /// `1/√x` to f32 precision.
    Exact,
}

impl InvSqrt {
    pub fn eval(self, x: f32) -> f32 {
        match self {
            InvSqrt::Fast => inv_sqrt_fast(x),
            InvSqrt::Exact => inv_sqrt_exact(x),
        }
    }
}

/// Clamp that maps NaN to `lo`: every limiter in the core uses it so NaN never survives a clamp.
pub fn clamp_nan_low(v: f32, lo: f32, hi: f32) -> f32 {
    if v >= hi {
        hi
    } else if v > lo {
        v
    } else {
        lo
    }
}

pub const DEG_PER_RAD: f32 = 57.295_78;

/// tan(x) for the small angles of filter design (the low-pass designs call it with
/// π·fc/fs < 0.71), in f32 without `libm::tanf`, whose general argument reduction alone is
/// 2.8 KiB of the firmware's flash for a function called only while building filters. The
/// argument is halved (exactly) down to |y| ≤ 1/16, where the Taylor series to y⁹ is exact to
/// f32 precision, and doubled back with tan 2y = 2t / (1 − t²). Within 2 ulp of `libm::tanf`
/// below 1/16 and 6 ulp (4e-7 relative) below 0.75, the test sweeps both; the estimator's
/// BROAD scores are the same to the printed 0.001°.
pub fn tan_small(x: f32) -> f32 {
    let mut y = x;
    let mut halvings = 0;
    while y.abs() > 0.0625 && halvings < 8 {
        y *= 0.5;
        halvings += 1;
    }
    let y2 = y * y;
    let mut t = y * (1.0 + y2 * (1.0 / 3.0 + y2 * (2.0 / 15.0 + y2 * (17.0 / 315.0 + y2 * (62.0 / 2835.0)))));
    for _ in 0..halvings {
        t = 2.0 * t / (1.0 - t * t);
    }
    t
}

/// `x` in `[lo, hi]` (finite bounds), so finite: a NaN fails both comparisons, an infinity
/// the bound it passes. What the configuration checks ask of a value.
pub fn within(x: f32, lo: f32, hi: f32) -> bool {
    lo <= x && x <= hi
}

/// `x` in `(lo, hi]` (finite bounds), so finite: as [`within`].
pub fn above(x: f32, lo: f32, hi: f32) -> bool {
    lo < x && x <= hi
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limit_is_clamp_for_ordered_bounds_and_never_panics() {
        for v in [-3.0f32, -1.0, 0.0, 0.5, 1.0, 2.0, f32::INFINITY, f32::NEG_INFINITY, f32::MIN_POSITIVE] {
            assert_eq!(limit(v, -1.0, 1.0).to_bits(), v.clamp(-1.0, 1.0).to_bits(), "{v}");
        }
        assert!(limit(f32::NAN, -1.0, 1.0).is_nan());
        for v in -5..5i32 {
            assert_eq!(limit(v, -2, 3), v.clamp(-2, 3));
        }
        // Reversed bounds: an answer, not a panic.
        assert_eq!(limit(0, 3, -2), 3);
    }

    #[test]
    fn tan_small_is_libms_tanf_to_a_few_ulp() {
        let ulps = |a: f32, b: f32| (a.to_bits() as i64 - b.to_bits() as i64).abs();
        let mut worst_small = 0;
        let mut worst = 0;
        for i in -75_000i32..=75_000 {
            let x = i as f32 * 1e-5;
            let d = ulps(tan_small(x), libm::tanf(x));
            if x.abs() <= 0.0625 {
                worst_small = worst_small.max(d);
            }
            worst = worst.max(d);
        }
        assert!(worst_small <= 2, "{worst_small} ulp below 1/16");
        assert!(worst <= 6, "{worst} ulp below 0.75");
        assert_eq!(tan_small(0.0), 0.0);
    }

    #[test]
    fn fast_inv_sqrt_matches_the_reference_spot_values() {
        assert_eq!(inv_sqrt_fast(1.0), 0.998_307_17);
        assert!(inv_sqrt_fast(0.0).is_finite());
        assert!((inv_sqrt_fast(0.0) - 1.981_775_4e19).abs() < 1e13);
    }

    #[test]
    fn exact_inv_sqrt_of_zero_and_nan_is_zero() {
        assert_eq!(inv_sqrt_exact(0.0), 0.0);
        assert_eq!(inv_sqrt_exact(f32::NAN), 0.0);
        assert_eq!(inv_sqrt_exact(-1.0), 0.0);
        assert_eq!(inv_sqrt_exact(4.0), 0.5);
    }

    #[test]
    fn rotation_about_x_raises_the_nose() {
        // +10° about body X is nose up: the forward axis (+Y) gains a positive earth z.
        let q = Quat::from_axis_angle(Vec3::new(1.0, 0.0, 0.0), 10f32.to_radians());
        let fwd = q.rotate(Vec3::new(0.0, 1.0, 0.0));
        assert!(fwd.z > 0.17 && fwd.z < 0.18);
        let t = quat_to_tilt(q);
        assert!((t.pitch_rad - 10f32.to_radians()).abs() < 1e-6);
        assert!(t.roll_rad.abs() < 1e-6);
    }

    #[test]
    fn rotation_about_y_is_roll_right_side_down() {
        let q = Quat::from_axis_angle(Vec3::new(0.0, 1.0, 0.0), 10f32.to_radians());
        let right = q.rotate(Vec3::new(1.0, 0.0, 0.0));
        assert!(right.z < -0.17);
        let t = quat_to_tilt(q);
        assert!((t.roll_rad - 10f32.to_radians()).abs() < 1e-6);
    }

    #[test]
    fn euler_asin_argument_is_clamped() {
        // norm slightly above 1 at +90° roll: the reference gives NaN, we give π/2.
        let q = Quat::new(0.7075, 0.0, 0.7075, 0.0);
        let t = quat_to_tilt(q);
        assert!((t.roll_rad - core::f32::consts::FRAC_PI_2).abs() < 1e-6);
    }

    #[test]
    fn rotate_inverse_undoes_rotate() {
        let q = Quat::from_axis_angle(Vec3::new(0.6, 0.0, 0.8), 1.1);
        let v = Vec3::new(0.3, -2.0, 1.5);
        let back = q.rotate_inverse(q.rotate(v));
        assert!(back.sub(v).norm() < 1e-5);
    }

    #[test]
    fn clamp_maps_nan_to_the_low_limit() {
        assert_eq!(clamp_nan_low(f32::NAN, -1.0, 1.0), -1.0);
        assert_eq!(clamp_nan_low(f32::INFINITY, -1.0, 1.0), 1.0);
        assert_eq!(clamp_nan_low(0.5, -1.0, 1.0), 0.5);
    }
}
