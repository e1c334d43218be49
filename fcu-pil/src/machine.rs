//! The emulated Cortex-M4F: Unicorn runs the instructions; this module adds what Unicorn
//! leaves out of an M-profile core: the instruction-count clock, exception entry and return
//! (basic and extended FP frames, EXC_RETURN, tail-chaining through the run loop), WFI and the
//! idle loop, fault detection, and the dispatch of memory-mapped I/O to the models.
//!
//! **Time.** The clock counts processor cycles at the current HCLK, as the machine's
//! [`TimingProfile`] prices them ([`crate::timing`]: the optimistic profile charges one cycle
//! per instruction, the pessimistic one each instruction's class, flash wait states, APB stalls
//! and the FP state's stacking). Exception entry and return cost 12 and 10 cycles (Cortex-M4
//! TRM §5.5) plus what the profile adds. The clock advances a whole translation block at a
//! time (charged at its start): interrupts are taken and timed events seen at block
//! boundaries, a quantum of a few instructions (a block ends at every branch); a register
//! access inside the block reaches its model at the instant the profile gives it (early in the
//! block, or at its end). A `b .` idle loop and WFI skip straight to the next event, counting
//! the cycles they would have spun. The same ELF, the same inputs and the same profile give
//! the same instruction stream, the same times and the same outputs, byte for byte.
//!
//! **Faults** are taken as a Cortex-M4 takes them with the configurable faults disabled (as the
//! firmware leaves them): an undefined instruction, an access to reserved memory (a precise
//! BusFault) or an exception frame that does not fit in RAM (a BusFault on stacking) escalates
//! to HardFault and runs the firmware's handler, recorded in [`State::hard_faults`]. A fault
//! while the HardFault handler runs locks the core up ([`LockupEvent`]): nothing executes and
//! no interrupt is taken until a reset (the watchdog's), while the peripherals run on. What the
//! chip does but the model does not know (an access to memory the chip has and the model lacks,
//! an unstacking failure) ends the run with an error instead.
//!
//! **Flash** is mapped read-only; a store into it reaches the board's flash model through
//! Unicorn's write-protection hook ([`Peripherals::flash_memory_write`]), and the model's
//! contents are copied back into the guest ([`Peripherals::take_flash_changes`]). While the
//! model is busy (a program or erase), instruction fetches from flash, stores into it and
//! FLASH_CR writes wait for the end ([`Peripherals::flash_busy_until`]). An injected power cut
//! ([`Peripherals::take_power_cut`]) powers the board on again with RAM cleared.

use std::collections::HashMap;

use unicorn_engine::{Arch, ArmCpuModel, HookType, MemType, Mode, Prot, RegisterARM, Unicorn};

use crate::elf::Image;
use crate::periph::flash::{self, AcrTiming};
use crate::periph::{Time, Unmodelled};
use crate::scs::{self, Scs};
use crate::timing::{self, Timing, TimingProfile};

/// Flash, its boot alias at 0, SRAM, and the system memory page with the factory values.
pub const FLASH_BASE: u32 = 0x0800_0000;
pub const FLASH_SIZE: u32 = 256 * 1024;
pub const SRAM_BASE: u32 = 0x2000_0000;
pub const SRAM_SIZE: u32 = 64 * 1024;
pub const SYSMEM_PAGE: u32 = 0x1FFF_7000;

/// Cycles of exception entry and return on a Cortex-M4 with zero-wait-state memory.
const ENTRY_CYCLES: u64 = 12;
const RETURN_CYCLES: u64 = 10;
/// The `until` address of `emu_start`: never executed.
const NEVER: u64 = 0xFFFF_FFFE;
/// The NMI's exception number (ARMv7-M B1.5.2).
const NMI: usize = 2;
/// Value painted over the stack region at power-on, to find the high-water mark.
pub const STACK_PAINT: u8 = 0xA5;

/// What the rest of the board looks like to the core: the memory-mapped peripherals outside
/// the system control space, with their own sense of time.
pub trait Peripherals {
    /// A read of `size` bytes (1, 2 or 4) at `addr`.
    fn read(&mut self, addr: u32, size: u32, now: Time) -> Result<u32, Unmodelled>;
    /// A write of `size` bytes at `addr`.
    fn write(&mut self, addr: u32, size: u32, value: u32, now: Time) -> Result<(), Unmodelled>;
    /// The next time a model changes by itself (or an external input is scheduled).
    fn next_event(&self) -> Option<Time>;
    /// Brings every model up to `now` and reports each interrupt line's level. Returns
    /// `true` if the independent watchdog expired (the machine then resets).
    fn advance(&mut self, now: Time, lines: &mut dyn FnMut(u32, bool)) -> Result<bool, Unmodelled>;
    /// Time units per processor cycle at the current SYSCLK.
    fn units_per_cycle(&self) -> Result<u64, Unmodelled>;
    /// A system reset (watchdog or SYSRESETREQ): every model back to its reset state except
    /// what survives a reset on the chip (RCC's reset flags).
    fn system_reset(&mut self, watchdog: bool);
    /// The bytes of the factory system-memory page at [`SYSMEM_PAGE`] (4 KiB).
    fn system_memory_page(&self) -> Vec<u8>;
    /// Bytes a bus master other than the core (DMA) wrote to memory since the last call:
    /// (address, byte), in order. The machine stores them in the guest's RAM.
    fn take_memory_writes(&mut self) -> Vec<(u32, u8)> {
        Vec::new()
    }
    /// A CPU write of `size` bytes into the flash memory, `offset` bytes from [`FLASH_BASE`]
    /// (or from its boot alias at 0). The default refuses it: a board without a flash model.
    fn flash_memory_write(&mut self, offset: u32, _size: u32, _value: u32, _now: Time) -> Result<(), Unmodelled> {
        Err(Unmodelled::new(format!("flash +{offset:#07x}"), "a write to flash, and no flash interface is modelled"))
    }
    /// The flash memory's ranges changed since the last call: (offset, contents). The machine
    /// copies them into the guest's flash and its boot alias.
    fn take_flash_changes(&mut self) -> Vec<(u32, Vec<u8>)> {
        Vec::new()
    }
    /// While a flash operation runs (BSY), until when: instruction fetches from flash stall.
    fn flash_busy_until(&self) -> Option<Time> {
        None
    }
    /// The flash contents at power-on, given the image's (the ELF over erased flash).
    fn power_on_flash(&mut self, image: Vec<u8>) -> Vec<u8> {
        image
    }
    /// A bus error the last register write caused (a wrong flash key), once.
    fn take_bus_error(&mut self) -> Option<&'static str> {
        None
    }
    /// Whether the board lost its power (an injected cut), once: the machine powers it on again.
    fn take_power_cut(&mut self) -> bool {
        false
    }
    /// The level of the line wired to the core's NMI (the clock security system's CSSF): the
    /// machine pends the NMI while it is high and the NMI is not being served.
    fn nmi_line(&self) -> bool {
        false
    }
    /// The system clock is gone (a failed crystal with no clock security system): the core
    /// executes nothing until a reset; the peripherals and the watchdog go on.
    fn core_clock_stopped(&self) -> bool {
        false
    }
    /// Every model back to power-on, except what keeps without power (the flash memory).
    fn power_on_reset(&mut self) {
        self.system_reset(false);
    }
}

/// Why a run ended early.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Fault {
    /// An access to a register or bit the models do not implement.
    Unmodelled { error: Unmodelled, pc: u32, at: Time },
    /// An access to memory the chip has and the model lacks (the SRAM bit-band alias, an
    /// unmodelled peripheral), a write to system memory, an instruction fetch from RAM: what
    /// the chip does with these is not modelled, so the run stops. (An access to reserved
    /// memory is a BusFault, taken as silicon takes it.)
    Memory { kind: &'static str, address: u32, pc: u32, at: Time },
    /// Unstacking an exception frame failed (a handler moved SP out of RAM): the UNSTKERR
    /// BusFault on return is not modelled.
    Stacking { address: u32, pc: u32, at: Time },
    /// An EXC_RETURN the architecture does not allow, or a return from a non-active exception.
    BadReturn { exc_return: u32, pc: u32, at: Time },
    /// Something in the emulator itself failed.
    Emulator(String),
    /// The harness was set up wrongly (an unknown timing profile in the environment).
    Setup(String),
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let t = |at: &Time| crate::periph::time_to_s(*at);
        match self {
            Fault::Unmodelled { error, pc, at } => write!(f, "unmodelled access at {:.6} s, in the block at PC {pc:#010x}: {error}", t(at)),
            Fault::Memory { kind, address, pc, at } => write!(f, "{kind} at address {address:#010x}, PC {pc:#010x}, {:.6} s", t(at)),
            Fault::Stacking { address, pc, at } => {
                write!(f, "exception return with its frame at {address:#010x} outside RAM, PC {pc:#010x}, {:.6} s", t(at))
            }
            Fault::BadReturn { exc_return, pc, at } => {
                write!(f, "invalid exception return {exc_return:#010x} at PC {pc:#010x}, {:.6} s", t(at))
            }
            Fault::Emulator(m) => write!(f, "emulator: {m}"),
            Fault::Setup(m) => write!(f, "setup: {m}"),
        }
    }
}

impl std::error::Error for Fault {}

/// A HardFault the firmware took (it runs its handler; the caller decides whether that ends
/// the run).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HardFaultEvent {
    pub at: Time,
    pub pc: u32,
    pub cause: String,
}

/// The core locked up (ARMv7-M B1.5.15): a fault it could not take, here a fault while the
/// HardFault handler ran. It executes nothing more and takes no interrupt; the peripherals
/// run on, and only a reset (the independent watchdog's, on this board) ends it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LockupEvent {
    pub at: Time,
    /// The instruction that faulted (the core's own PC reads 0xFFFF_FFFE while locked).
    pub pc: u32,
    pub cause: String,
}

/// An interval during which the interrupt masks (PRIMASK, or BASEPRI at or above its
/// priority) kept the watched exception from being taken, see
/// [`Machine::measure_masking_against`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaskedInterval {
    pub from: Time,
    pub to: Time,
    /// Start of the translation block whose instructions set the mask.
    pub pc: u32,
}

/// Interrupt masking and pending-to-entry waits, measured only when asked (reading the mask
/// registers at every block costs host time).
#[derive(Clone, Debug, Default)]
pub struct MaskingStats {
    /// The exception whose masking is measured.
    pub watched: usize,
    pub longest: Option<MaskedInterval>,
    /// Completed intervals and their total time.
    pub intervals: u64,
    pub total: Time,
    /// The open interval: since when, and the block that set the mask.
    open: Option<(Time, u32)>,
}

impl MaskingStats {
    fn close(&mut self, to: Time) {
        if let Some((from, pc)) = self.open.take() {
            let interval = MaskedInterval { from, to, pc };
            self.intervals += 1;
            self.total += to - from;
            if self.longest.is_none_or(|l| l.to - l.from < to - from) {
                self.longest = Some(interval);
            }
        }
    }
}

/// CFSR bits (ARMv7-M B3.2.15): BusFault IBUSERR, PRECISERR, STKERR. (BFAR is not modelled,
/// so BFARVALID stays clear.)
const CFSR_IBUSERR: u32 = 1 << 8;
const CFSR_PRECISERR: u32 = 1 << 9;
const CFSR_STKERR: u32 = 1 << 12;
/// CFSR IMPRECISERR: a bus error on a buffered write (a wrong flash key).
const CFSR_IMPRECISERR: u32 = 1 << 10;
/// CFSR bits (ARMv7-M B3.2.15): UsageFault UNDEFINSTR, INVSTATE.
const CFSR_UNDEFINSTR: u32 = 1 << 16;
const CFSR_INVSTATE: u32 = 1 << 17;

#[derive(Clone, Debug)]
enum Stop {
    /// The deadline (an event, or the end of the run) was reached.
    Deadline,
    /// A pending exception can preempt.
    Interrupt,
    /// The guest branched to an EXC_RETURN value in handler mode.
    ExceptionReturn,
    SyncFault(SyncFault),
    Unmodelled(Unmodelled),
    Memory {
        kind: &'static str,
        address: u32,
        /// The CFSR bits of the BusFault silicon raises for it; `None`: not modelled.
        bus_fault: Option<u32>,
    },
}

/// A fault the core raises at the instruction it executes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SyncFault {
    /// An undefined instruction (a panic's `udf`).
    UndefinedInstruction,
    /// Another CPU exception QEMU raised, by its EXCP number.
    CpuException(u32),
}

impl SyncFault {
    /// The UsageFault status bit it sets in CFSR (ARMv7-M B3.2.15): UNDEFINSTR for an
    /// undefined instruction, INVSTATE otherwise.
    fn cfsr_bits(self) -> u32 {
        match self {
            SyncFault::UndefinedInstruction => CFSR_UNDEFINSTR,
            SyncFault::CpuException(_) => CFSR_INVSTATE,
        }
    }
}

impl std::fmt::Display for SyncFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SyncFault::UndefinedInstruction => write!(f, "undefined instruction (UsageFault UNDEFINSTR)"),
            SyncFault::CpuException(n) => write!(f, "CPU exception {n} (QEMU EXCP number)"),
        }
    }
}

/// Instruction counts and pessimistic cycle counts of translation blocks, from the flash image.
struct Code {
    flash: Vec<u8>,
    /// Per flash halfword: the block starting there (`None` = not seen yet). A direct table:
    /// the block hook runs millions of times a second.
    blocks: Vec<Option<BlockInfo>>,
}

#[derive(Clone, Copy, Debug)]
struct BlockInfo {
    size: u32,
    instructions: u64,
    /// The block's own cycles in the pessimistic profile ([`timing::block_cycles`]).
    cycles: u64,
    /// Its PC-relative loads (flash data reads).
    literal_loads: u64,
    /// It holds an FP instruction (a lazily stacked FP state is saved there).
    has_fp: bool,
    kind: BlockKind,
}

/// What the block hook does with a block besides counting it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BlockKind {
    Plain,
    /// `b .`: an idle spin.
    IdleSpin,
    /// `subs rN, #1; bne .-2` (cortex-m's `asm::delay`): a countdown of rN laps.
    Countdown(u8),
    /// `ldr rT, [rA]; subs rD, rT, rS; cmp rD, rL; blo .-6` with rA = DWT_CYCCNT: a wait until
    /// `CYCCNT - rS >= rL`, unsigned (a cycle-counter delay). Fields: rA, rS, rL.
    CycleCountWait {
        addr: u8,
        start: u8,
        limit: u8,
    },
}

impl Code {
    fn new(flash: Vec<u8>) -> Code {
        let n = flash.len() / 2;
        Code { flash, blocks: vec![None; n] }
    }

    fn halfword(&self, addr: u32) -> Option<u16> {
        let off = addr.checked_sub(FLASH_BASE)? as usize;
        let b = self.flash.get(off..off + 2)?;
        Some(u16::from_le_bytes([b[0], b[1]]))
    }

    /// The block at `addr` of `size` bytes: its instructions, its pessimistic cycles, its kind.
    fn block(&mut self, addr: u32, size: u32) -> BlockInfo {
        let slot = addr.checked_sub(FLASH_BASE).map(|o| (o / 2) as usize);
        if let Some(Some(info)) = slot.and_then(|i| self.blocks.get(i)) {
            if info.size == size {
                return *info;
            }
        }
        let cost = timing::block_cycles(size, |i| self.halfword(addr.wrapping_add(2 * i)).unwrap_or(0));
        let info = BlockInfo {
            size,
            instructions: cost.instructions,
            cycles: cost.cycles,
            literal_loads: cost.literal_loads,
            has_fp: cost.has_fp,
            kind: self.classify(addr, size),
        };
        if let Some(entry) = slot.and_then(|i| self.blocks.get_mut(i)) {
            *entry = Some(info);
        }
        info
    }

    fn classify(&self, addr: u32, size: u32) -> BlockKind {
        let hw = |i: u32| self.halfword(addr + 2 * i).unwrap_or(0);
        if size == 2 && hw(0) == 0xE7FE {
            return BlockKind::IdleSpin;
        }
        // SUBS Rdn, #1 (T2: 0b00111 Rdn 00000001) then BNE back to it (0xD1FD).
        if size == 4 && hw(0) & 0xF8FF == 0x3801 && hw(1) == 0xD1FD {
            return BlockKind::Countdown(((hw(0) >> 8) & 7) as u8);
        }
        if size == 8 {
            let (ldr, subs, cmp, b) = (hw(0), hw(1), hw(2), hw(3));
            // LDR Rt, [Rn, #0] (T1), SUBS Rd, Rn', Rm (T1), CMP Rn'', Rm' (T1), BCC -6 (T1).
            let is_ldr = ldr >> 6 == 0b01101_00000;
            let is_subs = subs >> 9 == 0b0001101;
            let is_cmp = cmp >> 6 == 0b0100001010;
            let is_blo_back = b == 0xD3FB;
            if is_ldr && is_subs && is_cmp && is_blo_back {
                let (rt, ra) = ((ldr & 7) as u8, ((ldr >> 3) & 7) as u8);
                let (rd, rn, rs) = ((subs & 7) as u8, ((subs >> 3) & 7) as u8, ((subs >> 6) & 7) as u8);
                let (cn, rl) = ((cmp & 7) as u8, ((cmp >> 3) & 7) as u8);
                // The loop reads only rA, rS, rL, which it must not write.
                let written = [rt, rd];
                if rn == rt && cn == rd && ![ra, rs, rl].iter().any(|r| written.contains(r)) {
                    return BlockKind::CycleCountWait { addr: ra, start: rs, limit: rl };
                }
            }
        }
        BlockKind::Plain
    }

    fn is_wfi_before(&self, pc: u32) -> bool {
        self.halfword(pc.wrapping_sub(2)) == Some(0xBF30)
    }
}

/// Per-exception accounting, for the measurements on the image.
#[derive(Clone, Debug, Default)]
pub struct ExceptionStats {
    /// Entries taken.
    pub entries: u64,
    /// Instructions executed in each completed activation, nested handlers excluded.
    pub instructions: Vec<u64>,
    /// Entry time of each completed activation and its return time.
    pub spans: Vec<(Time, Time)>,
    /// While measuring ([`Machine::measure_masking_against`]): the longest time from its
    /// interrupt line rising to its entry, and that entry's time.
    pub longest_pending: Option<(Time, Time)>,
}

/// The state the hooks see.
pub struct State<P: Peripherals> {
    pub board: P,
    pub scs: Scs,
    pub now: Time,
    deadline: Time,
    units_per_cycle: u64,
    pub instructions: u64,
    /// Time spent in WFI or in the `b .` idle loop.
    pub idle_time: Time,
    /// Time the core spent stalled on a flash fetch while a program or erase ran.
    pub flash_stall_time: Time,
    /// While measured ([`Machine::measure_time_in`]): the code ranges (start, end), sorted,
    /// and the time spent running blocks that start in one of them.
    pub region: Option<(Vec<(u32, u32)>, Time)>,
    /// A store into flash went through Unicorn: its copy must be restored from the model.
    flash_dirty: bool,
    /// The flash interface was written since the block hook last found it idle: the hook looks
    /// at it (a program or erase may be running) only then, to keep its own cost down.
    flash_watch: bool,
    stop: Option<Stop>,
    code: Code,
    /// How the clock prices what runs, with the caches and bus state it needs.
    pub timing: Timing,
    /// Start of the block being executed (for error reports and access times) and its size.
    block_pc: u32,
    block_size: u32,
    /// When the block being executed started its own instructions (after what its start cost).
    block_started_at: Time,
    /// The exception being served (0 = thread mode), tracked at entry and return.
    current_exception: usize,
    /// Instructions attributed to each active exception (preempted ones keep their count).
    exc_instructions: Vec<u64>,
    exc_entered_at: Vec<Time>,
    /// Stack of exceptions (nesting) for attribution.
    exc_stack: Vec<usize>,
    pub exception_stats: HashMap<usize, ExceptionStats>,
    /// Whether the core sleeps (WFI, or SLEEPONEXIT on return to thread mode).
    sleeping: bool,
    pub hard_faults: Vec<HardFaultEvent>,
    /// Every lockup; the last one holds while `locked_up` is set.
    pub lockups: Vec<LockupEvent>,
    locked_up: bool,
    pub resets: Vec<(Time, &'static str)>,
    /// Exception entries that stacked the extended (FP) frame.
    pub fp_frames: u64,
    /// Per active exception: whether its extended frame's FP state is still owed (lazy
    /// stacking) or was saved (and is restored on return).
    fp_frames_owed: Vec<LazyFp>,
    /// Masking and pending waits, when measured.
    pub masking: Option<MaskingStats>,
    /// While measuring: per exception, since when its interrupt line has held it pending.
    pending_since: Vec<Option<Time>>,
    /// When the interrupt lines were last sampled.
    lines_sampled_at: Time,
    /// The last exception return was charged as the start of a tail-chain: the entry that
    /// follows pays the rest ([`Timing::tail_chain_cycles`]).
    tail_chaining: bool,
}

#[derive(Clone, Copy, Debug)]
struct LazyFp {
    owed: bool,
    saved: bool,
}

impl<P: Peripherals> State<P> {
    /// The state at power-on: nothing run, nothing pending, the clock at the board's reset
    /// frequency.
    fn power_on(board: P, code: Code, timing: Timing) -> Result<Self, Fault> {
        let units_per_cycle = board.units_per_cycle().map_err(|error| Fault::Unmodelled { error, pc: 0, at: 0 })?;
        Ok(State {
            board,
            scs: Scs::new(units_per_cycle),
            now: 0,
            deadline: 0,
            units_per_cycle,
            instructions: 0,
            idle_time: 0,
            region: None,
            flash_stall_time: 0,
            flash_dirty: false,
            flash_watch: false,
            stop: None,
            code,
            timing,
            block_pc: 0,
            block_size: 0,
            block_started_at: 0,
            current_exception: 0,
            exc_instructions: vec![0; scs::EXCEPTIONS],
            exc_entered_at: vec![0; scs::EXCEPTIONS],
            exc_stack: Vec::new(),
            exception_stats: HashMap::new(),
            sleeping: false,
            hard_faults: Vec::new(),
            lockups: Vec::new(),
            locked_up: false,
            resets: Vec::new(),
            fp_frames: 0,
            fp_frames_owed: Vec::new(),
            masking: None,
            pending_since: vec![None; scs::EXCEPTIONS],
            lines_sampled_at: 0,
            tail_chaining: false,
        })
    }

    fn attribute(&mut self, n: u64) {
        if let Some(c) = self.exc_instructions.get_mut(self.current_exception) {
            *c += n;
        }
    }

    /// Whether the core is locked up.
    pub fn locked_up(&self) -> bool {
        self.locked_up
    }

    /// Hands the interrupt lines' levels, sampled at `now`, to the NVIC. While measuring, a
    /// line that pends its exception starts that exception's wait: from the earliest instant
    /// it can have risen, the emulation's deadline (the first model event since the last
    /// sample) or the last sample, whichever is later. That is exact for the first event
    /// after the last sample and an upper bound (by less than a block) for a later one.
    fn sample_lines(&mut self, now: Time, lines: &[(u32, bool)]) {
        let measuring = self.masking.is_some();
        let rose_by = self.lines_sampled_at.max(self.deadline.min(now));
        for &(irq, level) in lines {
            self.scs.sample_line(irq, level);
            if !measuring {
                continue;
            }
            let exc = 16 + irq as usize;
            let Some(since) = self.pending_since.get_mut(exc) else { continue };
            if level && since.is_none() && !self.scs.is_active(exc) {
                *since = Some(rose_by);
            } else if !level && since.is_some() {
                // Software may have cleared the pending bit (NVIC_ICPR) with the line low.
                let ispr = self.scs.read(scs::reg::NVIC_ISPR + 4 * (irq / 32), now, self.current_exception).unwrap_or(u32::MAX);
                if ispr & (1 << (irq % 32)) == 0 {
                    *since = None;
                }
            }
        }
        self.lines_sampled_at = now;
    }
}

/// The emulated STM32F401 core with its peripherals.
pub struct Machine<P: Peripherals + 'static> {
    uc: Unicorn<'static, State<P>>,
    image: Image,
    /// The lowest address of the stack region (flip-link puts the stack at the bottom of
    /// RAM) and the initial stack pointer.
    pub stack_bottom: u32,
    pub stack_top: u32,
}

fn emu(e: unicorn_engine::uc_error) -> Fault {
    Fault::Emulator(format!("{e:?}"))
}

/// The flash as the image programs it (erased bytes read 0xFF).
fn flash_contents(image: &Image) -> Result<Vec<u8>, Fault> {
    let mut flash = vec![0xFFu8; FLASH_SIZE as usize];
    for seg in &image.segments {
        let off = seg.address.checked_sub(FLASH_BASE).map(|o| o as usize);
        match off.and_then(|o| flash.get_mut(o..o + seg.data.len())) {
            Some(dst) => dst.copy_from_slice(&seg.data),
            None => {
                return Err(Fault::Emulator(format!("ELF segment at {:#010x} ({} bytes) is not in flash", seg.address, seg.data.len())))
            }
        }
    }
    Ok(flash)
}

/// Flash, read-only and executable, and its alias at 0 (BOOT0 low: boot from flash); SRAM; the
/// system-memory page.
fn map_memory<P: Peripherals>(uc: &mut Unicorn<'static, State<P>>, flash: &[u8], sysmem: &[u8]) -> Result<(), Fault> {
    uc.mem_map(u64::from(FLASH_BASE), u64::from(FLASH_SIZE), Prot::READ | Prot::EXEC).map_err(emu)?;
    uc.mem_write(u64::from(FLASH_BASE), flash).map_err(emu)?;
    uc.mem_map(0, u64::from(FLASH_SIZE), Prot::READ | Prot::EXEC).map_err(emu)?;
    uc.mem_write(0, flash).map_err(emu)?;
    uc.mem_map(u64::from(SRAM_BASE), u64::from(SRAM_SIZE), Prot::READ | Prot::WRITE).map_err(emu)?;
    uc.mem_map(u64::from(SYSMEM_PAGE), 0x1000, Prot::READ).map_err(emu)?;
    uc.mem_write(u64::from(SYSMEM_PAGE), sysmem).map_err(emu)
}

/// The regions whose accesses go to the peripheral models and the SCS: APB1, APB2, AHB1
/// (GPIO, RCC, FLASH), the peripheral bit-band alias and the private peripheral bus, as
/// (base, size). Everything else stays unmapped: an access faults.
const PERIPHERAL_REGIONS: [(u64, u64); 5] =
    [(0x4000_0000, 0x8000), (0x4001_0000, 0x8000), (0x4002_0000, 0x8000), (0x4200_0000, 0x0200_0000), (0xE000_0000, 0x0010_0000)];

fn map_peripherals<P: Peripherals + 'static>(uc: &mut Unicorn<'static, State<P>>) -> Result<(), Fault> {
    for (base, size) in PERIPHERAL_REGIONS {
        uc.mmio_map(
            base,
            size,
            Some(move |uc: &mut Unicorn<'_, State<P>>, offset: u64, size: usize| mmio_read(uc, (base + offset) as u32, size as u32)),
            Some(move |uc: &mut Unicorn<'_, State<P>>, offset: u64, size: usize, value: u64| {
                mmio_write(uc, (base + offset) as u32, size as u32, value as u32)
            }),
        )
        .map_err(emu)?;
    }
    Ok(())
}

/// The hooks that price blocks, stamp register accesses and stop the emulation at a fault.
fn add_hooks<P: Peripherals + 'static>(uc: &mut Unicorn<'static, State<P>>) -> Result<(), Fault> {
    uc.add_block_hook(1, 0, block_hook::<P>).map_err(emu)?;
    // No memory hook on the peripheral range or on flash: with one, Unicorn 2.1.5 misexecuted
    // the release image (see `timing`); the profiles date accesses from the block being run.
    uc.add_intr_hook(|uc: &mut Unicorn<'_, State<P>>, intno: u32| {
        let st = uc.get_data_mut();
        // QEMU's EXCP_EXCEPTION_EXIT: a branch to EXC_RETURN in handler mode.
        st.stop = Some(if intno == 8 { Stop::ExceptionReturn } else { Stop::SyncFault(SyncFault::CpuException(intno)) });
        let _ = uc.emu_stop();
    })
    .map_err(emu)?;
    uc.add_insn_invalid_hook(|uc: &mut Unicorn<'_, State<P>>| {
        uc.get_data_mut().stop = Some(Stop::SyncFault(SyncFault::UndefinedInstruction));
        let _ = uc.emu_stop();
        true
    })
    .map_err(emu)?;
    uc.add_mem_hook(HookType::MEM_UNMAPPED | HookType::MEM_PROT, 1, 0, memory_fault_hook::<P>).map_err(emu)?;
    Ok(())
}

/// A store into flash (mapped read-only) goes to the flash model ([`flash_write`]). Otherwise
/// nothing answers at a reserved address: the bus returns an error, a BusFault (precise for a
/// data access, ARMv7-M B3.2.15; an instruction fetch faults when the instruction would
/// execute). An address where the chip has something the model lacks, and the rest, are
/// refused.
fn memory_fault_hook<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, kind: MemType, addr: u64, size: usize, value: i64) -> bool {
    if kind == MemType::WRITE_PROT {
        if let Some(offset) = flash_offset(addr as u32) {
            return flash_write(uc, offset, size as u32, value as u32);
        }
    }
    let reserved = !implemented_but_unmodelled(addr as u32);
    let (kind, bus_fault) = match kind {
        MemType::READ_UNMAPPED if reserved => ("read of reserved memory", Some(CFSR_PRECISERR)),
        MemType::WRITE_UNMAPPED if reserved => ("write to reserved memory", Some(CFSR_PRECISERR)),
        MemType::FETCH_UNMAPPED if reserved => ("instruction fetch from reserved memory", Some(CFSR_IBUSERR)),
        MemType::READ_UNMAPPED | MemType::WRITE_UNMAPPED | MemType::FETCH_UNMAPPED => {
            ("access to memory the chip has and the model does not", None)
        }
        MemType::WRITE_PROT => ("write to read-only memory (system memory)", None),
        MemType::FETCH_PROT => ("instruction fetch from non-executable memory", None),
        _ => ("memory access fault", None),
    };
    let st = uc.get_data_mut();
    if st.stop.is_none() || matches!(st.stop, Some(Stop::Deadline | Stop::Interrupt)) {
        st.stop = Some(Stop::Memory { kind, address: addr as u32, bus_fault });
    }
    false
}

impl<P: Peripherals + 'static> Machine<P> {
    /// Powers on the board with `image` in flash, its time priced by `profile`.
    pub fn new(image: Image, board: P, profile: TimingProfile) -> Result<Self, Fault> {
        let mut board = board;
        let flash = board.power_on_flash(flash_contents(&image)?);
        let sysmem = board.system_memory_page();
        let state = State::power_on(board, Code::new(flash.clone()), Timing::new(profile))?;
        let mut uc = Unicorn::new_with_data(Arch::ARM, Mode::THUMB | Mode::MCLASS, state).map_err(emu)?;
        uc.ctl_set_cpu_model(ArmCpuModel::CORTEX_M4 as i32).map_err(emu)?;
        map_memory(&mut uc, &flash, &sysmem)?;
        map_peripherals(&mut uc)?;
        add_hooks(&mut uc)?;
        let stack_top = image.initial_sp;
        let mut m = Machine { uc, image, stack_bottom: SRAM_BASE, stack_top };
        m.power_on_ram()?;
        m.reset_core()?;
        Ok(m)
    }

    /// SRAM as at power-on: zero (an assumption: real SRAM powers up with arbitrary contents),
    /// with the stack region painted so its high-water mark can be read later.
    fn power_on_ram(&mut self) -> Result<(), Fault> {
        self.uc.mem_write(u64::from(SRAM_BASE), &vec![0; SRAM_SIZE as usize]).map_err(emu)?;
        let paint = vec![STACK_PAINT; self.stack_top.saturating_sub(SRAM_BASE) as usize];
        self.uc.mem_write(u64::from(SRAM_BASE), &paint).map_err(emu)
    }

    pub fn state(&self) -> &State<P> {
        self.uc.get_data()
    }

    pub fn state_mut(&mut self) -> &mut State<P> {
        self.uc.get_data_mut()
    }

    pub fn board(&self) -> &P {
        &self.uc.get_data().board
    }

    pub fn board_mut(&mut self) -> &mut P {
        &mut self.uc.get_data_mut().board
    }

    /// The exception being served (0 in thread mode; 16 + n for IRQ n).
    pub fn current_exception(&self) -> usize {
        self.uc.get_data().current_exception
    }

    pub fn now(&self) -> Time {
        self.uc.get_data().now
    }

    pub fn image(&self) -> &Image {
        &self.image
    }

    fn reg(&self, r: RegisterARM) -> Result<u32, Fault> {
        self.uc.reg_read(r).map(|v| v as u32).map_err(emu)
    }

    fn set_reg(&mut self, r: RegisterARM, v: u32) -> Result<(), Fault> {
        self.uc.reg_write(r, u64::from(v)).map_err(emu)
    }

    pub fn pc(&self) -> u32 {
        self.reg(RegisterARM::PC).unwrap_or(0)
    }

    /// Reads guest memory (RAM or flash).
    pub fn read_memory(&self, addr: u32, len: usize) -> Result<Vec<u8>, Fault> {
        self.uc.mem_read_as_vec(u64::from(addr), len).map_err(emu)
    }

    /// The core's reset: SP and PC from the vector table at 0, thread mode, everything
    /// unmasked, no FP context (ARMv7-M B1.5.5).
    fn reset_core(&mut self) -> Result<(), Fault> {
        let vt = self.read_memory(0, 8)?;
        let sp = u32::from_le_bytes([vt[0], vt[1], vt[2], vt[3]]);
        let pc = u32::from_le_bytes([vt[4], vt[5], vt[6], vt[7]]);
        self.set_reg(RegisterARM::CONTROL, 0)?;
        self.set_reg(RegisterARM::PRIMASK, 0)?;
        self.set_reg(RegisterARM::BASEPRI, 0)?;
        self.set_reg(RegisterARM::FAULTMASK, 0)?;
        self.set_reg(RegisterARM::XPSR_NZCVQG, 1 << 24)?;
        self.rebuild_flags()?;
        self.set_reg(RegisterARM::SP, sp & !3)?;
        self.set_reg(RegisterARM::LR, 0xFFFF_FFFF)?;
        self.set_reg(RegisterARM::PC, pc | 1)?;
        let st = self.uc.get_data_mut();
        st.scs = Scs::new(st.units_per_cycle);
        st.timing.reset();
        st.current_exception = 0;
        st.exc_stack.clear();
        st.fp_frames_owed.clear();
        st.sleeping = false;
        st.locked_up = false;
        let now = st.now;
        if let Some(m) = st.masking.as_mut() {
            m.close(now);
        }
        st.pending_since.iter_mut().for_each(|p| *p = None);
        Ok(())
    }

    /// QEMU caches the handler-mode flag: a write that moves the CPU between thread and
    /// handler mode from outside the emulation is followed by an APSR write, which rebuilds
    /// the cache.
    fn rebuild_flags(&mut self) -> Result<(), Fault> {
        let apsr = self.reg(RegisterARM::APSR_NZCV)?;
        self.set_reg(RegisterARM::APSR_NZCV, apsr)
    }

    fn add_cycles(&mut self, cycles: u64) {
        let st = self.uc.get_data_mut();
        st.now += cycles * st.units_per_cycle;
    }

    /// Exception entry (ARMv7-M B1.5.6): push the frame (extended when an FP context is
    /// active, with the FP registers saved at once rather than lazily: the same values), set
    /// LR to EXC_RETURN, IPSR to the exception, and branch to its vector.
    ///
    /// A frame that does not fit in RAM (a stack overflow: flip-link puts the stack at the
    /// bottom of RAM, so it runs off into reserved memory) is a BusFault on stacking, STKERR,
    /// a derived exception. SP has moved to the frame all the same (the push updates SP before
    /// it writes). The BusFault is not enabled, so it escalates to HardFault, which preempts
    /// the exception being entered: the HardFault handler is entered in its place without a
    /// frame of its own, the other exception staying pending. When the exception being entered
    /// is HardFault (or NMI) itself, its handler runs anyway: a derived fault of the kind
    /// being entered cannot preempt it ("the fault handler still executes even though the
    /// stack pushes for the handler failed", Cortex-M3 TRM §5.12.1, the Cortex-M4 generic
    /// user guide's "Fault escalation"). Either way the handler starts with SP outside RAM,
    /// and its first stack access faults in the HardFault handler: a lockup.
    fn enter_exception(&mut self, exc: usize, return_pc: u32) -> Result<(), Fault> {
        let now = self.now();
        if self.uc.get_data().masking.is_some() {
            let primask = self.reg(RegisterARM::PRIMASK)? & 1 != 0;
            let basepri = self.reg(RegisterARM::BASEPRI)?;
            self.uc.get_data_mut().observe_masks(primask, basepri);
        }
        let control = self.reg(RegisterARM::CONTROL)?;
        if control & 2 != 0 {
            return Err(Fault::Unmodelled {
                error: Unmodelled::new("CONTROL.SPSEL", "the process stack (PSP) is not modelled"),
                pc: return_pc,
                at: now,
            });
        }
        let fp_active = control & 4 != 0;
        let xpsr = self.reg(RegisterARM::XPSR)?;
        let (frame_sp, bytes) = self.exception_frame(return_pc, xpsr, fp_active)?;
        let stacked = frame_sp >= SRAM_BASE && frame_sp.wrapping_add(bytes.len() as u32) <= SRAM_BASE + SRAM_SIZE;
        // A push that faults is abandoned (ARMv7-M B1.5.6, PushStack): which of its words
        // reached RAM is not specified; none do here.
        if stacked {
            self.uc.mem_write(u64::from(frame_sp), &bytes).map_err(emu)?;
        }
        self.set_reg(RegisterARM::SP, frame_sp)?;
        let exc = if stacked { exc } else { self.stacking_fault(exc, frame_sp, return_pc, now) };
        self.branch_to_handler(exc, xpsr, control)?;
        self.charge_entry();
        self.uc.get_data_mut().fp_frames_owed.push(LazyFp { owed: fp_active && stacked, saved: false });
        self.uc.get_data_mut().timing.exception_boundary();
        self.uc.get_data_mut().record_entry(exc, now, fp_active && stacked);
        Ok(())
    }

    /// The frame an entry pushes, with where it goes: R0–R3, R12, LR, the return address and
    /// xPSR, then with an active FP context S0–S15, FPSCR and a reserved word; 8-byte aligned
    /// (STKALIGN), the stacked xPSR's bit 9 saying whether a word of padding was added.
    fn exception_frame(&mut self, return_pc: u32, xpsr: u32, fp_active: bool) -> Result<(u32, Vec<u8>), Fault> {
        let mut regs = [0u32; 8];
        for (slot, r) in
            regs.iter_mut().zip([RegisterARM::R0, RegisterARM::R1, RegisterARM::R2, RegisterARM::R3, RegisterARM::R12, RegisterARM::LR])
        {
            *slot = self.reg(r)?;
        }
        regs[6] = return_pc & !1;
        let sp = self.reg(RegisterARM::SP)?;
        let frame_bytes: u32 = if fp_active { 0x68 } else { 0x20 };
        let mut frame_sp = sp.wrapping_sub(frame_bytes);
        let mut stacked_xpsr = xpsr;
        if frame_sp & 4 != 0 {
            // STKALIGN: the frame is 8-byte aligned and xPSR bit 9 remembers the padding.
            frame_sp = frame_sp.wrapping_sub(4);
            stacked_xpsr |= 1 << 9;
        } else {
            stacked_xpsr &= !(1 << 9);
        }
        regs[7] = stacked_xpsr;
        let mut words: Vec<u32> = regs.to_vec();
        if fp_active {
            for i in 0..16 {
                words.push(self.uc.reg_read(RegisterARM::S0 as i32 + i).map_err(emu)? as u32);
            }
            words.push(self.reg(RegisterARM::FPSCR)?);
            words.push(0);
        }
        Ok((frame_sp, words.iter().flat_map(|w| w.to_le_bytes()).collect()))
    }

    /// A frame that did not fit in RAM: STKERR, and the exception whose handler runs instead
    /// (HardFault, unless HardFault or NMI itself is being entered; see
    /// [`Machine::enter_exception`]).
    fn stacking_fault(&mut self, exc: usize, frame_sp: u32, return_pc: u32, now: Time) -> usize {
        let st = self.uc.get_data_mut();
        let cause = format!(
            "BusFault on stacking (STKERR) entering exception {exc}: its frame at {frame_sp:#010x} is outside RAM (stack overflow)"
        );
        st.hard_faults.push(HardFaultEvent { at: now, pc: return_pc, cause });
        if exc == scs::HARD_FAULT || exc == NMI {
            st.scs.cfsr |= CFSR_STKERR;
            exc
        } else {
            st.scs.record_forced_fault(CFSR_STKERR);
            scs::HARD_FAULT
        }
    }

    /// LR to EXC_RETURN, CONTROL.FPCA cleared, IPSR to `exc`, and the PC to its vector.
    fn branch_to_handler(&mut self, exc: usize, xpsr: u32, control: u32) -> Result<(), Fault> {
        let in_handler = xpsr & 0x1FF != 0;
        let mut exc_return: u32 = if in_handler { 0xFFFF_FFF1 } else { 0xFFFF_FFF9 };
        if control & 4 != 0 {
            exc_return &= !0x10;
        }
        self.set_reg(RegisterARM::LR, exc_return)?;
        self.set_reg(RegisterARM::CONTROL, control & !4)?;
        // IPSR = exception, EPSR: T set, IT cleared; flags kept.
        self.set_reg(RegisterARM::XPSR_NZCVQG, (xpsr & 0xF80F_0000) | (1 << 24) | exc as u32)?;
        self.rebuild_flags()?;
        let vtor = self.uc.get_data().scs.vtor;
        let v = self.read_memory(vtor + 4 * exc as u32, 4)?;
        let vector = u32::from_le_bytes([v[0], v[1], v[2], v[3]]);
        self.set_reg(RegisterARM::PC, vector | 1)
    }

    /// The entry's cycles: the rest of a tail-chain where the profile prices one as a whole,
    /// else a full entry.
    fn charge_entry(&mut self) {
        let tail_chain = std::mem::take(&mut self.uc.get_data_mut().tail_chaining);
        let entry = match self.uc.get_data().timing.tail_chain_cycles() {
            Some(cycles) if tail_chain => cycles,
            _ => ENTRY_CYCLES + self.uc.get_data().timing.entry_cycles(),
        };
        self.add_cycles(entry);
    }

    /// Exception return (ARMv7-M B1.5.8).
    fn return_from_exception(&mut self) -> Result<(), Fault> {
        let now = self.now();
        let pc = self.reg(RegisterARM::PC)?;
        let exc_return = pc | 1;
        let bad = |m: &Self| Fault::BadReturn { exc_return, pc: m.uc.get_data().block_pc, at: now };
        if !matches!(exc_return, 0xFFFF_FFF1 | 0xFFFF_FFF9 | 0xFFFF_FFE1 | 0xFFFF_FFE9) {
            if exc_return & 4 != 0 {
                return Err(Fault::Unmodelled {
                    error: Unmodelled::new("EXC_RETURN", "return to the process stack (PSP) is not modelled"),
                    pc,
                    at: now,
                });
            }
            return Err(bad(self));
        }
        let xpsr = self.reg(RegisterARM::XPSR)?;
        let exc = (xpsr & 0x1FF) as usize;
        if !self.uc.get_data_mut().record_return(exc, now) {
            return Err(bad(self));
        }
        let fp_frame = exc_return & 0x10 == 0;
        let (ret_pc, stacked_xpsr) = self.pop_frame(fp_frame, pc, now)?;
        let to_thread = exc_return & 8 != 0;
        let stacked_exc = stacked_xpsr & 0x1FF;
        if to_thread != (stacked_exc == 0) {
            return Err(bad(self));
        }
        let control = self.reg(RegisterARM::CONTROL)?;
        self.set_reg(RegisterARM::CONTROL, if fp_frame { control | 4 } else { control & !4 })?;
        self.set_reg(RegisterARM::XPSR_NZCVQG, stacked_xpsr & !(1 << 9))?;
        self.rebuild_flags()?;
        let thumb = if stacked_xpsr & (1 << 24) != 0 { 1 } else { 0 };
        self.set_reg(RegisterARM::PC, (ret_pc & !1) | thumb)?;
        self.charge_return()?;
        self.uc.get_data_mut().timing.exception_boundary();
        let st = self.uc.get_data_mut();
        if to_thread && st.scs.sleep_on_exit() {
            st.sleeping = true;
        }
        Ok(())
    }

    /// Unstacks the frame at SP (extended with `fp_frame`) into the registers and moves SP
    /// past it and its padding: the return address and the stacked xPSR.
    fn pop_frame(&mut self, fp_frame: bool, pc: u32, now: Time) -> Result<(u32, u32), Fault> {
        let sp = self.reg(RegisterARM::SP)?;
        let frame_bytes: u32 = if fp_frame { 0x68 } else { 0x20 };
        if sp < SRAM_BASE || sp.wrapping_add(frame_bytes) > SRAM_BASE + SRAM_SIZE {
            return Err(Fault::Stacking { address: sp, pc, at: now });
        }
        let raw = self.read_memory(sp, frame_bytes as usize)?;
        let word = |i: usize| u32::from_le_bytes([raw[4 * i], raw[4 * i + 1], raw[4 * i + 2], raw[4 * i + 3]]);
        for (i, r) in
            [RegisterARM::R0, RegisterARM::R1, RegisterARM::R2, RegisterARM::R3, RegisterARM::R12, RegisterARM::LR].into_iter().enumerate()
        {
            self.set_reg(r, word(i))?;
        }
        let stacked_xpsr = word(7);
        if fp_frame {
            for i in 0..16 {
                self.uc.reg_write(RegisterARM::S0 as i32 + i, u64::from(word(8 + i as usize))).map_err(emu)?;
            }
            self.set_reg(RegisterARM::FPSCR, word(24))?;
        }
        let mut new_sp = sp + frame_bytes;
        if stacked_xpsr & (1 << 9) != 0 {
            new_sp += 4;
        }
        self.set_reg(RegisterARM::SP, new_sp)?;
        Ok((word(6), stacked_xpsr))
    }

    /// The return's cycles, unless an exception that can preempt as it starts is tail-chained
    /// onto it and the profile prices that as a whole (the entry then charges it).
    fn charge_return(&mut self) -> Result<(), Fault> {
        let saved = self.uc.get_data_mut().fp_frames_owed.pop().is_some_and(|f| f.saved);
        let extra = self.uc.get_data().timing.return_cycles(saved);
        let basepri = self.reg(RegisterARM::BASEPRI)?;
        let primask = self.reg(RegisterARM::PRIMASK)? & 1 != 0;
        let st = self.uc.get_data_mut();
        st.tail_chaining = st.timing.tail_chain_cycles().is_some() && st.scs.takeable(basepri, primask).is_some();
        if !st.tail_chaining {
            self.add_cycles(RETURN_CYCLES + extra);
        }
        Ok(())
    }

    /// A synchronous fault in the guest (undefined instruction, bad state, a bus error):
    /// escalated to HardFault, since the configurable faults are not enabled by the firmware.
    /// A fault while the HardFault (or NMI) handler runs cannot be escalated any further: the
    /// core locks up (ARMv7-M B1.5.15).
    fn raise_hard_fault(&mut self, pc: u32, cause: String, cfsr_bits: u32) -> Result<(), Fault> {
        let now = self.now();
        let st = self.uc.get_data_mut();
        if st.scs.is_active(scs::HARD_FAULT) || st.scs.is_active(2) {
            return self.lock_up(pc, cause);
        }
        st.scs.record_forced_fault(cfsr_bits);
        st.hard_faults.push(HardFaultEvent { at: now, pc, cause });
        st.scs.set_pending(scs::HARD_FAULT);
        self.enter_exception(scs::HARD_FAULT, pc)?;
        Ok(())
    }

    /// Lockup (ARMv7-M B1.5.15): the core stops executing, with the PC at 0xFFFF_FFFE and
    /// the exception state as it was; interrupts stay pending, the peripherals and the
    /// watchdog run on. A reset ends it.
    fn lock_up(&mut self, pc: u32, cause: String) -> Result<(), Fault> {
        let now = self.now();
        let st = self.uc.get_data_mut();
        st.lockups.push(LockupEvent { at: now, pc, cause });
        st.locked_up = true;
        st.sleeping = false;
        if let Some(m) = st.masking.as_mut() {
            m.close(now);
        }
        self.set_reg(RegisterARM::PC, 0xFFFF_FFFE)
    }

    /// Whether the core is locked up (see [`LockupEvent`]).
    pub fn locked_up(&self) -> bool {
        self.uc.get_data().locked_up
    }

    /// Sets the stack pointer (the main stack): the way to exhaust the stack on the image,
    /// so that the next exception's frame does not fit.
    pub fn set_stack_pointer(&mut self, sp: u32) -> Result<(), Fault> {
        self.set_reg(RegisterARM::SP, sp)
    }

    /// Measures, from now on, the intervals during which PRIMASK, or BASEPRI at or above the
    /// priority of exception `exc`, kept `exc` from being taken ([`State::masking`]), and
    /// every interrupt's longest wait from its line rising to its entry
    /// ([`ExceptionStats::longest_pending`]). Off by default: it reads two registers at every
    /// translation block.
    pub fn measure_masking_against(&mut self, exc: usize) {
        let st = self.uc.get_data_mut();
        st.masking = Some(MaskingStats { watched: exc, ..MaskingStats::default() });
        st.pending_since.iter_mut().for_each(|p| *p = None);
        for stats in st.exception_stats.values_mut() {
            stats.longest_pending = None;
        }
    }

    /// From now on, adds up the time spent in blocks that start within `ranges` (code
    /// addresses, start inclusive, end exclusive): the CPU time of a part of the firmware
    /// ([`State::region`]). Skipped idle laps are never in it.
    pub fn measure_time_in(&mut self, mut ranges: Vec<(u32, u32)>) {
        ranges.sort_unstable();
        self.uc.get_data_mut().region = Some((ranges, 0));
    }

    /// Injects an imprecise BusFault (as a failed buffered write would give), escalated to
    /// HardFault: the way to exercise the firmware's fault path on the real image.
    pub fn inject_bus_fault(&mut self) -> Result<(), Fault> {
        let pc = self.pc();
        // CFSR.IMPRECISERR (bit 10).
        self.raise_hard_fault(pc, "injected imprecise BusFault".into(), 1 << 10)
    }

    /// Makes the running code call `function` (a symbol of the image) as if the code at the
    /// current PC had called it: the way to run the firmware's panic handler on the image.
    pub fn inject_call(&mut self, function: u32, arg0: u32) -> Result<(), Fault> {
        let pc = self.pc();
        self.set_reg(RegisterARM::LR, pc | 1)?;
        self.set_reg(RegisterARM::R0, arg0)?;
        self.set_reg(RegisterARM::PC, function | 1)
    }

    /// Brings the peripherals and SysTick up to now, samples the interrupt lines, and handles
    /// a watchdog or software reset.
    fn service(&mut self) -> Result<(), Fault> {
        let now = self.now();
        let pc = self.uc.get_data().block_pc;
        let st = self.uc.get_data_mut();
        st.scs.advance(now);
        let mut lines = Vec::new();
        let watchdog =
            st.board.advance(now, &mut |irq, level| lines.push((irq, level))).map_err(|error| Fault::Unmodelled { error, pc, at: now })?;
        st.sample_lines(now, &lines);
        if st.board.nmi_line() && !st.scs.is_active(NMI) {
            st.scs.set_pending(NMI);
        }
        store_memory_writes(&mut self.uc).map_err(|error| Fault::Unmodelled { error, pc, at: now })?;
        let st = self.uc.get_data_mut();
        match st.board.units_per_cycle() {
            Ok(u) if u != st.units_per_cycle => {
                st.units_per_cycle = u;
                st.scs.set_units_per_cycle(now, u);
            }
            Ok(_) => {}
            Err(error) => return Err(Fault::Unmodelled { error, pc, at: now }),
        }
        let software = std::mem::take(&mut st.scs.reset_requested);
        let power = st.board.take_power_cut();
        if power {
            st.resets.push((now, "power cut"));
            st.board.power_on_reset();
            let u = st.board.units_per_cycle().unwrap_or(21);
            st.units_per_cycle = u;
            self.power_on_ram()?;
            self.reset_core()?;
        } else if watchdog || software {
            st.resets.push((now, if watchdog { "watchdog" } else { "software (SYSRESETREQ)" }));
            st.board.system_reset(watchdog);
            let u = st.board.units_per_cycle().unwrap_or(21);
            st.units_per_cycle = u;
            self.reset_core()?;
        }
        Ok(())
    }

    /// Runs the board until `target` (or a fault).
    pub fn run_until(&mut self, target: Time) -> Result<(), Fault> {
        loop {
            self.service()?;
            let now = self.now();
            if now >= target {
                return Ok(());
            }
            let st = self.uc.get_data_mut();
            if st.locked_up || st.board.core_clock_stopped() {
                // Nothing runs and nothing wakes the core: on to the next event (the watchdog's
                // expiry resets the board in `service`).
                let next = [st.board.next_event(), st.scs.next_event(now)].into_iter().flatten().filter(|&t| t > now).min();
                let deadline = next.map_or(target, |t| t.min(target));
                let upc = st.units_per_cycle;
                st.deadline = deadline;
                st.now += (deadline - now).div_ceil(upc) * upc;
                continue;
            }
            let basepri = self.reg(RegisterARM::BASEPRI)?;
            let primask = self.reg(RegisterARM::PRIMASK)? & 1 != 0;
            let st = self.uc.get_data_mut();
            if st.sleeping && st.scs.would_wake(basepri) {
                st.sleeping = false;
            }
            if let Some(exc) = st.scs.takeable(basepri, primask) {
                let pc = self.pc();
                self.enter_exception(exc, pc)?;
                continue;
            }
            let st = self.uc.get_data_mut();
            let next = [st.board.next_event(), st.scs.next_event(now)].into_iter().flatten().filter(|&t| t > now).min();
            let deadline = next.map_or(target, |t| t.min(target));
            if st.sleeping {
                // WFI: nothing to do until the next event.
                let upc = st.units_per_cycle;
                let skip = (deadline - now).div_ceil(upc) * upc;
                st.deadline = deadline;
                st.now += skip;
                st.idle_time += skip;
                continue;
            }
            st.deadline = deadline;
            st.stop = None;
            let pc = self.pc();
            let result = self.uc.emu_start(u64::from(pc | 1), NEVER, 0, 0);
            let now = self.now();
            let stop = self.uc.get_data_mut().stop.take();
            let block_pc = self.uc.get_data().block_pc;
            match (result, stop) {
                (_, Some(Stop::Unmodelled(error))) => return Err(Fault::Unmodelled { error, pc: block_pc, at: now }),
                (_, Some(Stop::Memory { kind, address, bus_fault: Some(bits) })) => {
                    let pc = self.pc();
                    self.raise_hard_fault(pc, format!("precise BusFault: {kind} at {address:#010x}"), bits)?;
                }
                (_, Some(Stop::Memory { kind, address, bus_fault: None })) => {
                    return Err(Fault::Memory { kind, address, pc: self.pc(), at: now })
                }
                (_, Some(Stop::ExceptionReturn)) => self.return_from_exception()?,
                (_, Some(Stop::SyncFault(fault))) => {
                    let pc = self.pc();
                    self.raise_hard_fault(pc, fault.to_string(), fault.cfsr_bits())?;
                }
                (Ok(()), Some(Stop::Deadline | Stop::Interrupt)) => {}
                (Ok(()), None) => {
                    // Unicorn returns on its own only for WFI (the CPU halted).
                    let pc = self.pc();
                    if self.uc.get_data().code.is_wfi_before(pc) {
                        self.uc.get_data_mut().sleeping = true;
                    } else {
                        return Err(Fault::Emulator(format!("emulation stopped without a reason at PC {pc:#010x}")));
                    }
                }
                (Err(e), _) => return Err(Fault::Emulator(format!("{e:?} at PC {:#010x} (block {block_pc:#010x})", self.pc()))),
            }
        }
    }

    /// Lowest stack address written since power-on (the paint is gone), if any.
    pub fn stack_high_water(&self) -> Option<u32> {
        let len = self.stack_top.saturating_sub(self.stack_bottom) as usize;
        let ram = self.read_memory(self.stack_bottom, len).ok()?;
        ram.iter().position(|&b| b != STACK_PAINT).map(|i| self.stack_bottom + i as u32)
    }
}

/// Called as each translated block starts. A stop requested here stops the emulation before
/// the block runs, so the block is charged only once it is going to run: a deadline or an
/// interrupt that came due during the previous block stops here uncharged, and the block
/// runs whole (and pays) when the emulation resumes. Charging before stopping would bill a
/// block twice whenever an event fell inside it, and never let a block run that is longer than
/// the spacing of the events.
fn block_hook<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, address: u64, size: u32) {
    if uc.get_data().flash_watch && stalled_by_flash(uc, address as u32) {
        return;
    }
    if stop_before_block(uc) {
        return;
    }
    uc.get_data_mut().tail_chaining = false;
    if uc.get_data().masking.is_some() {
        track_masking(uc);
    }
    let addr = address as u32;
    let (kind, n, body) = charge_block(uc.get_data_mut(), addr, size);
    match kind {
        BlockKind::Plain => {}
        BlockKind::IdleSpin => {
            skip_idle_spin(uc.get_data_mut(), addr, size, (n, body));
            let _ = uc.emu_stop();
        }
        BlockKind::CycleCountWait { addr: reg_addr, start, limit } => {
            let reg = |uc: &Unicorn<'_, State<P>>, r: u8| uc.reg_read(RegisterARM::R0 as i32 + i32::from(r)).unwrap_or(0) as u32;
            let (a, s0, l) = (reg(uc, reg_addr), reg(uc, start), reg(uc, limit));
            if a == scs::DWT_BASE + scs::reg::DWT_CYCCNT {
                skip_cycle_count_wait(uc.get_data_mut(), addr, size, (n, body), (s0, l));
            }
        }
        BlockKind::Countdown(reg) => {
            // `subs rN, #1; bne`: rN laps of two instructions. Run all but the last at once
            // (no further than the deadline), exactly as executing them would: the register
            // ends one above zero and the block's own execution finishes the countdown.
            let r = RegisterARM::R0 as i32 + i32::from(reg);
            let laps_left = uc.reg_read(r).unwrap_or(0);
            let skip = skip_countdown(uc.get_data_mut(), addr, size, (n, body), laps_left);
            if skip > 0 {
                let _ = uc.reg_write(r, laps_left - skip);
            }
        }
    }
    let st = uc.get_data_mut();
    st.block_started_at = st.now - body * st.units_per_cycle;
}

/// While a flash operation may run: the flash copy brought up to date, and whether the block
/// at `addr` stalls on it (the emulation then stops before it). Stops watching once the
/// flash is idle.
fn stalled_by_flash<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, addr: u32) -> bool {
    if uc.get_data().flash_dirty {
        if let Err(e) = sync_flash(uc) {
            fail(uc, e);
            return true;
        }
    }
    if stall_on_flash(uc, addr) {
        return true;
    }
    let st = uc.get_data_mut();
    st.flash_watch = st.board.flash_busy_until().is_some();
    false
}

/// Charges the block at `addr` (its start's refill and literal loads, a lazy FP save it
/// triggers, its instructions) to the clock and to the measured region: its kind and its
/// instructions and its body's cycles.
fn charge_block<P: Peripherals>(st: &mut State<P>, addr: u32, size: u32) -> (BlockKind, u64, u64) {
    let info = st.code.block(addr, size);
    let (n, kind) = (info.instructions, info.kind);
    let body = st.timing.body_cycles(n, info.cycles);
    let mut entry = st.timing.block_entry_cycles(addr, size) + st.timing.literal_load_cycles(info.literal_loads);
    if info.has_fp && st.fp_frames_owed.iter().any(|f| f.owed) {
        // The first FP instruction since an extended frame was stacked saves its FP state.
        entry += st.timing.lazy_fp_save_cycles();
        for f in st.fp_frames_owed.iter_mut().filter(|f| f.owed) {
            *f = LazyFp { owed: false, saved: true };
        }
    }
    let upc = st.units_per_cycle;
    st.block_pc = addr;
    st.block_size = size;
    st.instructions += n;
    st.now += (entry + body) * upc;
    st.attribute(n);
    if let Some((ranges, time)) = st.region.as_mut() {
        let i = ranges.partition_point(|&(start, _)| start <= addr);
        if i > 0 && addr < ranges[i - 1].1 {
            *time += (entry + body) * upc;
        }
    }
    (kind, n, body)
}

/// `b .`: spins until the deadline without translating every lap; the emulation stops there.
fn skip_idle_spin<P: Peripherals>(st: &mut State<P>, addr: u32, size: u32, (n, body): (u64, u64)) {
    let upc = st.units_per_cycle;
    if st.deadline > st.now {
        let lap = st.timing.steady_lap_cycles(addr, size, body) * upc;
        let laps = (st.deadline - st.now).div_ceil(lap);
        st.now += laps * lap;
        st.idle_time += laps * lap;
        st.instructions += laps * n;
    }
    st.stop = Some(Stop::Deadline);
}

/// A wait on the cycle counter (`(start, limit)` in its registers): the lap that exits is the
/// first whose CYCCNT read satisfies the test, and every lap before it only re-reads the
/// counter. Skips to that lap (no further than the deadline); the block then runs it.
fn skip_cycle_count_wait<P: Peripherals>(st: &mut State<P>, addr: u32, size: u32, (n, body): (u64, u64), (start, limit): (u32, u32)) {
    if !st.scs.cyccnt_running() {
        return;
    }
    let upc = st.units_per_cycle;
    // The read is the block's first instruction: at its start under the optimistic profile,
    // at its end under the pessimistic (as `access_time` stamps it).
    let read_at = match st.timing.profile {
        TimingProfile::Optimistic => st.now - body * upc,
        TimingProfile::Pessimistic => st.now,
    };
    let elapsed = st.scs.cyccnt(read_at).wrapping_sub(start);
    if elapsed < limit {
        let lap = st.timing.steady_lap_cycles(addr, size, body);
        let laps = u64::from(limit - elapsed).div_ceil(lap);
        let affordable = st.deadline.saturating_sub(st.now) / (lap * upc);
        let skip = laps.min(affordable);
        st.now += skip * lap * upc;
        st.instructions += skip * n;
        st.attribute(skip * n);
    }
}

/// A countdown loop with `laps_left` laps: all but the last charged at once (no further than
/// the deadline). Returns how many laps were skipped.
fn skip_countdown<P: Peripherals>(st: &mut State<P>, addr: u32, size: u32, (n, body): (u64, u64), laps_left: u64) -> u64 {
    let upc = st.units_per_cycle;
    let lap = st.timing.steady_lap_cycles(addr, size, body);
    let affordable = st.deadline.saturating_sub(st.now) / (lap * upc);
    let skip = laps_left.saturating_sub(1).min(affordable);
    if skip > 0 {
        st.now += skip * lap * upc;
        st.instructions += skip * n;
        st.attribute(skip * n);
    }
    skip
}

/// At the start of a block, before it is charged, and at exception entry: whether PRIMASK or
/// BASEPRI keep the watched exception out (ARMv7-M B1.5.4: BASEPRI, group-masked, boosts the
/// execution priority when non-zero; the exception is taken only if its group priority is
/// lower). The masks change only by the instructions of the previous block (MSR and CPS end
/// their block; exception entry and return leave the masks alone), so an interval starts and
/// ends where a block does, or where an interrupt is taken between two blocks.
fn track_masking<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>) {
    let primask = uc.reg_read(RegisterARM::PRIMASK).unwrap_or(0) & 1 != 0;
    let basepri = uc.reg_read(RegisterARM::BASEPRI).unwrap_or(0) as u32;
    uc.get_data_mut().observe_masks(primask, basepri);
}

impl<P: Peripherals> State<P> {
    /// An entry into `exc` at `now` (its handler about to run): the active and current
    /// exception, the statistics, and how long it waited when masking is measured.
    fn record_entry(&mut self, exc: usize, now: Time, fp_frame: bool) {
        let st = self;
        st.scs.activate(exc);
        st.exc_stack.push(exc);
        st.current_exception = exc;
        if let Some(c) = st.exc_instructions.get_mut(exc) {
            *c = 0;
        }
        if let Some(t) = st.exc_entered_at.get_mut(exc) {
            *t = now;
        }
        st.exception_stats.entry(exc).or_default().entries += 1;
        st.fp_frames += u64::from(fp_frame);
        st.sleeping = false;
        if st.masking.is_some() {
            if let (Some(since), Some(stats)) = (st.pending_since.get_mut(exc).and_then(Option::take), st.exception_stats.get_mut(&exc)) {
                let wait = now - since;
                if stats.longest_pending.is_none_or(|(w, _)| w < wait) {
                    stats.longest_pending = Some((wait, now));
                }
            }
        }
    }

    /// The return from `exc` at `now`: no longer active (false if it was not: a bad return),
    /// its activation in the statistics, the current exception the one it preempted.
    fn record_return(&mut self, exc: usize, now: Time) -> bool {
        let st = self;
        if !st.scs.deactivate(exc) {
            return false;
        }
        let instructions = st.exc_instructions.get(exc).copied().unwrap_or(0);
        let entered = st.exc_entered_at.get(exc).copied().unwrap_or(0);
        let stats = st.exception_stats.entry(exc).or_default();
        // Keep the last 100 000 activations: enough for every statistic over a flight.
        if stats.instructions.len() < 100_000 {
            stats.instructions.push(instructions);
            stats.spans.push((entered, now));
        }
        st.exc_stack.pop();
        st.current_exception = st.exc_stack.last().copied().unwrap_or(0);
        true
    }

    /// Opens or closes the masked interval with the masks as they are now (see
    /// [`track_masking`]).
    fn observe_masks(&mut self, primask: bool, basepri: u32) {
        // The STM32F401 implements priority bits 7:4 only.
        let basepri = basepri & 0xF0;
        let st = self;
        let (now, pc, current) = (st.now, st.block_pc, st.current_exception);
        let Some(watched) = st.masking.as_ref().map(|m| m.watched) else { return };
        let masked = primask
            || (basepri != 0 && {
                let prigroup = st.scs.read(scs::reg::AIRCR, now, current).map_or(0, |aircr| (aircr >> 8) & 7);
                let group_mask = (0xFFu32 << (prigroup + 1)) & 0xFF;
                (basepri & group_mask) as i32 <= st.scs.group_priority(watched)
            });
        if let Some(m) = st.masking.as_mut() {
            match (masked, m.open) {
                (true, None) => m.open = Some((now, pc)),
                (false, Some(_)) => m.close(now),
                _ => {}
            }
        }
    }
}

/// Stops the emulation (before the block about to start) if the deadline has passed or an
/// interrupt can be taken. `run_until` starts the emulation only when neither holds, so the
/// first block of every start runs.
fn stop_before_block<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>) -> bool {
    let st = uc.get_data_mut();
    let stop = if st.now >= st.deadline {
        Some(Stop::Deadline)
    } else if st.scs.any_pending() {
        let basepri = uc.reg_read(RegisterARM::BASEPRI).unwrap_or(0) as u32;
        let primask = uc.reg_read(RegisterARM::PRIMASK).unwrap_or(0) & 1 != 0;
        uc.get_data().scs.takeable(basepri, primask).map(|_| Stop::Interrupt)
    } else {
        None
    };
    match stop {
        Some(stop) => {
            uc.get_data_mut().stop = Some(stop);
            let _ = uc.emu_stop();
            true
        }
        None => false,
    }
}

fn fail<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, e: Unmodelled) {
    let st = uc.get_data_mut();
    if st.stop.is_none() || matches!(st.stop, Some(Stop::Deadline | Stop::Interrupt)) {
        st.stop = Some(Stop::Unmodelled(e));
    }
    let _ = uc.emu_stop();
}

/// Address ranges where the STM32F401 answers (RM0368 §2.3, memory map and register
/// boundary addresses) but the model maps nothing: the rest of system memory and the option
/// bytes, the SRAM bit-band alias, and the peripheral space outside the modelled buses.
fn implemented_but_unmodelled(addr: u32) -> bool {
    (0x1FFF_0000..0x1FFF_C010).contains(&addr) || (0x2200_0000..0x2400_0000).contains(&addr) || (0x4000_0000..0x6000_0000).contains(&addr)
}

/// Peripheral bit-band alias (0x4200_0000 + 32·offset + 4·bit ↔ bit of 0x4000_0000 + offset).
fn bit_band(addr: u32) -> Option<(u32, u32)> {
    (0x4200_0000..0x4400_0000).contains(&addr).then(|| {
        let off = addr - 0x4200_0000;
        ((0x4000_0000 + off / 32) & !3, ((off / 32) & 3) * 8 + (off % 32) / 4)
    })
}

/// The instant a register access at `addr` (the peripheral's own address for a bit-band alias)
/// reaches its model, in `transfers` bus transfers. Optimistic: the start of its block, the
/// earliest instant the block allows (its instruction is not known). Pessimistic: the clock, which has charged
/// the whole block, plus the access's stall.
fn access_time<P: Peripherals>(st: &mut State<P>, addr: u32, transfers: u64) -> Time {
    match st.timing.profile {
        TimingProfile::Optimistic => st.block_started_at,
        TimingProfile::Pessimistic => {
            st.now += st.timing.register_access_cycles(addr, transfers) * st.units_per_cycle;
            st.now
        }
    }
}

/// RCC_CFGR (RM0368 §6.3.3), whose APB prescalers set the pessimistic profile's bus stalls.
const RCC_CFGR: u32 = 0x4002_3808;

/// After a write that may have changed FLASH_ACR or RCC_CFGR (`word`, with `written` the bits
/// the write carried in their register positions): the pessimistic profile reads the register
/// back through the bus, as the firmware would, to follow its wait states, caches and APB
/// prescalers.
fn follow_timing_registers<P: Peripherals>(st: &mut State<P>, word: u32, written: u32, now: Time) {
    if !st.timing.pessimistic() {
        return;
    }
    if word == flash::BASE {
        if let Ok(acr) = st.board.read(flash::BASE, 4, now) {
            let resets = AcrTiming::decode(written);
            st.timing.set_acr(AcrTiming { icache_reset: resets.icache_reset, dcache_reset: resets.dcache_reset, ..AcrTiming::decode(acr) });
        }
    } else if word == RCC_CFGR {
        if let Ok(cfgr) = st.board.read(RCC_CFGR, 4, now) {
            st.timing.set_rcc_cfgr(cfgr);
        }
    }
}

fn mmio_read<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, addr: u32, size: u32) -> u64 {
    let st = uc.get_data_mut();
    let target = bit_band(addr).map_or(addr, |(word, _)| word);
    let now = access_time(st, target, 1);
    let lane = 8 * (addr & 3);
    let mask = if size >= 4 { u32::MAX } else { (1u32 << (8 * size)) - 1 };
    let result = if (scs::SCS_BASE..scs::SCS_BASE + 0x1000).contains(&addr) {
        let ce = st.current_exception;
        st.scs.read(addr & !3 & 0xFFF, now, ce).map(|w| (w >> lane) & mask)
    } else if (scs::DWT_BASE..scs::DWT_BASE + 0x1000).contains(&addr) {
        st.scs.dwt_read(addr & !3 & 0xFFF, now).map(|w| (w >> lane) & mask)
    } else if let Some((word, bit)) = bit_band(addr) {
        st.board.read(word, 4, now).map(|w| (w >> bit) & 1)
    } else {
        st.board.read(addr, size, now)
    };
    match result {
        Ok(v) => {
            if let Err(e) = store_memory_writes(uc) {
                fail(uc, e);
            }
            u64::from(v)
        }
        Err(e) => {
            fail(uc, e);
            0
        }
    }
}

/// Brings the emulation's deadline forward to the models' next event, if an access made it
/// sooner.
fn pull_deadline<P: Peripherals>(st: &mut State<P>) {
    let now = st.now;
    if let Some(t) = [st.board.next_event(), st.scs.next_event(now)].into_iter().flatten().filter(|&t| t > now).min() {
        st.deadline = st.deadline.min(t);
    }
}

/// The flash memory: an offset from [`FLASH_BASE`] for an address in flash or its boot alias.
fn flash_offset(addr: u32) -> Option<u32> {
    [FLASH_BASE, 0].into_iter().find_map(|base| addr.checked_sub(base).filter(|&o| o < FLASH_SIZE))
}

/// A CPU store into flash (mapped read-only, so Unicorn calls the protection hook; no memory
/// hook covers flash: one there corrupted registers in Unicorn 2.1.5). The flash model decides
/// what the write does; returning true lets Unicorn complete the store into its own copy, which
/// [`sync_flash`] then overwrites with the model's contents before anything else runs (a load
/// of the same address later in the same translation block would see the raw store: code that
/// programs flash polls FLASH_SR between, which syncs). A store while BSY waits for the
/// operation in progress to end.
fn flash_write<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, offset: u32, size: u32, value: u32) -> bool {
    let st = uc.get_data_mut();
    // A store while an operation runs waits on the bus for it to end (RM0368 §3.5).
    let now = stall_while_flash_busy(st, st.now);
    match st.board.flash_memory_write(offset, size, value, now) {
        Ok(()) => {
            st.flash_dirty = true;
            st.flash_watch = true;
            pull_deadline(st);
            // A data read from flash later in the same block (a literal load) waits for the
            // operation the store started, as the fetch of the next block will (RM0368 §3.5).
            if literal_load_after_store(uc) {
                let st = uc.get_data_mut();
                let at = st.now;
                stall_while_flash_busy(st, at);
            }
            true
        }
        Err(e) => {
            fail(uc, e);
            false
        }
    }
}

/// Whether the block running holds a PC-relative (literal) load after the store at the PC:
/// a data read from flash that comes after the store within the block.
fn literal_load_after_store<P: Peripherals>(uc: &Unicorn<'_, State<P>>) -> bool {
    let Ok(pc) = uc.reg_read(RegisterARM::PC) else { return false };
    let st = uc.get_data();
    let (start, end) = (u64::from(st.block_pc), u64::from(st.block_pc) + u64::from(st.block_size));
    if pc < start || pc >= end {
        return false;
    }
    let Ok(code) = uc.mem_read_as_vec(pc, (end - pc) as usize) else { return false };
    let halfword = |i: usize| code.get(2 * i..2 * i + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let is_32_bit = |hw: u16| hw >> 11 >= 0b11101;
    // Past the store itself, instruction by instruction.
    let mut i = match halfword(0) {
        Some(hw) if is_32_bit(hw) => 2,
        Some(_) => 1,
        None => return false,
    };
    while let Some(hw) = halfword(i) {
        if timing::is_literal_load(hw) {
            return true;
        }
        i += if is_32_bit(hw) { 2 } else { 1 };
    }
    false
}

/// FLASH_CR (RM0368 §3.8.5): "not accessible in write mode when the BSY bit is set": a write
/// stalls the AHB until BSY clears.
const FLASH_CR: u32 = flash::BASE + 0x10;

/// An access that waits on the bus for a flash operation to end: the clock moves on to BSY's
/// end (the write then lands there). Returns the instant the access completes.
fn stall_while_flash_busy<P: Peripherals>(st: &mut State<P>, at: Time) -> Time {
    if let Some(until) = st.board.flash_busy_until().filter(|&t| t > at) {
        let upc = st.units_per_cycle;
        let stall = (until - at).div_ceil(upc) * upc;
        st.now = st.now.max(at + stall);
        st.flash_stall_time += stall;
        return at + stall;
    }
    at
}

/// Copies the flash model's changes into the guest's flash and its boot alias.
fn sync_flash<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>) -> Result<(), Unmodelled> {
    let st = uc.get_data_mut();
    st.flash_dirty = false;
    let changes = st.board.take_flash_changes();
    for (offset, bytes) in changes {
        for base in [FLASH_BASE, 0] {
            uc.mem_write(u64::from(base + offset), &bytes)
                .map_err(|e| Unmodelled::new("FLASH", format!("copying flash +{offset:#07x} failed in the emulator: {e:?}")))?;
        }
    }
    Ok(())
}

/// An instruction fetch from flash while a program or erase runs waits for it to end
/// (RM0368 §3.5): the clock moves on to the end of BSY, or to the emulation's deadline if that
/// comes first (an event, the end of the run: a power cut or the watchdog can land mid-erase),
/// and the emulation stops before the block, so the run loop brings the models (DMA, the UART,
/// the watchdog) up to that instant; the block's next start stalls again while BSY lasts.
fn stall_on_flash<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, pc: u32) -> bool {
    let st = uc.get_data_mut();
    let Some(until) = st.board.flash_busy_until() else { return false };
    if flash_offset(pc).is_none() || until <= st.now {
        return false;
    }
    let upc = st.units_per_cycle;
    let limit = until.min(st.deadline);
    if limit > st.now {
        let stall = (limit - st.now).div_ceil(upc) * upc;
        st.now += stall;
        st.flash_stall_time += stall;
    }
    st.stop = Some(Stop::Deadline);
    let _ = uc.emu_stop();
    true
}

/// Stores in the guest's RAM what another bus master (DMA) wrote since the last call, and in
/// its flash what the flash model changed.
fn store_memory_writes<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>) -> Result<(), Unmodelled> {
    // An operation the access completed (a FLASH_SR poll at BSY's end), or a store let through.
    sync_flash(uc)?;
    let writes = uc.get_data_mut().board.take_memory_writes();
    for (addr, byte) in writes {
        uc.mem_write(u64::from(addr), &[byte])
            .map_err(|e| Unmodelled::new("DMA", format!("a write to {addr:#010x} failed in the emulator: {e:?}")))?;
    }
    Ok(())
}

fn mmio_write<P: Peripherals>(uc: &mut Unicorn<'_, State<P>>, addr: u32, size: u32, value: u32) {
    let st = uc.get_data_mut();
    let band = bit_band(addr);
    let (target, transfers) = band.map_or((addr, 1), |(word, _)| (word, 2));
    let mut now = access_time(st, target, transfers);
    if target & !0x3FF == flash::BASE {
        st.flash_watch = true;
        // An ACR write that empties the data cache makes stale words readable again.
        st.flash_dirty = true;
        if target & !3 == FLASH_CR {
            now = stall_while_flash_busy(st, now);
        }
    }
    let result = if (scs::SCS_BASE..scs::SCS_BASE + 0x1000).contains(&addr) {
        match size {
            4 => st.scs.write(addr & 0xFFF, value, now),
            1 => st.scs.write_byte(addr & 0xFFF, value as u8, now),
            _ => Err(Unmodelled::new(format!("SCS+{:#05x}", addr & 0xFFF), format!("{size}-byte write"))),
        }
    } else if (scs::DWT_BASE..scs::DWT_BASE + 0x1000).contains(&addr) {
        st.scs.dwt_write(addr & 0xFFF, value, now)
    } else if let Some((word, bit)) = bit_band(addr) {
        st.board.read(word, 4, now).and_then(|w| {
            let w = if value & 1 != 0 { w | (1 << bit) } else { w & !(1 << bit) };
            st.board.write(word, 4, w, now)
        })
    } else {
        st.board.write(addr, size, value, now)
    };
    match result {
        Ok(()) => {
            let written = match band {
                Some((_, bit)) => (value & 1) << bit,
                None if size >= 4 => value,
                None => value << (8 * (addr & 3)),
            };
            follow_timing_registers(st, target & !3, written, now);
            if let Some(kind) = st.board.take_bus_error() {
                // A buffered write's bus error: an imprecise BusFault, escalated to HardFault.
                if st.stop.is_none() || matches!(st.stop, Some(Stop::Deadline | Stop::Interrupt)) {
                    st.stop = Some(Stop::Memory { kind, address: target, bus_fault: Some(CFSR_IMPRECISERR) });
                }
                let _ = uc.emu_stop();
                return;
            }
            // A write may bring a model's next event closer (an interrupt enable set while a
            // byte is shifting): the emulation must stop for it, not at the deadline set
            // before the write.
            pull_deadline(st);
            // A write may raise an interrupt line (an enable bit set while its flag is up):
            // sample the lines now; the next block hook takes the interrupt if it can.
            let mut lines = Vec::new();
            match st.board.advance(now, &mut |irq, level| lines.push((irq, level))) {
                Ok(_) => st.sample_lines(now, &lines),
                Err(e) => fail(uc, e),
            }
            if let Err(e) = store_memory_writes(uc) {
                fail(uc, e);
            }
        }
        Err(e) => fail(uc, e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elf::Segment;

    /// A board of plain registers that logs every access: (address, time, value written).
    #[derive(Default)]
    struct Bench {
        registers: HashMap<u32, u32>,
        log: Vec<(u32, Time, Option<u32>)>,
        /// A watchdog that expires once, at this time.
        watchdog_at: Option<Time>,
        /// An interrupt line high over `from..to`: (from, to, IRQ number).
        pulse: Option<(Time, Time, u32)>,
        /// The time of the last `advance`.
        advanced_to: Time,
    }

    /// 84 MHz: 4 time units per cycle.
    const UPC: u64 = 4;

    impl Peripherals for Bench {
        fn read(&mut self, addr: u32, _size: u32, now: Time) -> Result<u32, Unmodelled> {
            self.log.push((addr, now, None));
            Ok(self.registers.get(&(addr & !3)).copied().unwrap_or(0))
        }
        fn write(&mut self, addr: u32, _size: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
            self.log.push((addr, now, Some(value)));
            self.registers.insert(addr & !3, value);
            Ok(())
        }
        fn next_event(&self) -> Option<Time> {
            let edges = self.pulse.map(|(from, to, _)| [from, to]).unwrap_or_default();
            let edges = edges.into_iter().filter(|&t| t > self.advanced_to);
            self.watchdog_at.into_iter().chain(edges).min()
        }
        fn advance(&mut self, now: Time, lines: &mut dyn FnMut(u32, bool)) -> Result<bool, Unmodelled> {
            if let Some((from, to, irq)) = self.pulse {
                lines(irq, (from..to).contains(&now));
            }
            self.advanced_to = now;
            Ok(self.watchdog_at.take_if(|&mut t| t <= now).is_some())
        }
        fn units_per_cycle(&self) -> Result<u64, Unmodelled> {
            Ok(UPC)
        }
        fn system_reset(&mut self, _watchdog: bool) {}
        fn system_memory_page(&self) -> Vec<u8> {
            vec![0xFF; 0x1000]
        }
    }

    /// A flash image: the vector table (SP, reset at 0x100, IRQ0 at 0x140), `code` at 0x100 and
    /// `handler` at 0x140.
    fn program(code: &[u16], handler: &[u16]) -> Image {
        program_with(code, &[(16, handler)], 0x140)
    }

    /// A flash image: `code` at 0x100 (the reset vector), and each (exception, handler) from
    /// `handlers_at` on, 0x40 bytes apart, with its vector.
    fn program_with(code: &[u16], handlers: &[(usize, &[u16])], handlers_at: usize) -> Image {
        let mut flash = vec![0u8; 0x400];
        let mut word = |at: usize, w: u32| flash[at..at + 4].copy_from_slice(&w.to_le_bytes());
        word(0, SRAM_BASE + 0x1000);
        word(4, FLASH_BASE + 0x101);
        let mut places = vec![(0x100, code)];
        for (k, &(exc, handler)) in handlers.iter().enumerate() {
            let at = handlers_at + 0x40 * k;
            word(4 * exc, FLASH_BASE + at as u32 + 1);
            places.push((at, handler));
        }
        for (at, halfwords) in places {
            for (i, h) in halfwords.iter().enumerate() {
                flash[at + 2 * i..at + 2 * i + 2].copy_from_slice(&h.to_le_bytes());
            }
        }
        Image {
            path: "hand-assembled".into(),
            segments: vec![Segment { address: FLASH_BASE, data: flash }],
            initial_sp: SRAM_BASE + 0x1000,
            symbols: HashMap::new(),
            symbol_sizes: HashMap::new(),
            functions: Vec::new(),
            flash_bytes: 0x400,
            ram_bytes: 0,
        }
    }

    fn run(image: Image, profile: TimingProfile, until: Time) -> Machine<Bench> {
        let mut m = Machine::new(image, Bench::default(), profile).unwrap();
        m.run_until(until).unwrap();
        m
    }

    fn accesses(m: &Machine<Bench>, addr: u32) -> Vec<(Time, Option<u32>)> {
        m.board().log.iter().filter(|a| a.0 == addr).map(|a| (a.1, a.2)).collect()
    }

    /// RCC_CFGR = PPRE1 /2, then a read and a write of TIM2 (APB1), then `b .`.
    const APB_PROGRAM: [u16; 15] = [
        0xF643, 0x0108, // movw r1, #0x3808
        0xF2C4, 0x0102, // movt r1, #0x4002
        0xF44F, 0x5080, // mov.w r0, #0x1000
        0x6008, // str r0, [r1]           (RCC_CFGR, instruction 3)
        0x2100, // movs r1, #0
        0xF2C4, 0x0100, // movt r1, #0x4000
        0xBF00, // nop
        0x680A, // ldr r2, [r1]           (TIM2, instruction 7)
        0x3001, // adds r0, #1
        0x6048, // str r0, [r1, #4]       (TIM2, instruction 9)
        0xE7FE, // b .
    ];

    /// IRQ0 enabled and pended with an FP context active; the handler returns at once.
    const IRQ_PROGRAM: [u16; 14] = [
        0xF24E, 0x1100, // movw r1, #0xE100
        0xF2CE, 0x0100, // movt r1, #0xE000   (NVIC_ISER0)
        0x2001, // movs r0, #1
        0x6008, // str r0, [r1]
        0xEE00, 0x0A10, // vmov s0, r0     (CONTROL.FPCA set)
        0xF24E, 0x2200, // movw r2, #0xE200
        0xF2CE, 0x0200, // movt r2, #0xE000   (NVIC_ISPR0)
        0x6010, // str r0, [r2]
        0xE7FE, // b .
    ];
    const IRQ_HANDLER: [u16; 2] = [0x2307, 0x4770]; // movs r3, #7; bx lr

    /// IRQ0 and IRQ1 enabled and pended together: IRQ1 is tail-chained onto IRQ0's return.
    const TWO_IRQ_PROGRAM: [u16; 12] = [
        0xF24E, 0x1100, // movw r1, #0xE100
        0xF2CE, 0x0100, // movt r1, #0xE000   (NVIC_ISER0)
        0x2003, // movs r0, #3
        0x6008, // str r0, [r1]
        0xF24E, 0x2200, // movw r2, #0xE200
        0xF2CE, 0x0200, // movt r2, #0xE000   (NVIC_ISPR0)
        0x6010, // str r0, [r2]
        0xE7FE, // b .
    ];

    /// A tail-chained entry costs the optimistic profile the Cortex-M4's 6 cycles, return and
    /// entry together (the firmware's DMA stop counts on that minimum); the pessimistic one
    /// a full return and entry.
    #[test]
    fn a_tail_chained_entry_costs_6_cycles_optimistic_and_a_return_and_entry_pessimistic() {
        let image = || program_with(&TWO_IRQ_PROGRAM, &[(16, &IRQ_HANDLER), (17, &IRQ_HANDLER)], 0x140);
        let m = run(image(), TimingProfile::Optimistic, 2000);
        let (irq0, irq1) = (m.state().exception_stats[&16].spans[0], m.state().exception_stats[&17].spans[0]);
        assert_eq!(irq1.0, irq0.1, "no return cycles before the chained entry");
        assert_eq!(irq1.1 - irq1.0, UPC * (timing::TAIL_CHAIN_CYCLES + 2), "6 cycles, then the handler's 2 instructions");
        let m = run(image(), TimingProfile::Pessimistic, 4000);
        let (irq0, irq1) = (m.state().exception_stats[&16].spans[0], m.state().exception_stats[&17].spans[0]);
        assert!(irq1.0 >= irq0.1 + UPC * RETURN_CYCLES, "a full return: {irq0:?} then {irq1:?}");
        assert!(irq1.1 - irq1.0 >= UPC * (ENTRY_CYCLES + 2), "a full entry: {irq1:?}");
    }

    #[test]
    fn the_optimistic_profile_is_the_instruction_count_clock() {
        // The figures the instruction-count clock has always given these programs: every
        // instruction 4 units (one cycle at 84 MHz), entry 12 and return 10 cycles.
        let m = run(program(&APB_PROGRAM, &[]), TimingProfile::Optimistic, 1000);
        assert_eq!((m.now(), m.state().instructions), (1000, 250));
        let m = run(program(&IRQ_PROGRAM, &IRQ_HANDLER), TimingProfile::Optimistic, 1000);
        assert_eq!((m.now(), m.state().instructions), (1000, 228));
        assert_eq!(m.now(), UPC * (m.state().instructions + ENTRY_CYCLES + RETURN_CYCLES));
        let irq0 = &m.state().exception_stats[&16];
        // Entered after the 9 instructions before `b .`; returned after 12 + 2 cycles.
        assert_eq!(irq0.spans, vec![(36, 36 + UPC * (12 + 2))]);
        assert_eq!(m.state().fp_frames, 1, "the handler preempted FP code");
    }

    #[test]
    fn optimistic_register_accesses_are_stamped_at_the_start_of_their_block() {
        // One block: every access at its start, however many instructions precede it.
        let m = run(program(&APB_PROGRAM, &[]), TimingProfile::Optimistic, 1000);
        assert_eq!(accesses(&m, 0x4002_3808), vec![(0, Some(0x1000))]);
        assert_eq!(accesses(&m, 0x4000_0000), vec![(0, None)]);
        assert_eq!(accesses(&m, 0x4000_0004), vec![(0, Some(0x1001))]);
    }

    #[test]
    fn pessimistic_accesses_come_at_the_end_of_their_block_after_the_apb_stall() {
        let m = run(program(&APB_PROGRAM, &[]), TimingProfile::Pessimistic, 1000);
        // movw, movt, mov.w 1 each; str 2 + 1 (after data processing); movs, movt, nop 1;
        // ldr 2; adds 1; str 2 + 1; b 1: 16 cycles.
        let end = 16 * UPC;
        assert_eq!(accesses(&m, 0x4002_3808)[0], (end, Some(0x1000)), "RCC is on AHB1: no stall");
        // APB1 at HCLK/2: 1 (bridge) + 1 (edge) + 2 × 2 (setup, access) = 6 cycles each.
        assert_eq!(accesses(&m, 0x4000_0000), vec![(end + 6 * UPC, None)]);
        assert_eq!(accesses(&m, 0x4000_0004), vec![(end + 12 * UPC, Some(0x1001))]);
        // `b .` after a taken branch: 1 + 3 per lap, from the end of the block to the deadline.
        let idle_from = end + 12 * UPC + 4 * UPC;
        assert_eq!(m.now(), idle_from + (1000 - idle_from).div_ceil(4 * UPC) * 4 * UPC);
    }

    #[test]
    fn pessimistic_lazy_fp_stacking_costs_nothing_to_a_handler_without_fp() {
        let m = run(program(&IRQ_PROGRAM, &IRQ_HANDLER), TimingProfile::Pessimistic, 1000);
        // The first block: movw, movt, movs 1; str 3; vmov 1; movw, movt 1; str 3; b 1: 13
        // cycles. The interrupt is taken where the next block would start.
        let entered = 13 * UPC;
        let irq0 = &m.state().exception_stats[&16];
        // Entry 12, the handler's movs and bx: 2. The extended frame only reserves the FP
        // registers' space: the handler runs no FP instruction, so they are never saved.
        assert_eq!(irq0.spans, vec![(entered, entered + UPC * (12 + 2))]);
        assert_eq!(m.state().fp_frames, 1);
    }

    /// ACR = `acr`, then a loop of two more laps, each reading ACR back.
    fn art_program(acr: u16) -> [u16; 12] {
        [
            0xF643,
            0x4100, // movw r1, #0x3C00
            0xF2C4,
            0x0102, // movt r1, #0x4002   (FLASH_ACR)
            0xF240 | ((acr >> 12) & 0xF),
            ((acr >> 8) & 0x7) << 12 | (acr & 0xFF), // movw r0, #acr
            0x6008,                                  // str r0, [r1]
            0x2203,                                  // movs r2, #3
            0x3A01,                                  // 0x110: subs r2, #1 (a new 128-bit line)
            0x680B,                                  // ldr r3, [r1]
            0xD1FC,                                  // bne 0x110
            0xE7FE,                                  // b .
        ]
    }

    fn acr_reads(m: &Machine<Bench>) -> Vec<Time> {
        let mut reads: Vec<Time> = accesses(m, flash::BASE).into_iter().filter(|a| a.1.is_none()).map(|a| a.0).collect();
        reads.dedup();
        reads
    }

    #[test]
    fn a_branch_to_an_uncached_line_pays_the_wait_states_and_a_cached_one_does_not() {
        // LATENCY 2, PRFTEN, ICEN.
        let m = run(program(&art_program(0x302), &[]), TimingProfile::Pessimistic, 1000);
        // The first block: movw, movt, movw 1; str 3; movs, subs 1; ldr 3; bne 1 = 12 cycles
        // (the wait states were 0 when it was fetched). Then the loop's block, twice: refill 3,
        // its line missing (2) the first time and cached the second, body subs 1, ldr 3, bne 1.
        let first = 12 * UPC;
        assert_eq!(acr_reads(&m), vec![first, first + 10 * UPC, first + 10 * UPC + 8 * UPC]);
        // Without the cache (ICEN = 0) every lap pays the wait states.
        let m = run(program(&art_program(0x102), &[]), TimingProfile::Pessimistic, 1000);
        assert_eq!(acr_reads(&m), vec![first, first + 10 * UPC, first + 20 * UPC]);
        // Under the optimistic profile a lap is its three instructions, and each read is dated
        // at its block's start: the first block's at 0, the loop's after the first block's 8.
        let m = run(program(&art_program(0x302), &[]), TimingProfile::Optimistic, 1000);
        assert_eq!(acr_reads(&m), vec![0, 8 * UPC, 11 * UPC]);
    }

    fn code(halfwords: &[u16]) -> Code {
        Code::new(halfwords.iter().flat_map(|h| h.to_le_bytes()).collect())
    }

    #[test]
    fn a_32_bit_instruction_counts_once() {
        // push {r7, lr}; bl (32-bit); udf
        let mut c = code(&[0xB580, 0xF000, 0xF800, 0xDE00]);
        assert_eq!(c.block(FLASH_BASE, 8).instructions, 3);
    }

    #[test]
    fn the_idle_spin_and_the_delay_loops_are_recognised_exactly() {
        assert_eq!(code(&[0xE7FE]).block(FLASH_BASE, 2).kind, BlockKind::IdleSpin);
        assert_eq!(code(&[0x3801, 0xD1FD]).block(FLASH_BASE, 4).kind, BlockKind::Countdown(0));
        // ldr r3, [r1]; subs r3, r3, r2; cmp r3, r0; blo .-6 (the firmware's delay_ms)
        let wait = code(&[0x680B, 0x1A9B, 0x4283, 0xD3FB]).block(FLASH_BASE, 8).kind;
        assert_eq!(wait, BlockKind::CycleCountWait { addr: 1, start: 2, limit: 0 });
        // The same loop writing its start register is not a pure wait.
        let writes_start = code(&[0x680A, 0x1A92, 0x4282, 0xD3FB]).block(FLASH_BASE, 8).kind;
        assert_eq!(writes_start, BlockKind::Plain);
    }

    /// `r1` = 0x6000_0000 (reserved on the STM32F401: no external memory controller), then a
    /// read from it.
    const RESERVED_READ: [u16; 3] = [
        0x2160, // movs r1, #0x60
        0x0609, // lsls r1, r1, #24
        0x6808, // ldr r0, [r1]
    ];
    /// A HardFault handler that touches no stack: r3 = 7, then `b .`.
    const STACKLESS_HANDLER: [u16; 2] = [0x2307, 0xE7FE];
    /// A HardFault handler whose first instruction pushes (as a compiled one does).
    const PUSHING_HANDLER: [u16; 3] = [0xB580, 0x2307, 0xE7FE]; // push {r7, lr}; movs r3, #7; b .
    const HANDLERS_AT: usize = 0x300;

    fn r(m: &Machine<Bench>, reg: RegisterARM) -> u32 {
        m.reg(reg).unwrap()
    }

    /// Rule: an undefined instruction (a panic's `udf`) is a UsageFault with CFSR.UNDEFINSTR,
    /// escalated to HardFault when UsageFault is not enabled (ARMv7-M B1.5.14, B3.2.15).
    #[test]
    fn an_undefined_instruction_sets_undefinstr_and_escalates_to_hard_fault() {
        let udf = [0xDE00u16, 0xE7FE];
        let m = run(program_with(&udf, &[(scs::HARD_FAULT, &STACKLESS_HANDLER)], HANDLERS_AT), TimingProfile::Optimistic, 400);
        let st = m.state();
        assert_eq!(st.hard_faults.len(), 1, "{:?}", st.hard_faults);
        assert!(st.hard_faults[0].cause.contains("undefined instruction"), "{}", st.hard_faults[0].cause);
        assert_eq!(st.scs.cfsr, CFSR_UNDEFINSTR);
        assert_eq!(st.scs.hfsr, 1 << 30, "HFSR.FORCED: the UsageFault is not enabled");
        assert_eq!(m.current_exception(), scs::HARD_FAULT, "the handler ran");
    }

    #[test]
    fn a_read_of_reserved_memory_is_a_precise_bus_fault_escalated_to_hard_fault() {
        let code = [RESERVED_READ.as_slice(), &[0xE7FE]].concat();
        let m = run(program_with(&code, &[(scs::HARD_FAULT, &STACKLESS_HANDLER)], HANDLERS_AT), TimingProfile::Optimistic, 400);
        let st = m.state();
        assert_eq!(st.hard_faults.len(), 1, "{:?}", st.hard_faults);
        let hf = &st.hard_faults[0];
        assert_eq!(hf.pc, FLASH_BASE + 0x104, "the faulting load is the stacked PC");
        assert!(hf.cause.contains("read of reserved memory at 0x60000000"), "{}", hf.cause);
        assert_eq!(st.scs.cfsr, CFSR_PRECISERR);
        assert_eq!(st.scs.hfsr, 1 << 30, "HFSR.FORCED: the BusFault is not enabled");
        assert_eq!((m.current_exception(), r(&m, RegisterARM::R3)), (scs::HARD_FAULT, 7), "the handler ran");
        let frame = m.read_memory(r(&m, RegisterARM::SP) + 24, 4).unwrap();
        assert_eq!(u32::from_le_bytes(frame.try_into().unwrap()), FLASH_BASE + 0x104);
        assert!(st.lockups.is_empty() && !m.locked_up());
    }

    #[test]
    fn a_fault_in_the_hard_fault_handler_locks_up_until_the_watchdog_resets_the_board() {
        let code = [RESERVED_READ.as_slice(), &[0xE7FE]].concat();
        let image = program_with(&code, &[(scs::HARD_FAULT, &RESERVED_READ), (16, &STACKLESS_HANDLER)], HANDLERS_AT);
        let bench = Bench { watchdog_at: Some(4000), ..Bench::default() };
        let mut m = Machine::new(image, bench, TimingProfile::Optimistic).unwrap();
        m.run_until(1000).unwrap();
        let st = m.state();
        assert_eq!(st.lockups.len(), 1);
        let lockup = &st.lockups[0];
        assert_eq!(lockup.pc, FLASH_BASE + HANDLERS_AT as u32 + 4, "the load in the HardFault handler");
        assert!(lockup.cause.contains("read of reserved memory"), "{}", lockup.cause);
        assert!(m.locked_up() && m.pc() == 0xFFFF_FFFE);
        // Locked: no instruction runs and an interrupt does not wake it, for as long as it lasts.
        let instructions = st.instructions;
        let now = m.now();
        m.state_mut().scs.write(scs::reg::NVIC_ISER, 1, now).unwrap();
        m.state_mut().scs.set_pending(16);
        m.run_until(3999).unwrap();
        assert_eq!((m.now(), m.state().instructions), (4000, instructions), "time passes, nothing runs");
        assert!(!m.state().exception_stats.contains_key(&16), "IRQ0 was taken while locked up");
        // The watchdog's reset ends it: the program runs again from the reset vector (and locks
        // up again).
        m.run_until(8000).unwrap();
        let st = m.state();
        assert_eq!(st.resets, vec![(4000, "watchdog")]);
        assert!(st.instructions > instructions, "nothing ran after the reset");
        assert_eq!(st.lockups.len(), 2);
        assert!(st.lockups[1].at > 4000);
    }

    #[test]
    fn a_frame_that_does_not_fit_enters_the_hard_fault_handler_without_one() {
        // IRQ0 enabled, then `b .`.
        let code = [0xF24E, 0x1100, 0xF2CE, 0x0100, 0x2001, 0x6008, 0xE7FE];
        for (handler, locks_up) in [(STACKLESS_HANDLER.as_slice(), false), (PUSHING_HANDLER.as_slice(), true)] {
            let image = program_with(&code, &[(scs::HARD_FAULT, handler), (16, &[0x2305, 0x4770])], HANDLERS_AT);
            let mut m = Machine::new(image, Bench::default(), TimingProfile::Optimistic).unwrap();
            m.run_until(100).unwrap();
            m.set_stack_pointer(SRAM_BASE + 8).unwrap();
            m.state_mut().scs.set_pending(16);
            m.run_until(400).unwrap();
            let st = m.state();
            assert_eq!(st.hard_faults.len(), 1, "{:?}", st.hard_faults);
            assert!(st.hard_faults[0].cause.contains("STKERR") && st.hard_faults[0].cause.contains("exception 16"));
            assert_eq!((st.scs.cfsr, st.scs.hfsr), (CFSR_STKERR, 1 << 30));
            assert!(!st.exception_stats.contains_key(&16), "IRQ0's handler ran");
            assert_eq!(st.scs.clone().read(0x200, m.now(), 0).unwrap() & 1, 1, "IRQ0 stays pending");
            assert_eq!(r(&m, RegisterARM::SP), SRAM_BASE + 8 - 0x20, "SP moved to the frame that failed");
            if locks_up {
                assert_eq!(st.lockups.len(), 1, "the handler's push faulted and locked the core up");
                assert_eq!(st.lockups[0].pc, FLASH_BASE + HANDLERS_AT as u32);
                assert!(st.lockups[0].cause.contains("write to reserved memory"), "{}", st.lockups[0].cause);
                assert_ne!(r(&m, RegisterARM::R3), 7);
            } else {
                assert!(st.lockups.is_empty());
                assert_eq!((m.current_exception(), r(&m, RegisterARM::R3)), (scs::HARD_FAULT, 7), "the handler ran");
            }
        }
    }

    #[test]
    fn masked_intervals_count_primask_and_basepri_at_or_above_the_watched_priority() {
        let nops = |n: usize| vec![0xBF00u16; n];
        let code: Vec<u16> = [
            // IRQ0 at priority 0x20 (NVIC_IPR0 byte 0).
            vec![0xF24E, 0x4100, 0xF2CE, 0x0100, 0x2020, 0x7008],
            // PRIMASK over 10 nops.
            vec![0xB672],
            nops(10),
            vec![0xB662],
            // BASEPRI 0x30: below IRQ0's priority, it does not mask it.
            vec![0x2030, 0xF380, 0x8811],
            nops(5),
            // BASEPRI 0x20: at IRQ0's priority, it masks it, over 20 nops.
            vec![0x2020, 0xF380, 0x8811],
            nops(20),
            vec![0x2000, 0xF380, 0x8811, 0xE7FE],
        ]
        .concat();
        for profile in [TimingProfile::Optimistic, TimingProfile::Pessimistic] {
            let mut m = Machine::new(program(&code, &[]), Bench::default(), profile).unwrap();
            m.measure_masking_against(16);
            m.run_until(2000).unwrap();
            let masking = m.state().masking.clone().unwrap();
            assert_eq!(masking.intervals, 2, "{profile}: {masking:?}");
            let longest = masking.longest.unwrap();
            // The BASEPRI interval: from the end of the block with the MSR that set it (an MSR
            // ends its block: that one starts after the first MSR, at halfword 6 + 1 + 10 + 1 +
            // 3) to the end of the one that cleared it: 20 nops, movs and msr.
            let pc_of_set = FLASH_BASE + 0x100 + 2 * (6 + 1 + 10 + 1 + 3);
            assert_eq!(longest.pc, pc_of_set, "{profile}: {longest:x?}");
            if profile == TimingProfile::Optimistic {
                assert_eq!(longest.to - longest.from, 22 * UPC, "{longest:?}");
                // PRIMASK over 10 nops and the CPSIE.
                assert_eq!(masking.total, 22 * UPC + 11 * UPC);
            }
        }
    }

    #[test]
    fn the_pending_wait_runs_from_the_line_rising_to_the_entry() {
        let code = [
            0xF24E, 0x1100, 0xF2CE, 0x0100, 0x2001, 0x6008, // IRQ0 enabled
            0xB672, // cpsid i
            0x2064, // movs r0, #100
            0x3801, 0xD1FD, // subs r0, #1; bne .-2
            0xB662, // cpsie i
            0xE7FE,
        ];
        let bench = Bench { pulse: Some((200, 240, 0)), ..Bench::default() };
        let mut m = Machine::new(program(&code, &IRQ_HANDLER), bench, TimingProfile::Optimistic).unwrap();
        m.measure_masking_against(16);
        m.run_until(2000).unwrap();
        let st = m.state();
        let (entry, _) = st.exception_stats[&16].spans[0];
        // Entered as soon as PRIMASK cleared: 4 + 2 + 2 × 100 + 1 instructions.
        assert_eq!(entry, 207 * UPC);
        assert_eq!(st.masking.as_ref().unwrap().longest.unwrap().to, entry);
        assert_eq!(st.exception_stats[&16].longest_pending, Some((entry - 200, entry)));
    }
}
