//! The STEVAL-FCU001V1 around the core: the peripheral models at their addresses (RM0368
//! table 1), gated by their RCC clock enables, and the board's wiring between them: the radio
//! receiver on PA0..PA3 (TIM2 CH1..4), the motors on TIM4 CH1..4, the three sensors' chip
//! selects on PA8, PB12 and PC13 for SPI2, the LEDs on PB5 and PB4, the battery divider on
//! PB1 (ADC1 channel 9) and the debug UART on USART1 (TX on PA9; RX on PA10, fed by the host
//! with [`Board::push_uart_rx`] and served by DMA2 when the firmware asks).
//!
//! Pins reach their peripherals through GPIO as on the chip (RM0368 §8.3.2, §8.3.7): only in
//! alternate-function mode with the peripheral's AF number (STM32F401xB/C datasheet, table
//! "Alternate function mapping"). With any other mode or number:
//! - a radio edge on PA0..PA3 is not captured by TIM2 (AF1), though IDR still shows the level;
//! - TIM4's compare does not reach PB6..PB9 (AF2): the MOSFET gates are pulled low;
//! - SPI2's frames do not reach the sensors unless both SCK (PB13) and the data line (PB15) are
//!   AF5: the model then deselects every sensor, so none is clocked and the receiver reads an
//!   undriven line. (On the chip a sensor would keep its transaction open with no clock; the
//!   model ends it. Frames clocked meanwhile count as I²C exposures, which the chip would not
//!   have: only wrong firmware gets there.)
//! - a USART1 frame leaves on PA9 only if the pin was AF7 from its start bit to its stop bits;
//!   otherwise it is recorded in [`Records::uart_lost`], not in [`Records::uart`]. So is a frame
//!   the host cannot read: sent at a baud rate more than [`HOST_BAUD_TOLERANCE`] off its
//!   115 200, or garbled by a BRR write during it.
//! - a byte the host sends reaches USART1's receiver only if PA10 was AF7 from its start bit on
//!   and USART1's clock runs; otherwise it is recorded in [`Records::uart_rx_lost`].
//!
//! The flash memory (the FLASH model's) survives a reset, and a power cut; a power-on takes
//! the image's sectors from the ELF and the others from the model (a saved file).
//!
//! The ADC's path is wired to the pad whatever the pin's mode (RM0368 §8.3.12 and the I/O
//! structure figures of §8.3: the analog connection is taken ahead of the Schmitt trigger and the
//! output driver), so a conversion of PB1 reads the battery divider unless the port drives the
//! pin itself (push-pull output, or open-drain driving low). The weak pull-up or pull-down of an
//! input (about 40 kΩ against the divider's 10/20 kΩ) is not modelled.
//!
//! Switching a pin's routing while its input level differs from what the peripheral last saw
//! would, on the chip, show the peripheral an edge; the model does not produce one.

use std::collections::VecDeque;

use crate::machine::{Peripherals, SYSMEM_PAGE};
use crate::periph::rcc::Bus::{Ahb1, Apb1, Apb2};
use crate::periph::{self, adc, dbgmcu, dma, flash, gpio, irq, iwdg, pwr, rcc, spi, tim, usart, Peripheral, Time, Unmodelled};

/// A chip-select or LED pin: (port index 0 = A, pin).
const CS_PINS: [(usize, u8); 3] = [(0, 8), (1, 12), (2, 13)];
const LED1: (usize, u8) = (1, 5);
const LED2: (usize, u8) = (1, 4);

/// The alternate functions the board's wiring needs (STM32F401xB/C datasheet, table "Alternate
/// function mapping"): TIM2_CH1..4 on PA0..PA3, TIM4_CH1..4 on PB6..PB9, SPI2_SCK on PB13 and
/// SPI2_MOSI (the bidirectional data line) on PB15, USART1_TX on PA9.
const AF_TIM2: u8 = 1;
const AF_TIM4: u8 = 2;
const AF_SPI2: u8 = 5;
const AF_USART1: u8 = 7;
/// PA0..PA3: the radio's four channels, in TIM2 channel order.
const RADIO_PORT: usize = 0;
/// PB6..PB9: the motors, in TIM4 channel order.
const MOTOR_PORT: usize = 1;
const MOTOR_PIN_0: u8 = 6;
const SPI2_SCK: (usize, u8) = (1, 13);
const SPI2_DATA: (usize, u8) = (1, 15);
const USART1_TX: (usize, u8) = (0, 9);
/// PA10: USART1_RX (AF7), the line from the host.
const USART1_RX: (usize, u8) = (0, 10);
/// PB1: ADC1_IN9, the battery divider.
const BATTERY_PIN: (usize, u8) = (1, 1);

/// The host at the other end of the debug UART listens at 115 200 baud, 8N1.
pub const HOST_BAUD: f64 = 115_200.0;
/// How far a frame's baud rate may be off [`HOST_BAUD`] and still be read. Assumption: the
/// host's receiver tolerates what RM0368 §19.3.5 gives the USART's own receiver (3.75 % for
/// 8-bit frames, 16× oversampling, DIV_Fraction = 0, noise counted as an error).
pub const HOST_BAUD_TOLERANCE: f64 = 0.0375;

/// What the board recorded for the measurements and the tests.
#[derive(Clone, Debug, Default)]
pub struct Records {
    /// Each write to a TIM4 compare register: (time, channel, value).
    pub ccr_writes: Vec<(Time, usize, u32)>,
    /// TIM2 capture latency: (capture time, time the firmware read the capture register).
    pub capture_reads: Vec<(Time, Time)>,
    /// LED levels (lit = pin low) whenever they change: (time, led1, led2).
    pub leds: Vec<(Time, bool, bool)>,
    /// UART bytes with the time their stop bit ended.
    pub uart: Vec<(Time, u8)>,
    /// Bytes USART1 sent that the host did not receive, with the time their stop bit ended: PA9
    /// was not in AF7 for the whole frame, BRR changed during it, or its baud rate was more
    /// than [`HOST_BAUD_TOLERANCE`] off [`HOST_BAUD`].
    pub uart_lost: Vec<(Time, u8)>,
    /// Bytes the host sent on PA10 that USART1's receiver never saw, with the end of their stop
    /// bit: PA10 was not USART1_RX (AF7) for the whole frame, or USART1's clock was off.
    pub uart_rx_lost: Vec<(Time, u8)>,
    /// Time TIM9 was started (the control tick), each boot.
    pub tick_timer_starts: Vec<Time>,
    /// The last peripheral register read: (time, address, value). A firmware stuck in a
    /// polling loop is stuck on this register.
    pub last_read: Option<(Time, u32, u32)>,
}

/// A peripheral's clock enable in RCC: its bus and bit. Its reset bit sits at the same position
/// in the bus's reset register (RM0368 §6.3: RCC_AHB1ENR/_AHB1RSTR, _APB1ENR/_APB1RSTR,
/// _APB2ENR/_APB2RSTR).
type RccBit = (rcc::Bus, u32);

/// One peripheral on the board's bus: where it is, how RCC clocks and resets it, its interrupt
/// lines, and the model behind it. A new peripheral is a row here and a [`Peripheral`] model.
struct Slot {
    base: u32,
    name: &'static str,
    /// Its clock enable and reset bit in RCC. `None`: not gated by RCC and no reset bit (the
    /// IWDG runs on the LSI; RCC, FLASH and DBGMCU are always there).
    rcc: Option<RccBit>,
    /// Its interrupt lines: (IRQ number, RM0368 table 38; the model's line, see
    /// [`Peripheral::irq_line`]).
    irqs: &'static [(u32, usize)],
    /// The registers a report names: (offset, name).
    registers: &'static [(u32, &'static str)],
    /// The data register, where a narrow write is a write of that data rather than of a byte
    /// lane (the bus does a read-modify-write of the word elsewhere).
    data_register: Option<u32>,
    model: fn(&Board) -> &dyn Peripheral,
    model_mut: fn(&mut Board) -> &mut dyn Peripheral,
}

const TIM2_BASE: u32 = tim::TimerKind::Tim2.base();
const TIM4_BASE: u32 = tim::TimerKind::Tim4.base();

/// The peripherals at their addresses (RM0368 table 1), with their RCC bits (the enable
/// registers, RM0368 §6.3.9 to §6.3.12, and the matching reset registers) and their interrupt
/// lines (RM0368 table 38).
const SLOTS: [Slot; 16] = [
    Slot {
        base: TIM2_BASE,
        name: "TIM2",
        rcc: Some((Apb1, 0)),
        irqs: &[(irq::TIM2, 0)],
        registers: &[],
        data_register: None,
        model: |b| &b.tim2,
        model_mut: |b| &mut b.tim2,
    },
    Slot {
        base: TIM4_BASE,
        name: "TIM4",
        rcc: Some((Apb1, 2)),
        irqs: &[(irq::TIM4, 0)],
        registers: &[],
        data_register: None,
        model: |b| &b.tim4,
        model_mut: |b| &mut b.tim4,
    },
    Slot {
        base: iwdg::BASE,
        name: "IWDG",
        rcc: None,
        irqs: &[],
        registers: &[(0x0, "KR"), (0x4, "PR"), (0x8, "RLR"), (0xC, "SR")],
        data_register: None,
        model: |b| &b.iwdg,
        model_mut: |b| &mut b.iwdg,
    },
    Slot {
        base: spi::BASE,
        name: "SPI2",
        rcc: Some((Apb1, 14)),
        irqs: &[(irq::SPI2, 0)],
        registers: &[(spi::CR1, "CR1"), (spi::CR2, "CR2"), (spi::SR, "SR"), (spi::DR, "DR")],
        data_register: Some(spi::DR),
        model: |b| &b.spi2,
        model_mut: |b| &mut b.spi2,
    },
    Slot {
        base: pwr::BASE,
        name: "PWR",
        rcc: Some((Apb1, 28)),
        irqs: &[],
        registers: &[(0x0, "CR"), (0x4, "CSR")],
        data_register: None,
        model: |b| &b.pwr,
        model_mut: |b| &mut b.pwr,
    },
    Slot {
        base: usart::BASE,
        name: "USART1",
        rcc: Some((Apb2, 4)),
        irqs: &[(irq::USART1, 0)],
        registers: &[(0x0, "SR"), (usart::DR, "DR"), (0x8, "BRR"), (0xC, "CR1"), (0x10, "CR2"), (0x14, "CR3")],
        data_register: Some(usart::DR),
        model: |b| &b.usart1,
        model_mut: |b| &mut b.usart1,
    },
    Slot {
        base: adc::BASE,
        name: "ADC1",
        rcc: Some((Apb2, 8)),
        irqs: &[(irq::ADC, 0)],
        registers: &[(0x0, "SR"), (0x4, "CR1"), (0x8, "CR2")],
        data_register: None,
        model: |b| &b.adc,
        model_mut: |b| &mut b.adc,
    },
    Slot {
        base: tim::TimerKind::Tim9.base(),
        name: "TIM9",
        rcc: Some((Apb2, 16)),
        irqs: &[(irq::TIM1_BRK_TIM9, 0)],
        registers: &[],
        data_register: None,
        model: |b| &b.tim9,
        model_mut: |b| &mut b.tim9,
    },
    Slot {
        base: gpio::base('A').unwrap(),
        name: "GPIOA",
        rcc: Some((Ahb1, 0)),
        irqs: &[],
        registers: &[],
        data_register: None,
        model: |b| &b.gpio[0],
        model_mut: |b| &mut b.gpio[0],
    },
    Slot {
        base: gpio::base('B').unwrap(),
        name: "GPIOB",
        rcc: Some((Ahb1, 1)),
        irqs: &[],
        registers: &[],
        data_register: None,
        model: |b| &b.gpio[1],
        model_mut: |b| &mut b.gpio[1],
    },
    Slot {
        base: gpio::base('C').unwrap(),
        name: "GPIOC",
        rcc: Some((Ahb1, 2)),
        irqs: &[],
        registers: &[],
        data_register: None,
        model: |b| &b.gpio[2],
        model_mut: |b| &mut b.gpio[2],
    },
    Slot {
        base: rcc::BASE,
        name: "RCC",
        rcc: None,
        irqs: &[],
        registers: &[(0x0, "CR"), (0x4, "PLLCFGR"), (0x8, "CFGR"), (0xC, "CIR"), (0x74, "CSR")],
        data_register: None,
        model: |b| &b.rcc,
        model_mut: |b| &mut b.rcc,
    },
    Slot {
        base: flash::BASE,
        name: "FLASH",
        rcc: None,
        irqs: &[(irq::FLASH, 0)],
        registers: &[(0x0, "ACR"), (0x4, "KEYR"), (0x8, "OPTKEYR"), (0xC, "SR"), (0x10, "CR")],
        data_register: None,
        model: |b| &b.flash,
        model_mut: |b| &mut b.flash,
    },
    Slot {
        base: dma::BASE,
        name: "DMA1",
        rcc: Some((Ahb1, 21)),
        irqs: &[(irq::DMA1_STREAM3, dma::SPI2_RX_STREAM)],
        registers: &[(0x0, "LISR"), (0x4, "HISR"), (0x8, "LIFCR"), (0xC, "HIFCR")],
        data_register: None,
        model: |b| &b.dma1,
        model_mut: |b| &mut b.dma1,
    },
    Slot {
        base: dma::DMA2_BASE,
        name: "DMA2",
        rcc: Some((Ahb1, 22)),
        irqs: &[(irq::DMA2_STREAM2, 2), (irq::DMA2_STREAM5, 5)],
        registers: &[(0x0, "LISR"), (0x4, "HISR"), (0x8, "LIFCR"), (0xC, "HIFCR")],
        data_register: None,
        model: |b| &b.dma2,
        model_mut: |b| &mut b.dma2,
    },
    Slot {
        base: dbgmcu::BASE,
        name: "DBGMCU",
        rcc: None,
        irqs: &[],
        registers: &[(0x0, "IDCODE"), (0x4, "CR"), (0x8, "APB1_FZ"), (0xC, "APB2_FZ")],
        data_register: None,
        model: |b| &b.dbgmcu,
        model_mut: |b| &mut b.dbgmcu,
    },
];

/// Every peripheral's registers fit in 1 KiB from its base.
const SLOT_SIZE: u32 = 0x400;

/// The peripheral at `addr`, with the register's offset in it.
fn slot_at(addr: u32) -> Option<(&'static Slot, u32)> {
    let (base, offset) = (addr & !(SLOT_SIZE - 1), addr & (SLOT_SIZE - 1));
    SLOTS.iter().find(|s| s.base == base).map(|s| (s, offset))
}

/// A peripheral register's name for reports: `IWDG.SR`, `SPI2.SR`, `RCC.CR`, or the
/// peripheral and offset (`TIM2+0x010`).
pub fn register_name(addr: u32) -> String {
    match slot_at(addr) {
        Some((slot, offset)) => match slot.registers.iter().find(|(o, _)| *o == offset) {
            Some((_, reg)) => format!("{}.{reg}", slot.name),
            None => format!("{}+{offset:#05x}", slot.name),
        },
        None => format!("{addr:#010x}"),
    }
}

pub struct Board {
    pub rcc: rcc::Rcc,
    pub flash: flash::Flash,
    pub pwr: pwr::Pwr,
    pub gpio: [gpio::Gpio; 3],
    pub tim2: tim::Timer,
    pub tim4: tim::Timer,
    pub tim9: tim::Timer,
    pub spi2: spi::Spi2,
    pub usart1: usart::Usart,
    pub iwdg: iwdg::Iwdg,
    pub dma1: dma::Dma,
    pub dma2: dma::Dma,
    pub adc: adc::Adc,
    pub dbgmcu: dbgmcu::Dbgmcu,
    /// Radio edges still to happen: (time, channel, level after the edge).
    edges: VecDeque<(Time, usize, bool)>,
    /// When each channel's last capture happened (for the capture latency).
    last_capture: [Option<Time>; 4],
    pub records: Records,
    tim9_was_running: bool,
    /// Since when PA9 has been USART1_TX (None: it is not now).
    uart_tx_routed_since: Option<Time>,
    /// The battery divider's output (None until the harness sets a battery voltage).
    battery_divider_volts: Option<f64>,
    /// The host's side of USART1's receive line: frames still to arrive, in time order.
    uart_rx_line: VecDeque<RxFrame>,
    /// The burst the host is sending: its first frame's start and the frames scheduled in it.
    uart_rx_burst: Option<(Time, u64)>,
    /// Since when PA10 has been USART1_RX (None: it is not now).
    uart_rx_routed_since: Option<Time>,
}

/// A frame the host sends on PA10: start of its start bit, end of its stop bit, the byte.
#[derive(Clone, Copy, Debug)]
struct RxFrame {
    start: Time,
    end: Time,
    byte: u8,
}

impl Default for Board {
    fn default() -> Self {
        Self::new()
    }
}

impl Board {
    pub fn new() -> Board {
        Board {
            rcc: rcc::Rcc::new(),
            flash: flash::Flash::new(),
            pwr: pwr::Pwr::new(),
            gpio: [gpio::Gpio::new('A'), gpio::Gpio::new('B'), gpio::Gpio::new('C')],
            tim2: tim::Timer::new(tim::TimerKind::Tim2),
            tim4: tim::Timer::new(tim::TimerKind::Tim4),
            tim9: tim::Timer::new(tim::TimerKind::Tim9),
            spi2: spi::Spi2::new(),
            usart1: usart::Usart::new(),
            iwdg: iwdg::Iwdg::new(),
            dma1: dma::Dma::new(),
            dma2: dma::Dma::dma2(),
            adc: adc::Adc::new(),
            dbgmcu: dbgmcu::Dbgmcu::new(),
            edges: VecDeque::new(),
            last_capture: [None; 4],
            records: Records::default(),
            tim9_was_running: false,
            uart_tx_routed_since: None,
            battery_divider_volts: None,
            uart_rx_line: VecDeque::new(),
            uart_rx_burst: None,
            uart_rx_routed_since: None,
        }
    }

    /// Schedules a radio edge on PA0..PA3 (channel 0..3) at `at`; edges must come in time order.
    pub fn schedule_edge(&mut self, at: Time, channel: usize, level: bool) {
        self.edges.push_back((at, channel, level));
    }

    /// The compare values TIM4 drives at `now` (the preloaded values in force).
    pub fn motor_compares(&mut self, now: Time) -> [u16; 4] {
        let mut out = [0u16; 4];
        let running = self.is_clocked(TIM4_BASE);
        for (ch, o) in out.iter_mut().enumerate() {
            // Without its clock (or after a reset) TIM4's outputs are off, and a pin not routed
            // to TIM4 does not carry them: the MOSFET gates are pulled low.
            let driven = running && self.gpio[MOTOR_PORT].routes(MOTOR_PIN_0 + ch as u8, AF_TIM4);
            *o = if driven { self.tim4.pwm_compare(ch, now).min(u32::from(u16::MAX)) as u16 } else { 0 };
        }
        out
    }

    /// The LEDs now (lit = true).
    pub fn leds(&self) -> (bool, bool) {
        let lit = |(port, pin): (usize, u8)| self.gpio[port].output_level(pin) == Some(false);
        (lit(LED1), lit(LED2))
    }

    /// Sets the battery voltage the divider feeds to PB1.
    pub fn set_battery_volts(&mut self, volts: f64) {
        self.battery_divider_volts = Some(adc::battery_pin_volts(volts));
        self.refresh_battery_pin();
    }

    /// PB1 as ADC1_IN9 sees it: the divider, unless the port drives the pin.
    fn refresh_battery_pin(&mut self) {
        let Some(divider) = self.battery_divider_volts else {
            return;
        };
        let (port, pin) = BATTERY_PIN;
        let g = &self.gpio[port];
        let volts = match g.output_level(pin) {
            Some(false) => 0.0,
            Some(true) if !g.open_drain(pin) => adc::VDDA_VOLTS,
            _ => divider,
        };
        self.adc.set_channel_volts(adc::BATTERY_CHANNEL, volts);
    }

    /// Whether the peripheral at `base` has its clock (one RCC does not gate always has).
    fn is_clocked(&self, base: u32) -> bool {
        slot_at(base).is_some_and(|(slot, _)| slot.rcc.is_none_or(|(bus, bit)| self.rcc.is_enabled(bus, bit)))
    }

    fn forward_pins(&mut self, now: Time) {
        let changed = self.gpio.iter_mut().fold(false, |acc, g| g.take_pins_changed() | acc);
        if !changed {
            return;
        }
        // A chip select that is not driven low (input, or high) deselects its sensor; without
        // SCK and the data line on SPI2 no sensor is reached at all.
        let routed = |(port, pin): (usize, u8)| self.gpio[port].routes(pin, AF_SPI2);
        let bus_routed = routed(SPI2_SCK) && routed(SPI2_DATA);
        let cs_low = CS_PINS.map(|(port, pin)| bus_routed && self.gpio[port].output_level(pin) == Some(false));
        self.spi2.set_chip_selects(cs_low, now);
        let (port, pin) = USART1_TX;
        self.uart_tx_routed_since = match (self.gpio[port].routes(pin, AF_USART1), self.uart_tx_routed_since) {
            (true, since) => since.or(Some(now)),
            (false, _) => None,
        };
        self.track_uart_rx_pin(now);
        self.refresh_battery_pin();
        let (l1, l2) = self.leds();
        if self.records.leds.last().is_none_or(|&(_, a, b)| (a, b) != (l1, l2)) {
            self.records.leds.push((now, l1, l2));
        }
    }

    fn deliver_edges(&mut self, now: Time) {
        while let Some(&(at, channel, level)) = self.edges.front() {
            if at > now {
                break;
            }
            self.edges.pop_front();
            self.gpio[RADIO_PORT].set_external(channel as u8, Some(level));
            // TIM2 sees the pin only through AF1, and only with its clock on.
            if !self.gpio[RADIO_PORT].routes(channel as u8, AF_TIM2) || !self.is_clocked(TIM2_BASE) {
                continue;
            }
            // The capture unit latches the counter at the edge itself, whenever the firmware
            // looks at it.
            let before = self.tim2.captures(channel);
            self.tim2.capture(channel, level, at);
            if self.tim2.captures(channel) != before {
                if let Some(slot) = self.last_capture.get_mut(channel) {
                    *slot = Some(at);
                }
            }
        }
    }

    /// Every model learns the clocks RCC derives now (the timers count their APB's timer
    /// clock); returns them.
    fn sync_clocks(&mut self, now: Time) -> Result<periph::Clocks, Unmodelled> {
        let clocks = self.rcc.clocks()?;
        for slot in &SLOTS {
            (slot.model_mut)(self).set_clocks(now, clocks);
        }
        Ok(clocks)
    }

    fn route(&mut self, addr: u32, now: Time, op: Op) -> Result<u32, Unmodelled> {
        let clocks = self.sync_clocks(now)?;
        let Some((slot, offset)) = slot_at(addr) else {
            return Err(Unmodelled::new(format!("{addr:#010x}"), "no peripheral modelled at this address"));
        };
        if let Some((bus, bit)) = slot.rcc.filter(|&(bus, bit)| !self.rcc.is_enabled(bus, bit)) {
            return Err(Unmodelled::new(slot.name, format!("accessed while its clock is disabled in RCC ({bus:?} enable bit {bit})")));
        }
        if slot.base == iwdg::BASE {
            // The IWDG runs on the LSI (no enable bit in RCC): it learns when the LSI is ready.
            self.iwdg.set_lsi(self.rcc.lsi_ready_at());
        }
        let model = (slot.model_mut)(self);
        let value = match op {
            Op::Read => model.read(offset, now, clocks)?,
            Op::Write(v) => model.write(offset, v, now, clocks).map(|()| 0)?,
        };
        self.observe_access(slot.base, offset, op, now);
        Ok(value)
    }

    /// What the board does with an access the model took: the capture latency of a TIM2
    /// capture register read, TIM4's compare writes, and the IWDG's start key forcing the LSI
    /// on (RM0368 §17.3.2).
    fn observe_access(&mut self, base: u32, offset: u32, op: Op, now: Time) {
        let ccr = (tim::CCR1..tim::CCR1 + 16).contains(&offset).then(|| ((offset - tim::CCR1) / 4) as usize);
        match (base, op, ccr) {
            (TIM2_BASE, Op::Read, Some(ch)) => {
                if let Some(Some(at)) = self.last_capture.get_mut(ch).map(Option::take) {
                    self.records.capture_reads.push((at, now));
                }
            }
            (TIM4_BASE, Op::Write(value), Some(ch)) => self.records.ccr_writes.push((now, ch, value)),
            (iwdg::BASE, _, _) if self.iwdg.is_started() => {
                self.rcc.force_lsi_on(now);
                self.iwdg.set_lsi(self.rcc.lsi_ready_at());
            }
            _ => {}
        }
    }

    /// Moves the frames USART1 has finished by `now` to the records: on the wire if PA9 was
    /// USART1_TX all through the frame (the routing last changed before `now`, see
    /// [`Board::forward_pins`], so this runs before any write that may change it).
    fn collect_uart(&mut self, now: Time) -> Result<(), Unmodelled> {
        self.usart1.advance(now, self.rcc.clocks()?);
        for f in self.usart1.take_output() {
            let baud = periph::TIME_HZ as f64 / f.bit.max(1) as f64;
            let readable = f.intact && (baud / HOST_BAUD - 1.0).abs() <= HOST_BAUD_TOLERANCE;
            let on_wire = self.uart_tx_routed_since.is_some_and(|since| since <= f.start);
            if readable && on_wire {
                self.records.uart.push((f.end, f.byte));
            } else {
                self.records.uart_lost.push((f.end, f.byte));
            }
        }
        Ok(())
    }

    /// SPI2's received bytes that DMA1 stream 3 took go to memory, and SPI2 learns how many
    /// more the stream takes. After every access (a DMA register write may enable the stream)
    /// and every advance.
    fn serve_dma(&mut self) {
        for byte in self.spi2.take_dma_bytes() {
            self.dma1.spi2_rx(byte);
        }
        self.spi2.set_dma_budget(self.dma1.spi2_rx_capacity());
        self.serve_usart1_rx_dma();
    }

    fn after_access(&mut self, now: Time) -> Result<(), Unmodelled> {
        for r in self.rcc.take_reset_pulses() {
            self.reset_peripheral(r);
        }
        self.serve_dma();
        self.forward_pins(now);
        let tim9_running = self.tim9.started_at().is_some();
        if tim9_running && !self.tim9_was_running {
            if let Some(t) = self.tim9.started_at() {
                self.records.tick_timer_starts.push(t);
            }
        }
        self.tim9_was_running = tim9_running;
        // Flash wait states must suit HCLK before the clock goes up.
        let clocks = self.rcc.clocks()?;
        self.flash.check_wait_states(clocks.hclk_hz)
    }

    fn reset_peripheral(&mut self, bit: RccBit) {
        if let Some(slot) = SLOTS.iter().find(|slot| slot.rcc == Some(bit)) {
            (slot.model_mut)(self).reset();
        }
    }
}

/// USART1's receive side: the host's line on PA10, and DMA2 serving the receiver.
impl Board {
    /// The host sends `bytes` on PA10 at [`HOST_BAUD`], 8N1, back to back, from `not_before`
    /// or right after what it is still sending.
    pub fn push_uart_rx(&mut self, bytes: &[u8], not_before: Time) {
        /// Ten bits (start, 8 data, stop) per frame, in time units times the baud rate.
        const FRAME_UNITS_X_BAUD: u64 = 10 * periph::TIME_HZ;
        let baud = HOST_BAUD as u64;
        let line_end = self.uart_rx_line.back().map(|f| f.end);
        let (t0, mut k) = match (self.uart_rx_burst, line_end) {
            (Some(burst), Some(end)) if end >= not_before => burst,
            _ => (not_before, 0),
        };
        for &byte in bytes {
            let start = t0 + k * FRAME_UNITS_X_BAUD / baud;
            let end = t0 + (k + 1) * FRAME_UNITS_X_BAUD / baud;
            self.uart_rx_line.push_back(RxFrame { start, end, byte });
            k += 1;
        }
        self.uart_rx_burst = Some((t0, k));
    }

    /// How many of the host's frames have not ended yet.
    pub fn uart_rx_pending(&self) -> usize {
        self.uart_rx_line.len()
    }

    fn track_uart_rx_pin(&mut self, now: Time) {
        let (port, pin) = USART1_RX;
        self.uart_rx_routed_since = match (self.gpio[port].routes(pin, AF_USART1), self.uart_rx_routed_since) {
            (true, since) => since.or(Some(now)),
            (false, _) => None,
        };
    }

    /// The frames whose stop bits ended by `now` reach USART1's receiver if PA10 was AF7 from
    /// their start bit on and USART1's clock runs; a frame that lands with DMAR set goes on to
    /// DMA2 at once, one byte at a time, so a stalled CPU loses nothing a circular stream keeps.
    fn deliver_uart_rx(&mut self, now: Time) -> Result<(), Unmodelled> {
        while let Some(&frame) = self.uart_rx_line.front() {
            if frame.end > now {
                break;
            }
            self.uart_rx_line.pop_front();
            let on_pin = self.uart_rx_routed_since.is_some_and(|since| since <= frame.start);
            if !on_pin || !self.is_clocked(usart::BASE) {
                self.records.uart_rx_lost.push((frame.end, frame.byte));
                continue;
            }
            let clocks = self.rcc.clocks()?;
            let line_bit = (periph::TIME_HZ as f64 / HOST_BAUD).round() as Time;
            self.usart1.receive(frame.byte, frame.end, line_bit, clocks);
            self.serve_usart1_rx_dma();
        }
        Ok(())
    }

    /// USART1's pending receive DMA request, served if a DMA2 stream takes it.
    fn serve_usart1_rx_dma(&mut self) {
        if self.usart1.rx_dma_request() && self.is_clocked(dma::DMA2_BASE) && self.dma2.capacity(dma::Request::Usart1Rx) > 0 {
            let byte = self.usart1.dma_read();
            self.dma2.serve(dma::Request::Usart1Rx, byte);
        }
    }
}

#[derive(Clone, Copy)]
enum Op {
    Read,
    Write(u32),
}

impl Peripherals for Board {
    fn read(&mut self, addr: u32, size: u32, now: Time) -> Result<u32, Unmodelled> {
        self.deliver_edges(now);
        self.deliver_uart_rx(now)?;
        let word = self.route(addr & !3, now, Op::Read)?;
        self.records.last_read = Some((now, addr & !3, word));
        self.after_access(now)?;
        let lane = 8 * (addr & 3);
        let mask = if size >= 4 { u32::MAX } else { (1u32 << (8 * size)) - 1 };
        Ok((word >> lane) & mask)
    }

    fn write(&mut self, addr: u32, size: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.deliver_edges(now);
        self.deliver_uart_rx(now)?;
        self.collect_uart(now)?;
        let word = if size >= 4 {
            value
        } else {
            let is_data_register = slot_at(addr & !3).is_some_and(|(slot, offset)| slot.data_register == Some(offset));
            if is_data_register {
                // A narrow write to a data register is a write of that data.
                value & ((1u32 << (8 * size)) - 1)
            } else {
                let lane = 8 * (addr & 3);
                let mask = ((1u32 << (8 * size)) - 1) << lane;
                let old = self.route(addr & !3, now, Op::Read)?;
                (old & !mask) | ((value << lane) & mask)
            }
        };
        self.route(addr & !3, now, Op::Write(word))?;
        self.after_access(now)
    }

    fn next_event(&self) -> Option<Time> {
        let models = SLOTS.iter().filter_map(|slot| (slot.model)(self).next_event());
        let host_rx = self.uart_rx_line.front().map(|f| f.end);
        self.edges.front().map(|e| e.0).into_iter().chain(host_rx).chain(models).min()
    }

    fn advance(&mut self, now: Time, lines: &mut dyn FnMut(u32, bool)) -> Result<bool, Unmodelled> {
        self.deliver_edges(now);
        // The RCC first: the clocks the others run on come from it (its turn below is then a
        // no-op).
        self.rcc.advance(now);
        let clocks = self.sync_clocks(now)?;
        self.iwdg.set_lsi(self.rcc.lsi_ready_at());
        // The host's frames reach the receiver at their own instants, before USART1 catches up
        // to `now` (an idle line is flagged only if no frame came meanwhile).
        self.deliver_uart_rx(now)?;
        for slot in &SLOTS {
            (slot.model_mut)(self).advance(now, clocks);
        }
        self.serve_dma();
        self.collect_uart(now)?;
        for slot in &SLOTS {
            for &(irq, line) in slot.irqs {
                lines(irq, (slot.model)(self).irq_line(line));
            }
        }
        Ok(self.iwdg.expired(now))
    }

    fn take_memory_writes(&mut self) -> Vec<(u32, u8)> {
        let mut writes = self.dma1.take_memory_writes();
        writes.extend(self.dma2.take_memory_writes());
        writes
    }

    fn flash_memory_write(&mut self, offset: u32, size: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.flash.write_memory(offset, size, value, now)?;
        // The store went into the machine's copy too: it gets the model's bytes back.
        self.flash.touch(offset & !3, 4);
        Ok(())
    }

    fn take_flash_changes(&mut self) -> Vec<(u32, Vec<u8>)> {
        self.flash.take_changes()
    }

    fn flash_busy_until(&self) -> Option<Time> {
        self.flash.busy_until()
    }

    /// A sector the image programs (any byte not 0xFF) is the image's, as a flash tool that
    /// erases only the sectors it writes leaves it; the other sectors keep what the flash
    /// model holds (loaded from a file, or kept from an earlier boot).
    fn power_on_flash(&mut self, image: Vec<u8>) -> Vec<u8> {
        let mut contents = self.flash.memory().to_vec();
        for (offset, len) in flash::SECTORS {
            let range = offset as usize..(offset + len) as usize;
            if let (Some(src), Some(dst)) = (image.get(range.clone()), contents.get_mut(range)) {
                if src.iter().any(|&b| b != 0xFF) {
                    dst.copy_from_slice(src);
                }
            }
        }
        self.flash.load_memory(&contents);
        self.flash.take_changes();
        contents
    }

    fn take_bus_error(&mut self) -> Option<&'static str> {
        self.flash.take_bus_error()
    }

    fn take_power_cut(&mut self) -> bool {
        self.flash.take_power_lost()
    }

    fn nmi_line(&self) -> bool {
        self.rcc.nmi_line()
    }

    fn core_clock_stopped(&self) -> bool {
        self.rcc.core_clock_stopped()
    }

    /// A system reset, and what only a power-on resets: RCC's reset flags, DBGMCU.
    fn power_on_reset(&mut self) {
        self.system_reset(false);
        self.rcc.power_on_reset();
        self.dbgmcu = dbgmcu::Dbgmcu::new();
    }

    fn units_per_cycle(&self) -> Result<u64, Unmodelled> {
        let hz = self.rcc.clocks()?.hclk_hz;
        periph::units_per_cycle(hz)
            .ok_or_else(|| Unmodelled::new("RCC", format!("HCLK {hz} Hz does not divide the model's 336 MHz time base")))
    }

    fn system_reset(&mut self, watchdog: bool) {
        if watchdog {
            self.rcc.note_watchdog_reset();
        }
        let mut rcc = std::mem::take(&mut self.rcc);
        rcc.system_reset();
        let records = std::mem::take(&mut self.records);
        let edges = std::mem::take(&mut self.edges);
        // The host keeps sending through a reset.
        let rx_line = std::mem::take(&mut self.uart_rx_line);
        let rx_burst = self.uart_rx_burst;
        let sensors = self.spi2.take_sensors();
        let adc_inputs = self.adc.clone();
        // DBGMCU_CR, _APB1_FZ and _APB2_FZ are reset by a power-on reset only, not by a system
        // reset (RM0368 §23, their register descriptions).
        let dbgmcu = std::mem::take(&mut self.dbgmcu);
        let battery = self.battery_divider_volts;
        // The supply and the LSI's frequency are the board's and the chip's, not registers.
        let vdd_volts = self.pwr.vdd_volts();
        let lsi_hz = self.iwdg.lsi_hz();
        // The flash memory keeps its contents; an operation in progress is cut.
        let mut flash = std::mem::take(&mut self.flash);
        flash.system_reset();
        *self = Board::new();
        self.flash = flash;
        self.dbgmcu = dbgmcu;
        self.battery_divider_volts = battery;
        self.pwr.set_vdd_volts(vdd_volts);
        self.iwdg.set_lsi_hz(lsi_hz);
        self.rcc = rcc;
        self.records = records;
        self.edges = edges;
        self.uart_rx_line = rx_line;
        self.uart_rx_burst = rx_burst;
        // The sensors are powered by the board, not reset with the MCU.
        self.spi2.put_sensors(sensors);
        self.adc.copy_inputs_from(&adc_inputs);
        // The pins are inputs again: PB1 reads the divider.
        self.refresh_battery_pin();
    }

    fn system_memory_page(&self) -> Vec<u8> {
        let mut page = vec![0xFFu8; 0x1000];
        let cal = adc::vrefint_cal().to_le_bytes();
        let off = (adc::VREFINT_CAL_ADDR - SYSMEM_PAGE) as usize;
        if let Some(dst) = page.get_mut(off..off + 2) {
            dst.copy_from_slice(&cal);
        }
        page
    }
}
