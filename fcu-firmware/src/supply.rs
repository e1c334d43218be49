//! The supply and the clock's guards: the programmable voltage detector watching VDD for the
//! flash, and the clock security system watching the HSE crystal.
//!
//! **VDD for flash writes.** A save programs and erases at x32 (PSIZE = 32), which RM0368
//! (§3.5.1, program/erase parallelism) allows only at VDD ≥ 2.7 V; the factory option bytes leave
//! the brown-out reset off. The PVD is set to level 6 (PLS = 110): its falling threshold is 2.85 V
//! at the least and its rising one 3.10 V at the most (DS9716), so PVDO = 0 says VDD is above
//! 2.7 V, and the board's 3.3 V regulator reads above both. The firmware only reports it
//! ([`vdd_ok_for_flash`]); whether a save may run is the link task's decision. (Brown-out level
//! 3 in the option bytes was the other way: it would reset the chip at any dip under 2.7 V in
//! flight too, where the F401 runs down to 1.7 V, and it is a permanent change of the part made
//! by a flash write of its own.)
//!
//! **The crystal.** With CSSON, a crystal that stops (RM0368 §6.2.7) turns the HSE and its PLL
//! off, switches SYSCLK to the 16 MHz HSI and raises the NMI. Without it the system clock is
//! gone: the core stops with TIM4 holding the motors' duty until the watchdog resets the board.

use stm32f4xx_hal::pac::{PWR, RCC, TIM4};

/// PLS = 110: the PVD's level 6 (falling 2.85 V minimum, rising 3.10 V maximum, DS9716).
const PVD_LEVEL_6: u8 = 0b110;

/// Both guards, once the clock is set up: the PVD, and the clock security system if the
/// crystal runs.
pub fn start(pwr: PWR, rcc: &mut stm32f4xx_hal::rcc::Rcc, crystal_ready: bool) {
    watch_vdd(pwr, rcc);
    watch_crystal(crystal_ready);
}

/// Turns the PVD on at level 6 (PWR's clock first: its registers need it).
fn watch_vdd(pwr: PWR, rcc: &mut stm32f4xx_hal::rcc::Rcc) {
    use stm32f4xx_hal::rcc::Enable;
    PWR::enable(rcc);
    pwr.cr().modify(|_, w| w.pls().set(PVD_LEVEL_6).pvde().set_bit());
}

/// VDD is above the PVD's level-6 threshold (PVDO = 0): high enough for the flash's x32
/// program and erase. What the link task hands to `fcu-link`, which decides.
pub fn vdd_ok_for_flash() -> bool {
    // SAFETY: a read of PWR_CSR, a status register no code writes after `watch_vdd`.
    let pwr = unsafe { &*PWR::ptr() };
    pwr.csr().read().pvdo().bit_is_clear()
}

/// Arms the clock security system once the HSE drives the clock (CSSON is only useful, and the
/// detector only runs, with the crystal ready).
fn watch_crystal(crystal_ready: bool) {
    if !crystal_ready {
        return;
    }
    // SAFETY: a read-modify-write of RCC_CR in `init` (interrupts off), after the HAL's clock
    // set-up has released RCC's register block and before anything else touches RCC_CR.
    let rcc = unsafe { &*RCC::ptr() };
    rcc.cr().modify(|_, w| w.csson().set_bit());
}

/// The crystal failed: the clock security system has moved SYSCLK to the 16 MHz HSI, so every
/// timer now runs 5.25 times slower than the firmware set it, and an ESC's idle pulse is no
/// longer an idle pulse. The motors stop at once (all four compares 0: no pulse at all, which
/// an ESC takes as a lost signal, and the MOSFETs' off), CSSF is cleared (the NMI would be
/// taken again for ever otherwise), and the board resets: it boots again on the HSI, on the
/// ground, naming the crystal.
// SAFETY (of the definition, cortex-m-rt's `unsafe fn` for the NMI): it preempts everything,
// including code in the middle of a TIM4 or RCC access; it only writes TIM4's compares and
// event register and RCC_CIR's clear bit, and never returns.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    // SAFETY: register writes only, see above: stopping the motors is what must happen whatever
    // the interrupted code was doing with TIM4.
    let tim4 = unsafe { &*TIM4::ptr() };
    for n in 0..4 {
        tim4.ccr(n).write(|w| w.ccr().set(0));
    }
    tim4.egr().write(|w| w.ug().set_bit());
    // SAFETY: CIR's clear bits are write-1 and its enables are 0 in this firmware: a write of
    // CSSC alone changes nothing else.
    let rcc = unsafe { &*RCC::ptr() };
    rcc.cir().write(|w| w.cssc().set_bit());
    cortex_m::peripheral::SCB::sys_reset()
}
