//! Sensor register tables and burst decoding (LSM6DSL, LIS2MDL, LPS22HB).

use super::RawImu;

/// Decode an LSM6DSL burst read starting at OUTX_L_G (0x22): 6 gyro bytes then 6 accel
/// bytes, each axis little-endian int16.
pub fn decode_lsm6dsl_burst(bytes: &[u8; 12]) -> RawImu {
    let w = |lo: u8, hi: u8| i16::from_le_bytes([lo, hi]);
    let [g0, g1, g2, g3, g4, g5, a0, a1, a2, a3, a4, a5] = *bytes;
    RawImu { gyro: [w(g0, g1), w(g2, g3), w(g4, g5)], accel: [w(a0, a1), w(a2, a3), w(a4, a5)] }
}
