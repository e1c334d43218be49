//! Register-level models of the STM32F401 peripherals the firmware touches, written from the
//! reference manual (RM0368) and the `stm32f4` PAC's register descriptions (generated from ST's
//! SVD), never from the firmware's code.
//!
//! Every model is a [`Peripheral`]; the board ([`crate::board`]) places each at its base address,
//! gates it by its RCC clock enable and wires its interrupt lines, from one table.

pub mod adc;
pub mod dbgmcu;
pub mod dma;
pub mod flash;
pub mod gpio;
pub mod iwdg;
pub mod pwr;
pub mod rcc;
pub mod sensors;
pub mod spi;
pub mod tim;
pub mod usart;

/// What the board needs from a peripheral model.
///
/// - Registers are addressed by their byte offset from the peripheral's base address.
/// - `read` and `write` see 32-bit accesses: the board splits or widens other sizes. An offset
///   or a bit the model does not implement is an [`Unmodelled`] error, which ends the run naming
///   the register: no silent zeros.
/// - Every access and every [`Peripheral::advance`] comes with the current time ([`Time`]) and
///   the clocks the RCC derives, so a model may compute lazily; one that changes by itself (a
///   timer's update, a byte shifted out) says when in [`Peripheral::next_event`].
///
/// Each model also keeps its own `read`/`write` taking only what it uses; this trait is the
/// board's uniform view of them.
pub trait Peripheral {
    /// The register at `offset`, read at `now`.
    fn read(&mut self, offset: u32, now: Time, clocks: Clocks) -> Result<u32, Unmodelled>;
    /// `value` written to the register at `offset` at `now`.
    fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled>;
    /// The next time the model changes by itself, if it does.
    fn next_event(&self) -> Option<Time> {
        None
    }
    /// Brings the model up to `now`.
    fn advance(&mut self, _now: Time, _clocks: Clocks) {}
    /// The clocks as RCC derives them now, before every access and every advance: a model that
    /// counts a clock on its own (a timer) counts at the new rate from `now` on.
    fn set_clocks(&mut self, _now: Time, _clocks: Clocks) {}
    /// The level of its interrupt output `line` (0 for a peripheral with one line; a DMA
    /// controller's stream number).
    fn irq_line(&self, _line: usize) -> bool {
        false
    }
    /// Its reset bit in RCC was pulsed (RM0368 §6.3, RCC_AHB1RSTR, _APB1RSTR, _APB2RSTR: each
    /// reset bit sits where the peripheral's enable bit sits in the matching xENR): its
    /// registers go back to their reset values. A peripheral with no reset bit never sees this.
    fn reset(&mut self) {}
}

/// Emulated time since power-on, in units of 1/[`TIME_HZ`] s.
pub type Time = u64;

/// Units of [`Time`] per second: the least common multiple of the board's clocks (16 MHz and
/// 84 MHz), so a cycle of any of them is a whole number of units.
pub const TIME_HZ: u64 = 336_000_000;

/// Time units per cycle of a clock of `hz`, if it divides [`TIME_HZ`].
pub fn units_per_cycle(hz: u64) -> Option<u64> {
    (hz > 0 && TIME_HZ % hz == 0).then(|| TIME_HZ / hz)
}

/// Seconds to [`Time`], rounded to the nearest unit.
pub fn time_from_s(s: f64) -> Time {
    (s.max(0.0) * TIME_HZ as f64).round() as Time
}

/// [`Time`] to seconds.
pub fn time_to_s(t: Time) -> f64 {
    t as f64 / TIME_HZ as f64
}

/// An access the models do not implement: the run stops with this.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unmodelled {
    /// Peripheral and register, e.g. `TIM2.CCMR1` or `SPI2+0x40`.
    pub register: String,
    /// What was not modelled, e.g. `write of 0x0000_0100 sets OPM, not modelled`.
    pub what: String,
}

impl Unmodelled {
    pub fn new(register: impl Into<String>, what: impl Into<String>) -> Self {
        Unmodelled { register: register.into(), what: what.into() }
    }

    /// An offset with no register behind it (or a register this model leaves out).
    pub fn offset(peripheral: &str, offset: u32, write: bool) -> Self {
        Unmodelled::new(
            format!("{peripheral}+{offset:#05x}"),
            if write { "write to an unmodelled register" } else { "read of an unmodelled register" },
        )
    }

    /// Bits set in `value` outside the `modelled` mask of a register.
    pub fn check_bits(register: &str, value: u32, modelled: u32) -> Result<(), Unmodelled> {
        let extra = value & !modelled;
        if extra == 0 {
            Ok(())
        } else {
            Err(Unmodelled::new(register, format!("write of {value:#010x} sets bits {extra:#010x} that the model does not implement")))
        }
    }
}

impl std::fmt::Display for Unmodelled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.register, self.what)
    }
}

/// The clock frequencies the RCC model derives from its registers, for the other models.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Clocks {
    pub sysclk_hz: u64,
    pub hclk_hz: u64,
    pub pclk1_hz: u64,
    pub pclk2_hz: u64,
    /// Timer kernel clocks: PCLKx, doubled when the APB prescaler is not 1 (RM0368 §6.2).
    pub tim_apb1_hz: u64,
    pub tim_apb2_hz: u64,
}

impl Clocks {
    /// Reset state: HSI 16 MHz everywhere.
    pub const RESET: Clocks = Clocks {
        sysclk_hz: 16_000_000,
        hclk_hz: 16_000_000,
        pclk1_hz: 16_000_000,
        pclk2_hz: 16_000_000,
        tim_apb1_hz: 16_000_000,
        tim_apb2_hz: 16_000_000,
    };

    /// The board running: SYSCLK 84 MHz from the PLL, APB1 at 42 MHz (its timers at 84 MHz),
    /// APB2 at 84 MHz.
    pub const PLL_84_MHZ: Clocks = Clocks {
        sysclk_hz: 84_000_000,
        hclk_hz: 84_000_000,
        pclk1_hz: 42_000_000,
        pclk2_hz: 84_000_000,
        tim_apb1_hz: 84_000_000,
        tim_apb2_hz: 84_000_000,
    };
}

/// STM32F401 interrupt numbers (RM0368 table 38) of the lines the models drive.
pub mod irq {
    pub const TIM1_BRK_TIM9: u32 = 24;
    pub const TIM2: u32 = 28;
    pub const TIM4: u32 = 30;
    pub const SPI2: u32 = 36;
    pub const USART1: u32 = 37;
    pub const ADC: u32 = 18;
    pub const DMA1_STREAM3: u32 = 14;
    pub const DMA2_STREAM2: u32 = 58;
    pub const DMA2_STREAM5: u32 = 68;
    pub const FLASH: u32 = 4;
}
