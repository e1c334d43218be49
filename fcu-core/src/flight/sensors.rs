//! The tick's sensor front end: the health checks, the calibration and the offsets it
//! produces, and the gyro's offset removal and low-pass.

use super::block::Block;
use crate::config::Config;
use crate::filter::BiquadBank;
use crate::imu::{CalibrationPhase, Calibrator, Decoder, HealthMonitor, Offsets, RawImu, SensorFault, MAX_MISSING_SAMPLES};

/// What the tick may do once the calibration has had its sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum AfterCalibration {
    /// Offsets exist: the tick runs its pipeline.
    RunPipeline,
    /// The start-up calibration is still settling or averaging, so there are no offsets to
    /// correct the sensor with: the motors stay off and the tick does nothing else.
    NoOffsetsYet,
}

/// The front end's state: calibration, offsets, health, and the gyro filters.
#[derive(Clone, Debug)]
pub(super) struct Sensors {
    calibrator: Calibrator,
    /// A calibration was asked for and has not started yet.
    cal_pending: bool,
    /// The offsets in force, removed from every sample.
    offsets: Offsets,
    /// `None` when the configuration has no health checks (the reference).
    health: Option<HealthMonitor>,
    /// The first sensor fault seen, latched.
    fault: Option<SensorFault>,
    /// The last reading the pipeline ran on (`None` before the first).
    last_raw: Option<RawImu>,
    missing_samples: u32,
    gyro_lpf: BiquadBank<3>,
}

impl Sensors {
    pub(super) fn new(cfg: &Config) -> Sensors {
        Sensors {
            calibrator: Calibrator::new(cfg.calibration),
            cal_pending: false,
            offsets: Offsets::UNCALIBRATED,
            health: cfg.health.map(|h| HealthMonitor::new(h, &cfg.imu)),
            fault: None,
            last_raw: None,
            missing_samples: 0,
            gyro_lpf: BiquadBank::new(cfg.gyro_filter),
        }
    }

    /// The gyro low-pass's new coefficients, its memory kept.
    pub(super) fn set_gyro_filter(&mut self, c: crate::filter::BiquadCoeffs) {
        self.gyro_lpf.set_coefficients(c);
    }

    /// A reading arrived this tick.
    pub(super) fn sample_arrived(&mut self) {
        self.missing_samples = 0;
    }

    /// The sensor read failed this tick: the last sample is held for up to
    /// [`MAX_MISSING_SAMPLES`] ticks (a single bus glitch must not drop the drone); after that
    /// the sensor is faulty.
    pub(super) fn sample_missing(&mut self) -> RawImu {
        self.missing_samples = self.missing_samples.saturating_add(1);
        if self.missing_samples > MAX_MISSING_SAMPLES {
            self.fault.get_or_insert(SensorFault::NoData);
        }
        self.last_raw.unwrap_or_default()
    }

    /// The health checks on this tick's reading (a repeat of the last one counts towards
    /// "stuck").
    pub(super) fn check(&mut self, raw: RawImu) {
        let repeated = self.last_raw == Some(raw);
        self.last_raw = Some(raw);
        if let Some(h) = &mut self.health {
            if let Some(f) = h.check(raw, repeated) {
                self.fault.get_or_insert(f);
            }
        }
    }

    /// Ask for a calibration (it starts at the next [`calibrate`](Self::calibrate)).
    pub(super) fn ask_calibration(&mut self, asked: bool) {
        self.cal_pending |= asked;
    }

    /// A calibration is asked for or running: [`calibrate`](Self::calibrate) has work to do.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn calibration_due(&self) -> bool {
        self.cal_pending || !self.calibrator.is_idle()
    }

    /// The start-up settling and average (the tick stops there until the first offsets exist)
    /// and a requested average, while a calibration is asked for or running.
    #[inline(never)] // docs/performance.md, «calibration off the path».
    pub(super) fn calibrate(&mut self, imu: RawImu, decoder: &Decoder, block: &mut Block) -> AfterCalibration {
        if self.calibrator.in_startup() {
            if self.calibrator.settle() {
                return AfterCalibration::NoOffsetsYet;
            }
            match self.calibrator.feed(decoder.to_body(imu)) {
                Some(o) => self.set_offsets(o, decoder, block), // and this tick goes on, as the reference's does
                None => return AfterCalibration::NoOffsetsYet,
            }
        }
        if self.cal_pending && !self.calibrator.is_averaging() {
            self.calibrator.request();
        }
        self.cal_pending = false;
        if self.calibrator.is_averaging() {
            if let Some(o) = self.calibrator.feed(decoder.to_body(imu)) {
                self.set_offsets(o, decoder, block);
            }
        }
        AfterCalibration::RunPipeline
    }

    /// New offsets from a calibration; the block's samples taken before keep the ones they were
    /// taken under.
    pub(super) fn set_offsets(&mut self, o: Offsets, decoder: &Decoder, block: &mut Block) {
        block.offsets_change(&self.offsets, decoder);
        self.offsets = o;
    }

    /// The gyro of this reading, offsets removed and low-passed, mdps, body axes.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn gyro_mdps(&mut self, gyro: [i16; 3], decoder: &Decoder) -> [f32; 3] {
        let gyro_mdps = self.offsets.gyro(decoder.gyro_mdps(gyro));
        let gyro_f = self.gyro_lpf.update(gyro_mdps.map(|g| g as f32));
        if gyro_f[0].is_finite() && gyro_f[1].is_finite() && gyro_f[2].is_finite() {
            return gyro_f;
        }
        // Integer inputs cannot make this happen; if it ever did, restart the filters and (in
        // the product) treat it as the sensor fault it would be.
        self.gyro_lpf.reset_to(0.0);
        if self.health.is_some() {
            self.fault.get_or_insert(SensorFault::NotFinite);
        }
        [0.0; 3]
    }

    pub(super) fn offsets(&self) -> Offsets {
        self.offsets
    }

    pub(super) fn fault(&self) -> Option<SensorFault> {
        self.fault
    }

    /// A calibration (start-up or requested) is running.
    pub(super) fn calibrating(&self) -> bool {
        self.calibrator.in_startup() || self.calibrator.is_averaging()
    }

    /// A calibration has passed since power-on.
    pub(super) fn calibrated(&self) -> bool {
        self.calibrator.has_passed()
    }

    pub(super) fn phase(&self) -> CalibrationPhase {
        self.calibrator.phase()
    }
}
