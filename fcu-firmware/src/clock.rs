//! The monotonic clock of the tasks' delays and the link's `time_boot_ms`, in milliseconds
//! since boot, counted on the DWT cycle counter.
//!
//! A monotonic that counts SysTick's interrupts (rtic-monotonics' `systick_monotonic`) loses
//! time whenever interrupts are held off longer than its period: a flash erase stalls every
//! fetch for up to 500 ms, and the interrupts that fell in the stall come as one, so such a
//! clock fell 268 ms behind over one erase. The cycle counter is a free-running core register
//! that counts on while fetches stall: reading it gives the time whatever the interrupts did.
//! SysTick still interrupts every millisecond, to wake the timer queue's delays and to look at
//! the counter well within its wrap (2^32 cycles: 51 s at 84 MHz, longer than any stall). The
//! core never sleeps (RTIC's idle is a spin loop, and only a halted boot waits in WFI), so the
//! counter never pauses for a sleep either.

use core::cell::Cell;
use cortex_m::interrupt::Mutex;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{DWT, SCB, SYST};
use rtic_monotonics::rtic_time::timer_queue::TimerQueue;
use rtic_monotonics::{fugit, TimerQueueBackend, TimerQueueBasedMonotonic};

/// The clock's resolution: 1 kHz, milliseconds.
const TICK_HZ: u32 = 1000;
/// The same, as fugit's instants and durations take it.
const TICK_RATE: u64 = TICK_HZ as u64;

/// The count of milliseconds, and where the cycle counter stood when it was last brought up to
/// date, with the cycles since the last whole millisecond.
#[derive(Clone, Copy)]
struct Count {
    ms: u32,
    last_cycles: u32,
    spare_cycles: u32,
    cycles_per_ms: u32,
}

static COUNT: Mutex<Cell<Count>> = Mutex::new(Cell::new(Count { ms: 0, last_cycles: 0, spare_cycles: 0, cycles_per_ms: 0 }));
static QUEUE: TimerQueue<CycleBackend> = TimerQueue::new();

/// The clock for `rtic_monotonics`' timer queue.
pub struct CycleBackend;

/// The tasks' monotonic: `Mono::now()`, `Mono::delay(..)`.
pub struct Mono;

impl Mono {
    /// Starts the clock at 0 ms. The cycle counter must already run (`init` starts it first);
    /// `sysclk_hz` is the core clock it counts, a whole number of kHz.
    pub fn start(mut systick: SYST, sysclk_hz: u32) {
        let cycles_per_ms = sysclk_hz / TICK_HZ;
        cortex_m::interrupt::free(|cs| {
            COUNT.borrow(cs).set(Count { ms: 0, last_cycles: DWT::cycle_count(), spare_cycles: 0, cycles_per_ms });
        });
        systick.disable_counter();
        systick.set_clock_source(SystClkSource::Core);
        systick.set_reload(cycles_per_ms.saturating_sub(1));
        systick.clear_current();
        systick.enable_interrupt();
        systick.enable_counter();
        QUEUE.initialize(CycleBackend);
    }
}

impl TimerQueueBasedMonotonic for Mono {
    type Backend = CycleBackend;
    type Instant = fugit::MonotonicTimerInstant<u32, TICK_RATE>;
    type Duration = fugit::TimerDuration<u32, TICK_RATE>;
}

impl TimerQueueBackend for CycleBackend {
    type Ticks = u32;

    /// Milliseconds since [`Mono::start`]: the cycles counted since the last look added.
    fn now() -> u32 {
        cortex_m::interrupt::free(|cs| {
            let cell = COUNT.borrow(cs);
            let mut count = cell.get();
            if count.cycles_per_ms == 0 {
                return 0;
            }
            let cycles = DWT::cycle_count();
            let spare = count.spare_cycles.wrapping_add(cycles.wrapping_sub(count.last_cycles));
            count.ms = count.ms.wrapping_add(spare / count.cycles_per_ms);
            count.spare_cycles = spare % count.cycles_per_ms;
            count.last_cycles = cycles;
            cell.set(count);
            count.ms
        })
    }

    /// SysTick interrupts every millisecond and the queue looks at its deadlines each time:
    /// there is no compare to set.
    fn set_compare(_instant: u32) {}

    fn clear_compare_flag() {}

    fn pend_interrupt() {
        SCB::set_pendst();
    }

    /// Each SysTick brings the count up to date, well within the cycle counter's wrap.
    fn on_interrupt() {
        let _ms = Self::now();
    }

    fn timer_queue() -> &'static TimerQueue<Self> {
        &QUEUE
    }
}

/// SysTick: the timer queue's deadlines (RTIC binds no task to it).
#[cortex_m_rt::exception]
fn SysTick() {
    // SAFETY: called from the clock's own interrupt, as the queue requires.
    unsafe { QUEUE.on_monotonic_interrupt() };
}
