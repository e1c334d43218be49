//! Throttle mapping, quad-X mixing and the compare-value clamp.
//!
//! Motor numbering and signs are the reference's (`docs/reference.md#motors`), with
//! `s = [x, y, z]` = pitch, roll and yaw commands:
//!
//! | motor | position | spin | mix |
//! |---|---|---|---|
//! | M1 (TIM4 CH1, PB6) | rear right | CW | thr − x − y + z |
//! | M2 (CH2, PB7) | front right | CCW | thr + x − y − z |
//! | M3 (CH3, PB8) | front left | CW | thr + x + y + z |
//! | M4 (CH4, PB9) | rear left | CCW | thr − x + y − z |
//!
//! Positive pitch (nose up) raises the front motors, positive roll (right side down)
//! raises the left ones, positive yaw (counter-clockwise) raises the CW-spinning pair.

use crate::rc::StickCounts;

/// A motor command in TIM4 compare counts, before the compare clamp: the reference's `int16`
/// `motor_thr`, what the throttle stick maps to. Its own type so that a stick value (also 16-bit
/// counts, [`StickCounts`]) cannot be passed where a compare value is meant; the registers'
/// values after the clamp are `u16` ([`MixerConfig::to_compare`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
#[repr(transparent)]
pub struct CompareCounts(pub i16);

/// Sign of each command axis `[x, y, z]` in each motor.
pub const MIX: [[f32; 3]; 4] = [[-1.0, -1.0, 1.0], [1.0, -1.0, -1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, -1.0]];

/// What happens when a motor command leaves the compare range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Saturate {
    /// Each motor clamped on its own (reference): a saturated motor loses the attitude
    /// correction it was asked for.
    Clip,
    /// Shift all four (and, if the spread itself does not fit, scale the corrections) so
    /// the differences between motors, i.e. the torques, survive.
    AttitudePriority,
}

/// Throttle map and compare range of one motor build.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MixerConfig {
    /// `motor_thr = (int16)(slope·gTHR + offset)`, counts.
    pub throttle_slope: f32,
    pub throttle_offset: f32,
    /// Compare range: a command ≤ min writes min, ≥ max writes max.
    pub min_compare: f32,
    pub max_compare: f32,
    /// TIM4 prescaler and auto-reload (the period is `arr + 1` counts).
    pub timer_psc: u16,
    pub timer_arr: u16,
    pub saturate: Saturate,
}

impl MixerConfig {
    /// DC build (on-board MOSFETs, 494 Hz): 0.33333·gTHR + 633.333, compare 0..1900 of 2000.
    pub const REFERENCE_DC: MixerConfig = MixerConfig {
        throttle_slope: 0.33333,
        throttle_offset: 633.333,
        min_compare: 0.0,
        max_compare: 1900.0,
        timer_psc: 84,
        timer_arr: 1999,
        saturate: Saturate::Clip,
    };

    /// ESC build (400 Hz): 0.32·gTHR + 900, idle 850, max 1700 of 2076.
    pub const REFERENCE_ESC: MixerConfig = MixerConfig {
        throttle_slope: 0.32,
        throttle_offset: 900.0,
        min_compare: 850.0,
        max_compare: 1700.0,
        timer_psc: 100,
        timer_arr: 2075,
        saturate: Saturate::Clip,
    };

    /// This throttle map for a thrust gain `g` (see `control::BatteryCompensation`); the
    /// compare range is the timer's and does not move.
    pub fn scaled_throttle(&self, g: f32) -> MixerConfig {
        MixerConfig { throttle_slope: self.throttle_slope * g, throttle_offset: self.throttle_offset * g, ..*self }
    }

    pub fn is_valid(&self) -> bool {
        use crate::math::within;
        within(self.throttle_slope, 0.0, f32::MAX)
            && within(self.throttle_offset, f32::MIN, f32::MAX)
            // Both compares finite: the minimum at least 0, the maximum above it and at most
            // the period.
            && self.min_compare >= 0.0
            && self.min_compare < self.max_compare
            && self.max_compare <= self.period_counts()
            // CCRx is 16 bits: ARR + 1 = 65 536 (full duty at ARR 65 535) would be written as 0.
            && self.max_compare <= f32::from(u16::MAX)
    }

    /// TIM4 counts per PWM period (`arr + 1`): the compare value of full duty.
    pub fn period_counts(&self) -> f32 {
        f32::from(self.timer_arr) + 1.0
    }

    /// The compare value written when the motors must not run: 0 (DC) or the ESC idle pulse.
    pub fn off_compare(&self) -> u16 {
        self.to_compare(self.min_compare)
    }

    /// The reference's `(int16)(slope·gTHR + offset)`, saturating instead of undefined.
    pub fn throttle_counts(&self, throttle: StickCounts) -> CompareCounts {
        // Through i32 and a saturate to 16 bits: the same result as `as i16` for every input
        // (docs/performance.md, «integer throttle cast»).
        let v = (self.throttle_slope * f32::from(throttle.0) + self.throttle_offset) as i32;
        CompareCounts(v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16)
    }

    /// Distribute throttle and commands to the four motors. Returns the motor commands
    /// (before the compare clamp) and, per axis, the direction the mix could not deliver.
    pub fn mix(&self, throttle: CompareCounts, s: [f32; 3]) -> ([f32; 4], Saturation) {
        let thr = f32::from(throttle.0);
        let [x, y, z] = s;
        // The reference's exact expressions: ((thr ∓ x) ∓ y) ± z, then "+ MOTOR_OFF" (0).
        let reference = [thr - x - y + z + 0.0, thr + x - y - z + 0.0, thr + x + y + z + 0.0, thr - x + y - z + 0.0];
        match self.saturate {
            Saturate::Clip => (reference, Saturation::NONE),
            Saturate::AttitudePriority => self.mix_attitude_priority(thr, s),
        }
    }

    fn mix_attitude_priority(&self, thr: f32, s: [f32; 3]) -> ([f32; 4], Saturation) {
        let [x, y, z] = s;
        // The quad-X rows of MIX: the corrections are z − (x+y), (x−y) − z, (x+y) + z and
        // −(x−y) − z, so their extremes are z ± |x+y| and ±|x−y| − z, each exactly one of the
        // four (docs/performance.md, «extremes from |x ± y|»). A NaN is caught by `spread`
        // below.
        let (a, b) = (x + y, x - y);
        let corrections = [z - a, b - z, a + z, -b - z];
        let (abs_a, abs_b) = (a.abs(), b.abs());
        let lower = |a: f32, b: f32| if b < a { b } else { a };
        let upper = |a: f32, b: f32| if b > a { b } else { a };
        let highest = upper(z + abs_a, abs_b - z);
        let lowest = lower(z - abs_a, -abs_b - z);
        let range = self.max_compare - self.min_compare;
        let spread = highest - lowest;
        let none = Saturation::NONE;
        if spread <= range {
            // The usual case: shift the throttle (never above what fits) so no motor clips.
            // (`thr` comes from an i16, so it is finite; a NaN spread fails this test.)
            let hi_thr = self.max_compare - highest;
            let lo_thr = self.min_compare - lowest;
            let t = if thr < hi_thr { thr } else { hi_thr };
            let base = if t > lo_thr { t } else { lo_thr };
            return (corrections.map(|r| base + r), none);
        }
        if !spread.is_finite() {
            return ([self.min_compare; 4], none);
        }
        // Even the corrections alone do not fit: keep their proportions, centred.
        let sat = Saturation::of_commands(s);
        let scale = range / spread;
        let base = self.min_compare - lowest * scale;
        (corrections.map(|r| base + r * scale), sat)
    }

    /// The reference's `set_motor_pwm`: `cmd ≥ max → max`, `cmd ≤ min → min`, otherwise
    /// truncated. NaN, which the C would turn into an undefined compare value, gives `min`.
    pub fn to_compare(&self, cmd: f32) -> u16 {
        self.compare_range().to_compare(cmd)
    }

    /// The compare range in counts, for converting several commands.
    pub fn compare_range(&self) -> CompareRange {
        // The validated range is 0 ≤ min < max ≤ 65535, so both casts are exact truncations.
        CompareRange { min_counts: self.min_compare as i32, max_counts: self.max_compare as i32 }
    }
}

/// The compare range truncated to whole counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompareRange {
    pub min_counts: i32,
    pub max_counts: i32,
}

impl CompareRange {
    /// Truncate, then clamp in integers. Clamping the float first and truncating after (the
    /// reference's order) gives the same count for every input when `0 ≤ min`: truncation is
    /// monotonic and maps `min`, `max` to `min_counts`, `max_counts`. NaN truncates to 0 and
    /// then clamps to `min_counts`, as the float clamp sends it to `min`. One `vcvt` and two
    /// integer compares instead of two float compares per motor.
    pub fn to_compare(self, cmd: f32) -> u16 {
        crate::math::limit(cmd as i32, self.min_counts, self.max_counts) as u16
    }
}

/// Which directions of which axes the mixer could not deliver on the last tick: one byte
/// for the three axes (bit `2·axis` positive, `2·axis + 1` negative), so the tick reads and
/// writes it once rather than six flags one by one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Saturation(u8);

impl Saturation {
    /// Nothing saturated.
    pub const NONE: Saturation = Saturation(0);

    /// Every axis whose command is non-zero, in the direction of its sign (what the mixer
    /// reports when it has to scale all corrections down).
    pub fn of_commands(s: [f32; 3]) -> Saturation {
        let mut set = Saturation::NONE;
        for (axis, v) in s.into_iter().enumerate() {
            set = set.with(axis, v > 0.0, v < 0.0);
        }
        set
    }

    /// This set with `axis` saturated in the given directions as well.
    pub fn with(self, axis: usize, positive: bool, negative: bool) -> Saturation {
        let bits = u8::from(positive) | u8::from(negative) << 1;
        Saturation(self.0 | bits.checked_shl(2 * axis as u32).unwrap_or(0))
    }

    pub fn positive(self, axis: usize) -> bool {
        self.axis_bits(axis) & 1 != 0
    }

    pub fn negative(self, axis: usize) -> bool {
        self.axis_bits(axis) & 2 != 0
    }

    /// The two bits of one axis.
    pub(crate) fn axis_bits(self, axis: usize) -> u8 {
        self.0.checked_shr(2 * axis as u32).unwrap_or(0) & 3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_scale_compare_that_would_wrap_to_zero_is_refused() {
        let wraps = MixerConfig { timer_arr: u16::MAX, max_compare: 65_536.0, ..MixerConfig::REFERENCE_DC };
        assert!(!wraps.is_valid(), "compare 65536 is written to a 16-bit CCR as 0: full throttle would stop the motors");
        let fits = MixerConfig { timer_arr: u16::MAX, max_compare: 65_535.0, ..MixerConfig::REFERENCE_DC };
        assert!(fits.is_valid());
    }

    #[test]
    fn reference_throttle_map_spot_values() {
        let m = MixerConfig::REFERENCE_DC;
        assert_eq!(m.throttle_counts(StickCounts(200)), CompareCounts(699));
        assert_eq!(m.throttle_counts(StickCounts(1500)), CompareCounts(1133));
        assert_eq!(m.throttle_counts(StickCounts(3630)), CompareCounts(1843));
    }

    #[test]
    fn reference_mixer_worked_example() {
        let m = MixerConfig::REFERENCE_DC;
        let (cmd, _) = m.mix(CompareCounts(1133), [50.0, -20.0, 10.0]);
        let ccr = cmd.map(|c| m.to_compare(c));
        assert_eq!(ccr, [1113, 1193, 1173, 1053]);
    }

    #[test]
    fn compare_clamp_handles_nan_and_infinities() {
        let m = MixerConfig::REFERENCE_DC;
        assert_eq!(m.to_compare(f32::NAN), 0);
        assert_eq!(m.to_compare(f32::INFINITY), 1900);
        assert_eq!(m.to_compare(f32::NEG_INFINITY), 0);
        assert_eq!(m.to_compare(1899.9), 1899);
        let esc = MixerConfig::REFERENCE_ESC;
        assert_eq!(esc.to_compare(f32::NAN), 850);
        assert_eq!(esc.off_compare(), 850);
    }

    #[test]
    fn attitude_priority_keeps_the_roll_torque_when_a_motor_hits_the_top() {
        let mut m = MixerConfig::REFERENCE_DC;
        let s = [0.0, 300.0, 0.0];
        let (clipped, _) = m.mix(CompareCounts(1800), s);
        let clip_ccr = clipped.map(|c| m.to_compare(c));
        m.saturate = Saturate::AttitudePriority;
        let (kept, sat) = m.mix(CompareCounts(1800), s);
        let ccr = kept.map(|c| m.to_compare(c));
        let torque = |c: [u16; 4]| (i32::from(c[2]) + i32::from(c[3])) - (i32::from(c[0]) + i32::from(c[1]));
        // Reference: left motors clip at 1900, torque shrinks to 2·(1900 − 1500) = 800.
        assert_eq!(torque(clip_ccr), 2 * (1900 - 1500));
        // Attitude priority: the full 4·300 = 1200 survives, the throttle gives way.
        assert!((torque(ccr) - 1200).abs() <= 2, "{ccr:?}");
        assert_eq!(sat, Saturation::NONE);
    }

    #[test]
    fn attitude_priority_spreads_the_corrections_as_the_mix_matrix() {
        let m = MixerConfig { saturate: Saturate::AttitudePriority, ..MixerConfig::REFERENCE_DC };
        for s in [[50.0, -20.0, 10.0], [-300.0, 120.5, -40.25], [0.0, 0.0, 700.0], [1.5, 2.5, -3.5]] {
            let (cmd, _) = m.mix(CompareCounts(1000), s);
            for (c, row) in cmd.iter().zip(MIX) {
                let want = 1000.0 + row[0] * s[0] + row[1] * s[1] + row[2] * s[2];
                assert!((c - want).abs() < 1e-3, "{s:?}: {c} vs {want}");
            }
        }
    }

    #[test]
    fn attitude_priority_scales_when_the_spread_does_not_fit() {
        let m = MixerConfig { saturate: Saturate::AttitudePriority, ..MixerConfig::REFERENCE_DC };
        let (cmd, sat) = m.mix(CompareCounts(1000), [800.0, 800.0, 0.0]);
        for c in cmd {
            assert!((-0.01..=1900.01).contains(&c), "{c}");
        }
        assert!(sat.positive(0) && sat.positive(1) && !sat.positive(2));
    }

    /// The reference's order: clamp in float, then truncate.
    fn compare_float_first(m: &MixerConfig, cmd: f32) -> u16 {
        let v = if cmd >= m.max_compare {
            m.max_compare
        } else if cmd > m.min_compare {
            cmd
        } else {
            m.min_compare
        };
        v as u16
    }

    #[test]
    fn compare_truncating_first_equals_the_reference_order_near_the_limits() {
        let non_integer = MixerConfig { min_compare: 850.5, max_compare: 1699.75, ..MixerConfig::REFERENCE_ESC };
        for m in [MixerConfig::REFERENCE_DC, MixerConfig::REFERENCE_ESC, non_integer] {
            for edge in [m.min_compare, m.max_compare, 0.0] {
                let mut x = edge - 3.0;
                while x <= edge + 3.0 {
                    for v in [x, f32::from_bits(x.to_bits() + 1), f32::from_bits(x.to_bits().saturating_sub(1))] {
                        assert_eq!(m.to_compare(v), compare_float_first(&m, v), "{v} with {m:?}");
                    }
                    x += 0.125;
                }
            }
        }
    }

    proptest::proptest! {
        #[test]
        fn compare_truncating_first_equals_the_reference_order(cmd in proptest::num::f32::ANY, esc in proptest::bool::ANY) {
            let m = if esc { MixerConfig::REFERENCE_ESC } else { MixerConfig::REFERENCE_DC };
            proptest::prop_assert_eq!(m.to_compare(cmd), compare_float_first(&m, cmd));
        }

        #[test]
        fn compare_values_stay_in_range_for_any_input(
            thr in proptest::num::i16::ANY,
            x in proptest::num::f32::ANY,
            y in proptest::num::f32::ANY,
            z in proptest::num::f32::ANY,
            priority in proptest::bool::ANY,
            esc in proptest::bool::ANY,
        ) {
            let mut m = if esc { MixerConfig::REFERENCE_ESC } else { MixerConfig::REFERENCE_DC };
            if priority { m.saturate = Saturate::AttitudePriority; }
            let (cmd, _) = m.mix(CompareCounts(thr), [x, y, z]);
            for c in cmd {
                let ccr = m.to_compare(c);
                proptest::prop_assert!(f32::from(ccr) >= m.min_compare && f32::from(ccr) <= m.max_compare);
            }
        }
    }
}
