//! FLASH interface (RM0368 §3), at 0x4002_3C00: only the access control register ACR.
//!
//! ACR's LATENCY, PRFTEN, ICEN, DCEN, ICRST and DCRST are stored; caches and prefetch have no
//! timing effect in this model (the emulator does not model flash wait states), but
//! [`Flash::check_wait_states`] checks LATENCY against RM0368's table for the board's supply.
//! KEYR, OPTKEYR, SR, CR and OPTCR (programming and option bytes) are not modelled.
//! Layout and reset values from the `stm32f4` 0.16 PAC (`stm32f401/flash/*.rs`).

use super::{Time, Unmodelled};

/// Base address of the flash interface registers (RM0368 memory map).
pub const BASE: u32 = 0x4002_3C00;
/// Peripheral name used in error messages.
pub const NAME: &str = "FLASH";

const ACR: u32 = 0x00;

const ACR_LATENCY: u32 = 0xF;
const ACR_PRFTEN: u32 = 1 << 8;
const ACR_ICEN: u32 = 1 << 9;
const ACR_DCEN: u32 = 1 << 10;
/// Write-only in the SVD (reads 0).
const ACR_ICRST: u32 = 1 << 11;
/// Read-write in the SVD.
const ACR_DCRST: u32 = 1 << 12;
const ACR_FIELDS: u32 = ACR_LATENCY | ACR_PRFTEN | ACR_ICEN | ACR_DCEN | ACR_ICRST | ACR_DCRST;

/// What ACR says about the flash's timing, decoded from a value read from or written to it: the
/// emulator's timing profiles see the register only through the bus (see `crate::timing`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AcrTiming {
    /// Wait states (LATENCY).
    pub latency: u32,
    pub prefetch: bool,
    pub icache: bool,
    pub dcache: bool,
    /// ICRST / DCRST set in a written value: the cache is emptied.
    pub icache_reset: bool,
    pub dcache_reset: bool,
}

impl AcrTiming {
    pub fn decode(acr: u32) -> Self {
        AcrTiming {
            latency: acr & ACR_LATENCY,
            prefetch: acr & ACR_PRFTEN != 0,
            icache: acr & ACR_ICEN != 0,
            dcache: acr & ACR_DCEN != 0,
            icache_reset: acr & ACR_ICRST != 0,
            dcache_reset: acr & ACR_DCRST != 0,
        }
    }
}

/// Assumption: VDD = 3.3 V (the board's regulator; the reference firmware uses a 3.3 V ADC
/// reference, `docs/reference.md#battery`), so the 2.7–3.6 V row of RM0368's wait-state table
/// applies: one wait state per started 30 MHz of HCLK, up to 84 MHz.
pub const HCLK_PER_WAIT_STATE_HZ: u64 = 30_000_000;
/// The F401's maximum HCLK.
pub const HCLK_MAX_HZ: u64 = 84_000_000;

/// The flash interface model.
#[derive(Clone, Debug, Default)]
pub struct Flash {
    acr: u32,
}

impl Flash {
    /// Reset state: ACR = 0 (zero wait states, caches and prefetch off).
    pub fn new() -> Self {
        Flash { acr: 0 }
    }

    /// Wait states programmed in ACR.LATENCY.
    pub fn latency(&self) -> u32 {
        self.acr & ACR_LATENCY
    }

    /// Whether prefetch, instruction cache and data cache are enabled.
    pub fn prefetch_and_caches(&self) -> (bool, bool, bool) {
        (self.acr & ACR_PRFTEN != 0, self.acr & ACR_ICEN != 0, self.acr & ACR_DCEN != 0)
    }

    /// Checks LATENCY against RM0368's table "Number of wait states according to CPU clock
    /// (HCLK) frequency", 2.7–3.6 V row: 0 WS up to 30 MHz, 1 WS up to 60 MHz, 2 WS up to
    /// 84 MHz. Too few wait states make the CPU read wrong instructions from flash.
    pub fn check_wait_states(&self, hclk_hz: u64) -> Result<(), Unmodelled> {
        if hclk_hz > HCLK_MAX_HZ {
            return Err(Unmodelled::new(
                "FLASH.ACR",
                format!("HCLK {hclk_hz} Hz above the F401's 84 MHz: no wait-state setting is specified"),
            ));
        }
        let needed = hclk_hz.saturating_sub(1) / HCLK_PER_WAIT_STATE_HZ;
        let latency = u64::from(self.latency());
        if latency < needed {
            Err(Unmodelled::new(
                "FLASH.ACR",
                format!(
                    "LATENCY = {latency} wait states at HCLK {:.3} MHz; RM0368's wait-state table (VDD 2.7-3.6 V) needs at least {needed}",
                    hclk_hz as f64 / 1e6
                ),
            ))
        } else {
            Ok(())
        }
    }

    pub fn read(&mut self, offset: u32, _now: Time) -> Result<u32, Unmodelled> {
        match offset {
            ACR => Ok(self.acr & !ACR_ICRST),
            _ => Err(Unmodelled::offset(NAME, offset, false)),
        }
    }

    pub fn write(&mut self, offset: u32, value: u32, _now: Time) -> Result<(), Unmodelled> {
        match offset {
            ACR => {
                Unmodelled::check_bits("FLASH.ACR", value, ACR_FIELDS)?;
                // RM0368 FLASH_ACR: ICRST/DCRST "can be written only when the I/D cache is disabled".
                if value & ACR_ICRST != 0 && self.acr & ACR_ICEN != 0 {
                    return Err(Unmodelled::new(
                        "FLASH.ACR",
                        "ICRST written while ICEN = 1 (RM0368: only when the instruction cache is disabled)",
                    ));
                }
                if value & ACR_DCRST != 0 && self.acr & ACR_DCEN != 0 && self.acr & ACR_DCRST == 0 {
                    return Err(Unmodelled::new(
                        "FLASH.ACR",
                        "DCRST written while DCEN = 1 (RM0368: only when the data cache is disabled)",
                    ));
                }
                self.acr = value & ACR_FIELDS;
                Ok(())
            }
            _ => Err(Unmodelled::offset(NAME, offset, true)),
        }
    }
}

impl super::Peripheral for Flash {
    fn read(&mut self, offset: u32, now: Time, _clocks: super::Clocks) -> Result<u32, Unmodelled> {
        Flash::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: super::Clocks) -> Result<(), Unmodelled> {
        Flash::write(self, offset, value, now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reset_is_zero_wait_states() {
        let mut f = Flash::new();
        assert_eq!(f.read(ACR, 0), Ok(0));
        assert_eq!(f.latency(), 0);
        assert!(f.check_wait_states(16_000_000).is_ok());
    }

    #[test]
    fn eighty_four_mhz_needs_two_wait_states() {
        let mut f = Flash::new();
        f.write(ACR, 1, 0).unwrap();
        assert!(f.check_wait_states(84_000_000).is_err());
        assert!(f.check_wait_states(60_000_000).is_ok());
        assert!(f.check_wait_states(60_000_001).is_err());
        f.write(ACR, 2 | ACR_PRFTEN | ACR_ICEN | ACR_DCEN, 0).unwrap();
        assert!(f.check_wait_states(84_000_000).is_ok());
        assert_eq!(f.read(ACR, 0), Ok(0x702));
        assert_eq!(f.prefetch_and_caches(), (true, true, true));
    }

    #[test]
    fn thirty_mhz_runs_with_zero_wait_states() {
        let f = Flash::new();
        assert!(f.check_wait_states(30_000_000).is_ok());
        assert!(f.check_wait_states(30_000_001).is_err());
    }

    #[test]
    fn hclk_above_84_mhz_is_an_error() {
        let mut f = Flash::new();
        f.write(ACR, 7, 0).unwrap();
        assert!(f.check_wait_states(100_000_000).is_err());
    }

    #[test]
    fn icrst_reads_zero_and_needs_the_cache_off() {
        let mut f = Flash::new();
        f.write(ACR, ACR_ICRST, 0).unwrap();
        assert_eq!(f.read(ACR, 0), Ok(0));
        f.write(ACR, ACR_ICEN, 0).unwrap();
        assert!(f.write(ACR, ACR_ICEN | ACR_ICRST, 0).is_err());
    }

    #[test]
    fn other_registers_are_unmodelled() {
        let mut f = Flash::new();
        assert!(f.write(0x04, 0x4567_0123, 0).is_err(), "KEYR");
        assert!(f.read(0x0C, 0).is_err(), "SR");
        assert!(f.read(0x14, 0).is_err(), "OPTCR");
        assert!(f.write(ACR, 1 << 13, 0).is_err(), "reserved bit");
    }
}
