//! Attitude estimation (accelerometer + gyroscope, no magnetometer).
//!
//! [`Estimator`] is what the outer step calls: one update per block of samples, with the
//! block-averaged accelerometer (mg) and filtered gyro (mdps) in body axes.

pub mod mahony;
pub mod vqf;

pub use mahony::{Mahony, MahonyConfig, MDPS_TO_RAD_S};
pub use vqf::{Vqf, VqfConfig};

use crate::math::Quat;

/// Which estimator runs, with its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EstimatorConfig {
    /// The reference's Mahony filter (bit-exact with [`MahonyConfig::REFERENCE`]).
    Mahony(MahonyConfig),
    /// The default profile's VQF (6D): [`VqfConfig::DEFAULT`] at 160 Hz,
    /// [`VqfConfig::at_rate`] for another sample period.
    Vqf(VqfConfig),
}

impl EstimatorConfig {
    pub fn is_valid(&self) -> bool {
        match self {
            EstimatorConfig::Mahony(c) => c.is_valid(),
            EstimatorConfig::Vqf(c) => c.is_valid(),
        }
    }
}

/// A running estimator.
// One instance lives in the flight controller and there is no heap to box into: the size
// difference between the variants (≈ 0.5 KiB) is the price of a static, allocation-free state.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Estimator {
    Mahony(Mahony),
    Vqf(Vqf),
}

impl Estimator {
    pub fn new(cfg: EstimatorConfig) -> Self {
        match cfg {
            EstimatorConfig::Mahony(c) => Estimator::Mahony(Mahony::new(c)),
            EstimatorConfig::Vqf(c) => Estimator::Vqf(Vqf::new(c)),
        }
    }

    /// One update. `low_throttle` is the reference's `gTHR < MIN_THR` (Mahony's ground gain;
    /// VQF ignores it: its rest detector decides from the data when the craft is still).
    pub fn update(&mut self, accel_mg: [f32; 3], gyro_mdps: [f32; 3], low_throttle: bool) {
        match self {
            Estimator::Mahony(m) => m.update(accel_mg, gyro_mdps, low_throttle),
            Estimator::Vqf(v) => v.update_gated(accel_mg, gyro_mdps, low_throttle),
        }
    }

    /// Body-to-earth attitude (earth z up). Its norm is whatever the estimator keeps
    /// (0.9983 for the reference's fast inverse square root).
    pub fn quat(&self) -> Quat {
        match self {
            Estimator::Mahony(m) => m.quat(),
            Estimator::Vqf(v) => v.quat(),
        }
    }
}
