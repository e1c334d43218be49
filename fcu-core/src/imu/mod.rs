//! The IMU boundary: raw LSM6DSL words in sensor axes → integer mg / mdps in body axes,
//! offset calibration and sensor health.
//!
//! The conversions are the ST driver's, bit for bit: `accel_mg = trunc(raw · 0.122f)` and
//! `gyro_mdps = trunc(raw · 70.0f)`, computed in f32 and truncated toward zero.

pub mod registers;

/// One LSM6DSL reading as it comes off the bus: int16 words in **sensor** axes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RawImu {
    pub accel: [i16; 3],
    pub gyro: [i16; 3],
}

/// A reading in **body** axes, integer milli-g and milli-degrees per second, as the reference
/// carries it from the driver to the offset removal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BodyImu {
    pub accel_mg: [i32; 3],
    pub gyro_mdps: [i32; 3],
}

/// Sensor-to-body mount as a signed permutation: body axis `i` = `sign[i]` × sensor axis
/// `source[i]`. The board's mount (the reference's `COORDINATE_SYSTEM 3`) is
/// X = −sensor Y, Y = +sensor X, Z = +sensor Z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mount {
    pub source: [u8; 3],
    pub sign: [i8; 3],
}

impl Mount {
    /// The reference's mode 3 (the only one of its four modes that works).
    pub const STEVAL_FCU001: Mount = Mount { source: [1, 0, 2], sign: [-1, 1, 1] };

    /// True when `source` is a permutation of 0..3 and every sign is ±1.
    pub fn is_valid(&self) -> bool {
        let mut seen = [false; 3];
        for &s in &self.source {
            match seen.get_mut(usize::from(s)) {
                Some(slot) if !*slot => *slot = true,
                _ => return false,
            }
        }
        self.sign.iter().all(|&s| s == 1 || s == -1)
    }

    /// The driver's conversion and the mount in one pass: body axis `i` is
    /// `trunc(raw[source[i]] · k)` with the sign of axis `i`.
    pub fn convert(&self, raw: [i16; 3], k: f32) -> [i32; 3] {
        self.permute(raw).map(|x| scale_truncate(x, k))
    }

    /// The signed permutation on raw words: body axis `i` is `sign[i] · raw[source[i]]`,
    /// widened so that negating −32768 cannot overflow. Converting after the sign is what the
    /// reference's convert-then-negate gives, bit for bit: f32 negation is exact and truncation
    /// is odd, so `trunc(−x · k) = −trunc(x · k)`.
    pub fn permute(&self, raw: [i16; 3]) -> [i32; 3] {
        let [w0, w1, w2] = self.select(raw);
        let [g0, g1, g2] = self.sign.map(i32::from);
        [w0 * g0, w1 * g1, w2 * g2]
    }

    /// The permutation alone: body axis `i` gets sensor word `source[i]`, sign not applied.
    pub fn select(&self, raw: [i16; 3]) -> [i32; 3] {
        let [r0, r1, r2] = raw;
        // A fourth slot so `source & 3` always indexes inside: no bounds check, no branch.
        let w = [r0, r1, r2, 0];
        let pick = |src: u8| i32::from(w.get(usize::from(src & 3)).copied().unwrap_or(0));
        let [s0, s1, s2] = self.source;
        [pick(s0), pick(s1), pick(s2)]
    }

    /// Apply to a float vector.
    pub fn apply_f32(&self, v: [f32; 3]) -> [f32; 3] {
        let mut out = [0f32; 3];
        for ((o, &src), &sign) in out.iter_mut().zip(&self.source).zip(&self.sign) {
            let x = v.get(usize::from(src)).copied().unwrap_or(0.0);
            *o = if sign < 0 { -x } else { x };
        }
        out
    }

    /// The inverse mount: body vector → sensor axes (used by the simulator's IMU model).
    pub fn body_to_sensor_f32(&self, body: [f32; 3]) -> [f32; 3] {
        let mut out = [0f32; 3];
        for ((&b, &src), &sign) in body.iter().zip(&self.source).zip(&self.sign) {
            if let Some(o) = out.get_mut(usize::from(src)) {
                *o = if sign < 0 { -b } else { b };
            }
        }
        out
    }
}

/// Sensitivities and mount of the accelerometer and gyroscope.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuConfig {
    /// LSM6DSL at ±4 g: 0.122 mg/LSB.
    pub accel_mg_per_lsb: f32,
    /// LSM6DSL at ±2000 dps: 70 mdps/LSB.
    pub gyro_mdps_per_lsb: f32,
    pub mount: Mount,
}

impl ImuConfig {
    pub const REFERENCE: ImuConfig = ImuConfig { accel_mg_per_lsb: 0.122, gyro_mdps_per_lsb: 70.0, mount: Mount::STEVAL_FCU001 };

    /// Driver conversion and mount: `trunc(raw·sensitivity)` in f32, then the mount.
    /// A saturating float→int cast keeps any sensitivity from producing undefined values.
    pub fn to_body(&self, raw: RawImu) -> BodyImu {
        Decoder::new(self).to_body(raw)
    }
}

/// `trunc(x · k)` in f32, the driver's conversion (saturating, so no sensitivity can make it
/// undefined).
fn scale_truncate(x: i32, k: f32) -> i32 {
    (x as f32 * k) as i32
}

/// An [`ImuConfig`] prepared once for the 800 Hz path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decoder {
    mount: Mount,
    accel_mg_per_lsb: f32,
    gyro: GyroScale,
}

/// How gyro words become mdps.
#[derive(Clone, Copy, Debug, PartialEq)]
enum GyroScale {
    /// A whole number of mdps per LSB small enough that `raw · k` stays below 2^24, where f32
    /// holds every integer: the f32 product is then exact, its truncation is the integer
    /// product, and one integer multiply (by `sign · k`, per body axis) replaces two
    /// conversions, a float multiply and the sign. The board's 70 mdps/LSB (±2000 dps) is
    /// such a scale.
    Integer {
        signed_k: [i32; 3],
    },
    Float(f32),
}

impl Decoder {
    pub fn new(cfg: &ImuConfig) -> Self {
        let k = cfg.gyro_mdps_per_lsb;
        // |raw| ≤ 32768 = 2^15, so k ≤ 2^9 keeps |raw · k| ≤ 2^24.
        let gyro = if (1.0..=512.0).contains(&k) && k == (k as i32) as f32 {
            GyroScale::Integer { signed_k: cfg.mount.sign.map(|s| i32::from(s) * k as i32) }
        } else {
            GyroScale::Float(k)
        };
        Decoder { mount: cfg.mount, accel_mg_per_lsb: cfg.accel_mg_per_lsb, gyro }
    }

    pub fn to_body(&self, raw: RawImu) -> BodyImu {
        BodyImu { accel_mg: self.accel_mg(raw.accel), gyro_mdps: self.gyro_mdps(raw.gyro) }
    }

    /// Accelerometer words (sensor axes) to body mg.
    pub fn accel_mg(&self, accel: [i16; 3]) -> [i32; 3] {
        self.mount.convert(accel, self.accel_mg_per_lsb)
    }

    /// Gyro words (sensor axes) to body mdps.
    pub fn gyro_mdps(&self, gyro: [i16; 3]) -> [i32; 3] {
        match self.gyro {
            GyroScale::Integer { signed_k: [k0, k1, k2] } => {
                let [w0, w1, w2] = self.mount.select(gyro);
                [w0 * k0, w1 * k1, w2 * k2]
            }
            GyroScale::Float(k) => self.mount.permute(gyro).map(|x| scale_truncate(x, k)),
        }
    }
}

/// Offsets removed from every body sample. The accelerometer Z offset keeps 1 g: the
/// reference subtracts `(offset_z − 1000)` so a level board reads (0, 0, +1000) mg.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Offsets {
    pub accel_mg: [i32; 3],
    pub gyro_mdps: [i32; 3],
}

/// The reference's gravity rule: the Z offset keeps this much of the mean.
pub const ACCEL_Z_REFERENCE_MG: i32 = 1000;

impl Offsets {
    /// The reference's statics before calibration: accel (0, 0, 1000), gyro 0 (a no-op).
    pub const UNCALIBRATED: Offsets = Offsets { accel_mg: [0, 0, ACCEL_Z_REFERENCE_MG], gyro_mdps: [0; 3] };

    /// Accelerometer offset removal in wrapping int32, as the reference (which cannot
    /// overflow for 16-bit inputs, but must not panic if it did).
    pub fn accel(&self, accel_mg: [i32; 3]) -> [i32; 3] {
        let [ax, ay, az] = accel_mg;
        let [ox, oy, oz] = self.accel_mg;
        [ax.wrapping_sub(ox), ay.wrapping_sub(oy), az.wrapping_sub(oz.wrapping_sub(ACCEL_Z_REFERENCE_MG))]
    }

    /// Gyro offset removal, likewise.
    pub fn gyro(&self, gyro_mdps: [i32; 3]) -> [i32; 3] {
        let [gx, gy, gz] = gyro_mdps;
        let [ox, oy, oz] = self.gyro_mdps;
        [gx.wrapping_sub(ox), gy.wrapping_sub(oy), gz.wrapping_sub(oz)]
    }
}

/// Motion check of a calibration: while averaging, a gyro axis that moves
/// more than `gyro_max_dev_mdps` from its running mean, or an accelerometer norm outside
/// `1 g ± accel_norm_tol_mg`, restarts the average; after `timeout_ticks` it gives up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionCheck {
    pub gyro_max_dev_mdps: f32,
    pub accel_norm_tol_mg: f32,
    pub timeout_ticks: u32,
}

/// How offsets are measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationConfig {
    /// Ticks ignored after boot before the start-up average begins (the reference's 800).
    pub settle_ticks: u32,
    /// Samples averaged (800); the factor is `1/samples` applied as the reference does.
    pub samples: u32,
    /// `None` in the reference profile: any motion is accepted.
    pub motion_check: Option<MotionCheck>,
}

impl CalibrationConfig {
    pub const REFERENCE: CalibrationConfig = CalibrationConfig { settle_ticks: 800, samples: 800, motion_check: None };
}

/// What a calibration attempt ended in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationOutcome {
    Passed,
    /// The motion check never allowed a full average within the timeout.
    FailedMotion,
}

/// Where the calibrator is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationPhase {
    /// Boot settling: samples are ignored, nothing else runs.
    Settling,
    /// Averaging (start-up or requested). `restarts` counts motion-check restarts.
    Averaging { restarts: u16 },
    /// Not averaging; the last attempt ended in `last` (or none yet).
    Idle { last: Option<CalibrationOutcome> },
}

/// Offset calibration: the reference's start-up and stick-requested averages, optionally
/// with a motion check. Feed it one body sample per tick.
#[derive(Clone, Debug)]
pub struct Calibrator {
    cfg: CalibrationConfig,
    phase: CalibrationPhase,
    ticks_in_phase: u32,
    count: u32,
    sums: [i64; 6],
    attempt_ticks: u32,
    passed_once: bool,
}

impl Calibrator {
    pub fn new(cfg: CalibrationConfig) -> Self {
        Calibrator {
            cfg,
            phase: CalibrationPhase::Settling,
            ticks_in_phase: 0,
            count: 0,
            sums: [0; 6],
            attempt_ticks: 0,
            passed_once: false,
        }
    }

    pub fn phase(&self) -> CalibrationPhase {
        self.phase
    }

    /// True once any calibration has passed since boot.
    pub fn has_passed(&self) -> bool {
        self.passed_once
    }

    /// True when neither settling nor averaging.
    pub fn is_idle(&self) -> bool {
        matches!(self.phase, CalibrationPhase::Idle { .. })
    }

    /// True while averaging (start-up or requested).
    pub fn is_averaging(&self) -> bool {
        matches!(self.phase, CalibrationPhase::Averaging { .. })
    }

    /// True while the boot settling delay or the start-up average runs: the reference's
    /// `sensor_init_cali == 0`, when the control tick does nothing else.
    pub fn in_startup(&self) -> bool {
        !self.passed_once && !matches!(self.phase, CalibrationPhase::Idle { .. })
    }

    /// Start a requested calibration (ignored while one is running or during settling).
    pub fn request(&mut self) {
        if let CalibrationPhase::Idle { .. } = self.phase {
            self.begin_average();
        }
    }

    fn begin_average(&mut self) {
        self.phase = CalibrationPhase::Averaging { restarts: 0 };
        self.clear_sums();
        self.attempt_ticks = 0;
    }

    fn clear_sums(&mut self) {
        self.sums = [0; 6];
        self.count = 0;
    }

    /// Count a boot-settling tick. Returns true while still settling.
    pub fn settle(&mut self) -> bool {
        if self.phase != CalibrationPhase::Settling {
            return false;
        }
        self.ticks_in_phase = self.ticks_in_phase.saturating_add(1);
        if self.ticks_in_phase > self.cfg.settle_ticks {
            self.begin_average();
            return false;
        }
        true
    }

    /// Add one raw body sample (before offset removal). Returns the new offsets when an
    /// average completes, on exactly the sample that completes it.
    pub fn feed(&mut self, s: BodyImu) -> Option<Offsets> {
        let CalibrationPhase::Averaging { restarts } = self.phase else {
            return None;
        };
        self.attempt_ticks = self.attempt_ticks.saturating_add(1);
        if let Some(check) = self.cfg.motion_check {
            if self.moving(&check, &s) {
                self.clear_sums();
                if self.attempt_ticks >= check.timeout_ticks {
                    self.phase = CalibrationPhase::Idle { last: Some(CalibrationOutcome::FailedMotion) };
                } else {
                    self.phase = CalibrationPhase::Averaging { restarts: restarts.saturating_add(1) };
                }
                return None;
            }
        }
        let all = [s.accel_mg[0], s.accel_mg[1], s.accel_mg[2], s.gyro_mdps[0], s.gyro_mdps[1], s.gyro_mdps[2]];
        for (sum, v) in self.sums.iter_mut().zip(all) {
            *sum = sum.saturating_add(i64::from(v));
        }
        self.count = self.count.saturating_add(1);
        if self.count < self.cfg.samples {
            return None;
        }
        let n = self.cfg.samples;
        let [a0, a1, a2, g0, g1, g2] = self.sums.map(|sum| truncated_mean(sum, n));
        self.clear_sums();
        self.passed_once = true;
        self.phase = CalibrationPhase::Idle { last: Some(CalibrationOutcome::Passed) };
        Some(Offsets { accel_mg: [a0, a1, a2], gyro_mdps: [g0, g1, g2] })
    }

    fn moving(&self, check: &MotionCheck, s: &BodyImu) -> bool {
        let [ax, ay, az] = s.accel_mg.map(|v| v as f32);
        let norm = libm::sqrtf(ax * ax + ay * ay + az * az);
        if (norm - ACCEL_Z_REFERENCE_MG as f32).abs() > check.accel_norm_tol_mg {
            return true;
        }
        if self.count == 0 {
            return false;
        }
        let n = self.count as f32;
        let gyro_sums = [self.sums[3], self.sums[4], self.sums[5]];
        s.gyro_mdps.iter().zip(gyro_sums).any(|(&g, sum)| (g as f32 - sum as f32 / n).abs() > check.gyro_max_dev_mdps)
    }
}

/// The mean of `n` samples from their sum, truncated toward zero: the reference's offset.
///
/// The reference multiplies its sum by the double 0.00125 and truncates. For its 800 samples
/// (both profiles' count) that is this quotient, in integers rather than emulated doubles on
/// the M4: the double nearest 1/800 lies above it (by 2e-17 relative), so for
/// `sum = 800·q + r` (0 ≤ r < 800, |q| < 2^31 for i32 samples) the product is at least
/// `q` and exceeds `q + r/800` by under 2e-7 with its rounding, far short of `q + 1`;
/// both truncate toward zero, so negative sums mirror. For any other count the quotient is
/// the exact truncated mean.
fn truncated_mean(sum: i64, n: u32) -> i32 {
    let magnitude = quotient_u64_u32(sum.unsigned_abs(), n.max(1));
    // The mean of i32 samples is an i32: the clamp only keeps the cast honest.
    let magnitude = i64::try_from(magnitude).unwrap_or(i64::MAX);
    let mean = if sum < 0 { -magnitude } else { magnitude };
    mean.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// `num / d` (`d > 0`) by shift and subtract, in 32-bit operations: the M4 divides only 32
/// bits, and a 64-bit `/` would bring compiler-builtins' general division (about 1 KB of
/// flash) into the image for a quotient taken once per calibration.
fn quotient_u64_u32(num: u64, d: u32) -> u64 {
    // The sums of a level, still board's 800 samples fit 32 bits: one hardware division.
    if let Ok(num) = u32::try_from(num) {
        return u64::from(num / d.max(1));
    }
    let d = u64::from(d);
    let mut quotient = 0u64;
    let mut remainder = 0u64;
    for bit in (0..64).rev() {
        // remainder < d < 2^32 before the shift, so it never overflows.
        remainder = (remainder << 1) | ((num >> bit) & 1);
        if remainder >= d {
            remainder -= d;
            quotient |= 1 << bit;
        }
    }
    quotient
}

/// In-flight sensor health (`docs/safety.md#sensor-faults`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthConfig {
    /// Identical raw accel and gyro words for this many ticks = stuck sensor (100 ms).
    pub stuck_ticks: u32,
    /// Converted values beyond these magnitudes are out of range (a wrong full scale or a
    /// corrupt read; the LSM6DSL at ±4 g / ±2000 dps cannot produce them).
    pub accel_limit_mg: u32,
    pub gyro_limit_mdps: u32,
}

/// Why the sensor was declared faulty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorFault {
    NotFinite,
    OutOfRange,
    Stuck,
    /// The bus delivered no sample for more than [`MAX_MISSING_SAMPLES`] ticks in a row.
    NoData,
}

/// Missing samples (a failed bus read) bridged by holding the last one before the sensor is
/// declared faulty: 3 ticks, under 4 ms, shorter than anything the airframe notices.
pub const MAX_MISSING_SAMPLES: u32 = 3;

/// Watches raw words for a stuck sensor and converted values for impossible ones.
#[derive(Clone, Debug)]
pub struct HealthMonitor {
    cfg: HealthConfig,
    /// Readings in a row identical to the one before.
    same_count: u32,
    /// The conversion, kept only when some 16-bit word converted at the configured
    /// sensitivities can exceed the limits. At the board's ±4 g / ±2000 dps none can
    /// (3,997 mg < 4,100 and 2,293,760 mdps < 2,300,000): the range check is then decided once,
    /// here, instead of converting and comparing on every tick for a verdict that is always
    /// "in range".
    range_check: Option<Decoder>,
}

impl HealthMonitor {
    pub fn new(cfg: HealthConfig, imu: &ImuConfig) -> Self {
        // The conversion truncates `raw · k` and is monotonic in `raw`, so the largest
        // magnitudes come from the extreme words.
        let largest = |k: f32| -> u32 {
            let [lo, hi] = [i16::MIN, i16::MAX].map(|w| scale_truncate(i32::from(w), k).unsigned_abs());
            lo.max(hi)
        };
        let reachable = largest(imu.accel_mg_per_lsb) > cfg.accel_limit_mg || largest(imu.gyro_mdps_per_lsb) > cfg.gyro_limit_mdps;
        HealthMonitor { cfg, same_count: 0, range_check: reachable.then(|| Decoder::new(imu)) }
    }

    /// Check one reading: whether its raw words repeat the previous reading's (stuck?) and,
    /// converted, its values (possible?). The caller keeps the previous reading (the pipeline
    /// holds it anyway, to bridge a missed sample). The converted values are integers, so they
    /// are always finite; a non-finite value can only appear later, in the filters, which
    /// report it as [`SensorFault::NotFinite`] themselves.
    pub fn check(&mut self, raw: RawImu, repeated: bool) -> Option<SensorFault> {
        let cfg = &self.cfg;
        self.same_count = if repeated { self.same_count.saturating_add(1) } else { 0 };
        if let Some(decoder) = &self.range_check {
            let body = decoder.to_body(raw);
            let over = |v: &[i32; 3], limit: u32| v.iter().any(|x| x.unsigned_abs() > limit);
            if over(&body.accel_mg, cfg.accel_limit_mg) || over(&body.gyro_mdps, cfg.gyro_limit_mdps) {
                return Some(SensorFault::OutOfRange);
            }
        }
        if self.same_count >= cfg.stuck_ticks {
            return Some(SensorFault::Stuck);
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversion_truncates_toward_zero_like_the_driver() {
        let b = ImuConfig::REFERENCE.to_body(RawImu { accel: [9, -9, 8197], gyro: [1, -1, 32767] });
        // sensor X=9 → body Y; sensor Y=−9 → body X = +trunc(−9·0.122)·(−1) = 1
        assert_eq!(b.accel_mg, [1, 1, 1000]);
        assert_eq!(b.gyro_mdps, [70, 70, 2_293_690]);
    }

    #[test]
    fn mount_mode_3_is_a_rotation_about_z() {
        let m = Mount::STEVAL_FCU001;
        assert!(m.is_valid());
        assert_eq!(m.convert([1, 2, 3], 1.0), [-2, 1, 3]);
        assert_eq!(m.body_to_sensor_f32(m.apply_f32([1.0, 2.0, 3.0])), [1.0, 2.0, 3.0]);
    }

    proptest::proptest! {
        #[test]
        fn converting_with_the_sign_on_the_sensitivity_equals_converting_then_negating(
            raw in proptest::array::uniform3(proptest::num::i16::ANY),
            gyro in proptest::bool::ANY,
        ) {
            // The reference converts each sensor axis, then remaps with X = −Y: the one-pass
            // conversion must give the same integers for every possible word.
            let k = if gyro { 70.0f32 } else { 0.122f32 };
            let conv = raw.map(|r| (f32::from(r) * k) as i32);
            let reference = [-conv[1], conv[0], conv[2]];
            proptest::prop_assert_eq!(Mount::STEVAL_FCU001.convert(raw, k), reference);
        }
    }

    #[test]
    fn integer_gyro_scale_equals_the_drivers_float_conversion_for_every_word() {
        for k in [70.0f32, 8.75, 17.5, 35.0, 1.0, 512.0] {
            let cfg = ImuConfig { gyro_mdps_per_lsb: k, ..ImuConfig::REFERENCE };
            let d = Decoder::new(&cfg);
            assert_eq!(matches!(d.gyro, GyroScale::Integer { .. }), k.fract() == 0.0, "{k}");
            for w in i16::MIN..=i16::MAX {
                let words = [w, w.wrapping_add(1), w.wrapping_mul(3)];
                let float = words.map(|r| (f32::from(r) * k) as i32);
                assert_eq!(d.gyro_mdps(words), [-float[1], float[0], float[2]], "{k} {w}");
            }
        }
    }

    #[test]
    fn invalid_mount_is_detected() {
        assert!(!Mount { source: [0, 0, 2], sign: [1, 1, 1] }.is_valid());
        assert!(!Mount { source: [0, 1, 2], sign: [1, 0, 1] }.is_valid());
        assert!(!Mount { source: [0, 1, 3], sign: [1, 1, 1] }.is_valid());
    }

    #[test]
    fn offsets_keep_one_g_on_z() {
        let o = Offsets { accel_mg: [10, -20, 1030], gyro_mdps: [5, 6, 7] };
        assert_eq!(o.accel([10, -20, 1030]), [0, 0, 1000]);
        assert_eq!(o.gyro([5, 6, 7]), [0, 0, 0]);
    }

    #[test]
    fn calibration_averages_after_settling_and_truncates() {
        let mut c = Calibrator::new(CalibrationConfig { settle_ticks: 3, samples: 4, motion_check: None });
        for _ in 0..3 {
            assert!(c.settle());
        }
        assert!(!c.settle());
        let s = BodyImu { accel_mg: [1, -3, 1001], gyro_mdps: [7, 0, -7] };
        assert_eq!(c.feed(s), None);
        assert_eq!(c.feed(s), None);
        assert_eq!(c.feed(s), None);
        let s2 = BodyImu { accel_mg: [2, -2, 1002], gyro_mdps: [8, 1, -8] };
        let o = c.feed(s2).unwrap();
        // (3+2)/4 = 1.25 → 1; (−9−2)/4 = −2.75 → −2 (toward zero)
        assert_eq!(o.accel_mg, [1, -2, 1001]);
        assert_eq!(o.gyro_mdps, [7, 0, -7]);
        assert!(c.has_passed());
    }

    #[test]
    fn motion_check_restarts_and_gives_up() {
        let check = MotionCheck { gyro_max_dev_mdps: 2000.0, accel_norm_tol_mg: 100.0, timeout_ticks: 50 };
        let mut c = Calibrator::new(CalibrationConfig { settle_ticks: 0, samples: 10, motion_check: Some(check) });
        assert!(!c.settle());
        let still = BodyImu { accel_mg: [0, 0, 1000], gyro_mdps: [100, 0, 0] };
        let shaken = BodyImu { accel_mg: [0, 0, 1300], gyro_mdps: [100, 0, 0] };
        for _ in 0..5 {
            assert_eq!(c.feed(still), None);
        }
        assert_eq!(c.feed(shaken), None);
        assert_eq!(c.phase(), CalibrationPhase::Averaging { restarts: 1 });
        for _ in 0..60 {
            c.feed(shaken);
        }
        assert_eq!(c.phase(), CalibrationPhase::Idle { last: Some(CalibrationOutcome::FailedMotion) });
        assert!(!c.has_passed());
    }

    #[test]
    fn a_stuck_sensor_is_reported_after_the_configured_ticks() {
        let cfg = HealthConfig { stuck_ticks: 3, accel_limit_mg: 4100, gyro_limit_mdps: 2_300_000 };
        let mut h = HealthMonitor::new(cfg, &ImuConfig::REFERENCE);
        let raw = RawImu { accel: [1, 2, 3], gyro: [4, 5, 6] };
        assert_eq!(h.check(raw, false), None);
        for _ in 0..2 {
            assert_eq!(h.check(raw, true), None);
        }
        assert_eq!(h.check(raw, true), Some(SensorFault::Stuck));
        let other = RawImu { accel: [1, 2, 4], gyro: [4, 5, 6] };
        assert_eq!(h.check(other, false), None);
    }

    #[test]
    fn an_impossible_value_is_out_of_range() {
        // A ±4 g sensor cannot say 5 g: a wrong full scale or a corrupt read. With limits a
        // word can exceed at these sensitivities, the check runs.
        let cfg = HealthConfig { stuck_ticks: 80, accel_limit_mg: 3000, gyro_limit_mdps: 2_000_000 };
        let mut h = HealthMonitor::new(cfg, &ImuConfig::REFERENCE);
        // Sensor X is body Y: 24,600 LSB is 3,001 mg.
        assert_eq!(h.check(RawImu { accel: [24_600, 0, 8197], gyro: [0; 3] }, false), Some(SensorFault::OutOfRange));
        // 28,572 LSB is 2,000,040 mdps.
        assert_eq!(h.check(RawImu { accel: [0, 0, 8197], gyro: [0, 0, -28_572] }, false), Some(SensorFault::OutOfRange));
        assert_eq!(h.check(RawImu { accel: [24_590, 0, 8197], gyro: [0, 0, -28_571] }, false), None);
    }

    #[test]
    fn the_range_check_is_dropped_only_when_no_word_can_fail_it() {
        // ±4 g gives at most 3,997 mg and ±2000 dps at most 2,293,760 mdps: limits at or above
        // those cannot be exceeded by any sensor word, limits one below can.
        let reachable = |accel_limit_mg, gyro_limit_mdps| {
            HealthMonitor::new(HealthConfig { stuck_ticks: 80, accel_limit_mg, gyro_limit_mdps }, &ImuConfig::REFERENCE)
                .range_check
                .is_some()
        };
        assert!(!reachable(4100, 2_300_000));
        assert!(!reachable(3997, 2_293_760));
        assert!(reachable(3996, 2_293_760));
        assert!(reachable(3997, 2_293_759));
        // Every word really stays inside the product's limits.
        let body = |w: i16| ImuConfig::REFERENCE.to_body(RawImu { accel: [w; 3], gyro: [w; 3] });
        for w in [i16::MIN, i16::MIN + 1, -1, 0, 1, i16::MAX] {
            let b = body(w);
            assert!(b.accel_mg.iter().all(|v| v.unsigned_abs() <= 3997), "{w}: {b:?}");
            assert!(b.gyro_mdps.iter().all(|v| v.unsigned_abs() <= 2_293_760), "{w}: {b:?}");
        }
    }

    /// The reference's calibration mean: the sum times the double 0.00125, truncated.
    fn reference_mean(sum: i64) -> i32 {
        (sum as f64 * 0.00125) as i32
    }

    #[test]
    fn the_double_nearest_1_over_800_is_above_it() {
        // 0.00125 = m · 2^e exactly; above 1/800 means 800 · m > 2^−e.
        let bits = 0.00125f64.to_bits();
        let m = u128::from(bits & ((1 << 52) - 1) | (1 << 52));
        let e = ((bits >> 52) & 0x7ff) as i32 - 1075;
        assert!(800 * m > 1u128 << -e, "{m} {e}");
    }

    #[test]
    fn the_integer_mean_of_800_samples_is_the_references_double_product() {
        // Either side of every multiple of 800 (where a double below 1/800 would truncate to
        // one less) over the whole range of 800 i32 samples, and both signs.
        let q_max = i64::from(i32::MAX);
        let qs = (0..=4096).chain((0..=31).map(|k| 1 << k)).chain([q_max - 1, q_max, 12_345_678, 1_000_003]);
        for q in qs {
            for r in [0, 1, 399, 400, 401, 798, 799] {
                for sum in [800 * q + r, -(800 * q + r)] {
                    assert_eq!(truncated_mean(sum, 800), reference_mean(sum), "sum {sum}");
                }
            }
        }
    }

    #[test]
    fn the_mean_holds_at_the_ends_of_the_sums_range() {
        assert_eq!(quotient_u64_u32(u64::MAX, 1), u64::MAX);
        assert_eq!(quotient_u64_u32(u64::MAX, u32::MAX), u64::MAX / u64::from(u32::MAX));
        assert_eq!(quotient_u64_u32(0, 7), 0);
        assert_eq!(truncated_mean(i64::MIN, 1), i32::MIN);
        assert_eq!(truncated_mean(i64::MAX, 1), i32::MAX);
        assert_eq!(truncated_mean(i64::MIN, u32::MAX), (i64::MIN / i64::from(u32::MAX)).clamp(i32::MIN.into(), i32::MAX.into()) as i32);
        assert_eq!(truncated_mean(-7, 2), -3);
        assert_eq!(truncated_mean(-1, 0), -1);
    }

    proptest::proptest! {
        #[test]
        fn the_shift_and_subtract_quotient_is_the_division(num in proptest::num::u64::ANY, d in 1u32..) {
            proptest::prop_assert_eq!(quotient_u64_u32(num, d), num / u64::from(d));
        }

        #[test]
        fn the_mean_of_any_count_truncates_toward_zero(sum in proptest::num::i64::ANY, n in 1u32..) {
            let exact = (i128::from(sum) / i128::from(n)).clamp(i32::MIN.into(), i32::MAX.into());
            proptest::prop_assert_eq!(i128::from(truncated_mean(sum, n)), exact);
        }

        #[test]
        fn the_integer_mean_is_the_references_for_any_sum_of_800_samples(sum in -800 * i64::from(i32::MAX)..=800 * i64::from(i32::MAX)) {
            proptest::prop_assert_eq!(truncated_mean(sum, 800), reference_mean(sum));
        }
    }

    #[test]
    fn a_completed_calibration_gives_the_truncated_means() {
        let mut c = Calibrator::new(CalibrationConfig { settle_ticks: 0, samples: 800, motion_check: None });
        c.settle();
        let mut out = None;
        for k in 0..800 {
            // Sums 800·7 + 799 (→ 7), −800·3 (→ −3), 800·2 − 1 (→ 1, not 2).
            let a0 = if k == 0 { 7 * 800 + 799 } else { 0 };
            let a1 = if k == 0 { -3 * 800 } else { 0 };
            let g2 = if k == 0 { 2 * 800 - 1 } else { 0 };
            out = c.feed(BodyImu { accel_mg: [a0, a1, 1000], gyro_mdps: [0, 0, g2] });
        }
        assert_eq!(out, Some(Offsets { accel_mg: [7, -3, 1000], gyro_mdps: [0, 0, 1] }));
    }
}
