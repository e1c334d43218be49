//! The barometer boundary: an LPS22HB burst → pressure (Pa) and temperature (°C), and the
//! sensor's health, with its faults named as the IMU's are ([`crate::imu::SensorFault`]).
//!
//! The outer step checks every burst handed to it ([`crate::flight::OuterStep::set_baro`]) in
//! its vertical half ([`crate::althold::Vertical`]; `docs/altitude.md`).

pub mod registers;

use registers::{status, BURST_LEN};

/// Counts of PRESS_OUT per hPa (datasheet: 4096 LSB/hPa).
pub const COUNTS_PER_HPA: i32 = 4096;
/// Pa per count, 100 / 4096 (a power of two apart from the 100, so exact in f32).
pub const PA_PER_COUNT: f32 = 100.0 / COUNTS_PER_HPA as f32;
/// Counts of TEMP_OUT per °C (datasheet: 100 LSB/°C).
pub const COUNTS_PER_DEG_C: f32 = 100.0;

/// The part's operating pressure range, 260–1260 hPa, in Pa: a reading outside it is a corrupt
/// word or a dead part, never the air.
pub const PRESSURE_MIN_PA: f32 = 26_000.0;
pub const PRESSURE_MAX_PA: f32 = 126_000.0;
/// The part's operating temperature range, °C.
pub const TEMPERATURE_MIN_C: f32 = -40.0;
pub const TEMPERATURE_MAX_C: f32 = 85.0;

/// Pressure change per metre of height near the ground, Pa/m: ρ·g with the sea-level density
/// (1.225 kg/m³ · 9.80665 m/s²). Higher up the air is thinner and a metre is fewer pascals, so
/// this is the upper bound a limit on pressure change wants.
pub const PA_PER_M_SEA_LEVEL: f32 = 12.013;

/// One burst as it comes off the bus (from STATUS, [`registers::BURST_START`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RawBaro {
    pub status: u8,
    /// PRESS_OUT_H:L:XL, the 24-bit two's complement word sign-extended.
    pub pressure_counts: i32,
    /// TEMP_OUT_H:L.
    pub temperature_counts: i16,
}

impl RawBaro {
    /// STATUS.P_DA: the pressure bytes hold a sample not read before.
    pub fn pressure_fresh(&self) -> bool {
        self.status & status::P_DA != 0
    }

    pub fn pressure_pa(&self) -> f32 {
        self.pressure_counts as f32 * PA_PER_COUNT
    }

    pub fn temperature_c(&self) -> f32 {
        f32::from(self.temperature_counts) / COUNTS_PER_DEG_C
    }
}

/// Decode a burst read from STATUS: STATUS, PRESS_OUT_XL, _L, _H, TEMP_OUT_L, _H.
pub fn decode_burst(bytes: &[u8; BURST_LEN]) -> RawBaro {
    let [st, xl, l, h, tl, th] = *bytes;
    // The 24-bit word in the top three bytes of an i32, then an arithmetic shift: the sign
    // extension of its two's complement.
    let pressure_counts = i32::from_be_bytes([h, l, xl, 0]) >> 8;
    RawBaro { status: st, pressure_counts, temperature_counts: i16::from_le_bytes([tl, th]) }
}

/// A sample the health check passed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaroSample {
    pub pressure_pa: f32,
    pub temperature_c: f32,
}

/// Why a reading was not used, or the sensor is not to be trusted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BaroFault {
    /// No new sample (P_DA never set, or no burst at all) for longer than
    /// [`BaroHealthConfig::no_data_s`].
    NoData,
    /// [`BaroHealthConfig::stuck_samples`] new samples in a row with the very same pressure word:
    /// with the part's noise (some 30 counts RMS) that does not happen to a working sensor.
    Stuck,
    /// Pressure or temperature outside the part's operating range.
    OutOfRange,
    /// A change from the last accepted sample faster than the drone can climb or fall: a corrupt
    /// read or a knock on the part. The sample is not used; a change that persists is accepted
    /// once the time since the last accepted sample makes it possible.
    Spike,
}

/// How the health check judges the samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaroHealthConfig {
    /// The part's output data rate, Hz.
    pub odr_hz: f32,
    /// How often [`BaroMonitor::check`] is called, Hz (the outer step's rate).
    pub check_hz: f32,
    /// Longest time without a new sample before [`BaroFault::NoData`], s.
    pub no_data_s: f32,
    pub stuck_samples: u32,
    /// Fastest vertical speed believed, m/s.
    pub max_vertical_speed_m_s: f32,
    /// Allowance on top of the speed limit: noise and gust transients, Pa.
    pub spike_margin_pa: f32,
}

impl BaroHealthConfig {
    /// At 75 Hz read from the 160 Hz outer step:
    /// - no data: 0.1 s, seven samples the part should have made (a missed read or two is
    ///   bridged, a part that stopped converting is not);
    /// - stuck: 15 samples (0.2 s) of one word. Two samples 0.75 Pa RMS apart (30 counts) agree
    ///   about once in a hundred; fifteen in a row never;
    /// - spikes: 15 m/s, twice the speed of a free fall from the room's ceiling; 10 Pa of margin,
    ///   nine times the noise of a difference of two samples plus a strong gust's transient.
    pub const DEFAULT: BaroHealthConfig = BaroHealthConfig {
        odr_hz: 75.0,
        check_hz: 160.0,
        no_data_s: 0.1,
        stuck_samples: 15,
        max_vertical_speed_m_s: 15.0,
        spike_margin_pa: 10.0,
    };
}

/// Watches the bursts: new sample or not, range, stuck word, spikes.
#[derive(Clone, Debug)]
pub struct BaroMonitor {
    cfg: BaroHealthConfig,
    no_data_checks: u32,
    checks_since_fresh: u32,
    last_counts: Option<i32>,
    same_count: u32,
    /// The last sample passed, and new samples since.
    accepted_pa: Option<f32>,
    samples_since_accepted: u32,
}

impl BaroMonitor {
    pub fn new(cfg: BaroHealthConfig) -> Self {
        // f32 → u32 saturates, and NaN becomes 0: a bad rate makes the check strict, not absent.
        let no_data_checks = (cfg.no_data_s * cfg.check_hz) as u32;
        BaroMonitor {
            cfg,
            no_data_checks,
            checks_since_fresh: 0,
            last_counts: None,
            same_count: 0,
            accepted_pa: None,
            samples_since_accepted: 0,
        }
    }

    /// Forget the history (after the part is configured again).
    pub fn reset(&mut self) {
        *self = BaroMonitor::new(self.cfg);
    }

    /// Judge one call's burst (`None` when the bus read failed). `Ok(Some)`: a new sample to use;
    /// `Ok(None)`: nothing new yet, still within the no-data time; `Err`: what is wrong.
    pub fn check(&mut self, raw: Option<RawBaro>) -> Result<Option<BaroSample>, BaroFault> {
        self.checks_since_fresh = self.checks_since_fresh.saturating_add(1);
        let Some(raw) = raw.filter(RawBaro::pressure_fresh) else {
            return if self.checks_since_fresh > self.no_data_checks { Err(BaroFault::NoData) } else { Ok(None) };
        };
        self.checks_since_fresh = 0;
        self.samples_since_accepted = self.samples_since_accepted.saturating_add(1);

        let repeated = self.last_counts == Some(raw.pressure_counts);
        self.last_counts = Some(raw.pressure_counts);
        self.same_count = if repeated { self.same_count.saturating_add(1) } else { 0 };

        let sample = BaroSample { pressure_pa: raw.pressure_pa(), temperature_c: raw.temperature_c() };
        if !(PRESSURE_MIN_PA..=PRESSURE_MAX_PA).contains(&sample.pressure_pa)
            || !(TEMPERATURE_MIN_C..=TEMPERATURE_MAX_C).contains(&sample.temperature_c)
        {
            return Err(BaroFault::OutOfRange);
        }
        if self.same_count.saturating_add(1) >= self.cfg.stuck_samples {
            return Err(BaroFault::Stuck);
        }
        if let Some(accepted) = self.accepted_pa {
            let elapsed_s = self.samples_since_accepted as f32 / self.cfg.odr_hz;
            let limit_pa = self.cfg.spike_margin_pa + self.cfg.max_vertical_speed_m_s * PA_PER_M_SEA_LEVEL * elapsed_s;
            // So that a NaN limit (absurd numbers in the configuration) rejects rather than accepts.
            let possible = (sample.pressure_pa - accepted).abs() <= limit_pa;
            if !possible {
                return Err(BaroFault::Spike);
            }
        }
        self.accepted_pa = Some(sample.pressure_pa);
        self.samples_since_accepted = 0;
        Ok(Some(sample))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The burst of a fresh sample of `counts` and `temp` (°C·100).
    fn burst(counts: i32, temp: i16) -> [u8; BURST_LEN] {
        let [_, h, l, xl] = counts.to_be_bytes();
        let [tl, th] = temp.to_le_bytes();
        [status::P_DA | status::T_DA, xl, l, h, tl, th]
    }

    fn fresh(pa: f32) -> Option<RawBaro> {
        Some(RawBaro { status: status::P_DA, pressure_counts: (pa / PA_PER_COUNT) as i32, temperature_counts: 2500 })
    }

    #[test]
    fn a_burst_decodes_to_pascals_and_degrees() {
        // 1013.25 hPa = 4,150,272 counts; 25.00 °C = 2500.
        let raw = decode_burst(&burst(4_150_272, 2500));
        assert!(raw.pressure_fresh());
        assert_eq!(raw.pressure_counts, 4_150_272);
        assert_eq!(raw.pressure_pa(), 101_325.0);
        assert_eq!(raw.temperature_c(), 25.0);
        // One count is 1/4096 hPa.
        assert_eq!(decode_burst(&burst(1, 0)).pressure_pa(), 100.0 / 4096.0);
        assert_eq!(decode_burst(&burst(0, -1250)).temperature_c(), -12.5);
    }

    #[test]
    fn the_24_bit_word_is_twos_complement() {
        let neg = decode_burst(&[0, 0xFF, 0xFF, 0xFF, 0, 0]);
        assert_eq!(neg.pressure_counts, -1);
        assert_eq!(decode_burst(&[0, 0x00, 0x00, 0x80, 0, 0]).pressure_counts, -(1 << 23));
        assert_eq!(decode_burst(&[0, 0xFF, 0xFF, 0x7F, 0, 0]).pressure_counts, (1 << 23) - 1);
        assert_eq!(decode_burst(&[0, 0x56, 0x34, 0x12, 0, 0]).pressure_counts, 0x12_3456);
        assert!(!decode_burst(&[0, 0, 0, 0, 0, 0]).pressure_fresh());
    }

    #[test]
    fn good_samples_pass_and_missed_reads_are_bridged_then_no_data() {
        let mut m = BaroMonitor::new(BaroHealthConfig::DEFAULT);
        assert!(matches!(m.check(fresh(100_000.0)), Ok(Some(s)) if s.pressure_pa == 100_000.0 && s.temperature_c == 25.0));
        // 0.1 s at 160 Hz: 16 calls without a new sample are bridged, the 17th is not.
        let stale = Some(RawBaro { status: 0, ..fresh(100_000.0).unwrap_or_default() });
        for k in 0..16 {
            let r = if k % 2 == 0 { m.check(None) } else { m.check(stale) };
            assert_eq!(r, Ok(None), "call {k}");
        }
        assert_eq!(m.check(None), Err(BaroFault::NoData));
        assert!(matches!(m.check(fresh(100_001.0)), Ok(Some(_))));
    }

    #[test]
    fn readings_outside_the_parts_range_are_out_of_range() {
        let mut m = BaroMonitor::new(BaroHealthConfig::DEFAULT);
        // An all-ones bus reads P_DA set and −1 counts.
        assert_eq!(m.check(Some(decode_burst(&[0xFF; BURST_LEN]))), Err(BaroFault::OutOfRange));
        assert_eq!(m.check(fresh(25_000.0)), Err(BaroFault::OutOfRange));
        assert_eq!(m.check(fresh(127_000.0)), Err(BaroFault::OutOfRange));
        let hot = Some(RawBaro { temperature_counts: 9000, ..fresh(100_000.0).unwrap_or_default() });
        assert_eq!(m.check(hot), Err(BaroFault::OutOfRange));
        assert!(matches!(m.check(fresh(100_000.0)), Ok(Some(_))));
    }

    #[test]
    fn the_same_word_fifteen_samples_running_is_stuck() {
        let mut m = BaroMonitor::new(BaroHealthConfig::DEFAULT);
        for k in 0..14 {
            assert!(matches!(m.check(fresh(100_000.0)), Ok(Some(_))), "sample {k}");
        }
        assert_eq!(m.check(fresh(100_000.0)), Err(BaroFault::Stuck));
        // A re-read of the same sample (P_DA clear) is not a repeat.
        let mut m = BaroMonitor::new(BaroHealthConfig::DEFAULT);
        for k in 0..40 {
            let pa = 100_000.0 + (k % 2) as f32;
            assert!(m.check(fresh(pa)).is_ok(), "sample {k}");
        }
    }

    #[test]
    fn a_jump_faster_than_the_drone_can_move_is_a_spike_and_not_used() {
        let mut m = BaroMonitor::new(BaroHealthConfig::DEFAULT);
        assert!(m.check(fresh(100_000.0)).is_ok());
        // One sample later (13 ms) 10 Pa + 15 m/s · 12 Pa/m · 13 ms ≈ 12.4 Pa are possible.
        assert!(matches!(m.check(fresh(100_012.0)), Ok(Some(_))));
        assert_eq!(m.check(fresh(100_040.0)), Err(BaroFault::Spike));
        // The next sample is judged against the last accepted one, two periods back.
        assert!(matches!(m.check(fresh(100_020.0)), Ok(Some(_))));
    }

    #[test]
    fn a_lasting_change_is_accepted_once_the_time_allows_it() {
        let mut m = BaroMonitor::new(BaroHealthConfig::DEFAULT);
        assert!(m.check(fresh(100_000.0)).is_ok());
        // 60 Pa (5 m) at once: possible after (60 − 10) / (15 · 12.013) s = 0.28 s = 21 samples.
        let mut spikes = 0;
        for k in 0..40 {
            match m.check(fresh(100_060.0 + (k % 2) as f32)) {
                Err(BaroFault::Spike) => spikes += 1,
                Ok(Some(_)) => break,
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(spikes, 20);
    }
}
