//! IWDG, independent watchdog (RM0368 §15), at 0x4000_3000.
//!
//! Behaviour (RM0368 §15, IWDG functional description and registers):
//! - KR = 0xCCCC starts the watchdog; "the counter starts counting down from the reset value of
//!   0xFFF" (not from RLR). Once started it cannot be stopped: only a reset does that.
//! - KR = 0xAAAA reloads the counter from RLR (and write-protects PR/RLR again).
//! - KR = 0x5555 unlocks PR and RLR; any other key value protects them again. A write to PR or
//!   RLR while protected is ignored (counted in [`Iwdg::ignored_writes`]).
//! - A PR (RLR) write sets SR.PVU (RVU) while the value crosses into the VDD domain, which
//!   "takes up to 5 RC 40 kHz cycles" (RM text, i.e. 5 LSI cycles); until then reads return and
//!   the counter uses the previous value. RM: "PVU must be reset in order to be able to change
//!   the prescaler divider" (RVU likewise): a write while busy is an [`Unmodelled`] error.
//! - The counter decrements at LSI / (4·2^PR) (PR 6 and 7 both /256); the reset happens when it
//!   would go below 0, i.e. (value + 1) prescaled ticks after the reload (RM0368's min/max
//!   timeout table: RL = 0 gives the minimum timeout of one tick, 0.125 ms at /4).
//!
//! - The watchdog runs on the LSI, which is off after reset (RCC_CSR.LSION = 0). The start key
//!   forces the LSI on (RM0368 §15.3); the board tells the model when the oscillator is stable
//!   ([`Iwdg::set_lsi`], from the RCC model's LSION/LSIRDY and its start-up time). While the LSI
//!   is off nothing crosses into the watchdog's domain: PVU/RVU stay set and the counter does
//!   not move. So a set-up that waits for SR = 0 before writing the start key, with the LSI not
//!   turned on by software, spins for ever on silicon and here (RM0368 IWDG_SR note: after a
//!   PR/RLR update it is not necessary to wait for PVU/RVU before going on; ST's own
//!   `HAL_IWDG_Init` writes 0xCCCC first, "LSI is turned on automatically", then the values,
//!   then polls SR with a time-out).
//!
//! The LSI runs at its nominal 32 kHz unless the board sets another frequency
//! ([`Iwdg::set_lsi_hz`]): DS9716 allows 17–47 kHz over parts, supply and temperature, and the
//! firmware's timeouts must hold at both ends. Assumptions: the
//! option byte WDG_SW selects the software watchdog (the counter only runs after 0xCCCC); no
//! debugger, so DBG_IWDG_STOP has no effect. When a PR update completes while the counter runs,
//! the counter continues from its current value with the new prescaler from that instant (the
//! partial tick is dropped: the prescaler's phase is not documented).
//!
//! Layout and reset values from the `stm32f4` 0.16 PAC (`stm32f401/iwdg/*.rs`).

use super::{Clocks, Peripheral, Time, Unmodelled, TIME_HZ};

/// Base address of the IWDG (RM0368 memory map).
pub const BASE: u32 = 0x4000_3000;
/// Peripheral name used in error messages.
pub const NAME: &str = "IWDG";

/// Nominal LSI frequency.
pub const LSI_HZ: u64 = 32_000;
/// One LSI cycle in [`Time`] units (10 500).
pub const LSI_CYCLE: Time = TIME_HZ / LSI_HZ;
/// PR/RLR update time into the VDD domain: 5 LSI cycles (RM0368 IWDG_SR description), at the
/// nominal LSI.
pub const UPDATE_TIME: Time = 5 * LSI_CYCLE;
/// DS9716's LSI range (f_LSI, min and max).
pub const LSI_MIN_HZ: u64 = 17_000;
pub const LSI_MAX_HZ: u64 = 47_000;

const KR: u32 = 0x00;
const PR: u32 = 0x04;
const RLR: u32 = 0x08;
const SR: u32 = 0x0C;

const KEY_UNLOCK: u32 = 0x5555;
const KEY_RELOAD: u32 = 0xAAAA;
const KEY_START: u32 = 0xCCCC;

const RLR_RESET: u32 = 0x0FFF;
/// The counter's value at start (RM0368 §15 functional description: "the counter starts counting down from the reset value of 0xFFF").
const COUNTER_START: u32 = 0x0FFF;

/// Prescaler divider for PR (RM0368 IWDG_PR description: 4, 8, …, 256; 0b111 is also /256).
fn divider(pr: u32) -> u64 {
    4u64 << (pr & 0b111).min(6)
}

/// The IWDG model.
#[derive(Clone, Debug)]
pub struct Iwdg {
    unlocked: bool,
    /// PR and RLR as effective in the VDD domain.
    pr: u32,
    rlr: u32,
    /// A PR / RLR write on its way: (value, time written). It lands [`UPDATE_TIME`] after
    /// both the write and the LSI's start.
    pr_pending: Option<(u32, Time)>,
    rlr_pending: Option<(u32, Time)>,
    /// When the LSI is stable (None: off).
    lsi_ready_at: Option<Time>,
    started: bool,
    /// Counter value at `reference`, the time of the last reload (or rebase).
    counter: u32,
    reference: Time,
    ignored_writes: u32,
    /// The LSI's frequency and one of its cycles in [`Time`] units.
    lsi_hz: u64,
    lsi_cycle: Time,
}

impl Default for Iwdg {
    fn default() -> Self {
        Iwdg::new()
    }
}

impl Iwdg {
    /// Reset state: stopped, PR = 0, RLR = 0xFFF, registers protected.
    pub fn new() -> Self {
        Iwdg {
            unlocked: false,
            pr: 0,
            rlr: RLR_RESET,
            pr_pending: None,
            rlr_pending: None,
            lsi_ready_at: None,
            started: false,
            counter: COUNTER_START,
            reference: 0,
            ignored_writes: 0,
            lsi_hz: LSI_HZ,
            lsi_cycle: LSI_CYCLE,
        }
    }

    /// The LSI runs at `hz` (a part at one end of DS9716's 17–47 kHz, rounded to whole
    /// [`Time`] units per cycle). It is the chip's: the board keeps it through resets.
    pub fn set_lsi_hz(&mut self, hz: u64) {
        self.lsi_hz = hz.max(1);
        self.lsi_cycle = (TIME_HZ + self.lsi_hz / 2) / self.lsi_hz;
    }

    /// The LSI's frequency.
    pub fn lsi_hz(&self) -> u64 {
        self.lsi_hz
    }

    /// One counter tick in [`Time`] units.
    fn tick(&self, pr: u32) -> Time {
        divider(pr) * self.lsi_cycle
    }

    /// Whether the watchdog has been started (KR = 0xCCCC).
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// The LSI as the RCC has it: stable from `ready_at`, or off.
    pub fn set_lsi(&mut self, ready_at: Option<Time>) {
        self.lsi_ready_at = ready_at;
    }

    /// When a PR/RLR value written at `written` reaches the watchdog's domain (never while
    /// the LSI is off).
    fn lands_at(&self, written: Time) -> Option<Time> {
        self.lsi_ready_at.map(|lsi| written.max(lsi) + 5 * self.lsi_cycle)
    }

    /// The counter's reference time: it cannot count before the LSI runs.
    fn counting_from(&self) -> Option<Time> {
        self.lsi_ready_at.map(|lsi| self.reference.max(lsi))
    }

    /// Writes to PR/RLR ignored because the registers were write-protected.
    pub fn ignored_writes(&self) -> u32 {
        self.ignored_writes
    }

    /// When the watchdog resets the chip unless reloaded before; `None` when not started.
    pub fn next_event(&self) -> Option<Time> {
        self.expiry()
    }

    /// Whether the counter has run out at `now` (the machine then resets the chip).
    pub fn expired(&self, now: Time) -> bool {
        self.expiry().is_some_and(|t| now >= t)
    }

    /// Timeout after a reload with the configured PR and RLR (pending writes included), in
    /// seconds at the LSI's frequency; `None` when not started.
    pub fn timeout_s(&self) -> Option<f64> {
        if !self.started {
            return None;
        }
        let pr = self.pr_pending.map_or(self.pr, |(v, _)| v);
        let rlr = self.rlr_pending.map_or(self.rlr, |(v, _)| v);
        Some((f64::from(rlr) + 1.0) * divider(pr) as f64 / self.lsi_hz as f64)
    }

    /// Completes PR/RLR updates due by `now`.
    pub fn advance(&mut self, now: Time) {
        if let Some((value, written)) = self.rlr_pending {
            if self.lands_at(written).is_some_and(|done| done <= now) {
                self.rlr = value;
                self.rlr_pending = None;
            }
        }
        if let Some((value, written)) = self.pr_pending {
            if let Some(done) = self.lands_at(written).filter(|&done| done <= now) {
                if let Some(from) = self.counting_from().filter(|&from| self.started && done > from) {
                    let elapsed = (done - from) / self.tick(self.pr);
                    self.counter = self.counter.saturating_sub(u32::try_from(elapsed).unwrap_or(u32::MAX));
                    self.reference = done;
                }
                self.pr = value;
                self.pr_pending = None;
            }
        }
    }

    fn expiry(&self) -> Option<Time> {
        if !self.started {
            return None;
        }
        let mut counter = u64::from(self.counter);
        let mut reference = self.counting_from()?;
        let mut pr = self.pr;
        if let Some((new_pr, done)) = self.pr_pending.and_then(|(v, written)| Some((v, self.lands_at(written)?))) {
            let old = reference + (counter + 1) * self.tick(pr);
            if old <= done {
                return Some(old);
            }
            if done > reference {
                counter -= (done - reference) / self.tick(pr);
                reference = done;
            }
            pr = new_pr;
        }
        Some(reference + (counter + 1) * self.tick(pr))
    }

    pub fn read(&mut self, offset: u32, now: Time) -> Result<u32, Unmodelled> {
        self.advance(now);
        match offset {
            // KR is write-only (RM0368 IWDG_KR description).
            KR => Ok(0),
            PR => Ok(self.pr),
            RLR => Ok(self.rlr),
            SR => Ok(u32::from(self.pr_pending.is_some()) | (u32::from(self.rlr_pending.is_some()) << 1)),
            _ => Err(Unmodelled::offset(NAME, offset, false)),
        }
    }

    pub fn write(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.advance(now);
        match offset {
            KR => {
                Unmodelled::check_bits("IWDG.KR", value, 0xFFFF)?;
                self.unlocked = value == KEY_UNLOCK;
                match value {
                    KEY_RELOAD if self.started => {
                        self.counter = self.rlr;
                        self.reference = now;
                    }
                    KEY_START if !self.started => {
                        self.started = true;
                        self.counter = COUNTER_START;
                        self.reference = now;
                    }
                    _ => {}
                }
                Ok(())
            }
            PR => {
                Unmodelled::check_bits("IWDG.PR", value, 0b111)?;
                if !self.unlocked {
                    self.ignored_writes = self.ignored_writes.saturating_add(1);
                } else if self.pr_pending.is_some() {
                    return Err(Unmodelled::new("IWDG.PR", "write while SR.PVU = 1 (RM0368: PVU must be reset to change the prescaler)"));
                } else {
                    self.pr_pending = Some((value, now));
                }
                Ok(())
            }
            RLR => {
                Unmodelled::check_bits("IWDG.RLR", value, 0xFFF)?;
                if !self.unlocked {
                    self.ignored_writes = self.ignored_writes.saturating_add(1);
                } else if self.rlr_pending.is_some() {
                    return Err(Unmodelled::new(
                        "IWDG.RLR",
                        "write while SR.RVU = 1 (RM0368: RVU must be reset to change the reload value)",
                    ));
                } else {
                    self.rlr_pending = Some((value, now));
                }
                Ok(())
            }
            SR => Err(Unmodelled::new("IWDG.SR", format!("write of {value:#010x} to a read-only register"))),
            _ => Err(Unmodelled::offset(NAME, offset, true)),
        }
    }
}

impl Peripheral for Iwdg {
    fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        Iwdg::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: Clocks) -> Result<(), Unmodelled> {
        Iwdg::write(self, offset, value, now)
    }

    fn next_event(&self) -> Option<Time> {
        Iwdg::next_event(self)
    }

    fn advance(&mut self, now: Time, _clocks: Clocks) {
        Iwdg::advance(self, now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The HAL's `IndependentWatchdog::start(50 ms)` sequence: unlock, PR = 6, RLR = 6, reload,
    /// start.
    fn start_like_the_hal(w: &mut Iwdg, t: Time) {
        w.write(KR, KEY_UNLOCK, t).unwrap();
        w.write(PR, 6, t).unwrap();
        w.write(RLR, 6, t).unwrap();
        w.write(KR, KEY_RELOAD, t).unwrap();
        w.write(KR, KEY_START, t).unwrap();
    }

    /// A watchdog whose LSI has been running since power-on (as if software set LSION).
    fn running() -> Iwdg {
        let mut w = Iwdg::new();
        w.set_lsi(Some(0));
        w
    }

    #[test]
    fn reset_values_match_the_svd() {
        let mut w = Iwdg::new();
        assert_eq!(w.read(PR, 0), Ok(0));
        assert_eq!(w.read(RLR, 0), Ok(0xFFF));
        assert_eq!(w.read(SR, 0), Ok(0));
        assert_eq!(w.next_event(), None);
        assert_eq!(w.timeout_s(), None);
    }

    #[test]
    fn lsi_cycle_is_10500_units() {
        assert_eq!(LSI_CYCLE, 10_500);
    }

    #[test]
    fn writes_without_unlock_are_ignored() {
        let mut w = running();
        w.write(PR, 3, 0).unwrap();
        w.write(RLR, 10, 0).unwrap();
        assert_eq!(w.ignored_writes(), 2);
        assert_eq!(w.read(SR, 0), Ok(0));
        w.write(KR, KEY_UNLOCK, 0).unwrap();
        w.write(KR, 0x1234, 0).unwrap();
        w.write(PR, 3, 0).unwrap();
        assert_eq!(w.ignored_writes(), 3, "any other key protects again");
    }

    #[test]
    fn pvu_and_rvu_are_busy_for_five_lsi_cycles() {
        let mut w = running();
        w.write(KR, KEY_UNLOCK, 0).unwrap();
        w.write(PR, 4, 0).unwrap();
        w.write(RLR, 100, 0).unwrap();
        assert_eq!(w.read(SR, UPDATE_TIME - 1), Ok(0b11));
        assert_eq!(w.read(PR, UPDATE_TIME - 1), Ok(0), "old value until the update completes");
        assert!(w.write(PR, 5, 1).is_err(), "write while PVU is set");
        assert_eq!(w.read(SR, UPDATE_TIME), Ok(0));
        assert_eq!(w.read(PR, UPDATE_TIME), Ok(4));
        assert_eq!(w.read(RLR, UPDATE_TIME), Ok(100));
    }

    #[test]
    fn first_period_after_start_counts_from_0xfff() {
        let mut w = running();
        w.write(KR, KEY_UNLOCK, 0).unwrap();
        w.write(PR, 0, 0).unwrap();
        w.write(RLR, 9, 0).unwrap();
        w.write(KR, KEY_START, UPDATE_TIME).unwrap();
        // 4096 ticks of /4 at 32 kHz: 512 ms (RM0368 timeout table, maximum at /4).
        assert_eq!(w.next_event(), Some(UPDATE_TIME + 4096 * 4 * LSI_CYCLE));
        assert!(!w.expired(UPDATE_TIME + 4096 * 4 * LSI_CYCLE - 1));
        assert!(w.expired(UPDATE_TIME + 4096 * 4 * LSI_CYCLE));
        // After a reload: RLR + 1 = 10 ticks.
        w.write(KR, KEY_RELOAD, 1_000_000).unwrap();
        assert_eq!(w.next_event(), Some(1_000_000 + 10 * 4 * LSI_CYCLE));
        assert!((w.timeout_s().unwrap() - 10.0 * 4.0 / 32_000.0).abs() < 1e-12);
    }

    #[test]
    fn minimum_timeout_is_one_tick() {
        let mut w = running();
        w.write(KR, KEY_UNLOCK, 0).unwrap();
        w.write(RLR, 0, 0).unwrap();
        w.write(KR, KEY_START, UPDATE_TIME).unwrap();
        w.write(KR, KEY_RELOAD, UPDATE_TIME).unwrap();
        // 0.125 ms = 4 LSI cycles.
        assert_eq!(w.next_event(), Some(UPDATE_TIME + 4 * LSI_CYCLE));
    }

    #[test]
    fn hal_50ms_setup_gives_56ms_after_the_first_feed() {
        let mut w = running();
        start_like_the_hal(&mut w, 0);
        // Until the prescaler update lands the counter runs at /4, then at /256 from 0xFFF - 1.
        let first = w.next_event().unwrap();
        let expected = UPDATE_TIME + (0xFFE + 1) * 256 * LSI_CYCLE;
        assert_eq!(first, expected);
        assert!((w.timeout_s().unwrap() - 0.056).abs() < 1e-9, "(6 + 1) x 256 / 32 kHz");
        let feed = 1_000_000;
        w.write(KR, KEY_RELOAD, feed).unwrap();
        assert_eq!(w.next_event(), Some(feed + 7 * 256 * LSI_CYCLE));
    }

    #[test]
    fn the_watchdog_cannot_be_stopped() {
        let mut w = running();
        w.write(KR, KEY_START, 0).unwrap();
        for key in [KEY_UNLOCK, 0, KEY_START, 0xFFFF] {
            w.write(KR, key, 10).unwrap();
            assert!(w.is_started());
        }
        assert!(w.write(KR, 0x1_0000, 10).is_err(), "reserved bits");
        assert!(w.write(SR, 0, 10).is_err());
    }

    #[test]
    fn advance_applies_a_prescaler_change_to_the_running_counter() {
        let mut w = running();
        w.write(KR, KEY_START, 0).unwrap();
        w.write(KR, KEY_UNLOCK, 0).unwrap();
        w.write(PR, 1, 0).unwrap();
        let predicted = w.next_event().unwrap();
        w.advance(UPDATE_TIME);
        assert_eq!(w.next_event(), Some(predicted), "prediction and lazy update agree");
        // 5 LSI cycles at /4 is one whole tick: 0xFFE left, then /8.
        assert_eq!(predicted, UPDATE_TIME + 0xFFF * 8 * LSI_CYCLE);
    }

    /// Rule (RM0368 §15.3 and the IWDG_SR note; libopencm3 and MicroPython hit it): with the
    /// LSI off, as after reset, PR/RLR never land, so waiting for SR = 0 before the start key
    /// spins for ever. The wrong sequence, played for a whole second.
    #[test]
    fn waiting_for_pvu_before_the_start_key_hangs_with_the_lsi_off() {
        let mut w = Iwdg::new();
        w.write(KR, KEY_UNLOCK, 0).unwrap();
        w.write(PR, 1, 0).unwrap();
        w.write(RLR, 199, 0).unwrap();
        let one_second = TIME_HZ;
        for t in (0..one_second).step_by(LSI_CYCLE as usize) {
            assert_eq!(w.read(SR, t), Ok(0b11), "PVU/RVU cleared at {t} with no LSI");
        }
        assert!(!w.is_started());
        assert_eq!(w.read(PR, one_second), Ok(0), "the old prescaler stays");
    }

    /// ST's order (`HAL_IWDG_Init`): start key (the LSI starts), unlock, PR, RLR, then poll SR:
    /// the values land 5 LSI cycles after the LSI is stable, and the counter only counts once
    /// it runs.
    #[test]
    fn the_start_key_first_lets_the_values_land_once_the_lsi_runs() {
        let mut w = Iwdg::new();
        w.write(KR, KEY_START, 0).unwrap();
        // What the board does on the start key: the RCC forces the LSI on (40 µs start-up).
        let lsi = TIME_HZ / 25_000;
        w.set_lsi(Some(lsi));
        w.write(KR, KEY_UNLOCK, 0).unwrap();
        w.write(PR, 1, 0).unwrap();
        w.write(RLR, 199, 0).unwrap();
        assert_eq!(w.read(SR, lsi + UPDATE_TIME - 1), Ok(0b11));
        assert_eq!(w.read(SR, lsi + UPDATE_TIME), Ok(0));
        w.write(KR, KEY_RELOAD, lsi + UPDATE_TIME).unwrap();
        assert_eq!(w.next_event(), Some(lsi + UPDATE_TIME + 200 * 8 * LSI_CYCLE), "50 ms after the reload");
        assert!((w.timeout_s().unwrap() - 0.050).abs() < 1e-12);
    }

    /// The LSI at either end of DS9716's range: the timeout and the update time scale with it
    /// (the firmware's 200 counts at /8: 94 ms at 17 kHz, 34 ms at 47 kHz).
    #[test]
    fn the_timeout_follows_the_lsi_across_its_range() {
        for (hz, timeout_ms) in [(LSI_MIN_HZ, 94.1), (LSI_MAX_HZ, 34.0)] {
            let mut w = Iwdg::new();
            w.set_lsi_hz(hz);
            w.set_lsi(Some(0));
            w.write(KR, KEY_START, 0).unwrap();
            w.write(KR, KEY_UNLOCK, 0).unwrap();
            w.write(PR, 1, 0).unwrap();
            w.write(RLR, 199, 0).unwrap();
            let update = 5 * TIME_HZ / hz;
            assert_eq!(w.read(SR, update - 10), Ok(0b11), "{hz} Hz");
            assert_eq!(w.read(SR, update + 10), Ok(0), "{hz} Hz");
            w.write(KR, KEY_RELOAD, update + 10).unwrap();
            let expiry_ms = (w.next_event().unwrap() - (update + 10)) as f64 * 1e3 / TIME_HZ as f64;
            assert!((expiry_ms - timeout_ms).abs() < 0.1, "{hz} Hz: {expiry_ms:.2} ms");
            assert!((w.timeout_s().unwrap() * 1e3 - timeout_ms).abs() < 0.1);
        }
    }

    /// The counter does not move while the LSI starts: the first period is counted from the
    /// oscillator's start, not from the key.
    #[test]
    fn the_counter_waits_for_the_lsi() {
        let mut w = Iwdg::new();
        w.write(KR, KEY_START, 0).unwrap();
        assert_eq!(w.next_event(), None, "no LSI yet: no expiry");
        w.set_lsi(Some(1000));
        assert_eq!(w.next_event(), Some(1000 + 4096 * 4 * LSI_CYCLE));
    }
}
