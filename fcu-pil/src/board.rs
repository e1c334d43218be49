//! The STEVAL-FCU001V1 around the core: the peripheral models at their addresses (RM0368
//! table 1), gated by their RCC clock enables, and the board's wiring between them: the radio
//! receiver on PA0..PA3 (TIM2 CH1..4), the motors on TIM4 CH1..4, the three sensors' chip
//! selects on PA8, PB12 and PC13 for SPI2, the LEDs on PB5 and PB4, the battery divider on
//! PB1 (ADC1 channel 9) and the debug UART on USART1.

use std::collections::VecDeque;

use crate::machine::{Peripherals, SYSMEM_PAGE};
use crate::periph::{self, adc, dbgmcu, flash, gpio, iwdg, pwr, rcc, spi, tim, usart, Time, Unmodelled};

/// A chip-select or LED pin: (port index 0 = A, pin).
const CS_PINS: [(usize, u8); 3] = [(0, 8), (1, 12), (2, 13)];
const LED1: (usize, u8) = (1, 5);
const LED2: (usize, u8) = (1, 4);

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
    /// Time TIM9 was started (the control tick), each boot.
    pub tick_timer_starts: Vec<Time>,
    /// The last peripheral register read: (time, address, value). A firmware stuck in a
    /// polling loop is stuck on this register.
    pub last_read: Option<(Time, u32, u32)>,
}

/// A peripheral register's name for reports: `IWDG.SR`, `SPI2.SR`, `RCC.CR`, or the
/// peripheral and offset (`TIM2+0x010`).
pub fn register_name(addr: u32) -> String {
    const PERIPHERALS: [(u32, &str, &[&str]); 14] = [
        (0x4000_0000, "TIM2", &[]),
        (0x4000_0800, "TIM4", &[]),
        (0x4000_3000, "IWDG", &["KR", "PR", "RLR", "SR"]),
        (0x4000_3800, "SPI2", &["CR1", "CR2", "SR", "DR"]),
        (0x4000_7000, "PWR", &["CR", "CSR"]),
        (0x4001_1000, "USART1", &["SR", "DR", "BRR", "CR1", "CR2", "CR3"]),
        (0x4001_2000, "ADC1", &["SR", "CR1", "CR2"]),
        (0x4001_4000, "TIM9", &[]),
        (0x4002_0000, "GPIOA", &[]),
        (0x4002_0400, "GPIOB", &[]),
        (0x4002_0800, "GPIOC", &[]),
        (0x4002_3800, "RCC", &["CR", "PLLCFGR", "CFGR", "CIR"]),
        (0x4002_3C00, "FLASH", &["ACR", "KEYR", "OPTKEYR", "SR", "CR"]),
        (0xE004_2000, "DBGMCU", &["IDCODE", "CR", "APB1_FZ", "APB2_FZ"]),
    ];
    // RCC's registers past CIR are named only where a report needs them.
    if addr == 0x4002_3874 {
        return "RCC.CSR".into();
    }
    let (base, offset) = (addr & !0x3FF, addr & 0x3FF);
    match PERIPHERALS.iter().find(|(b, _, _)| *b == base) {
        Some((_, name, regs)) => match regs.get((offset / 4) as usize) {
            Some(reg) if offset % 4 == 0 => format!("{name}.{reg}"),
            _ => format!("{name}+{offset:#05x}"),
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
    pub adc: adc::Adc,
    pub dbgmcu: dbgmcu::Dbgmcu,
    /// Radio edges still to happen: (time, channel, level after the edge).
    edges: VecDeque<(Time, usize, bool)>,
    /// When each channel's last capture happened (for the capture latency).
    last_capture: [Option<Time>; 4],
    pub records: Records,
    tim9_was_running: bool,
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
            adc: adc::Adc::new(),
            dbgmcu: dbgmcu::Dbgmcu::new(),
            edges: VecDeque::new(),
            last_capture: [None; 4],
            records: Records::default(),
            tim9_was_running: false,
        }
    }

    /// Schedules a radio edge on PA0..PA3 (channel 0..3) at `at`; edges must come in time order.
    pub fn schedule_edge(&mut self, at: Time, channel: usize, level: bool) {
        self.edges.push_back((at, channel, level));
    }

    /// The compare values TIM4 drives at `now` (the preloaded values in force).
    pub fn motor_compares(&mut self, now: Time) -> [u16; 4] {
        let mut out = [0u16; 4];
        let running = self.rcc.is_enabled(rcc::Bus::Apb1, 2);
        for (ch, o) in out.iter_mut().enumerate() {
            // Without its clock (or after a reset) TIM4's outputs are off: the pins fall back
            // to inputs and the MOSFET gates are pulled low.
            let driven = running && self.gpio[1].mode(6 + ch as u8) == 2 && self.gpio[1].alternate(6 + ch as u8) == 2;
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
        self.adc.set_channel_volts(adc::BATTERY_CHANNEL, adc::battery_pin_volts(volts));
    }

    fn clock_check(&self, name: &str, bus: rcc::Bus, bit: u32) -> Result<(), Unmodelled> {
        if self.rcc.is_enabled(bus, bit) {
            Ok(())
        } else {
            Err(Unmodelled::new(name, format!("accessed while its clock is disabled in RCC ({bus:?} enable bit {bit})")))
        }
    }

    fn forward_pins(&mut self, now: Time) {
        let changed = self.gpio.iter_mut().fold(false, |acc, g| g.take_output_changed() | acc);
        if !changed {
            return;
        }
        // A chip select that is not driven low (input, or high) deselects its sensor.
        let cs_low = CS_PINS.map(|(port, pin)| self.gpio[port].output_level(pin) == Some(false));
        self.spi2.set_chip_selects(cs_low, now);
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
            self.gpio[0].set_external(channel as u8, Some(level));
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

    /// The timers count their APB's timer clock.
    fn sync_timer_clocks(&mut self, now: Time) -> Result<(), Unmodelled> {
        let c = self.rcc.clocks()?;
        let units = |hz: u64| {
            periph::units_per_cycle(hz)
                .ok_or_else(|| Unmodelled::new("RCC", format!("timer clock {hz} Hz does not divide the 336 MHz time base")))
        };
        let (apb1, apb2) = (units(c.tim_apb1_hz)?, units(c.tim_apb2_hz)?);
        self.tim2.set_clock_units(now, apb1);
        self.tim4.set_clock_units(now, apb1);
        self.tim9.set_clock_units(now, apb2);
        Ok(())
    }

    fn route(&mut self, addr: u32, now: Time, op: Op) -> Result<u32, Unmodelled> {
        use rcc::Bus::{Ahb1, Apb1, Apb2};
        self.sync_timer_clocks(now)?;
        let (base, offset) = (addr & !0x3FF, addr & 0x3FF);
        let clocks = self.rcc.clocks();
        macro_rules! dev {
            ($name:expr, $bus:expr, $bit:expr, $model:expr) => {{
                self.clock_check($name, $bus, $bit)?;
                match op {
                    Op::Read => $model.read(offset, now),
                    Op::Write(v) => $model.write(offset, v, now).map(|()| 0),
                }
            }};
        }
        match base {
            0x4000_0000 => {
                let v = dev!("TIM2", Apb1, 0, self.tim2)?;
                if matches!(op, Op::Read) && (0x34..=0x40).contains(&offset) {
                    let ch = ((offset - 0x34) / 4) as usize;
                    if let Some(Some(at)) = self.last_capture.get_mut(ch).map(Option::take) {
                        self.records.capture_reads.push((at, now));
                    }
                }
                Ok(v)
            }
            0x4000_0800 => {
                let v = dev!("TIM4", Apb1, 2, self.tim4)?;
                if let Op::Write(value) = op {
                    if (0x34..=0x40).contains(&offset) {
                        self.records.ccr_writes.push((now, ((offset - 0x34) / 4) as usize, value));
                    }
                }
                Ok(v)
            }
            0x4000_3000 => {
                // The IWDG runs on the LSI and has no enable bit in RCC; its start key forces
                // the LSI on.
                self.iwdg.set_lsi(self.rcc.lsi_ready_at());
                let v = match op {
                    Op::Read => self.iwdg.read(offset, now),
                    Op::Write(v) => self.iwdg.write(offset, v, now).map(|()| 0),
                }?;
                if self.iwdg.is_started() {
                    self.rcc.force_lsi_on(now);
                    self.iwdg.set_lsi(self.rcc.lsi_ready_at());
                }
                Ok(v)
            }
            0x4000_3800 => {
                self.clock_check("SPI2", Apb1, 14)?;
                let clocks = clocks?;
                match op {
                    Op::Read => self.spi2.read(offset, now, clocks),
                    Op::Write(v) => self.spi2.write(offset, v, now, clocks).map(|()| 0),
                }
            }
            0x4000_7000 => dev!("PWR", Apb1, 28, self.pwr),
            0x4001_1000 => {
                self.clock_check("USART1", Apb2, 4)?;
                let clocks = clocks?;
                match op {
                    Op::Read => self.usart1.read(offset, now, clocks),
                    Op::Write(v) => self.usart1.write(offset, v, now, clocks).map(|()| 0),
                }
            }
            0x4001_2000 => {
                self.clock_check("ADC1", Apb2, 8)?;
                let clocks = clocks?;
                match op {
                    Op::Read => self.adc.read(offset, now, clocks),
                    Op::Write(v) => self.adc.write(offset, v, now, clocks).map(|()| 0),
                }
            }
            0x4001_4000 => {
                let v = dev!("TIM9", Apb2, 16, self.tim9)?;
                Ok(v)
            }
            0x4002_0000 => dev!("GPIOA", Ahb1, 0, self.gpio[0]),
            0x4002_0400 => dev!("GPIOB", Ahb1, 1, self.gpio[1]),
            0x4002_0800 => dev!("GPIOC", Ahb1, 2, self.gpio[2]),
            0x4002_3800 => match op {
                Op::Read => self.rcc.read(offset, now),
                Op::Write(v) => self.rcc.write(offset, v, now).map(|()| 0),
            },
            0x4002_3C00 => match op {
                Op::Read => self.flash.read(offset, now),
                Op::Write(v) => self.flash.write(offset, v, now).map(|()| 0),
            },
            0xE004_2000 => match op {
                Op::Read => self.dbgmcu.read(offset, now),
                Op::Write(v) => self.dbgmcu.write(offset, v, now).map(|()| 0),
            },
            _ => Err(Unmodelled::new(format!("{addr:#010x}"), "no peripheral modelled at this address")),
        }
    }

    fn after_access(&mut self, now: Time) -> Result<(), Unmodelled> {
        self.forward_pins(now);
        for r in self.rcc.take_reset_pulses() {
            self.reset_peripheral(r);
        }
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

    fn reset_peripheral(&mut self, (bus, bit): (rcc::Bus, u32)) {
        use rcc::Bus::{Ahb1, Apb1, Apb2};
        match (bus, bit) {
            // The pins' external levels (the radio) survive a reset of the port's registers.
            (Ahb1, 0) => self.gpio[0].reset_registers(),
            (Ahb1, 1) => self.gpio[1].reset_registers(),
            (Ahb1, 2) => self.gpio[2].reset_registers(),
            (Apb1, 0) => self.tim2 = tim::Timer::new(tim::TimerKind::Tim2),
            (Apb1, 2) => self.tim4 = tim::Timer::new(tim::TimerKind::Tim4),
            (Apb1, 14) => self.spi2.reset_registers(),
            (Apb1, 28) => self.pwr = pwr::Pwr::new(),
            (Apb2, 4) => self.usart1.reset_registers(),
            (Apb2, 8) => self.adc.reset_registers(),
            (Apb2, 16) => self.tim9 = tim::Timer::new(tim::TimerKind::Tim9),
            _ => {}
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
        let word = self.route(addr & !3, now, Op::Read)?;
        self.records.last_read = Some((now, addr & !3, word));
        self.after_access(now)?;
        let lane = 8 * (addr & 3);
        let mask = if size >= 4 { u32::MAX } else { (1u32 << (8 * size)) - 1 };
        Ok((word >> lane) & mask)
    }

    fn write(&mut self, addr: u32, size: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.deliver_edges(now);
        let word = if size >= 4 {
            value
        } else {
            let is_data_register = matches!(addr & !3, 0x4000_380C | 0x4001_1004);
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
        [
            self.edges.front().map(|e| e.0),
            self.rcc.next_event(),
            self.tim2.next_event(),
            self.tim4.next_event(),
            self.tim9.next_event(),
            self.spi2.next_event(),
            self.usart1.next_event(),
            self.iwdg.next_event(),
            self.adc.next_event(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn advance(&mut self, now: Time, lines: &mut dyn FnMut(u32, bool)) -> Result<bool, Unmodelled> {
        self.deliver_edges(now);
        self.rcc.advance(now);
        let clocks = self.rcc.clocks()?;
        self.sync_timer_clocks(now)?;
        self.tim2.advance(now);
        self.tim4.advance(now);
        self.tim9.advance(now);
        self.spi2.advance(now, clocks);
        self.usart1.advance(now, clocks);
        self.records.uart.extend(self.usart1.take_output());
        self.iwdg.set_lsi(self.rcc.lsi_ready_at());
        self.iwdg.advance(now);
        self.adc.advance(now, clocks);
        lines(periph::irq::TIM2, self.tim2.irq_line());
        lines(periph::irq::TIM4, self.tim4.irq_line());
        lines(periph::irq::TIM1_BRK_TIM9, self.tim9.irq_line());
        lines(periph::irq::SPI2, self.spi2.irq_line());
        lines(periph::irq::USART1, self.usart1.irq_line());
        lines(periph::irq::ADC, self.adc.irq_line());
        Ok(self.iwdg.expired(now))
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
        let sensors = self.spi2.take_sensors();
        let adc_inputs = self.adc.clone();
        *self = Board::new();
        self.rcc = rcc;
        self.records = records;
        self.edges = edges;
        // The sensors are powered by the board, not reset with the MCU.
        self.spi2.put_sensors(sensors);
        self.adc.copy_inputs_from(&adc_inputs);
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
