//! PWR, power controller (RM0368 §5), at 0x4000_7000.
//!
//! Modelled: CR.VOS (regulator voltage scaling) and the flag-clear bits CWUF/CSBF (their flags
//! never set: Stop/Standby are not modelled), CSR.VOSRDY (always 1: the regulator is assumed ready
//! before the firmware runs), and the programmable voltage detector (RM0368 §5.2.3): CR.PVDE and
//! CR.PLS, CSR.PVDO = 1 while VDD is below the selected threshold. VDD is the board's
//! ([`Pwr::set_vdd_volts`], 3.3 V from the board's regulator unless a test sets it); each level's
//! thresholds are the datasheet's typical values ([`PVD_THRESHOLDS_V`]), with its hysteresis: the
//! falling threshold while PVDO = 0, the rising one while PVDO = 1. The PVD's EXTI line 16 is not
//! modelled (the firmware polls PVDO). Not modelled (an [`Unmodelled`] error when set): low-power
//! modes (LPDS, PDDS, FPDS, LPLVDS, MRLVDS), backup-domain access (DBP), ADCDC1,
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
const CR_PVDE: u32 = 1 << 4;
const CR_PLS_SHIFT: u32 = 5;
const CR_PLS: u32 = 0b111 << CR_PLS_SHIFT;
const CR_VOS: u32 = 0b11 << 14;

/// CSR read-only flags: WUF, SBF, PVDO, BRR, VOSRDY. Writes to them are ignored.
const CSR_READ_ONLY: u32 = 0x0000_400F;
const CSR_VOSRDY: u32 = 1 << 14;
const CSR_PVDO: u32 = 1 << 2;

/// The PVD's thresholds per PLS level, (falling, rising) in volts, typical (DS9716, "embedded
/// reset and power control block characteristics"; the F4 datasheets share the table).
#[expect(clippy::approx_constant, reason = "3.14 V is level 7's rising threshold, not π")]
pub const PVD_THRESHOLDS_V: [(f64, f64); 8] =
    [(2.04, 2.14), (2.19, 2.30), (2.35, 2.45), (2.51, 2.60), (2.66, 2.76), (2.84, 2.93), (2.93, 3.03), (3.03, 3.14)];

/// VDD on the board: its 3.3 V regulator's output.
pub const BOARD_VDD_VOLTS: f64 = 3.3;

/// Maximum HCLK for each voltage scale (STM32F401xB/C datasheet, general operating conditions).
pub const SCALE2_HCLK_MAX_HZ: u64 = 84_000_000;
pub const SCALE3_HCLK_MAX_HZ: u64 = 60_000_000;

/// The PWR model.
#[derive(Clone, Debug)]
pub struct Pwr {
    cr: u32,
    /// The supply, set by the board (not a register: it survives resets).
    vdd_volts: f64,
    /// CSR.PVDO as last evaluated (the hysteresis needs it).
    pvdo: bool,
}

impl Default for Pwr {
    fn default() -> Self {
        Pwr::new()
    }
}

impl Pwr {
    /// Reset state: VOS = scale 2 (RM0368), everything else off.
    pub fn new() -> Self {
        Pwr { cr: CR_RESET, vdd_volts: BOARD_VDD_VOLTS, pvdo: false }
    }

    /// The supply on VDD from now on (a board set-up or a sagging regulator).
    pub fn set_vdd_volts(&mut self, volts: f64) {
        self.vdd_volts = volts;
        self.refresh_pvdo();
    }

    /// The supply on VDD.
    pub fn vdd_volts(&self) -> f64 {
        self.vdd_volts
    }

    /// Whether the PVD is on (CR.PVDE).
    pub fn pvd_enabled(&self) -> bool {
        self.cr & CR_PVDE != 0
    }

    /// CR.PLS, the PVD's level (0..7).
    pub fn pvd_level(&self) -> u32 {
        (self.cr & CR_PLS) >> CR_PLS_SHIFT
    }

    /// CSR.PVDO: VDD below the threshold of the selected level (0 with the PVD off).
    pub fn pvdo(&self) -> bool {
        self.pvdo
    }

    fn refresh_pvdo(&mut self) {
        if !self.pvd_enabled() {
            self.pvdo = false;
            return;
        }
        let (falling, rising) = PVD_THRESHOLDS_V[self.pvd_level() as usize];
        let threshold = if self.pvdo { rising } else { falling };
        self.pvdo = self.vdd_volts < threshold;
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
            CSR => Ok(CSR_VOSRDY | if self.pvdo { CSR_PVDO } else { 0 }),
            _ => Err(Unmodelled::offset(NAME, offset, false)),
        }
    }

    pub fn write(&mut self, offset: u32, value: u32, _now: Time) -> Result<(), Unmodelled> {
        match offset {
            CR => {
                Unmodelled::check_bits("PWR.CR", value, CR_VOS | CR_CWUF | CR_CSBF | CR_PVDE | CR_PLS)?;
                let vos = (value & CR_VOS) >> 14;
                if vos == 0b00 || vos == 0b11 {
                    return Err(Unmodelled::new("PWR.CR", format!("VOS = {vos:#04b}: reserved value (RM0368 PWR_CR)")));
                }
                // RM0368: VOS "can be modified only when the PLL is OFF"; the PLL state lives in
                // the RCC model, so the machine may check `Rcc` before forwarding this write.
                self.cr = value & (CR_VOS | CR_PVDE | CR_PLS);
                self.refresh_pvdo();
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
        let vdd = self.vdd_volts;
        *self = Pwr::new();
        self.vdd_volts = vdd;
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

    /// Rule (RM0368 §5.2.3, PWR_CSR.PVDO): with PVDE, PVDO tells whether VDD is under the
    /// level's threshold, with the datasheet's hysteresis; with the PVD off it reads 0.
    #[test]
    fn pvdo_follows_vdd_against_the_selected_level_with_hysteresis() {
        let mut pwr = Pwr::new();
        pwr.set_vdd_volts(2.5);
        assert_eq!(pwr.read(CSR, 0).unwrap() & CSR_PVDO, 0, "PVD off");
        let level6 = CR_RESET | CR_PVDE | (6 << CR_PLS_SHIFT);
        pwr.write(CR, level6, 0).unwrap();
        assert_eq!(pwr.read(CR, 0), Ok(level6));
        assert_eq!(pwr.read(CSR, 0).unwrap() & CSR_PVDO, CSR_PVDO, "2.5 V under level 6");
        pwr.set_vdd_volts(3.0);
        assert!(pwr.pvdo(), "3.0 V: still under the rising threshold (3.03 V)");
        pwr.set_vdd_volts(3.3);
        assert!(!pwr.pvdo());
        pwr.set_vdd_volts(2.95);
        assert!(!pwr.pvdo(), "2.95 V: above the falling threshold (2.93 V)");
        pwr.set_vdd_volts(2.7);
        assert!(pwr.pvdo());
        // The supply is the board's: a reset of PWR keeps it (and turns the PVD off).
        Peripheral::reset(&mut pwr);
        assert!(!pwr.pvdo() && !pwr.pvd_enabled());
        pwr.write(CR, level6, 0).unwrap();
        assert!(pwr.pvdo(), "2.7 V kept through the reset");
    }

    #[test]
    fn csr_flags_are_read_only_and_ewup_is_unmodelled() {
        let mut pwr = Pwr::new();
        assert!(pwr.write(CSR, CSR_VOSRDY, 0).is_ok());
        assert!(pwr.write(CSR, 1 << 8, 0).is_err());
        assert!(pwr.read(0x08, 0).is_err());
    }
}
