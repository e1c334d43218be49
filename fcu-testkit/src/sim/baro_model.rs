//! The simulated LPS22HB in its flight configuration (`fcu_core::baro::registers`: 75 Hz, the
//! ODR/20 low-pass, BDU), a barometer that lies like a real one: its coefficients are drawn per
//! seed, so that no tune of the estimator fits one value.
//!
//! What the part reads, in order:
//! - the air's pressure at the drone's height (ISA, from the take-off level's pressure);
//! - a fixed offset (soldering, the part's accuracy) and a slow thermal drift (the board warms
//!   up after power-on and the part's offset follows its temperature);
//! - prop wash: a bias proportional to the collective thrust, of unknown sign and size (where
//!   the sensor sits in the downwash decides both);
//! - ground effect: near the floor the wash raises the pressure under the drone, in proportion
//!   to the thrust, fading within a few rotor diameters;
//! - gusts: the wind's dynamic pressure on the package's hole, `c·½ρv²`, of unknown sign
//!   (stagnation or suction) and size;
//! - the part itself: its low-pass at ODR/20, a sample at each ODR period with the datasheet's
//!   noise (0.0075 hPa RMS), quantised to 1/4096 hPa.
//!
//! Not yet called by the simulator's loop (`docs/altitude.md`).

use fcu_core::baro::registers::{status, BURST_LEN};
use fcu_core::baro::{RawBaro, COUNTS_PER_DEG_C, PA_PER_COUNT};

use super::rng::Rng;

/// Sea-level air density, kg/m³ (the dynamic pressure of a gust).
const AIR_DENSITY_KG_M3: f64 = 1.225;

/// The part's rates and noise, and the ranges the seed draws the airframe's errors from.
#[derive(Clone, Debug, PartialEq)]
pub struct BaroModelParams {
    /// Pressure at the take-off level, Pa, and the air's temperature, °C.
    pub ground_pa: f64,
    pub ambient_c: f64,
    pub odr_hz: f64,
    /// The part's low-pass bandwidth, Hz (ODR/20).
    pub filter_hz: f64,
    /// Noise of one sample, Pa RMS (datasheet: 0.0075 hPa with the filter, low-noise mode).
    pub noise_pa: f64,
    /// Offset drawn uniformly in ± this, Pa: ±1 hPa, as soldering shifts a part's offset well
    /// beyond the datasheet's ±0.1 hPa accuracy (the estimator re-zeroes, so it must not care).
    pub offset_max_pa: f64,
    /// The board's warm-up after power-on: a rise drawn in 25–100 % of this, °C, with a time
    /// constant drawn in the range, s.
    pub warmup_max_c: f64,
    pub warmup_tau_s: (f64, f64),
    /// The offset's temperature coefficient, drawn in ± this, Pa/°C. The datasheet's relative
    /// accuracy, ±0.1 hPa over 0–65 °C, bounds the slope near 0.3 Pa/°C.
    pub thermal_max_pa_per_c: f64,
    /// Prop wash at full collective thrust: magnitude drawn in 20–100 % of this, sign either, Pa.
    pub wash_max_pa: f64,
    /// Ground effect at full thrust on the floor: drawn in 20–100 % of this, Pa (always an
    /// overpressure), fading as `1/(1 + (h/h0)²)` with `h0` drawn in the range, m.
    pub ground_effect_max_pa: f64,
    pub ground_effect_height_m: (f64, f64),
    /// Pressure coefficient of the wind on the package: magnitude in 20–100 % of this, sign
    /// either.
    pub gust_coefficient_max: f64,
}

impl Default for BaroModelParams {
    /// A drone of this size with the sensor on its board under the props: a wash of up to
    /// 15 Pa at full thrust (up to a metre and a quarter: a few tenths at hover), up to 10 Pa of
    /// ground effect, a 1–4 °C warm-up over minutes.
    fn default() -> Self {
        BaroModelParams {
            ground_pa: 101_325.0,
            ambient_c: 25.0,
            odr_hz: 75.0,
            filter_hz: 75.0 / 20.0,
            noise_pa: 0.75,
            offset_max_pa: 100.0,
            warmup_max_c: 4.0,
            warmup_tau_s: (100.0, 300.0),
            thermal_max_pa_per_c: 0.3,
            wash_max_pa: 15.0,
            ground_effect_max_pa: 10.0,
            ground_effect_height_m: (0.05, 0.15),
            gust_coefficient_max: 1.0,
        }
    }
}

impl BaroModelParams {
    /// A perfect part (still sampled, filtered and quantised): for tests of the rest of the chain.
    pub fn ideal() -> Self {
        BaroModelParams {
            noise_pa: 0.0,
            offset_max_pa: 0.0,
            warmup_max_c: 0.0,
            thermal_max_pa_per_c: 0.0,
            wash_max_pa: 0.0,
            ground_effect_max_pa: 0.0,
            gust_coefficient_max: 0.0,
            ..BaroModelParams::default()
        }
    }
}

/// The seed's draw of the errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaroErrors {
    pub offset_pa: f64,
    pub warmup_c: f64,
    pub warmup_tau_s: f64,
    pub thermal_pa_per_c: f64,
    /// At full collective thrust.
    pub wash_pa: f64,
    /// At full thrust on the floor.
    pub ground_effect_pa: f64,
    pub ground_effect_height_m: f64,
    pub gust_coefficient: f64,
}

impl BaroErrors {
    fn draw(p: &BaroModelParams, rng: &mut Rng) -> Self {
        let between = |rng: &mut Rng, (lo, hi): (f64, f64)| lo + (hi - lo) * rng.uniform();
        let magnitude = |rng: &mut Rng, max: f64| max * between(rng, (0.2, 1.0));
        let signed = |rng: &mut Rng, max: f64| {
            let m = magnitude(rng, max);
            if rng.chance(0.5) {
                m
            } else {
                -m
            }
        };
        BaroErrors {
            offset_pa: p.offset_max_pa * rng.symmetric(),
            warmup_c: p.warmup_max_c * between(rng, (0.25, 1.0)),
            warmup_tau_s: between(rng, p.warmup_tau_s).max(1.0),
            thermal_pa_per_c: p.thermal_max_pa_per_c * rng.symmetric(),
            wash_pa: signed(rng, p.wash_max_pa),
            ground_effect_pa: magnitude(rng, p.ground_effect_max_pa),
            ground_effect_height_m: between(rng, p.ground_effect_height_m).max(1e-3),
            gust_coefficient: signed(rng, p.gust_coefficient_max),
        }
    }
}

/// What the part is exposed to at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BaroInputs {
    /// Height of the sensor above the take-off level (the floor), m.
    pub height_m: f64,
    /// Collective thrust as a fraction of full (the mean of the motors' speed²).
    pub thrust_fraction: f64,
    /// Speed of the air relative to the drone, m/s.
    pub airspeed_m_s: f64,
}

/// Pressure at `height_m` above a level at `ground_pa` (ISA troposphere).
pub fn isa_pressure_pa(ground_pa: f64, height_m: f64) -> f64 {
    ground_pa * (1.0 - height_m / 44_330.77).max(0.0).powf(1.0 / 0.190_263)
}

/// The part between reads.
#[derive(Clone, Debug)]
pub struct BaroModel {
    params: BaroModelParams,
    errors: BaroErrors,
    rng: Rng,
    since_power_on_s: f64,
    /// The low-pass's output, Pa (None until the first step).
    filtered_pa: Option<f64>,
    time_to_next_sample_s: f64,
    /// The output registers and their flags.
    pressure_counts: i32,
    temperature_counts: i16,
    p_da: bool,
    /// Set by [`BaroModel::freeze`]: the words stop changing, the part still flags new data.
    frozen: bool,
}

impl BaroModel {
    pub fn new(params: BaroModelParams, seed: u64) -> Self {
        let mut rng = Rng::fork(seed, 0x4241_524F);
        let errors = BaroErrors::draw(&params, &mut rng);
        BaroModel {
            params,
            errors,
            rng,
            since_power_on_s: 0.0,
            filtered_pa: None,
            time_to_next_sample_s: 0.0,
            pressure_counts: 0,
            temperature_counts: 0,
            p_da: false,
            frozen: false,
        }
    }

    pub fn params(&self) -> &BaroModelParams {
        &self.params
    }

    pub fn errors(&self) -> &BaroErrors {
        &self.errors
    }

    /// The board's temperature now, °C.
    pub fn temperature_c(&self) -> f64 {
        let e = &self.errors;
        self.params.ambient_c + e.warmup_c * (1.0 - (-self.since_power_on_s / e.warmup_tau_s).exp())
    }

    /// The pressure at the sensing element before the part's filter, Pa: the air plus every
    /// error of the installation.
    pub fn sensed_pa(&self, inputs: &BaroInputs) -> f64 {
        let e = &self.errors;
        let thrust = if inputs.thrust_fraction.is_finite() { inputs.thrust_fraction.clamp(0.0, 1.0) } else { 0.0 };
        let height = if inputs.height_m.is_finite() { inputs.height_m } else { 0.0 };
        let airspeed = if inputs.airspeed_m_s.is_finite() { inputs.airspeed_m_s } else { 0.0 };
        let above_floor = height.max(0.0) / e.ground_effect_height_m;
        isa_pressure_pa(self.params.ground_pa, height)
            + e.offset_pa
            + e.thermal_pa_per_c * (self.temperature_c() - self.params.ambient_c)
            + e.wash_pa * thrust
            + e.ground_effect_pa * thrust / (1.0 + above_floor * above_floor)
            + e.gust_coefficient * 0.5 * AIR_DENSITY_KG_M3 * airspeed * airspeed
    }

    /// Advance the part by `dt_s` (call once per plant substep).
    pub fn step(&mut self, dt_s: f64, inputs: &BaroInputs) {
        self.since_power_on_s += dt_s;
        let sensed = self.sensed_pa(inputs);
        let alpha = 1.0 - (-std::f64::consts::TAU * self.params.filter_hz * dt_s).exp();
        let filtered = match self.filtered_pa {
            Some(f) => f + alpha * (sensed - f),
            None => sensed,
        };
        self.filtered_pa = Some(filtered);
        self.time_to_next_sample_s -= dt_s;
        if self.time_to_next_sample_s <= 0.0 {
            self.time_to_next_sample_s += 1.0 / self.params.odr_hz.max(1.0);
            if !self.frozen {
                let pa = filtered + self.params.noise_pa * self.rng.gaussian();
                // The ADC rounds to the nearest count; `as` saturates.
                self.pressure_counts = (pa / f64::from(PA_PER_COUNT)).round() as i32;
                self.temperature_counts = (self.temperature_c() * f64::from(COUNTS_PER_DEG_C)).round() as i16;
            }
            self.p_da = true;
        }
    }

    /// The burst from STATUS the core reads; reading PRESS_OUT_H clears P_DA, as the part does.
    pub fn read_burst(&mut self) -> [u8; BURST_LEN] {
        let st = if self.p_da { status::P_DA | status::T_DA } else { 0 };
        self.p_da = false;
        let [_, h, l, xl] = self.pressure_counts.to_be_bytes();
        let [tl, th] = self.temperature_counts.to_le_bytes();
        [st, xl, l, h, tl, th]
    }

    /// The same read, decoded.
    pub fn read(&mut self) -> RawBaro {
        fcu_core::baro::decode_burst(&self.read_burst())
    }

    /// Make the part stick at its current words (a fault-injection hook): it still flags new
    /// samples, as a part whose converter hung behind a working interface would.
    pub fn freeze(&mut self) {
        self.frozen = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT_S: f64 = 0.00025;

    fn still() -> BaroInputs {
        BaroInputs::default()
    }

    /// Run for `secs` and collect the pressure of every new sample, Pa.
    fn samples(m: &mut BaroModel, inputs: &BaroInputs, secs: f64) -> Vec<f64> {
        let mut out = Vec::new();
        for _ in 0..(secs / DT_S).round() as usize {
            m.step(DT_S, inputs);
            let r = m.read();
            if r.pressure_fresh() {
                // In f64, where counts · 100/4096 is exact.
                out.push(f64::from(r.pressure_counts) * 100.0 / 4096.0);
            }
        }
        out
    }

    fn mean(v: &[f64]) -> f64 {
        v.iter().sum::<f64>() / v.len().max(1) as f64
    }

    fn rms_about_mean(v: &[f64]) -> f64 {
        let m = mean(v);
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
    }

    /// A model of the `ideal` part with one error switched on by `f`.
    fn with(seed: u64, f: impl FnOnce(&mut BaroModelParams)) -> BaroModel {
        let mut p = BaroModelParams::ideal();
        f(&mut p);
        BaroModel::new(p, seed)
    }

    #[test]
    fn pressure_follows_height_by_the_isa() {
        let mut m = BaroModel::new(BaroModelParams::ideal(), 1);
        let at = |m: &mut BaroModel, h: f64| *samples(m, &BaroInputs { height_m: h, ..still() }, 2.0).last().unwrap_or(&0.0);
        assert!((at(&mut m, 0.0) - 101_325.0).abs() < 0.02);
        // A metre is 12 Pa near the ground; 100 m is 1,195.6 Pa (ISA).
        assert!((at(&mut m, 0.0) - at(&mut m, 1.0) - 12.0).abs() < 0.1);
        assert!((at(&mut m, 100.0) - isa_pressure_pa(101_325.0, 100.0)).abs() < 0.02);
        assert!((101_325.0 - isa_pressure_pa(101_325.0, 100.0) - 1195.56).abs() < 0.01);
        // And the core's own formula reads the heights back.
        let h = fcu_core::altitude::baro_height_m(at(&mut m, 2.0) as f32, 101_325.0);
        assert!((h - 2.0).abs() < 0.003, "{h}");
    }

    #[test]
    fn samples_come_at_the_odr_in_1_over_4096_hpa_steps() {
        let mut m = BaroModel::new(BaroModelParams::default(), 3);
        let s = samples(&mut m, &still(), 2.0);
        assert!((149..=151).contains(&s.len()), "{} samples in 2 s", s.len());
        let count = f64::from(PA_PER_COUNT);
        assert!(s.iter().all(|p| ((p / count) - (p / count).round()).abs() < 1e-6));
        // A change well under one count does not show.
        let mut m = BaroModel::new(BaroModelParams::ideal(), 1);
        let a = samples(&mut m, &still(), 1.0);
        let b = samples(&mut m, &BaroInputs { height_m: 0.0005, ..still() }, 1.0);
        assert_eq!(a.last(), b.last());
    }

    #[test]
    fn the_noise_is_the_datasheets_rms() {
        let mut m = with(5, |p| p.noise_pa = 0.75);
        let s = samples(&mut m, &still(), 40.0);
        let rms = rms_about_mean(&s);
        assert!((rms - 0.75).abs() < 0.05, "{rms} Pa RMS over {} samples", s.len());
        assert!((mean(&s) - 101_325.0).abs() < 0.05);
    }

    #[test]
    fn the_parts_filter_has_its_time_constant() {
        let mut m = BaroModel::new(BaroModelParams::ideal(), 1);
        samples(&mut m, &still(), 0.5);
        // A 120 Pa step (10 m): after one time constant of the 3.75 Hz pole, 63 % of it.
        let tau_s = 1.0 / (std::f64::consts::TAU * 3.75);
        let s = samples(&mut m, &BaroInputs { height_m: -10.0, ..still() }, tau_s + 1.0 / 75.0);
        let step = isa_pressure_pa(101_325.0, -10.0) - 101_325.0;
        let reached = (s.last().unwrap_or(&0.0) - 101_325.0) / step;
        assert!((0.5..0.8).contains(&reached), "{reached}");
    }

    #[test]
    fn offsets_are_drawn_per_seed_within_a_hectopascal() {
        let offsets: Vec<f64> = (0..400).map(|seed| BaroModel::new(BaroModelParams::default(), seed).errors().offset_pa).collect();
        assert!(offsets.iter().all(|o| o.abs() <= 100.0));
        // Uniform in ±100 Pa: mean 0, RMS 100/√3.
        assert!(mean(&offsets).abs() < 8.0, "{}", mean(&offsets));
        let rms = (offsets.iter().map(|o| o * o).sum::<f64>() / offsets.len() as f64).sqrt();
        assert!((rms - 57.7).abs() < 5.0, "{rms}");
        // And it is what the part reads at rest.
        let mut m = with(9, |p| p.offset_max_pa = 100.0);
        let s = samples(&mut m, &still(), 1.0);
        assert!((s.last().unwrap_or(&0.0) - 101_325.0 - m.errors().offset_pa).abs() < 0.02);
    }

    #[test]
    fn the_thermal_drift_is_slow_and_follows_the_warm_up() {
        for seed in 0..20 {
            let mut m = with(seed, |p| {
                p.warmup_max_c = 4.0;
                p.thermal_max_pa_per_c = 0.3;
            });
            let e = *m.errors();
            let first = samples(&mut m, &still(), 1.0);
            let s = samples(&mut m, &still(), 30.0);
            let after_30_s = *s.last().unwrap_or(&0.0);
            let rest = samples(&mut m, &still(), 1500.0);
            let settled = *rest.last().unwrap_or(&0.0);
            let full = e.thermal_pa_per_c * e.warmup_c;
            // After five time constants at least, the whole warm-up shows.
            assert!((settled - *first.first().unwrap_or(&0.0) - full).abs() < 0.05, "seed {seed}: {settled} {full}");
            // Slow: over a 30 s hold early on, less than 0.4 Pa (3 cm) of drift.
            assert!((after_30_s - *first.last().unwrap_or(&0.0)).abs() < 0.4, "seed {seed}");
            assert!((m.temperature_c() - 25.0 - e.warmup_c).abs() < 0.03 && (1.0..=4.0).contains(&e.warmup_c));
        }
    }

    #[test]
    fn prop_wash_is_proportional_to_thrust_with_either_sign() {
        let mut signs = [0, 0];
        for seed in 0..40 {
            let mut m = with(seed, |p| p.wash_max_pa = 15.0);
            let wash = m.errors().wash_pa;
            assert!((3.0..=15.0).contains(&wash.abs()), "{wash}");
            signs[usize::from(wash > 0.0)] += 1;
            // High enough that ground effect (off here anyway) could not matter.
            let at = |m: &mut BaroModel, thrust: f64| {
                *samples(m, &BaroInputs { height_m: 5.0, thrust_fraction: thrust, ..still() }, 1.0).last().unwrap_or(&0.0)
            };
            let idle = at(&mut m, 0.0);
            let half = at(&mut m, 0.5);
            let full = at(&mut m, 1.0);
            assert!((half - idle - 0.5 * wash).abs() < 0.05 && (full - idle - wash).abs() < 0.05, "seed {seed}");
        }
        assert!(signs[0] >= 10 && signs[1] >= 10, "both signs drawn: {signs:?}");
    }

    #[test]
    fn ground_effect_raises_the_pressure_near_the_floor_and_fades_with_height() {
        for seed in 0..20 {
            let mut m = with(seed, |p| p.ground_effect_max_pa = 10.0);
            let e = *m.errors();
            assert!(e.ground_effect_pa > 0.0 && (0.05..=0.15).contains(&e.ground_effect_height_m));
            // Against the pressure of the height alone, at hover-like thrust.
            let excess = |m: &mut BaroModel, h: f64, thrust: f64| {
                let s = samples(m, &BaroInputs { height_m: h, thrust_fraction: thrust, ..still() }, 1.0);
                s.last().unwrap_or(&0.0) - isa_pressure_pa(101_325.0, h)
            };
            let floor = excess(&mut m, 0.0, 0.4);
            assert!((floor - 0.4 * e.ground_effect_pa).abs() < 0.05, "seed {seed}: {floor}");
            assert!(excess(&mut m, 0.0, 0.0).abs() < 0.02, "no wash without thrust");
            let h0 = excess(&mut m, e.ground_effect_height_m, 0.4);
            assert!((h0 - floor / 2.0).abs() < 0.05, "half at h0: {h0} {floor}");
            assert!(excess(&mut m, 1.0, 0.4) < 0.03 * floor + 0.02, "gone at 1 m");
        }
    }

    #[test]
    fn a_gust_gives_a_pressure_transient_of_either_sign() {
        let mut signs = [0, 0];
        for seed in 0..40 {
            let mut m = with(seed, |p| p.gust_coefficient_max = 1.0);
            let c = m.errors().gust_coefficient;
            signs[usize::from(c > 0.0)] += 1;
            let calm = *samples(&mut m, &still(), 1.0).last().unwrap_or(&0.0);
            // A 0.3 s, 2 m/s gust (the `gust` scenario's): ½ρv² = 2.45 Pa times the coefficient.
            let gust = samples(&mut m, &BaroInputs { airspeed_m_s: 2.0, ..still() }, 0.3);
            let after = *samples(&mut m, &still(), 1.0).last().unwrap_or(&0.0);
            let peak = gust.iter().map(|p| p - calm).fold(0.0f64, |a, d| if d.abs() > a.abs() { d } else { a });
            let full = c * 0.5 * 1.225 * 4.0;
            assert!(peak.signum() == c.signum() && (peak.abs() - full.abs()).abs() < 0.1 + 0.01 * full.abs(), "seed {seed}: {peak} {full}");
            assert!((after - calm).abs() < 0.03, "the transient passes");
        }
        assert!(signs[0] >= 10 && signs[1] >= 10, "{signs:?}");
    }

    #[test]
    fn a_read_clears_data_ready_until_the_next_sample() {
        let mut m = BaroModel::new(BaroModelParams::default(), 1);
        m.step(DT_S, &still());
        assert!(m.read().pressure_fresh());
        assert!(!m.read().pressure_fresh());
        let (mut fresh, mut reads) = (0, 0);
        // Read at 160 Hz for a second: 75 of the reads bring a new sample.
        for k in 0..4000 {
            m.step(DT_S, &still());
            if k % 25 == 0 {
                reads += 1;
                fresh += usize::from(m.read().pressure_fresh());
            }
        }
        assert_eq!(reads, 160);
        assert!((74..=76).contains(&fresh), "{fresh}");
    }

    #[test]
    fn a_frozen_part_repeats_its_words_and_still_flags_data() {
        let mut m = BaroModel::new(BaroModelParams::default(), 2);
        samples(&mut m, &still(), 0.5);
        m.freeze();
        let s = samples(&mut m, &BaroInputs { height_m: 3.0, ..still() }, 0.5);
        assert!(s.len() > 30 && s.windows(2).all(|w| w[0] == w[1]));
        // The core's monitor calls it stuck.
        let mut monitor = fcu_core::baro::BaroMonitor::new(fcu_core::baro::BaroHealthConfig::DEFAULT);
        let verdicts: Vec<_> = (0..20).map(|_| monitor.check(Some(RawBaro { status: status::P_DA, ..m.read() }))).collect();
        assert_eq!(verdicts.last(), Some(&Err(fcu_core::baro::BaroFault::Stuck)));
    }

    #[test]
    fn the_same_seed_draws_the_same_part_and_others_differ() {
        let a = BaroModel::new(BaroModelParams::default(), 11);
        let b = BaroModel::new(BaroModelParams::default(), 11);
        let c = BaroModel::new(BaroModelParams::default(), 12);
        assert_eq!(a.errors(), b.errors());
        assert_ne!(a.errors(), c.errors());
        let (mut a, mut b) = (a, b);
        assert_eq!(samples(&mut a, &still(), 0.2), samples(&mut b, &still(), 0.2));
    }

    /// One flight of the core's estimator on the simulated part, with a perfect accelerometer:
    /// 3 s on the floor and the re-zero (arming), 1 s of spin-up to thrust 0.4 on the floor,
    /// a 2 s climb to 1 m, a 30 s hover. Returns the estimate's error (estimate − truth) at the
    /// end of spin-up, its mean over the hover, and its drift from 2 s into the hover to its end.
    fn fly(seed: u64) -> (f64, f64, f64) {
        use fcu_core::altitude::{AltitudeConfig, AltitudeEstimator};
        use fcu_core::baro::{BaroHealthConfig, BaroMonitor};
        let mut m = BaroModel::new(BaroModelParams::default(), seed);
        let mut monitor = BaroMonitor::new(BaroHealthConfig::DEFAULT);
        let mut est = AltitudeEstimator::new(AltitudeConfig::DEFAULT);
        let dt = 1.0 / 160.0;
        let (mut h, mut v) = (0.0f64, 0.0f64);
        let (mut spin_up_err, mut hover_errs, mut hold_start_err) = (0.0, Vec::new(), 0.0);
        for k in 0..(36 * 160) {
            let t = k as f64 * dt;
            let thrust = if t < 3.0 { 0.0 } else { (t - 3.0).min(1.0) * 0.4 };
            let a = if (4.0..5.0).contains(&t) {
                1.0
            } else if (5.0..6.0).contains(&t) {
                -1.0
            } else {
                0.0
            };
            for _ in 0..25 {
                m.step(dt / 25.0, &BaroInputs { height_m: h, thrust_fraction: thrust, airspeed_m_s: 0.0 });
            }
            h += (v + 0.5 * a * dt) * dt;
            v += a * dt;
            let pressure = monitor.check(Some(m.read())).ok().flatten().map(|s| s.pressure_pa);
            // On the floor until the climb starts (the supervisor's verdict in flight).
            let e = est.update(a as f32, pressure, thrust as f32, t < 4.0);
            if k == 3 * 160 {
                assert!(est.rezero());
            }
            let err = f64::from(e.height_m) - h;
            if k == 4 * 160 {
                spin_up_err = err;
            }
            if k == 8 * 160 {
                hold_start_err = err;
            }
            if t >= 6.0 {
                hover_errs.push(err);
            }
        }
        (spin_up_err, mean(&hover_errs), hover_errs.last().unwrap_or(&0.0) - hold_start_err)
    }

    #[test]
    fn the_cores_estimator_on_the_simulated_part_drifts_little_over_a_hold() {
        let runs: Vec<(f64, f64, f64)> = (0..20).map(fly).collect();
        let median = |f: fn(&(f64, f64, f64)) -> f64| {
            let mut v: Vec<f64> = runs.iter().map(f).map(f64::abs).collect();
            v.sort_by(f64::total_cmp);
            (v[v.len() / 2], v[v.len() - 1])
        };
        let spin_up = median(|r| r.0);
        let offset = median(|r| r.1);
        let drift = median(|r| r.2);
        eprintln!("over 20 barometer draws, |error| median (max): at the end of spin-up on the floor {:.3} ({:.3}) m, mean over the hover {:.3} ({:.3}) m, drift over 28 s of hover {:.3} ({:.3}) m", spin_up.0, spin_up.1, offset.0, offset.1, drift.0, drift.1);
        // On the floor the floor is the height: the spin-up's wash and ground effect do not read
        // as a jump.
        assert!(spin_up.1 < 0.01, "{spin_up:?}");
        // The goal for a 30 s hold: drift within 0.1 m.
        assert!(drift.0 < 0.1, "{drift:?}");
        // The barometer re-referenced to the accelerometer's height clear of the floor after the
        // lift-off: the wash at the hover's thrust (either sign) and the ground effect that was
        // in the lift-off's reference are out (0.12 m median, 0.37 m worst, without it).
        assert!(offset.0 < 0.03 && offset.1 < 0.06, "{offset:?}");
    }
}
