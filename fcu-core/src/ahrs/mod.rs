//! Attitude estimation (accelerometer + gyroscope, no magnetometer).
//!
//! [`Estimator`] is what the outer step calls: one update per block of samples, with the
//! block-averaged accelerometer (mg) and filtered gyro (mdps) in body axes.

pub mod mahony;

pub use mahony::{Mahony, MahonyConfig, MDPS_TO_RAD_S};

use crate::math::Quat;

/// Which estimator runs, with its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EstimatorConfig {
    /// The reference's Mahony filter (bit-exact with [`MahonyConfig::REFERENCE`]).
    Mahony(MahonyConfig),
}

impl EstimatorConfig {
    pub fn is_valid(&self) -> bool {
        match self {
            EstimatorConfig::Mahony(c) => c.is_valid(),
        }
    }
}

/// A running estimator.
#[derive(Clone, Debug)]
pub enum Estimator {
    Mahony(Mahony),
}

impl Estimator {
    pub fn new(cfg: EstimatorConfig) -> Self {
        match cfg {
            EstimatorConfig::Mahony(c) => Estimator::Mahony(Mahony::new(c)),
        }
    }

    /// One update. `low_throttle` is the reference's `gTHR < MIN_THR` (ground gain).
    pub fn update(&mut self, accel_mg: [f32; 3], gyro_mdps: [f32; 3], low_throttle: bool) {
        match self {
            Estimator::Mahony(m) => m.update(accel_mg, gyro_mdps, low_throttle),
        }
    }

    /// Body-to-earth attitude (earth z up).
    pub fn quat(&self) -> Quat {
        match self {
            Estimator::Mahony(m) => m.quat(),
        }
    }
}
