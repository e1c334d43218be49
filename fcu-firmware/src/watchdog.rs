//! The independent watchdog, set on its registers for a 50 ms timeout. (The HAL's
//! `IndependentWatchdog::start(50 ms)` picks prescaler /256 with reload 6: 56 ms.)
//!
//! The order is ST's (`HAL_IWDG_Init`): start first, then the values, then a bounded wait.
//! The watchdog counts on the LSI, which is off after reset (RCC_CSR.LSION = 0); the start key
//! turns it on (RM0368 §15.3). New PR/RLR values cross into the LSI's domain only while it
//! runs, so waiting for SR.PVU/RVU to clear before the start key never ends on silicon.

use stm32f4xx_hal::pac::{DBGMCU, IWDG};

/// Prescaler /8 (PR = 1) of the 32 kHz LSI: 4 kHz, 0.25 ms per count (RM0368 §15.3).
const PRESCALER_DIV8: u8 = 1;
/// Prescaler /64 (PR = 4): 500 Hz, 2 ms per count.
const PRESCALER_DIV64: u8 = 4;
/// 1000 counts of 2 ms: the timeout over a flash erase.
const FLASH_RELOAD: u16 = 999;
/// 200 counts of 0.25 ms: 50 ms at the LSI's nominal 32 kHz. The LSI varies from 17 to 47 kHz
/// over parts and temperature (datasheet), so the real timeout lies between about 34 and
/// 94 ms: 27 to 75 missed control ticks.
const RELOAD: u16 = 199;
/// How long the new values may take to land: the LSI's start-up (40 µs at most) and five of
/// its cycles at its slowest 17 kHz (294 µs), with margin: 2 ms of the 84 MHz cycle counter.
/// Meanwhile the watchdog runs on its reset values (/4, 0xFFF: at least 348 ms), so the wait
/// cannot be cut short by a reset.
const UPDATE_BOUND_CYCLES: u32 = 2 * 84_000;

/// The watchdog's values did not land within the bound: its LSI clock is not running.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub struct LsiNotRunning;

pub struct Watchdog {
    iwdg: IWDG,
}

impl Watchdog {
    /// Starts the watchdog (it cannot be stopped again), sets prescaler and reload, waits for
    /// them to be in force, and reloads the counter with them. A core halted by a debugger
    /// does not reset under the probe. Needs the DWT cycle counter running.
    pub fn start(iwdg: IWDG, dbgmcu: &DBGMCU) -> Result<Watchdog, LsiNotRunning> {
        dbgmcu.apb1_fz().modify(|_, w| w.dbg_iwdg_stop().set_bit());
        iwdg.kr().write(|w| w.key().start());
        iwdg.kr().write(|w| w.key().unlock());
        iwdg.pr().write(|w| w.pr().set(PRESCALER_DIV8));
        iwdg.rlr().write(|w| w.rl().set(RELOAD));
        crate::cycles::poll(UPDATE_BOUND_CYCLES, || (iwdg.sr().read().bits() == 0).then_some(())).ok_or(LsiNotRunning)?;
        // The first reload after the values land: from here the timeout is 50 ms.
        iwdg.kr().write(|w| w.key().feed());
        Ok(Watchdog { iwdg })
    }

    /// Stretches the timeout over a flash erase: prescaler /64 and 1000 counts, 2 s at the
    /// LSI's nominal 32 kHz, 1.36 s at its fastest 47 kHz, against an erase of 500 ms at most.
    /// The control tick, which feeds the watchdog, stalls with every other fetch from flash
    /// while a sector erases.
    pub fn stretch_for_flash(&mut self) -> Result<(), LsiNotRunning> {
        self.set(PRESCALER_DIV64, FLASH_RELOAD)
    }

    /// Back to the flight timeout (50 ms) after [`Watchdog::stretch_for_flash`].
    pub fn restore(&mut self) -> Result<(), LsiNotRunning> {
        self.set(PRESCALER_DIV8, RELOAD)
    }

    /// New values while running: a bounded wait for any earlier update to have landed (RM0368
    /// IWDG_SR: PR can be changed only with PVU clear, RLR only with RVU clear; a write while
    /// one is under way is not taken), a reload (the count starts full under the old values),
    /// then PR and RLR, a bounded wait for them to land, and a reload with them.
    fn set(&mut self, prescaler: u8, reload: u16) -> Result<(), LsiNotRunning> {
        let iwdg = &self.iwdg;
        let idle = crate::cycles::poll(UPDATE_BOUND_CYCLES, || (iwdg.sr().read().bits() == 0).then_some(()));
        iwdg.kr().write(|w| w.key().feed());
        idle.ok_or(LsiNotRunning)?;
        iwdg.kr().write(|w| w.key().unlock());
        iwdg.pr().write(|w| w.pr().set(prescaler));
        iwdg.rlr().write(|w| w.rl().set(reload));
        let landed = crate::cycles::poll(UPDATE_BOUND_CYCLES, || (iwdg.sr().read().bits() == 0).then_some(()));
        iwdg.kr().write(|w| w.key().feed());
        landed.ok_or(LsiNotRunning)
    }

    pub fn feed(&mut self) {
        self.iwdg.kr().write(|w| w.key().feed());
    }
}
