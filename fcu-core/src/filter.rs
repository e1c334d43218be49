//! Discrete filters: the reference's direct-form-I biquad, its Butterworth design, a
//! first-order low-pass and the block average of the outer loop.

/// Biquad coefficients in the reference's convention: the feedback coefficients are stored
/// **pre-negated**, so `y = b0·x + b1·x₁ + b2·x₂ + a1·y₁ + a2·y₂`
/// (standard form `H(z) = (b0 + b1 z⁻¹ + b2 z⁻²) / (1 − a1 z⁻¹ − a2 z⁻²)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BiquadCoeffs {
    pub a1: f32,
    pub a2: f32,
    pub b0: f32,
    pub b1: f32,
    pub b2: f32,
}

impl BiquadCoeffs {
    /// The reference's gyro filter: Butterworth 100 Hz at 800 Hz, the C double literals
    /// rounded to f32 exactly as the C initialiser does.
    pub const REFERENCE_GYRO: BiquadCoeffs = BiquadCoeffs {
        a1: 0.942_809_041_582_063_4_f64 as f32,
        a2: -0.333_333_333_333_333_4_f64 as f32,
        b0: 0.097_631_072_937_817_49_f64 as f32,
        b1: 0.195_262_145_875_634_98_f64 as f32,
        b2: 0.097_631_072_937_817_49_f64 as f32,
    };

    /// The default profile's gyro low-pass: Butterworth at 150 Hz for 800 Hz, i.e.
    /// `butterworth_lowpass(150.0, 800.0)` (tested equal), as a constant so that building a
    /// configuration cannot fail. Half the reference's lag at the loop's crossover (~4° at
    /// 10 Hz instead of 8°), and still −17 dB at the 400 Hz Nyquist limit.
    pub const GYRO_150_HZ_AT_800_HZ: BiquadCoeffs = {
        let a1 = 0.462_938_025_291_040_94_f64 as f32;
        let a2 = -0.209_715_357_756_554_64_f64 as f32;
        let b0 = ((1.0 - a1 as f64 - a2 as f64) / 4.0) as f32;
        BiquadCoeffs { a1, a2, b0, b1: 2.0 * b0, b2: b0 }
    };

    /// Second-order Butterworth low-pass by the bilinear transform with pre-warping, the
    /// design the reference's coefficients come from. `None` unless `0 < cutoff < fs/2`.
    pub fn butterworth_lowpass(cutoff_hz: f32, sample_hz: f32) -> Option<BiquadCoeffs> {
        if !(cutoff_hz > 0.0 && sample_hz.is_finite() && cutoff_hz < 0.5 * sample_hz) {
            return None;
        }
        let k = libm::tan(core::f64::consts::PI * f64::from(cutoff_hz) / f64::from(sample_hz));
        let sqrt2 = core::f64::consts::SQRT_2;
        let norm = 1.0 / (1.0 + sqrt2 * k + k * k);
        let a1 = (2.0 * (1.0 - k * k) * norm) as f32;
        let a2 = (-(1.0 - sqrt2 * k + k * k) * norm) as f32;
        // The numerator from the poles as rounded: b0 + b1 + b2 = 4·b0 = 1 − a1 − a2, so the DC
        // gain is 1 to f32 precision however low the cut-off. (Rounding the f64 design's own
        // b0 leaves an error of order ulp(a1) / (fc/fs)²: 1e-3 at 10 Hz, 0.1 at 1 Hz.) For the
        // usual cut-offs this is the design's b0 to within an ulp.
        let b0 = ((1.0 - f64::from(a1) - f64::from(a2)) / 4.0) as f32;
        Some(BiquadCoeffs { a1, a2, b0, b1: 2.0 * b0, b2: b0 })
    }

    /// Gain at 0 Hz: `(b0 + b1 + b2) / (1 − a1 − a2)`.
    pub fn dc_gain(&self) -> f32 {
        (self.b0 + self.b1 + self.b2) / (1.0 - self.a1 - self.a2)
    }

    /// True when every coefficient is finite and the poles are inside the unit circle
    /// (the stability triangle of `1 − a1 z⁻¹ − a2 z⁻²`).
    pub fn is_stable(&self) -> bool {
        let finite = |c: f32| crate::math::within(c, f32::MIN, f32::MAX);
        // The poles' bounds hold only for finite `a1` and `a2`.
        finite(self.b0) && finite(self.b1) && finite(self.b2) && self.a2.abs() < 1.0 && self.a1.abs() < 1.0 - self.a2
    }
}

/// Direct-form-I biquad with the reference's state shift and evaluation order
/// (`((((b0·x + b1·x₁) + b2·x₂) + a1·y₁) + a2·y₂`, every product rounded to f32).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Biquad {
    c: BiquadCoeffs,
    s: BiquadState,
}

/// The memory of one direct-form-I channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct BiquadState {
    x1: f32,
    x2: f32,
    y1: f32,
    y2: f32,
}

impl BiquadState {
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    fn update(&mut self, c: &BiquadCoeffs, x: f32) -> f32 {
        let y = c.b0 * x + c.b1 * self.x1 + c.b2 * self.x2 + c.a1 * self.y1 + c.a2 * self.y2;
        self.x2 = self.x1;
        self.x1 = x;
        self.y2 = self.y1;
        self.y1 = y;
        y
    }

    fn reset_to(&mut self, c: &BiquadCoeffs, x: f32) {
        let y = x * c.dc_gain();
        *self = BiquadState { x1: x, x2: x, y1: y, y2: y };
    }
}

impl Biquad {
    pub const fn new(c: BiquadCoeffs) -> Self {
        Biquad { c, s: BiquadState { x1: 0.0, x2: 0.0, y1: 0.0, y2: 0.0 } }
    }

    pub fn update(&mut self, x: f32) -> f32 {
        self.s.update(&self.c, x)
    }

    /// Start from a steady state at `x` (no start-up transient), used after a reset.
    pub fn reset_to(&mut self, x: f32) {
        self.s.reset_to(&self.c, x);
    }
}

/// `N` biquads with the same coefficients (the three gyro axes), each coefficient read once
/// per update instead of once per channel. Each channel computes exactly what a [`Biquad`]
/// with these coefficients computes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BiquadBank<const N: usize> {
    c: BiquadCoeffs,
    s: [BiquadState; N],
}

impl<const N: usize> BiquadBank<N> {
    pub fn new(c: BiquadCoeffs) -> Self {
        BiquadBank { c, s: [BiquadState::default(); N] }
    }

    /// New coefficients, the filters' memory kept (a run-time change of the cut-off).
    pub fn set_coefficients(&mut self, c: BiquadCoeffs) {
        self.c = c;
    }

    pub fn update(&mut self, x: [f32; N]) -> [f32; N] {
        let c = self.c;
        let mut y = [0.0; N];
        for ((y, s), x) in y.iter_mut().zip(&mut self.s).zip(x) {
            *y = s.update(&c, x);
        }
        y
    }

    /// Every channel to a steady state at `x`.
    pub fn reset_to(&mut self, x: f32) {
        let c = self.c;
        for s in &mut self.s {
            s.reset_to(&c, x);
        }
    }
}

/// First-order low-pass (PT1) in the reference's EMA form `y += (x − y)·k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pt1 {
    pub k: f32,
    pub y: f32,
}

impl Pt1 {
    pub const fn new(k: f32) -> Self {
        Pt1 { k, y: 0.0 }
    }

    /// The EMA factor of a first-order low-pass with `cutoff_hz` at `sample_hz`.
    pub fn coefficient(cutoff_hz: f32, sample_hz: f32) -> f32 {
        let rc_dt = sample_hz / (core::f32::consts::TAU * cutoff_hz);
        1.0 / (1.0 + rc_dt)
    }

    pub fn update(&mut self, x: f32) -> f32 {
        self.y = self.y + (x - self.y) * self.k;
        self.y
    }
}

/// The number of samples in the outer-loop block (the reference's `FIFO_Order`).
pub const BLOCK: usize = 5;

/// Add one sample to a running block sum. The reference averages a block of [`BLOCK`]
/// stored vectors as an f32 sum from 0.0 over slots 0..4, then `× 0.2`: a sum kept tick by
/// tick from 0.0, in slot order, is that sum bit for bit (same order, same roundings).
#[inline(always)] // docs/performance.md, «inlined into the tick».
pub fn accumulate(sum: &mut [f32; 3], x: [f32; 3]) {
    for (s, x) in sum.iter_mut().zip(x) {
        *s += x;
    }
}

/// The mean of a block from its sum: `sum · 0.2`, in f64 as the reference (reference
/// arithmetic) or in f32. Always inlined, so that a caller's constant `false` leaves no f64
/// code behind (the firmware, built without the `reference` feature).
#[inline(always)] // docs/performance.md, «inlined into the tick».
pub fn block_mean(sum: [f32; 3], reference_arithmetic: bool) -> [f32; 3] {
    sum.map(|s| if reference_arithmetic { (f64::from(s) * 0.2) as f32 } else { s * 0.2 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_gyro_filter_is_the_150hz_butterworth_at_800hz() {
        assert_eq!(BiquadCoeffs::butterworth_lowpass(150.0, 800.0), Some(BiquadCoeffs::GYRO_150_HZ_AT_800_HZ));
    }

    #[test]
    fn reference_coefficients_are_the_100hz_butterworth_at_800hz() {
        let d = BiquadCoeffs::butterworth_lowpass(100.0, 800.0).unwrap();
        let r = BiquadCoeffs::REFERENCE_GYRO;
        for (a, b) in [(d.a1, r.a1), (d.a2, r.a2), (d.b0, r.b0), (d.b1, r.b1), (d.b2, r.b2)] {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
    }

    #[test]
    fn butterworth_rejects_cutoff_at_or_above_nyquist() {
        assert!(BiquadCoeffs::butterworth_lowpass(400.0, 800.0).is_none());
        assert!(BiquadCoeffs::butterworth_lowpass(0.0, 800.0).is_none());
        assert!(BiquadCoeffs::butterworth_lowpass(f32::NAN, 800.0).is_none());
    }

    #[test]
    fn step_response_matches_the_reference_worked_example() {
        // docs/reference.md#examples: the gyro filter's step response.
        let mut f = Biquad::new(BiquadCoeffs::REFERENCE_GYRO);
        let want = [97.6311, 384.9407, 720.9061, 941.8876, 1038.2424, 1055.4261, 1039.5088, 1018.7738];
        for w in want {
            let y = f.update(1000.0);
            assert!((y - w).abs() < 1e-3, "{y} vs {w}");
        }
    }

    #[test]
    fn reset_to_gives_a_steady_state() {
        let mut f = Biquad::new(BiquadCoeffs::butterworth_lowpass(80.0, 800.0).unwrap());
        f.reset_to(250.0);
        for _ in 0..10 {
            assert!((f.update(250.0) - 250.0).abs() < 0.01);
        }
    }

    #[test]
    fn a_bank_channel_is_bit_for_bit_a_biquad() {
        let c = BiquadCoeffs::REFERENCE_GYRO;
        let mut bank = BiquadBank::<3>::new(c);
        let mut single = [Biquad::new(c); 3];
        for k in 0..200u16 {
            let x = [f32::from(k % 17) * 70.0, -f32::from(k) * 3.5, f32::from(k * 7 % 31) - 15.0];
            let y = bank.update(x);
            for ((y, f), x) in y.iter().zip(&mut single).zip(x) {
                assert_eq!(y.to_bits(), f.update(x).to_bits());
            }
        }
        bank.reset_to(12.5);
        single[1].reset_to(12.5);
        assert_eq!(bank.update([1.0; 3])[1].to_bits(), single[1].update(1.0).to_bits());
    }

    #[test]
    fn pt1_coefficient_gives_the_reference_corner() {
        // The reference's 0.025 at 800 Hz is a ~3.2 Hz corner.
        let k = Pt1::coefficient(3.2, 800.0);
        assert!((k - 0.025).abs() < 0.001, "{k}");
    }

    #[test]
    fn block_average_of_constant_is_the_constant() {
        let mut sum = [0.0f32; 3];
        for _ in 0..BLOCK {
            accumulate(&mut sum, [1.5, -2.0, 1000.0]);
        }
        assert_eq!(block_mean(sum, true), [1.5, -2.0, 1000.0]);
        assert_eq!(block_mean(sum, false), [1.5, -2.0, 1000.0]);
    }

    proptest::proptest! {
        // Down to 0.5 Hz at 1 kHz, where 1 − a1 − a2 is about 2e-5: the numerator is taken
        // from the rounded poles, so the gain stays 1 to f32 precision.
        #[test]
        fn butterworth_dc_gain_is_one(fc in 0.5f32..390.0, fs in 800.0f32..1000.0) {
            let c = BiquadCoeffs::butterworth_lowpass(fc, fs).unwrap();
            proptest::prop_assert!((c.dc_gain() - 1.0).abs() < 1e-5, "gain {}", c.dc_gain());
            proptest::prop_assert!(c.is_stable());
        }

        #[test]
        fn biquad_settles_to_its_input(x in -2.3e6f32..2.3e6) {
            let mut f = Biquad::new(BiquadCoeffs::REFERENCE_GYRO);
            let mut y = 0.0;
            for _ in 0..200 { y = f.update(x); }
            proptest::prop_assert!((y - x).abs() <= 1e-4 * x.abs().max(1.0));
        }
    }
}
