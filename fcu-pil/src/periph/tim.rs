//! General-purpose timers: TIM2 (32-bit, 4 channels, 0x4000_0000, APB1), TIM4 (16-bit,
//! 4 channels, 0x4000_0800, APB1) and TIM9 (16-bit, 2 channels, reduced register set,
//! 0x4001_4000, APB2), upcounting only.
//!
//! Facts from RM0368 §13 (TIM2..TIM5) and §14 (TIM9..TIM11) and the `stm32f4` PAC (`tim2`, `tim3`
//! which TIM4 uses, `tim9`): register offsets, fields, reset values (all 0, ARR included),
//! access types (SR rc_w0, EGR write-only).
//!
//! Counter: counts up at timer_clock / (PSC + 1); when it reaches ARR the next count wraps it to 0
//! with an update event (UEV) unless UDIS: UEV loads the shadow registers (PSC always, ARR when
//! ARPE, CCRx of output channels with OCxPE) and sets UIF. If CNT > ARR (written so), it counts
//! on to its maximum and wraps there. OPM clears CEN at the update. EGR.UG reinitialises counter
//! and prescaler and generates a UEV (unless UDIS), setting UIF only if URS = 0 (RM: "URS = 1:
//! only counter overflow generates an update interrupt").
//!
//! Time is computed in closed form from the last "anchor" (the counter and prescaler values at
//! a known time), so update events do not need an `advance` each: a read brings the state up to
//! date arithmetically, with at most a couple of steps when preloaded values are pending.
//!
//! Channel numbers in this API are 0-based: channel 0 is CH1 (pin TI1), channel 3 is CH4.

use super::{Clocks, Peripheral, Time, Unmodelled, TIME_HZ};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimerKind {
    Tim2,
    Tim4,
    Tim9,
}

impl TimerKind {
    pub const fn name(self) -> &'static str {
        match self {
            TimerKind::Tim2 => "TIM2",
            TimerKind::Tim4 => "TIM4",
            TimerKind::Tim9 => "TIM9",
        }
    }

    pub const fn base(self) -> u32 {
        match self {
            TimerKind::Tim2 => 0x4000_0000,
            TimerKind::Tim4 => 0x4000_0800,
            TimerKind::Tim9 => 0x4001_4000,
        }
    }

    /// NVIC line (RM0368 table 38).
    pub const fn irq(self) -> u32 {
        match self {
            TimerKind::Tim2 => super::irq::TIM2,
            TimerKind::Tim4 => super::irq::TIM4,
            TimerKind::Tim9 => super::irq::TIM1_BRK_TIM9,
        }
    }

    pub const fn channels(self) -> usize {
        match self {
            TimerKind::Tim9 => 2,
            _ => 4,
        }
    }

    /// CNT/ARR/CCR width: TIM2 is 32-bit, the others 16-bit.
    pub const fn counter_mask(self) -> u32 {
        match self {
            TimerKind::Tim2 => 0xFFFF_FFFF,
            _ => 0xFFFF,
        }
    }

    /// The timer kernel clock: APB1 timer clock for TIM2/TIM4, APB2 for TIM9.
    pub const fn kernel_hz(self, clocks: &Clocks) -> u64 {
        match self {
            TimerKind::Tim9 => clocks.tim_apb2_hz,
            _ => clocks.tim_apb1_hz,
        }
    }

    /// TIM2..5 register set (CR2, CCMR2, DCR, DMAR…) rather than TIM9's reduced one.
    const fn full(self) -> bool {
        !matches!(self, TimerKind::Tim9)
    }
}

pub const CR1: u32 = 0x00;
pub const CR2: u32 = 0x04;
pub const SMCR: u32 = 0x08;
pub const DIER: u32 = 0x0C;
pub const SR: u32 = 0x10;
pub const EGR: u32 = 0x14;
pub const CCMR1: u32 = 0x18;
pub const CCMR2: u32 = 0x1C;
pub const CCER: u32 = 0x20;
pub const CNT: u32 = 0x24;
pub const PSC: u32 = 0x28;
pub const ARR: u32 = 0x2C;
pub const CCR1: u32 = 0x34;
pub const DCR: u32 = 0x48;
pub const DMAR: u32 = 0x4C;
/// TIM2_OR (ITR1_RMP), TIM2 only.
pub const OR: u32 = 0x50;

pub const CR1_CEN: u32 = 1 << 0;
pub const CR1_UDIS: u32 = 1 << 1;
pub const CR1_URS: u32 = 1 << 2;
pub const CR1_OPM: u32 = 1 << 3;
pub const CR1_DIR: u32 = 1 << 4;
pub const CR1_CMS: u32 = 0b11 << 5;
pub const CR1_ARPE: u32 = 1 << 7;
pub const CR1_CKD: u32 = 0b11 << 8;

pub const SR_UIF: u32 = 1 << 0;
pub const SR_TIF: u32 = 1 << 6;
pub const EGR_UG: u32 = 1 << 0;
pub const EGR_TG: u32 = 1 << 6;
pub const DIER_UIE: u32 = 1 << 0;
pub const DIER_TIE: u32 = 1 << 6;

/// CCxIF in SR (and CCxIE in DIER, CCxG in EGR) for 0-based channel `c`.
pub const fn sr_ccif(c: usize) -> u32 {
    1 << (c + 1)
}

/// CCxOF in SR for 0-based channel `c`.
pub const fn sr_ccof(c: usize) -> u32 {
    1 << (c + 9)
}

/// OCxM values (CCMRx output mode).
const OCM_FROZEN: u32 = 0b000;
const OCM_PWM1: u32 = 0b110;
const OCM_PWM2: u32 = 0b111;

/// One general-purpose timer.
#[derive(Clone, Debug)]
pub struct Timer {
    kind: TimerKind,
    cr1: u32,
    cr2: u32,
    smcr: u32,
    dier: u32,
    sr: u32,
    ccmr: [u32; 2],
    ccer: u32,
    /// PSC register (preload) and the active prescaler.
    psc: u32,
    psc_active: u32,
    /// ARR register (preload) and the active auto-reload.
    arr: u32,
    arr_active: u32,
    /// CCRx registers (the preload in output mode, the captured value in input mode).
    ccr: [u32; 4],
    /// The compare values in use (output mode).
    ccr_active: [u32; 4],
    /// Counter and prescaler counter at `anchor`.
    cnt: u32,
    psc_cnt: u64,
    anchor: Time,
    units_per_tick: u64,
    started_at: Option<Time>,
    last_update: Option<Time>,
    updates: u64,
    /// Captures latched per channel (for the board's records).
    captures: [u64; 4],
}

impl Timer {
    /// Reset state (all registers 0, PAC reset values), kernel clock of [`Clocks::RESET`].
    pub fn new(kind: TimerKind) -> Self {
        Timer {
            kind,
            cr1: 0,
            cr2: 0,
            smcr: 0,
            dier: 0,
            sr: 0,
            ccmr: [0; 2],
            ccer: 0,
            psc: 0,
            psc_active: 0,
            arr: 0,
            arr_active: 0,
            ccr: [0; 4],
            ccr_active: [0; 4],
            cnt: 0,
            psc_cnt: 0,
            anchor: 0,
            units_per_tick: Self::upt(kind, &Clocks::RESET),
            started_at: None,
            last_update: None,
            updates: 0,
            captures: [0; 4],
        }
    }

    pub fn kind(&self) -> TimerKind {
        self.kind
    }

    /// Time units per kernel-clock tick (rounded when the clock does not divide [`TIME_HZ`]; the
    /// board's clocks all do).
    fn upt(kind: TimerKind, clocks: &Clocks) -> u64 {
        let hz = kind.kernel_hz(clocks);
        if hz == 0 {
            return u64::MAX; // no clock: never ticks
        }
        ((TIME_HZ + hz / 2) / hz).max(1)
    }

    /// The kernel clock is the one `clocks` gives this timer (APB1 or APB2 timer clock).
    pub fn set_clocks(&mut self, clocks: Clocks, now: Time) {
        self.set_clock_units(now, Self::upt(self.kind, &clocks));
    }

    /// The kernel clock is `units_per_tick` time units per cycle from `now` on (RCC
    /// reprogrammed): the count so far is kept, later ticks use the new rate. Cheap when
    /// unchanged, so the bus may call it with every access.
    pub fn set_clock_units(&mut self, now: Time, units_per_tick: u64) {
        let units_per_tick = units_per_tick.max(1);
        if units_per_tick == self.units_per_tick {
            return;
        }
        self.sync(now);
        if self.running() {
            self.anchor = self.anchor.max(now);
        }
        self.units_per_tick = units_per_tick;
    }

    fn name(&self) -> &'static str {
        self.kind.name()
    }

    fn reg(&self, r: &str) -> String {
        format!("{}.{}", self.name(), r)
    }

    fn running(&self) -> bool {
        self.cr1 & CR1_CEN != 0
    }

    fn mask(&self) -> u32 {
        self.kind.counter_mask()
    }

    /// CCxS of 0-based channel `c` (0 = output, 1/2 = input, 3 = TRC).
    fn ccs(&self, c: usize) -> u32 {
        (self.ccmr[c / 2] >> ((c % 2) * 8)) & 0b11
    }

    fn ccmr_byte(&self, c: usize) -> u32 {
        (self.ccmr[c / 2] >> ((c % 2) * 8)) & 0xFF
    }

    fn is_output(&self, c: usize) -> bool {
        self.ccs(c) == 0
    }

    fn oc_preload(&self, c: usize) -> bool {
        self.ccmr_byte(c) & (1 << 3) != 0
    }

    fn ocm(&self, c: usize) -> u32 {
        (self.ccmr_byte(c) >> 4) & 0b111
    }

    fn cc_enabled(&self, c: usize) -> bool {
        self.ccer & (1 << (4 * c)) != 0
    }

    /// (CCxP, CCxNP) of channel `c`.
    fn polarity(&self, c: usize) -> (bool, bool) {
        (self.ccer & (1 << (4 * c + 1)) != 0, self.ccer & (1 << (4 * c + 3)) != 0)
    }

    /// Counter steps from the anchor value to the next overflow.
    fn steps_to_update(&self) -> u64 {
        let top = if self.cnt <= self.arr_active { self.arr_active } else { self.mask() };
        u64::from(top - self.cnt) + 1
    }

    fn load_shadows(&mut self) {
        self.psc_active = self.psc;
        self.arr_active = self.arr;
        for c in 0..self.kind.channels() {
            if self.is_output(c) {
                self.ccr_active[c] = self.ccr[c];
            }
        }
    }

    /// No preload differs from its active value: periods are all alike from now on.
    fn settled(&self) -> bool {
        self.cr1 & CR1_UDIS != 0
            || (self.psc_active == self.psc
                && self.arr_active == self.arr
                && (0..self.kind.channels()).all(|c| !self.is_output(c) || self.ccr_active[c] == self.ccr[c]))
    }

    /// Counter overflow at `t` (the counter has just wrapped to 0).
    fn overflow(&mut self, t: Time) {
        if self.cr1 & CR1_UDIS == 0 {
            self.load_shadows();
            self.sr |= SR_UIF;
            self.last_update = Some(t);
            self.updates += 1;
        }
        if self.cr1 & CR1_OPM != 0 {
            self.cr1 &= !CR1_CEN;
        }
    }

    /// Output compare (RM0368 §13.3.8, §14.3.9): the counter reaching CCRx sets CCxIF,
    /// whatever OCxM says (frozen included). Counts from `from` (exclusive) to `to`
    /// (inclusive) within one period.
    fn note_compare_matches(&mut self, from: u32, to: u32) {
        for c in 0..self.kind.channels() {
            let ccr = self.ccr_active[c];
            if self.is_output(c) && ccr > from && ccr <= to {
                self.sr |= sr_ccif(c);
            }
        }
    }

    /// The counter wrapped to 0: a compare value of 0 matches there.
    fn note_compare_match_at_zero(&mut self) {
        for c in 0..self.kind.channels() {
            if self.is_output(c) && self.ccr_active[c] == 0 {
                self.sr |= sr_ccif(c);
            }
        }
    }

    /// The next compare match that can raise the interrupt line (CCxIE set, CCxIF clear, an
    /// output channel whose compare value the counter reaches).
    fn next_compare_event(&self) -> Option<Time> {
        let div = u64::from(self.psc_active) + 1;
        (0..self.kind.channels())
            .filter(|&c| self.is_output(c) && self.dier & sr_ccif(c) != 0 && self.sr & sr_ccif(c) == 0)
            .filter_map(|c| {
                let ccr = self.ccr_active[c];
                let to_update = self.steps_to_update();
                let steps = if ccr > self.cnt && u64::from(ccr - self.cnt) < to_update {
                    u64::from(ccr - self.cnt)
                } else if ccr <= self.arr_active {
                    to_update + u64::from(ccr)
                } else {
                    return None;
                };
                Some(self.anchor.saturating_add((steps * div - self.psc_cnt).saturating_mul(self.units_per_tick)))
            })
            .min()
    }

    /// Bring counter, prescaler counter and flags up to `now`.
    fn sync(&mut self, now: Time) {
        if !self.running() || now <= self.anchor {
            return;
        }
        let upt = self.units_per_tick;
        let mut ticks = (now - self.anchor) / upt;
        loop {
            let div = u64::from(self.psc_active) + 1;
            let to_update = self.steps_to_update();
            let total = self.psc_cnt + ticks;
            let steps = total / div;
            if steps < to_update {
                // steps < to_update ≤ mask − cnt + 1: no overflow of the counter field.
                self.note_compare_matches(self.cnt, self.cnt + steps as u32);
                self.cnt += steps as u32;
                self.psc_cnt = total % div;
                self.anchor += ticks * upt;
                return;
            }
            let used = to_update * div - self.psc_cnt;
            ticks -= used;
            self.anchor += used * upt;
            let top = self.cnt.wrapping_add((to_update - 1) as u32);
            self.note_compare_matches(self.cnt, top);
            self.cnt = 0;
            self.psc_cnt = 0;
            self.overflow(self.anchor);
            self.note_compare_match_at_zero();
            if !self.running() {
                return; // one-pulse mode stopped it
            }
            if self.settled() {
                let period = (u64::from(self.arr_active) + 1) * (u64::from(self.psc_active) + 1);
                let n = ticks / period;
                if n > 0 {
                    ticks -= n * period;
                    self.anchor += n * period * upt;
                    // Whole periods: every compare value the counter reaches matched.
                    self.note_compare_matches(0, self.arr_active);
                    self.note_compare_match_at_zero();
                    if self.cr1 & CR1_UDIS == 0 {
                        self.sr |= SR_UIF;
                        self.last_update = Some(self.anchor);
                        self.updates += n;
                    }
                }
            }
        }
    }

    /// Bring the timer up to `now`.
    pub fn advance(&mut self, now: Time) {
        self.sync(now);
    }

    /// The next update event or compare match that can raise the interrupt line (UIE set,
    /// UIF clear, counting, UDIS clear; or CCxIE set and CCxIF clear). Computed from the last
    /// synchronised state.
    pub fn next_event(&self) -> Option<Time> {
        if !self.running() {
            return None;
        }
        let update = if self.dier & DIER_UIE == 0 || self.sr & SR_UIF != 0 || self.cr1 & CR1_UDIS != 0 {
            None
        } else {
            let div = u64::from(self.psc_active) + 1;
            let ticks = self.steps_to_update() * div - self.psc_cnt;
            Some(self.anchor.saturating_add(ticks.saturating_mul(self.units_per_tick)))
        };
        [update, self.next_compare_event()].into_iter().flatten().min()
    }

    /// Level of the interrupt line: SR flags (UIF, CCxIF, TIF) AND their DIER enables.
    pub fn irq_line(&self) -> bool {
        let mut flags = SR_UIF | SR_TIF;
        for c in 0..self.kind.channels() {
            flags |= sr_ccif(c);
        }
        self.sr & self.dier & flags != 0
    }

    /// When CEN was last set.
    pub fn started_at(&self) -> Option<Time> {
        self.started_at
    }

    /// The last update event (overflow or UG) that set or would set UIF.
    pub fn last_update(&self) -> Option<Time> {
        self.last_update
    }

    /// Update events since reset (with UDIS clear).
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// The counter at `now`.
    pub fn counter(&mut self, now: Time) -> u32 {
        self.sync(now);
        self.cnt
    }

    /// Counts per period (active ARR + 1), as of the last synchronisation.
    pub fn period_counts(&self) -> u32 {
        self.arr_active.saturating_add(1)
    }

    /// The active compare value of 0-based `channel` at `now` (with OCxPE, the preload moved in
    /// at the last update event). 0 for a channel this timer does not have.
    pub fn pwm_compare(&mut self, channel: usize, now: Time) -> u32 {
        self.sync(now);
        if channel < self.kind.channels() {
            self.ccr_active[channel]
        } else {
            0
        }
    }

    /// Fraction of the time the channel's output pin is high at `now`, in 0..=1:
    /// PWM mode 1 (OCxREF active while CNT < CCRx) gives min(CCRx, ARR+1)/(ARR+1), PWM mode 2 the
    /// complement, CCxP = 1 inverts; a stopped counter gives the static level. 0 when the channel
    /// is an input, does not exist, or its output is disabled (CCxE = 0). Frozen mode keeps
    /// OCxREF at its reset level (inactive).
    pub fn duty(&mut self, channel: usize, now: Time) -> f64 {
        self.sync(now);
        if channel >= self.kind.channels() || !self.is_output(channel) || !self.cc_enabled(channel) {
            return 0.0;
        }
        let ccr = self.ccr_active[channel];
        let pwm1 = if self.running() {
            let period = f64::from(self.arr_active) + 1.0;
            (f64::from(ccr) / period).clamp(0.0, 1.0)
        } else if self.cnt < ccr {
            1.0
        } else {
            0.0
        };
        let reference = match self.ocm(channel) {
            OCM_PWM1 => pwm1,
            OCM_PWM2 => 1.0 - pwm1,
            _ => 0.0,
        };
        if self.polarity(channel).0 {
            1.0 - reference
        } else {
            reference
        }
    }

    /// The input pin of 0-based `channel` (TIx) changed at `now`. Every capture channel mapped on
    /// it (CCxS = 01: its own pin; CCxS = 10: the neighbour's, TI2 for IC1 etc.) with CCxE set and
    /// a matching polarity (CCxNP/CCxP = 00 rising, 01 falling, 11 both) latches the counter into
    /// CCRx and sets CCxIF (CCxOF too if CCxIF was still set).
    pub fn capture(&mut self, channel: usize, rising: bool, now: Time) {
        if channel >= self.kind.channels() {
            return;
        }
        let value = self.counter_at(now);
        for c in 0..self.kind.channels() {
            let source = match self.ccs(c) {
                1 => c,
                2 => c ^ 1,
                _ => continue,
            };
            if source != channel || !self.cc_enabled(c) {
                continue;
            }
            let matches = match self.polarity(c) {
                (false, false) => rising,
                (true, false) => !rising,
                (true, true) => true,
                (false, true) => false, // reserved, refused at CCER write
            };
            if matches {
                self.capture_value(c, value);
            }
        }
    }

    fn capture_now(&mut self, c: usize) {
        self.capture_value(c, self.cnt);
    }

    fn capture_value(&mut self, c: usize, value: u32) {
        if self.sr & sr_ccif(c) != 0 {
            self.sr |= sr_ccof(c);
        }
        self.sr |= sr_ccif(c);
        self.ccr[c] = value;
        self.captures[c] += 1;
    }

    /// Captures latched into CCRx of 0-based `channel` since reset.
    pub fn captures(&self, channel: usize) -> u64 {
        self.captures.get(channel).copied().unwrap_or(0)
    }

    /// The counter at `t`, which may lie before the last synchronisation (an edge delivered
    /// late): counted back within the current period arithmetic (exact while the period is
    /// uniform, i.e. no preload pending and the counter within ARR).
    fn counter_at(&mut self, t: Time) -> u32 {
        if t >= self.anchor || !self.running() {
            self.sync(t);
            return self.cnt;
        }
        let div = u64::from(self.psc_active) + 1;
        let period = (u64::from(self.arr_active) + 1) * div;
        if self.cnt > self.arr_active {
            return self.cnt;
        }
        let back = (self.anchor - t).div_ceil(self.units_per_tick) % period;
        let pos = u64::from(self.cnt) * div + self.psc_cnt;
        let at = (pos + period - back) % period;
        (at / div) as u32
    }

    fn ccr_offset(&self, offset: u32) -> Option<usize> {
        let c = offset.checked_sub(CCR1)? / 4;
        (offset % 4 == 0 && (c as usize) < self.kind.channels()).then_some(c as usize)
    }

    pub fn read(&mut self, offset: u32, now: Time) -> Result<u32, Unmodelled> {
        self.sync(now);
        let full = self.kind.full();
        Ok(match offset {
            CR1 => self.cr1,
            CR2 if full => self.cr2,
            SMCR => self.smcr,
            DIER => self.dier,
            SR => self.sr,
            EGR => 0, // write-only
            CCMR1 => self.ccmr[0],
            CCMR2 if full => self.ccmr[1],
            CCER => self.ccer,
            CNT => self.cnt,
            PSC => self.psc,
            ARR => self.arr,
            DCR if full => 0,
            OR if self.kind == TimerKind::Tim2 => 0,
            _ => match self.ccr_offset(offset) {
                Some(c) => {
                    if !self.is_output(c) {
                        // Input capture: reading CCRx clears CCxIF.
                        self.sr &= !sr_ccif(c);
                    }
                    self.ccr[c]
                }
                None => return Err(Unmodelled::offset(self.name(), offset, false)),
            },
        })
    }

    pub fn write(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.sync(now);
        let full = self.kind.full();
        let channels = self.kind.channels();
        let ch_bits = |per: fn(usize) -> u32| (0..channels).fold(0, |m, c| m | per(c));
        match offset {
            CR1 => self.write_cr1(value, now),
            CR2 if full => {
                // MMS (TRGO) and CCDS (DMA) are stored: nothing listens to them here. TI1S is refused.
                Unmodelled::check_bits(&self.reg("CR2"), value, (1 << 3) | (0b111 << 4))?;
                self.cr2 = value;
                Ok(())
            }
            SMCR => {
                // Slave mode off only: SMS and ECE must stay 0; the trigger fields are then unused.
                let stored = if full { (0b111 << 4) | (1 << 7) | (0xF << 8) | (0b11 << 12) | (1 << 15) } else { (0b111 << 4) | (1 << 7) };
                Unmodelled::check_bits(&self.reg("SMCR"), value, stored)?;
                self.smcr = value;
                Ok(())
            }
            DIER => {
                Unmodelled::check_bits(&self.reg("DIER"), value, DIER_UIE | DIER_TIE | ch_bits(sr_ccif))?;
                self.dier = value;
                Ok(())
            }
            SR => {
                // rc_w0: writing 0 clears a flag, writing 1 leaves it.
                let flags = SR_UIF | SR_TIF | ch_bits(sr_ccif) | ch_bits(sr_ccof);
                self.sr &= value | !flags;
                Ok(())
            }
            EGR => self.write_egr(value, now),
            CCMR1 => self.write_ccmr(0, value),
            CCMR2 if full => self.write_ccmr(1, value),
            CCER => self.write_ccer(value),
            CNT => {
                Unmodelled::check_bits(&self.reg("CNT"), value, self.mask())?;
                self.cnt = value;
                Ok(())
            }
            PSC => {
                // Buffered: takes effect at the next update event.
                Unmodelled::check_bits(&self.reg("PSC"), value, 0xFFFF)?;
                self.psc = value;
                Ok(())
            }
            ARR => {
                Unmodelled::check_bits(&self.reg("ARR"), value, self.mask())?;
                self.arr = value;
                if self.cr1 & CR1_ARPE == 0 {
                    self.arr_active = value;
                }
                Ok(())
            }
            DCR if full => Unmodelled::check_bits(&self.reg("DCR"), value, 0),
            OR if self.kind == TimerKind::Tim2 => Unmodelled::check_bits(&self.reg("OR"), value, 0),
            _ => match self.ccr_offset(offset) {
                Some(c) => {
                    Unmodelled::check_bits(&self.reg(&format!("CCR{}", c + 1)), value, self.mask())?;
                    if self.is_output(c) {
                        self.ccr[c] = value;
                        if !self.oc_preload(c) {
                            self.ccr_active[c] = value;
                        }
                    }
                    // In input mode CCRx is read-only: the write is ignored.
                    Ok(())
                }
                None => Err(Unmodelled::offset(self.name(), offset, true)),
            },
        }
    }

    fn write_cr1(&mut self, value: u32, now: Time) -> Result<(), Unmodelled> {
        // DIR and CMS (down/centre-aligned counting) are not modelled; TIM9 has neither.
        // CKD only divides the sampling clock of the input filters, which must be off: stored.
        let modelled = CR1_CEN | CR1_UDIS | CR1_URS | CR1_OPM | CR1_ARPE | CR1_CKD;
        Unmodelled::check_bits(&self.reg("CR1"), value, modelled)?;
        let was_running = self.running();
        self.cr1 = value;
        if value & CR1_ARPE == 0 {
            self.arr_active = self.arr;
        }
        if !was_running && self.running() {
            self.anchor = now;
            self.started_at = Some(now);
        }
        Ok(())
    }

    fn write_egr(&mut self, value: u32, now: Time) -> Result<(), Unmodelled> {
        let channels = self.kind.channels();
        let ccg = (0..channels).fold(0, |m, c| m | sr_ccif(c));
        Unmodelled::check_bits(&self.reg("EGR"), value, EGR_UG | EGR_TG | ccg)?;
        if value & EGR_UG != 0 {
            // Counter and prescaler reinitialised; UEV unless UDIS; UIF unless URS.
            self.cnt = 0;
            self.psc_cnt = 0;
            self.anchor = self.anchor.max(now);
            if self.cr1 & CR1_UDIS == 0 {
                self.load_shadows();
                if self.cr1 & CR1_URS == 0 {
                    self.sr |= SR_UIF;
                    self.last_update = Some(now);
                    self.updates += 1;
                }
            }
        }
        for c in 0..channels {
            if value & sr_ccif(c) != 0 {
                if self.is_output(c) {
                    self.sr |= sr_ccif(c);
                } else {
                    self.capture_now(c);
                }
            }
        }
        if value & EGR_TG != 0 {
            self.sr |= SR_TIF;
        }
        Ok(())
    }

    fn write_ccmr(&mut self, index: usize, value: u32) -> Result<(), Unmodelled> {
        let name = self.reg(if index == 0 { "CCMR1" } else { "CCMR2" });
        Unmodelled::check_bits(&name, value, 0xFFFF)?;
        let mut new = 0;
        for half in 0..2 {
            let c = index * 2 + half;
            let mut byte = (value >> (8 * half)) & 0xFF;
            if self.cc_enabled(c) {
                // CCxS is writable only while the channel is off (CCxE = 0).
                byte = (byte & !0b11) | self.ccs(c);
            }
            match byte & 0b11 {
                0 => {
                    let ocm = (byte >> 4) & 0b111;
                    if !matches!(ocm, OCM_FROZEN | OCM_PWM1 | OCM_PWM2) {
                        return Err(Unmodelled::new(
                            &name,
                            format!("OC{}M = {ocm:#05b}: only frozen and PWM modes 1/2 are modelled", c + 1),
                        ));
                    }
                    if byte & (1 << 7) != 0 {
                        return Err(Unmodelled::new(&name, format!("OC{}CE (clear on ETRF) not modelled", c + 1)));
                    }
                }
                1 | 2 => {
                    if byte & 0xFC != 0 {
                        return Err(Unmodelled::new(&name, format!("IC{} prescaler/filter {:#04x}: only 0 is modelled", c + 1, byte >> 2)));
                    }
                }
                _ => return Err(Unmodelled::new(&name, format!("CC{}S = 11 (TRC input) not modelled", c + 1))),
            }
            new |= byte << (8 * half);
        }
        let before: [bool; 2] = [self.is_output(index * 2), self.is_output(index * 2 + 1)];
        let preload_before = [self.oc_preload(index * 2), self.oc_preload(index * 2 + 1)];
        self.ccmr[index] = new;
        for half in 0..2 {
            let c = index * 2 + half;
            // Becoming an output, or losing the preload: the compare value in use is the register.
            if self.is_output(c) && (!before[half] || (preload_before[half] && !self.oc_preload(c))) {
                self.ccr_active[c] = self.ccr[c];
            }
        }
        Ok(())
    }

    fn write_ccer(&mut self, value: u32) -> Result<(), Unmodelled> {
        let name = self.reg("CCER");
        let channels = self.kind.channels();
        let modelled = (0..channels).fold(0, |m, c| m | (0b1011 << (4 * c)));
        Unmodelled::check_bits(&name, value, modelled)?;
        for c in 0..channels {
            let p = value & (1 << (4 * c + 1)) != 0;
            let np = value & (1 << (4 * c + 3)) != 0;
            if np && (self.is_output(c) || !p) {
                return Err(Unmodelled::new(
                    &name,
                    format!(
                        "CC{}NP/CC{}P = {}{}: reserved (input) or must be kept cleared (output)",
                        c + 1,
                        c + 1,
                        u8::from(np),
                        u8::from(p)
                    ),
                ));
            }
        }
        self.ccer = value;
        Ok(())
    }
}

impl Peripheral for Timer {
    fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        Timer::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: Clocks) -> Result<(), Unmodelled> {
        Timer::write(self, offset, value, now)
    }

    fn next_event(&self) -> Option<Time> {
        Timer::next_event(self)
    }

    fn advance(&mut self, now: Time, _clocks: Clocks) {
        Timer::advance(self, now)
    }

    fn irq_line(&self, _line: usize) -> bool {
        Timer::irq_line(self)
    }

    fn set_clocks(&mut self, now: Time, clocks: Clocks) {
        Timer::set_clocks(self, clocks, now)
    }

    fn reset(&mut self) {
        *self = Timer::new(self.kind);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Time units per tick of the 84 MHz timer clocks of [`Clocks::PLL_84_MHZ`].
    const UPT: Time = 4;

    fn timer(kind: TimerKind) -> Timer {
        let mut t = Timer::new(kind);
        t.set_clocks(Clocks::PLL_84_MHZ, 0);
        t
    }

    /// PSC/ARR, UG with URS (the HAL's trigger_update), UIF cleared, CEN at `t0`.
    fn start(t: &mut Timer, psc: u32, arr: u32, t0: Time) {
        t.write(PSC, psc, t0).unwrap();
        t.write(ARR, arr, t0).unwrap();
        t.write(CR1, CR1_URS, t0).unwrap();
        t.write(EGR, EGR_UG, t0).unwrap();
        t.write(CR1, 0, t0).unwrap();
        t.write(CR1, CR1_CEN, t0).unwrap();
    }

    #[test]
    fn reset_values_are_zero_and_unknown_offsets_fail() {
        let mut t = Timer::new(TimerKind::Tim2);
        for off in [CR1, CR2, SMCR, DIER, SR, CCMR1, CCMR2, CCER, CNT, PSC, ARR, CCR1, DCR, OR] {
            assert_eq!(t.read(off, 0), Ok(0), "{off:#x}");
        }
        assert!(t.read(DMAR, 0).is_err());
        assert!(t.read(0x30, 0).is_err());
        let mut t9 = Timer::new(TimerKind::Tim9);
        assert!(t9.read(CR2, 0).is_err(), "TIM9 has no CR2");
        assert!(t9.read(CCMR2, 0).is_err());
        assert!(t9.read(CCR1 + 8, 0).is_err(), "TIM9 has 2 channels");
        assert!(Timer::new(TimerKind::Tim4).read(OR, 0).is_err());
    }

    #[test]
    fn tim9_ticks_at_807_69_hz_with_psc_51_arr_1999() {
        let mut t = timer(TimerKind::Tim9);
        t.write(DIER, DIER_UIE, 0).unwrap();
        start(&mut t, 51, 1999, 100);
        assert_eq!(t.read(SR, 100).unwrap() & SR_UIF, 0, "UG with URS = 1 does not set UIF");
        let period = 52 * 2000 * UPT; // 84 MHz / 52 / 2000 = 807.69 Hz
        assert_eq!(t.next_event(), Some(100 + period));
        t.advance(100 + period - 1);
        assert!(!t.irq_line());
        t.advance(100 + period);
        assert!(t.irq_line());
        assert_eq!(t.next_event(), None, "UIF pending: the line cannot change by itself");
        t.write(SR, !SR_UIF, 100 + period + 10).unwrap();
        assert!(!t.irq_line());
        assert_eq!(t.next_event(), Some(100 + 2 * period));
    }

    /// Output compare on a frozen channel: the counter reaching CCR1 sets CC1IF every period
    /// (the firmware's early sensor read, a fixed time before each update).
    #[test]
    fn a_frozen_compare_channel_flags_its_match_every_period() {
        let mut t = timer(TimerKind::Tim9);
        t.write(CCR1, 1900, 0).unwrap();
        t.write(DIER, DIER_UIE | sr_ccif(0), 0).unwrap();
        start(&mut t, 51, 1999, 100);
        let tick = 52 * UPT;
        assert_eq!(t.next_event(), Some(100 + 1900 * tick), "the match comes before the update");
        t.advance(100 + 1900 * tick - 1);
        assert!(!t.irq_line());
        t.advance(100 + 1900 * tick);
        assert_eq!(t.read(SR, 100 + 1900 * tick).unwrap(), sr_ccif(0));
        t.write(SR, !sr_ccif(0), 100 + 1900 * tick).unwrap();
        let period = 2000 * tick;
        assert_eq!(t.next_event(), Some(100 + period), "then the update");
        t.advance(100 + period);
        t.write(SR, !SR_UIF, 100 + period).unwrap();
        assert_eq!(t.next_event(), Some(100 + period + 1900 * tick), "and the next period's match");
        // Ten periods later in closed form: the flag is set, UIF too, and so is CC2IF: CH2 is
        // an output with CCR2 = 0, which the counter reaches at every wrap.
        assert_eq!(t.read(SR, 100 + 12 * period).unwrap(), SR_UIF | sr_ccif(0) | sr_ccif(1));
    }

    #[test]
    fn counter_counts_at_kernel_clock_over_psc_plus_one() {
        let mut t = timer(TimerKind::Tim2);
        start(&mut t, 20, 32767, 0);
        // 84 MHz / 21 = 4 MHz: 84 units per count.
        assert_eq!(t.read(CNT, 84 * 1000).unwrap(), 1000);
        assert_eq!(t.read(CNT, 84 * 1000 + 83).unwrap(), 1000);
        // Ten seconds later, in closed form: 40 000 000 counts mod 32 768.
        assert_eq!(t.read(CNT, 10 * TIME_HZ).unwrap(), (40_000_000 % 32768) as u32);
        assert_eq!(t.updates(), 40_000_000 / 32768);
    }

    #[test]
    fn psc_is_buffered_until_the_next_update() {
        let mut t = timer(TimerKind::Tim4);
        start(&mut t, 0, 99, 0);
        t.write(PSC, 1, 10 * UPT).unwrap();
        assert_eq!(t.read(CNT, 50 * UPT).unwrap(), 50, "old prescaler still active");
        assert_eq!(t.read(CNT, 100 * UPT).unwrap(), 0, "update at 100 ticks");
        assert_eq!(t.read(CNT, 120 * UPT).unwrap(), 10, "now /2");
    }

    #[test]
    fn ug_with_urs_clear_sets_uif_and_udis_blocks_the_update() {
        let mut t = timer(TimerKind::Tim2);
        t.write(PSC, 7, 0).unwrap();
        t.write(EGR, EGR_UG, 0).unwrap();
        assert_eq!(t.read(SR, 0).unwrap(), SR_UIF);
        t.write(SR, 0, 1).unwrap();
        t.write(CR1, CR1_UDIS, 2).unwrap();
        t.write(PSC, 3, 2).unwrap();
        t.write(EGR, EGR_UG, 3).unwrap();
        assert_eq!(t.read(SR, 4).unwrap(), 0);
        assert_eq!(t.psc_active, 7, "UDIS: shadow registers keep their value");
    }

    #[test]
    fn arr_is_preloaded_only_with_arpe() {
        let mut t = timer(TimerKind::Tim4);
        start(&mut t, 0, 999, 0);
        t.write(ARR, 99, 10 * UPT).unwrap();
        assert_eq!(t.period_counts(), 100, "ARPE = 0: immediate");
        t.write(CR1, CR1_CEN | CR1_ARPE, 20 * UPT).unwrap();
        t.write(ARR, 49, 20 * UPT).unwrap();
        assert_eq!(t.period_counts(), 100);
        t.advance(100 * UPT);
        assert_eq!(t.period_counts(), 50);
        assert_eq!(t.read(ARR, 100 * UPT).unwrap(), 49);
    }

    #[test]
    fn sr_is_rc_w0() {
        let mut t = timer(TimerKind::Tim2);
        t.write(CCMR1, 0x0101, 0).unwrap();
        t.write(CCER, 0x0011, 0).unwrap();
        t.capture(0, true, 5);
        t.capture(1, true, 6);
        t.write(EGR, EGR_UG, 7).unwrap();
        assert_eq!(t.read(SR, 8).unwrap(), SR_UIF | sr_ccif(0) | sr_ccif(1));
        t.write(SR, !sr_ccif(0), 9).unwrap();
        assert_eq!(t.read(SR, 10).unwrap(), SR_UIF | sr_ccif(1), "writing 1 leaves, 0 clears");
    }

    #[test]
    fn input_capture_latches_the_counter_on_the_selected_edge() {
        let mut t = timer(TimerKind::Tim2);
        t.write(DIER, sr_ccif(0), 0).unwrap();
        t.write(CCMR1, 0x01, 0).unwrap(); // CC1S = 01: IC1 on TI1
        t.write(CCER, 0x01, 0).unwrap(); // CC1E, rising
        start(&mut t, 20, 32767, 0);
        t.capture(0, false, 84 * 100);
        assert!(!t.irq_line(), "falling edge ignored");
        t.capture(0, true, 84 * 1000);
        assert!(t.irq_line());
        assert_eq!(t.read(CCR1, 84 * 2000).unwrap(), 1000);
        assert!(!t.irq_line(), "reading CCR1 clears CC1IF");
        t.write(CCR1, 5, 84 * 2001).unwrap();
        assert_eq!(t.read(CCR1, 84 * 2002).unwrap(), 1000, "read-only in input mode");
    }

    #[test]
    fn both_edges_and_overcapture() {
        let mut t = timer(TimerKind::Tim2);
        t.write(CCMR1, 0x01, 0).unwrap();
        t.write(CCER, 0b1011, 0).unwrap(); // CC1NP = CC1P = 1: both edges
        start(&mut t, 20, 32767, 0);
        t.capture(0, true, 84 * 10);
        t.capture(0, false, 84 * 20);
        assert_eq!(t.read(SR, 84 * 21).unwrap(), sr_ccif(0) | sr_ccof(0));
        assert_eq!(t.read(CCR1, 84 * 22).unwrap(), 20);
        assert!(t.write(CCER, 0b1001, 0).is_err(), "CC1NP/CC1P = 10 is reserved");
    }

    #[test]
    fn cc1s_10_maps_ic1_on_ti2() {
        let mut t = timer(TimerKind::Tim9);
        t.write(CCMR1, 0x02, 0).unwrap();
        t.write(CCER, 0x01, 0).unwrap();
        start(&mut t, 0, 0xFFFF, 0);
        t.capture(0, true, 10 * UPT);
        assert_eq!(t.read(SR, 10 * UPT).unwrap() & sr_ccif(0), 0);
        t.capture(1, true, 12 * UPT);
        assert_eq!(t.read(CCR1, 13 * UPT).unwrap(), 12);
    }

    #[test]
    fn pwm_compare_is_preloaded_with_ocpe_until_the_update() {
        let mut t = timer(TimerKind::Tim4);
        t.write(CCMR1, 0x0068, 0).unwrap(); // OC1M = PWM1, OC1PE
        t.write(CCER, 0x0001, 0).unwrap();
        start(&mut t, 84, 1999, 0);
        let count = 85 * UPT;
        t.write(CCR1, 500, 10 * count).unwrap();
        assert_eq!(t.pwm_compare(0, 11 * count), 0, "preload not yet active");
        assert_eq!(t.pwm_compare(0, 2000 * count), 500);
        assert_eq!(t.duty(0, 2000 * count), 0.25);
        t.write(CCR1, 3000, 2001 * count).unwrap();
        assert_eq!(t.duty(0, 4000 * count), 1.0, "CCR > ARR: always active");
    }

    #[test]
    fn duty_follows_mode_polarity_and_enable() {
        let mut t = timer(TimerKind::Tim4);
        t.write(CCMR1, 0x7060, 0).unwrap(); // CH1 PWM1, CH2 PWM2, no preload
        t.write(CCR1, 250, 0).unwrap();
        t.write(CCR1 + 4, 250, 0).unwrap();
        start(&mut t, 0, 999, 0);
        assert_eq!(t.duty(0, 10), 0.0, "CC1E = 0");
        t.write(CCER, 0x0011, 10).unwrap();
        assert_eq!(t.duty(0, 10), 0.25);
        assert_eq!(t.duty(1, 10), 0.75);
        t.write(CCER, 0x0013, 10).unwrap();
        assert_eq!(t.duty(0, 10), 0.75, "CC1P: active low");
        assert_eq!(t.duty(3, 10), 0.0);
        assert_eq!(t.duty(9, 10), 0.0);
    }

    #[test]
    fn one_pulse_mode_stops_at_the_update() {
        let mut t = timer(TimerKind::Tim9);
        start(&mut t, 0, 9, 0);
        t.write(CR1, CR1_CEN | CR1_OPM, 0).unwrap();
        assert_eq!(t.read(CR1, 100 * UPT).unwrap() & CR1_CEN, 0);
        assert_eq!(t.read(CNT, 100 * UPT).unwrap(), 0);
        assert_eq!(t.updates(), 1);
    }

    #[test]
    fn a_clock_change_keeps_the_count_and_changes_the_rate() {
        let mut t = Timer::new(TimerKind::Tim2);
        start(&mut t, 0, 0xFFFF_FFFF, 0);
        assert_eq!(t.read(CNT, 21 * 100).unwrap(), 100, "16 MHz HSI: 21 units per tick");
        t.set_clocks(Clocks::PLL_84_MHZ, 21 * 100);
        assert_eq!(t.read(CNT, 21 * 100 + 4 * 50).unwrap(), 150);
        assert_eq!(t.started_at(), Some(0));
    }

    #[test]
    fn counter_above_arr_runs_to_its_maximum() {
        let mut t = timer(TimerKind::Tim4);
        start(&mut t, 0, 99, 0);
        t.write(CNT, 0xFFF0, 0).unwrap();
        assert_eq!(t.read(CNT, 15 * UPT).unwrap(), 0xFFFF);
        assert_eq!(t.read(CNT, 16 * UPT).unwrap(), 0);
        assert_eq!(t.updates(), 1);
    }

    #[test]
    fn unmodelled_settings_are_refused() {
        let mut t = Timer::new(TimerKind::Tim2);
        assert!(t.write(CR1, CR1_DIR, 0).is_err());
        assert!(t.write(CR1, 0b01 << 5, 0).is_err());
        assert!(t.write(SMCR, 0b100, 0).is_err(), "slave mode");
        assert!(t.write(DIER, 1 << 8, 0).is_err(), "UDE: no DMA");
        assert!(t.write(CCMR1, 0x31, 0).is_err(), "IC1 filter");
        assert!(t.write(CCMR1, 0x05, 0).is_err(), "IC1 prescaler");
        assert!(t.write(CCMR1, 0x30, 0).is_err(), "toggle mode");
        assert!(t.write(CCMR1, 0x03, 0).is_err(), "TRC");
        assert!(t.write(OR, 0x400, 0).is_err(), "TIM2 remap");
        assert!(t.write(CR2, 1 << 7, 0).is_err(), "TI1S");
        assert!(t.write(CCER, 0b1000, 0).is_err(), "CC1NP in output mode");
        let mut t4 = Timer::new(TimerKind::Tim4);
        assert!(t4.write(ARR, 0x1_0000, 0).is_err(), "16-bit ARR");
        let mut t9 = Timer::new(TimerKind::Tim9);
        assert!(t9.write(CR1, CR1_DIR, 0).is_err(), "TIM9 has no DIR");
        assert!(t9.write(0x04, 0, 0).is_err());
        assert!(t9.write(DIER, sr_ccif(2), 0).is_err(), "TIM9 has no CC3");
    }

    #[test]
    fn tim2_is_32_bit() {
        let mut t = timer(TimerKind::Tim2);
        start(&mut t, 0, 0xFFFF_FFFF, 0);
        t.write(CNT, 0xFFFF_FFFE, 0).unwrap();
        assert_eq!(t.read(CNT, UPT).unwrap(), 0xFFFF_FFFF);
        assert_eq!(t.read(CNT, 2 * UPT).unwrap(), 0);
    }

    #[test]
    fn an_edge_delivered_late_captures_the_counter_at_the_edge() {
        let mut t = timer(TimerKind::Tim2);
        t.write(CCMR1, 0x01, 0).unwrap();
        t.write(CCER, 0x01, 0).unwrap();
        start(&mut t, 20, 32767, 0);
        t.advance(84 * 5000);
        t.capture(0, true, 84 * 4000);
        assert_eq!(t.read(CCR1, 84 * 5001).unwrap(), 4000);
        assert_eq!(t.captures(0), 1);
        t.advance(84 * 40_000);
        t.capture(0, true, 84 * 32_770);
        assert_eq!(t.read(CCR1, 84 * 40_001).unwrap(), 2, "across a wrap");
    }

    #[test]
    fn set_clock_units_is_idempotent() {
        let mut t = timer(TimerKind::Tim4);
        start(&mut t, 0, 0xFFFF, 0);
        t.set_clock_units(100, UPT);
        assert_eq!(t.read(CNT, 40).unwrap(), 10);
    }

    #[test]
    fn ccxg_on_an_input_channel_captures() {
        let mut t = timer(TimerKind::Tim2);
        t.write(CCMR2, 0x0100, 0).unwrap(); // CC4S = 01
        start(&mut t, 0, 0xFFFF_FFFF, 0);
        t.write(EGR, sr_ccif(3), 33 * UPT).unwrap();
        assert_eq!(t.read(CCR1 + 12, 34 * UPT).unwrap(), 33);
    }
}
