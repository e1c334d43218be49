//! Sensor register tables and burst decoding (LSM6DSL, LIS2MDL, LPS22HB): pure data and
//! byte handling, so the firmware only moves bytes.
//!
//! Every value written at boot is the reference's (`docs/reference.md#sensors`). Each table is an
//! ordered list of `(register, value)` writes; the firmware plays it over the 3-wire SPI bus and
//! checks `WHO_AM_I` between the interface write (which switches the sensor to 3-wire SPI, so
//! it can answer on the shared data line at all) and the rest of the configuration.

use super::RawImu;

/// Bit 7 of the first SPI byte selects a read; the other seven bits are the register.
pub const SPI_READ: u8 = 0x80;

/// The first byte of an SPI read of register `addr`.
pub const fn read_address(addr: u8) -> u8 {
    addr | SPI_READ
}

/// The first byte of an SPI write to register `addr` (bit 7 clear).
pub const fn write_address(addr: u8) -> u8 {
    addr & !SPI_READ
}

/// One register write of a boot table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RegWrite {
    pub addr: u8,
    pub value: u8,
}

const fn w(addr: u8, value: u8) -> RegWrite {
    RegWrite { addr, value }
}

/// The three sensors on the shared SPI2 bus. The discriminant order is the blink count of
/// the LED error code (LSM6DSL = 1 blink, LIS2MDL = 2, LPS22HB = 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    Lsm6dsl,
    Lis2mdl,
    Lps22hb,
}

impl Sensor {
    pub const ALL: [Sensor; 3] = [Sensor::Lsm6dsl, Sensor::Lis2mdl, Sensor::Lps22hb];

    pub const fn name(self) -> &'static str {
        match self {
            Sensor::Lsm6dsl => "LSM6DSL",
            Sensor::Lis2mdl => "LIS2MDL",
            Sensor::Lps22hb => "LPS22HB",
        }
    }

    /// Blinks of the fatal-sensor LED code that name this sensor.
    pub const fn blink_count(self) -> u8 {
        match self {
            Sensor::Lsm6dsl => 1,
            Sensor::Lis2mdl => 2,
            Sensor::Lps22hb => 3,
        }
    }

    pub const fn who_am_i_addr(self) -> u8 {
        match self {
            Sensor::Lsm6dsl => lsm6dsl::WHO_AM_I,
            Sensor::Lis2mdl => lis2mdl::WHO_AM_I,
            Sensor::Lps22hb => lps22hb::WHO_AM_I,
        }
    }

    pub const fn who_am_i_value(self) -> u8 {
        match self {
            Sensor::Lsm6dsl => lsm6dsl::WHO_AM_I_VALUE,
            Sensor::Lis2mdl => lis2mdl::WHO_AM_I_VALUE,
            Sensor::Lps22hb => lps22hb::WHO_AM_I_VALUE,
        }
    }

    /// Writes that put the sensor on the 3-wire bus; played before `WHO_AM_I` is read.
    pub fn interface_writes(self) -> &'static [RegWrite] {
        match self {
            Sensor::Lsm6dsl => &lsm6dsl::INTERFACE,
            Sensor::Lis2mdl => &lis2mdl::INTERFACE,
            Sensor::Lps22hb => &lps22hb::INTERFACE,
        }
    }

    /// The configuration played after a good `WHO_AM_I` (and, for the LPS22HB, after its
    /// boot delay [`lps22hb::BOOT_DELAY_MS`]).
    pub fn config_writes(self) -> &'static [RegWrite] {
        match self {
            Sensor::Lsm6dsl => &lsm6dsl::CONFIG,
            Sensor::Lis2mdl => &lis2mdl::CONFIG,
            Sensor::Lps22hb => &lps22hb::CONFIG,
        }
    }

    /// Milliseconds to wait between the interface writes and `WHO_AM_I` (the LPS22HB's
    /// software reset and boot; the reference waits a full second there).
    pub const fn settle_ms(self) -> u32 {
        match self {
            Sensor::Lps22hb => lps22hb::BOOT_DELAY_MS,
            _ => 0,
        }
    }

    /// Writes played after [`Sensor::settle_ms`] and before `WHO_AM_I` (the LPS22HB's
    /// software reset cleared its 3-wire bit, so it is set again as the reference does).
    pub fn after_settle_writes(self) -> &'static [RegWrite] {
        match self {
            Sensor::Lps22hb => &lps22hb::AFTER_BOOT,
            _ => &[],
        }
    }

    /// Whether a `WHO_AM_I` answer identifies this sensor.
    pub const fn identifies(self, who_am_i: u8) -> bool {
        who_am_i == self.who_am_i_value()
    }
}

/// Milliseconds from power-up before the sensors listen: the LSM6DSL's boot (15 ms), the
/// LIS2MDL's turn-on (up to 20 ms) and the LPS22HB's boot (4.5 ms), from their datasheets'
/// timing tables, with margin. A write in that window is dropped, and a dropped 3-wire select
/// makes the sensor answer `WHO_AM_I` on a pin this board does not wire.
pub const POWER_UP_MS: u32 = 25;

/// Attempts at a sensor's interface writes and `WHO_AM_I` before it is declared missing, and
/// the wait between two attempts.
pub const WHO_AM_I_ATTEMPTS: u32 = 3;
pub const WHO_AM_I_RETRY_MS: u32 = 10;

/// The first sensor whose `WHO_AM_I` answer was wrong, in bus order. The product flies only
/// with all three answering (`docs/safety.md#boot`: a WHO_AM_I wrong at boot means no flight).
pub fn first_missing(answers: [u8; 3]) -> Option<Sensor> {
    Sensor::ALL.into_iter().zip(answers).find(|&(s, a)| !s.identifies(a)).map(|(s, _)| s)
}

/// LSM6DSL accelerometer + gyroscope.
pub mod lsm6dsl {
    use super::{w, RegWrite};

    pub const FIFO_CTRL5: u8 = 0x0A;
    pub const WHO_AM_I: u8 = 0x0F;
    pub const WHO_AM_I_VALUE: u8 = 0x6A;
    pub const CTRL1_XL: u8 = 0x10;
    pub const CTRL2_G: u8 = 0x11;
    pub const CTRL3_C: u8 = 0x12;
    pub const CTRL4_C: u8 = 0x13;
    pub const CTRL6_C: u8 = 0x15;
    pub const CTRL8_XL: u8 = 0x17;
    pub const OUTX_L_G: u8 = 0x22;
    pub const OUTX_L_XL: u8 = 0x28;

    /// CTRL3_C: SIM (3-wire SPI) | IF_INC (address auto-increment).
    pub const CTRL3_C_3WIRE_AUTOINC: u8 = 0x0C;
    /// CTRL3_C final value: the above plus BDU (block data update).
    pub const CTRL3_C_FINAL: u8 = 0x4C;
    /// CTRL4_C: I2C_disable.
    pub const CTRL4_C_I2C_DISABLE: u8 = 0x04;
    /// FIFO_CTRL5: bypass mode (the sensor FIFO is not used).
    pub const FIFO_CTRL5_BYPASS: u8 = 0x00;
    /// CTRL1_XL: ODR 6.66 kHz, ±4 g, LPF1_BW_SEL = 0, BW0_XL = 0 (1.5 kHz analog filter).
    pub const CTRL1_XL_VALUE: u8 = 0xA8;
    /// CTRL8_XL: LPF2_XL_EN, HPCF_XL = 11 (ODR/400 ≈ 16.65 Hz), low-latency composite path.
    pub const CTRL8_XL_VALUE: u8 = 0xE0;
    /// CTRL2_G: ODR 416 Hz, ±2000 dps.
    pub const CTRL2_G_VALUE: u8 = 0x6C;
    /// CTRL6_C: FTYPE = 01 (the reference's read-modify-write of a register that is 0 after
    /// reset). No effect while LPF1_SEL_G is clear, kept for parity.
    pub const CTRL6_C_VALUE: u8 = 0x01;

    /// Bytes of one accel + gyro burst from [`OUTX_L_G`]: gyro X, Y, Z then accel X, Y, Z.
    pub const BURST_LEN: usize = 12;

    /// The interface write comes first: at power-up the sensor listens in 4-wire mode, which
    /// still accepts writes on the data line but answers reads on a pin that is not wired.
    pub const INTERFACE: [RegWrite; 1] = [w(CTRL3_C, CTRL3_C_3WIRE_AUTOINC)];

    pub const CONFIG: [RegWrite; 7] = [
        w(CTRL3_C, CTRL3_C_FINAL),
        w(CTRL4_C, CTRL4_C_I2C_DISABLE),
        w(FIFO_CTRL5, FIFO_CTRL5_BYPASS),
        w(CTRL1_XL, CTRL1_XL_VALUE),
        w(CTRL8_XL, CTRL8_XL_VALUE),
        w(CTRL2_G, CTRL2_G_VALUE),
        w(CTRL6_C, CTRL6_C_VALUE),
    ];
}

/// LIS2MDL magnetometer (initialised as the reference; never read in flight).
pub mod lis2mdl {
    use super::{w, RegWrite};

    pub const WHO_AM_I: u8 = 0x4F;
    pub const WHO_AM_I_VALUE: u8 = 0x40;
    pub const CFG_REG_A: u8 = 0x60;
    pub const CFG_REG_B: u8 = 0x61;
    pub const CFG_REG_C: u8 = 0x62;

    /// CFG_REG_C: BDU | I2C_DIS. 4WSPI stays 0: 3-wire SPI is this sensor's power-up default,
    /// so no interface bit is needed (unlike the LSM6DSL and LPS22HB). I2C_DIS (bit 5): with
    /// its chip select high the sensor would otherwise watch the shared SCK/SDA lines as an
    /// I2C bus (the reference leaves it on; the LSM6DSL's CTRL4_C gets the same bit).
    pub const CFG_REG_C_BDU_I2C_DIS: u8 = 0x30;
    /// CFG_REG_A: temperature compensation, ODR 100 Hz, continuous mode.
    pub const CFG_REG_A_VALUE: u8 = 0x8C;
    /// CFG_REG_B: offset cancellation.
    pub const CFG_REG_B_VALUE: u8 = 0x02;

    pub const INTERFACE: [RegWrite; 1] = [w(CFG_REG_C, CFG_REG_C_BDU_I2C_DIS)];

    pub const CONFIG: [RegWrite; 2] = [w(CFG_REG_A, CFG_REG_A_VALUE), w(CFG_REG_B, CFG_REG_B_VALUE)];
}

/// LPS22HB barometer (initialised as the reference; never read in the control task).
pub mod lps22hb {
    use super::{w, RegWrite};

    pub const WHO_AM_I: u8 = 0x0F;
    pub const WHO_AM_I_VALUE: u8 = 0xB1;
    pub const CTRL_REG1: u8 = 0x10;
    pub const CTRL_REG2: u8 = 0x11;

    /// CTRL_REG1: SIM (3-wire SPI).
    pub const CTRL_REG1_3WIRE: u8 = 0x01;
    /// CTRL_REG2: BOOT | SWRESET | IF_ADD_INC (the reset value's auto-increment kept).
    pub const CTRL_REG2_RESET_BOOT: u8 = 0x94;
    /// CTRL_REG1 after the driver init: ODR 25 Hz, BDU, 3-wire SPI.
    pub const CTRL_REG1_FINAL: u8 = 0x33;
    /// CTRL_REG2 after init: IF_ADD_INC | I2C_DIS (bit 3), so the deselected sensor does not
    /// take SPI traffic on the shared lines for I2C (ST's application code sets it).
    pub const CTRL_REG2_I2C_DIS: u8 = 0x18;
    /// The reference's blocking wait after the software reset and boot.
    pub const BOOT_DELAY_MS: u32 = 1000;

    /// 3-wire first, then reset + boot; the reset clears SIM again, so [`CONFIG`] sets it
    /// back before anything is read.
    pub const INTERFACE: [RegWrite; 2] = [w(CTRL_REG1, CTRL_REG1_3WIRE), w(CTRL_REG2, CTRL_REG2_RESET_BOOT)];

    pub const CONFIG: [RegWrite; 2] = [w(CTRL_REG1, CTRL_REG1_FINAL), w(CTRL_REG2, CTRL_REG2_I2C_DIS)];

    /// Written after the boot delay and before `WHO_AM_I`, exactly as the reference does.
    pub const AFTER_BOOT: [RegWrite; 1] = [w(CTRL_REG1, CTRL_REG1_3WIRE)];
}

/// Decode an LSM6DSL burst read starting at OUTX_L_G (0x22): 6 gyro bytes then 6 accel
/// bytes, each axis little-endian int16.
pub fn decode_lsm6dsl_burst(bytes: &[u8; lsm6dsl::BURST_LEN]) -> RawImu {
    let w = |lo: u8, hi: u8| i16::from_le_bytes([lo, hi]);
    let [g0, g1, g2, g3, g4, g5, a0, a1, a2, a3, a4, a5] = *bytes;
    RawImu { gyro: [w(g0, g1), w(g2, g3), w(g4, g5)], accel: [w(a0, a1), w(a2, a3), w(a4, a5)] }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_address_sets_bit_7_and_write_clears_it() {
        assert_eq!(read_address(lsm6dsl::WHO_AM_I), 0x8F);
        assert_eq!(read_address(lsm6dsl::OUTX_L_G), 0xA2);
        assert_eq!(read_address(lis2mdl::WHO_AM_I), 0xCF);
        assert_eq!(write_address(0x92), 0x12);
        assert_eq!(write_address(lsm6dsl::CTRL3_C), 0x12);
    }

    #[test]
    fn who_am_i_table_matches_the_datasheets() {
        assert_eq!((Sensor::Lsm6dsl.who_am_i_addr(), Sensor::Lsm6dsl.who_am_i_value()), (0x0F, 0x6A));
        assert_eq!((Sensor::Lis2mdl.who_am_i_addr(), Sensor::Lis2mdl.who_am_i_value()), (0x4F, 0x40));
        assert_eq!((Sensor::Lps22hb.who_am_i_addr(), Sensor::Lps22hb.who_am_i_value()), (0x0F, 0xB1));
    }

    #[test]
    fn lsm6dsl_boot_table_is_the_reference() {
        assert_eq!(lsm6dsl::INTERFACE, [RegWrite { addr: 0x12, value: 0x0C }]);
        let expected = [(0x12, 0x4C), (0x13, 0x04), (0x0A, 0x00), (0x10, 0xA8), (0x17, 0xE0), (0x11, 0x6C), (0x15, 0x01)];
        let got: [(u8, u8); 7] = lsm6dsl::CONFIG.map(|r| (r.addr, r.value));
        assert_eq!(got, expected);
    }

    #[test]
    fn lis2mdl_and_lps22hb_boot_tables_are_the_reference() {
        assert_eq!(lis2mdl::CONFIG.map(|r| (r.addr, r.value)), [(0x60, 0x8C), (0x61, 0x02)]);
        assert_eq!(lis2mdl::INTERFACE.map(|r| (r.addr, r.value)), [(0x62, 0x30)], "BDU and I2C_DIS");
        assert_eq!(lps22hb::CONFIG[1], RegWrite { addr: 0x11, value: 0x18 }, "IF_ADD_INC and I2C_DIS");
        assert_eq!(lps22hb::INTERFACE[0], RegWrite { addr: 0x10, value: 0x01 });
        assert_eq!(lps22hb::AFTER_BOOT[0], RegWrite { addr: 0x10, value: 0x01 });
        assert_eq!(lps22hb::CONFIG[0].value & lps22hb::CTRL_REG1_3WIRE, lps22hb::CTRL_REG1_3WIRE);
        assert_eq!(Sensor::Lps22hb.settle_ms(), 1000);
    }

    #[test]
    fn all_answers_right_means_nothing_missing() {
        assert_eq!(first_missing([0x6A, 0x40, 0xB1]), None);
    }

    #[test]
    fn wrong_who_am_i_names_the_first_missing_sensor_in_bus_order() {
        assert_eq!(first_missing([0xFF, 0x40, 0xB1]), Some(Sensor::Lsm6dsl));
        assert_eq!(first_missing([0x6A, 0x00, 0x00]), Some(Sensor::Lis2mdl));
        assert_eq!(first_missing([0x6A, 0x40, 0xB0]), Some(Sensor::Lps22hb));
    }

    #[test]
    fn sensor_blink_counts_are_distinct_and_start_at_one() {
        assert_eq!(Sensor::ALL.map(Sensor::blink_count), [1, 2, 3]);
    }

    #[test]
    fn burst_decodes_gyro_then_accel_little_endian() {
        let bytes = [0x01, 0x00, 0xFF, 0xFF, 0x00, 0x80, 0x34, 0x12, 0xFF, 0x7F, 0x10, 0xFC];
        let raw = decode_lsm6dsl_burst(&bytes);
        assert_eq!(raw.gyro, [1, -1, i16::MIN]);
        assert_eq!(raw.accel, [0x1234, i16::MAX, -1008]);
    }
}
