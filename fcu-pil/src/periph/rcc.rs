//! RCC, reset and clock control (RM0368 §6), at 0x4002_3800.
//!
//! Modelled: the HSI, HSE (a 16 MHz crystal on this board) and main-PLL oscillators with their
//! ready flags and start-up times, the system clock switch (SW → SWS), the AHB/APB prescalers, the
//! peripheral clock enables and resets of AHB1/APB1/APB2, the reset flags in CSR and the LSI
//! enable. Everything the HAL's `Rcc::freeze` (stm32f4xx-hal 0.23, `rcc/f4/mod.rs`) and the
//! `Enable`/`Reset` traits (`rcc/f4/enable.rs`) touch on an F401, and the clock security system
//! (below). Not modelled (an access is an [`Unmodelled`] error): HSE bypass, HSI trimming, the I2S PLL, MCO
//! outputs, the RTC prescaler and clock (BDCR), the clock interrupts (CIR enables), the
//! low-power clock enables (xLPENR, untouched by the HAL's code paths the firmware uses), AHB2
//! (USB OTG, not initialised), SSCGR, PLLI2SCFGR and DCKCFGR.TIMPRE.
//!
//! **Clock security system (RM0368 §6.2.7).** CR.CSSON arms the detector, which runs while the
//! HSE is ready. A crystal that stops ([`Rcc::fail_hse`], a fault the harness injects) with the
//! detector running: the HSE is turned off (HSEON and CSSON clear), the PLL too if the HSE feeds
//! it and it is the system clock, the system clock switches to the HSI (SW and SWS = HSI), and
//! CIR.CSSF sets, which is the NMI's line ([`Rcc::nmi_line`]) until CIR.CSSC clears it ("the NMI
//! is executed indefinitely unless the CSS interrupt pending bit is cleared"). The same failure
//! without the detector: HSERDY clears and, when the HSE drives SYSCLK directly or through the
//! PLL, the system clock is gone ([`Rcc::core_clock_stopped`]): the core stops until a reset
//! (the watchdog runs on the LSI). The other models keep counting at the clocks they had (an
//! assumption: on silicon the bus clocks stop too and TIM4 holds its output levels, which to the
//! motors is the same as holding their duty).
//!
//! Register layout, reset values and field positions are from the `stm32f4` 0.16 PAC
//! (`stm32f401/rcc/*.rs`, generated from ST's SVD); behaviour from RM0368 §6.

use super::{units_per_cycle, Clocks, Peripheral, Time, Unmodelled, TIME_HZ};

/// Base address of the RCC (RM0368 memory map).
pub const BASE: u32 = 0x4002_3800;
/// Peripheral name used in error messages.
pub const NAME: &str = "RCC";

/// HSI RC oscillator frequency (RM0368 §6.2.2).
pub const HSI_HZ: u64 = 16_000_000;
/// HSE crystal frequency on this board (`docs/reference.md#clock-and-timers`).
pub const HSE_HZ: u64 = 16_000_000;
/// Time from HSEON to HSERDY. Assumption: the F401 datasheet's typical crystal start-up time
/// t_SU(HSE) = 2 ms (it depends on the crystal; the datasheet gives no maximum).
pub const HSE_STARTUP: Time = 2 * TIME_HZ / 1000;
/// Time from PLLON (with its input ready) to PLLRDY. Assumption: 100 µs, between the F401
/// datasheet's typical (75 µs) and maximum (200 µs) PLL lock time t_LOCK.
pub const PLL_LOCK: Time = TIME_HZ / 10_000;
/// Time from HSION to HSIRDY: the datasheet's maximum HSI start-up time, 4 µs.
pub const HSI_STARTUP: Time = TIME_HZ / 250_000;
/// Time from LSION to LSIRDY: the datasheet's maximum LSI start-up time, 40 µs.
pub const LSI_STARTUP: Time = TIME_HZ / 25_000;

/// A ready time that never comes (an oscillator that does not start).
const NEVER: Time = Time::MAX / 4;

/// Datasheet limits of the F401 (STM32F401xB/C datasheet, general operating conditions).
pub const SYSCLK_MAX_HZ: u64 = 84_000_000;
pub const PCLK1_MAX_HZ: u64 = 42_000_000;
pub const PCLK2_MAX_HZ: u64 = 84_000_000;

// Register offsets (PAC `stm32f401/rcc.rs`).
const CR: u32 = 0x00;
const PLLCFGR: u32 = 0x04;
const CFGR: u32 = 0x08;
const CIR: u32 = 0x0C;
const AHB1RSTR: u32 = 0x10;
const APB1RSTR: u32 = 0x20;
const APB2RSTR: u32 = 0x24;
const AHB1ENR: u32 = 0x30;
const APB1ENR: u32 = 0x40;
const APB2ENR: u32 = 0x44;
const BDCR: u32 = 0x70;
const CSR: u32 = 0x74;
const DCKCFGR: u32 = 0x8C;

// CR fields.
const CR_RESET: u32 = 0x0000_0083; // HSION, HSIRDY, HSITRIM = 16
const CR_HSION: u32 = 1 << 0;
const CR_HSIRDY: u32 = 1 << 1;
const CR_HSITRIM_RESET: u32 = 16 << 3;
const CR_HSEON: u32 = 1 << 16;
const CR_HSERDY: u32 = 1 << 17;
const CR_CSSON: u32 = 1 << 19;
const CR_PLLON: u32 = 1 << 24;
const CR_PLLRDY: u32 = 1 << 25;
/// Read-only fields of CR: HSIRDY, HSICAL, HSERDY, PLLRDY, PLLI2SRDY. Writes to them are ignored.
const CR_READ_ONLY: u32 = 0x0A02_FF02;

// PLLCFGR fields: PLLM 5:0, PLLN 14:6, PLLP 17:16, PLLSRC 22, PLLQ 27:24. Bit 29 is reserved
// but 1 at reset (SVD reset value 0x2400_3010); it must keep that value.
const PLLCFGR_RESET: u32 = 0x2400_3010;
const PLLCFGR_FIELDS: u32 = 0x0F43_7FFF;
const PLLCFGR_PLLSRC: u32 = 1 << 22;

// CFGR fields: SW 1:0, SWS 3:2 (read-only), HPRE 7:4, PPRE1 12:10, PPRE2 15:13. RTCPRE, MCO1,
// I2SSRC, MCO1PRE, MCO2PRE and MCO2 are not modelled: they must stay at their reset value 0.
const CFGR_FIELDS: u32 = 0x0000_FCFF;
const CFGR_SWS: u32 = 0b11 << 2;

// CIR: the ready-interrupt flags (read-only) and their clear bits (write-only) are accepted;
// the interrupt enables (bits 13:8) are not modelled, so the flags never set.
const CIR_FLAGS_AND_CLEARS: u32 = 0x00BF_00BF;
/// CIR.CSSF, the clock security system's flag (read-only), and CSSC, its clear bit.
const CIR_CSSF: u32 = 1 << 7;
const CIR_CSSC: u32 = 1 << 23;

// Peripheral reset and enable fields (identical bit sets for RSTR and ENR on each bus).
const AHB1_FIELDS: u32 = 0x0060_109F; // GPIOA..E, GPIOH, CRC, DMA1, DMA2
const APB1_FIELDS: u32 = 0x10E2_C80F; // TIM2..5, WWDG, SPI2, SPI3, USART2, I2C1..3, PWR
const APB2_FIELDS: u32 = 0x0007_7931; // TIM1, USART1, USART6, ADC1, SDIO, SPI1, SPI4, SYSCFG, TIM9..11
/// AHB1ENR resets to 0x0010_0000 in the SVD (bit 20, the F40x's CCMDATARAMEN, which the F401 does
/// not have). The model keeps the SVD value; the bit is reserved and must keep it.
const AHB1ENR_RESET: u32 = 0x0010_0000;

// CSR fields.
const CSR_LSION: u32 = 1 << 0;
const CSR_LSIRDY: u32 = 1 << 1;
const CSR_RMVF: u32 = 1 << 24;
const CSR_BORRSTF: u32 = 1 << 25;
const CSR_PINRSTF: u32 = 1 << 26;
const CSR_PORRSTF: u32 = 1 << 27;
const CSR_SFTRSTF: u32 = 1 << 28;
const CSR_IWDGRSTF: u32 = 1 << 29;
/// All reset flags, bits 31:25. RM0368 RCC_CSR: set by hardware, cleared by RMVF; the SVD marks
/// them rw but the RM gives no write effect, so writes to them are ignored.
const CSR_FLAGS: u32 = 0xFE00_0000;
/// CSR reset value (SVD and RM0368): BORRSTF, PINRSTF and PORRSTF set by a power-on reset.
const CSR_POWER_ON: u32 = CSR_BORRSTF | CSR_PINRSTF | CSR_PORRSTF;

/// Reports a write that changes bits outside `modelled` from their reset value: reserved bits
/// written as their reset value, and unmodelled features left at reset, are accepted.
fn check_reset(register: &str, value: u32, modelled: u32, reset: u32) -> Result<(), Unmodelled> {
    let bad = (value ^ reset) & !modelled;
    if bad == 0 {
        Ok(())
    } else {
        Err(Unmodelled::new(register, format!("write of {value:#010x} changes bits {bad:#010x} from their reset value; not modelled")))
    }
}

/// A peripheral bus with clock-enable and reset registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Bus {
    Ahb1,
    Apb1,
    Apb2,
}

/// System clock source, as encoded in CFGR.SW / CFGR.SWS.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Source {
    Hsi,
    Hse,
    Pll,
}

impl Source {
    fn bits(self) -> u32 {
        match self {
            Source::Hsi => 0,
            Source::Hse => 1,
            Source::Pll => 2,
        }
    }
}

/// The RCC model.
#[derive(Clone, Debug)]
pub struct Rcc {
    /// Latest time the model has been brought up to.
    last: Time,
    /// Time HSIRDY sets (None: HSI off).
    hsi_ready_at: Option<Time>,
    /// Time HSERDY sets (None: HSE off).
    hse_ready_at: Option<Time>,
    /// Time PLLON was set (None: PLL off). PLLRDY follows once its input is ready too.
    pll_on_at: Option<Time>,
    /// Time LSIRDY sets (None: LSI off).
    lsi_ready_at: Option<Time>,
    /// CSR.LSION as software wrote it.
    lsion: bool,
    /// The IWDG has forced the LSI on (its start key): software can no longer stop it.
    lsi_forced: bool,
    /// A board whose HSE crystal never oscillates (a fault to inject): HSERDY never sets.
    hse_dead: bool,
    /// A chip whose PLL never locks (a fault to inject): PLLRDY never sets.
    pll_dead: bool,
    /// CR.CSSON: the clock security system is armed.
    csson: bool,
    /// CIR.CSSF: the clock security system saw the HSE fail (the NMI's line).
    cssf: bool,
    /// The HSE failed while it drove SYSCLK and no detector switched away from it: no clock.
    clock_lost: bool,
    pllcfgr: u32,
    /// CFGR without SWS.
    cfgr: u32,
    sws: Source,
    ahb1rstr: u32,
    apb1rstr: u32,
    apb2rstr: u32,
    ahb1enr: u32,
    apb1enr: u32,
    apb2enr: u32,
    /// CSR reset flags (bits 31:25).
    reset_flags: u32,
    pulses: Vec<(Bus, u32)>,
}

impl Default for Rcc {
    fn default() -> Self {
        Rcc::new()
    }
}

impl Rcc {
    /// Power-on reset state: HSI on and ready and selected, PLL and HSE off, all peripheral
    /// clocks off, reset flags BORRSTF | PINRSTF | PORRSTF.
    pub fn new() -> Self {
        Rcc {
            last: 0,
            hsi_ready_at: Some(0),
            hse_ready_at: None,
            pll_on_at: None,
            lsi_ready_at: None,
            lsion: false,
            lsi_forced: false,
            hse_dead: false,
            pll_dead: false,
            csson: false,
            cssf: false,
            clock_lost: false,
            pllcfgr: PLLCFGR_RESET,
            cfgr: 0,
            sws: Source::Hsi,
            ahb1rstr: 0,
            apb1rstr: 0,
            apb2rstr: 0,
            ahb1enr: AHB1ENR_RESET,
            apb1enr: 0,
            apb2enr: 0,
            reset_flags: CSR_POWER_ON,
            pulses: Vec::new(),
        }
    }

    /// A system reset (watchdog, software, NRST): every register back to its reset value except
    /// the reset flags in CSR, which only a power-on reset or RMVF clears (RM0368 §6.1.2 "System reset", RCC_CSR description).
    pub fn system_reset(&mut self) {
        let flags = self.reset_flags;
        let last = self.last;
        let (hse_dead, pll_dead) = (self.hse_dead, self.pll_dead);
        *self = Rcc::new();
        self.reset_flags = flags;
        self.last = last;
        self.hse_dead = hse_dead;
        self.pll_dead = pll_dead;
        // The oscillator restarts at reset; the CPU only runs once HSI is ready.
        self.hsi_ready_at = Some(last);
    }

    /// A power-on reset: everything back to power-on, the reset flags too (the injected HSE
    /// and PLL faults stay: they are the board's and the chip's).
    pub fn power_on_reset(&mut self) {
        let last = self.last;
        let (hse_dead, pll_dead) = (self.hse_dead, self.pll_dead);
        *self = Rcc::new();
        self.last = last;
        self.hse_dead = hse_dead;
        self.pll_dead = pll_dead;
        self.hsi_ready_at = Some(last);
    }

    /// Records an independent-watchdog reset in CSR; the machine calls this before
    /// [`Rcc::system_reset`]. Sets IWDGRSTF and also PINRSTF: on the F4 every internal reset
    /// source drives the NRST pin low through the reset pulse generator (RM0368 §6.1, figure
    /// "Simplified diagram of the reset circuit"), so the pin-reset flag is set as well.
    pub fn note_watchdog_reset(&mut self) {
        self.reset_flags |= CSR_IWDGRSTF | CSR_PINRSTF;
    }

    /// Records a software reset (SYSRESETREQ) in CSR: SFTRSTF, and PINRSTF as for the watchdog.
    pub fn note_software_reset(&mut self) {
        self.reset_flags |= CSR_SFTRSTF | CSR_PINRSTF;
    }

    /// Makes the HSE crystal dead (a fault injected on the board): HSEON is accepted and
    /// HSERDY never sets, as with a cracked crystal or a missing load capacitor. Survives
    /// resets: it is the board's, not the chip's.
    pub fn set_hse_dead(&mut self, dead: bool) {
        self.hse_dead = dead;
    }

    /// The HSE crystal stops at `now` (a fault injected in flight) and stays dead through
    /// resets. What follows depends on the clock security system (RM0368 §6.2.7, module
    /// documentation): with CSSON and the HSE ready, the switch to the HSI and CSSF; without,
    /// a system clock fed by the HSE is lost.
    pub fn fail_hse(&mut self, now: Time) {
        self.settle(now);
        self.hse_dead = true;
        let Some(ready_at) = self.hse_ready_at else { return };
        let was_running = ready_at <= self.last;
        let pll_from_hse = self.pllcfgr & PLLCFGR_PLLSRC != 0;
        let feeds_sysclk = self.sws == Source::Hse || (self.sws == Source::Pll && pll_from_hse);
        if self.csson && was_running {
            self.hse_ready_at = None;
            self.csson = false;
            self.cssf = true;
            if feeds_sysclk {
                if self.sws == Source::Pll {
                    self.pll_on_at = None;
                }
                self.cfgr &= !0b11;
                self.sws = Source::Hsi;
            }
        } else {
            // HSEON stays as software wrote it; HSERDY (and a PLL fed by it) never comes back.
            self.hse_ready_at = Some(NEVER);
            self.clock_lost |= was_running && feeds_sysclk;
        }
    }

    /// CIR.CSSF: the clock security system's interrupt, wired to the core's NMI.
    pub fn nmi_line(&self) -> bool {
        self.cssf
    }

    /// The system clock is gone (the HSE failed under it with no clock security system): the
    /// core executes nothing until a reset.
    pub fn core_clock_stopped(&self) -> bool {
        self.clock_lost
    }

    /// Makes the PLL dead (a fault injected on the chip): PLLON is accepted and PLLRDY never
    /// sets. Survives resets.
    pub fn set_pll_dead(&mut self, dead: bool) {
        self.pll_dead = dead;
    }

    /// When the LSI is (or will be) running and stable; `None` while it is off. The IWDG
    /// counts on it and moves PR/RLR into its domain with it.
    pub fn lsi_ready_at(&self) -> Option<Time> {
        self.lsi_ready_at
    }

    /// The IWDG's start key forces the LSI on: ST's `HAL_IWDG_Init` relies on it ("LSI is
    /// turned on automatically" by the start key, RM0368 §15.3), and later STM32 manuals say it
    /// outright (once the watchdog is started the LSI is forced on and cannot be disabled).
    /// LSION keeps what software wrote; LSIRDY follows the oscillator.
    pub fn force_lsi_on(&mut self, now: Time) {
        self.lsi_forced = true;
        self.start_lsi(now);
    }

    fn start_lsi(&mut self, now: Time) {
        if self.lsi_ready_at.is_none() {
            self.lsi_ready_at = Some(now + LSI_STARTUP);
        }
    }

    /// The reset flags of CSR (bits 31:25, in place).
    pub fn reset_flags(&self) -> u32 {
        self.reset_flags
    }

    /// Whether the clock of peripheral `bit` on `bus` is enabled (its xENR bit).
    pub fn is_enabled(&self, bus: Bus, bit: u32) -> bool {
        bit < 32 && (self.enr(bus) >> bit) & 1 != 0
    }

    /// Whether peripheral `bit` on `bus` is held in reset (its xRSTR bit is set).
    pub fn in_reset(&self, bus: Bus, bit: u32) -> bool {
        let rstr = match bus {
            Bus::Ahb1 => self.ahb1rstr,
            Bus::Apb1 => self.apb1rstr,
            Bus::Apb2 => self.apb2rstr,
        };
        bit < 32 && (rstr >> bit) & 1 != 0
    }

    /// Peripherals whose xRSTR bit went from 0 to 1 since the last call, in write order.
    pub fn take_reset_pulses(&mut self) -> Vec<(Bus, u32)> {
        std::mem::take(&mut self.pulses)
    }

    /// The next time a ready flag (and so possibly SWS and the clocks) changes by itself.
    pub fn next_event(&self) -> Option<Time> {
        [self.hsi_ready_at, self.hse_ready_at, self.pll_ready_at(), self.lsi_ready_at]
            .into_iter()
            .flatten()
            .filter(|&t| t > self.last && t < NEVER)
            .min()
    }

    /// Brings ready flags and the clock switch up to `now`.
    pub fn advance(&mut self, now: Time) {
        self.settle(now);
    }

    /// The clock frequencies from the current SWS and prescalers (as of the last access or
    /// [`Rcc::advance`]). Errors: a PLL configuration outside RM0368's ranges, SYSCLK above
    /// 84 MHz, PCLK1 above 42 MHz, or a frequency that does not divide the 336 MHz time base.
    pub fn clocks(&self) -> Result<Clocks, Unmodelled> {
        let sysclk = match self.sws {
            Source::Hsi => HSI_HZ,
            Source::Hse => HSE_HZ,
            Source::Pll => self.pll_output()?,
        };
        let err = |what: String| Unmodelled::new("RCC.CFGR", what);
        if sysclk > SYSCLK_MAX_HZ {
            return Err(err(format!("SYSCLK {} MHz above the F401's {} MHz maximum", mhz(sysclk), mhz(SYSCLK_MAX_HZ))));
        }
        let hpre = match (self.cfgr >> 4) & 0xF {
            0..=7 => 1,
            8 => 2,
            9 => 4,
            10 => 8,
            11 => 16,
            12 => 64,
            13 => 128,
            14 => 256,
            _ => 512,
        };
        let ppre = |bits: u32| match bits & 0b111 {
            0..=3 => 1,
            4 => 2,
            5 => 4,
            6 => 8,
            _ => 16,
        };
        let ppre1 = ppre(self.cfgr >> 10);
        let ppre2 = ppre(self.cfgr >> 13);
        let hclk = exact_div(sysclk, hpre, "HCLK")?;
        let pclk1 = exact_div(hclk, ppre1, "PCLK1")?;
        let pclk2 = exact_div(hclk, ppre2, "PCLK2")?;
        if pclk1 > PCLK1_MAX_HZ {
            return Err(err(format!("PCLK1 {} MHz above the F401's {} MHz maximum", mhz(pclk1), mhz(PCLK1_MAX_HZ))));
        }
        if pclk2 > PCLK2_MAX_HZ {
            return Err(err(format!("PCLK2 {} MHz above the F401's {} MHz maximum", mhz(pclk2), mhz(PCLK2_MAX_HZ))));
        }
        // Timer clocks: x1 when the APB prescaler is 1, else x2 (RM0368 §6.2, TIMPRE = 0).
        let tim1 = if ppre1 == 1 { pclk1 } else { 2 * pclk1 };
        let tim2 = if ppre2 == 1 { pclk2 } else { 2 * pclk2 };
        for (name, hz) in
            [("SYSCLK", sysclk), ("HCLK", hclk), ("PCLK1", pclk1), ("PCLK2", pclk2), ("APB1 timer clock", tim1), ("APB2 timer clock", tim2)]
        {
            if units_per_cycle(hz).is_none() {
                return Err(err(format!("{name} = {hz} Hz does not divide the emulator's {} MHz time base", mhz(TIME_HZ))));
            }
        }
        Ok(Clocks { sysclk_hz: sysclk, hclk_hz: hclk, pclk1_hz: pclk1, pclk2_hz: pclk2, tim_apb1_hz: tim1, tim_apb2_hz: tim2 })
    }

    pub fn read(&mut self, offset: u32, now: Time) -> Result<u32, Unmodelled> {
        self.settle(now);
        Ok(match offset {
            CR => self.cr(now),
            PLLCFGR => self.pllcfgr,
            CFGR => self.cfgr | (self.sws.bits() << 2),
            CIR => {
                if self.cssf {
                    CIR_CSSF
                } else {
                    0
                }
            }
            AHB1RSTR => self.ahb1rstr,
            APB1RSTR => self.apb1rstr,
            APB2RSTR => self.apb2rstr,
            AHB1ENR => self.ahb1enr,
            APB1ENR => self.apb1enr,
            APB2ENR => self.apb2enr,
            BDCR => 0,
            CSR => {
                let mut v = self.reset_flags;
                if self.lsion {
                    v |= CSR_LSION;
                }
                if self.lsi_ready_at.is_some_and(|t| t <= now) {
                    v |= CSR_LSIRDY;
                }
                v
            }
            DCKCFGR => 0,
            _ => return Err(Unmodelled::offset(NAME, offset, false)),
        })
    }

    pub fn write(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.settle(now);
        match offset {
            CR => self.write_cr(value, now)?,
            PLLCFGR => {
                check_reset("RCC.PLLCFGR", value, PLLCFGR_FIELDS, PLLCFGR_RESET)?;
                if self.pll_on_at.is_some() && (value ^ self.pllcfgr) & PLLCFGR_FIELDS != 0 {
                    return Err(Unmodelled::new(
                        "RCC.PLLCFGR",
                        format!("write of {value:#010x} while PLLON = 1: RM0368 allows PLLCFGR writes only with the PLL disabled"),
                    ));
                }
                self.pllcfgr = (value & PLLCFGR_FIELDS) | (PLLCFGR_RESET & !PLLCFGR_FIELDS);
            }
            CFGR => {
                check_reset("RCC.CFGR", value, CFGR_FIELDS, 0)?;
                if value & 0b11 == 0b11 {
                    return Err(Unmodelled::new("RCC.CFGR", "SW = 0b11: not allowed (RM0368 RCC_CFGR)"));
                }
                self.cfgr = value & CFGR_FIELDS & !CFGR_SWS;
                self.settle(now);
            }
            CIR => {
                check_reset("RCC.CIR", value, CIR_FLAGS_AND_CLEARS, 0)?;
                if value & CIR_CSSC != 0 {
                    self.cssf = false;
                }
            }
            AHB1RSTR => self.write_rstr(Bus::Ahb1, value)?,
            APB1RSTR => self.write_rstr(Bus::Apb1, value)?,
            APB2RSTR => self.write_rstr(Bus::Apb2, value)?,
            AHB1ENR => {
                check_reset("RCC.AHB1ENR", value, AHB1_FIELDS, AHB1ENR_RESET)?;
                self.ahb1enr = (value & AHB1_FIELDS) | AHB1ENR_RESET;
            }
            APB1ENR => {
                check_reset("RCC.APB1ENR", value, APB1_FIELDS, 0)?;
                self.apb1enr = value & APB1_FIELDS;
            }
            APB2ENR => {
                check_reset("RCC.APB2ENR", value, APB2_FIELDS, 0)?;
                self.apb2enr = value & APB2_FIELDS;
            }
            // LSERDY (bit 1) is read-only; LSE, RTC and backup-domain reset are not modelled.
            BDCR => check_reset("RCC.BDCR", value, 1 << 1, 0)?,
            CSR => {
                check_reset("RCC.CSR", value, CSR_FLAGS | CSR_RMVF | CSR_LSIRDY | CSR_LSION, 0)?;
                self.lsion = value & CSR_LSION != 0;
                if self.lsion || self.lsi_forced {
                    self.start_lsi(now);
                } else {
                    self.lsi_ready_at = None;
                }
                if value & CSR_RMVF != 0 {
                    self.reset_flags = 0;
                }
            }
            DCKCFGR => check_reset("RCC.DCKCFGR", value, 0, 0)?,
            _ => return Err(Unmodelled::offset(NAME, offset, true)),
        }
        Ok(())
    }

    fn enr(&self, bus: Bus) -> u32 {
        match bus {
            Bus::Ahb1 => self.ahb1enr,
            Bus::Apb1 => self.apb1enr,
            Bus::Apb2 => self.apb2enr,
        }
    }

    fn write_rstr(&mut self, bus: Bus, value: u32) -> Result<(), Unmodelled> {
        let (name, fields, reg) = match bus {
            Bus::Ahb1 => ("RCC.AHB1RSTR", AHB1_FIELDS, &mut self.ahb1rstr),
            Bus::Apb1 => ("RCC.APB1RSTR", APB1_FIELDS, &mut self.apb1rstr),
            Bus::Apb2 => ("RCC.APB2RSTR", APB2_FIELDS, &mut self.apb2rstr),
        };
        check_reset(name, value, fields, 0)?;
        let rising = value & !*reg;
        *reg = value & fields;
        for bit in 0..32 {
            if (rising >> bit) & 1 != 0 {
                self.pulses.push((bus, bit));
            }
        }
        Ok(())
    }

    fn cr(&self, now: Time) -> u32 {
        let mut v = CR_HSITRIM_RESET;
        if self.hsi_ready_at.is_some() {
            v |= CR_HSION;
        }
        if self.is_ready(Source::Hsi, now) {
            v |= CR_HSIRDY;
        }
        if self.hse_ready_at.is_some() {
            v |= CR_HSEON;
        }
        if self.is_ready(Source::Hse, now) {
            v |= CR_HSERDY;
        }
        if self.csson {
            v |= CR_CSSON;
        }
        if self.pll_on_at.is_some() {
            v |= CR_PLLON;
        }
        if self.is_ready(Source::Pll, now) {
            v |= CR_PLLRDY;
        }
        v
    }

    fn write_cr(&mut self, value: u32, now: Time) -> Result<(), Unmodelled> {
        // HSITRIM must stay 16, HSEBYP and PLLI2SON 0: not modelled.
        check_reset("RCC.CR", value, CR_READ_ONLY | CR_HSION | CR_HSEON | CR_PLLON | CR_CSSON, CR_RESET)?;
        self.csson = value & CR_CSSON != 0;
        let pll_src_hse = self.pllcfgr & PLLCFGR_PLLSRC != 0;
        let pll_is_sys = self.sws == Source::Pll;

        // PLLON "cannot be reset if the PLL clock is used as the system clock" (RM0368 RCC_CR).
        if value & CR_PLLON == 0 && self.pll_on_at.is_some() && !pll_is_sys {
            self.pll_on_at = None;
        }
        let pll_on = self.pll_on_at.is_some() || value & CR_PLLON != 0;

        // HSION "cannot be cleared if the HSI is used directly or indirectly as the system clock".
        if value & CR_HSION == 0 && self.hsi_ready_at.is_some() {
            let used = self.sws == Source::Hsi || (pll_is_sys && !pll_src_hse);
            if !used {
                if pll_on && !pll_src_hse {
                    return Err(Unmodelled::new("RCC.CR", "HSION cleared while the PLL runs from the HSI: not modelled"));
                }
                self.hsi_ready_at = None;
            }
        } else if value & CR_HSION != 0 && self.hsi_ready_at.is_none() {
            self.hsi_ready_at = Some(now + HSI_STARTUP);
        }

        // HSEON "cannot be reset if the HSE oscillator is used directly or indirectly as the
        // system clock".
        if value & CR_HSEON == 0 && self.hse_ready_at.is_some() {
            let used = self.sws == Source::Hse || (pll_is_sys && pll_src_hse);
            if !used {
                if pll_on && pll_src_hse {
                    return Err(Unmodelled::new("RCC.CR", "HSEON cleared while the PLL runs from the HSE: not modelled"));
                }
                self.hse_ready_at = None;
            }
        } else if value & CR_HSEON != 0 && self.hse_ready_at.is_none() {
            self.hse_ready_at = Some(if self.hse_dead { NEVER } else { now + HSE_STARTUP });
        }

        if value & CR_PLLON != 0 && self.pll_on_at.is_none() {
            // A PLL configured outside RM0368's ranges does not lock reliably: report it here.
            self.pll_output()?;
            self.pll_on_at = Some(now);
        }
        self.settle(now);
        Ok(())
    }

    fn pll_ready_at(&self) -> Option<Time> {
        let on = self.pll_on_at?;
        if self.pll_dead {
            return None;
        }
        let input = if self.pllcfgr & PLLCFGR_PLLSRC != 0 { self.hse_ready_at? } else { self.hsi_ready_at? };
        Some(on.max(input) + PLL_LOCK)
    }

    fn is_ready(&self, source: Source, now: Time) -> bool {
        let at = match source {
            Source::Hsi => self.hsi_ready_at,
            Source::Hse => self.hse_ready_at,
            Source::Pll => self.pll_ready_at(),
        };
        at.is_some_and(|t| t <= now)
    }

    /// Applies the clock switch: SWS follows SW once the selected source is ready (RM0368
    /// RCC_CFGR and §6.2 "System clock (SYSCLK) selection": "the switch occurs when the clock source becomes ready").
    fn settle(&mut self, now: Time) {
        self.last = self.last.max(now);
        let target = match self.cfgr & 0b11 {
            0 => Source::Hsi,
            1 => Source::Hse,
            _ => Source::Pll,
        };
        if target != self.sws && self.is_ready(target, self.last) {
            self.sws = target;
        }
    }

    /// The main PLL's P output (SYSCLK when selected) from PLLCFGR, checked against RM0368
    /// RCC_PLLCFGR: PLLM 2..63, PLLN 2..432, VCO input 1..2 MHz, VCO output 192..432 MHz.
    fn pll_output(&self) -> Result<u64, Unmodelled> {
        let err = |what: String| Unmodelled::new("RCC.PLLCFGR", what);
        let m = u64::from(self.pllcfgr & 0x3F);
        let n = u64::from((self.pllcfgr >> 6) & 0x1FF);
        let p = 2 * (u64::from((self.pllcfgr >> 16) & 0b11) + 1);
        let input = if self.pllcfgr & PLLCFGR_PLLSRC != 0 { HSE_HZ } else { HSI_HZ };
        if m < 2 {
            return Err(err(format!("PLLM = {m}: wrong configuration (RM0368: 2 <= PLLM <= 63)")));
        }
        if !(2..=432).contains(&n) {
            return Err(err(format!("PLLN = {n}: wrong configuration (RM0368: 2 <= PLLN <= 432)")));
        }
        if input < 1_000_000 * m || input > 2_000_000 * m {
            return Err(err(format!(
                "VCO input {} / {m} = {:.3} MHz outside RM0368's 1..2 MHz",
                mhz(input),
                input as f64 / m as f64 / 1e6
            )));
        }
        if (input * n) % m != 0 {
            return Err(err(format!("VCO frequency {} x {n} / {m} is not a whole number of Hz", mhz(input))));
        }
        let vco = input * n / m;
        if !(192_000_000..=432_000_000).contains(&vco) {
            return Err(err(format!("VCO output {} MHz outside the F401's 192..432 MHz", mhz(vco))));
        }
        exact_div(vco, p, "PLL output")
    }
}

/// `hz / div`, an error naming the clock when it is not a whole number of Hz.
fn exact_div(hz: u64, div: u64, name: &str) -> Result<u64, Unmodelled> {
    if hz % div == 0 {
        Ok(hz / div)
    } else {
        Err(Unmodelled::new("RCC.CFGR", format!("{name} = {} MHz / {div} is not a whole number of Hz", mhz(hz))))
    }
}

/// A frequency in MHz for messages (`84`, `10.5`).
fn mhz(hz: u64) -> String {
    let s = format!("{:.6}", hz as f64 / 1e6);
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

impl Peripheral for Rcc {
    fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        Rcc::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: Clocks) -> Result<(), Unmodelled> {
        Rcc::write(self, offset, value, now)
    }

    fn next_event(&self) -> Option<Time> {
        Rcc::next_event(self)
    }

    fn advance(&mut self, now: Time, _clocks: Clocks) {
        Rcc::advance(self, now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US: Time = TIME_HZ / 1_000_000;

    /// The board's clock tree: HSE 16 MHz, M=8, N=168, P=4 (VCO 336 MHz), SYSCLK 84 MHz.
    const PLLCFGR_84MHZ: u32 = 0x2400_0000 | PLLCFGR_PLLSRC | (7 << 24) | (1 << 16) | (168 << 6) | 8;

    fn read(rcc: &mut Rcc, offset: u32, now: Time) -> u32 {
        rcc.read(offset, now).expect("modelled register")
    }

    #[test]
    fn reset_values_match_the_svd() {
        let mut rcc = Rcc::new();
        assert_eq!(read(&mut rcc, CR, 0), 0x0000_0083);
        assert_eq!(read(&mut rcc, PLLCFGR, 0), 0x2400_3010);
        assert_eq!(read(&mut rcc, CFGR, 0), 0);
        assert_eq!(read(&mut rcc, AHB1ENR, 0), 0x0010_0000);
        assert_eq!(read(&mut rcc, APB1ENR, 0), 0);
        assert_eq!(read(&mut rcc, APB2ENR, 0), 0);
        assert_eq!(read(&mut rcc, CSR, 0), 0x0E00_0000);
        assert_eq!(CSR_POWER_ON, 0x0E00_0000);
        assert_eq!(rcc.clocks(), Ok(Clocks::RESET));
    }

    #[test]
    fn hserdy_sets_a_startup_time_after_hseon() {
        let mut rcc = Rcc::new();
        rcc.write(CR, 0x83 | CR_HSEON, 1000).unwrap();
        assert_eq!(read(&mut rcc, CR, 1000) & (CR_HSEON | CR_HSERDY), CR_HSEON);
        assert_eq!(rcc.next_event(), Some(1000 + HSE_STARTUP));
        assert_eq!(read(&mut rcc, CR, 1000 + HSE_STARTUP - 1) & CR_HSERDY, 0);
        assert_eq!(read(&mut rcc, CR, 1000 + HSE_STARTUP) & CR_HSERDY, CR_HSERDY);
        assert_eq!(rcc.next_event(), None);
    }

    #[test]
    fn pll_locks_a_lock_time_after_its_input_is_ready() {
        let mut rcc = Rcc::new();
        rcc.write(PLLCFGR, PLLCFGR_84MHZ, 0).unwrap();
        // PLLON together with HSEON: the PLL waits for the crystal, then locks.
        rcc.write(CR, 0x83 | CR_HSEON | CR_PLLON, 0).unwrap();
        assert_eq!(read(&mut rcc, CR, HSE_STARTUP) & CR_PLLRDY, 0);
        assert_eq!(read(&mut rcc, CR, HSE_STARTUP + PLL_LOCK - 1) & CR_PLLRDY, 0);
        assert_eq!(read(&mut rcc, CR, HSE_STARTUP + PLL_LOCK) & CR_PLLRDY, CR_PLLRDY);
    }

    #[test]
    fn sws_follows_sw_only_once_the_source_is_ready() {
        let mut rcc = Rcc::new();
        rcc.write(PLLCFGR, PLLCFGR_84MHZ, 0).unwrap();
        rcc.write(CR, 0x83 | CR_HSEON, 0).unwrap();
        rcc.write(CR, 0x83 | CR_HSEON | CR_PLLON, 10).unwrap();
        rcc.write(CFGR, (0b100 << 10) | 0b10, 20).unwrap();
        assert_eq!(read(&mut rcc, CFGR, 20) & CFGR_SWS, 0, "PLL not ready: still on HSI");
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, HSI_HZ);
        let ready = HSE_STARTUP + PLL_LOCK;
        assert_eq!(rcc.next_event(), Some(HSE_STARTUP));
        rcc.advance(ready);
        assert_eq!(read(&mut rcc, CFGR, ready) & CFGR_SWS, 0b10 << 2);
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, 84_000_000);
    }

    #[test]
    fn board_configuration_gives_84_42_84_mhz() {
        let mut rcc = Rcc::new();
        rcc.write(PLLCFGR, PLLCFGR_84MHZ, 0).unwrap();
        rcc.write(CR, 0x83 | CR_HSEON, 0).unwrap();
        rcc.write(CR, 0x83 | CR_HSEON | CR_PLLON, HSE_STARTUP).unwrap();
        let t = HSE_STARTUP + PLL_LOCK;
        // PPRE2 = /1, PPRE1 = /2 (0b100), HPRE = /1, then SW = PLL.
        rcc.write(CFGR, 0b100 << 10, t).unwrap();
        rcc.write(CFGR, (0b100 << 10) | 0b10, t).unwrap();
        let clocks = rcc.clocks().unwrap();
        assert_eq!(clocks, Clocks::PLL_84_MHZ);
    }

    #[test]
    fn pclk1_above_42_mhz_is_an_error() {
        let mut rcc = Rcc::new();
        rcc.write(PLLCFGR, PLLCFGR_84MHZ, 0).unwrap();
        rcc.write(CR, 0x83 | CR_HSEON | CR_PLLON, 0).unwrap();
        rcc.write(CFGR, 0b10, HSE_STARTUP + PLL_LOCK).unwrap();
        let e = rcc.clocks().unwrap_err();
        assert!(e.what.contains("PCLK1 84 MHz above"), "{e}");
    }

    #[test]
    fn sysclk_above_84_mhz_is_an_error() {
        let mut rcc = Rcc::new();
        // M=8, N=168, P=2: VCO 336 MHz, SYSCLK 168 MHz (an F407 setting).
        rcc.write(PLLCFGR, PLLCFGR_84MHZ & !(0b11 << 16), 0).unwrap();
        rcc.write(CR, 0x83 | CR_HSEON | CR_PLLON, 0).unwrap();
        rcc.write(CFGR, (0b101 << 10) | (0b100 << 13) | 0b10, HSE_STARTUP + PLL_LOCK).unwrap();
        let e = rcc.clocks().unwrap_err();
        assert!(e.what.contains("SYSCLK 168 MHz above"), "{e}");
    }

    #[test]
    fn pll_vco_input_outside_1_to_2_mhz_is_an_error_at_pllon() {
        let mut rcc = Rcc::new();
        // M=4 from the 16 MHz HSE: 4 MHz VCO input.
        rcc.write(PLLCFGR, (PLLCFGR_84MHZ & !0x3F) | 4, 0).unwrap();
        let e = rcc.write(CR, 0x83 | CR_HSEON | CR_PLLON, 0).unwrap_err();
        assert!(e.what.contains("VCO input"), "{e}");
    }

    #[test]
    fn pll_vco_output_outside_192_to_432_mhz_is_an_error_at_pllon() {
        let mut rcc = Rcc::new();
        // M=16, N=168: 1 MHz x 168 = 168 MHz VCO.
        rcc.write(PLLCFGR, (PLLCFGR_84MHZ & !0x3F) | 16, 0).unwrap();
        let e = rcc.write(CR, 0x83 | CR_PLLON, 0).unwrap_err();
        assert!(e.what.contains("VCO output 168 MHz"), "{e}");
    }

    #[test]
    fn pllcfgr_write_while_pll_on_is_an_error() {
        let mut rcc = Rcc::new();
        rcc.write(PLLCFGR, PLLCFGR_84MHZ, 0).unwrap();
        rcc.write(CR, 0x83 | CR_HSEON | CR_PLLON, 0).unwrap();
        assert!(rcc.write(PLLCFGR, PLLCFGR_84MHZ, 10).is_ok(), "same value is harmless");
        assert!(rcc.write(PLLCFGR, PLLCFGR_84MHZ ^ (1 << 6), 10).is_err());
    }

    #[test]
    fn pllcfgr_reserved_bit_29_must_keep_its_reset_value() {
        let mut rcc = Rcc::new();
        assert!(rcc.write(PLLCFGR, PLLCFGR_84MHZ & !(1 << 29), 0).is_err());
    }

    #[test]
    fn mco_and_rtcpre_are_unmodelled_unless_at_reset_value() {
        let mut rcc = Rcc::new();
        assert!(rcc.write(CFGR, 0, 0).is_ok());
        assert!(rcc.write(CFGR, 0b11 << 21, 0).is_err(), "MCO1");
        assert!(rcc.write(CFGR, 2 << 16, 0).is_err(), "RTCPRE");
        assert!(rcc.write(CFGR, 0b11, 0).is_err(), "SW = 11");
    }

    #[test]
    fn hse_cannot_be_stopped_while_it_is_the_system_clock() {
        let mut rcc = Rcc::new();
        rcc.write(CR, 0x83 | CR_HSEON, 0).unwrap();
        rcc.write(CFGR, 0b01, HSE_STARTUP).unwrap();
        rcc.write(CR, 0x83, HSE_STARTUP + 10).unwrap();
        assert_eq!(read(&mut rcc, CR, HSE_STARTUP + 10) & CR_HSEON, CR_HSEON);
        // HSI can be stopped now (it is no longer the system clock).
        rcc.write(CR, CR_HSITRIM_RESET | CR_HSEON, HSE_STARTUP + 20).unwrap();
        assert_eq!(read(&mut rcc, CR, HSE_STARTUP + 20) & (CR_HSION | CR_HSIRDY), 0);
    }

    #[test]
    fn hsebyp_is_unmodelled() {
        let mut rcc = Rcc::new();
        assert!(rcc.write(CR, 0x83 | (1 << 18), 0).is_err());
        // Read-only ready flags and HSICAL written back by a read-modify-write are ignored.
        assert!(rcc.write(CR, 0x83 | CR_HSERDY | 0xFF00, 0).is_ok());
    }

    #[test]
    fn reset_flags_survive_a_system_reset_and_rmvf_clears_them() {
        let mut rcc = Rcc::new();
        rcc.write(CSR, CSR_RMVF, 0).unwrap();
        assert_eq!(read(&mut rcc, CSR, 0), 0);
        rcc.write(APB2ENR, 1 << 4, 0).unwrap();
        rcc.note_watchdog_reset();
        rcc.system_reset();
        assert_eq!(read(&mut rcc, CSR, 5) & CSR_FLAGS, CSR_IWDGRSTF | CSR_PINRSTF);
        assert!(!rcc.is_enabled(Bus::Apb2, 4), "enables reset");
        assert_eq!(read(&mut rcc, CR, 5), 0x83);
        // Writing the flags does nothing; RMVF clears them.
        rcc.write(CSR, CSR_PORRSTF, 5).unwrap();
        assert_eq!(read(&mut rcc, CSR, 5) & CSR_FLAGS, CSR_IWDGRSTF | CSR_PINRSTF);
        rcc.write(CSR, CSR_RMVF, 5).unwrap();
        assert_eq!(read(&mut rcc, CSR, 5) & CSR_FLAGS, 0);
    }

    #[test]
    fn enables_are_reported_per_bus() {
        let mut rcc = Rcc::new();
        rcc.write(APB2ENR, (1 << 4) | (1 << 8), 0).unwrap();
        rcc.write(AHB1ENR, AHB1ENR_RESET | 0b111, 0).unwrap();
        assert!(rcc.is_enabled(Bus::Apb2, 4));
        assert!(rcc.is_enabled(Bus::Apb2, 8));
        assert!(!rcc.is_enabled(Bus::Apb1, 4));
        assert!(rcc.is_enabled(Bus::Ahb1, 2));
        assert!(!rcc.is_enabled(Bus::Ahb1, 40));
        assert!(rcc.write(APB2ENR, 1 << 1, 0).is_err(), "reserved bit");
    }

    #[test]
    fn reset_pulses_are_reported_once_per_rising_edge() {
        let mut rcc = Rcc::new();
        rcc.write(APB2RSTR, 1 << 4, 0).unwrap();
        assert!(rcc.in_reset(Bus::Apb2, 4));
        rcc.write(APB2RSTR, 1 << 4, 1).unwrap();
        rcc.write(APB2RSTR, 0, 2).unwrap();
        assert!(!rcc.in_reset(Bus::Apb2, 4));
        rcc.write(AHB1RSTR, 0b11, 3).unwrap();
        assert_eq!(rcc.take_reset_pulses(), vec![(Bus::Apb2, 4), (Bus::Ahb1, 0), (Bus::Ahb1, 1)]);
        assert!(rcc.take_reset_pulses().is_empty());
    }

    #[test]
    fn lsirdy_follows_lsion_after_startup() {
        let mut rcc = Rcc::new();
        rcc.write(CSR, CSR_LSION, 100 * US).unwrap();
        assert_eq!(read(&mut rcc, CSR, 100 * US) & 0b11, CSR_LSION);
        assert_eq!(read(&mut rcc, CSR, 100 * US + LSI_STARTUP) & 0b11, CSR_LSION | CSR_LSIRDY);
    }

    /// Rule: the LSI is off after reset (CSR reset value 0x0E00_0000, LSION = 0); only LSION or
    /// the IWDG's start key turn it on (RM0368 §6.2.5, §17.3.2).
    #[test]
    fn the_lsi_is_off_after_reset_and_the_watchdog_start_forces_it_on() {
        let mut rcc = Rcc::new();
        assert_eq!(read(&mut rcc, CSR, 10 * US) & 0b11, 0, "LSI off at power-on");
        assert_eq!(rcc.lsi_ready_at(), None);
        rcc.force_lsi_on(20 * US);
        assert_eq!(rcc.lsi_ready_at(), Some(20 * US + LSI_STARTUP));
        assert_eq!(read(&mut rcc, CSR, 20 * US + LSI_STARTUP) & 0b11, CSR_LSIRDY, "LSION keeps software's value");
        // Software cannot stop a forced LSI.
        rcc.write(CSR, 0, 30 * US + LSI_STARTUP).unwrap();
        assert_eq!(rcc.lsi_ready_at(), Some(20 * US + LSI_STARTUP));
        // A system reset stops it (the IWDG is reset too).
        rcc.system_reset();
        assert_eq!(rcc.lsi_ready_at(), None);
        // Without the force, clearing LSION stops it.
        rcc.write(CSR, CSR_LSION, 40 * US).unwrap();
        rcc.write(CSR, 0, 50 * US).unwrap();
        assert_eq!(rcc.lsi_ready_at(), None);
    }

    /// A dead crystal: HSEON is taken, HSERDY never comes, and neither does a PLL fed by it;
    /// the HSI keeps the chip running.
    #[test]
    fn a_dead_crystal_never_sets_hserdy() {
        let mut rcc = Rcc::new();
        rcc.set_hse_dead(true);
        rcc.write(CR, CR_RESET | CR_HSEON, 0).unwrap();
        let much_later = 1000 * HSE_STARTUP;
        assert_eq!(read(&mut rcc, CR, much_later) & (CR_HSEON | CR_HSERDY), CR_HSEON);
        assert_eq!(rcc.next_event(), None, "no oscillator event ever comes");
        rcc.system_reset();
        rcc.write(CR, CR_RESET | CR_HSEON, much_later).unwrap();
        assert_eq!(read(&mut rcc, CR, 2 * much_later) & CR_HSERDY, 0, "still dead after a reset");
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, HSI_HZ);
    }

    /// The injected faults are the board's crystal and the chip's PLL: a power cut and the
    /// power-on after it keep them.
    #[test]
    fn a_power_on_reset_keeps_the_injected_clock_faults() {
        let mut rcc = Rcc::new();
        rcc.set_hse_dead(true);
        rcc.set_pll_dead(true);
        rcc.power_on_reset();
        rcc.write(CR, CR_RESET | CR_HSEON | CR_PLLON, 0).unwrap();
        let much_later = 1000 * PLL_LOCK;
        assert_eq!(read(&mut rcc, CR, much_later) & (CR_HSERDY | CR_PLLRDY), 0);
    }

    #[test]
    fn a_dead_pll_never_sets_pllrdy_and_sysclk_cannot_switch_to_it() {
        let mut rcc = Rcc::new();
        rcc.set_pll_dead(true);
        rcc.write(CR, CR_RESET | CR_PLLON, 0).unwrap();
        let much_later = 1000 * PLL_LOCK;
        assert_eq!(read(&mut rcc, CR, much_later) & CR_PLLRDY, 0);
        rcc.system_reset();
        rcc.write(CR, CR_RESET | CR_PLLON, much_later).unwrap();
        assert_eq!(read(&mut rcc, CR, 2 * much_later) & CR_PLLRDY, 0, "still dead after a reset");
        // SW = PLL is accepted, SWS stays on the HSI: the clock never switches.
        rcc.write(CFGR, 0b10, 2 * much_later).unwrap();
        assert_eq!(read(&mut rcc, CFGR, 3 * much_later) & 0b1100, 0);
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, HSI_HZ);
    }

    /// The board running from the crystal through the PLL at 84 MHz; returns since when.
    fn on_the_crystal(rcc: &mut Rcc, csson: bool) -> Time {
        rcc.write(PLLCFGR, PLLCFGR_84MHZ, 0).unwrap();
        let css = if csson { CR_CSSON } else { 0 };
        rcc.write(CR, CR_RESET | CR_HSEON | CR_PLLON | css, 0).unwrap();
        // PPRE1 /2 keeps PCLK1 at 42 MHz.
        rcc.write(CFGR, 0b10 | (0b100 << 10), 0).unwrap();
        let running = HSE_STARTUP + PLL_LOCK;
        rcc.advance(running);
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, 84_000_000);
        assert_eq!(read(rcc, CR, running) & CR_CSSON, css);
        running
    }

    /// Rule (RM0368 §6.2.7): with CSSON, a failed crystal turns the HSE and the PLL it feeds
    /// off, switches SYSCLK to the HSI, and raises CSSF (the NMI) until CSSC clears it.
    #[test]
    fn a_crystal_failure_under_the_clock_security_system_switches_to_the_hsi_and_raises_the_nmi() {
        let mut rcc = Rcc::new();
        let t = on_the_crystal(&mut rcc, true) + 1000;
        rcc.advance(t);
        rcc.fail_hse(t);
        assert!(rcc.nmi_line(), "CSSF");
        assert!(!rcc.core_clock_stopped());
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, HSI_HZ, "SYSCLK on the HSI");
        assert_eq!(read(&mut rcc, CFGR, t) & 0b1111, 0, "SW and SWS = HSI");
        assert_eq!(read(&mut rcc, CR, t) & (CR_HSEON | CR_HSERDY | CR_CSSON | CR_PLLON | CR_PLLRDY), 0);
        assert_eq!(read(&mut rcc, CIR, t), CIR_CSSF);
        rcc.write(CIR, CIR_CSSC, t + 10).unwrap();
        assert!(!rcc.nmi_line(), "CSSC clears CSSF");
        assert_eq!(read(&mut rcc, CIR, t + 10), 0);
        // The crystal stays dead through a reset; the reset clears the detector's state.
        rcc.system_reset();
        assert!(!rcc.nmi_line() && !rcc.core_clock_stopped());
        rcc.write(CR, CR_RESET | CR_HSEON, t + 20).unwrap();
        assert_eq!(read(&mut rcc, CR, t + 20 + 10 * HSE_STARTUP) & CR_HSERDY, 0);
    }

    /// Without the clock security system, the same failure takes the system clock away: no NMI,
    /// and the core stops (until the watchdog's reset).
    #[test]
    fn a_crystal_failure_without_the_clock_security_system_stops_the_core() {
        let mut rcc = Rcc::new();
        let t = on_the_crystal(&mut rcc, false) + 1000;
        rcc.advance(t);
        rcc.fail_hse(t);
        assert!(!rcc.nmi_line());
        assert!(rcc.core_clock_stopped());
        assert_eq!(read(&mut rcc, CR, t) & (CR_HSERDY | CR_PLLRDY), 0);
        rcc.system_reset();
        assert!(!rcc.core_clock_stopped(), "a reset starts again on the HSI");
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, HSI_HZ);
    }

    /// A crystal that fails while the HSI is the system clock stops nothing.
    #[test]
    fn a_crystal_failure_off_the_system_clock_leaves_the_core_running() {
        let mut rcc = Rcc::new();
        rcc.write(CR, CR_RESET | CR_HSEON, 0).unwrap();
        rcc.advance(HSE_STARTUP);
        rcc.fail_hse(HSE_STARTUP);
        assert!(!rcc.core_clock_stopped() && !rcc.nmi_line());
        assert_eq!(rcc.clocks().unwrap().sysclk_hz, HSI_HZ);
    }

    #[test]
    fn unmodelled_offsets_are_errors() {
        let mut rcc = Rcc::new();
        assert!(rcc.read(0x50, 0).is_err(), "AHB1LPENR");
        assert!(rcc.write(0x34, 0, 0).is_err(), "AHB2ENR");
        assert!(rcc.write(BDCR, 1, 0).is_err(), "LSEON");
    }
}
