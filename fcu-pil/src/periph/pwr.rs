//! PWR, power controller (RM0368 §5), at 0x4000_7000.
//!
//! Modelled: CR.VOS (regulator voltage scaling) and the flag-clear bits CWUF/CSBF (their flags
//! never set: Stop/Standby are not modelled), CSR.VOSRDY (always 1: the regulator is assumed ready
//! before the firmware runs). Not modelled (an [`Unmodelled`] error when set): low-power modes
//! (LPDS, PDDS, FPDS, LPLVDS, MRLVDS), the PVD (PVDE, PLS), backup-domain access (DBP), ADCDC1,
//! the wake-up pin (EWUP) and the backup regulator (BRE). The HAL's F401 code paths do not touch
//! PWR at all (over-drive is only for F427/F446/F469).
//!
//! Field positions from the `stm32f4` 0.16 PAC (`stm32f401/pwr/*.rs`). The SVD gives CR a reset
//! value of 0, but RM0368 (PWR_CR) gives 0x0000_8000: VOS = 0b10, scale 2, the F401's reset value.
//! The RM is followed here.

use super::{Clocks, Peripheral, Time, Unmodelled};

/// Base address of PWR (RM0368 memory map).
pub const BASE: u32 = 0x4000_7000;
/// Peripheral name used in error messages.
pub const NAME: &str = "PWR";

const CR: u32 = 0x00;
const CSR: u32 = 0x04;

const CR_RESET: u32 = 0x0000_8000;
const CR_CWUF: u32 = 1 << 2;
const CR_CSBF: u32 = 1 << 3;
const CR_VOS: u32 = 0b11 << 14;

/// CSR read-only flags: WUF, SBF, PVDO, BRR, VOSRDY. Writes to them are ignored.
const CSR_READ_ONLY: u32 = 0x0000_400F;
const CSR_VOSRDY: u32 = 1 << 14;

/// Maximum HCLK for each voltage scale (STM32F401xB/C datasheet, general operating conditions).
pub const SCALE2_HCLK_MAX_HZ: u64 = 84_000_000;
pub const SCALE3_HCLK_MAX_HZ: u64 = 60_000_000;

/// The PWR model.
#[derive(Clone, Debug)]
pub struct Pwr {
    cr: u32,
}

impl Default for Pwr {
    fn default() -> Self {
        Pwr::new()
    }
}

impl Pwr {
    /// Reset state: VOS = scale 2 (RM0368), everything else off.
    pub fn new() -> Self {
        Pwr { cr: CR_RESET }
    }

    /// The selected voltage scale: 2 or 3. RM0368: 0b01 is scale 3, 0b10 scale 2; the reserved
    /// values 0b00 and 0b11 are rejected at the write.
    pub fn vos_scale(&self) -> u8 {
        if self.cr & CR_VOS == 0b01 << 14 {
            3
        } else {
            2
        }
    }

    /// Maximum HCLK the selected voltage scale allows (datasheet: scale 3 ≤ 60 MHz, scale 2
    /// ≤ 84 MHz). RM0368: the scale only takes effect with the PLL on; with the PLL off the
    /// regulator is in scale 3, which the F401 reaches only from HSI/HSE at 16 MHz.
    pub fn max_hclk_hz(&self) -> u64 {
        if self.vos_scale() == 3 {
            SCALE3_HCLK_MAX_HZ
        } else {
            SCALE2_HCLK_MAX_HZ
        }
    }

    /// Error if `hclk_hz` exceeds what the selected voltage scale allows.
    pub fn check_hclk(&self, hclk_hz: u64) -> Result<(), Unmodelled> {
        if hclk_hz > self.max_hclk_hz() {
            Err(Unmodelled::new(
                "PWR.CR",
                format!("HCLK {hclk_hz} Hz above the {} Hz that voltage scale {} allows", self.max_hclk_hz(), self.vos_scale()),
            ))
        } else {
            Ok(())
        }
    }

    pub fn read(&mut self, offset: u32, _now: Time) -> Result<u32, Unmodelled> {
        match offset {
            // CWUF and CSBF always read 0.
            CR => Ok(self.cr & !(CR_CWUF | CR_CSBF)),
            CSR => Ok(CSR_VOSRDY),
            _ => Err(Unmodelled::offset(NAME, offset, false)),
        }
    }

    pub fn write(&mut self, offset: u32, value: u32, _now: Time) -> Result<(), Unmodelled> {
        match offset {
            CR => {
                Unmodelled::check_bits("PWR.CR", value, CR_VOS | CR_CWUF | CR_CSBF)?;
                let vos = (value & CR_VOS) >> 14;
                if vos == 0b00 || vos == 0b11 {
                    return Err(Unmodelled::new("PWR.CR", format!("VOS = {vos:#04b}: reserved value (RM0368 PWR_CR)")));
                }
                // RM0368: VOS "can be modified only when the PLL is OFF"; the PLL state lives in
                // the RCC model, so the machine may check `Rcc` before forwarding this write.
                self.cr = value & CR_VOS;
                Ok(())
            }
            CSR => Unmodelled::check_bits("PWR.CSR", value, CSR_READ_ONLY),
            _ => Err(Unmodelled::offset(NAME, offset, true)),
        }
    }
}

impl Peripheral for Pwr {
    fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        Pwr::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: Clocks) -> Result<(), Unmodelled> {
        Pwr::write(self, offset, value, now)
    }

    fn reset(&mut self) {
        *self = Pwr::new();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reset_selects_scale_2_and_vosrdy_is_set() {
        let mut pwr = Pwr::new();
        assert_eq!(pwr.read(CR, 0), Ok(0x0000_8000));
        assert_eq!(pwr.read(CSR, 0), Ok(1 << 14));
        assert_eq!(pwr.vos_scale(), 2);
        assert!(pwr.check_hclk(84_000_000).is_ok());
    }

    #[test]
    fn scale_3_limits_hclk_to_60_mhz() {
        let mut pwr = Pwr::new();
        pwr.write(CR, 0b01 << 14, 0).unwrap();
        assert_eq!(pwr.vos_scale(), 3);
        assert!(pwr.check_hclk(60_000_000).is_ok());
        assert!(pwr.check_hclk(84_000_000).is_err());
    }

    #[test]
    fn reserved_vos_values_and_low_power_bits_are_errors() {
        let mut pwr = Pwr::new();
        assert!(pwr.write(CR, 0, 0).is_err());
        assert!(pwr.write(CR, 0b11 << 14, 0).is_err());
        assert!(pwr.write(CR, CR_RESET | 1, 0).is_err(), "LPDS");
        assert!(pwr.write(CR, CR_RESET | (1 << 8), 0).is_err(), "DBP");
        assert!(pwr.write(CR, CR_RESET | CR_CWUF | CR_CSBF, 0).is_ok());
        assert_eq!(pwr.read(CR, 0), Ok(CR_RESET));
    }

    #[test]
    fn csr_flags_are_read_only_and_ewup_is_unmodelled() {
        let mut pwr = Pwr::new();
        assert!(pwr.write(CSR, CSR_VOSRDY, 0).is_ok());
        assert!(pwr.write(CSR, 1 << 8, 0).is_err());
        assert!(pwr.read(0x08, 0).is_err());
    }
}
