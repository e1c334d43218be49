//! The three timers of the board, set up on the registers because the HAL offers neither
//! input capture on both edges nor raw PSC/ARR values from a run-time configuration:
//! TIM2 captures the radio, TIM4 drives the motors, TIM9 paces the control tick.

use fcu_core::rc::{CaptureEdge, CHANNELS};
use stm32f4xx_hal::gpio::{Alternate, PA0, PA1, PA2, PA3};
use stm32f4xx_hal::pac::{TIM2, TIM4, TIM9};
use stm32f4xx_hal::rcc::{Enable, Rcc, Reset};

/// TIM2 prescaler: 84 MHz / (20 + 1) = 4 MHz, 0.25 µs per count (the reference's RC LSB).
pub const RC_CAPTURE_PSC: u16 = 20;
/// TIM2 auto-reload: the core's 15-bit capture wrap (32768 counts, 8.192 ms) on a 32-bit timer.
pub const RC_CAPTURE_ARR: u32 = fcu_core::rc::CAPTURE_WRAP - 1;

/// PA0..PA3 (AIL, ELE, THR, RUD) in TIM2's alternate function.
pub type CapturePins = (PA0<Alternate<1>>, PA1<Alternate<1>>, PA2<Alternate<1>>, PA3<Alternate<1>>);

/// TIM2 CH1..CH4 on PA0..PA3 capturing both edges.
///
/// Zero-sized on purpose: the pins are typed (their port and number are in the type, not in
/// RAM). An RTIC resource lives in `.uninit`, which is never loaded at boot, and a resource
/// that is initialised from constants and never written again can have its one store folded
/// into a static initializer that then never reaches RAM (it happened to this struct when it
/// kept the pins as run-time port/pin bytes: every channel read PA0's level, or garbage, and
/// the radio never decoded). `scripts/check-uninit-constants` guards the firmware's IR.
pub struct RcCapture {
    tim: TIM2,
    /// Owned so nothing else reconfigures them; their levels, read at interrupt time (in one
    /// read of GPIOA's IDR) tell a rising edge from a falling one, as the reference does.
    _pins: CapturePins,
    /// Edges taken from each channel since TIM2's last update (one capture wrap, 8.192 ms).
    edges_in_window: [u8; CHANNELS],
    /// The channels whose capture interrupt is on, as DIER's CCxIE bits: DIER is written by
    /// the capture alone, so its copy here saves a bus read per look.
    enabled_mask: u8,
}

/// Edges one channel may raise interrupts for in one capture wrap (8.192 ms). A receiver's
/// pulses are at least 0.8 ms wide in frames of at least 2 ms, so a working channel gives at
/// most 2 edges per 2 ms, 9 per wrap; a broken wire or an interfering signal on the pin can
/// give millions per second, and the capture interrupt outranks the control tick. Past this
/// budget the channel's interrupt is off until the next wrap: the interrupt's cost is bounded
/// (4 channels × 16 edges per 8.192 ms, under 1 % of the CPU) and the core, seeing that
/// channel's pulses stop, declares the link lost and flies its failsafe, as for a receiver
/// that went silent, instead of the watchdog resetting a starved board in the air.
pub const EDGE_BUDGET_PER_WRAP: u8 = 16;

impl RcCapture {
    pub fn new(tim: TIM2, pins: CapturePins, rcc: &mut Rcc) -> Self {
        TIM2::enable(rcc);
        TIM2::reset(rcc);
        tim.psc().write(|w| w.psc().set(RC_CAPTURE_PSC));
        tim.arr().write(|w| w.arr().set(RC_CAPTURE_ARR));
        // CCxS = 01: channel x captures its own input TIx; no prescaler, no filter.
        tim.ccmr1_input().write(|w| w.cc1s().ti1().cc2s().ti2());
        tim.ccmr2_input().write(|w| w.cc3s().ti3().cc4s().ti4());
        // CCxP = CCxNP = 1: capture on both edges.
        tim.ccer().write(|w| {
            for n in 0..4 {
                w.cce(n).set_bit().ccp(n).set_bit().ccnp(n).set_bit();
            }
            w
        });
        tim.egr().write(|w| w.ug().set_bit());
        // The flags are rc_w0: clear each explicitly (a plain `write(|w| w)` writes 1s, which
        // leaves them as they are). Nothing is pending at boot anyway.
        tim.sr().write(|w| {
            w.uif().clear();
            for n in 0..4 {
                w.ccif(n).clear().ccof(n).clear();
            }
            w
        });
        let capture = RcCapture { tim, _pins: pins, edges_in_window: [0; CHANNELS], enabled_mask: ALL_CAPTURES };
        // The capture interrupts and the wrap's, which reopens the edge budget.
        capture.write_interrupts();
        capture.tim.cr1().write(|w| w.cen().set_bit());
        capture
    }

    /// Hands each edge captured since the last call to `sink`, one per channel at most.
    /// Reading CCRx clears its flag. An over-capture (a second edge before the first was
    /// read) cannot happen with RC pulses of 0.8 ms or more, and would only lose one width
    /// that the core rejects.
    ///
    /// A channel that has used its [`EDGE_BUDGET_PER_WRAP`] has its interrupt turned off here
    /// (returned: how many were, this time); the next wrap (this same interrupt, UIF) turns it
    /// back on, dropping what it captured meanwhile. Runs in the capture interrupt, which
    /// outranks the control tick: short and straight.
    pub fn take_edges(&mut self, mut sink: impl FnMut(CaptureEdge)) -> u32 {
        // The flags are looked at again until a look finds no channel not yet read, and only
        // then is anything handed on: the radio's latency ends at the CCR read, so an edge
        // latched while this interrupt runs (the next channel's, in a receiver's frame) waits
        // for the look in progress, not for the queueing of those before it, and whatever
        // comes after the last look waits only for the return. One edge per channel at most
        // (pulses are 0.8 ms or more): a second one, a storm's, waits for the next entry, so
        // a storm costs each entry at most its four reads.
        let mut taken = 0u32;
        let mut captures = [0u16; CHANNELS];
        for _ in 0..MAX_LOOKS {
            let mut sr = self.tim.sr().read().bits();
            if sr & 1 != 0 {
                self.reopen_window();
                // Again: a reopened channel's flag was cleared with its stale capture.
                sr = self.tim.sr().read().bits();
            }
            // CCxIF is SR bit x (bits 1..4); DIER's CCxIE sit at the same bits.
            let new = sr & u32::from(self.enabled_mask) & !taken;
            if new == 0 {
                break;
            }
            for (channel, (slot, ccr)) in captures.iter_mut().zip(self.tim.ccr_iter()).enumerate() {
                if new & (2 << channel) != 0 {
                    *slot = ccr.read().ccr().bits() as u16;
                }
            }
            taken |= new;
        }
        if taken == 0 {
            return 0;
        }
        // The four pins' levels in one read of GPIOA's IDR (PA0..PA3 are its bits 0..3): a
        // pin keeps its level for the 0.8 ms of a pulse, far longer than the looks take.
        // SAFETY: a read of an input data register, which no write reaches; the pins are this
        // struct's own, in their alternate function, and IDR reflects them in any mode.
        let levels = unsafe { (*stm32f4xx_hal::pac::GPIOA::ptr()).idr().read().bits() };
        let mut muted = 0;
        for (channel, (&capture_counts, count)) in captures.iter().zip(self.edges_in_window.iter_mut()).enumerate() {
            if taken & (2 << channel) == 0 {
                continue;
            }
            sink(CaptureEdge { channel, capture_counts, level_high: levels & (1 << channel) != 0 });
            *count = count.saturating_add(1);
            if *count == EDGE_BUDGET_PER_WRAP {
                self.enabled_mask &= !(2 << channel);
                muted += 1;
            }
        }
        if muted > 0 {
            // DIER is written by this interrupt alone after init: no other writer to race.
            self.write_interrupts();
        }
        // CCxOF is left set: it raises no interrupt, and clearing it with a write would race
        // a capture flag arriving between the read above and that write.
        muted
    }

    /// A new capture wrap: every channel gets its budget back. A channel that was muted
    /// loses what it captured meanwhile (read and dropped: a latched time from the middle
    /// of a storm pairs with nothing), then raises interrupts again.
    fn reopen_window(&mut self) {
        self.tim.sr().write(|w| w.uif().clear());
        for (channel, count) in self.edges_in_window.iter_mut().enumerate() {
            if self.enabled_mask & (2 << channel) == 0 {
                let _stale = self.tim.ccr(channel).read();
            }
            *count = 0;
        }
        if self.enabled_mask != ALL_CAPTURES {
            self.enabled_mask = ALL_CAPTURES;
            self.write_interrupts();
        }
    }

    /// DIER from the channels' mask, with the update interrupt always on.
    fn write_interrupts(&self) {
        let on = |channel: u8| self.enabled_mask & (2 << channel) != 0;
        self.tim.dier().write(|w| w.cc1ie().bit(on(0)).cc2ie().bit(on(1)).cc3ie().bit(on(2)).cc4ie().bit(on(3)).uie().set_bit());
    }
}

/// Looks at the capture flags in one interrupt at most.
const MAX_LOOKS: usize = 4;

/// CC1IE..CC4IE (the same bits as CC1IF..CC4IF in SR).
const ALL_CAPTURES: u8 = 0b1_1110;

/// TIM4 CH1..CH4 on PB6..PB9: PWM mode 1, active high, at the off compare (0 on the DC
/// board, the idle pulse for ESCs) from the first period on.
pub struct Motors {
    tim: TIM4,
}

impl Motors {
    pub fn new(tim: TIM4, psc: u16, arr: u16, off_compare: u16, rcc: &mut Rcc) -> Self {
        TIM4::enable(rcc);
        TIM4::reset(rcc);
        tim.psc().write(|w| w.psc().set(psc));
        tim.arr().write(|w| w.arr().set(arr));
        for n in 0..4 {
            tim.ccr(n).write(|w| w.ccr().set(off_compare));
        }
        // Preload on: a compare written mid-period takes effect at the next period, so a
        // pulse is never cut or stretched by a write.
        tim.ccmr1_output().write(|w| w.oc1m().pwm_mode1().oc1pe().set_bit().oc2m().pwm_mode1().oc2pe().set_bit());
        tim.ccmr2_output().write(|w| w.oc3m().pwm_mode1().oc3pe().set_bit().oc4m().pwm_mode1().oc4pe().set_bit());
        tim.ccer().write(|w| w.cc1e().set_bit().cc2e().set_bit().cc3e().set_bit().cc4e().set_bit());
        tim.egr().write(|w| w.ug().set_bit());
        tim.cr1().write(|w| w.arpe().set_bit().cen().set_bit());
        Motors { tim }
    }

    /// Writes the four compare values the core computed (motor 1..4 = CH1..CH4).
    pub fn write(&mut self, compare: [u16; 4]) {
        for (n, value) in compare.into_iter().enumerate() {
            self.tim.ccr(n).write(|w| w.ccr().set(value));
        }
    }
}

/// How long before each control tick the IMU burst starts: the burst takes about 41 µs
/// (address and 12 bytes at 2.625 MHz, then the end-of-read interrupt), so its sample is in
/// when the tick starts, about 19 µs old, and the tick goes straight to the control law.
pub const SENSOR_READ_LEAD_CYCLES: u32 = 60 * 84;

/// What a TIM9 interrupt is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickEvents {
    /// CC1: the IMU burst for the coming tick is due.
    pub read_due: bool,
    /// Update: the control tick.
    pub tick_due: bool,
}

/// TIM9: its update interrupt is the control tick; its channel 1 compare, a fixed lead
/// before each update, starts the tick's sensor read.
pub struct TickTimer {
    tim: TIM9,
}

/// The right to start TIM9, apart from the [`TickTimer`] the control task keeps: boot hands
/// it to a task that runs once every resource is in place and the interrupts are enabled.
/// Started at the end of `init` instead, TIM9 would count through what follows it (RTIC
/// moving the resources into place, and whatever the compiler schedules after the start) with
/// every interrupt masked.
pub struct TickStart(());

impl TickStart {
    pub fn start(self) {
        // SAFETY: CR1 is written only here, once, after `TickTimer::new` set it up and before
        // the timer runs; `TickTimer` reads SR and writes SR, registers this never touches.
        let tim = unsafe { &*TIM9::ptr() };
        tim.cr1().modify(|_, w| w.cen().set_bit());
    }
}

impl TickTimer {
    /// Configures TIM9 but does not start it: [`TickStart::start`] is the last step of boot.
    pub fn new(tim: TIM9, psc: u16, arr: u16, rcc: &mut Rcc) -> (Self, TickStart) {
        TIM9::enable(rcc);
        TIM9::reset(rcc);
        tim.psc().write(|w| w.psc().set(psc));
        tim.arr().write(|w| w.arr().set(arr));
        // Channel 1 frozen (an output compare driving no pin), matching the lead before the
        // update; preload off: the value is written once, before the timer runs.
        let lead_counts = SENSOR_READ_LEAD_CYCLES.div_ceil(u32::from(psc) + 1);
        let read_at = (u32::from(arr) + 1).saturating_sub(lead_counts);
        tim.ccr1().write(|w| w.ccr().set(read_at as u16));
        // Load PSC/ARR now; URS keeps this forced update from raising the interrupt.
        tim.cr1().write(|w| w.urs().set_bit());
        tim.egr().write(|w| w.ug().set_bit());
        tim.sr().write(|w| w.uif().clear_bit().cc1if().clear_bit());
        tim.dier().write(|w| w.uie().set_bit().cc1ie().set_bit());
        (TickTimer { tim }, TickStart(()))
    }

    /// Which of the interrupt's events are pending, each cleared (rc_w0: a 0 clears, a 1
    /// leaves the flag alone, so a flag rising meanwhile is not lost).
    ///
    /// Both at once, with the counter past CC1, means the CPU was stalled through at least a
    /// period (a flash erase: every fetch waits, up to 500 ms): the update flag is a swallowed
    /// period's, and this period's update is still to come. The burst starts now and the tick
    /// waits for its update, as in any period, instead of ticking now without the burst's
    /// sample. Should the update come while this is decided (the counter wrapped meanwhile),
    /// the tick is due after all.
    pub fn take_events(&mut self) -> TickEvents {
        let sr = self.tim.sr().read();
        let events = TickEvents { read_due: sr.cc1if().bit_is_set(), tick_due: sr.uif().bit_is_set() };
        if events.read_due && events.tick_due {
            let count = self.tim.cnt().read().cnt().bits();
            if count >= self.tim.ccr1().read().ccr().bits() {
                self.tim.sr().write(|w| w.uif().clear_bit().cc1if().clear_bit());
                let wrapped = self.tim.cnt().read().cnt().bits() < count;
                if wrapped {
                    // The update taken here: its flag, if it rose after the write, is cleared
                    // (CC1IF written 1 stays as it is).
                    self.tim.sr().write(|w| w.uif().clear_bit().cc1if().bit(true));
                }
                return TickEvents { read_due: true, tick_due: wrapped };
            }
        }
        self.tim.sr().write(|w| w.uif().bit(!events.tick_due).cc1if().bit(!events.read_due));
        events
    }
}
