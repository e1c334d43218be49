//! DBGMCU, MCU debug component (RM0368 §23), at 0xE004_2000.
//!
//! No debugger is attached in this model, so the core never halts and the freeze bits
//! (DBG_xxx_STOP in APB1_FZ / APB2_FZ) and the low-power debug bits in CR have no effect: they
//! are stored and read back only. IDCODE is read-only. CR, APB1_FZ and APB2_FZ are reset by a
//! power-on reset only (RM0368 §23, register descriptions: "not reset by system reset"): the
//! board keeps this model across a system reset.
//!
//! Field positions from the `stm32f4` 0.16 PAC (`stm32f401/dbgmcu/*.rs`). The SVD's IDCODE reset
//! value (0x1000_6411) is the F40x's DEV_ID; the F401xB/C (this board:
//! `docs/reference.md#versions`, built for the STM32F401xC) has DEV_ID 0x423 (RM0368
//! DBGMCU_IDCODE), REV_ID 0x1000 for revision A and 0x1001 for revision Z. Assumption: revision Z.

use super::{Clocks, Peripheral, Time, Unmodelled};

/// Base address of DBGMCU (on the private peripheral bus).
pub const BASE: u32 = 0xE004_2000;
/// Peripheral name used in error messages.
pub const NAME: &str = "DBGMCU";

/// IDCODE: REV_ID 0x1001 (revision Z) in bits 31:16, DEV_ID 0x423 (STM32F401xB/C) in bits 11:0.
pub const IDCODE: u32 = 0x1001_0423;

const IDCODE_OFFSET: u32 = 0x00;
const CR: u32 = 0x04;
const APB1_FZ: u32 = 0x08;
const APB2_FZ: u32 = 0x0C;

/// DBG_SLEEP, DBG_STOP, DBG_STANDBY, TRACE_IOEN, TRACE_MODE.
const CR_FIELDS: u32 = 0x0000_00E7;
/// DBG_TIM2..5_STOP, DBG_RTC_STOP, DBG_WWDG_STOP, DBG_IWDG_STOP, DBG_I2C1..3_SMBUS_TIMEOUT.
const APB1_FZ_FIELDS: u32 = 0x00E0_1C0F;
/// DBG_TIM1_STOP, DBG_TIM9..11_STOP.
const APB2_FZ_FIELDS: u32 = 0x0007_0001;

/// DBG_IWDG_STOP in APB1_FZ.
pub const APB1_FZ_DBG_IWDG_STOP: u32 = 1 << 12;

/// The DBGMCU model.
#[derive(Clone, Debug, Default)]
pub struct Dbgmcu {
    cr: u32,
    apb1_fz: u32,
    apb2_fz: u32,
}

impl Dbgmcu {
    /// Power-on state: all zero.
    pub fn new() -> Self {
        Dbgmcu { cr: 0, apb1_fz: 0, apb2_fz: 0 }
    }

    /// APB1_FZ as written (e.g. [`APB1_FZ_DBG_IWDG_STOP`]); stored only, no effect.
    pub fn apb1_fz(&self) -> u32 {
        self.apb1_fz
    }

    /// APB2_FZ as written; stored only, no effect.
    pub fn apb2_fz(&self) -> u32 {
        self.apb2_fz
    }

    pub fn read(&mut self, offset: u32, _now: Time) -> Result<u32, Unmodelled> {
        match offset {
            IDCODE_OFFSET => Ok(IDCODE),
            CR => Ok(self.cr),
            APB1_FZ => Ok(self.apb1_fz),
            APB2_FZ => Ok(self.apb2_fz),
            _ => Err(Unmodelled::offset(NAME, offset, false)),
        }
    }

    pub fn write(&mut self, offset: u32, value: u32, _now: Time) -> Result<(), Unmodelled> {
        match offset {
            IDCODE_OFFSET => Err(Unmodelled::new("DBGMCU.IDCODE", format!("write of {value:#010x} to a read-only register"))),
            CR => {
                Unmodelled::check_bits("DBGMCU.CR", value, CR_FIELDS)?;
                self.cr = value;
                Ok(())
            }
            APB1_FZ => {
                Unmodelled::check_bits("DBGMCU.APB1_FZ", value, APB1_FZ_FIELDS)?;
                self.apb1_fz = value;
                Ok(())
            }
            APB2_FZ => {
                Unmodelled::check_bits("DBGMCU.APB2_FZ", value, APB2_FZ_FIELDS)?;
                self.apb2_fz = value;
                Ok(())
            }
            _ => Err(Unmodelled::offset(NAME, offset, true)),
        }
    }
}

impl Peripheral for Dbgmcu {
    fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        Dbgmcu::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: Clocks) -> Result<(), Unmodelled> {
        Dbgmcu::write(self, offset, value, now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idcode_is_the_f401xc_dev_id_and_read_only() {
        let mut d = Dbgmcu::new();
        assert_eq!(d.read(0, 0).map(|v| v & 0xFFF), Ok(0x423));
        assert!(d.write(0, 0, 0).is_err());
    }

    #[test]
    fn freeze_bits_are_stored_without_effect() {
        let mut d = Dbgmcu::new();
        d.write(APB1_FZ, APB1_FZ_DBG_IWDG_STOP, 0).unwrap();
        assert_eq!(d.read(APB1_FZ, 0), Ok(1 << 12));
        assert_eq!(d.apb1_fz(), 1 << 12);
        d.write(APB2_FZ, 1 << 16, 0).unwrap();
        assert_eq!(d.read(APB2_FZ, 0), Ok(1 << 16));
        d.write(CR, 0b111, 0).unwrap();
        assert_eq!(d.read(CR, 0), Ok(0b111));
    }

    #[test]
    fn reserved_bits_and_offsets_are_errors() {
        let mut d = Dbgmcu::new();
        assert!(d.write(APB1_FZ, 1 << 4, 0).is_err());
        assert!(d.write(APB2_FZ, 1 << 1, 0).is_err());
        assert!(d.write(CR, 1 << 3, 0).is_err());
        assert!(d.read(0x10, 0).is_err());
    }
}
