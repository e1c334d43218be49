//! LPS22HB register map and the flight configuration (datasheet DocID027083, sections 8 and 9),
//! as data: the firmware plays the writes over the 3-wire SPI bus and hands back the burst.
//!
//! This is the configuration altitude hold flies with, not the reference's (the reference's own
//! boot table, which reads the sensor at 25 Hz with no filter and throws the value away, stays
//! in [`crate::imu::registers::lps22hb`]). Not played by the firmware yet: see
//! `docs/altitude.md`.
//!
//! # Why 75 Hz and the ODR/20 filter
//!
//! The control tick is 800 Hz and the outer step, where the height estimate runs, 160 Hz
//! ([`crate::config::Timing::outer_hz`]). The sensor's fastest rate, 75 Hz, is still below the
//! outer step's, so every sample the part makes is used, each at most 13 ms old when the step
//! reads it. The estimator trusts the barometer only below about 0.1 Hz (`1/(2π·τ)` with its
//! time constant τ = 1.5 s, [`crate::altitude::AltitudeConfig::time_constant_s`]); above that
//! the accelerometer carries the height. The strongest filter, a bandwidth of ODR/20 = 3.75 Hz,
//! is still 35 times that crossover, so its delay (about 1/(2π·3.75 Hz) = 42 ms) costs the estimate nothing, while it
//! gives the datasheet's lowest noise (0.0075 hPa RMS, about 6 cm of height) and smooths the
//! prop wash's pressure flicker before it is sampled. ODR/9 (8.3 Hz) would only add noise
//! the estimator has to average out again.
//!
//! Low-noise mode (RES_CONF.LC_EN = 0, the reset value) for the same reason: the 12 µA of the
//! low-current mode's saving are nothing next to the motors.

use crate::imu::registers::RegWrite;

pub const INTERRUPT_CFG: u8 = 0x0B;
pub const WHO_AM_I: u8 = 0x0F;
pub const WHO_AM_I_VALUE: u8 = 0xB1;
pub const CTRL_REG1: u8 = 0x10;
pub const CTRL_REG2: u8 = 0x11;
pub const CTRL_REG3: u8 = 0x12;
pub const FIFO_CTRL: u8 = 0x14;
pub const RES_CONF: u8 = 0x1A;
pub const INT_SOURCE: u8 = 0x25;
pub const FIFO_STATUS: u8 = 0x26;
pub const STATUS: u8 = 0x27;
pub const PRESS_OUT_XL: u8 = 0x28;
pub const PRESS_OUT_L: u8 = 0x29;
pub const PRESS_OUT_H: u8 = 0x2A;
pub const TEMP_OUT_L: u8 = 0x2B;
pub const TEMP_OUT_H: u8 = 0x2C;
/// Reading this register resets the pressure low-pass filter (its value means nothing).
pub const LPFP_RES: u8 = 0x33;

/// CTRL_REG1 bits: ODR in bits 6..4, EN_LPFP bit 3, LPFP_CFG bit 2, BDU bit 1, SIM bit 0.
pub mod ctrl_reg1 {
    pub const ODR_SHIFT: u8 = 4;
    pub const ODR_MASK: u8 = 0x70;
    pub const EN_LPFP: u8 = 0x08;
    /// With EN_LPFP: bandwidth ODR/20 when set, ODR/9 when clear (ODR/2 without EN_LPFP).
    pub const LPFP_CFG: u8 = 0x04;
    /// Block data update: the output registers hold one sample until all of it has been read,
    /// so the three pressure bytes of a burst never mix two samples.
    pub const BDU: u8 = 0x02;
    /// 3-wire SPI: the board wires only the shared data line.
    pub const SIM: u8 = 0x01;
}

/// CTRL_REG2 bits.
pub mod ctrl_reg2 {
    /// Reload the trimming values from flash.
    pub const BOOT: u8 = 0x80;
    pub const FIFO_EN: u8 = 0x40;
    /// Register address auto-increment on multi-byte access (set at reset): the burst.
    pub const IF_ADD_INC: u8 = 0x10;
    /// With its chip select high the part would otherwise watch the shared lines as an I2C bus.
    pub const I2C_DIS: u8 = 0x08;
    /// Software reset: every register back to its reset value (SIM included); self-clearing.
    pub const SWRESET: u8 = 0x04;
    /// One conversion in power-down mode (ODR = 0); unused at a continuous ODR.
    pub const ONE_SHOT: u8 = 0x01;
}

/// STATUS bits.
pub mod status {
    /// A temperature sample was overwritten before it was read.
    pub const T_OR: u8 = 0x20;
    /// A pressure sample was overwritten before it was read.
    pub const P_OR: u8 = 0x10;
    /// A new temperature sample is in TEMP_OUT.
    pub const T_DA: u8 = 0x02;
    /// A new pressure sample is in PRESS_OUT (cleared when PRESS_OUT_H is read).
    pub const P_DA: u8 = 0x01;
}

/// The output data rates of CTRL_REG1.ODR (0 is power-down / one-shot).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Odr {
    Hz1 = 1,
    Hz10 = 2,
    Hz25 = 3,
    Hz50 = 4,
    Hz75 = 5,
}

impl Odr {
    pub const fn hz(self) -> f32 {
        match self {
            Odr::Hz1 => 1.0,
            Odr::Hz10 => 10.0,
            Odr::Hz25 => 25.0,
            Odr::Hz50 => 50.0,
            Odr::Hz75 => 75.0,
        }
    }

    pub const fn bits(self) -> u8 {
        (self as u8) << ctrl_reg1::ODR_SHIFT
    }
}

/// The pressure low-pass filter (EN_LPFP, LPFP_CFG).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PressureFilter {
    /// Filter off: bandwidth ODR/2.
    Off,
    /// Bandwidth ODR/9.
    OdrDiv9,
    /// Bandwidth ODR/20.
    OdrDiv20,
}

impl PressureFilter {
    pub const fn bits(self) -> u8 {
        match self {
            PressureFilter::Off => 0,
            PressureFilter::OdrDiv9 => ctrl_reg1::EN_LPFP,
            PressureFilter::OdrDiv20 => ctrl_reg1::EN_LPFP | ctrl_reg1::LPFP_CFG,
        }
    }

    pub const fn divider(self) -> f32 {
        match self {
            PressureFilter::Off => 2.0,
            PressureFilter::OdrDiv9 => 9.0,
            PressureFilter::OdrDiv20 => 20.0,
        }
    }
}

/// The rate and filter altitude hold flies with (see the module's comment for why).
pub const ODR: Odr = Odr::Hz75;
pub const FILTER: PressureFilter = PressureFilter::OdrDiv20;

/// The filter's bandwidth at the flight configuration, Hz (3.75).
pub const fn bandwidth_hz() -> f32 {
    ODR.hz() / FILTER.divider()
}

/// CTRL_REG1 in flight: 75 Hz, ODR/20 filter, BDU, 3-wire SPI (0x5F).
pub const CTRL_REG1_FLIGHT: u8 = ODR.bits() | FILTER.bits() | ctrl_reg1::BDU | ctrl_reg1::SIM;
/// CTRL_REG2 in flight: auto-increment for the burst, I2C off (0x18).
pub const CTRL_REG2_FLIGHT: u8 = ctrl_reg2::IF_ADD_INC | ctrl_reg2::I2C_DIS;
/// CTRL_REG2 for the software reset, keeping the auto-increment of the reset value (0x14).
pub const CTRL_REG2_RESET: u8 = ctrl_reg2::SWRESET | ctrl_reg2::IF_ADD_INC;
/// RES_CONF: low-noise mode (LC_EN clear). Written while the part is still powered down,
/// as the datasheet asks for a change of LC_EN.
pub const RES_CONF_LOW_NOISE: u8 = 0x00;

/// Milliseconds between the software reset and the next access: the part's boot (the
/// datasheet's 4.5 ms) with margin. The reference waits a whole second here.
pub const RESET_SETTLE_MS: u32 = 5;

/// Played first: 3-wire mode, so the part answers on the shared data line at all, then the
/// software reset (from a warm MCU restart the part may still be converting with anything set).
pub const INTERFACE: [RegWrite; 2] = [w(CTRL_REG1, ctrl_reg1::SIM), w(CTRL_REG2, CTRL_REG2_RESET)];

/// Played after [`RESET_SETTLE_MS`] and before `WHO_AM_I`: the reset cleared SIM.
pub const AFTER_RESET: [RegWrite; 1] = [w(CTRL_REG1, ctrl_reg1::SIM)];

/// Played after a good `WHO_AM_I`. CTRL_REG1 last: setting the ODR starts the conversions, so
/// everything else is in place by then.
pub const CONFIG: [RegWrite; 3] = [w(CTRL_REG2, CTRL_REG2_FLIGHT), w(RES_CONF, RES_CONF_LOW_NOISE), w(CTRL_REG1, CTRL_REG1_FLIGHT)];

/// One burst from STATUS through TEMP_OUT_H (auto-increment): the data-ready flags and the
/// sample they describe in one transfer. With BDU the pressure bytes cannot tear.
pub const BURST_START: u8 = STATUS;
pub const BURST_LEN: usize = 6;

const fn w(addr: u8, value: u8) -> RegWrite {
    RegWrite { addr, value }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imu::registers::{lps22hb, read_address};

    #[test]
    fn register_addresses_are_the_datasheets() {
        assert_eq!([WHO_AM_I, CTRL_REG1, CTRL_REG2, CTRL_REG3, RES_CONF, STATUS], [0x0F, 0x10, 0x11, 0x12, 0x1A, 0x27]);
        assert_eq!([PRESS_OUT_XL, PRESS_OUT_L, PRESS_OUT_H, TEMP_OUT_L, TEMP_OUT_H], [0x28, 0x29, 0x2A, 0x2B, 0x2C]);
        // The reference's table names the same part at the same addresses.
        assert_eq!((lps22hb::WHO_AM_I, lps22hb::WHO_AM_I_VALUE, lps22hb::CTRL_REG1), (WHO_AM_I, WHO_AM_I_VALUE, CTRL_REG1));
    }

    #[test]
    fn the_flight_ctrl_reg1_is_75_hz_odr_over_20_bdu_and_3_wire() {
        assert_eq!(CTRL_REG1_FLIGHT, 0x5F);
        assert_eq!((CTRL_REG1_FLIGHT & ctrl_reg1::ODR_MASK) >> ctrl_reg1::ODR_SHIFT, 0b101);
        assert_eq!(bandwidth_hz(), 3.75);
        assert_eq!([Odr::Hz1, Odr::Hz10, Odr::Hz25, Odr::Hz50, Odr::Hz75].map(Odr::bits), [0x10, 0x20, 0x30, 0x40, 0x50]);
        assert_eq!([PressureFilter::Off, PressureFilter::OdrDiv9, PressureFilter::OdrDiv20].map(PressureFilter::bits), [0, 0x08, 0x0C]);
    }

    #[test]
    fn the_boot_sequence_sets_3_wire_before_every_read_and_starts_conversions_last() {
        let seq: [(u8, u8); 6] = [INTERFACE[0], INTERFACE[1], AFTER_RESET[0], CONFIG[0], CONFIG[1], CONFIG[2]].map(|r| (r.addr, r.value));
        assert_eq!(seq, [(0x10, 0x01), (0x11, 0x14), (0x10, 0x01), (0x11, 0x18), (0x1A, 0x00), (0x10, 0x5F)]);
        // SIM survives every write after the reset, so no read ever goes to the unwired pin.
        assert!(AFTER_RESET.iter().chain(&CONFIG).filter(|r| r.addr == CTRL_REG1).all(|r| r.value & ctrl_reg1::SIM != 0));
        // IF_ADD_INC is never cleared: the burst depends on it.
        assert!(INTERFACE.iter().chain(&CONFIG).filter(|r| r.addr == CTRL_REG2).all(|r| r.value & ctrl_reg2::IF_ADD_INC != 0));
        assert_eq!(CONFIG.last().map(|r| r.addr), Some(CTRL_REG1));
    }

    #[test]
    fn the_burst_covers_status_through_temperature() {
        assert_eq!(usize::from(TEMP_OUT_H - BURST_START) + 1, BURST_LEN);
        assert_eq!(read_address(BURST_START), 0xA7);
    }
}
