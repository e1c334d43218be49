//! Timing profiles of the emulated Cortex-M4: how many processor cycles the board spends on what
//! Unicorn executes, and at which instant a memory-mapped register access reaches its model.
//! Unicorn runs the instructions and knows nothing of time; the profile decides. Both profiles
//! are deterministic (nothing depends on the host), so a run is reproducible under either.
//!
//! **Why two profiles.** The STM32F401 at 84 MHz is not cycle-exact anywhere in its documents:
//! the Cortex-M4 TRM gives ranges (a taken branch refills the pipeline in 1 to 3 cycles, a
//! divide takes 2 to 12, a load 1 or 2 depending on its neighbour), RM0368 gives the flash wait
//! states but not the organisation of the ART accelerator, and ST gives no figure at all for an
//! APB access. So the harness does not pretend to one answer: it brackets the board.
//! [`TimingProfile::Optimistic`] is at least as fast as the board at every point, and
//! [`TimingProfile::Pessimistic`] at least as slow (up to what is listed below as not
//! modelled). A firmware timing window (the SPI end-of-read rule: SPE cleared no earlier than
//! one SPI clock after the second-to-last RXNE and before the last byte ends) holds on the board
//! if it holds under both: the optimistic profile tests its early end (the firmware is as fast,
//! and its register accesses as early, as they can be), the pessimistic its late end.
//!
//! **Optimistic** (`FCU_PIL_TIMING=optimistic`, the default):
//! - every instruction is one cycle at HCLK (CPI 1), no flash wait states, no refill after a
//!   taken branch, register accesses free: the instruction-count clock, time exactly the
//!   instructions executed (and the exceptions' entries and returns). (One caveat to "at least as
//!   fast": the core may fold an IT instruction into its neighbour, 0 cycles; it is counted as
//!   one, so the lower bound is off by at most one cycle per IT executed.)
//! - exception entry 12 cycles, return 10 (Cortex-M4 TRM §5.5, zero-wait-state memory); the
//!   extended FP frame costs nothing more (lazy stacking deferred the FP registers). An
//!   exception tail-chained onto a return (pending and able to preempt when the return starts)
//!   costs the silicon minimum, 6 cycles for the return and the entry together (the TRM's
//!   tail-chaining figure), so a handler may start as early as 6 cycles after the return began.
//! - a memory-mapped access is time-stamped at the start of its block, the earliest instant
//!   the block allows. Unicorn's MMIO callbacks see a stale PC (QEMU's `io_readx`/`io_writex`
//!   do not restore the CPU state), so the accessing instruction is not known. A memory hook
//!   bound to the peripheral range would make Unicorn restore it, but with one installed
//!   Unicorn 2.1.5 misexecuted the release image's capture interrupt (a TIM2 CCR read inside an
//!   IT block landed 0x400 past the timer: an unmodelled access the run stopped at), so the
//!   profile does without, at the price of a bound looser by up to a block's instructions.
//!
//! **Pessimistic** (`FCU_PIL_TIMING=pessimistic`):
//! - each instruction costs its class's cycles, decoded from the Thumb-2 encoding and cached
//!   per translation block (Cortex-M4 TRM table 3-1 and, for the FPU, table 7-1; where the TRM
//!   gives a range, its top): data processing, multiply and multiply-accumulate 1; SDIV/UDIV 12
//!   (2 to 12); LDR/STR and their byte, halfword, exclusive and FP forms 2 (LDR/STR pipelining
//!   with a neighbour, which saves a cycle, is not taken); a PC-relative (literal) load one more
//!   (the TRM: "might add a cycle because of contention with the fetch unit"); LDRD/STRD 3;
//!   LDM/STM/PUSH/POP 1+N; VLDR/VSTR 2 (.F64 3); VLDM/VSTM/VPUSH/VPOP 1+N words; VMLA/VMLS/
//!   VNMLA/VNMLS and the fused forms 3; VDIV and VSQRT 14; other FP 1; VMOV of two registers 2;
//!   TBB/TBH 2; DMB/DSB/ISB 1+3 (B, the barrier's own time, assumed at most a refill); a load or
//!   store right after a data-processing instruction one more (the TRM's address-generation
//!   stall; the decoder tracks no registers, so it is assumed whenever the pair occurs).
//! - a taken branch (the next block does not start where this one ended) refills the pipeline:
//!   3 cycles (P, 1 to 3 in the TRM).
//! - flash wait states, FLASH_ACR.LATENCY as the firmware programs it, through a model of the
//!   ART accelerator (RM0368 §3.4): an instruction cache of 64 lines of 128 bits, filled on a
//!   miss, least recently used line replaced (RM0368 says LRU; it does not say how the lines
//!   are organised, so the model is fully associative, an assumption). A block whose first line
//!   misses pays LATENCY cycles at its start; with ICEN off every block start pays; with
//!   PRFTEN off every further line of the block pays as well (with it on, the prefetch of the
//!   next sequential line hides it: a line holds 4 to 8 instructions, at least 4 cycles, and is
//!   fetched in LATENCY + 1). As in RM0368, a line served by the prefetch buffer is not copied
//!   into the cache. ICRST empties the model.
//! - data reads from flash: every PC-relative (literal) load pays LATENCY, as a miss of the
//!   ART's data cache would (pessimistic: a pool read again soon hits). Constant tables read
//!   through a register are not seen: watching flash data reads needs a Unicorn memory hook on
//!   flash, which corrupts guest registers in Unicorn 2.1.5 (see docs/fcu-pil.md), so the model
//!   does without.
//! - every access to a peripheral register stalls the core for the bridge and the APB
//!   transfer. ST gives no figure for this; the model's, an assumption from the AMBA APB
//!   protocol: one HCLK through the AHB/APB bridge, up to one PCLK period less one HCLK to meet
//!   the PCLK edge, then the APB transfer's setup and access phases, two PCLK cycles. With the
//!   board's prescalers (read from RCC_CFGR.PPRE1/PPRE2, RM0368 §6.3.3) that is 6 cycles on
//!   APB1 (42 MHz: TIM2, TIM4, SPI2, IWDG, PWR) and 3 on APB2 (84 MHz: TIM9, USART1, ADC1).
//!   AHB1 peripherals (GPIO, RCC, FLASH) and the private peripheral bus (NVIC, SysTick, DWT)
//!   add nothing beyond the load or store's own cycles. A bit-band write is a read and a
//!   write on the bus (ARMv7-M: the bit-band write is a locked read-modify-write), so it pays
//!   twice. A store pays like a load (the core's write buffer could hide it; a bound does not
//!   count on that).
//! - exception entry 12 cycles and return 10, plus 17 at an entry that stacks the extended FP
//!   frame (the lazy save of S0–S15 and FPSCR at the handler's first FP instruction, Arm's
//!   application note 298 on Cortex-M4F lazy stacking: 29 cycles of latency with the FP state
//!   stacked against 12 without; charged at entry rather than at that instruction, which is
//!   earlier, never later) and 17 at a return that unstacks one (assumed the same as the save);
//!   an entry also pays LATENCY for the vector's read from flash (the TRM's 12 cycles assume
//!   zero-wait-state memory; that the read hides behind the stacking is not counted on). A
//!   tail-chained exception pays a full return and entry (22 cycles, where the core needs 6).
//! - a memory-mapped access is time-stamped as late as the profile makes it: the end of its
//!   block (all the block's cycles charged), plus the stalls of the block's accesses so far,
//!   its own included. Register effects in the models are immediate at that instant.
//!
//! **Not modelled in either** (so the bracket is as wide as the board's behaviour only up to
//! these): the extra cycle of some unaligned 32-bit instruction groups and of a branch to an
//! unaligned 32-bit instruction (the TRM's P of 3 covers the latter), contention between the
//! I-code and D-code buses for the flash beyond the literal-load cycle, the prefetch buffer
//! falling behind on sequential code with many loads, interrupts taken only between
//! translation blocks (a quantum of a few instructions), and a divide's or VDIV's overlap with
//! later independent instructions (counted as blocking: pessimistic).

use std::ffi::OsStr;
use std::fmt;
use std::str::FromStr;

use crate::periph::flash::AcrTiming;

/// The environment variable that picks the profile when nothing else does.
pub const TIMING_ENV: &str = "FCU_PIL_TIMING";

/// Which end of the board's timing the emulator plays (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TimingProfile {
    /// CPI 1, no wait states, free register accesses, accesses stamped early in their block.
    #[default]
    Optimistic,
    /// Per-class instruction cycles, flash wait states through the ART model, APB stalls, lazy
    /// FP stacking; accesses stamped at the end of their block.
    Pessimistic,
}

impl TimingProfile {
    pub const ALL: [TimingProfile; 2] = [TimingProfile::Optimistic, TimingProfile::Pessimistic];

    pub fn name(self) -> &'static str {
        match self {
            TimingProfile::Optimistic => "optimistic",
            TimingProfile::Pessimistic => "pessimistic",
        }
    }

    /// The profile [`TIMING_ENV`] names; optimistic when it is not set.
    pub fn from_env() -> Result<TimingProfile, String> {
        Self::from_env_value(std::env::var_os(TIMING_ENV).as_deref())
    }

    /// [`TimingProfile::from_env`] for a given value of the variable (`None`: not set).
    pub fn from_env_value(value: Option<&OsStr>) -> Result<TimingProfile, String> {
        match value {
            None => Ok(TimingProfile::Optimistic),
            Some(v) => v
                .to_str()
                .ok_or_else(|| format!("{TIMING_ENV}={v:?} is not optimistic or pessimistic"))?
                .parse()
                .map_err(|e: ParseTimingError| format!("{TIMING_ENV}={:?} is not optimistic or pessimistic", e.0)),
        }
    }
}

impl fmt::Display for TimingProfile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not a timing profile (the name is kept for the message).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParseTimingError(pub String);

impl fmt::Display for ParseTimingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unknown timing profile {:?}: expected optimistic or pessimistic", self.0)
    }
}

impl std::error::Error for ParseTimingError {}

impl FromStr for TimingProfile {
    type Err = ParseTimingError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        TimingProfile::ALL.into_iter().find(|p| p.name() == s).ok_or_else(|| ParseTimingError(s.to_string()))
    }
}

/// Pipeline refill after a taken branch, the top of the TRM's 1 to 3.
pub const BRANCH_REFILL_CYCLES: u64 = 3;
/// The lazy save (or the restore) of S0–S15 and FPSCR (AN298: 29 cycles against 12).
pub const FP_STATE_CYCLES: u64 = 17;
/// A tail-chain on a Cortex-M4: the return and the next entry together (TRM §3.3.1, interrupt
/// latency: "tail-chaining … 6 cycles").
pub const TAIL_CHAIN_CYCLES: u64 = 6;
/// A Thumb-2 halfword whose top five bits are 0b11101, 0b11110 or 0b11111 starts a 32-bit
/// instruction.
pub fn is_32_bit(hw1: u16) -> bool {
    hw1 >> 11 >= 0b11101
}

/// What an instruction is, as far as its neighbour's timing cares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// Writes a core register from the ALU (a following load or store may wait for it).
    DataProcessing,
    LoadStore,
    Other,
}

/// Cycles of one instruction in the pessimistic profile (a taken branch's refill is charged
/// where the next block starts, a load's address stall by [`block_cycles`]), and its class.
pub fn instruction_cycles(hw1: u16, hw2: u16) -> (u64, Class) {
    if is_32_bit(hw1) {
        wide_instruction_cycles(hw1, hw2)
    } else {
        narrow_instruction_cycles(hw1)
    }
}

fn register_count(bits: u16) -> u64 {
    u64::from(bits.count_ones())
}

/// A 16-bit Thumb instruction's cycles and class.
fn narrow_instruction_cycles(hw1: u16) -> (u64, Class) {
    use Class::{DataProcessing as Dp, LoadStore as Ls, Other};
    match hw1 >> 12 {
        0b0000..=0b0011 => (1, Dp),
        0b0100 => match hw1 >> 10 {
            0b01_0000 => (1, Dp),
            0b01_0001 => (1, if (hw1 >> 8) & 3 == 0b11 { Other } else { Dp }),
            // LDR (literal).
            _ => (3, Ls),
        },
        0b0101..=0b1001 => (2, Ls),
        0b1010 => (1, Dp),
        0b1011 => {
            if hw1 & 0xFE00 == 0xB400 || hw1 & 0xFE00 == 0xBC00 {
                // PUSH / POP: the list, plus LR or PC in bit 8.
                (1 + register_count(hw1 & 0x1FF), Ls)
            } else if hw1 & 0xF500 == 0xB100 || hw1 & 0xFF00 == 0xBF00 || hw1 & 0xFF00 == 0xBE00 || hw1 & 0xFFE0 == 0xB660 {
                // CBZ/CBNZ, IT and hints, BKPT, CPS.
                (1, Other)
            } else {
                // ADD/SUB SP, extends, reverses.
                (1, Dp)
            }
        }
        // STMIA / LDMIA.
        0b1100 => (1 + register_count(hw1 & 0xFF), Ls),
        // B<c>, UDF, SVC, B.
        _ => (1, Other),
    }
}

/// A 32-bit Thumb-2 instruction's cycles and class (its halfwords `hw1`, `hw2`).
fn wide_instruction_cycles(hw1: u16, hw2: u16) -> (u64, Class) {
    use Class::{DataProcessing as Dp, LoadStore as Ls, Other};
    let op1 = (hw1 >> 11) & 3;
    let op2 = (hw1 >> 4) & 0x7F;
    match op1 {
        0b01 => {
            if op2 & 0b110_0100 == 0 {
                // LDM/STM (PUSH.W/POP.W): the register list in the second halfword.
                (1 + register_count(hw2), Ls)
            } else if op2 & 0b110_0100 == 0b000_0100 {
                if hw1 & 0xFFF0 == 0xE8D0 && hw2 & 0xFFE0 == 0xF000 {
                    // TBB / TBH.
                    (2, Ls)
                } else if hw1 & 0xFFE0 == 0xE840 || (hw1 & 0xFFE0 == 0xE8C0 && hw2 & 0x00C0 == 0x0040) {
                    // LDREX / STREX and their byte and halfword forms.
                    (2, Ls)
                } else {
                    // LDRD / STRD.
                    (3, Ls)
                }
            } else if op2 & 0b110_0000 == 0b010_0000 {
                (1, Dp)
            } else {
                coprocessor_cycles(hw1, hw2)
            }
        }
        0b10 => {
            if hw2 & 0x8000 == 0 {
                (1, Dp)
            } else if hw2 & 0xD000 == 0x8000 && op2 == 0b011_1011 {
                // DMB / DSB / ISB.
                (1 + BRANCH_REFILL_CYCLES, Other)
            } else {
                // B, B<c>, BL, MSR, MRS, hints.
                (1, Other)
            }
        }
        _ => {
            if op2 & 0b111_0001 == 0 {
                (2, Ls)
            } else if op2 & 0b110_0001 == 0b000_0001 && op2 & 0b110_0111 != 0b000_0111 {
                // Loads: byte, halfword, word; one more from the PC (a literal).
                (if hw1 & 0xF == 0xF { 3 } else { 2 }, Ls)
            } else if op2 & 0b111_0000 == 0b010_0000 || op2 & 0b111_1000 == 0b011_0000 {
                // Data processing (register), multiply and multiply-accumulate.
                (1, Dp)
            } else if op2 & 0b111_1000 == 0b011_1000 {
                // SDIV / UDIV, or a long multiply.
                (if op2 == 0b011_1001 || op2 == 0b011_1011 { 12 } else { 1 }, Dp)
            } else if op2 & 0b100_0000 != 0 {
                coprocessor_cycles(hw1, hw2)
            } else {
                (1, Other)
            }
        }
    }
}

/// The FPU's instructions (coprocessors 10 and 11), Cortex-M4 TRM table 7-1.
fn coprocessor_cycles(hw1: u16, hw2: u16) -> (u64, Class) {
    use Class::{DataProcessing as Dp, LoadStore as Ls, Other};
    if (hw2 >> 9) & 7 != 0b101 {
        return (1, Other);
    }
    if hw1 & 0xFE00 == 0xEC00 {
        if hw1 & 0x01E0 == 0x0040 {
            // VMOV of two core registers to or from two singles or a double.
            return (2, Dp);
        }
        if hw1 & 0x0120 == 0x0100 {
            // VLDR / VSTR: a double is two transfers; from the PC, a literal.
            let size = if hw2 & 0x0100 != 0 { 3 } else { 2 };
            return (size + u64::from(hw1 & 0xF == 0xF), Ls);
        }
        // VLDM / VSTM / VPUSH / VPOP: imm8 is the number of words.
        return (1 + u64::from(hw2 & 0xFF), Ls);
    }
    if hw1 & 0xFF00 == 0xEE00 {
        if hw2 & 0x0010 != 0 {
            // VMOV between a core register and a single, VMRS, VMSR.
            return (1, Dp);
        }
        // opc1: bits 7, 5 and 4 of the first halfword (bit 6 is a register bit).
        let opc1 = ((hw1 >> 5) & 0b100) | ((hw1 >> 4) & 0b11);
        return match opc1 {
            // VMLA/VMLS, VNMLA/VNMLS, VFNMA/VFNMS, VFMA/VFMS.
            0b000 | 0b001 | 0b101 | 0b110 => (3, Other),
            // VDIV.
            0b100 => (14, Other),
            // VSQRT (opc2 0001, opc3 11); the other two-register operations are one cycle.
            0b111 if hw1 & 0xF == 0b0001 && hw2 & 0x00C0 == 0x00C0 => (14, Other),
            _ => (1, Other),
        };
    }
    (1, Other)
}

/// A straight run of instructions (a block) as the pessimistic profile prices it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockCost {
    /// Cycles of its instructions (wait states apart).
    pub cycles: u64,
    pub instructions: u64,
    /// PC-relative (literal) loads: each a data read from flash.
    pub literal_loads: u64,
    /// It holds an FP instruction (coprocessor 10 or 11).
    pub has_fp: bool,
}

/// Pessimistic cycles of a straight run of instructions (a block), how many there are, and how
/// many read a literal from flash. `halfword(i)` is the i-th halfword of the block.
pub fn block_cycles(size_bytes: u32, halfword: impl Fn(u32) -> u16) -> BlockCost {
    let (mut cycles, mut instructions, mut literal_loads) = (0u64, 0u64, 0u64);
    let mut has_fp = false;
    let mut previous = Class::Other;
    let mut i = 0;
    while 2 * i < size_bytes {
        let hw1 = halfword(i);
        let wide = is_32_bit(hw1);
        let hw2 = if wide { halfword(i + 1) } else { 0 };
        let (c, class) = instruction_cycles(hw1, hw2);
        let stall = u64::from(class == Class::LoadStore && previous == Class::DataProcessing);
        cycles += c + stall;
        instructions += 1;
        literal_loads += u64::from(is_literal_load(hw1));
        has_fp |= wide && hw1 & 0xEC00 == 0xEC00 && (hw2 >> 9) & 7 == 0b101;
        previous = class;
        i += if wide { 2 } else { 1 };
    }
    BlockCost { cycles: cycles.max(1), instructions: instructions.max(1), literal_loads, has_fp }
}

/// LDR (literal), 16- or 32-bit (byte, halfword, word, signed; LDRD and VLDR from the PC apart).
pub(crate) fn is_literal_load(hw1: u16) -> bool {
    if !is_32_bit(hw1) {
        return hw1 >> 11 == 0b01001;
    }
    // 1111 1000 U0xx 1111 (LDR/LDRB/LDRH literal) and 1111 1001 U0x1 1111 (LDRSB/LDRSH).
    hw1 & 0xFE0F == 0xF80F && hw1 & 0x0010 != 0
}

/// A fully associative cache of 128-bit lines, least recently used line replaced.
#[derive(Clone, Debug)]
pub struct LineCache<const N: usize> {
    /// Line numbers (address / 16); `u32::MAX` = empty.
    lines: [u32; N],
    last_used: [u64; N],
    clock: u64,
}

impl<const N: usize> Default for LineCache<N> {
    fn default() -> Self {
        LineCache { lines: [u32::MAX; N], last_used: [0; N], clock: 0 }
    }
}

impl<const N: usize> LineCache<N> {
    /// Looks `line` up; on a miss it is filled, replacing the least recently used line.
    /// Returns whether it hit.
    pub fn access(&mut self, line: u32) -> bool {
        self.clock += 1;
        if let Some(i) = self.lines.iter().position(|&l| l == line) {
            self.last_used[i] = self.clock;
            return true;
        }
        let victim = (0..N).min_by_key(|&i| (self.lines[i] != u32::MAX, self.last_used[i])).unwrap_or(0);
        self.lines[victim] = line;
        self.last_used[victim] = self.clock;
        false
    }

    pub fn contains(&self, line: u32) -> bool {
        self.lines.contains(&line)
    }

    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

/// RCC_CFGR's APB prescaler field (PPRE1 at bit 10, PPRE2 at bit 13; RM0368 §6.3.3): 0xx not
/// divided, 100 /2, 101 /4, 110 /8, 111 /16.
pub fn apb_divider(cfgr: u32, shift: u32) -> u64 {
    let ppre = (cfgr >> shift) & 0b111;
    if ppre < 0b100 {
        1
    } else {
        2 << (ppre - 0b100)
    }
}

pub const PPRE1_SHIFT: u32 = 10;
pub const PPRE2_SHIFT: u32 = 13;

/// Flash (and its boot alias at 0, and the system memory) as one 128-bit line number, or `None`
/// for an address outside the flash module.
fn flash_line(addr: u32) -> Option<u32> {
    use crate::machine::{FLASH_BASE, FLASH_SIZE, SYSMEM_PAGE};
    if addr < FLASH_SIZE {
        Some(addr / 16)
    } else if (FLASH_BASE..FLASH_BASE + FLASH_SIZE).contains(&addr) {
        Some((addr - FLASH_BASE) / 16)
    } else if (SYSMEM_PAGE..SYSMEM_PAGE + 0x1000).contains(&addr) {
        Some((addr - SYSMEM_PAGE + FLASH_SIZE) / 16)
    } else {
        None
    }
}

/// The bus a peripheral address is on, for the access stall.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bus {
    Apb1,
    Apb2,
    /// AHB1 peripherals and the private peripheral bus: no stall beyond the instruction's own.
    Fast,
}

pub fn bus_of(addr: u32) -> Bus {
    match addr {
        0x4000_0000..=0x4000_7FFF => Bus::Apb1,
        0x4001_0000..=0x4001_7FFF => Bus::Apb2,
        _ => Bus::Fast,
    }
}

/// One HCLK through the AHB/APB bridge (assumption, see the module documentation).
pub const APB_BRIDGE_CYCLES: u64 = 1;
/// Setup and access phases of an APB transfer, in PCLK cycles (AMBA APB).
pub const APB_TRANSFER_PCLKS: u64 = 2;

/// The dynamic part of the timing: the flash interface's state and the caches, the bus
/// prescalers, and where the last block ended (to see a taken branch).
#[derive(Clone, Debug)]
pub struct Timing {
    pub profile: TimingProfile,
    acr: AcrTiming,
    apb1_divider: u64,
    apb2_divider: u64,
    icache: LineCache<64>,
    dcache: LineCache<8>,
    /// Where the last charged block ended; `None` after an exception entry or return (their
    /// cycles include the refill) and at reset.
    previous_block_end: Option<u32>,
}

impl Timing {
    pub fn new(profile: TimingProfile) -> Timing {
        Timing {
            profile,
            acr: AcrTiming::default(),
            apb1_divider: 1,
            apb2_divider: 1,
            icache: LineCache::default(),
            dcache: LineCache::default(),
            previous_block_end: None,
        }
    }

    pub fn pessimistic(&self) -> bool {
        self.profile == TimingProfile::Pessimistic
    }

    /// A system reset: FLASH_ACR and RCC_CFGR back to 0, the caches empty.
    pub fn reset(&mut self) {
        *self = Timing::new(self.profile);
    }

    /// FLASH_ACR as the flash interface now holds it, and the bits of a write that reset the
    /// caches.
    pub fn set_acr(&mut self, acr: AcrTiming) {
        if acr.icache_reset {
            self.icache.clear();
        }
        if acr.dcache_reset {
            self.dcache.clear();
        }
        self.acr = AcrTiming { icache_reset: false, dcache_reset: false, ..acr };
    }

    pub fn acr(&self) -> AcrTiming {
        self.acr
    }

    /// RCC_CFGR as the RCC now holds it.
    pub fn set_rcc_cfgr(&mut self, cfgr: u32) {
        self.apb1_divider = apb_divider(cfgr, PPRE1_SHIFT);
        self.apb2_divider = apb_divider(cfgr, PPRE2_SHIFT);
    }

    /// An exception entry or return: the next block's fetch is part of their cycles.
    pub fn exception_boundary(&mut self) {
        self.previous_block_end = None;
    }

    /// The block's own cycles (`instructions` under CPI 1, else `pessimistic_cycles`).
    pub fn body_cycles(&self, instructions: u64, pessimistic_cycles: u64) -> u64 {
        match self.profile {
            TimingProfile::Optimistic => instructions,
            TimingProfile::Pessimistic => pessimistic_cycles,
        }
    }

    /// Cycles charged at the start of the block at `addr` (`size` bytes) before its body runs:
    /// the refill after a taken branch and the flash wait states. Records the block as the
    /// last one run.
    pub fn block_entry_cycles(&mut self, addr: u32, size: u32) -> u64 {
        let previous = self.previous_block_end.replace(addr.wrapping_add(size));
        if !self.pessimistic() {
            return 0;
        }
        let refill = if previous.is_some_and(|end| end != addr) { BRANCH_REFILL_CYCLES } else { 0 };
        refill + self.fetch_cycles(addr, size)
    }

    /// Wait states of fetching the block's lines through the ART accelerator.
    fn fetch_cycles(&mut self, addr: u32, size: u32) -> u64 {
        let (Some(first), Some(last)) = (flash_line(addr), flash_line(addr.wrapping_add(size.max(1) - 1))) else {
            return 0;
        };
        let latency = u64::from(self.acr.latency);
        let mut cycles = 0;
        for line in first..=last.max(first) {
            let sequential = line != first;
            if sequential && self.acr.prefetch {
                continue;
            }
            let hit = self.acr.icache && self.icache.access(line);
            if !hit {
                cycles += latency;
            }
        }
        cycles
    }

    /// Cycles of one more lap of a loop that is one block branching back to itself, once it
    /// has run once (its line cached if the cache is on).
    pub fn steady_lap_cycles(&self, addr: u32, size: u32, body: u64) -> u64 {
        if !self.pessimistic() {
            return body;
        }
        let lines = match (flash_line(addr), flash_line(addr.wrapping_add(size.max(1) - 1))) {
            (Some(a), Some(b)) => u64::from(b - a + 1),
            _ => 0,
        };
        let fetched = if self.acr.icache || lines == 0 {
            0
        } else if self.acr.prefetch {
            1
        } else {
            lines
        };
        body + BRANCH_REFILL_CYCLES + fetched * u64::from(self.acr.latency)
    }

    /// Stall of an access to a peripheral register at `addr` (the peripheral's own address for
    /// a bit-band alias access); `transfers` is 2 for a bit-band write, else 1.
    pub fn register_access_cycles(&self, addr: u32, transfers: u64) -> u64 {
        if !self.pessimistic() {
            return 0;
        }
        let divider = match bus_of(addr) {
            Bus::Apb1 => self.apb1_divider,
            Bus::Apb2 => self.apb2_divider,
            Bus::Fast => return 0,
        };
        transfers * (APB_BRIDGE_CYCLES + (divider - 1) + APB_TRANSFER_PCLKS * divider)
    }

    /// Wait states of a block's literal loads, each charged as a miss of the ART's data cache
    /// (pessimistic: a literal pool read again soon would hit).
    pub fn literal_load_cycles(&self, literal_loads: u64) -> u64 {
        if self.pessimistic() {
            literal_loads * u64::from(self.acr.latency)
        } else {
            0
        }
    }

    /// Cycles added to exception entry (12): the vector's read from flash. An extended frame
    /// only reserves the FP registers' space (lazy stacking, FPCCR.LSPEN = 1 at reset): they
    /// are saved at the first FP instruction that runs before the return
    /// ([`Timing::lazy_fp_save_cycles`]).
    pub fn entry_cycles(&self) -> u64 {
        if !self.pessimistic() {
            return 0;
        }
        u64::from(self.acr.latency)
    }

    /// The deferred save of the FP state, charged at the first FP instruction run while an
    /// extended frame's state is still owed.
    pub fn lazy_fp_save_cycles(&self) -> u64 {
        if self.pessimistic() {
            FP_STATE_CYCLES
        } else {
            0
        }
    }

    /// A return with an exception tail-chained onto it, return and entry together: the
    /// Cortex-M4's 6 cycles under the optimistic profile; `None` under the pessimistic one,
    /// which charges a full return and entry.
    pub fn tail_chain_cycles(&self) -> Option<u64> {
        (!self.pessimistic()).then_some(TAIL_CHAIN_CYCLES)
    }

    /// Cycles added to exception return (10) when it restores an FP state that was saved.
    pub fn return_cycles(&self, fp_state_saved: bool) -> u64 {
        if self.pessimistic() && fp_state_saved {
            FP_STATE_CYCLES
        } else {
            0
        }
    }

    /// Whether `addr`'s line is in the instruction cache model (for tests and diagnostics).
    pub fn icache_holds(&self, addr: u32) -> bool {
        flash_line(addr).is_some_and(|l| self.icache.contains(l))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cost(halfwords: &[u16]) -> u64 {
        block_cycles(2 * halfwords.len() as u32, |i| halfwords.get(i as usize).copied().unwrap_or(0)).cycles
    }

    #[test]
    fn profiles_parse_by_name_and_a_wrong_name_is_named() {
        assert_eq!("optimistic".parse(), Ok(TimingProfile::Optimistic));
        assert_eq!("pessimistic".parse(), Ok(TimingProfile::Pessimistic));
        let e = "fast".parse::<TimingProfile>().unwrap_err();
        assert!(e.to_string().contains("\"fast\""), "{e}");
        assert_eq!(TimingProfile::from_env_value(None), Ok(TimingProfile::Optimistic));
        assert_eq!(TimingProfile::from_env_value(Some(OsStr::new("pessimistic"))), Ok(TimingProfile::Pessimistic));
        let e = TimingProfile::from_env_value(Some(OsStr::new("Pessimistic"))).unwrap_err();
        assert!(e.contains("FCU_PIL_TIMING") && e.contains("\"Pessimistic\""), "{e}");
        let e = TimingProfile::from_env_value(Some(OsStr::new(""))).unwrap_err();
        assert!(e.contains("FCU_PIL_TIMING=\"\""), "{e}");
    }

    #[test]
    fn data_processing_is_one_cycle_and_loads_two() {
        // adds r0, r1, #1; movs r2, #5; lsls r3, r3, #2; mov.w r0, #1; add.w r1, r2, r3, lsl #2
        assert_eq!(cost(&[0x1C48, 0x2205, 0x009B, 0xF04F, 0x0001, 0xEB02, 0x0183]), 5);
        // ldr r0, [r1, #4]; str r0, [r2]; ldrb.w r3, [r4, #1]; ldr.w r5, [r6, #256]
        assert_eq!(cost(&[0x6848, 0x6010, 0xF894, 0x3001, 0xF8D6, 0x5100]), 8);
        // ldr r0, [pc, #8] (a literal: one more)
        assert_eq!(cost(&[0x4802]), 3);
        // ldr.w r0, [pc, #8]
        assert_eq!(cost(&[0xF8DF, 0x0008]), 3);
    }

    #[test]
    fn a_load_after_data_processing_waits_for_its_address() {
        // adds r1, #4; ldr r0, [r1]
        assert_eq!(cost(&[0x3104, 0x6808]), 1 + 2 + 1);
        // ldr r0, [r1]; adds r1, #4
        assert_eq!(cost(&[0x6808, 0x3104]), 2 + 1);
    }

    #[test]
    fn multiple_transfers_cost_one_plus_n() {
        // push {r4, r5, r7, lr}: 1 + 4
        assert_eq!(cost(&[0xB5B0]), 5);
        // pop {r4, pc}: 1 + 2
        assert_eq!(cost(&[0xBD10]), 3);
        // stmia r0!, {r1, r2, r3}: 1 + 3
        assert_eq!(cost(&[0xC00E]), 4);
        // push.w {r4-r11, lr}: 1 + 9
        assert_eq!(cost(&[0xE92D, 0x4FF0]), 10);
        // ldrd r0, r1, [r2]: 3
        assert_eq!(cost(&[0xE9D2, 0x0100]), 3);
        // vpush {d8-d9}: imm8 = 4 words, 1 + 4
        assert_eq!(cost(&[0xED2D, 0x8B04]), 5);
        // vldr s0, [r0, #4]: 2; vldr d0, [r0]: 3; vldr s0, [pc, #4]: 3
        assert_eq!(cost(&[0xED90, 0x0A01]), 2);
        assert_eq!(cost(&[0xED90, 0x0B00]), 3);
        assert_eq!(cost(&[0xED9F, 0x0A01]), 3);
    }

    #[test]
    fn divides_and_fp_long_operations_take_their_worst_case() {
        // sdiv r0, r1, r2; udiv r0, r1, r2
        assert_eq!(cost(&[0xFB91, 0xF0F2]), 12);
        assert_eq!(cost(&[0xFBB1, 0xF0F2]), 12);
        // mul r0, r1, r2; mla r0, r1, r2, r3; umull r0, r1, r2, r3
        assert_eq!(cost(&[0xFB01, 0xF002, 0xFB01, 0x3002, 0xFBA2, 0x0103]), 3);
        // vdiv.f32 s0, s1, s2: 14; vsqrt.f32 s0, s1: 14
        assert_eq!(cost(&[0xEE80, 0x0A81]), 14);
        assert_eq!(cost(&[0xEEB1, 0x0AE0]), 14);
        // vmla.f32 s0, s1, s2: 3; vfma.f32 s0, s1, s2: 3
        assert_eq!(cost(&[0xEE00, 0x0A81]), 3);
        assert_eq!(cost(&[0xEEA0, 0x0A81]), 3);
        // vadd.f32 s0, s1, s2; vmul.f32 s0, s1, s2; vneg.f32 s0, s1; vcvt.s32.f32 s0, s0: 1 each
        assert_eq!(cost(&[0xEE30, 0x0A81, 0xEE20, 0x0A81, 0xEEB1, 0x0A60, 0xEEBD, 0x0AC0]), 4);
        // vmov r0, s1 (1); vmov r0, r1, d0 (2)
        assert_eq!(cost(&[0xEE10, 0x0A90]), 1);
        assert_eq!(cost(&[0xEC51, 0x0B10]), 2);
    }

    #[test]
    fn branches_cost_one_here_and_their_refill_where_the_next_block_starts() {
        // b.n; bl; bx lr; cbz r0; beq: one each, statically
        assert_eq!(cost(&[0xE7FE]), 1);
        assert_eq!(cost(&[0xF000, 0xF800]), 1);
        assert_eq!(cost(&[0x4770]), 1);
        assert_eq!(cost(&[0xB100]), 1);
        assert_eq!(cost(&[0xD0FE]), 1);
        // tbb [pc, r0]: 2; dsb: 1 + 3
        assert_eq!(cost(&[0xE8DF, 0xF000]), 2);
        assert_eq!(cost(&[0xF3BF, 0x8F4F]), 4);
        let mut t = Timing::new(TimingProfile::Pessimistic);
        assert_eq!(t.block_entry_cycles(0x2000_0000, 8), 0, "the first block: nothing to refill");
        assert_eq!(t.block_entry_cycles(0x2000_0008, 4), 0, "fall-through");
        assert_eq!(t.block_entry_cycles(0x2000_0100, 4), BRANCH_REFILL_CYCLES, "taken branch");
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(0x2000_0200, 4), 0, "the entry's 12 cycles include the refill");
        let mut o = Timing::new(TimingProfile::Optimistic);
        o.block_entry_cycles(0x2000_0000, 8);
        assert_eq!(o.block_entry_cycles(0x2000_0100, 4), 0, "optimistic: CPI 1, no refill");
    }

    fn two_wait_states(icache: bool, prefetch: bool) -> Timing {
        let mut t = Timing::new(TimingProfile::Pessimistic);
        t.set_acr(AcrTiming { latency: 2, icache, prefetch, dcache: true, ..AcrTiming::default() });
        // Start every case from a known previous block so no refill is charged by accident.
        t.exception_boundary();
        t
    }

    #[test]
    fn the_art_cache_hits_a_line_it_has_fetched_and_misses_a_new_one() {
        let mut t = two_wait_states(true, true);
        let a = 0x0800_0100;
        assert_eq!(t.block_entry_cycles(a, 6), 2, "first fetch misses");
        assert!(t.icache_holds(a));
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(a + 8, 4), 0, "same 128-bit line: hit");
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(a + 16, 4), 2, "next line: miss");
        // The boot alias at 0 is the same flash: the same line.
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(0x100, 4), 0);
        // A block from SRAM pays no wait state.
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(0x2000_0000, 4), 0);
    }

    #[test]
    fn the_art_cache_holds_64_lines_and_replaces_the_least_recently_used() {
        let mut t = two_wait_states(true, true);
        let line = |i: u32| 0x0800_0000 + 16 * i;
        for i in 0..64 {
            t.exception_boundary();
            assert_eq!(t.block_entry_cycles(line(i), 2), 2);
        }
        // Line 0 used again: line 1 is now the least recently used.
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(line(0), 2), 0);
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(line(64), 2), 2, "a 65th line misses");
        assert!(!t.icache_holds(line(1)), "and replaced the least recently used");
        assert!(t.icache_holds(line(0)) && t.icache_holds(line(2)));
        t.set_acr(AcrTiming { latency: 2, icache: false, icache_reset: true, ..t.acr() });
        assert!(!t.icache_holds(line(0)), "ICRST empties it");
    }

    #[test]
    fn without_the_cache_every_block_start_pays_and_without_prefetch_every_line() {
        let mut t = two_wait_states(false, true);
        for _ in 0..3 {
            t.exception_boundary();
            assert_eq!(t.block_entry_cycles(0x0800_0100, 40), 2, "ICEN off: every start, prefetch hides the rest");
        }
        let mut t = two_wait_states(false, false);
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(0x0800_0100, 40), 3 * 2, "three lines, each fetched");
        let mut t = two_wait_states(true, false);
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(0x0800_0100, 40), 3 * 2);
        t.exception_boundary();
        assert_eq!(t.block_entry_cycles(0x0800_0100, 40), 0, "all three cached");
        // With prefetch on, a line the prefetch buffer served is not copied into the cache.
        let mut t = two_wait_states(true, true);
        t.exception_boundary();
        t.block_entry_cycles(0x0800_0100, 40);
        assert!(t.icache_holds(0x0800_0100) && !t.icache_holds(0x0800_0110));
        // Zero wait states: nothing to pay.
        let mut t = Timing::new(TimingProfile::Pessimistic);
        assert_eq!(t.block_entry_cycles(0x0800_0100, 40), 0);
    }

    #[test]
    fn literal_loads_pay_the_flash_wait_states_as_data_cache_misses() {
        // ldr r0, [pc, #8]; ldr.w r1, [pc, #16]; ldr r2, [r3]; ldr r4, [sp, #4]
        let block = [0x4802u16, 0xF8DF, 0x1010, 0x681A, 0x9C01];
        let cost = block_cycles(10, |i| block[i as usize]);
        assert_eq!(cost.literal_loads, 2);
        let t = two_wait_states(true, true);
        assert_eq!(t.literal_load_cycles(cost.literal_loads), 4);
        assert_eq!(Timing::new(TimingProfile::Optimistic).literal_load_cycles(2), 0);
    }

    #[test]
    fn apb_accesses_stall_by_their_bus_clock() {
        let mut t = Timing::new(TimingProfile::Pessimistic);
        // Reset: both APBs at HCLK.
        assert_eq!(t.register_access_cycles(0x4000_380C, 1), 3);
        // The board's tree: PPRE1 = /2 (0b100), PPRE2 = /1.
        t.set_rcc_cfgr(0b100 << PPRE1_SHIFT);
        assert_eq!(t.register_access_cycles(0x4000_380C, 1), 6, "SPI2 on APB1 at 42 MHz");
        assert_eq!(t.register_access_cycles(0x4001_4010, 1), 3, "TIM9 on APB2 at 84 MHz");
        assert_eq!(t.register_access_cycles(0x4000_0000, 2), 12, "a bit-band write is two transfers");
        assert_eq!(t.register_access_cycles(0x4002_0014, 1), 0, "GPIOA on AHB1");
        assert_eq!(t.register_access_cycles(0xE000_E100, 1), 0, "NVIC on the PPB");
        t.set_rcc_cfgr((0b101 << PPRE1_SHIFT) | (0b100 << PPRE2_SHIFT));
        assert_eq!(t.register_access_cycles(0x4000_0000, 1), 1 + 3 + 8, "APB1 /4");
        assert_eq!(t.register_access_cycles(0x4001_0000, 1), 1 + 1 + 4, "APB2 /2");
        assert_eq!(Timing::new(TimingProfile::Optimistic).register_access_cycles(0x4000_380C, 1), 0);
    }

    #[test]
    fn the_fp_state_and_the_vector_fetch_cost_only_the_pessimistic_profile() {
        let p = Timing::new(TimingProfile::Pessimistic);
        assert_eq!((p.entry_cycles(), p.lazy_fp_save_cycles(), p.return_cycles(true), p.return_cycles(false)), (0, 17, 17, 0));
        let p = two_wait_states(true, true);
        assert_eq!(p.entry_cycles(), 2, "the vector's read");
        let o = Timing::new(TimingProfile::Optimistic);
        assert_eq!((o.entry_cycles(), o.lazy_fp_save_cycles(), o.return_cycles(true)), (0, 0, 0));
    }

    #[test]
    fn an_fp_instruction_marks_its_block() {
        // vadd.f32 s0, s0, s1 (0xEE30 0x0A20) then bx lr; and an integer-only block.
        assert!(block_cycles(6, |i| [0xEE30u16, 0x0A20, 0x4770][i as usize]).has_fp);
        assert!(!block_cycles(4, |i| [0x1840u16, 0x4770][i as usize]).has_fp);
    }

    #[test]
    fn a_loop_lap_costs_its_body_its_refill_and_its_fetch() {
        let t = two_wait_states(true, true);
        assert_eq!(t.steady_lap_cycles(0x0800_0100, 8, 5), 5 + 3);
        let t = two_wait_states(false, true);
        assert_eq!(t.steady_lap_cycles(0x0800_0100, 8, 5), 5 + 3 + 2);
        let t = Timing::new(TimingProfile::Optimistic);
        assert_eq!(t.steady_lap_cycles(0x0800_0100, 8, 4), 4);
    }
}
