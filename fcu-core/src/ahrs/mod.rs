//! Attitude estimation (accelerometer + gyroscope, no magnetometer).
//!
//! [`Estimator`] is what the outer step calls: one update per block of samples, with the
//! block-averaged accelerometer (mg) and filtered gyro (mdps) in body axes.

pub mod mahony;
pub mod vqf;

#[cfg(feature = "reference")]
pub use mahony::Mahony;
pub use mahony::{MahonyConfig, MDPS_TO_RAD_S};
pub use vqf::{Vqf, VqfConfig};

use crate::math::Quat;

/// Which estimator runs, with its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EstimatorConfig {
    /// The reference's Mahony filter (bit-exact with [`MahonyConfig::REFERENCE`]); compiled in
    /// by the crate's `reference` feature.
    Mahony(MahonyConfig),
    /// The default profile's VQF (6D): [`VqfConfig::DEFAULT`] at 160 Hz,
    /// [`VqfConfig::at_rate`] for another sample period.
    Vqf(VqfConfig),
}

impl EstimatorConfig {
    /// True when the parameters can fly and the estimator is compiled in.
    pub fn is_valid(&self) -> bool {
        match self {
            EstimatorConfig::Mahony(c) => cfg!(feature = "reference") && c.is_valid(),
            EstimatorConfig::Vqf(c) => c.is_valid(),
        }
    }
}

/// Why [`Estimator::new`] cannot run the estimator asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EstimatorError {
    /// The Mahony filter, in a build without the crate's `reference` feature.
    NotCompiledIn,
}

/// A running estimator.
#[derive(Clone, Debug)]
pub struct Estimator(Running);

// One instance lives in the flight controller and there is no heap to box into: the size
// difference between the variants (≈ 0.5 KiB) is the price of a static, allocation-free state.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
enum Running {
    #[cfg(feature = "reference")]
    Mahony(Mahony),
    Vqf(Vqf),
}

impl Estimator {
    /// The estimator `cfg` asks for; [`EstimatorError::NotCompiledIn`] for the Mahony filter
    /// when the crate is built without its `reference` feature.
    pub fn new(cfg: EstimatorConfig) -> Result<Self, EstimatorError> {
        match cfg {
            #[cfg(feature = "reference")]
            EstimatorConfig::Mahony(c) => Ok(Estimator(Running::Mahony(Mahony::new(c)))),
            #[cfg(not(feature = "reference"))]
            EstimatorConfig::Mahony(_) => Err(EstimatorError::NotCompiledIn),
            EstimatorConfig::Vqf(c) => Ok(Estimator(Running::Vqf(Vqf::new(c)))),
        }
    }

    /// One update. `low_throttle` is the reference's `gTHR < MIN_THR` (Mahony's ground gain;
    /// VQF ignores it: its rest detector decides from the data when the craft is still).
    pub fn update(&mut self, accel_mg: [f32; 3], gyro_mdps: [f32; 3], low_throttle: bool) {
        match &mut self.0 {
            #[cfg(feature = "reference")]
            Running::Mahony(m) => m.update(accel_mg, gyro_mdps, low_throttle),
            Running::Vqf(v) => v.update_gated(accel_mg, gyro_mdps, low_throttle),
        }
    }

    /// Body-to-earth attitude (earth z up). Its norm is whatever the estimator keeps
    /// (0.9983 for the reference's fast inverse square root).
    pub fn quat(&self) -> Quat {
        match &self.0 {
            #[cfg(feature = "reference")]
            Running::Mahony(m) => m.quat(),
            Running::Vqf(v) => v.quat(),
        }
    }
}
