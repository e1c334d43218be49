//! The Cortex-M4F's own system peripherals, which Unicorn does not emulate: the NVIC, the
//! system control block (SCB), SysTick, the FPU's control registers, and the DWT cycle counter
//! with its enable in the debug control block. Addresses and reset values from the ARMv7-M
//! Architecture Reference Manual (B3) and the Cortex-M4 TRM; the STM32F401 implements four
//! priority bits and 85 external interrupts (RM0368 §10).
//!
//! Exception numbers follow the architecture: 1 reset, 2 NMI, 3 HardFault, 4 MemManage,
//! 5 BusFault, 6 UsageFault, 11 SVCall, 12 DebugMonitor, 14 PendSV, 15 SysTick, 16 + n IRQ n.

use crate::periph::{Time, Unmodelled};

/// External interrupts of the STM32F401 (RM0368 table 38: positions 0..84).
pub const IRQS: usize = 85;
/// Exceptions including the system ones.
pub const EXCEPTIONS: usize = 16 + IRQS;
pub const HARD_FAULT: usize = 3;
pub const BUS_FAULT: usize = 5;
pub const USAGE_FAULT: usize = 6;
pub const SVCALL: usize = 11;
pub const PENDSV: usize = 14;
pub const SYSTICK: usize = 15;

/// Base of the system control space.
pub const SCS_BASE: u32 = 0xE000_E000;
/// Base of the DWT unit.
pub const DWT_BASE: u32 = 0xE000_1000;

/// Register offsets from [`SCS_BASE`] (ARMv7-M B3.2.2 SCB, B3.3.2 SysTick, B3.4.3 NVIC, C1.6.5
/// DEMCR; the FPU's FPCCR, FPCAR and FPDSCR in the Cortex-M4 TRM). The NVIC's banks run over 8
/// words, its priority registers over 60; `_END` is a bank's last word.
pub mod reg {
    pub const ICTR: u32 = 0x004;
    pub const SYST_CSR: u32 = 0x010;
    pub const SYST_RVR: u32 = 0x014;
    pub const SYST_CVR: u32 = 0x018;
    pub const SYST_CALIB: u32 = 0x01C;
    pub const NVIC_ISER: u32 = 0x100;
    pub const NVIC_ISER_END: u32 = 0x11C;
    pub const NVIC_ICER: u32 = 0x180;
    pub const NVIC_ICER_END: u32 = 0x19C;
    pub const NVIC_ISPR: u32 = 0x200;
    pub const NVIC_ISPR_END: u32 = 0x21C;
    pub const NVIC_ICPR: u32 = 0x280;
    pub const NVIC_ICPR_END: u32 = 0x29C;
    pub const NVIC_IABR: u32 = 0x300;
    pub const NVIC_IABR_END: u32 = 0x31C;
    pub const NVIC_IPR: u32 = 0x400;
    pub const NVIC_IPR_END: u32 = 0x4EC;
    pub const CPUID: u32 = 0xD00;
    pub const ICSR: u32 = 0xD04;
    pub const VTOR: u32 = 0xD08;
    pub const AIRCR: u32 = 0xD0C;
    pub const SCR: u32 = 0xD10;
    pub const CCR: u32 = 0xD14;
    pub const SHPR1: u32 = 0xD18;
    pub const SHPR2: u32 = 0xD1C;
    pub const SHPR3: u32 = 0xD20;
    pub const SHCSR: u32 = 0xD24;
    pub const CFSR: u32 = 0xD28;
    pub const HFSR: u32 = 0xD2C;
    pub const CPACR: u32 = 0xD88;
    pub const DEMCR: u32 = 0xDFC;
    pub const STIR: u32 = 0xF00;
    pub const FPCCR: u32 = 0xF34;
    pub const FPCAR: u32 = 0xF38;
    pub const FPDSCR: u32 = 0xF3C;
    /// DWT registers, from [`super::DWT_BASE`] (ARMv7-M C1.8.7, C1.8.8).
    pub const DWT_CTRL: u32 = 0x000;
    pub const DWT_CYCCNT: u32 = 0x004;
}
use reg::*;

/// Priority of thread mode with nothing active: lower than any configurable priority.
pub const THREAD_PRIORITY: i32 = 256;

/// NVIC, SCB, SysTick, FPU control, DWT and DEMCR.
#[derive(Clone, Debug)]
pub struct Scs {
    enabled: [bool; EXCEPTIONS],
    pending: [bool; EXCEPTIONS],
    active: [bool; EXCEPTIONS],
    /// Priority bytes as written (IPR and SHPR); the F401 implements bits 7:4.
    priority: [u8; EXCEPTIONS],
    /// Any pending flag set (a fast test for the block hook).
    any_pending: bool,
    pub vtor: u32,
    prigroup: u32,
    pub scr: u32,
    ccr: u32,
    shcsr: u32,
    pub cfsr: u32,
    pub hfsr: u32,
    cpacr: u32,
    fpccr: u32,
    fpcar: u32,
    fpdscr: u32,
    /// A write to AIRCR with SYSRESETREQ: the machine resets.
    pub reset_requested: bool,
    // SysTick.
    systick_csr: u32,
    systick_rvr: u32,
    /// Time of the last reload (the counter is computed from it).
    systick_reload_at: Time,
    /// CVR value loaded at `systick_reload_at`.
    systick_loaded: u32,
    systick_countflag: bool,
    /// Time units per processor clock cycle (SysTick's CLKSOURCE = 1 and DWT count it).
    units_per_cycle: u64,
    // DWT.
    demcr: u32,
    dwt_ctrl: u32,
    /// CYCCNT at `cyccnt_at` (it counts while CYCCNTENA and TRCENA are set).
    cyccnt_base: u32,
    cyccnt_at: Time,
    /// Whether an FPU instruction could be trapped: Unicorn always allows them, so the model
    /// only records when CPACR enabled CP10/CP11.
    pub fpu_enabled_at: Option<Time>,
}

/// CPUID of a Cortex-M4 r0p1 (the STM32F401's core, DBGMCU/PM0214).
const CPUID_VALUE: u32 = 0x410F_C241;

impl Scs {
    pub fn new(units_per_cycle: u64) -> Self {
        let mut s = Scs {
            enabled: [false; EXCEPTIONS],
            pending: [false; EXCEPTIONS],
            active: [false; EXCEPTIONS],
            priority: [0; EXCEPTIONS],
            any_pending: false,
            vtor: 0,
            prigroup: 0,
            scr: 0,
            // STKALIGN resets to 1 on the Cortex-M4 (PM0214 §4.4.8).
            ccr: 0x200,
            shcsr: 0,
            cfsr: 0,
            hfsr: 0,
            cpacr: 0,
            // ASPEN and LSPEN reset to 1 (PM0214 §4.6.2).
            fpccr: 0xC000_0000,
            fpcar: 0,
            fpdscr: 0,
            reset_requested: false,
            systick_csr: 0,
            systick_rvr: 0,
            systick_reload_at: 0,
            systick_loaded: 0,
            systick_countflag: false,
            units_per_cycle,
            demcr: 0,
            dwt_ctrl: 0x4000_0000,
            cyccnt_base: 0,
            cyccnt_at: 0,
            fpu_enabled_at: None,
        };
        // Reset, NMI and HardFault have fixed priorities −3, −2, −1 (kept out of `priority`).
        for e in [1, 2, HARD_FAULT] {
            s.enabled[e] = true;
        }
        s
    }

    /// The processor clock changed (HSI → PLL): SysTick and CYCCNT keep counting cycles.
    pub fn set_units_per_cycle(&mut self, now: Time, units: u64) {
        if units == self.units_per_cycle {
            return;
        }
        let cvr = self.systick_cvr(now);
        let cyc = self.cyccnt(now);
        self.units_per_cycle = units;
        self.systick_loaded = cvr;
        self.systick_reload_at = now;
        self.cyccnt_base = cyc;
        self.cyccnt_at = now;
    }

    // ---- priorities and pending state -------------------------------------------------

    /// The priority of an exception for preemption: fixed for reset/NMI/HardFault, else the
    /// group priority of its byte (PRIGROUP splits group and subpriority).
    pub fn group_priority(&self, exc: usize) -> i32 {
        match exc {
            1 => -3,
            2 => -2,
            HARD_FAULT => -1,
            _ => {
                let p = self.priority.get(exc).copied().unwrap_or(0) & 0xF0;
                let group_mask = (0xFFu32 << (self.prigroup + 1)) & 0xFF;
                (u32::from(p) & group_mask) as i32
            }
        }
    }

    fn full_priority(&self, exc: usize) -> i32 {
        match exc {
            1..=3 => self.group_priority(exc),
            _ => i32::from(self.priority.get(exc).copied().unwrap_or(0) & 0xF0),
        }
    }

    /// The execution priority: the highest (numerically lowest) group priority of the active
    /// exceptions, lowered further by BASEPRI and PRIMASK (ARMv7-M B1.5.4).
    pub fn execution_priority(&self, basepri: u32, primask: bool) -> i32 {
        let mut p = THREAD_PRIORITY;
        for (exc, &a) in self.active.iter().enumerate() {
            if a {
                p = p.min(self.group_priority(exc));
            }
        }
        let basepri = (basepri & 0xF0) as i32;
        if basepri != 0 {
            let group_mask = ((0xFFu32 << (self.prigroup + 1)) & 0xFF) as i32;
            p = p.min(basepri & group_mask);
        }
        if primask {
            p = p.min(0);
        }
        p
    }

    /// The pending, enabled exception that would be taken next, with its group priority:
    /// lowest group priority, then lowest subpriority, then lowest number.
    pub fn highest_pending(&self) -> Option<(usize, i32)> {
        if !self.any_pending {
            return None;
        }
        let mut best: Option<(usize, i32, i32)> = None;
        for exc in 1..EXCEPTIONS {
            if !self.pending[exc] || !self.is_enabled(exc) {
                continue;
            }
            let g = self.group_priority(exc);
            let f = self.full_priority(exc);
            if best.is_none_or(|(_, bg, bf)| (g, f) < (bg, bf)) {
                best = Some((exc, g, f));
            }
        }
        best.map(|(e, g, _)| (e, g))
    }

    /// Whether an exception can be taken now (it preempts the current execution priority).
    pub fn takeable(&self, basepri: u32, primask: bool) -> Option<usize> {
        let (exc, prio) = self.highest_pending()?;
        (prio < self.execution_priority(basepri, primask)).then_some(exc)
    }

    /// Whether WFI would wake: a pending exception that would preempt if PRIMASK were clear.
    pub fn would_wake(&self, basepri: u32) -> bool {
        self.takeable(basepri, false).is_some()
    }

    fn is_enabled(&self, exc: usize) -> bool {
        match exc {
            // System handlers other than the configurable faults are always enabled.
            1..=3 | SVCALL | 12 | PENDSV | SYSTICK => true,
            4 => self.shcsr & (1 << 16) != 0,
            BUS_FAULT => self.shcsr & (1 << 17) != 0,
            USAGE_FAULT => self.shcsr & (1 << 18) != 0,
            e if e >= 16 => self.enabled[e],
            _ => false,
        }
    }

    pub fn any_pending(&self) -> bool {
        self.any_pending
    }

    pub fn set_pending(&mut self, exc: usize) {
        if let Some(p) = self.pending.get_mut(exc) {
            *p = true;
            self.any_pending = true;
        }
    }

    fn refresh_any_pending(&mut self) {
        self.any_pending = self.pending.iter().any(|&p| p);
    }

    /// A peripheral's interrupt line: pends the IRQ while it is high and not being served
    /// (a line still high when its handler returns pends it again, see `deactivate`).
    pub fn sample_line(&mut self, irq: u32, level: bool) {
        let exc = 16 + irq as usize;
        if level && !self.active.get(exc).copied().unwrap_or(true) {
            self.set_pending(exc);
        }
    }

    /// Exception entry: pending → active.
    pub fn activate(&mut self, exc: usize) {
        if let Some(p) = self.pending.get_mut(exc) {
            *p = false;
        }
        if let Some(a) = self.active.get_mut(exc) {
            *a = true;
        }
        self.refresh_any_pending();
    }

    /// Exception return: the exception is no longer active. Returns false if it was not.
    pub fn deactivate(&mut self, exc: usize) -> bool {
        match self.active.get_mut(exc) {
            Some(a) if *a => {
                *a = false;
                true
            }
            _ => false,
        }
    }

    pub fn is_active(&self, exc: usize) -> bool {
        self.active.get(exc).copied().unwrap_or(false)
    }

    /// Number of active exceptions (nesting depth).
    pub fn active_count(&self) -> usize {
        self.active.iter().filter(|&&a| a).count()
    }

    pub fn sleep_on_exit(&self) -> bool {
        self.scr & (1 << 1) != 0
    }

    // ---- SysTick -------------------------------------------------------------------------

    fn systick_running(&self) -> bool {
        self.systick_csr & 1 != 0
    }

    fn systick_period_units(&self) -> u64 {
        (u64::from(self.systick_rvr) + 1) * self.units_per_cycle
    }

    /// The counter at `now`: counts down from the loaded value to 0, then reloads RVR.
    fn systick_cvr(&self, now: Time) -> u32 {
        if !self.systick_running() {
            return self.systick_loaded;
        }
        let elapsed = (now.saturating_sub(self.systick_reload_at)) / self.units_per_cycle;
        let loaded = u64::from(self.systick_loaded);
        if elapsed <= loaded {
            return (loaded - elapsed) as u32;
        }
        let period = u64::from(self.systick_rvr) + 1;
        let after = (elapsed - loaded - 1) % period;
        (u64::from(self.systick_rvr) - after) as u32
    }

    /// Next time the counter reaches 0 (its interrupt, with TICKINT).
    fn systick_next_zero(&self, now: Time) -> Option<Time> {
        if !self.systick_running() || self.systick_rvr == 0 {
            return None;
        }
        let first = self.systick_reload_at + u64::from(self.systick_loaded) * self.units_per_cycle;
        if first > now {
            return Some(first);
        }
        let period = self.systick_period_units();
        let k = (now - first) / period + 1;
        Some(first + k * period)
    }

    /// The next time this block changes state by itself (SysTick reaching 0).
    pub fn next_event(&self, now: Time) -> Option<Time> {
        self.systick_next_zero(now.saturating_sub(1))
    }

    /// Brings SysTick up to `now`: a wrap to 0 sets COUNTFLAG and, with TICKINT, pends SysTick.
    pub fn advance(&mut self, now: Time) {
        if !self.systick_running() || self.systick_rvr == 0 {
            return;
        }
        let first = self.systick_reload_at + u64::from(self.systick_loaded) * self.units_per_cycle;
        if now < first {
            return;
        }
        // One or more zeros reached since the last reload: re-base on the latest one.
        let period = self.systick_period_units();
        let k = (now - first) / period;
        let last_zero = first + k * period;
        self.systick_countflag = true;
        if self.systick_csr & 2 != 0 {
            self.set_pending(SYSTICK);
        }
        // The counter reloads RVR one cycle after reaching 0.
        self.systick_reload_at = last_zero + self.units_per_cycle;
        self.systick_loaded = self.systick_rvr;
    }

    // ---- DWT -----------------------------------------------------------------------------

    /// Whether CYCCNT counts (TRCENA and CYCCNTENA set).
    pub fn cyccnt_running(&self) -> bool {
        self.cyccnt_counting()
    }

    fn cyccnt_counting(&self) -> bool {
        self.demcr & (1 << 24) != 0 && self.dwt_ctrl & 1 != 0
    }

    pub fn cyccnt(&self, now: Time) -> u32 {
        if self.cyccnt_counting() {
            let cycles = now.saturating_sub(self.cyccnt_at) / self.units_per_cycle;
            self.cyccnt_base.wrapping_add(cycles as u32)
        } else {
            self.cyccnt_base
        }
    }

    fn rebase_cyccnt(&mut self, now: Time) {
        self.cyccnt_base = self.cyccnt(now);
        self.cyccnt_at = now;
    }

    pub fn dwt_read(&mut self, offset: u32, now: Time) -> Result<u32, Unmodelled> {
        match offset {
            DWT_CTRL => Ok(self.dwt_ctrl),
            DWT_CYCCNT => Ok(self.cyccnt(now)),
            _ => Err(Unmodelled::offset("DWT", offset, false)),
        }
    }

    pub fn dwt_write(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        match offset {
            DWT_CTRL => {
                // Only CYCCNTENA is modelled; the read-only NUMCOMP/NOxxx fields are ignored.
                Unmodelled::check_bits("DWT.CTRL", value & 0x0FFF_FFFF, 1)?;
                self.rebase_cyccnt(now);
                self.dwt_ctrl = (self.dwt_ctrl & 0xF000_0000) | (value & 1);
                Ok(())
            }
            DWT_CYCCNT => {
                self.cyccnt_base = value;
                self.cyccnt_at = now;
                Ok(())
            }
            _ => Err(Unmodelled::offset("DWT", offset, true)),
        }
    }

    // ---- register access ---------------------------------------------------------------

    /// A 32-bit read at `offset` from 0xE000_E000.
    pub fn read(&mut self, offset: u32, now: Time, current_exception: usize) -> Result<u32, Unmodelled> {
        self.advance(now);
        let bank = (offset & 0x1F) / 4;
        match offset {
            // INTLINESNUM = 2: 65 to 96 interrupt lines, for the F401's 85.
            ICTR => Ok(2),
            SYST_CSR => {
                let flag = self.systick_countflag;
                // COUNTFLAG clears on read.
                self.systick_countflag = false;
                Ok(self.systick_csr | (u32::from(flag) << 16))
            }
            SYST_RVR => Ok(self.systick_rvr),
            SYST_CVR => Ok(self.systick_cvr(now)),
            // No reference clock, 10 ms not exact (TENMS = 0).
            SYST_CALIB => Ok(0xC000_0000),
            // ISER/ICER read the enable state, ISPR/ICPR the pending state.
            NVIC_ISER..=NVIC_ISER_END | NVIC_ICER..=NVIC_ICER_END => Ok(self.bits32(&self.enabled, bank)),
            NVIC_ISPR..=NVIC_ISPR_END | NVIC_ICPR..=NVIC_ICPR_END => Ok(self.bits32(&self.pending, bank)),
            NVIC_IABR..=NVIC_IABR_END => Ok(self.bits32(&self.active, bank)),
            NVIC_IPR..=NVIC_IPR_END => Ok(self.priority_word(16 + (offset - NVIC_IPR) as usize)),
            CPUID => Ok(CPUID_VALUE),
            ICSR => Ok(self.icsr(current_exception)),
            VTOR => Ok(self.vtor),
            AIRCR => Ok(0xFA05_0000 | (self.prigroup << 8)),
            SCR => Ok(self.scr),
            CCR => Ok(self.ccr),
            SHPR1 | SHPR2 | SHPR3 => Ok(self.priority_word(4 + (offset - SHPR1) as usize)),
            SHCSR => Ok(self.shcsr),
            CFSR => Ok(self.cfsr),
            HFSR => Ok(self.hfsr),
            CPACR => Ok(self.cpacr),
            DEMCR => Ok(self.demcr),
            FPCCR => Ok(self.fpccr),
            FPCAR => Ok(self.fpcar),
            FPDSCR => Ok(self.fpdscr),
            _ => Err(Unmodelled::offset("SCS", offset, false)),
        }
    }

    /// A 32-bit write at `offset` from 0xE000_E000.
    pub fn write(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.advance(now);
        match offset {
            SYST_CSR | SYST_RVR | SYST_CVR => self.write_systick(offset, value, now),
            NVIC_ISER..=NVIC_ISER_END
            | NVIC_ICER..=NVIC_ICER_END
            | NVIC_ISPR..=NVIC_ISPR_END
            | NVIC_ICPR..=NVIC_ICPR_END
            | NVIC_IPR..=NVIC_IPR_END
            | STIR => {
                self.write_nvic(offset, value);
                Ok(())
            }
            ICSR | VTOR | AIRCR | SCR | CCR | SHPR1 | SHPR2 | SHPR3 | SHCSR | CFSR | HFSR | CPACR => self.write_scb(offset, value, now),
            DEMCR => {
                // TRCENA (bit 24) gates the DWT; the vector-catch and monitor bits need a debugger.
                Unmodelled::check_bits("DCB.DEMCR", value, 1 << 24)?;
                self.rebase_cyccnt(now);
                self.demcr = value;
                Ok(())
            }
            FPCCR => {
                Unmodelled::check_bits("FPU.FPCCR", value, 0xC000_0000)?;
                if value & 0xC000_0000 != 0xC000_0000 {
                    return Err(Unmodelled::new("FPU.FPCCR", "turning automatic/lazy FP state preservation off is not modelled"));
                }
                self.fpccr = value;
                Ok(())
            }
            FPDSCR => {
                self.fpdscr = value & 0x07C0_0000;
                Ok(())
            }
            _ => Err(Unmodelled::offset("SCS", offset, true)),
        }
    }

    /// SysTick's CSR, RVR and CVR.
    fn write_systick(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        match offset {
            SYST_CSR => {
                // ENABLE, TICKINT, CLKSOURCE. The external reference (CLKSOURCE = 0, HCLK/8 on
                // the STM32F4) is not modelled.
                Unmodelled::check_bits("SysTick.CSR", value, 0x7)?;
                if value & 1 != 0 && value & 4 == 0 {
                    return Err(Unmodelled::new("SysTick.CSR", "CLKSOURCE = 0 (HCLK/8 reference clock) is not modelled"));
                }
                let was_running = self.systick_running();
                let cvr = self.systick_cvr(now);
                self.systick_csr = value & 0x7;
                if !was_running && self.systick_running() {
                    // Counting starts from the current value (0 after a CVR write: reload first).
                    if cvr == 0 {
                        self.systick_loaded = self.systick_rvr;
                        self.systick_reload_at = now + self.units_per_cycle;
                    } else {
                        self.systick_loaded = cvr;
                        self.systick_reload_at = now;
                    }
                } else if was_running && !self.systick_running() {
                    self.systick_loaded = cvr;
                }
                Ok(())
            }
            SYST_RVR => {
                Unmodelled::check_bits("SysTick.RVR", value, 0x00FF_FFFF)?;
                self.systick_rvr = value;
                Ok(())
            }
            SYST_CVR => {
                // Any write clears the counter and COUNTFLAG; it reloads on the next cycle.
                self.systick_countflag = false;
                self.systick_loaded = 0;
                self.systick_reload_at = now;
                if self.systick_running() {
                    self.systick_loaded = self.systick_rvr;
                    self.systick_reload_at = now + self.units_per_cycle;
                }
                Ok(())
            }
            _ => Err(Unmodelled::offset("SCS", offset, true)),
        }
    }

    /// The NVIC's enable, pending and priority registers, and the software trigger.
    fn write_nvic(&mut self, offset: u32, value: u32) {
        let bank = (offset & 0x1F) / 4;
        match offset {
            NVIC_ISER..=NVIC_ISER_END => self.set_bits32(EnableOp::Enable, bank, value),
            NVIC_ICER..=NVIC_ICER_END => self.set_bits32(EnableOp::Disable, bank, value),
            NVIC_ISPR..=NVIC_ISPR_END => self.set_bits32(EnableOp::Pend, bank, value),
            NVIC_ICPR..=NVIC_ICPR_END => self.set_bits32(EnableOp::Unpend, bank, value),
            NVIC_IPR..=NVIC_IPR_END => self.set_priority_word(16 + (offset - NVIC_IPR) as usize, value),
            // STIR: software trigger of an external interrupt.
            _ => self.set_pending(16 + (value & 0x1FF) as usize),
        }
    }

    /// The system control block, CPACR included.
    fn write_scb(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        match offset {
            ICSR => self.write_icsr(value)?,
            VTOR => {
                // TBLOFF: bits 29:9 for 85 interrupts (the table is 101 words: 512-byte aligned).
                Unmodelled::check_bits("SCB.VTOR", value, 0x3FFF_FE00)?;
                self.vtor = value;
            }
            // Writes without VECTKEY are ignored (ARMv7-M B3.2.6).
            AIRCR if value >> 16 != 0x05FA => {}
            AIRCR => {
                Unmodelled::check_bits("SCB.AIRCR", value & 0xFFFF, 0x0704 | 0x4)?;
                self.prigroup = (value >> 8) & 7;
                if value & 4 != 0 {
                    self.reset_requested = true;
                }
            }
            SCR => {
                // SLEEPONEXIT modelled; SLEEPDEEP (stop mode) and SEVONPEND are not.
                Unmodelled::check_bits("SCB.SCR", value, 0x2)?;
                self.scr = value;
            }
            CCR => {
                // STKALIGN, DIV_0_TRP, UNALIGN_TRP stored (Unicorn does not trap either).
                Unmodelled::check_bits("SCB.CCR", value, 0x200 | 0x10 | 0x8)?;
                self.ccr = value;
            }
            SHPR1 | SHPR2 | SHPR3 => self.set_priority_word(4 + (offset - SHPR1) as usize, value),
            SHCSR => {
                Unmodelled::check_bits("SCB.SHCSR", value, 0x0007_0000)?;
                self.shcsr = value;
            }
            // Write one to clear.
            CFSR => self.cfsr &= !value,
            HFSR => self.hfsr &= !value,
            CPACR => {
                Unmodelled::check_bits("SCB.CPACR", value, 0x00F0_0000)?;
                self.cpacr = value;
                if value & 0x00F0_0000 == 0x00F0_0000 && self.fpu_enabled_at.is_none() {
                    self.fpu_enabled_at = Some(now);
                }
            }
            _ => return Err(Unmodelled::offset("SCS", offset, true)),
        }
        Ok(())
    }

    fn icsr(&self, current_exception: usize) -> u32 {
        let pending = self.highest_pending().map_or(0, |(e, _)| e as u32);
        let isr_pending = self.pending.iter().skip(16).any(|&p| p);
        let ret_to_base = self.active_count() <= 1;
        (u32::from(self.pending[2]) << 31)
            | (u32::from(self.pending[PENDSV]) << 28)
            | (u32::from(self.pending[SYSTICK]) << 26)
            | (u32::from(isr_pending) << 22)
            | ((pending & 0x1FF) << 12)
            | (u32::from(ret_to_base) << 11)
            | (current_exception as u32 & 0x1FF)
    }

    fn write_icsr(&mut self, value: u32) -> Result<(), Unmodelled> {
        Unmodelled::check_bits("SCB.ICSR", value, (1 << 31) | (1 << 28) | (1 << 27) | (1 << 26) | (1 << 25))?;
        if value & (1 << 31) != 0 {
            self.set_pending(2);
        }
        if value & (1 << 28) != 0 {
            self.set_pending(PENDSV);
        }
        if value & (1 << 27) != 0 {
            self.pending[PENDSV] = false;
        }
        if value & (1 << 26) != 0 {
            self.set_pending(SYSTICK);
        }
        if value & (1 << 25) != 0 {
            self.pending[SYSTICK] = false;
        }
        self.refresh_any_pending();
        Ok(())
    }

    fn bits32(&self, flags: &[bool; EXCEPTIONS], word: u32) -> u32 {
        (0..32).fold(0, |acc, bit| {
            let exc = 16 + (word * 32 + bit) as usize;
            acc | (u32::from(flags.get(exc).copied().unwrap_or(false)) << bit)
        })
    }

    fn set_bits32(&mut self, op: EnableOp, word: u32, value: u32) {
        for bit in 0..32 {
            if value & (1 << bit) == 0 {
                continue;
            }
            let exc = 16 + (word * 32 + bit) as usize;
            if exc >= EXCEPTIONS {
                continue;
            }
            match op {
                EnableOp::Enable => self.enabled[exc] = true,
                EnableOp::Disable => self.enabled[exc] = false,
                EnableOp::Pend => self.pending[exc] = true,
                EnableOp::Unpend => self.pending[exc] = false,
            }
        }
        self.refresh_any_pending();
    }

    fn priority_word(&self, first: usize) -> u32 {
        (0..4).fold(0, |acc, i| acc | (u32::from(self.priority.get(first + i).copied().unwrap_or(0)) << (8 * i)))
    }

    fn set_priority_word(&mut self, first: usize, value: u32) {
        for i in 0..4 {
            if let Some(p) = self.priority.get_mut(first + i) {
                // Bits 3:0 are not implemented on the STM32F4 (read as zero).
                *p = ((value >> (8 * i)) & 0xF0) as u8;
            }
        }
    }

    /// Byte lanes: priority registers may be written a byte at a time (RTIC does).
    pub fn write_byte(&mut self, offset: u32, value: u8, now: Time) -> Result<(), Unmodelled> {
        match offset {
            NVIC_IPR..=0x4EF => {
                if let Some(p) = self.priority.get_mut(16 + (offset - NVIC_IPR) as usize) {
                    *p = value & 0xF0;
                }
                Ok(())
            }
            SHPR1..=0xD23 => {
                if let Some(p) = self.priority.get_mut(4 + (offset - SHPR1) as usize) {
                    *p = value & 0xF0;
                }
                Ok(())
            }
            _ => {
                // Other registers: read-modify-write of the word.
                let aligned = offset & !3;
                let shift = 8 * (offset & 3);
                let old = self.read(aligned, now, 0)?;
                let word = (old & !(0xFF << shift)) | (u32::from(value) << shift);
                self.write(aligned, word, now)
            }
        }
    }

    /// A fault escalated to HardFault (BusFault/UsageFault not enabled, or a fault in a
    /// handler that cannot preempt): HFSR.FORCED and the configurable fault status bits.
    pub fn record_forced_fault(&mut self, cfsr_bits: u32) {
        self.cfsr |= cfsr_bits;
        self.hfsr |= 1 << 30;
    }
}

#[derive(Clone, Copy)]
enum EnableOp {
    Enable,
    Disable,
    Pend,
    Unpend,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_higher_priority_irq_preempts_and_basepri_masks_it() {
        let mut s = Scs::new(4);
        s.write(NVIC_ISER, 1 << 28, 0).unwrap(); // enable TIM2 (IRQ 28)
        s.write_byte(NVIC_IPR + 28, 0x10, 0).unwrap();
        s.sample_line(28, true);
        assert_eq!(s.takeable(0, false), Some(16 + 28));
        assert_eq!(s.takeable(0x10, false), None, "BASEPRI at the same priority masks it");
        assert_eq!(s.takeable(0, true), None, "PRIMASK masks it");
        s.activate(16 + 28);
        assert_eq!(s.execution_priority(0, false), 0x10);
    }

    #[test]
    fn systick_pends_every_reload_period() {
        let mut s = Scs::new(4);
        s.write(SYST_RVR, 999, 0).unwrap();
        s.write(SYST_CVR, 0, 0).unwrap();
        s.write(SYST_CSR, 7, 0).unwrap();
        let first = s.next_event(0).unwrap();
        assert_eq!(first, 1000 * 4, "RVR loads on the first cycle after enabling, then counts 999 down to 0");
        s.advance(first);
        assert!(s.any_pending());
        assert_eq!(s.next_event(first + 1).unwrap(), first + 4000);
    }

    #[test]
    fn cyccnt_counts_cycles_only_with_trcena_and_cyccntena() {
        let mut s = Scs::new(4);
        s.dwt_write(DWT_CTRL, 1, 0).unwrap();
        assert_eq!(s.cyccnt(400), 0);
        s.write(DEMCR, 1 << 24, 400).unwrap();
        assert_eq!(s.cyccnt(800), 100);
    }
}
