//! The two flash sectors that keep the parameters (sectors 1 and 2, reserved in `memory.x`),
//! erased and programmed through the FLASH interface's registers (RM0368 §3.5: unlocking the
//! control register, the program and erase sequences, the error flags).
//!
//! The F401 has a single bank: while a sector erases (DS9716: 16 KiB at x32, typically 250 ms,
//! at most 500 ms) or a word programs (16 µs typical, 100 µs at most), every instruction fetch
//! and data read from flash waits. Interrupts wait with it, the control tick included, so the
//! caller erases only while disarmed, with the watchdog's timeout stretched over the erase.
//! What the words mean (the snapshot format) is fcu-core's; this module only moves them.
//!
//! **Between IMU bursts.** The IMU burst's end-of-read interrupt must stop the SPI clock within
//! one byte (about 3 µs) of its DMA's completion; a stall there clocks in extra bytes and the
//! sample is lost. So every operation starts only in the tick's quiet time: no burst in flight,
//! no TIM9 event waiting for the control task, and the next burst start (TIM9's CC1) at least a
//! word's worst-case programming time away ([`QUIET_CYCLES`]). The check and the store that
//! starts the operation are one critical section. A word then ends before the next burst
//! starts; an erase, which outlasts hundreds of ticks, stalls the tick whole (no burst starts
//! until it ends) instead of cutting one. The barometer's burst starts and ends within one run
//! of the control task, after the tick's motor write, so an operation started from a lower
//! priority never overlaps it. `docs/firmware.md#parameter-saves` says why this and not code in
//! RAM.

use stm32f4xx_hal::pac::{FLASH, TIM9};

/// One parameter sector: 16 KiB.
pub const SECTOR_BYTES: u32 = 16 * 1024;

/// The parameter sectors: (sector number for CR.SNB, first address).
pub const SECTORS: [(u8, u32); 2] = [(1, 0x0800_4000), (2, 0x0800_8000)];

/// KEYR's unlock sequence (RM0368 §3.5.1). A wrong key locks CR until the next reset.
const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;

/// How long an erase may keep the interface busy: twice the datasheet's 500 ms maximum, on
/// the 84 MHz cycle counter (the counter runs on while fetches stall).
const ERASE_BOUND_CYCLES: u32 = 84_000_000;
/// How long one word may take to program: ten times the 100 µs maximum.
const PROGRAM_BOUND_CYCLES: u32 = 84_000;
/// How far the next burst start must be for an operation to start: DS9716's 100 µs maximum
/// word time, plus 20 µs for the look at TIM9 and the store after it (a few cycles) and for
/// the burst's interrupt entry once the stall ends. On the 84 MHz timer clock, which TIM9's
/// counts times (PSC + 1) give.
const QUIET_CYCLES: u32 = 120 * 84;
/// How long an operation waits for the quiet time: four ticks (5 ms); each 1.25 ms tick has
/// about 1 ms of it, so only a stopped or broken tick timer runs this out.
const QUIET_WAIT_BOUND_CYCLES: u32 = 420_000;

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// CR stayed locked after the key sequence.
    Locked,
    /// BSY did not clear within the bound.
    Timeout,
    /// The interface reported an error: SR's error flags (OPERR, WRPERR, PGAERR, PGPERR,
    /// PGSERR), as read.
    Refused(u32),
    /// A sector index other than 0 or 1, or an address outside the parameter sectors.
    OutOfRange,
    /// The tick never left the flash a quiet time to start in (see the module's comment).
    NoQuietTime,
}

/// OPERR | WRPERR | PGAERR | PGPERR | PGSERR (SR bits 1, 4..7).
const SR_ERRORS: u32 = 0xF2;

pub struct ParamFlash {
    flash: FLASH,
}

impl ParamFlash {
    pub fn new(flash: FLASH) -> Self {
        ParamFlash { flash }
    }

    /// The words of parameter sector `index` (0 or 1), as the flash holds them now.
    pub fn sector(&self, index: usize) -> Option<&'static [u32]> {
        let &(_, base) = SECTORS.get(index)?;
        // SAFETY: the sector is mapped, word-aligned flash reserved for this module by the
        // linker script; nothing else writes it, and this module writes it only through the
        // FLASH interface, which the CPU waits for. Reads of it see either the old or the new
        // words, never a torn Rust value (u32s, any bit pattern valid).
        Some(unsafe { core::slice::from_raw_parts(base as *const u32, (SECTOR_BYTES / 4) as usize) })
    }

    /// Erases parameter sector `index` (0 or 1) to all ones. Stalls the CPU for the erase.
    pub fn erase(&mut self, index: usize) -> Result<(), FlashError> {
        let &(snb, _) = SECTORS.get(index).ok_or(FlashError::OutOfRange)?;
        self.unlock()?;
        let result = self.wait_idle(PROGRAM_BOUND_CYCLES).and_then(|()| {
            self.clear_errors();
            self.flash.cr().modify(|_, w| {
                // SAFETY: SNB takes the sector number, 1 or 2 here (the F401CC has 0..5).
                unsafe { w.snb().bits(snb) };
                w.psize().psize32().ser().set_bit()
            });
            when_quiet(|| {
                self.flash.cr().modify(|_, w| w.strt().set_bit());
            })?;
            self.finish(ERASE_BOUND_CYCLES)
        });
        self.flash.cr().modify(|_, w| w.ser().clear_bit());
        self.lock_and_flush();
        result
    }

    /// Programs `words` from `address` on, one 32-bit word at a time (the parallelism the
    /// board's 3.3 V supply allows, RM0368 §3.5.2). The words must be erased (all ones) first:
    /// flash programming only clears bits.
    pub fn program(&mut self, address: u32, words: &[u32]) -> Result<(), FlashError> {
        let end = address.checked_add(4 * words.len() as u32).ok_or(FlashError::OutOfRange)?;
        let inside = SECTORS.iter().any(|&(_, base)| address >= base && end <= base + SECTOR_BYTES);
        if !inside || address % 4 != 0 {
            return Err(FlashError::OutOfRange);
        }
        self.unlock()?;
        let result = self.wait_idle(PROGRAM_BOUND_CYCLES).and_then(|()| {
            self.clear_errors();
            self.flash.cr().modify(|_, w| w.psize().psize32().pg().set_bit());
            let mut at = address;
            for &word in words {
                when_quiet(|| {
                    // SAFETY: `at` is a word-aligned address inside a parameter sector (checked
                    // above); with CR.PG set, a store there is a program request to the
                    // interface, which the bus holds until it is taken.
                    unsafe { core::ptr::write_volatile(at as *mut u32, word) };
                    cortex_m::asm::dsb();
                })?;
                self.finish(PROGRAM_BOUND_CYCLES)?;
                at += 4;
            }
            Ok(())
        });
        self.flash.cr().modify(|_, w| w.pg().clear_bit());
        self.lock_and_flush();
        result
    }

    fn unlock(&mut self) -> Result<(), FlashError> {
        if self.flash.cr().read().lock().is_locked() {
            // SAFETY: KEYR takes any 32-bit value; these two, in order, unlock CR.
            self.flash.keyr().write(|w| unsafe { w.key().bits(KEY1) });
            self.flash.keyr().write(|w| unsafe { w.key().bits(KEY2) });
        }
        if self.flash.cr().read().lock().is_locked() {
            Err(FlashError::Locked)
        } else {
            Ok(())
        }
    }

    fn wait_idle(&self, bound: u32) -> Result<(), FlashError> {
        crate::cycles::poll(bound, || self.flash.sr().read().bsy().bit_is_clear().then_some(())).ok_or(FlashError::Timeout)
    }

    /// Waits for the operation to end, then reads its verdict from SR.
    fn finish(&self, bound: u32) -> Result<(), FlashError> {
        self.wait_idle(bound)?;
        let errors = self.flash.sr().read().bits() & SR_ERRORS;
        self.clear_errors();
        if errors == 0 {
            Ok(())
        } else {
            Err(FlashError::Refused(errors))
        }
    }

    /// EOP and the error flags are cleared by writing 1 (rc_w1).
    fn clear_errors(&self) {
        self.flash.sr().write(|w| w.eop().clear().operr().clear().wrperr().clear().pgaerr().clear().pgperr().clear().pgserr().clear());
    }

    /// Locks CR again, and empties the data cache, which may hold words of the sector from
    /// before the operation (RM0368 §3.5: the cache is reset with DCEN off).
    fn lock_and_flush(&mut self) {
        self.flash.cr().modify(|_, w| w.lock().set_bit());
        self.flash.acr().modify(|_, w| w.dcen().clear_bit());
        self.flash.acr().modify(|_, w| w.dcrst().set_bit());
        self.flash.acr().modify(|_, w| w.dcrst().clear_bit().dcen().set_bit());
    }
}

/// Runs `start` (the store or the CR write that starts a flash operation) once the tick leaves
/// the time the operation needs, the look and the start in one critical section so that no
/// interrupt moves the tick on between them.
fn when_quiet(start: impl FnOnce()) -> Result<(), FlashError> {
    let mut start = Some(start);
    crate::cycles::poll(QUIET_WAIT_BOUND_CYCLES, || {
        cortex_m::interrupt::free(|_| {
            if !quiet() {
                return None;
            }
            start.take().map(|start| start())
        })
    })
    .ok_or(FlashError::NoQuietTime)
}

/// Whether an operation started now ends before the next IMU burst starts, and none is in
/// flight: TIM9 (the control tick's timer) stopped, or counting before its CC1 (the burst's
/// start) with no event of it waiting for the control task and CC1 [`QUIET_CYCLES`] or more
/// away. Between CC1 and the update the burst is in flight; a pending flag means the control
/// task has yet to run (start the burst, or tick).
fn quiet() -> bool {
    // SAFETY: reads only (CR1, SR, CNT, CCR1, PSC): TIM9 is the control task's, which alone
    // writes it; a read changes nothing in a timer (SR's flags clear on a write of 0).
    let tim = unsafe { &*TIM9::ptr() };
    if tim.cr1().read().cen().bit_is_clear() {
        return true;
    }
    let sr = tim.sr().read();
    if sr.uif().bit_is_set() || sr.cc1if().bit_is_set() {
        return false;
    }
    let count = u32::from(tim.cnt().read().cnt().bits());
    let burst_at = u32::from(tim.ccr1().read().ccr().bits());
    let cycles_per_count = u32::from(tim.psc().read().psc().bits()) + 1;
    count < burst_at && (burst_at - count).saturating_mul(cycles_per_count) >= QUIET_CYCLES
}
