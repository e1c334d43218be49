//! FLASH interface (RM0368 §3) at 0x4002_3C00, and the flash memory behind it: the
//! STM32F401CC's 256 KB (RM0368 §3.3 table 5: sectors 0–3 of 16 KB, 4 of 64 KB, 5 of 128 KB).
//!
//! **ACR.** LATENCY, PRFTEN, ICEN, DCEN, ICRST and DCRST are stored; [`Flash::check_wait_states`]
//! checks LATENCY against RM0368's table for the board's supply (the timing profiles read ACR
//! through the bus, see `crate::timing`).
//!
//! **Unlocking (RM0368 §3.5.1, §3.8.2 FLASH_KEYR).** CR is locked at reset. KEY1 = 0x4567_0123
//! then KEY2 = 0xCDEF_89AB unlock it; "any wrong sequence will lock up the FLASH_CR register until
//! the next reset" and a wrong key is a bus error (a HardFault; reported to the machine through
//! [`Flash::take_bus_error`]). A CR write while locked is ignored (counted in
//! [`Flash::ignored_writes`]); LOCK written 1 locks it again. A KEYR write while unlocked is not
//! described by the RM and is refused.
//!
//! **Erase (RM0368 §3.5.3).** CR.SER with SNB (0..5), PSIZE, then STRT: BSY sets, the sector goes
//! to 0xFF after DS9716's erase time (table "Flash memory programming": 16 KB 400/300/250 ms
//! typical at x8/x16/x32, 800/600/500 ms maximum; 64 KB 1200/700/550 and 2400/1400/1100 ms;
//! 128 KB 2/1.3/1 s and 4/2.6/2 s), then BSY clears and EOP sets (only with EOPIE, RM0368 §3.8.4).
//! MER erases the whole memory (4/5.5/8 s typical at x32/x16/x8, twice that maximum; the
//! table's mass-erase line is for the whole array). STRT with both SER and MER: the RM says
//! neither erase is performed and nothing about the flags, so it is refused; so is STRT with
//! neither, SNB beyond sector 5, and PSIZE x64 (it needs VPP, which the F401 has not).
//!
//! **Program (RM0368 §3.5.4).** With CR.PG set (and no SER/MER), a CPU write into the flash range
//! programs it: BSY for DS9716's word programming time (16 µs typical, 100 µs maximum; a byte or
//! half-word access is taken to cost the same), then the memory holds old AND new: "successive
//! write operations are possible without the need of an erase operation when changing bits from
//! 1 to 0. Writing 1 requires a Flash memory erase operation." So programming a word that was
//! not erased sets no error on the F401: it leaves the AND of both (a program over non-erased
//! data is the firmware's bug to catch by reading back). Errors (RM0368 §3.8.4 FLASH_SR), and the
//! write then changes nothing:
//! - PGSERR: a write into flash with PG clear (the control register "not correctly
//!   configured"), including while locked, or with PG and SER/MER together (an assumption: the
//!   RM lists no other case);
//! - PGPERR (FLASH_SR bit 6: "the size of the access ... does not correspond to the parallelism
//!   configuration PSIZE"): an access size other than PSIZE (a word write with PSIZE x8, a byte
//!   with x32). An unaligned store is split by the Cortex-M4 into aligned byte and halfword
//!   transfers (ARMv7-M A3.2.1), so the interface never sees it unaligned: an unaligned word at
//!   x32 is halfwords or bytes, PGPERR. A split whose transfers would each program (an
//!   unaligned word at x16 or x8) is refused: successive programs from one store are not
//!   modelled;
//! - PGAERR (bit 5: "the data to program cannot be contained in the same 128-bit Flash memory
//!   row") never: only an x64 access could cross a row, and x64 needs VPP, which the F401 has
//!   not;
//! - OPERR additionally, only with ERRIE; WRPERR never (the option bytes, all sectors
//!   unprotected at delivery, are not modelled).
//!
//! SR's flags clear by writing 1 (rc_w1); BSY is read-only.
//!
//! **The stall (RM0368 §3.5, "a Flash memory read during a write/erase operation stalls the
//! bus").** While BSY, the machine holds the CPU at its next instruction fetch from flash
//! ([`Flash::busy_until`]); DMA and the peripherals run on. A store into flash or a CR write
//! while BSY (RM0368 §3.8.5: "any attempt to write to it with the BSY bit set will cause the AHB
//! bus to stall until the BSY bit is cleared") waits on the bus: the machine completes it at
//! BSY's end, so the model itself refuses one that reaches it while busy. Data reads from flash
//! stall too: one in a block that runs from flash waits with the block's fetch, and a literal
//! load after the programming store in the store's own block waits for BSY's end (the machine
//! looks for one when the store starts an operation). A data read from flash by code in RAM
//! through a register is not seen (the machine has no read hook on flash; the firmware runs no
//! code from RAM).
//!
//! **The data cache (RM0368 §3.4, FLASH_ACR DCRST).** An operation does not update the ART's
//! data cache: words it held from before read stale until it is emptied (DCRST, written with
//! DCEN off). The model takes every word an operation changed as cached whenever DCEN has been
//! set since the last DCRST (an assumption: the cache holds 8 lines of 128 bits, and which ones
//! is not modelled), and the machine's view of the range keeps the old words until DCRST or a
//! reset ([`Flash::stale_ranges`]), so a missing flush shows on any read-back.
//!
//! **A power cut** ([`Flash::power_cut`]) or a system reset during an operation leaves the
//! memory part-way: an erase is modelled as a sweep through the sector's words in address order
//! (the words before the cut instant erased, the word under erase with some of its 0 bits raised
//! and the rest still 0, the words after it untouched); a program as the word's 1→0 bits
//! cleared one after another (some cleared, the rest not yet). Real flash erases a sector's
//! cells together and leaves them in between; the sweep is an assumption that puts every case a
//! storage scheme must survive (erased, half-erased, intact words in one sector) at a fraction
//! of the operation the test chooses.
//!
//! Layout and reset values from the `stm32f4` 0.16 PAC (`stm32f401/flash/*.rs`: CR resets to
//! 0x8000_0000, SR to 0). OPTKEYR and OPTCR (option bytes) are not modelled.

use super::{Time, Unmodelled};

/// Base address of the flash interface registers (RM0368 memory map).
pub const BASE: u32 = 0x4002_3C00;
/// Peripheral name used in error messages.
pub const NAME: &str = "FLASH";

const ACR: u32 = 0x00;
const KEYR: u32 = 0x04;
const OPTKEYR: u32 = 0x08;
const SR: u32 = 0x0C;
const CR: u32 = 0x10;
const OPTCR: u32 = 0x14;

pub const KEY1: u32 = 0x4567_0123;
pub const KEY2: u32 = 0xCDEF_89AB;

pub const SR_EOP: u32 = 1 << 0;
pub const SR_OPERR: u32 = 1 << 1;
pub const SR_WRPERR: u32 = 1 << 4;
pub const SR_PGAERR: u32 = 1 << 5;
pub const SR_PGPERR: u32 = 1 << 6;
pub const SR_PGSERR: u32 = 1 << 7;
pub const SR_RDERR: u32 = 1 << 8;
pub const SR_BSY: u32 = 1 << 16;
const SR_RC_W1: u32 = SR_EOP | SR_OPERR | SR_WRPERR | SR_PGAERR | SR_PGPERR | SR_PGSERR | SR_RDERR;

pub const CR_PG: u32 = 1 << 0;
pub const CR_SER: u32 = 1 << 1;
pub const CR_MER: u32 = 1 << 2;
pub const CR_SNB_SHIFT: u32 = 3;
const CR_SNB: u32 = 0xF << CR_SNB_SHIFT;
pub const CR_PSIZE_SHIFT: u32 = 8;
const CR_PSIZE: u32 = 0b11 << CR_PSIZE_SHIFT;
pub const CR_STRT: u32 = 1 << 16;
pub const CR_EOPIE: u32 = 1 << 24;
pub const CR_ERRIE: u32 = 1 << 25;
pub const CR_LOCK: u32 = 1 << 31;
const CR_FIELDS: u32 = CR_PG | CR_SER | CR_MER | CR_SNB | CR_PSIZE | CR_STRT | CR_EOPIE | CR_ERRIE | CR_LOCK;

/// The flash memory's address and size (the STM32F401CC's 256 KB).
pub const MEMORY_BASE: u32 = 0x0800_0000;
pub const MEMORY_SIZE: usize = 256 * 1024;
/// The sectors as (offset, size) (RM0368 §3.3 table 5, the first six: 256 KB).
pub const SECTORS: [(u32, u32); 6] =
    [(0, 0x4000), (0x4000, 0x4000), (0x8000, 0x4000), (0xC000, 0x4000), (0x1_0000, 0x1_0000), (0x2_0000, 0x2_0000)];

/// Which of DS9716's columns the operations take.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FlashTiming {
    #[default]
    Typical,
    Maximum,
}

/// An operation in progress.
#[derive(Clone, Debug)]
struct Operation {
    /// First byte and length of the range it changes.
    offset: u32,
    len: u32,
    /// The values the range ends with (0xFF for an erase; old AND new for a program).
    target: Vec<u8>,
    erase: bool,
    start: Time,
    end: Time,
}

/// The key sequence's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Keys {
    Locked,
    Key1Written,
    Unlocked,
    /// A wrong key: locked until the next reset.
    LockedUntilReset,
}

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

/// The flash interface model, with the memory it programs.
#[derive(Clone, Debug)]
pub struct Flash {
    acr: u32,
    /// CR without LOCK and STRT.
    cr: u32,
    keys: Keys,
    /// SR's EOP and error flags.
    flags: u32,
    op: Option<Operation>,
    memory: Vec<u8>,
    /// Ranges of `memory` changed since the machine last copied them: (offset, length).
    changed: Vec<(u32, u32)>,
    timing: FlashTiming,
    bus_error: Option<&'static str>,
    ignored_writes: u32,
    /// The last instant the model saw (for a reset, which comes without one).
    seen: Time,
    /// Counts completed or cut operations, so a caller can tell the memory changed.
    generation: u64,
    /// A power cut armed for an operation to come (see [`Flash::arm_power_cut`]).
    armed_cut: Option<ArmedCut>,
    /// When the armed cut falls, once its operation has started.
    cut_at: Option<Time>,
    power_lost: bool,
    /// When CR was unlocked, each time (KEY2 accepted): where a save began.
    unlocks: Vec<Time>,
    /// Each erase started: (start, end as planned).
    erases: Vec<(Time, Time)>,
    /// DCEN has been set since the data cache was last emptied (DCRST) or reset: the cache may
    /// hold words of the flash.
    dcache_used: bool,
    /// Ranges an operation changed while the data cache may have held them, with the words they
    /// held before (what a data read still sees until DCRST): (offset, old bytes).
    stale: Vec<(u32, Vec<u8>)>,
}

/// A power cut armed at a fraction of the `nth` operation of a kind from now on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmedCut {
    pub erase: bool,
    pub nth: u32,
    pub fraction: f64,
}

impl Default for Flash {
    fn default() -> Self {
        Flash::new()
    }
}

impl Flash {
    /// Power-on state: ACR = 0 (zero wait states, caches and prefetch off), CR locked, the memory
    /// erased.
    pub fn new() -> Self {
        Flash {
            acr: 0,
            cr: 0,
            keys: Keys::Locked,
            flags: 0,
            op: None,
            memory: vec![0xFF; MEMORY_SIZE],
            changed: Vec::new(),
            timing: FlashTiming::Typical,
            bus_error: None,
            ignored_writes: 0,
            seen: 0,
            generation: 0,
            armed_cut: None,
            cut_at: None,
            power_lost: false,
            unlocks: Vec::new(),
            erases: Vec::new(),
            dcache_used: false,
            stale: Vec::new(),
        }
    }

    /// The registers after a system reset: an operation in progress is cut where it stands;
    /// the memory keeps what it holds.
    pub fn system_reset(&mut self) {
        self.power_cut(self.seen);
        let memory = std::mem::take(&mut self.memory);
        let (timing, generation, armed_cut) = (self.timing, self.generation, self.armed_cut);
        let (unlocks, erases) = (std::mem::take(&mut self.unlocks), std::mem::take(&mut self.erases));
        // The reset empties the data cache: what it held stale is read from the memory again.
        let refresh: Vec<(u32, u32)> =
            self.stale.iter().map(|(o, old)| (*o, old.len() as u32)).chain(self.changed.iter().copied()).collect();
        *self = Flash::new();
        self.unlocks = unlocks;
        self.erases = erases;
        self.changed = refresh;
        self.memory = memory;
        self.timing = timing;
        self.generation = generation;
        self.armed_cut = armed_cut;
    }

    /// Arms a power cut at `fraction` (0..1) of the `nth` (1 = the next) erase, or program,
    /// that starts from now on: the board loses power there ([`Flash::take_power_lost`]).
    pub fn arm_power_cut(&mut self, cut: ArmedCut) {
        self.armed_cut = Some(cut);
    }

    /// Whether an armed power cut fell (once).
    pub fn take_power_lost(&mut self) -> bool {
        std::mem::take(&mut self.power_lost)
    }

    /// An operation starts: the armed cut, if it is this one, gets its instant.
    fn starting(&mut self, op: Operation) {
        if op.erase {
            self.erases.push((op.start, op.end));
        }
        if let Some(cut) = self.armed_cut.as_mut().filter(|c| c.erase == op.erase) {
            cut.nth = cut.nth.saturating_sub(1);
            if cut.nth == 0 {
                let span = (op.end - op.start) as f64;
                self.cut_at = Some(op.start + (span * cut.fraction.clamp(0.0, 1.0)).round() as Time);
                self.armed_cut = None;
            }
        }
        self.op = Some(op);
    }

    /// Moves the end of the operation in progress to `end` (not before its start): a test's way
    /// to end an erase at a chosen instant, DS9716 giving only a typical and a maximum time.
    pub fn retime_operation(&mut self, end: Time) {
        if let Some(op) = self.op.as_mut() {
            op.end = end.max(op.start + 1);
            if let Some(last) = self.erases.last_mut().filter(|e| op.erase && e.0 == op.start) {
                last.1 = op.end;
            }
        }
    }

    /// Takes DS9716's typical or maximum times from now on.
    pub fn set_timing(&mut self, timing: FlashTiming) {
        self.timing = timing;
    }

    /// The memory's contents (offset 0 at 0x0800_0000).
    pub fn memory(&self) -> &[u8] {
        &self.memory
    }

    /// Replaces the memory's contents (a file saved from an earlier run); a shorter `bytes`
    /// leaves the rest erased.
    pub fn load_memory(&mut self, bytes: &[u8]) {
        self.memory = vec![0xFF; MEMORY_SIZE];
        let n = bytes.len().min(MEMORY_SIZE);
        self.memory[..n].copy_from_slice(&bytes[..n]);
        self.changed.push((0, MEMORY_SIZE as u32));
        self.generation += 1;
    }

    /// Marks `len` bytes at `offset` for the machine to copy again (a store it let through).
    pub fn touch(&mut self, offset: u32, len: u32) {
        let end = (offset + len).min(MEMORY_SIZE as u32);
        if offset < end {
            self.changed.push((offset, end - offset));
        }
    }

    /// Completed (or cut) operations so far: it changes when the memory did.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// The ranges changed since the last call, with their contents, for the machine's copy.
    /// A data read sees a stale range's old words (the data cache's) until DCRST; the earliest
    /// stale copy of a byte is the one the cache holds.
    pub fn take_changes(&mut self) -> Vec<(u32, Vec<u8>)> {
        let changed = std::mem::take(&mut self.changed);
        changed
            .into_iter()
            .map(|(o, n)| {
                let mut bytes = self.memory[o as usize..(o + n) as usize].to_vec();
                for (so, old) in self.stale.iter().rev() {
                    let from = o.max(*so);
                    let to = (o + n).min(*so + old.len() as u32);
                    if from < to {
                        bytes[(from - o) as usize..(to - o) as usize].copy_from_slice(&old[(from - so) as usize..(to - so) as usize]);
                    }
                }
                (o, bytes)
            })
            .collect()
    }

    /// Ranges whose old words the data cache may still return (see [`Flash::take_changes`]).
    pub fn stale_ranges(&self) -> Vec<(u32, u32)> {
        self.stale.iter().map(|(o, old)| (*o, old.len() as u32)).collect()
    }

    /// Until when BSY stays set (None: idle).
    pub fn busy_until(&self) -> Option<Time> {
        self.op.as_ref().map(|op| op.end)
    }

    /// The operation in progress: (start, end, erase?).
    pub fn operation(&self) -> Option<(Time, Time, bool)> {
        self.op.as_ref().map(|op| (op.start, op.end, op.erase))
    }

    /// A bus error one of the last accesses caused (a wrong key), once.
    pub fn take_bus_error(&mut self) -> Option<&'static str> {
        self.bus_error.take()
    }

    /// The instants CR was unlocked (the key sequence's KEY2), since power-on.
    pub fn unlocks(&self) -> &[Time] {
        &self.unlocks
    }

    /// Each erase started since power-on: (start, end as planned, a power cut aside).
    pub fn erases(&self) -> &[(Time, Time)] {
        &self.erases
    }

    /// CR writes ignored because CR was locked.
    pub fn ignored_writes(&self) -> u32 {
        self.ignored_writes
    }

    /// The FLASH interrupt line: EOP·EOPIE + OPERR·ERRIE.
    pub fn irq_line(&self) -> bool {
        (self.flags & SR_EOP != 0 && self.cr & CR_EOPIE != 0) || (self.flags & SR_OPERR != 0 && self.cr & CR_ERRIE != 0)
    }

    /// End of the operation in progress, or an armed power cut.
    pub fn next_event(&self) -> Option<Time> {
        [self.busy_until(), self.cut_at].into_iter().flatten().min()
    }

    /// Completes the operation that ends by `now`, or cuts the power where an armed cut falls.
    pub fn advance(&mut self, now: Time) {
        self.seen = self.seen.max(now);
        if let Some(at) = self.cut_at.filter(|&t| t <= now) {
            self.cut_at = None;
            self.cut(at);
            self.power_lost = true;
        }
        if let Some(op) = self.op.take_if(|op| op.end <= now) {
            let range = op.offset as usize..(op.offset + op.len) as usize;
            if self.dcache_used {
                self.stale.push((op.offset, self.memory[range.clone()].to_vec()));
            }
            self.memory[range].copy_from_slice(&op.target);
            self.changed.push((op.offset, op.len));
            self.generation += 1;
            if self.cr & CR_EOPIE != 0 {
                self.flags |= SR_EOP;
            }
        }
    }

    /// The power fails at `now`: an operation in progress stops where it stands (see the
    /// module's comment for what that leaves).
    pub fn power_cut(&mut self, now: Time) {
        self.advance(now);
        self.cut(now);
    }

    fn cut(&mut self, now: Time) {
        let Some(op) = self.op.take() else { return };
        let span = (op.end - op.start).max(1) as f64;
        let fraction = ((now.saturating_sub(op.start)) as f64 / span).clamp(0.0, 1.0);
        let words = (op.len / 4).max(1) as usize;
        let range = op.offset as usize..(op.offset + op.len) as usize;
        let mut cells: Vec<u8> = self.memory[range.clone()].to_vec();
        if op.erase {
            let swept = fraction * words as f64;
            let done = swept.floor() as usize;
            for b in cells.iter_mut().take(4 * done) {
                *b = 0xFF;
            }
            if let Some(word) = cells.get_mut(4 * done..4 * done + 4) {
                let old = u32::from_le_bytes([word[0], word[1], word[2], word[3]]);
                let raised = part_of_bits(!old, swept - done as f64);
                word.copy_from_slice(&(old | raised).to_le_bytes());
            }
        } else {
            for (cell, target) in cells.chunks_mut(4).zip(op.target.chunks(4)) {
                let mut old = [0xFF; 4];
                old[..cell.len()].copy_from_slice(cell);
                let mut new = [0xFF; 4];
                new[..target.len()].copy_from_slice(target);
                let (old, new) = (u32::from_le_bytes(old), u32::from_le_bytes(new));
                let cleared = part_of_bits(old & !new, fraction);
                let now_bytes = (old & !cleared).to_le_bytes();
                cell.copy_from_slice(&now_bytes[..cell.len()]);
            }
        }
        self.memory[range].copy_from_slice(&cells);
        self.changed.push((op.offset, op.len));
        self.generation += 1;
    }

    fn psize_bytes(&self) -> u32 {
        1 << ((self.cr & CR_PSIZE) >> CR_PSIZE_SHIFT)
    }

    fn erase_time_s(&self, sector_bytes: Option<u32>) -> f64 {
        // DS9716 "Flash memory programming": [x8, x16, x32] typical, doubled for the maximum.
        let typical = match sector_bytes {
            Some(0x4000) => [0.4, 0.3, 0.25],
            Some(0x1_0000) => [1.2, 0.7, 0.55],
            Some(_) => [2.0, 1.3, 1.0],
            None => [8.0, 5.5, 4.0],
        };
        let column = ((self.cr & CR_PSIZE) >> CR_PSIZE_SHIFT).min(2) as usize;
        let t = typical[column];
        match self.timing {
            FlashTiming::Typical => t,
            FlashTiming::Maximum => 2.0 * t,
        }
    }

    fn program_time_s(&self) -> f64 {
        match self.timing {
            FlashTiming::Typical => 16e-6,
            FlashTiming::Maximum => 100e-6,
        }
    }

    /// A CPU write of `size` bytes at `offset` into the flash memory.
    pub fn write_memory(&mut self, offset: u32, size: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.advance(now);
        let name = format!("flash {:#010x}", MEMORY_BASE + offset);
        if self.op.is_some() {
            return Err(Unmodelled::new(name, "a write while BSY: the bus stalls until the operation ends (not modelled)"));
        }
        let unlocked = self.keys == Keys::Unlocked;
        if offset as usize + size as usize > MEMORY_SIZE {
            return Err(Unmodelled::new(name, "a store past the end of the flash memory"));
        }
        // The Cortex-M4 splits an unaligned store into aligned byte and halfword transfers
        // (ARMv7-M A3.2.1): the interface sees those, never an unaligned one.
        let transfers = aligned_transfers(offset, size);
        let error = if !unlocked || self.cr & CR_PG == 0 || self.cr & (CR_SER | CR_MER) != 0 {
            Some(SR_PGSERR)
        } else if transfers.iter().all(|&(_, n)| n != self.psize_bytes()) {
            Some(SR_PGPERR)
        } else if transfers.len() > 1 {
            return Err(Unmodelled::new(
                name,
                format!("an unaligned {size}-byte store split into transfers of which some match PSIZE: successive programs from one store are not modelled"),
            ));
        } else {
            None
        };
        if let Some(flag) = error {
            self.flags |= flag;
            if self.cr & CR_ERRIE != 0 {
                self.flags |= SR_OPERR;
            }
            return Ok(());
        }
        let range = offset as usize..(offset + size) as usize;
        let target: Vec<u8> = self.memory[range].iter().zip(value.to_le_bytes()).map(|(&old, new)| old & new).collect();
        let end = now + super::time_from_s(self.program_time_s());
        self.starting(Operation { offset, len: size, target, erase: false, start: now, end });
        Ok(())
    }

    fn write_keyr(&mut self, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.keys = match (self.keys, value) {
            (Keys::Locked, KEY1) => Keys::Key1Written,
            (Keys::Key1Written, KEY2) => {
                self.unlocks.push(now);
                Keys::Unlocked
            }
            (Keys::Unlocked, _) => {
                return Err(Unmodelled::new("FLASH.KEYR", format!("write of {value:#010x} while unlocked: not described by RM0368")))
            }
            _ => {
                self.bus_error = Some("FLASH_KEYR written with a wrong key (bus error; CR locked until reset)");
                Keys::LockedUntilReset
            }
        };
        Ok(())
    }

    fn write_cr(&mut self, value: u32, now: Time) -> Result<(), Unmodelled> {
        Unmodelled::check_bits("FLASH.CR", value, CR_FIELDS)?;
        if self.keys != Keys::Unlocked {
            self.ignored_writes = self.ignored_writes.saturating_add(1);
            return Ok(());
        }
        if self.op.is_some() {
            return Err(Unmodelled::new("FLASH.CR", "written while BSY: the bus stalls until the operation ends (not modelled)"));
        }
        if value & CR_PSIZE == CR_PSIZE {
            return Err(Unmodelled::new("FLASH.CR", "PSIZE x64 needs an external VPP, which the F401 does not have"));
        }
        self.cr = value & !(CR_LOCK | CR_STRT);
        if value & CR_LOCK != 0 {
            self.keys = Keys::Locked;
        }
        if value & CR_STRT == 0 {
            return Ok(());
        }
        let (offset, len, sector) = match (value & CR_SER != 0, value & CR_MER != 0) {
            (true, false) => {
                let snb = (value & CR_SNB) >> CR_SNB_SHIFT;
                let Some(&(offset, len)) = SECTORS.get(snb as usize) else {
                    return Err(Unmodelled::new("FLASH.CR", format!("STRT for sector {snb}: the STM32F401CC has sectors 0 to 5")));
                };
                (offset, len, Some(len))
            }
            (false, true) => (0, MEMORY_SIZE as u32, None),
            (true, true) => {
                return Err(Unmodelled::new("FLASH.CR", "STRT with SER and MER both set: RM0368 performs neither erase and names no flag"))
            }
            (false, false) => return Err(Unmodelled::new("FLASH.CR", "STRT with neither SER nor MER: no operation")),
        };
        let end = now + super::time_from_s(self.erase_time_s(sector));
        self.starting(Operation { offset, len, target: vec![0xFF; len as usize], erase: true, start: now, end });
        Ok(())
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

    pub fn read(&mut self, offset: u32, now: Time) -> Result<u32, Unmodelled> {
        self.advance(now);
        match offset {
            ACR => Ok(self.acr & !ACR_ICRST),
            KEYR => Ok(0),
            SR => Ok(self.flags | if self.op.is_some() { SR_BSY } else { 0 }),
            CR => {
                let lock = if self.keys == Keys::Unlocked { 0 } else { CR_LOCK };
                let strt = if self.op.as_ref().is_some_and(|op| op.erase) { CR_STRT } else { 0 };
                Ok(self.cr | lock | strt)
            }
            _ => Err(Unmodelled::offset(NAME, offset, false)),
        }
    }

    pub fn write(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.advance(now);
        match offset {
            KEYR => self.write_keyr(value, now),
            SR => {
                Unmodelled::check_bits("FLASH.SR", value, SR_RC_W1 | SR_BSY)?;
                self.flags &= !(value & SR_RC_W1);
                Ok(())
            }
            CR => self.write_cr(value, now),
            OPTKEYR | OPTCR => Err(Unmodelled::new("FLASH.OPTCR", "the option bytes are not modelled")),
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
                if value & ACR_DCRST != 0 && value & ACR_DCEN == 0 {
                    // The cache emptied: every stale range reads from the memory again.
                    let refreshed: Vec<(u32, u32)> = self.stale_ranges();
                    self.changed.extend(refreshed);
                    self.stale.clear();
                    self.dcache_used = false;
                }
                self.dcache_used |= value & ACR_DCEN != 0;
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

    fn next_event(&self) -> Option<Time> {
        Flash::next_event(self)
    }

    fn advance(&mut self, now: Time, _clocks: super::Clocks) {
        Flash::advance(self, now)
    }

    fn irq_line(&self, _line: usize) -> bool {
        Flash::irq_line(self)
    }
}

/// The aligned bus transfers a Cortex-M4 makes of a store of `size` bytes at `offset`:
/// (offset, size) each. Aligned: the store itself; otherwise bytes and halfwords, each
/// aligned (ARMv7-M A3.2.1: unaligned word and halfword accesses are split).
fn aligned_transfers(offset: u32, size: u32) -> Vec<(u32, u32)> {
    if offset % size == 0 {
        return vec![(offset, size)];
    }
    let mut out = Vec::new();
    let (mut at, end) = (offset, offset + size);
    while at < end {
        let n = if at % 2 == 0 && end - at >= 2 { 2 } else { 1 };
        out.push((at, n));
        at += n;
    }
    out
}

/// The lowest `fraction` of the set bits of `bits` (rounded down): the bits an interrupted
/// operation has flipped so far.
fn part_of_bits(bits: u32, fraction: f64) -> u32 {
    let n = (f64::from(bits.count_ones()) * fraction.clamp(0.0, 1.0)).floor() as u32;
    let mut out = 0;
    let mut rest = bits;
    for _ in 0..n {
        let low = rest & rest.wrapping_neg();
        out |= low;
        rest &= !low;
    }
    out
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
    fn the_option_bytes_and_reserved_bits_are_unmodelled() {
        let mut f = Flash::new();
        assert!(f.read(OPTCR, 0).is_err(), "OPTCR");
        assert!(f.write(OPTKEYR, 0x0819_2A3B, 0).is_err(), "OPTKEYR");
        assert!(f.write(ACR, 1 << 13, 0).is_err(), "reserved bit");
    }

    use crate::periph::{time_from_s, TIME_HZ};

    const X32: u32 = 0b10 << CR_PSIZE_SHIFT;
    const X8: u32 = 0;
    const MS: Time = TIME_HZ / 1000;
    const US: Time = TIME_HZ / 1_000_000;

    fn unlocked() -> Flash {
        let mut f = Flash::new();
        f.write(KEYR, KEY1, 0).unwrap();
        f.write(KEYR, KEY2, 0).unwrap();
        f
    }

    fn word(f: &Flash, offset: usize) -> u32 {
        u32::from_le_bytes(f.memory()[offset..offset + 4].try_into().unwrap())
    }

    /// Fills sector `snb` with a pattern (as an earlier program would have).
    fn fill(f: &mut Flash, snb: usize, pattern: u32) {
        let (o, n) = SECTORS[snb];
        for w in f.memory[o as usize..(o + n) as usize].chunks_mut(4) {
            w.copy_from_slice(&pattern.to_le_bytes());
        }
    }

    #[test]
    fn the_key_sequence_unlocks_cr_and_lock_locks_it_again() {
        let mut f = Flash::new();
        assert_eq!(f.read(CR, 0), Ok(CR_LOCK), "reset value 0x8000_0000");
        f.write(KEYR, KEY1, 0).unwrap();
        f.write(KEYR, KEY2, 0).unwrap();
        assert_eq!(f.read(CR, 0), Ok(0));
        assert_eq!(f.take_bus_error(), None);
        f.write(CR, CR_LOCK, 0).unwrap();
        assert_eq!(f.read(CR, 0), Ok(CR_LOCK));
    }

    /// Rule (RM0368 §3.5.1): a wrong key is a bus error and locks CR until the next reset: the
    /// right sequence after it does not unlock.
    #[test]
    fn a_wrong_key_is_a_bus_error_and_locks_cr_until_reset() {
        for wrong in [[KEY2, KEY1], [KEY1, KEY1], [0x1234, KEY2]] {
            let mut f = Flash::new();
            f.write(KEYR, wrong[0], 0).unwrap();
            f.write(KEYR, wrong[1], 0).unwrap();
            assert!(f.take_bus_error().is_some(), "{wrong:x?}");
            f.write(KEYR, KEY1, 0).unwrap();
            f.write(KEYR, KEY2, 0).unwrap();
            assert_eq!(f.read(CR, 0).unwrap() & CR_LOCK, CR_LOCK, "still locked");
            f.system_reset();
            f.write(KEYR, KEY1, 0).unwrap();
            f.write(KEYR, KEY2, 0).unwrap();
            assert_eq!(f.read(CR, 0), Ok(0), "unlocked after the reset");
        }
    }

    /// The wrong sequence: CR written without unlocking; the write is ignored, no erase starts.
    #[test]
    fn a_cr_write_while_locked_is_ignored() {
        let mut f = Flash::new();
        f.write(CR, CR_SER | (1 << CR_SNB_SHIFT) | X32 | CR_STRT, 0).unwrap();
        assert_eq!(f.read(SR, 0), Ok(0));
        assert_eq!(f.read(CR, 0), Ok(CR_LOCK));
        assert_eq!(f.ignored_writes(), 1);
    }

    /// Sector erase (RM0368 §3.5.3) with DS9716's typical 250 ms for 16 KB at x32: BSY
    /// throughout, the sector 0xFF after, EOP only with EOPIE.
    #[test]
    fn a_sector_erase_keeps_bsy_for_250_ms_at_x32_then_leaves_0xff() {
        let mut f = unlocked();
        fill(&mut f, 1, 0x1234_5678);
        fill(&mut f, 2, 0);
        f.write(CR, CR_SER | (1 << CR_SNB_SHIFT) | X32 | CR_EOPIE | CR_STRT, 0).unwrap();
        assert_eq!(f.busy_until(), Some(250 * MS));
        assert_eq!(f.read(SR, 250 * MS - 1).unwrap() & SR_BSY, SR_BSY);
        assert_eq!(word(&f, 0x4000), 0x1234_5678, "nothing changes before the end");
        assert_eq!(f.read(SR, 250 * MS), Ok(SR_EOP));
        assert!(f.irq_line());
        assert!(f.memory()[0x4000..0x8000].iter().all(|&b| b == 0xFF));
        assert_eq!(word(&f, 0x8000), 0, "sector 2 untouched");
        assert_eq!(f.take_changes().len(), 1);
        f.write(SR, SR_EOP, 250 * MS).unwrap();
        assert!(!f.irq_line());
        // Without EOPIE no EOP (RM0368 §3.8.4).
        f.write(CR, CR_SER | (2 << CR_SNB_SHIFT) | X32 | CR_STRT, 300 * MS).unwrap();
        assert_eq!(f.read(SR, 600 * MS), Ok(0));
    }

    #[test]
    fn erase_times_follow_the_sector_size_the_parallelism_and_the_column() {
        for (snb, psize, timing, seconds) in [
            (0, X8, FlashTiming::Typical, 0.4),
            (3, 0b01 << CR_PSIZE_SHIFT, FlashTiming::Typical, 0.3),
            (0, X32, FlashTiming::Maximum, 0.5),
            (4, X32, FlashTiming::Typical, 0.55),
            (5, X32, FlashTiming::Typical, 1.0),
            (5, X8, FlashTiming::Maximum, 4.0),
        ] {
            let mut f = unlocked();
            f.set_timing(timing);
            f.write(CR, CR_SER | (snb << CR_SNB_SHIFT) | psize | CR_STRT, 0).unwrap();
            assert_eq!(f.busy_until(), Some(time_from_s(seconds)), "sector {snb}");
        }
    }

    /// Programming (RM0368 §3.5.4): 16 µs typical per word (DS9716), then the word holds old AND
    /// new: bits only go 1 → 0, and a word that was not erased is ANDed, without an error flag.
    #[test]
    fn a_word_program_takes_16_us_and_only_clears_bits() {
        let mut f = unlocked();
        f.write(CR, CR_PG | X32, 0).unwrap();
        f.write_memory(0x4000, 4, 0xA5A5_0F0F, 0).unwrap();
        assert_eq!(f.read(SR, 16 * US - 1).unwrap(), SR_BSY);
        assert_eq!(word(&f, 0x4000), 0xFFFF_FFFF);
        assert_eq!(f.read(SR, 16 * US), Ok(0));
        assert_eq!(word(&f, 0x4000), 0xA5A5_0F0F);
        f.write_memory(0x4000, 4, 0x5A5A_FFFF, 20 * US).unwrap();
        f.advance(40 * US);
        assert_eq!(word(&f, 0x4000), 0x0000_0F0F, "a 1 cannot be programmed back");
        assert_eq!(f.read(SR, 40 * US), Ok(0), "no error flag for a non-erased word");
    }

    /// The wrong sequences of RM0368 §3.8.4, each refused with its flag and the memory unchanged.
    #[test]
    fn a_write_with_a_wrong_set_up_sets_its_error_flag_and_programs_nothing() {
        let cases: [(&str, u32, u32, u32, u32); 7] = [
            ("PG clear", X32, 0x4000, 4, SR_PGSERR),
            ("PG with SER", CR_PG | CR_SER | X32, 0x4000, 4, SR_PGSERR),
            ("a word at x8", CR_PG | X8, 0x4000, 4, SR_PGPERR),
            ("a byte at x32", CR_PG | X32, 0x4000, 1, SR_PGPERR),
            ("an unaligned word at x32: split into halfwords", CR_PG | X32, 0x4002, 4, SR_PGPERR),
            ("an unaligned word at x32: split into a byte, a halfword, a byte", CR_PG | X32, 0x4001, 4, SR_PGPERR),
            ("ERRIE adds OPERR", CR_PG | X8 | CR_ERRIE, 0x4000, 2, SR_PGPERR | SR_OPERR),
        ];
        for (what, cr, offset, size, flags) in cases {
            let mut f = unlocked();
            f.write(CR, cr, 0).unwrap();
            f.write_memory(offset, size, 0, 0).unwrap();
            assert_eq!(f.read(SR, 0), Ok(flags), "{what}");
            assert_eq!(f.busy_until(), None, "{what}");
            assert!(f.memory()[0x4000..0x4008].iter().all(|&b| b == 0xFF), "{what}");
            assert_eq!(f.irq_line(), cr & CR_ERRIE != 0, "{what}");
            f.write(SR, flags, 0).unwrap();
            assert_eq!(f.read(SR, 0), Ok(0), "{what}: rc_w1");
        }
        // Locked: PG cannot even be set; the write is a sequence error.
        let mut f = Flash::new();
        f.write_memory(0x4000, 4, 0, 0).unwrap();
        assert_eq!(f.read(SR, 0), Ok(SR_PGSERR));
    }

    /// Rule (RM0368 §3.5, FLASH_ACR.DCRST): an operation does not update the data cache; a
    /// word cached before it reads stale until the cache is emptied (DCRST with DCEN off).
    /// Assumption: every word of the range may be cached (the F401's D-cache holds 8 lines of
    /// 128 bits, which words is not modelled), so a missing DCRST shows on any read-back.
    #[test]
    fn with_the_data_cache_on_a_programmed_word_reads_stale_until_dcrst() {
        let mut f = unlocked();
        f.write(ACR, 2 | ACR_DCEN, 0).unwrap();
        f.write(CR, CR_PG | X32, 0).unwrap();
        f.write_memory(0x4000, 4, 0x1234_5678, 0).unwrap();
        f.touch(0x4000, 4);
        f.advance(20 * US);
        assert_eq!(word(&f, 0x4000), 0x1234_5678, "the memory holds the new word");
        let seen: Vec<(u32, Vec<u8>)> = f.take_changes();
        assert!(seen.iter().all(|(o, b)| *o != 0x4000 || b[..4] == [0xFF; 4]), "a read still sees the cached word: {seen:x?}");
        f.write(ACR, 2, 20 * US).unwrap();
        f.write(ACR, 2 | ACR_DCRST, 20 * US).unwrap();
        f.write(ACR, 2 | ACR_DCEN, 20 * US).unwrap();
        let seen = f.take_changes();
        assert!(seen.iter().any(|(o, b)| *o == 0x4000 && b[..4] == 0x1234_5678u32.to_le_bytes()), "after DCRST: {seen:x?}");
        assert!(f.stale_ranges().is_empty());
    }

    /// With the data cache never on, nothing is stale: the read-back sees the word at once.
    #[test]
    fn with_the_data_cache_off_a_programmed_word_reads_back_at_once() {
        let mut f = unlocked();
        f.write(CR, CR_PG | X32, 0).unwrap();
        f.write_memory(0x4000, 4, 0x1234_5678, 0).unwrap();
        f.advance(20 * US);
        assert!(f.take_changes().iter().any(|(o, b)| *o == 0x4000 && b[..4] == 0x1234_5678u32.to_le_bytes()));
    }

    #[test]
    fn strt_with_both_or_neither_erase_bits_or_a_missing_sector_is_refused() {
        for cr in [CR_SER | CR_MER, 0, CR_SER | (6 << CR_SNB_SHIFT)] {
            let mut f = unlocked();
            assert!(f.write(CR, cr | X32 | CR_STRT, 0).is_err(), "{cr:#x}");
        }
        let mut f = unlocked();
        assert!(f.write(CR, CR_PG | (0b11 << CR_PSIZE_SHIFT), 0).is_err(), "x64");
    }

    /// A power cut at 3/8 of a 16 KB erase: the first 3/8 of the words erased, the word under
    /// erase with some of its 0 bits raised and some still 0, the rest as they were.
    #[test]
    fn a_power_cut_mid_erase_leaves_erased_half_erased_and_intact_words() {
        let mut f = unlocked();
        fill(&mut f, 1, 0);
        f.write(CR, CR_SER | (1 << CR_SNB_SHIFT) | X32 | CR_STRT, 0).unwrap();
        let (start, end, erase) = f.operation().unwrap();
        assert!(erase);
        // 3/8 of the way, plus half a word's time.
        let words = 0x4000 / 4;
        let at = start + (end - start) * (3 * words / 8 * 2 + 1) / (2 * words);
        f.power_cut(at);
        assert_eq!(f.busy_until(), None);
        let cut = 0x4000 + 4 * (3 * words / 8) as usize;
        assert!(f.memory()[0x4000..cut].iter().all(|&b| b == 0xFF), "erased before the cut");
        let partial = word(&f, cut);
        assert!(partial != 0 && partial != u32::MAX, "the word under erase is half-way: {partial:#010x}");
        assert!(f.memory()[cut + 4..0x8000].iter().all(|&b| b == 0), "untouched after it");
    }

    /// A power cut half-way through a word program: some of its 1 → 0 bits cleared, not all.
    #[test]
    fn a_power_cut_mid_program_leaves_a_partly_programmed_word() {
        let mut f = unlocked();
        f.write(CR, CR_PG | X32, 0).unwrap();
        f.write_memory(0x8000, 4, 0x0000_0000, 0).unwrap();
        f.power_cut(8 * US);
        let w = word(&f, 0x8000);
        assert_eq!(w.count_ones(), 16, "half of the 32 bits cleared: {w:#010x}");
        // Cut at the end: the word is whole.
        let mut f = unlocked();
        f.write(CR, CR_PG | X32, 0).unwrap();
        f.write_memory(0x8000, 4, 0x1234_5678, 0).unwrap();
        f.power_cut(16 * US);
        assert_eq!(word(&f, 0x8000), 0x1234_5678);
    }

    /// A system reset (the watchdog) during an erase cuts it the same way; the memory survives,
    /// the registers do not.
    #[test]
    fn a_reset_mid_erase_keeps_the_memory_as_it_stands_and_locks_cr() {
        let mut f = unlocked();
        fill(&mut f, 0, 0);
        f.write(CR, CR_SER | X32 | CR_STRT, 0).unwrap();
        f.advance(125 * MS);
        f.system_reset();
        assert_eq!(f.read(CR, 125 * MS), Ok(CR_LOCK));
        assert_eq!(f.read(SR, 125 * MS), Ok(0));
        assert!(f.memory()[..0x1FFC].iter().all(|&b| b == 0xFF));
        assert!(f.memory()[0x2004..0x4000].iter().all(|&b| b == 0));
    }

    #[test]
    fn part_of_bits_takes_the_lowest_bits_first() {
        assert_eq!(part_of_bits(0b1011_0000, 0.5), 0b0001_0000, "1 of 3 bits, rounded down");
        assert_eq!(part_of_bits(u32::MAX, 1.0), u32::MAX);
        assert_eq!(part_of_bits(u32::MAX, 0.0), 0);
    }
}
