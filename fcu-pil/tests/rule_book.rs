//! The rule book: the register sequences the firmware relies on, played on the board's peripheral
//! models (no firmware image), each rule both ways: the sequence the vendor's reference code
//! writes, and the wrong one a real bug would write, expecting what the chip does with it.
//!
//! Each test names the reference-manual section (RM0368, the STM32F401's; RM0090 for the blocks
//! the F401 shares with the F405/F407) and the vendor sequence it follows (ST's HAL/LL or the
//! stm32f4xx-hal 0.23 code path the firmware goes through). `fcu-pil/RULES.md` is the index:
//! every test here is listed there, and every test listed there exists (checked below).
//!
//! Where the chip's answer to a wrong sequence is undefined or unspecified (a register access with
//! the peripheral's clock off reads 0 and drops writes; an out-of-spec ADC clock converts with no
//! guaranteed accuracy; too few flash wait states fetch wrong instructions), the models refuse it:
//! the run stops with an [`Unmodelled`] error naming the register, so the defect cannot pass as a
//! flight. The tests below say which rules are refusals.

use std::collections::HashMap;

use fcu_pil::board::Board;
use fcu_pil::machine::Peripherals;
use fcu_pil::periph::{irq, Time, Unmodelled, TIME_HZ};

const US: Time = TIME_HZ / 1_000_000;
const MS: Time = TIME_HZ / 1000;
/// Time between two register accesses of the bench (one 16 MHz cycle; an access at 84 MHz is
/// shorter, which only matters for timing the tests do not assert).
const STEP: Time = 21;

// Register addresses (RM0368 §2.3 memory map and the register maps of each chapter).
const RCC: u32 = 0x4002_3800;
const RCC_CR: u32 = RCC;
const RCC_PLLCFGR: u32 = RCC + 0x04;
const RCC_CFGR: u32 = RCC + 0x08;
const RCC_AHB1ENR: u32 = RCC + 0x30;
const RCC_APB1ENR: u32 = RCC + 0x40;
const RCC_APB2ENR: u32 = RCC + 0x44;
const FLASH_ACR: u32 = 0x4002_3C00;
const GPIO: [u32; 3] = [0x4002_0000, 0x4002_0400, 0x4002_0800];
const MODER: u32 = 0x00;
const PUPDR: u32 = 0x0C;
const IDR: u32 = 0x10;
const ODR: u32 = 0x14;
const BSRR: u32 = 0x18;
const AFRL: u32 = 0x20;
const AFRH: u32 = 0x24;
const TIM2: u32 = 0x4000_0000;
const TIM4: u32 = 0x4000_0800;
const TIM9: u32 = 0x4001_4000;
const CR1: u32 = 0x00;
const DIER: u32 = 0x0C;
const SR: u32 = 0x10;
const EGR: u32 = 0x14;
const CCMR1: u32 = 0x18;
const CCMR2: u32 = 0x1C;
const CCER: u32 = 0x20;
const CNT: u32 = 0x24;
const PSC: u32 = 0x28;
const ARR: u32 = 0x2C;
const CCR1: u32 = 0x34;
const SPI2: u32 = 0x4000_3800;
const USART1: u32 = 0x4001_1000;
const ADC1: u32 = 0x4001_2000;
const ADC_CCR: u32 = 0x4001_2304;
const PWR: u32 = 0x4000_7000;
const IWDG: u32 = 0x4000_3000;
const DBGMCU: u32 = 0xE004_2000;

// Ports as the board indexes them.
const PA: usize = 0;
const PB: usize = 1;
const PC: usize = 2;

/// The board's peripherals, driven register by register the way firmware would, with time moving
/// on a step per access.
struct Bench {
    board: Board,
    t: Time,
    lines: HashMap<u32, bool>,
    watchdog_resets: u32,
}

impl Bench {
    /// Power-on state: 16 MHz HSI, every peripheral clock off.
    fn new() -> Bench {
        Bench { board: Board::new(), t: 0, lines: HashMap::new(), watchdog_resets: 0 }
    }

    /// The clocks the firmware runs on, set up as stm32f4xx-hal 0.23 `Rcc::freeze` does
    /// (`rcc/f4/mod.rs`): FLASH_ACR first (LATENCY 2, prefetch and caches), HSE on and ready,
    /// PLL (M 8, N 168, P 4, Q 7 from the 16 MHz HSE) on and locked, APB1 /2, then SW = PLL.
    fn at_84_mhz() -> Bench {
        let mut b = Bench::new();
        b.modify(FLASH_ACR, 0xF, 2 | flash::ACR_PRFTEN | flash::ACR_ICEN | flash::ACR_DCEN);
        b.start_pll();
        b.modify(RCC_CFGR, 0xFCF0, rcc::PPRE1_DIV2);
        b.try_modify(RCC_CFGR, 0b11, rcc::SW_PLL).unwrap_or_else(|e| panic!("switch to the PLL: {e}"));
        b.wait_for(RCC_CFGR, rcc::SWS_PLL);
        b
    }

    /// HSE on and ready, then the PLL configured and locked (not yet the system clock).
    fn start_pll(&mut self) {
        self.modify(RCC_CR, 0, rcc::HSEON);
        self.wait_for(RCC_CR, rcc::HSERDY);
        self.modify(RCC_PLLCFGR, rcc::PLLCFGR_FIELDS, rcc::PLLCFGR_84_MHZ);
        self.modify(RCC_CR, 0, rcc::PLLON);
        self.wait_for(RCC_CR, rcc::PLLRDY);
    }

    fn step(&mut self) -> Time {
        self.t += STEP;
        self.t
    }

    fn try_write(&mut self, addr: u32, value: u32) -> Result<(), Unmodelled> {
        let t = self.step();
        self.board.write(addr, 4, value, t)
    }

    fn try_read(&mut self, addr: u32) -> Result<u32, Unmodelled> {
        let t = self.step();
        self.board.read(addr, 4, t)
    }

    fn write(&mut self, addr: u32, value: u32) {
        self.try_write(addr, value).unwrap_or_else(|e| panic!("write {value:#x} to {addr:#010x}: {e}"));
    }

    fn read(&mut self, addr: u32) -> u32 {
        self.try_read(addr).unwrap_or_else(|e| panic!("read of {addr:#010x}: {e}"))
    }

    fn try_modify(&mut self, addr: u32, clear: u32, set: u32) -> Result<(), Unmodelled> {
        let v = self.try_read(addr)?;
        self.try_write(addr, (v & !clear) | set)
    }

    fn modify(&mut self, addr: u32, clear: u32, set: u32) {
        self.try_modify(addr, clear, set).unwrap_or_else(|e| panic!("modify of {addr:#010x}: {e}"));
    }

    /// Brings the models to `t`, event by event, recording the interrupt lines and resetting the
    /// board when the watchdog expires (as the machine does).
    fn run_to(&mut self, t: Time) {
        loop {
            let due = self.board.next_event().filter(|&e| e > self.t && e < t);
            self.t = due.unwrap_or(t).max(self.t);
            let lines = &mut self.lines;
            let expired = self.board.advance(self.t, &mut |n, level| {
                lines.insert(n, level);
            });
            if expired.unwrap_or_else(|e| panic!("advance to {}: {e}", self.t)) {
                self.watchdog_resets += 1;
                self.board.system_reset(true);
            }
            if due.is_none() {
                return;
            }
        }
    }

    fn wait(&mut self, dt: Time) {
        self.run_to(self.t + dt);
    }

    /// Polls `addr` until every bit of `mask` is set (1 µs between polls, 10 ms at most).
    fn wait_for(&mut self, addr: u32, mask: u32) {
        for _ in 0..10_000 {
            if self.read(addr) & mask == mask {
                return;
            }
            self.wait(US);
        }
        panic!("{mask:#x} never set in {addr:#010x}");
    }

    /// Polls `addr` until every bit of `mask` is clear.
    fn wait_clear(&mut self, addr: u32, mask: u32) {
        for _ in 0..10_000 {
            if self.read(addr) & mask == 0 {
                return;
            }
            self.wait(US);
        }
        panic!("{mask:#x} never cleared in {addr:#010x}");
    }

    fn line(&self, n: u32) -> bool {
        self.lines.get(&n).copied().unwrap_or(false)
    }

    /// The HAL's `Enable::enable` (`rcc/f4/enable.rs`): the xENR bit set (bit-band), then DSB.
    fn enable(&mut self, enr: u32, bit: u32) {
        self.modify(enr, 0, 1 << bit);
    }

    fn gpio_enable(&mut self) {
        for bit in 0..3 {
            self.enable(RCC_AHB1ENR, bit);
        }
    }

    /// stm32f4xx-hal `into_alternate::<AF>()` (`gpio/convert.rs`, `change_mode!`): AFRL/AFRH
    /// first, then MODER = alternate, so the pin never sits in AF mode on another function.
    fn pin_to_alternate(&mut self, port: usize, pin: u32, af: u32) {
        self.set_af(port, pin, af);
        self.set_mode(port, pin, 0b10);
    }

    fn set_af(&mut self, port: usize, pin: u32, af: u32) {
        let (reg, shift) = if pin < 8 { (AFRL, 4 * pin) } else { (AFRH, 4 * (pin - 8)) };
        self.modify(GPIO[port] + reg, 0xF << shift, af << shift);
    }

    fn set_mode(&mut self, port: usize, pin: u32, mode: u32) {
        self.modify(GPIO[port] + MODER, 0b11 << (2 * pin), mode << (2 * pin));
    }

    /// stm32f4xx-hal `into_push_pull_output_in_state(High)`: the level in BSRR first, then MODER.
    fn pin_to_output_high(&mut self, port: usize, pin: u32) {
        self.write(GPIO[port] + BSRR, 1 << pin);
        self.set_mode(port, pin, 0b01);
    }

    fn pin_low(&mut self, (port, pin): (usize, u32)) {
        self.write(GPIO[port] + BSRR, 1 << (pin + 16));
    }

    fn pin_high(&mut self, (port, pin): (usize, u32)) {
        self.write(GPIO[port] + BSRR, 1 << pin);
    }
}

/// FLASH_ACR fields (RM0368 §3.8.1).
mod flash {
    pub const ACR_PRFTEN: u32 = 1 << 8;
    pub const ACR_ICEN: u32 = 1 << 9;
    pub const ACR_DCEN: u32 = 1 << 10;
}

/// RCC fields (RM0368 §6.3).
mod rcc {
    pub const HSEON: u32 = 1 << 16;
    pub const HSERDY: u32 = 1 << 17;
    pub const PLLON: u32 = 1 << 24;
    pub const PLLRDY: u32 = 1 << 25;
    pub const PLLCFGR_FIELDS: u32 = 0x0F43_7FFF;
    /// PLLM 8, PLLN 168, PLLP /4 (0b01), PLLSRC = HSE, PLLQ 7: 16 MHz / 8 · 168 / 4 = 84 MHz.
    pub const PLLCFGR_84_MHZ: u32 = 8 | (168 << 6) | (0b01 << 16) | (1 << 22) | (7 << 24);
    pub const PPRE1_DIV2: u32 = 0b100 << 10;
    pub const SW_PLL: u32 = 0b10;
    pub const SWS_PLL: u32 = 0b10 << 2;
}

/// The radio's four inputs (TIM2_CH1..4), the board's wiring.
const RADIO: [u32; 4] = [0, 1, 2, 3];
/// Chip selects of LSM6DSL (PA8) and LIS2MDL (PB12); the LPS22HB's (PC13) is set high too.
const CS_LSM6DSL: (usize, u32) = (PA, 8);
const CS_LIS2MDL: (usize, u32) = (PB, 12);
const CS_LPS22HB: (usize, u32) = (PC, 13);
const SPI2_SCK: (usize, u32) = (PB, 13);
const SPI2_DATA: (usize, u32) = (PB, 15);

/// TIM2 as `RcCapture::new` (fcu-firmware `timers.rs`) sets it up, minus the pins: 4 MHz counts
/// (PSC 20), 32768-count wrap, CCxS = 01 on all four channels, both edges (CCxP = CCxNP = 1),
/// UG, flags cleared by writing 0, capture and update interrupts, CEN.
fn tim2_capture_setup(b: &mut Bench) {
    b.enable(RCC_APB1ENR, 0);
    b.write(TIM2 + PSC, 20);
    b.write(TIM2 + ARR, 32767);
    b.write(TIM2 + CCMR1, 0x0101);
    b.write(TIM2 + CCMR2, 0x0101);
    b.write(TIM2 + CCER, 0xBBBB);
    b.write(TIM2 + EGR, 1);
    b.write(TIM2 + SR, !tim::ALL_TIM2_FLAGS & 0xFFFF);
    b.write(TIM2 + DIER, 0x1F);
    b.write(TIM2 + CR1, 1);
}

/// TIM2/TIM4/TIM9 SR fields (RM0368 §13.4.5, §14.4.4).
mod tim {
    pub const UIF: u32 = 1 << 0;
    pub const fn ccif(c: u32) -> u32 {
        1 << (c + 1)
    }
    pub const fn ccof(c: u32) -> u32 {
        1 << (c + 9)
    }
    /// UIF, CC1IF..CC4IF, CC1OF..CC4OF: the flags `RcCapture::new` clears.
    pub const ALL_TIM2_FLAGS: u32 = 0x1E1F;
}

/// The radio pins as the firmware sets them: `into_pull_down_input().into_alternate::<1>()`.
fn radio_pins(b: &mut Bench, af: u32) {
    for pin in RADIO {
        b.modify(GPIO[PA] + PUPDR, 0b11 << (2 * pin), 0b10 << (2 * pin));
        b.pin_to_alternate(PA, pin, af);
    }
}

/// A radio edge on PA0..PA3 (`channel` 0..3) now, delivered with the next access.
fn radio_edge(b: &mut Bench, channel: usize, level: bool) {
    let at = b.t + 1;
    b.board.schedule_edge(at, channel, level);
    b.wait(10 * US);
}

/// The sensor bus as the firmware sets it up: chip selects high (`into_push_pull_output_in_state`),
/// SCK and the data line on `sck_af`/`data_af` (AF5 on the board), then stm32f4xx-hal
/// `Spi::new_bidi` (`spi.rs`): CR2 = 0, CR1 = mode 3, master, BR /16, SSM + SSI, then BIDIMODE,
/// BIDIOE and SPE. The sensors have booted (25 ms after power-on).
fn sensor_bus(sck_af: u32, data_af: u32) -> Bench {
    let mut b = Bench::at_84_mhz();
    b.gpio_enable();
    for (port, pin) in [CS_LSM6DSL, CS_LIS2MDL, CS_LPS22HB] {
        b.pin_to_output_high(port, pin);
    }
    b.pin_to_alternate(SPI2_SCK.0, SPI2_SCK.1, sck_af);
    b.pin_to_alternate(SPI2_DATA.0, SPI2_DATA.1, data_af);
    b.enable(RCC_APB1ENR, 14);
    b.write(SPI2 + spi::CR2, 0);
    b.write(SPI2 + spi::CR1, spi::CPHA | spi::CPOL | spi::MSTR | spi::BR_DIV16 | spi::SSM | spi::SSI);
    b.modify(SPI2 + spi::CR1, 0, spi::BIDIMODE | spi::BIDIOE | spi::SPE);
    b.run_to(25 * MS);
    b
}

/// SPI2 fields (RM0368 §20.5).
mod spi {
    pub const CR1: u32 = 0x00;
    pub const CR2: u32 = 0x04;
    pub const SR: u32 = 0x08;
    pub const DR: u32 = 0x0C;
    pub const CPHA: u32 = 1 << 0;
    pub const CPOL: u32 = 1 << 1;
    pub const MSTR: u32 = 1 << 2;
    pub const BR_DIV16: u32 = 0b011 << 3;
    pub const SPE: u32 = 1 << 6;
    pub const SSI: u32 = 1 << 8;
    pub const SSM: u32 = 1 << 9;
    pub const BIDIOE: u32 = 1 << 14;
    pub const BIDIMODE: u32 = 1 << 15;
    pub const RXNE: u32 = 1 << 0;
    pub const TXE: u32 = 1 << 1;
    pub const BSY: u32 = 1 << 7;
}

/// One register write as fcu-firmware `SensorBus::write`: CS low, address and value, wait for
/// the line to be idle, CS high.
fn sensor_write(b: &mut Bench, cs: (usize, u32), addr: u8, value: u8) {
    b.pin_low(cs);
    for byte in [addr & 0x7F, value] {
        b.wait_for(SPI2 + spi::SR, spi::TXE);
        b.write(SPI2 + spi::DR, byte.into());
    }
    b.wait_for(SPI2 + spi::SR, spi::TXE);
    b.wait_clear(SPI2 + spi::SR, spi::BSY);
    b.pin_high(cs);
}

/// A one-byte read as fcu-firmware `SensorBus::read`, the RM's bidirectional receive (RM0368
/// RM0368 §20.3.5, "BIDIMODE = 1 and BIDIOE = 0", and §20.3.8 "Disabling the SPI"): the address sent,
/// SPE off, BIDIOE off, SPE on (the clock starts), SPE off again within the byte, the byte read
/// at RXNE, CS high, then the line back to transmit.
fn sensor_read(b: &mut Bench, cs: (usize, u32), addr: u8) -> u8 {
    b.pin_low(cs);
    b.wait_for(SPI2 + spi::SR, spi::TXE);
    b.write(SPI2 + spi::DR, u32::from(addr | 0x80));
    b.wait_for(SPI2 + spi::SR, spi::TXE);
    b.wait_clear(SPI2 + spi::SR, spi::BSY);
    let _stale = b.read(SPI2 + spi::DR);
    let _status = b.read(SPI2 + spi::SR);
    b.modify(SPI2 + spi::CR1, spi::SPE, 0);
    b.modify(SPI2 + spi::CR1, spi::BIDIOE, 0);
    b.modify(SPI2 + spi::CR1, 0, spi::SPE);
    // A bit and a half of the 2.625 MHz clock.
    b.wait(US / 2);
    b.modify(SPI2 + spi::CR1, spi::SPE, 0);
    b.wait_for(SPI2 + spi::SR, spi::RXNE);
    let value = b.read(SPI2 + spi::DR) as u8;
    b.pin_high(cs);
    b.wait_clear(SPI2 + spi::SR, spi::BSY);
    b.modify(SPI2 + spi::CR1, spi::SPE, 0);
    b.modify(SPI2 + spi::CR1, 0, spi::BIDIOE);
    b.modify(SPI2 + spi::CR1, 0, spi::SPE);
    value
}

/// USART1 fields (RM0368 §19.6).
mod usart {
    pub const SR: u32 = 0x00;
    pub const DR: u32 = 0x04;
    pub const BRR: u32 = 0x08;
    pub const CR1: u32 = 0x0C;
    pub const CR2: u32 = 0x10;
    pub const CR3: u32 = 0x14;
    pub const TC: u32 = 1 << 6;
    pub const TXE: u32 = 1 << 7;
    pub const RE: u32 = 1 << 2;
    pub const TE: u32 = 1 << 3;
    pub const UE: u32 = 1 << 13;
    /// 115200 baud from PCLK2 = 84 MHz, oversampling by 16: round(84e6 / 115200) = 729.
    pub const BRR_115200: u32 = 729;
}

/// USART1 as stm32f4xx-hal `Serial::tx` sets it up (`serial.rs`, `Serial::_new`): clock, BRR,
/// CR2 and CR3 reset, then one CR1 write with UE, TE and RE; only then is the TX pin converted
/// (`Tx::new` takes the pin after the registers), here to AF `af` (AF7 on the board).
fn uart_setup(af: u32) -> Bench {
    let mut b = Bench::at_84_mhz();
    b.gpio_enable();
    b.enable(RCC_APB2ENR, 4);
    b.write(USART1 + usart::BRR, usart::BRR_115200);
    b.write(USART1 + usart::CR2, 0);
    b.write(USART1 + usart::CR3, 0);
    b.write(USART1 + usart::CR1, usart::UE | usart::TE | usart::RE);
    b.pin_to_alternate(PA, 9, af);
    // The idle frame TE sends first.
    b.wait(100 * US);
    b
}

/// Sends `bytes` one per TXE, as fcu-firmware's `uart_tx` task does, then waits for TC.
fn uart_send(b: &mut Bench, bytes: &[u8]) {
    for &byte in bytes {
        b.wait_for(USART1 + usart::SR, usart::TXE);
        b.write(USART1 + usart::DR, byte.into());
    }
    b.wait_for(USART1 + usart::SR, usart::TC);
    b.wait(10 * US);
}

/// Pin multiplexing: every peripheral sees its pins only through their alternate function
/// (RM0368 §8.3.2 "I/O pin multiplexer and mapping", §8.3.7 "I/O alternate function
/// input/output"; AF numbers from the STM32F401xB/C datasheet's alternate-function table).
mod pins {
    use super::*;

    /// A radio edge reaches TIM2's capture only with its pin in AF mode on AF1 (TIM2_CH1..4).
    /// Vendor sequence: stm32f4xx-hal `into_pull_down_input().into_alternate::<1>()`. Wrong: AF2
    /// (TIM5's) or the pin left an input: no capture, no interrupt, though IDR shows the level.
    #[test]
    fn a_radio_edge_reaches_tim2_only_through_af1() {
        for (what, af, captured) in [("AF1", Some(1), true), ("AF2", Some(2), false), ("input", None, false)] {
            let mut b = Bench::at_84_mhz();
            b.gpio_enable();
            match af {
                Some(af) => radio_pins(&mut b, af),
                None => b.modify(GPIO[PA] + PUPDR, 0xFF, 0xAA),
            }
            tim2_capture_setup(&mut b);
            for ch in 0..4 {
                radio_edge(&mut b, ch, true);
            }
            let sr = b.read(TIM2 + SR);
            let flags = (0..4).fold(0, |m, c| m | tim::ccif(c));
            assert_eq!(sr & flags == flags, captured, "{what}: SR = {sr:#x}");
            assert_eq!(b.line(irq::TIM2), captured, "{what}: capture interrupt");
            assert_eq!(b.read(GPIO[PA] + IDR) & 0xF, 0xF, "{what}: IDR shows the levels either way");
        }
    }

    /// SPI2 reaches the sensors only with SCK (PB13) and the data line (PB15) both on AF5.
    /// Vendor sequence: stm32f4xx-hal `into_alternate::<5>()` then `Spi::new_bidi`. Wrong: SCK on
    /// AF6 or the data line on AF0 (or left an input): the LIS2MDL's WHO_AM_I (0x40, answered in
    /// 3-wire mode from power-on) reads the undriven line, and a write does not reach the LSM6DSL.
    #[test]
    fn spi2_reaches_the_sensors_only_with_sck_and_data_on_af5() {
        use fcu_pil::periph::sensors::{lis2mdl_reg, lsm6dsl_reg, Sensor, UNDRIVEN};
        for (what, sck_af, data_af, reached) in [("AF5", 5, 5, true), ("SCK on AF6", 6, 5, false), ("data on AF0", 5, 0, false)] {
            let mut b = sensor_bus(sck_af, data_af);
            let who = sensor_read(&mut b, CS_LIS2MDL, lis2mdl_reg::WHO_AM_I);
            let want = if reached { lis2mdl_reg::WHO_AM_I_VALUE } else { UNDRIVEN };
            assert_eq!(who, want, "{what}: LIS2MDL WHO_AM_I");
            let ctrl3 = lsm6dsl_reg::IF_INC | lsm6dsl_reg::SIM;
            sensor_write(&mut b, CS_LSM6DSL, lsm6dsl_reg::CTRL3_C, ctrl3);
            let now = b.t;
            let got = b.board.spi2.sensors().lsm6dsl.register(lsm6dsl_reg::CTRL3_C, now);
            assert_eq!(got == ctrl3, reached, "{what}: LSM6DSL CTRL3_C = {got:#04x} after the write");
        }
    }

    /// USART1's frames leave on PA9 only in AF7 (USART1_TX). Vendor sequence: stm32f4xx-hal
    /// `Serial::tx`, which converts PA9 to AF7 after enabling the transmitter. Wrong: PA9 on AF8
    /// or left an input: the bytes are not on the wire; the board records them as lost.
    #[test]
    fn usart1_bytes_leave_only_on_pa9_in_af7() {
        for (what, af, on_wire) in [("AF7", Some(7), true), ("AF8", Some(8), false), ("input", None, false)] {
            let mut b = match af {
                Some(af) => uart_setup(af),
                None => {
                    let mut b = uart_setup(7);
                    b.set_mode(PA, 9, 0b00);
                    b
                }
            };
            uart_send(&mut b, b"ok\n");
            let wire: Vec<u8> = b.board.records.uart.iter().map(|&(_, x)| x).collect();
            let lost: Vec<u8> = b.board.records.uart_lost.iter().map(|&(_, x)| x).collect();
            if on_wire {
                assert_eq!((wire, lost), (b"ok\n".to_vec(), vec![]), "{what}");
            } else {
                assert_eq!((wire, lost), (vec![], b"ok\n".to_vec()), "{what}");
            }
        }
    }

    /// A frame that starts before PA9 reaches AF7 is not a clean byte on the wire: the receiver
    /// sees its start bit cut. The same byte sent once the pin is routed goes out.
    #[test]
    fn a_frame_begun_before_pa9_is_on_af7_is_lost() {
        let mut b = uart_setup(0);
        b.write(USART1 + usart::DR, u32::from(b'a'));
        b.wait(20 * US);
        b.set_af(PA, 9, 7);
        uart_send(&mut b, b"b");
        let wire: Vec<u8> = b.board.records.uart.iter().map(|&(_, x)| x).collect();
        let lost: Vec<u8> = b.board.records.uart_lost.iter().map(|&(_, x)| x).collect();
        assert_eq!((wire, lost), (b"b".to_vec(), b"a".to_vec()));
    }

    /// TIM4's compare reaches a motor gate only through AF2 on PB6..PB9 (TIM4_CH1..4). Vendor
    /// sequence: fcu-firmware's `into_alternate::<2>()` on PB6..PB9. Wrong: PB7 on AF1: that motor
    /// gets no PWM (the gate is pulled low) while the others run.
    #[test]
    fn tim4_reaches_the_motors_only_through_af2() {
        let mut b = Bench::at_84_mhz();
        b.gpio_enable();
        for pin in 6..10 {
            b.pin_to_alternate(PB, pin, if pin == 7 { 1 } else { 2 });
        }
        tim4::motors_setup(&mut b, 300);
        let now = b.t;
        assert_eq!(b.board.motor_compares(now), [300, 0, 300, 300]);
    }
}

/// TIM2's capture flags (RM0368 §13.4.5 TIMx_SR: CCxIF and CCxOF are rc_w0; §13.3.5 "Input
/// capture mode"). Vendor sequence: fcu-firmware `RcCapture` writes SR with 0 in the flags it
/// clears (svd2rust's `clear()`, 1 in the others), and lets a CCRx read clear CCxIF; ST's HAL
/// `__HAL_TIM_CLEAR_FLAG` writes `~flag` to SR.
mod tim2 {
    use super::*;

    fn captured(b: &mut Bench, channel: usize) {
        radio_edge(b, channel, true);
        assert_ne!(b.read(TIM2 + SR) & tim::ccif(channel as u32), 0, "the edge was not captured");
    }

    fn setup() -> Bench {
        let mut b = Bench::at_84_mhz();
        b.gpio_enable();
        radio_pins(&mut b, 1);
        tim2_capture_setup(&mut b);
        b
    }

    /// Wrong: "clearing" CC1IF by writing 1 to it (the write-1-to-clear habit of other chips).
    /// Silicon: writing 1 leaves it set, so the capture interrupt stays pending and the handler
    /// is re-entered for ever. Writing 0 clears it.
    #[test]
    fn a_capture_flag_written_1_stays_set_and_written_0_clears() {
        let mut b = setup();
        captured(&mut b, 0);
        b.write(TIM2 + SR, tim::ccif(0));
        b.wait(US);
        assert_ne!(b.read(TIM2 + SR) & tim::ccif(0), 0, "CC1IF written 1: still set");
        assert!(b.line(irq::TIM2), "the capture interrupt stays pending");
        b.write(TIM2 + SR, !tim::ccif(0) & 0xFFFF);
        b.wait(US);
        assert_eq!(b.read(TIM2 + SR) & tim::ccif(0), 0, "CC1IF written 0: cleared");
        assert!(!b.line(irq::TIM2));
    }

    /// CCxOF is rc_w0 too, and a CCRx read clears CCxIF but not CCxOF ("cleared by software by
    /// writing it to 0"). Wrong: writing 1 to CC2OF, or expecting the CCR2 read to clear it.
    #[test]
    fn the_overcapture_flag_written_1_stays_set_and_a_ccr_read_leaves_it() {
        let mut b = setup();
        radio_edge(&mut b, 1, true);
        radio_edge(&mut b, 1, false);
        let sr = b.read(TIM2 + SR);
        assert_eq!(sr & (tim::ccif(1) | tim::ccof(1)), tim::ccif(1) | tim::ccof(1), "second edge before the read: overcapture");
        let _ = b.read(TIM2 + CCR1 + 4);
        let sr = b.read(TIM2 + SR);
        assert_eq!(sr & (tim::ccif(1) | tim::ccof(1)), tim::ccof(1), "the CCR2 read cleared CC2IF only");
        b.write(TIM2 + SR, tim::ccof(1));
        assert_ne!(b.read(TIM2 + SR) & tim::ccof(1), 0, "CC2OF written 1: still set");
        b.write(TIM2 + SR, !tim::ccof(1) & 0xFFFF);
        assert_eq!(b.read(TIM2 + SR) & tim::ccof(1), 0, "CC2OF written 0: cleared");
    }

    /// Wrong: clearing UIF with a read-modify-write of SR (`sr.modify(|_, w| w.uif().clear())`
    /// on a PAC that writes back what it read, or `TIM2->SR &= ~TIM_SR_UIF`). A capture that
    /// lands between the read and the write is written back as 0: silicon clears it and the
    /// edge is lost. The firmware writes SR instead (1 in every flag but the one it clears).
    #[test]
    fn a_read_modify_write_of_sr_loses_a_capture_that_lands_in_between() {
        let mut b = setup();
        b.wait(9 * MS);
        let read = b.read(TIM2 + SR);
        assert_ne!(read & tim::UIF, 0, "one wrap after 8.192 ms");
        assert_eq!(read & tim::ccif(2), 0);
        radio_edge(&mut b, 2, true);
        b.write(TIM2 + SR, read & !tim::UIF);
        assert_eq!(b.read(TIM2 + SR) & tim::ccif(2), 0, "the capture flag set in between was cleared by the write-back");
        // The firmware's write: 0 in UIF, 1 in every other flag.
        radio_edge(&mut b, 2, false);
        b.wait(9 * MS);
        b.write(TIM2 + SR, !tim::UIF & 0xFFFF);
        assert_ne!(b.read(TIM2 + SR) & tim::ccif(2), 0, "a write with 1s keeps the capture");
    }
}

/// TIM4's compare preload (RM0368 §13.4.7 TIMx_CCMR1 OCxPE: "0: … the new value is taken in
/// account immediately; 1: … loaded in the active register at each update event"; RM0368 §13.3.9 PWM
/// mode: "the corresponding preload register must be enabled by setting the OCxPE bit").
mod tim4 {
    use super::*;

    /// fcu-firmware `Motors::new` (the ST HAL's `HAL_TIM_PWM_ConfigChannel` likewise sets OCxPE):
    /// PSC and ARR of the flight configuration, CCRx = `compare`, PWM mode 1 with OCxPE, CCxE,
    /// UG, ARPE + CEN. The pins are the caller's.
    pub fn motors_setup(b: &mut Bench, compare: u32) {
        let mixer = fcu_core::Config::default().mixer;
        b.enable(RCC_APB1ENR, 2);
        b.write(TIM4 + PSC, mixer.timer_psc.into());
        b.write(TIM4 + ARR, mixer.timer_arr.into());
        for ch in 0..4 {
            b.write(TIM4 + CCR1 + 4 * ch, compare);
        }
        b.write(TIM4 + CCMR1, 0x6868);
        b.write(TIM4 + CCMR2, 0x6868);
        b.write(TIM4 + CCER, 0x1111);
        b.write(TIM4 + EGR, 1);
        b.write(TIM4 + CR1, (1 << 7) | 1);
    }

    fn motors() -> Bench {
        let mut b = Bench::at_84_mhz();
        b.gpio_enable();
        for pin in 6..10 {
            b.pin_to_alternate(PB, pin, 2);
        }
        motors_setup(&mut b, 100);
        b
    }

    /// The time to the next update event of TIM4 (from CNT, PSC and ARR).
    fn to_next_update(b: &mut Bench) -> Time {
        let mixer = fcu_core::Config::default().mixer;
        let cnt = Time::from(b.read(TIM4 + CNT));
        let counts = Time::from(mixer.timer_arr) + 1 - cnt;
        // The timer clock is 84 MHz: 4 time units per tick.
        counts * (Time::from(mixer.timer_psc) + 1) * 4
    }

    /// Wrong (for a motor output): a compare written with OC1PE = 0 takes effect at once, in the
    /// middle of the PWM period, cutting or stretching the pulse in flight.
    #[test]
    fn a_compare_written_with_preload_off_takes_effect_mid_period() {
        let mut b = motors();
        b.write(TIM4 + CCMR1, 0x6860);
        let half = to_next_update(&mut b) / 2;
        b.wait(half);
        b.write(TIM4 + CCR1, 700);
        let now = b.t;
        assert_eq!(b.board.motor_compares(now)[0], 700, "OC1PE = 0: in force mid-period");
    }

    /// The firmware's sequence: with OCxPE = 1 a compare written mid-period is held in the
    /// preload register until the update event, so every pulse is whole.
    #[test]
    fn a_compare_written_with_preload_on_waits_for_the_update_event() {
        let mut b = motors();
        let half = to_next_update(&mut b) / 2;
        b.wait(half);
        b.write(TIM4 + CCR1, 700);
        let now = b.t;
        assert_eq!(b.board.motor_compares(now), [100; 4], "OC1PE = 1: the old compare until the update");
        assert_eq!(b.read(TIM4 + CCR1), 700, "reads give the preload register");
        let dt = to_next_update(&mut b);
        b.wait(dt);
        let now = b.t;
        assert_eq!(b.board.motor_compares(now), [700, 100, 100, 100], "in force from the update event");
    }

    /// fcu-firmware `motors_off_now` (the HardFault and panic path): CCRx then EGR.UG, which
    /// generates the update event at once and so loads the preloaded compares without waiting
    /// for the period's end. Without the UG, the motors would run on to the end of the period.
    #[test]
    fn ug_loads_the_preloaded_compares_at_once() {
        let mut b = motors();
        let half = to_next_update(&mut b) / 2;
        b.wait(half);
        for ch in 0..4 {
            b.write(TIM4 + CCR1 + 4 * ch, 0);
        }
        let now = b.t;
        assert_eq!(b.board.motor_compares(now), [100; 4], "without UG: still running");
        b.write(TIM4 + EGR, 1);
        let now = b.t;
        assert_eq!(b.board.motor_compares(now), [0; 4], "UG: off at once");
    }
}

/// TIM9, the control tick (RM0368 §14.4.1 TIMx_CR1 URS: "1: only counter overflow generates an
/// update interrupt"; RM0368 §14.4.5 TIMx_EGR UG: re-initialises the counter and updates the
/// registers; RM0368 §14.4.9 TIMx_PSC: "the new prescaler ratio is taken into account at the next
/// update event"; RM0368 §14.4.4 TIMx_SR UIF: rc_w0). Vendor sequence: fcu-firmware `TickTimer::new`:
/// PSC, ARR, CR1 = URS, EGR = UG, SR = UIF cleared, DIER = UIE; `start`: CEN.
mod tim9 {
    use super::*;

    fn tick_period(timing: &fcu_core::config::Timing) -> Time {
        (Time::from(timing.tick_timer_psc) + 1) * (Time::from(timing.tick_timer_arr) + 1) * 4
    }

    /// `TickTimer::new` with `urs` and `ug` as given, then CEN.
    fn tick_timer(urs: bool, ug: bool) -> (Bench, Time) {
        let timing = fcu_core::Config::default().timing;
        let mut b = Bench::at_84_mhz();
        b.enable(RCC_APB2ENR, 16);
        b.write(TIM9 + PSC, timing.tick_timer_psc.into());
        b.write(TIM9 + ARR, timing.tick_timer_arr.into());
        b.write(TIM9 + CR1, if urs { 1 << 2 } else { 0 });
        if ug {
            b.write(TIM9 + EGR, 1);
        }
        b.write(TIM9 + DIER, 1);
        b.modify(TIM9 + CR1, 0, 1);
        let start = b.t;
        b.wait(US);
        (b, start)
    }

    /// The firmware's sequence: UG with URS = 1 loads PSC at once without raising UIF, so the
    /// first tick comes one whole period (1.238 ms at 807.69 Hz) after CEN.
    #[test]
    fn ug_with_urs_loads_the_prescaler_without_a_tick() {
        let (mut b, start) = tick_timer(true, true);
        assert!(!b.line(irq::TIM1_BRK_TIM9), "no tick at CEN");
        let period = tick_period(&fcu_core::Config::default().timing);
        b.run_to(start + period - 4 * US);
        assert!(!b.line(irq::TIM1_BRK_TIM9));
        b.run_to(start + period + 4 * US);
        assert!(b.line(irq::TIM1_BRK_TIM9), "first tick one period after CEN");
    }

    /// Wrong: UG with URS = 0 sets UIF; with UIE on, the control task runs once at start-up
    /// before any period has passed. (The firmware clears UIF before DIER, which this sequence
    /// leaves out, as a bug would.)
    #[test]
    fn ug_without_urs_raises_a_tick_at_once() {
        let (b, _) = tick_timer(false, true);
        assert!(b.line(irq::TIM1_BRK_TIM9), "UIF from the UG: a tick at CEN");
    }

    /// Wrong: PSC written without UG. PSC is buffered, so the first period runs at the reset
    /// prescaler (/1): the first tick comes after 2000 counts of 84 MHz (23.8 µs), not 1.238 ms.
    #[test]
    fn psc_without_ug_runs_the_first_period_at_the_old_prescaler() {
        let (mut b, start) = tick_timer(true, false);
        let arr = Time::from(fcu_core::Config::default().timing.tick_timer_arr);
        b.run_to(start + (arr + 1) * 4 + 2 * US);
        assert!(b.line(irq::TIM1_BRK_TIM9), "a tick after one period of the reset prescaler");
    }

    /// Wrong: "clearing" UIF by writing 1 (`sr.write(|w| w.uif().set_bit())`): it stays set, the
    /// line stays high and the control task is re-entered back to back. The firmware's
    /// `clear_update` writes 0.
    #[test]
    fn uif_written_1_stays_set() {
        let (mut b, start) = tick_timer(true, true);
        let period = tick_period(&fcu_core::Config::default().timing);
        b.run_to(start + period + 4 * US);
        b.write(TIM9 + SR, tim::UIF);
        b.wait(US);
        assert!(b.line(irq::TIM1_BRK_TIM9), "UIF written 1: the tick stays pending");
        b.write(TIM9 + SR, !tim::UIF & 0xFFFF);
        b.wait(US);
        assert!(!b.line(irq::TIM1_BRK_TIM9), "UIF written 0: cleared");
    }
}

/// A peripheral's registers before its RCC clock enable (RM0368 §6.3.9 RCC_AHB1ENR, §6.3.11
/// RCC_APB1ENR, §6.3.12 RCC_APB2ENR). Vendor sequence: stm32f4xx-hal `Enable::enable` sets the
/// xENR bit, then DSB (ST's workaround for "delay after an RCC peripheral clock enabling" in the
/// F401 errata), and only then touches the peripheral. On silicon an access without the clock
/// reads 0 and drops the write; the board refuses it, naming the peripheral, so the bug stops
/// the run instead of flying with a silently unconfigured peripheral.
mod rcc_enable {
    use super::*;

    /// (name, enable register, bit, a register of the peripheral, a value it reads back).
    const PERIPHERALS: [(&str, u32, u32, u32, u32); 10] = [
        ("GPIOA", RCC_AHB1ENR, 0, GPIO[0] + ODR, 1 << 3),
        ("GPIOB", RCC_AHB1ENR, 1, GPIO[1] + ODR, 1 << 3),
        ("GPIOC", RCC_AHB1ENR, 2, GPIO[2] + ODR, 1 << 3),
        ("TIM2", RCC_APB1ENR, 0, TIM2 + PSC, 20),
        ("TIM4", RCC_APB1ENR, 2, TIM4 + PSC, 20),
        ("SPI2", RCC_APB1ENR, 14, SPI2 + spi::CR2, 0),
        ("PWR", RCC_APB1ENR, 28, PWR, 0x8000),
        ("USART1", RCC_APB2ENR, 4, USART1 + usart::BRR, usart::BRR_115200),
        ("ADC1", RCC_APB2ENR, 8, ADC1 + 0x34, 9),
        ("TIM9", RCC_APB2ENR, 16, TIM9 + PSC, 51),
    ];

    /// Wrong: configuring a peripheral before (or without) its clock enable, or with another
    /// peripheral's bit set. Refused, naming the peripheral; after its own bit, accepted.
    #[test]
    fn every_peripheral_the_firmware_uses_is_refused_before_its_clock_enable() {
        for &(name, enr, bit, reg, value) in &PERIPHERALS {
            let mut b = Bench::new();
            let refused = |r: Result<(), Unmodelled>| matches!(r, Err(e) if e.register == name);
            assert!(refused(b.try_read(reg).map(drop)), "{name}: read before its clock enable");
            assert!(refused(b.try_write(reg, value)), "{name}: write before its clock enable");
            // Every other peripheral's clock on: still refused.
            for &(_, other_enr, other_bit, _, _) in PERIPHERALS.iter().filter(|p| p.0 != name) {
                b.enable(other_enr, other_bit);
            }
            assert!(refused(b.try_write(reg, value)), "{name}: write with only the others' clocks on");
            b.enable(enr, bit);
            b.try_write(reg, value).unwrap_or_else(|e| panic!("{name} after its clock enable: {e}"));
            assert_eq!(b.read(reg), value, "{name}: written value reads back");
        }
    }
}

/// The ADC clock (RM0368 §11.3.2 "ADC clock" and §11.12 ADC_CCR.ADCPRE; STM32F401xB/C
/// datasheet, ADC characteristics: f_ADC at most 36 MHz with VDDA 2.4–3.6 V). Vendor sequence:
/// fcu-firmware `Adc::new(…, AdcConfig::default().clock(Pclk2_div_4))`, i.e. stm32f4xx-hal
/// `set_clock` writing ADCPRE = 01 (/4: 21 MHz) before the first conversion; ST's reference
/// firmware uses /4 as well.
mod adc {
    use super::*;

    fn start_battery_conversion(b: &mut Bench) -> Result<(), Unmodelled> {
        b.write(ADC1 + 0x34, 9); // SQR3: channel 9 (PB1)
        b.write(ADC1 + 0x10, 0b111 << 27); // SMPR2: 480 cycles
        b.write(ADC1 + 0x08, 1); // CR2: ADON
        b.wait(5 * US);
        b.try_write(ADC1 + 0x08, 1 | (1 << 30)) // SWSTART
    }

    fn setup() -> Bench {
        let mut b = Bench::at_84_mhz();
        b.board.set_battery_volts(3.9);
        b.gpio_enable();
        b.set_mode(PB, 1, 0b11);
        b.enable(RCC_APB2ENR, 8);
        b
    }

    /// Wrong: ADCPRE left at its reset value /2 with PCLK2 = 84 MHz: a 42 MHz ADC clock, above
    /// the datasheet's 36 MHz. Silicon converts with no guaranteed accuracy; the model refuses
    /// the conversion (judged: an out-of-spec result is not something to fly on).
    #[test]
    fn an_adc_clock_of_42_mhz_is_refused() {
        let mut b = setup();
        let e = start_battery_conversion(&mut b).expect_err("a conversion at 42 MHz");
        assert_eq!(e.register, "ADC1.CR2");
        assert!(e.what.contains("42 MHz above the F401's 36 MHz maximum"), "{e}");
    }

    fn convert_battery(b: &mut Bench) -> u32 {
        b.modify(ADC_CCR, 0b11 << 16, 0b01 << 16);
        start_battery_conversion(b).unwrap_or_else(|e| panic!("{e}"));
        b.wait_for(ADC1, 1 << 1);
        b.read(ADC1 + 0x4C)
    }

    /// The firmware's setting, /4 (21 MHz): the conversion runs and reads the divider.
    #[test]
    fn an_adc_clock_of_21_mhz_converts() {
        let mut b = setup();
        let code = convert_battery(&mut b);
        // 3.9 V · 2/3 = 2.6 V of 3.3 V: 3226 counts.
        assert!((3220..=3232).contains(&code), "{code}");
    }

    /// The ADC reads the pad whatever the pin's mode (RM0368 §8.3.12; stm32f4xx-hal's
    /// `into_analog` only turns the digital input off). Wrong: PB1 left a push-pull output: the
    /// conversion reads the level the port drives, not the battery.
    #[test]
    fn a_battery_pin_left_as_an_output_reads_its_own_level() {
        let mut b = setup();
        b.set_mode(PB, 1, 0b01);
        assert_eq!(convert_battery(&mut b), 0, "driven low");
        b.pin_high((PB, 1));
        b.write(ADC1 + 0x08, 1 | (1 << 30));
        b.wait_for(ADC1, 1 << 1);
        assert_eq!(b.read(ADC1 + 0x4C), 4095, "driven high");
        b.set_mode(PB, 1, 0b11);
        b.write(ADC1 + 0x08, 1 | (1 << 30));
        b.wait_for(ADC1, 1 << 1);
        assert!((3220..=3232).contains(&b.read(ADC1 + 0x4C)), "analog again: the divider");
    }
}

/// Flash wait states (RM0368 §3.4.1 "Relation between CPU clock frequency and Flash memory read
/// time", table "Number of wait states according to CPU clock (HCLK) frequency", 2.7–3.6 V: 2 WS
/// above 60 MHz up to 84 MHz; its procedure "Increasing the CPU frequency": LATENCY first, check
/// it by reading FLASH_ACR, then SW; "Decreasing": SW first, then LATENCY). Vendor sequence:
/// stm32f4xx-hal `Rcc::freeze` (`flash_setup` before the oscillators, then the switch) and ST's
/// `HAL_RCC_ClockConfig` (LATENCY, read back, then SW). With too few wait states silicon fetches
/// wrong instructions; the model refuses the access that creates the condition.
mod flash_latency {
    use super::*;

    /// Up to the PLL, ready, with `latency` in FLASH_ACR; returns the result of switching to it.
    fn switch_with_latency(latency: u32) -> Result<(), Unmodelled> {
        let mut b = Bench::new();
        b.modify(FLASH_ACR, 0xF, latency);
        b.start_pll();
        b.try_modify(RCC_CFGR, 0xFCF3, rcc::PPRE1_DIV2 | rcc::SW_PLL)
    }

    /// The RM's order: LATENCY = 2, read back, then SW = PLL.
    #[test]
    fn latency_raised_and_read_back_before_the_switch_is_accepted() {
        let mut b = Bench::new();
        b.modify(FLASH_ACR, 0xF, 2);
        assert_eq!(b.read(FLASH_ACR) & 0xF, 2, "the new LATENCY reads back");
        b.start_pll();
        b.modify(RCC_CFGR, 0xFCF3, rcc::PPRE1_DIV2 | rcc::SW_PLL);
        b.wait_for(RCC_CFGR, rcc::SWS_PLL);
        // The HAL's whole sequence too.
        let _ = Bench::at_84_mhz();
    }

    /// Wrong: LATENCY 1 (enough up to 60 MHz) at 84 MHz.
    #[test]
    fn latency_1_at_84_mhz_is_refused() {
        let e = switch_with_latency(1).expect_err("84 MHz with 1 wait state");
        assert_eq!(e.register, "FLASH.ACR");
        assert!(e.what.contains("needs at least 2"), "{e}");
    }

    /// Wrong: SYSCLK switched to 84 MHz before LATENCY is raised (reset LATENCY 0).
    #[test]
    fn switching_to_84_mhz_before_raising_latency_is_refused() {
        let e = switch_with_latency(0).expect_err("84 MHz with 0 wait states");
        assert_eq!(e.register, "FLASH.ACR");
    }

    /// Wrong (decreasing): LATENCY lowered while HCLK is still 84 MHz.
    #[test]
    fn lowering_latency_before_the_clock_is_refused() {
        let mut b = Bench::at_84_mhz();
        let e = b.try_modify(FLASH_ACR, 0xF, 0).expect_err("LATENCY 0 at 84 MHz");
        assert_eq!(e.register, "FLASH.ACR");
    }
}

/// USART1 (RM0368 §19.3.2 "Transmitter", character transmission procedure: UE, M, STOP, BRR,
/// then TE, then DR at TXE; RM0368 §19.3.4 "the baud rate register value should not be changed during
/// communication"; RM0368 §19.6.1 USART_SR: TC rc_w0, cleared by an SR read then a DR write; TXE
/// cleared by the DR write). Vendor sequence: stm32f4xx-hal `Serial::tx` (BRR, CR2, CR3, then
/// one CR1 write with UE | TE | RE) and fcu-firmware's one byte per TXE interrupt.
mod usart1 {
    use super::*;

    /// Wrong: TE set before BRR is programmed (BRR = 0): the idle frame TE sends has no baud
    /// rate. Silicon's behaviour with USARTDIV = 0 is not specified; the model refuses it.
    #[test]
    fn te_before_brr_is_refused() {
        let mut b = Bench::at_84_mhz();
        b.enable(RCC_APB2ENR, 4);
        let e = b.try_write(USART1 + usart::CR1, usart::UE | usart::TE).expect_err("TE with BRR = 0");
        assert_eq!(e.register, "USART1.BRR");
    }

    /// Wrong: a DR write with the transmitter off, TE = 0 or UE = 0 (UE off stops the
    /// USART's prescalers and outputs): nothing would be sent. Refused.
    #[test]
    fn a_dr_write_with_te_or_ue_off_is_refused() {
        for (what, cr1) in [("TE = 0", usart::UE), ("UE = 0", usart::TE)] {
            let mut b = Bench::at_84_mhz();
            b.enable(RCC_APB2ENR, 4);
            b.write(USART1 + usart::BRR, usart::BRR_115200);
            b.write(USART1 + usart::CR1, cr1);
            let e = b.try_write(USART1 + usart::DR, 0x41).expect_err(what);
            assert_eq!(e.register, "USART1.DR", "{what}");
        }
    }

    /// Wrong: BRR worked out for another PCLK2, e.g. the 16 MHz HSI before the switch to the
    /// PLL (139 instead of 729): the bytes go out at 604 kbaud and the host, listening at
    /// 115 200, reads garbage. The board records them as lost. The HAL computes BRR from the
    /// frozen clocks (`Serial::_new`: `USART::clock(&rcc.clocks)`), giving 115 226 baud.
    #[test]
    fn a_brr_worked_out_for_another_clock_is_unreadable_by_the_host() {
        for (what, brr, read) in [("BRR for 84 MHz", usart::BRR_115200, true), ("BRR for 16 MHz", 139, false)] {
            let mut b = uart_setup(7);
            b.write(USART1 + usart::BRR, brr);
            uart_send(&mut b, b"hi");
            let wire: Vec<u8> = b.board.records.uart.iter().map(|&(_, x)| x).collect();
            let lost: Vec<u8> = b.board.records.uart_lost.iter().map(|&(_, x)| x).collect();
            let (want_wire, want_lost) = if read { (b"hi".to_vec(), vec![]) } else { (vec![], b"hi".to_vec()) };
            assert_eq!((wire, lost), (want_wire, want_lost), "{what}");
        }
    }

    /// Wrong: writing DR without waiting for TXE. The byte waiting in TDR is overwritten and
    /// never sent (counted by the model as a lost byte).
    #[test]
    fn a_dr_write_without_waiting_for_txe_overwrites_the_waiting_byte() {
        let mut b = uart_setup(7);
        for byte in *b"abc" {
            b.write(USART1 + usart::DR, byte.into());
        }
        b.wait(500 * US);
        let wire: Vec<u8> = b.board.records.uart.iter().map(|&(_, x)| x).collect();
        assert_eq!(wire, b"ac", "b was overwritten in TDR by c");
        assert_eq!(b.board.usart1.lost_bytes(), 1);
    }

    /// Wrong: changing BRR while a byte is on the wire: its remaining bits go out at the new
    /// rate, so the receiver sees garbage; the board records it as lost.
    #[test]
    fn a_brr_change_during_a_byte_garbles_it() {
        let mut b = uart_setup(7);
        b.write(USART1 + usart::DR, u32::from(b'x'));
        b.wait(30 * US);
        b.write(USART1 + usart::BRR, usart::BRR_115200 * 2);
        b.wait(200 * US);
        assert!(b.board.records.uart.is_empty(), "{:?}", b.board.records.uart);
        assert_eq!(b.board.records.uart_lost.iter().map(|&(_, x)| x).collect::<Vec<_>>(), b"x");
    }

    /// TC is rc_w0: writing 1 leaves it set; the SR read + DR write sequence (what a TXE-driven
    /// sender does) clears it, as does writing 0.
    #[test]
    fn tc_written_1_stays_set() {
        let mut b = uart_setup(7);
        assert_ne!(b.read(USART1 + usart::SR) & usart::TC, 0, "after the idle frame");
        b.write(USART1 + usart::SR, usart::TC);
        assert_ne!(b.read(USART1 + usart::SR) & usart::TC, 0, "TC written 1: still set");
        b.write(USART1 + usart::SR, 0);
        assert_eq!(b.read(USART1 + usart::SR) & usart::TC, 0, "TC written 0: cleared");
        uart_send(&mut b, b"z");
        assert_ne!(b.read(USART1 + usart::SR) & usart::TC, 0, "set again at the end of the byte");
        let _ = b.read(USART1 + usart::SR);
        b.write(USART1 + usart::DR, u32::from(b'y'));
        assert_eq!(b.read(USART1 + usart::SR) & usart::TC, 0, "SR read then DR write: cleared");
    }
}

/// DBGMCU (RM0368 §23, "MCU debug component (DBGMCU)": DBGMCU_APB1_FZ.DBG_IWDG_STOP stops the
/// watchdog's counter "when the core is halted"; CR, APB1_FZ and APB2_FZ are reset by a
/// power-on reset only). Vendor sequence: fcu-firmware `Watchdog::start` sets DBG_IWDG_STOP
/// (read-modify-write) before starting the IWDG.
mod dbgmcu {
    use super::*;

    /// The freeze bit acts only while a debugger halts the core; none is attached here (nor in
    /// flight), so a started watchdog still resets the board. Wrong assumption guarded: that
    /// setting DBG_IWDG_STOP disables the watchdog.
    #[test]
    fn the_iwdg_freeze_bit_does_not_stop_the_watchdog_without_a_debugger() {
        let mut b = Bench::new();
        b.modify(DBGMCU + 0x08, 0, 1 << 12);
        b.write(IWDG, 0xCCCC);
        b.wait(1000 * MS);
        assert_eq!(b.watchdog_resets, 1, "the default timeout (0xFFF at /4, 512 ms) reset the board");
    }

    /// The freeze bits survive a system reset (a watchdog reset here): only a power-on reset
    /// clears them. Wrong model guarded: DBGMCU back to 0 at every reset.
    #[test]
    fn the_freeze_bits_survive_a_system_reset() {
        let mut b = Bench::new();
        b.modify(DBGMCU + 0x08, 0, 1 << 12);
        b.write(DBGMCU + 0x0C, 1 << 16);
        b.write(IWDG, 0xCCCC);
        b.wait(1000 * MS);
        assert_eq!(b.watchdog_resets, 1);
        assert_eq!(b.read(DBGMCU + 0x08), 1 << 12);
        assert_eq!(b.read(DBGMCU + 0x0C), 1 << 16);
    }
}

/// The GPIO rules the firmware relies on (RM0368 §8.3.9 input, §8.3.10 output, §8.3.11
/// alternate-function configuration; RM0368 §8.4.7 GPIOx_BSRR).
mod gpio {
    use super::*;

    /// stm32f4xx-hal `into_push_pull_output_in_state(High)`: BSRR first, then MODER, so a chip
    /// select never drives low on its way to output. Wrong: MODER first, with ODR at its reset
    /// 0: the pin drives low at once (RM0368 §8.3.10: "the output buffer is enabled … a 0 in the
    /// output register activates the N-MOS"), selecting the sensor until BSRR is written.
    #[test]
    fn a_chip_select_set_to_output_before_its_level_drives_low() {
        let mut b = sensor_bus(5, 5);
        // Back to input, as after a reset of the port's registers.
        b.set_mode(PB, 12, 0b00);
        b.write(GPIO[PB] + BSRR, 1 << (12 + 16));
        b.set_mode(PB, 12, 0b01);
        assert!(b.board.spi2.chip_selects()[1], "MODER first: the LIS2MDL is selected");
        b.pin_high(CS_LIS2MDL);
        b.set_mode(PB, 12, 0b00);
        b.pin_to_output_high(PB, 12);
        assert!(!b.board.spi2.chip_selects()[1], "BSRR first: never selected");
    }

    /// The radio pins keep their pull-down in AF mode (RM0368 §8.3.11: the pull resistors follow
    /// PUPDR in alternate-function mode), so an unplugged receiver reads low, not floating, and
    /// IDR shows the pin's level while TIM2 owns it (the capture task reads the level there).
    /// Wrong: AF without the pull-down: an unplugged channel floats.
    #[test]
    fn radio_pins_keep_their_pull_down_in_af_mode() {
        let mut b = Bench::at_84_mhz();
        b.gpio_enable();
        radio_pins(&mut b, 1);
        assert_eq!(b.read(GPIO[PA] + IDR) & 0xF, 0);
        assert_eq!(b.board.gpio[PA].floating_pins() & 0xF, 0, "pulled down");
        b.modify(GPIO[PA] + PUPDR, 0b11, 0);
        let _ = b.read(GPIO[PA] + IDR);
        assert_eq!(b.board.gpio[PA].floating_pins() & 0xF, 1, "PA0 without its pull-down floats");
        radio_edge(&mut b, 1, true);
        assert_eq!(b.read(GPIO[PA] + IDR) & 0b10, 0b10, "IDR shows PA1 high in AF mode");
    }

    /// BSRR (what `set_high`/`set_low` write): one write sets and resets pins without a
    /// read-modify-write; with both bits of a pin set, set wins. Reads return 0.
    #[test]
    fn bsrr_sets_and_resets_without_a_read_and_set_wins() {
        let mut b = Bench::new();
        b.gpio_enable();
        b.write(GPIO[PB] + ODR, 1 << 4);
        b.write(GPIO[PB] + BSRR, (1 << 5) | (1 << (4 + 16)) | (1 << 6) | (1 << (6 + 16)));
        assert_eq!(b.read(GPIO[PB] + ODR), (1 << 5) | (1 << 6));
        assert_eq!(b.read(GPIO[PB] + BSRR), 0);
    }
}

/// USART1's receiver and DMA2 (RM0368 §19.3.3 "Receiver", §19.6.1 USART_SR, §9.3.9
/// "Circular mode", table 28 DMA2 request mapping), with bytes from the host on PA10 at 115 200
/// baud.
mod usart1_rx {
    use super::*;

    const RXNE: u32 = 1 << 5;
    const ORE: u32 = 1 << 3;
    const RXNEIE: u32 = 1 << 5;
    const DMAR: u32 = 1 << 6;
    const DMA2: u32 = 0x4002_6400;
    const S5CR: u32 = DMA2 + 0x10 + 5 * 0x18;
    const BUF: u32 = 0x2000_4000;
    /// One 8N1 frame at 115 200 baud: 10 bits.
    const FRAME: Time = 10 * TIME_HZ / 115_200;

    /// `uart_setup` with PA10 to `af` too (stm32f4xx-hal `Serial::new` converts both pins).
    fn receiver(af: u32) -> Bench {
        let mut b = uart_setup(7);
        b.pin_to_alternate(PA, 10, af);
        b
    }

    fn received(b: &mut Bench) -> Option<u8> {
        (b.read(USART1 + usart::SR) & RXNE != 0).then(|| b.read(USART1 + usart::DR) as u8)
    }

    /// A byte from the host reaches USART1 only with PA10 in AF mode on AF7 (USART1_RX). Wrong:
    /// AF8 or the pin left an input: the receiver never sees it.
    #[test]
    fn a_byte_reaches_usart1_only_on_pa10_in_af7() {
        for (what, af, arrives) in [("AF7", Some(7), true), ("AF8", Some(8), false), ("input", None, false)] {
            let mut b = receiver(af.unwrap_or(7));
            if af.is_none() {
                b.set_mode(PA, 10, 0b00);
            }
            let t = b.t;
            b.board.push_uart_rx(b"Z", t);
            b.wait(2 * FRAME);
            let lost: Vec<u8> = b.board.records.uart_rx_lost.iter().map(|&(_, x)| x).collect();
            if arrives {
                assert_eq!((received(&mut b), lost), (Some(b'Z'), vec![]), "{what}");
            } else {
                assert_eq!((received(&mut b), lost), (None, b"Z".to_vec()), "{what}");
            }
        }
    }

    /// The host's bytes come at its baud rate: RXNE sets at the end of the first frame's stop
    /// bit, 86.8 µs after its start, and the receive interrupt with it (RXNEIE).
    #[test]
    fn bytes_arrive_at_115200_baud_and_raise_rxne_with_its_interrupt() {
        let mut b = receiver(7);
        b.write(USART1 + usart::CR1, usart::UE | usart::TE | usart::RE | RXNEIE);
        let t0 = b.t;
        b.board.push_uart_rx(b"ab", t0);
        b.run_to(t0 + FRAME - 1);
        assert!(!b.line(irq::USART1));
        assert_eq!(b.board.usart1.rx_counts().0, 0, "the stop bit has not ended");
        b.run_to(t0 + FRAME);
        assert!(b.line(irq::USART1));
        assert_eq!(received(&mut b), Some(b'a'));
        b.run_to(t0 + 2 * FRAME);
        assert_eq!(received(&mut b), Some(b'b'));
    }

    /// The wrong sequence: the CPU does not read DR for 1 ms (a flash erase stalls it for far
    /// longer) while ten bytes arrive. Without DMA the first byte stays in RDR, ORE sets and the
    /// other nine are lost; it takes an SR read then a DR read to clear ORE.
    #[test]
    fn bytes_arriving_while_the_cpu_does_not_read_are_lost_to_an_overrun() {
        let mut b = receiver(7);
        let t0 = b.t;
        b.board.push_uart_rx(b"0123456789", t0);
        b.wait(MS);
        assert_eq!(b.read(USART1 + usart::SR) & (RXNE | ORE), RXNE | ORE);
        assert_eq!(b.read(USART1 + usart::DR), u32::from(b'0'));
        assert_eq!(b.read(USART1 + usart::SR) & (RXNE | ORE), 0);
        assert_eq!(b.board.usart1.rx_counts(), (10, 9, 0));
    }

    /// The right one: DMA2 stream 5, channel 4 (table 28), circular into an SRAM ring, with
    /// DMAR: every byte lands in memory while the CPU reads nothing, and the ring wraps.
    #[test]
    fn a_circular_dma2_stream_keeps_every_byte_while_the_cpu_does_not_read() {
        let mut b = receiver(7);
        b.enable(RCC_AHB1ENR, 22);
        b.write(S5CR + 0x08, USART1 + usart::DR);
        b.write(S5CR + 0x0C, BUF);
        b.write(S5CR + 0x04, 8);
        b.write(S5CR, (4 << 25) | (1 << 10) | (1 << 8) | (1 << 4) | 1);
        b.write(USART1 + usart::CR3, DMAR);
        let t0 = b.t;
        b.board.push_uart_rx(b"0123456789", t0);
        b.wait(MS);
        let writes = b.board.take_memory_writes();
        let expected: Vec<(u32, u8)> = (0..10u32).map(|i| (BUF + i % 8, b'0' + i as u8)).collect();
        assert_eq!(writes, expected);
        assert_eq!(b.read(USART1 + usart::SR) & (RXNE | ORE), 0);
        assert_eq!(b.read(S5CR + 0x04), 6, "NDTR: 8 reloaded at the wrap, 2 moved since");
        assert!(b.line(irq::DMA2_STREAM5), "TCIE: the wrap raised the stream's interrupt");
    }

    /// The same stream on the wrong channel (0) is refused at EN; with DMA2's clock off the
    /// registers are refused.
    #[test]
    fn dma2_on_the_wrong_channel_or_without_its_clock_is_refused() {
        let mut b = receiver(7);
        assert!(b.try_write(S5CR + 0x04, 8).is_err(), "DMA2 clock (AHB1ENR bit 22) off");
        b.enable(RCC_AHB1ENR, 22);
        b.write(S5CR + 0x08, USART1 + usart::DR);
        b.write(S5CR + 0x0C, BUF);
        b.write(S5CR + 0x04, 8);
        assert!(b.try_write(S5CR, (1 << 10) | (1 << 8) | 1).is_err());
    }
}

/// The flash interface on the core (RM0368 §3.5): hand-assembled programs run from flash in the
/// emulated Cortex-M4 with the board's models. Writes into flash reach the flash model through
/// Unicorn's write-protection hook (flash is mapped read-only; see `machine.rs`).
mod flash_program {
    use super::*;
    use fcu_pil::elf::{Image, Segment};
    use fcu_pil::machine::Machine;
    use fcu_pil::timing::TimingProfile;

    const FLASH: u32 = 0x4002_3C00;
    const SECTOR1: u32 = 0x0800_4000;
    const RESULTS: u32 = 0x2000_0000;

    fn movw(rd: u16, imm: u32) -> [u16; 2] {
        let (imm4, i, imm3, imm8) = ((imm >> 12) & 0xF, (imm >> 11) & 1, (imm >> 8) & 7, imm & 0xFF);
        [0xF240 | ((i as u16) << 10) | imm4 as u16, ((imm3 as u16) << 12) | (rd << 8) | imm8 as u16]
    }

    fn movt(rd: u16, imm: u32) -> [u16; 2] {
        let [a, b] = movw(rd, imm);
        [a | 0x0080, b]
    }

    fn mov32(rd: u16, v: u32) -> Vec<u16> {
        [movw(rd, v & 0xFFFF), movt(rd, v >> 16)].concat()
    }

    /// `str rt, [rn, #imm]` / `ldr rt, [rn, #imm]` (T1, word offsets).
    fn str_(rt: u16, rn: u16, imm: u16) -> u16 {
        0x6000 | ((imm / 4) << 6) | (rn << 3) | rt
    }

    fn ldr(rt: u16, rn: u16, imm: u16) -> u16 {
        0x6800 | ((imm / 4) << 6) | (rn << 3) | rt
    }

    /// Unlocks with `keys`, writes CR = `cr`, stores 0x1234_5678 at the start of sector 1 unless
    /// `cr` starts an erase (r4 and r7 hold markers across it), waits for BSY to clear, reads the
    /// word back; stores the word, r4 and r7 at `RESULTS`; then `b .`.
    fn program(keys: [u32; 2], cr: u32) -> Image {
        program_crs(keys, &[cr])
    }

    /// [`program`] with several CR writes in a row (no instruction between but the loads).
    fn program_crs(keys: [u32; 2], crs: &[u32]) -> Image {
        let mut code: Vec<u16> = Vec::new();
        code.extend(mov32(0, FLASH));
        for key in keys {
            code.extend(mov32(1, key));
            code.push(str_(1, 0, 0x04));
        }
        for &cr in crs {
            code.extend(mov32(1, cr));
            code.push(str_(1, 0, 0x10));
        }
        code.extend(mov32(2, SECTOR1));
        code.extend(mov32(3, 0x1234_5678));
        code.extend(mov32(4, 0x4444_4444));
        code.extend(mov32(7, 0x7777_7777));
        if crs.iter().all(|cr| cr & (1 << 16) == 0) {
            code.push(str_(3, 2, 0));
        }
        // Wait while BSY (SR bit 16): ldr r5, [r0, #0xC]; lsls r5, r5, #15; bmi back.
        code.extend([ldr(5, 0, 0x0C), 0x03ED, 0xD4FC]);
        code.push(ldr(6, 2, 0));
        code.extend(mov32(1, RESULTS));
        code.extend([str_(6, 1, 0), str_(4, 1, 4), str_(7, 1, 8)]);
        code.push(0xE7FE);
        let mut flash = vec![0u8; 0x400];
        let mut word = |at: usize, w: u32| flash[at..at + 4].copy_from_slice(&w.to_le_bytes());
        word(0, 0x2001_0000);
        word(4, 0x0800_0101);
        // HardFault: a `b .` at 0x300.
        word(12, 0x0800_0301);
        for (i, h) in code.iter().enumerate() {
            flash[0x100 + 2 * i..0x102 + 2 * i].copy_from_slice(&h.to_le_bytes());
        }
        flash[0x300..0x302].copy_from_slice(&0xE7FEu16.to_le_bytes());
        Image {
            path: "flash_program".into(),
            segments: vec![Segment { address: 0x0800_0000, data: flash }],
            initial_sp: 0x2001_0000,
            symbols: HashMap::new(),
            symbol_sizes: HashMap::new(),
            functions: Vec::new(),
            flash_bytes: 0x400,
            ram_bytes: 0,
        }
    }

    fn run(image: Image, profile: TimingProfile, until: Time) -> Machine<Board> {
        let mut m = Machine::new(image, Board::new(), profile).expect("machine");
        m.run_until(until).unwrap_or_else(|f| panic!("{f}"));
        m
    }

    fn words(m: &Machine<Board>, addr: u32, n: usize) -> Vec<u32> {
        let bytes = m.read_memory(addr, 4 * n).expect("memory");
        bytes.chunks(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
    }

    const PG_X32: u32 = 1 | (0b10 << 8);

    /// RM0368 §3.5.4 on the core: the store programs the word (16 µs, the fetch after it stalled
    /// until BSY cleared), the read-back and the flash's boot alias see it, and the registers
    /// around the store survive (the reason no memory hook covers flash), under both timing
    /// profiles.
    #[test]
    fn a_word_programmed_by_the_cpu_reads_back_and_the_registers_survive() {
        for profile in [TimingProfile::Optimistic, TimingProfile::Pessimistic] {
            let m = run(program([0x4567_0123, 0xCDEF_89AB], PG_X32), profile, MS);
            assert_eq!(words(&m, RESULTS, 3), vec![0x1234_5678, 0x4444_4444, 0x7777_7777], "{profile}");
            assert_eq!(words(&m, SECTOR1, 1), vec![0x1234_5678]);
            assert_eq!(words(&m, SECTOR1 - 0x0800_0000, 1), vec![0x1234_5678], "boot alias");
            assert_eq!(m.board().flash.memory()[0x4000..0x4004], 0x1234_5678u32.to_le_bytes());
            let stall = m.state().flash_stall_time;
            assert!(stall > 0 && stall <= 16 * US, "{profile}: stalled {stall} units");
            assert!(m.state().hard_faults.is_empty());
        }
    }

    /// RM0368 §3.5: a data read from flash stalls while BSY, as a fetch does. A literal load
    /// right after the programming store, in the same block, waits for the word: the FLASH_SR
    /// read after it sees BSY clear. Without the literal load the same read comes while BSY
    /// (a register read does not wait). Pessimistic profile: its accesses are dated where they
    /// run in the block.
    #[test]
    fn a_data_read_from_flash_right_after_a_program_waits_for_it() {
        for literal in [true, false] {
            let mut code: Vec<u16> = Vec::new();
            code.extend(mov32(0, FLASH));
            for key in [0x4567_0123, 0xCDEF_89AB] {
                code.extend(mov32(1, key));
                code.push(str_(1, 0, 0x04));
            }
            code.extend(mov32(1, PG_X32));
            code.push(str_(1, 0, 0x10));
            code.extend(mov32(2, SECTOR1));
            code.extend(mov32(3, 0x1234_5678));
            code.extend(mov32(4, RESULTS));
            code.push(str_(3, 2, 0));
            if literal {
                code.push(0x4900); // ldr r1, [pc, #0]: a word of this code, in flash
            }
            code.push(ldr(5, 0, 0x0C));
            code.push(str_(5, 4, 0));
            code.push(0xE7FE);
            let m = run(with_code(&code), TimingProfile::Pessimistic, MS);
            let sr = words(&m, RESULTS, 1)[0];
            assert_eq!(sr & (1 << 16) == 0, literal, "literal load {literal}: SR read {sr:#x}");
        }
    }

    /// The wrong sequence: the store without PG. PGSERR, and the word stays erased in the model
    /// and in the core's view of it (Unicorn's copy is restored from the model).
    #[test]
    fn a_store_into_flash_without_pg_sets_pgserr_and_leaves_the_word_erased() {
        let mut m = run(program([0x4567_0123, 0xCDEF_89AB], 0b10 << 8), TimingProfile::Optimistic, MS);
        assert_eq!(words(&m, RESULTS, 1), vec![0xFFFF_FFFF]);
        assert_eq!(words(&m, SECTOR1, 1), vec![0xFFFF_FFFF]);
        assert_eq!(m.board_mut().read(FLASH + 0x0C, 4, MS).unwrap() & 0x80, 0x80, "PGSERR");
    }

    /// The wrong sequence: the keys in the wrong order. A bus error (HardFault) on the core, and
    /// CR stays locked until the next reset.
    #[test]
    fn a_wrong_key_order_is_a_hard_fault_and_leaves_cr_locked() {
        let mut m = run(program([0xCDEF_89AB, 0x4567_0123], PG_X32), TimingProfile::Optimistic, MS);
        assert_eq!(m.state().hard_faults.len(), 1, "{:?}", m.state().hard_faults);
        assert!(m.state().hard_faults[0].cause.contains("FLASH_KEYR"));
        assert_eq!(m.board_mut().read(FLASH + 0x10, 4, MS).unwrap() >> 31, 1, "LOCK");
        assert_eq!(words(&m, SECTOR1, 1), vec![0xFFFF_FFFF]);
    }

    /// A power cut at every eighth of a sector erase started on the core: the memory the next
    /// power-on finds holds the sweep up to that point (erased words, then the word under
    /// erase part-way, then the old contents), and a new board powered on with it keeps it.
    #[test]
    fn a_power_cut_at_each_eighth_of_an_erase_leaves_the_sector_part_erased() {
        let cr = (1 << 16) | (0b10 << 8) | (1 << 3) | 0b10; // STRT, x32, SNB 1, SER
        for eighth in 1..8u64 {
            let mut board = Board::new();
            board.flash.load_memory(&vec![0u8; 0x8000]);
            let mut m = Machine::new(program([0x4567_0123, 0xCDEF_89AB], cr), board, TimingProfile::Optimistic).expect("machine");
            m.run_until(MS).unwrap_or_else(|f| panic!("{f}"));
            let (start, end, erase) = m.board().flash.operation().expect("erasing");
            assert!(erase);
            let at = start + (end - start) * eighth / 8;
            m.run_until(at).unwrap_or_else(|f| panic!("{f}"));
            m.board_mut().flash.power_cut(at);
            let contents = m.board().flash.memory().to_vec();
            let sector = &contents[0x4000..0x8000];
            let erased = sector.iter().position(|&b| b != 0xFF).unwrap_or(sector.len());
            let expected = 0x4000 * eighth as usize / 8;
            assert!(erased.abs_diff(expected) <= 4, "eighth {eighth}: {erased} bytes erased, expected about {expected}");
            assert!(sector[(erased + 4).min(0x4000)..].iter().all(|&b| b == 0), "eighth {eighth}: the rest intact");
            // Power on again with what the cut left: the image's sector 0 is the image's, sector 1
            // is the cut's.
            let mut board = Board::new();
            board.flash.load_memory(&contents);
            let again = Machine::new(program([0, 0], 0), board, TimingProfile::Optimistic).expect("machine");
            assert_eq!(again.read_memory(SECTOR1, 0x4000).unwrap(), sector, "eighth {eighth}");
        }
    }

    /// The wrong sequence: CR written again right after STRT, without waiting for BSY. The
    /// write stalls the bus until the erase ends (RM0368 §3.8.5), then takes effect: the core
    /// stands still for the whole erase.
    #[test]
    fn a_cr_write_during_an_erase_stalls_until_it_ends() {
        let erase = (1 << 16) | (0b10 << 8) | (1 << 3) | 0b10;
        let mut m = run(program_crs([0x4567_0123, 0xCDEF_89AB], &[erase, 1 << 31]), TimingProfile::Pessimistic, 300 * MS);
        let stall = m.state().flash_stall_time;
        assert!((249 * MS..=250 * MS).contains(&stall), "stalled {stall} units");
        assert_eq!(m.board_mut().read(FLASH + 0x10, 4, 300 * MS).unwrap() >> 31, 1, "LOCK written after the erase");
        assert!(m.board().flash.memory()[0x4000..0x8000].iter().all(|&b| b == 0xFF));
    }

    /// A program of register writes (r0 = address, r1 = value, `str r1, [r0]`), then `b .`.
    fn register_writes(writes: &[(u32, u32)]) -> Image {
        let mut code: Vec<u16> = Vec::new();
        for &(addr, value) in writes {
            code.extend(mov32(0, addr));
            code.extend(mov32(1, value));
            code.push(str_(1, 0, 0));
        }
        code.push(0xE7FE);
        with_code(&code)
    }

    /// An image whose reset handler is `code` (at 0x100, the rest of the flash zeroed; the
    /// vectors as [`program`]'s).
    fn with_code(code: &[u16]) -> Image {
        let mut image = program([0, 0], 0);
        let flash = &mut image.segments[0].data;
        flash[0x100..].fill(0);
        for (i, h) in code.iter().enumerate() {
            flash[0x100 + 2 * i..0x102 + 2 * i].copy_from_slice(&h.to_le_bytes());
        }
        image
    }

    /// The reason for circular DMA on USART1 RX (issue 21's flash stall): the core starts a
    /// 250 ms sector erase and stalls on its next fetch while the host sends 40 bytes. With
    /// DMA2 stream 5 circular into a 16-byte ring every byte is stored (the ring holds the last
    /// 16, in ring order); without DMA (the wrong set-up) the first byte waits in RDR, ORE is
    /// set, the other 39 are lost.
    #[test]
    fn bytes_arriving_during_an_erase_stall_are_kept_by_circular_dma_and_lost_without() {
        const RING: u32 = 0x2000_8000;
        let s5 = 0x4002_6400 + 0x10 + 5 * 0x18;
        for dma in [true, false] {
            let mut writes = vec![
                // AHB1ENR resets with CCMDATARAMEN (bit 20) set.
                (RCC_AHB1ENR, 1 | (1 << 20) | (1 << 22)),
                (RCC_APB2ENR, 1 << 4),
                (GPIO[PA] + AFRH, 7 << 8),
                (GPIO[PA] + MODER, 0b10 << 20),
                // 115 200 baud from the 16 MHz HSI: 16e6 / 115200 = 138.9.
                (USART1 + usart::BRR, 139),
                (USART1 + usart::CR1, usart::UE | usart::RE),
            ];
            if dma {
                writes.extend([
                    (s5 + 0x08, USART1 + usart::DR),
                    (s5 + 0x0C, RING),
                    (s5 + 0x04, 16),
                    (s5, (4 << 25) | (1 << 10) | (1 << 8) | 1),
                    (USART1 + usart::CR3, 1 << 6),
                ]);
            }
            let erase = (1 << 16) | (0b10 << 8) | (1 << 3) | 0b10;
            writes.extend([(FLASH + 0x04, 0x4567_0123), (FLASH + 0x04, 0xCDEF_89AB), (FLASH + 0x10, erase)]);
            let mut m = Machine::new(register_writes(&writes), Board::new(), TimingProfile::Pessimistic).expect("machine");
            m.run_until(MS).unwrap_or_else(|f| panic!("{f}"));
            assert!(m.board().flash.busy_until().is_some(), "erasing");
            let sent: Vec<u8> = (0..40).map(|i| b'A' + i).collect();
            m.board_mut().push_uart_rx(&sent, MS);
            m.run_until(300 * MS).unwrap_or_else(|f| panic!("{f}"));
            assert!(m.state().flash_stall_time >= 249 * MS, "the core stalled through the bytes");
            let (received, overrun, _) = m.board().usart1.rx_counts();
            let sr = m.board_mut().read(USART1 + usart::SR, 4, 300 * MS).unwrap();
            if dma {
                let ring = m.read_memory(RING, 16).unwrap();
                let expected: Vec<u8> = (0..16).map(|k| sent[if k < 8 { 32 + k } else { 16 + k }]).collect();
                assert_eq!(ring, expected, "bytes 24..39 in ring order");
                assert_eq!((received, overrun, sr & (1 << 3)), (40, 0, 0));
            } else {
                assert_eq!((received, overrun, sr & (1 << 3)), (40, 39, 1 << 3), "ORE");
                assert_eq!(m.board_mut().read(USART1 + usart::DR, 4, 300 * MS).unwrap(), u32::from(b'A'));
            }
        }
    }

    /// A power cut armed at 3/8 of the next erase: the board loses power there (the machine
    /// records it and powers on again: the program runs from its reset vector and starts the
    /// erase anew), and the sector holds what the cut left until the new erase ends.
    #[test]
    fn an_armed_power_cut_falls_at_its_fraction_and_the_board_powers_on_again() {
        let cr = (1 << 16) | (0b10 << 8) | (1 << 3) | 0b10; // STRT, x32, SNB 1, SER
        let mut board = Board::new();
        board.flash.load_memory(&vec![0u8; 0x8000]);
        board.flash.arm_power_cut(fcu_pil::periph::flash::ArmedCut { erase: true, nth: 1, fraction: 0.375 });
        let mut m = Machine::new(program([0x4567_0123, 0xCDEF_89AB], cr), board, TimingProfile::Optimistic).expect("machine");
        m.run_until(100 * MS).unwrap_or_else(|f| panic!("{f}"));
        let resets = m.state().resets.clone();
        assert_eq!(resets.len(), 1, "{resets:?}");
        assert_eq!(resets[0].1, "power cut");
        let (start, end, _) = m.board().flash.operation().expect("the erase restarted after power-on");
        // The optimistic profile dates the first block's register writes at its start: the
        // power-on instant itself.
        assert!(start >= resets[0].0, "a new erase, not the cut one: {start} {resets:?}");
        let cut_s = resets[0].0 as f64 / TIME_HZ as f64;
        assert!((cut_s - 0.375 * 0.25).abs() < 1e-4, "cut at {cut_s} s, 3/8 of 250 ms after the erase began");
        assert!((end - start) as f64 / TIME_HZ as f64 > 0.249);
        let sector = &m.board().flash.memory()[0x4000..0x8000];
        let erased = sector.iter().position(|&b| b != 0xFF).unwrap_or(sector.len());
        assert!(erased.abs_diff(0x4000 * 3 / 8) <= 4, "{erased} bytes erased");
        assert_eq!(m.read_memory(SECTOR1, 0x4000).unwrap(), sector, "the core sees the cut's contents");
    }

    /// A reboot (the watchdog, the firmware's reset request) keeps what the flash holds; the
    /// flash interface's registers go back to reset (locked).
    #[test]
    fn a_reboot_keeps_the_flash_contents_and_relocks_cr() {
        let mut b = Bench::new();
        b.write(FLASH + 0x04, 0x4567_0123);
        b.write(FLASH + 0x04, 0xCDEF_89AB);
        b.write(FLASH + 0x10, PG_X32);
        let t = b.step();
        b.board.flash_memory_write(0x4000, 4, 0xCAFE_F00D, t).expect("program");
        b.wait(MS);
        b.board.system_reset(true);
        assert_eq!(b.board.flash.memory()[0x4000..0x4004], 0xCAFE_F00Du32.to_le_bytes());
        assert_eq!(b.read(FLASH + 0x10) >> 31, 1, "LOCK after the reset");
    }

    /// A sector erase started from flash stalls the core for DS9716's 250 ms (x32, typical):
    /// the next instruction fetch waits for BSY to clear.
    #[test]
    fn a_sector_erase_stalls_the_core_for_250_ms() {
        let cr = (1 << 16) | (0b10 << 8) | (1 << 3) | 0b10; // STRT, x32, SNB 1, SER
        let m = run(program([0x4567_0123, 0xCDEF_89AB], cr), TimingProfile::Optimistic, 300 * MS);
        let stall = m.state().flash_stall_time;
        assert!((249 * MS..=250 * MS).contains(&stall), "stalled {stall} units");
        assert_eq!(words(&m, RESULTS, 1), vec![0xFFFF_FFFF], "read back erased");
    }
}

/// `fcu-pil/RULES.md` names only tests that exist, and names every test of this file.
#[test]
fn the_rules_index_matches_the_tests() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let index = std::fs::read_to_string(root.join("RULES.md")).expect("fcu-pil/RULES.md");
    let source = |rel: &str| std::fs::read_to_string(root.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    let here = source("tests/rule_book.rs");
    let mut named = Vec::new();
    for path in index.split('`').skip(1).step_by(2).filter(|s| s.contains("::")) {
        let parts: Vec<&str> = path.split("::").collect();
        let file = match parts.as_slice() {
            ["rule_book", ..] => "tests/rule_book.rs".to_string(),
            ["image", ..] => "tests/image.rs".to_string(),
            ["board", ..] => "src/board.rs".to_string(),
            // A model in its own file under its bus's module (periph/sensors/lps22hb.rs).
            ["periph", module, sub, "tests", _] => format!("src/periph/{module}/{sub}.rs"),
            ["periph", module, ..] => format!("src/periph/{module}.rs"),
            _ => continue,
        };
        let name = parts.last().copied().unwrap_or_default();
        let text = if file == "tests/rule_book.rs" { here.clone() } else { source(&file) };
        assert!(text.contains(&format!("fn {name}(")), "RULES.md names `{path}`, but {file} has no fn {name}");
        for module in &parts[1..parts.len() - 1] {
            if *module != "tests" {
                assert!(
                    text.contains(&format!("mod {module} "))
                        || file.ends_with(&format!("{module}.rs"))
                        || file.contains(&format!("/{module}/")),
                    "RULES.md: no module {module} in {file}"
                );
            }
        }
        named.push(path.to_string());
    }
    let mut module = String::new();
    let mut pending_test = false;
    for line in here.lines() {
        let l = line.trim_start();
        if let Some(rest) = l.strip_prefix("mod ") {
            module = rest.trim_end_matches(" {").to_string();
        }
        if l == "#[test]" {
            pending_test = true;
        } else if pending_test {
            if let Some(rest) = l.strip_prefix("fn ") {
                let name = rest.split('(').next().unwrap_or_default();
                let path = if line.starts_with("fn ") { format!("rule_book::{name}") } else { format!("rule_book::{module}::{name}") };
                assert!(named.contains(&path), "RULES.md does not list `{path}`");
            }
            pending_test = false;
        }
    }
}
