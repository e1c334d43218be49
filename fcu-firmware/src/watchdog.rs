//! The independent watchdog, set on its registers for a 50 ms timeout. (The HAL's
//! `IndependentWatchdog::start(50 ms)` picks prescaler /256 with reload 6: 56 ms.)

use stm32f4xx_hal::pac::{DBGMCU, IWDG};

/// Prescaler /8 (PR = 1) of the 32 kHz LSI: 4 kHz, 0.25 ms per count (RM0368 §17.3).
const PRESCALER_DIV8: u8 = 1;
/// 200 counts of 0.25 ms: 50 ms at the LSI's nominal 32 kHz. The LSI varies from 17 to 47 kHz
/// over parts and temperature (datasheet), so the real timeout lies between about 34 and
/// 94 ms: 27 to 75 missed control ticks.
const RELOAD: u16 = 199;

pub struct Watchdog {
    iwdg: IWDG,
}

impl Watchdog {
    /// Sets prescaler and reload, then starts the watchdog (it cannot be stopped again). A
    /// core halted by a debugger does not reset under the probe.
    pub fn start(iwdg: IWDG, dbgmcu: &DBGMCU) -> Watchdog {
        dbgmcu.apb1_fz().modify(|_, w| w.dbg_iwdg_stop().set_bit());
        iwdg.kr().write(|w| w.key().unlock());
        iwdg.pr().write(|w| w.pr().set(PRESCALER_DIV8));
        iwdg.rlr().write(|w| w.rl().set(RELOAD));
        // The new values cross into the LSI domain before they count (PVU, RVU).
        while iwdg.sr().read().bits() != 0 {}
        iwdg.kr().write(|w| w.key().feed());
        iwdg.kr().write(|w| w.key().start());
        Watchdog { iwdg }
    }

    pub fn feed(&mut self) {
        self.iwdg.kr().write(|w| w.key().feed());
    }
}
