//! STEVAL-FCU001V1 firmware: RTIC 2 wiring between the STM32F401 peripherals and fcu-core.
//!
//! Every flight decision (arming, throttle, failsafe, calibration, what the LEDs say) is made
//! by `fcu_core`; each task here moves bytes between a peripheral and one core call.
//!
//! | task         | binds / kind            | prio | work                                         |
//! |--------------|-------------------------|------|----------------------------------------------|
//! | sensor_dma   | DMA1_STREAM3 (TC)       | 5    | the IMU burst's bytes are in memory but the  |
//! |              |                         |      | last: stop the clock during it               |
//! | rc_capture   | TIM2 (both edges, wrap) | 4    | CCRx + pin level → edge queue; a pin past    |
//! |              |                         |      | its edge budget muted till the wrap          |
//! | control      | TIM1_BRK_TIM9 (CC1, tick)| 3   | CC1: start the IMU burst; tick: edges →      |
//! |              |                         |      | decoder, burst → `ControlTick::tick` → TIM4, |
//! |              |                         |      | every second outer job the barometer's burst,|
//! |              |                         |      | feed IWDG                                    |
//! | outer_step   | software                | 2    | battery reading, the job's barometer burst + |
//! |              |                         |      | `OuterStep::run` → `control`                 |
//! | report       | software                | 1    | status snapshots → lines into the UART queue |
//! | uart_tx      | USART1 (TXE)            | 1    | drains the UART queue, one byte per TXE      |
//! | housekeeping | software (monotonic)    | 1    | LEDs, battery ADC (10 Hz)                    |
//! | gcs_link     | software (monotonic)    | 1    | MAVLink: USART1 RX ring → `fcu_link::Link`,  |
//! |              |                         |      | parameter changes and commands → the control |
//! |              |                         |      | loop, saves to flash, frames → the UART      |
//! |              |                         |      | queue (200 Hz)                               |
#![no_std]
#![no_main]
// RTIC's generated `spawn` gives a task's message back in its `Err` when the task is busy: the
// status snapshot (its `Status` carries the altitude report) is that message, and a busy
// `report` only skips it. Nothing is boxed on a board without a heap.
#![allow(clippy::result_large_err)]

mod clock;
mod cycles;
mod link_task;
mod param_flash;
mod sensor_bus;
mod supply;
mod timers;
mod uart_rx;
mod watchdog;

use defmt_rtt as _;
use fcu_core::mixer::MixerConfig;

/// The tasks' clock: milliseconds on the cycle counter, which runs through a flash stall
/// (`clock`).
pub use clock::Mono;

/// The flight profile this build flies: the product (`Config::DEFAULT`), or its ESC variant
/// with the `esc` feature (TIM4 400 Hz, 850..1700 idle/max). In flash: the link task keeps
/// a reference to it for a reset to defaults, not a copy built in RAM.
static FLIGHT_CONFIG: fcu_core::Config = if cfg!(feature = "esc") { fcu_core::Config::esc() } else { fcu_core::Config::DEFAULT };

/// TIM4's compare for "motors off" in this build: 0 on the on-board MOSFETs, the idle pulse
/// for ESCs. A constant because the fault paths below cannot reach the configuration; `init`
/// checks that the flight configuration agrees.
const MOTORS_OFF_COMPARE: u16 =
    if cfg!(feature = "esc") { MixerConfig::REFERENCE_ESC.min_compare as u16 } else { MixerConfig::REFERENCE_DC.min_compare as u16 };

/// Puts TIM4 at the off compare at once, from any context (a fault or a panic): every CCR,
/// then an update event so the preloaded value takes effect now, not at the end of the PWM
/// period.
fn motors_off_now() {
    // SAFETY: only register writes to TIM4, which the motors alone use. This runs when the
    // program can no longer be trusted (HardFault, panic); whatever the interrupted code was
    // doing with TIM4, stopping the motors is what must happen, and these writes cannot make
    // anything worse than a running motor.
    let tim4 = unsafe { &*stm32f4xx_hal::pac::TIM4::ptr() };
    for n in 0..4 {
        tim4.ccr(n).write(|w| w.ccr().set(MOTORS_OFF_COMPARE));
    }
    tim4.egr().write(|w| w.ug().set_bit());
}

// The HardFault vector. A stack overflow faults while the core stacks an exception frame
// (flip-link puts the stack at the bottom of RAM, so it runs off into reserved memory), and the
// core then enters HardFault with SP still outside RAM: a handler whose first instruction is a
// push would fault again and lock the core up, the motors holding their duty until the
// watchdog resets the board. So the entry takes the reset SP from the vector table (VTOR, word
// 0) before anything is pushed; the handler never returns, so the frame it abandons is not
// needed. ARMv7-M: a fault in the HardFault handler escalates to lockup.
core::arch::global_asm!(
    ".section .HardFault.user, \"ax\"",
    ".global HardFault",
    ".type HardFault, %function",
    ".thumb_func",
    "HardFault:",
    "    ldr r0, =0xE000ED08",
    "    ldr r0, [r0]",
    "    ldr r0, [r0]",
    "    msr msp, r0",
    "    b {handler}",
    handler = sym hard_fault_with_a_stack,
);

/// A fault (bus error, undefined instruction, a stack overflow, a panic's `udf`), on a stack
/// the HardFault entry made sound: motors off first, then wait for the watchdog to reset the
/// board (at most its 50 ms timeout).
extern "C" fn hard_fault_with_a_stack() -> ! {
    motors_off_now();
    loop {
        cortex_m::asm::nop();
    }
}

/// No code path panics by design; if one ever does, the motors stop before anything else,
/// and the `udf` hands over to the HardFault handler (no message formatting: it would cost
/// flash, and nobody reads it in flight).
#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    motors_off_now();
    cortex_m::asm::udf()
}

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true, dispatchers = [EXTI0, EXTI1, EXTI2])]
mod app {
    use crate::sensor_bus::{BusError, SensorBus};
    use crate::timers::{Motors, RcCapture, TickStart, TickTimer};
    use crate::watchdog::Watchdog;
    use crate::Mono;
    use fcu_core::baro::{self, registers as baro_registers, RawBaro};
    use fcu_core::boot::BootVerdict;
    use fcu_core::flight::{ControlTick, OuterJob, OuterResult, OuterStep, Status};
    use fcu_core::imu::registers::{self, lsm6dsl, Sensor};
    use fcu_core::rc::CaptureEdge;
    use fcu_core::rc::EdgeDecoder;
    use fcu_core::telemetry::{self as tlm, LedPattern, LineBuf, Reporter, StatusFields};
    use fcu_core::Config;
    use heapless::spsc::{Consumer, Producer, Queue};
    use heapless::Deque;
    use rtic_monotonics::systick::prelude::*;
    use stm32f4xx_hal::adc::{config::AdcConfig, config::SampleTime, Adc};
    use stm32f4xx_hal::gpio::{Analog, Output, PB1, PB4, PB5};
    use stm32f4xx_hal::pac::{ADC1, USART1};
    use stm32f4xx_hal::serial::{Tx, TxISR, TxListen};

    /// Bytes of telemetry waiting for the UART: about 90 ms of output at 115200 baud, enough
    /// for a status line and a debug line together.
    const UART_QUEUE_BYTES: usize = 1024;
    /// LED refresh period; the fastest LED code toggles every 50 ms.
    const HOUSEKEEPING_PERIOD_MS: u32 = 10;
    /// Housekeeping periods between battery conversions (10 Hz).
    const BATTERY_EVERY_PERIODS: u32 = 10;
    /// How often a fatal boot fault is repeated on the UART.
    const FAULT_REPEAT_MS: u32 = 2000;
    /// How long the control tick waits for an IMU burst still in flight (it starts 60 µs
    /// before the tick and takes about 41 µs) before it ticks without a sample: 100 µs of the
    /// 84 MHz cycle counter. The barometer's burst (6 bytes, about 24 µs) has the same bound.
    const BURST_WAIT_CYCLES: u32 = 8_400;
    /// The barometer is read with every second outer job: at 80 Hz (every tenth 800 Hz tick),
    /// the tick multiple just above its 75 Hz output rate, so each of its samples is read at
    /// least once and none is overwritten unread (the outer step in between gets `None`, which
    /// the core's health check takes as a read with no new sample).
    const OUTER_JOBS_PER_BARO_READ: u8 = 2;
    /// How long the address byte (3 µs at 2.625 MHz) may take to leave: 20 µs.
    const ADDRESS_WAIT_CYCLES: u32 = 1_680;
    const UART_BAUD: u32 = 115_200;
    const SYSCLK_HZ: u32 = 84_000_000;
    const HSE_HZ: u32 = 16_000_000;
    /// The PLL's input, the HSE crystal or the HSI: both 16 MHz on this board.
    const INPUT_HZ: u32 = 16_000_000;

    /// What the control task hands to telemetry.
    #[derive(Clone, Copy)]
    pub struct Snapshot {
        pub(crate) status: Status,
        outer_overruns: u32,
        bus_errors: u32,
        /// Control ticks completed since boot.
        tick: u32,
        /// Each radio input's latest pulse width, capture counts (0: none yet).
        pub(crate) rc_widths_counts: [u16; 4],
    }

    /// The debug UART's transmit side and the bytes waiting for it.
    pub struct UartOut {
        tx: Tx<USART1>,
        queue: Deque<u8, UART_QUEUE_BYTES>,
        /// Bytes dropped because the queue was full (the line is cut, never blocks).
        dropped_bytes: u32,
    }

    impl UartOut {
        /// Bytes the queue can still take.
        pub(crate) fn room(&self) -> usize {
            UART_QUEUE_BYTES.saturating_sub(self.queue.len())
        }

        /// Nothing waits in the queue.
        pub(crate) fn is_idle(&self) -> bool {
            self.queue.is_empty()
        }

        pub(crate) fn send(&mut self, bytes: &[u8]) {
            for &b in bytes {
                if self.queue.push_back(b).is_err() {
                    self.dropped_bytes = self.dropped_bytes.saturating_add(1);
                }
            }
            if !self.queue.is_empty() {
                self.tx.listen();
            }
        }

        fn on_tx_empty(&mut self) {
            // The interrupt may come back with TXE already clear (a late-cleared pending bit,
            // or a queue refilled meanwhile): a byte is taken from the queue only when the
            // data register can hold it, so none is lost uncounted.
            if !self.tx.is_tx_empty() {
                return;
            }
            match self.queue.pop_front() {
                Some(b) => {
                    if embedded_hal_nb::serial::Write::write(&mut self.tx, b).is_err() {
                        self.dropped_bytes = self.dropped_bytes.saturating_add(1);
                    }
                }
                None => self.tx.unlisten(),
            }
        }
    }

    pub struct Leds {
        led1: PB5<Output>,
        led2: PB4<Output>,
    }

    impl Leds {
        /// Both LEDs are active low: lit = pin low.
        fn show(&mut self, l: tlm::Leds) {
            self.led1.set_state((!l.led1).into());
            self.led2.set_state((!l.led2).into());
        }
    }

    #[shared]
    struct Shared {
        outer_result: Option<OuterResult>,
        /// The job the control tick hands the outer step, with the barometer burst read for it
        /// (`None`: none read for this job, or the read failed). Passed through this slot
        /// rather than as the spawn's message: RTIC copies a message inside a critical
        /// section, and this one (376 bytes) held every interrupt off for 4 µs with slow flash.
        outer_job: Option<(OuterJob, Option<RawBaro>)>,
        uart: UartOut,
        led_pattern: LedPattern,
        battery_mv: u32,
        /// Radio pins muted for an edge storm since boot (`RcCapture::take_edges`).
        radio_mutes: u32,
        /// The sensor bus: the control tick starts the IMU's and the barometer's bursts, DMA1
        /// receives them.
        bus: SensorBus,
        /// The latest status for the link task (MAVLink), from `report`.
        latest: Option<Snapshot>,
        /// What the link task hands the control loop: accepted configuration changes for
        /// both halves, the station's commands (disarm, motor test, calibrations, a save
        /// running) for the control tick.
        mailbox: fcu_gcs::Mailbox,
        /// Fed by the control tick; stretched by the link task around a flash erase.
        watchdog: Option<Watchdog>,
        /// The UART speaks MAVLink: from boot (the link's protocol parameter), or from the first
        /// valid MAVLink frame a ground station sent to a board set to text lines.
        mavlink_on: bool,
    }

    #[local]
    struct Local {
        capture: RcCapture,
        /// Captured edges, from the capture interrupt to the control tick's decoder.
        edges_out: Producer<'static, CaptureEdge>,
        edges_in: Consumer<'static, CaptureEdge>,
        decoder: EdgeDecoder,
        tick_timer: TickTimer,
        inner: ControlTick,
        outer: OuterStep,
        motors: Motors,
        leds: Leds,
        adc: Adc<ADC1>,
        battery_pin: PB1<Analog>,
        reporter: Reporter,
        /// The link task's own state (`crate::link_task`).
        link: crate::link_task::LinkTask,
    }

    /// Edges the capture may queue between two control ticks: its budget allows 4 × 16 per
    /// 8.192 ms capture wrap, all of which could fall in one 1.25 ms tick; the queue holds 127.
    const EDGE_QUEUE: usize = 128;

    #[init(local = [edge_queue: Queue<CaptureEdge, EDGE_QUEUE> = Queue::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        // The HAL's GPIO split; its prelude stays out of the tasks (its fugit 0.3 `.millis()`
        // clashes with the monotonic's fugit 0.6).
        use stm32f4xx_hal::gpio::GpioExt;
        let dp = cx.device;
        let mut core = cx.core;
        let (mut rcc, clocks) = start_clocks(dp.RCC, &mut core.DCB, &mut core.DWT);
        crate::supply::start(dp.PWR, &mut rcc, clocks.crystal_ready);
        start_task_clock(core.SYST, &mut core.SCB, &rcc);
        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let gpioc = dp.GPIOC.split(&mut rcc);

        let defaults = &crate::FLIGHT_CONFIG;
        let (cfg, stored) = crate::link_task::load_parameters(dp.FLASH, defaults);
        // Motors first: off from the very start.
        let motors = start_motors(dp.TIM4, (gpiob.pb6, gpiob.pb7, gpiob.pb8, gpiob.pb9), &cfg, &mut rcc);
        let mut leds = Leds { led1: gpiob.pb5.into_push_pull_output(), led2: gpiob.pb4.into_push_pull_output() };
        leds.show(tlm::Leds { led1: true, led2: true });
        let mut uart = start_uart(dp.USART1, gpioa.pa9, gpioa.pa10, &mut rcc, &mut leds);
        let receiver = crate::link_task::start_receiver(dp.DMA2, &mut rcc);
        uart.send(tlm::BOOT_BANNER.as_bytes());
        if cfg.mixer.off_compare() != crate::MOTORS_OFF_COMPARE {
            halt(&mut leds, Some(&mut uart.tx), "the build's motor-off compare disagrees with its flight configuration");
        }

        let cs = chip_selects(gpioa.pa8, gpiob.pb12, gpioc.pc13);
        let mut bus = start_sensor_bus(dp.SPI2, dp.DMA1, cs, gpiob.pb13, gpiob.pb15, &mut rcc);
        let boot = init_sensors(&mut bus, &mut uart).with_crystal(clocks.crystal_ready).with_pll(clocks.pll_locked);
        let capture = start_radio(dp.TIM2, (gpioa.pa0, gpioa.pa1, gpioa.pa2, gpioa.pa3), &mut rcc);
        let (tick_timer, tick_start) = TickTimer::new(dp.TIM9, cfg.timing.tick_timer_psc, cfg.timing.tick_timer_arr, &mut rcc);
        let (adc, battery_pin) = start_battery(dp.ADC1, gpiob.pb1, &mut rcc);

        let fc = fcu_core::FlightController::new(&cfg).unwrap_or_else(|e| halt(&mut leds, Some(&mut uart.tx), e.field()));
        let decoder = fc.edge_decoder();
        let (edges_out, edges_in) = cx.local.edge_queue.split();
        let (inner, outer) = fc.into_parts();

        let (boot, watchdog) = arm_watchdog(boot, dp.IWDG, &dp.DBGMCU);
        start_tasks(boot, tick_start);
        let link = crate::link_task::LinkTask::new(cfg, defaults, stored, receiver);
        let shared = Shared {
            outer_result: None,
            outer_job: None,
            uart,
            led_pattern: boot.led_pattern(),
            battery_mv: 0,
            radio_mutes: 0,
            bus,
            latest: None,
            mailbox: fcu_gcs::Mailbox::new(cfg),
            watchdog,
            mavlink_on: link.speaks_mavlink_from_boot(),
        };
        let reporter = Reporter::firmware();
        let local =
            Local { capture, edges_out, edges_in, decoder, tick_timer, inner, outer, motors, leds, adc, battery_pin, reporter, link };
        (shared, local)
    }

    /// The tasks' clock, at either system clock (the LED codes and the fault line keep their
    /// pace): after `start_clocks`, which starts the cycle counter it counts.
    fn start_task_clock(syst: cortex_m::peripheral::SYST, scb: &mut cortex_m::peripheral::SCB, rcc: &stm32f4xx_hal::rcc::Rcc) {
        Mono::start(syst, rcc.clocks.sysclk().raw());
        // SAFETY: SysTick only drives the monotonic's timer queue: no RTIC task is bound to it,
        // so no resource ceiling counts on its priority. At its reset priority, 0, the highest,
        // its handler would delay the end-of-read interrupt and the radio capture; at the
        // lowest it delays only the LEDs and the fault line, which await it.
        unsafe { scb.set_priority(cortex_m::peripheral::scb::SystemHandler::SysTick, 0xF0) };
    }

    /// TIM4 driving PB6..PB9 (AF2) at the configuration's off compare from its first period.
    fn start_motors(
        tim4: stm32f4xx_hal::pac::TIM4,
        pins: (stm32f4xx_hal::gpio::PB6, stm32f4xx_hal::gpio::PB7, stm32f4xx_hal::gpio::PB8, stm32f4xx_hal::gpio::PB9),
        cfg: &Config,
        rcc: &mut stm32f4xx_hal::rcc::Rcc,
    ) -> Motors {
        let _motor_pins =
            (pins.0.into_alternate::<2>(), pins.1.into_alternate::<2>(), pins.2.into_alternate::<2>(), pins.3.into_alternate::<2>());
        Motors::new(tim4, cfg.mixer.timer_psc, cfg.mixer.timer_arr, cfg.mixer.off_compare(), rcc)
    }

    /// The three sensors' chip selects (LSM6DSL, LIS2MDL, LPS22HB), high (deselected) before
    /// the bus is clocked.
    fn chip_selects(
        imu: stm32f4xx_hal::gpio::PA8,
        magnetometer: stm32f4xx_hal::gpio::PB12,
        barometer: stm32f4xx_hal::gpio::PC13,
    ) -> [stm32f4xx_hal::gpio::AnyPin<Output>; 3] {
        [
            imu.into_push_pull_output_in_state(true.into()).erase(),
            magnetometer.into_push_pull_output_in_state(true.into()).erase(),
            barometer.into_push_pull_output_in_state(true.into()).erase(),
        ]
    }

    /// TIM2 capturing the radio's four inputs on PA0..PA3 (AF1), pulled down: a receiver that
    /// is not plugged in reads low, not noise.
    fn start_radio(
        tim2: stm32f4xx_hal::pac::TIM2,
        pins: (stm32f4xx_hal::gpio::PA0, stm32f4xx_hal::gpio::PA1, stm32f4xx_hal::gpio::PA2, stm32f4xx_hal::gpio::PA3),
        rcc: &mut stm32f4xx_hal::rcc::Rcc,
    ) -> RcCapture {
        let capture_pins = (
            pins.0.into_pull_down_input().into_alternate::<1>(),
            pins.1.into_pull_down_input().into_alternate::<1>(),
            pins.2.into_pull_down_input().into_alternate::<1>(),
            pins.3.into_pull_down_input().into_alternate::<1>(),
        );
        RcCapture::new(tim2, capture_pins, rcc)
    }

    /// ADC1 on the battery's divider (PB1). PCLK2 / 4 = 21 MHz: the F401's ADC clock must stay
    /// at or under 36 MHz (datasheet), and ST's code uses the same divider.
    fn start_battery(adc1: ADC1, pin: stm32f4xx_hal::gpio::PB1, rcc: &mut stm32f4xx_hal::rcc::Rcc) -> (Adc<ADC1>, PB1<Analog>) {
        let adc = Adc::new(adc1, true, AdcConfig::default().clock(stm32f4xx_hal::adc::config::Clock::Pclk2_div_4), rcc);
        (adc, pin.into_analog())
    }

    /// Arms the watchdog only once the sensors answered: from here a control tick that does
    /// not complete within the timeout resets the board (motors off at reset). Not armed on a
    /// board that may not fly, so the LED code and the UART message stay visible instead of a
    /// silent reset loop.
    fn arm_watchdog(
        boot: BootVerdict,
        iwdg: stm32f4xx_hal::pac::IWDG,
        dbgmcu: &stm32f4xx_hal::pac::DBGMCU,
    ) -> (BootVerdict, Option<Watchdog>) {
        let watchdog = if boot.may_fly() { Watchdog::start(iwdg, dbgmcu).ok() } else { None };
        (boot.with_watchdog(watchdog.is_some()), watchdog)
    }

    /// The tasks that run from the end of `init`: the control tick, or, on a board that may
    /// not fly (the core's verdict), the fault report instead (TIM9 stays stopped, so
    /// `control` never runs and the motors stay off); the LEDs and battery; the link task.
    fn start_tasks(boot: BootVerdict, tick_start: TickStart) {
        if boot.may_fly() {
            if start_ticking::spawn(tick_start).is_err() {
                defmt::error!("tick start already spawned");
            }
        } else if fault_report::spawn(boot).is_err() {
            defmt::error!("fault report already running");
        }
        if housekeeping::spawn().is_err() {
            defmt::error!("housekeeping already running");
        }
        if gcs_link::spawn(boot).is_err() {
            defmt::error!("link task already running");
        }
    }

    /// A boot step that cannot be flown past (a build defect, not a field condition): motors
    /// stay at compare 0, both LEDs on, the reason on the UART, no watchdog, no tasks.
    fn halt(leds: &mut Leds, tx: Option<&mut Tx<USART1>>, reason: &str) -> ! {
        leds.show(tlm::Leds { led1: true, led2: true });
        defmt::error!("boot halted: {}", reason);
        if let Some(tx) = tx {
            // Interrupts are still off in `init`: a blocking write is the only way out.
            for &b in b"FATAL boot halted: ".iter().chain(reason.as_bytes()).chain(b"\n") {
                let _sent = nb::block!(embedded_hal_nb::serial::Write::write(tx, b));
            }
        }
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// How the clock tree came up.
    struct ClockCheck {
        crystal_ready: bool,
        pll_locked: bool,
    }

    /// HSE 16 MHz → 84 MHz SYSCLK/HCLK/PCLK2, 42 MHz PCLK1; the HAL sets 2 flash wait states
    /// and picks M 8, N 168, P 4, Q 7: the reference's VCO (336 MHz) and outputs with a 2 MHz
    /// PLL input instead of 1 MHz. The HAL waits for HSERDY and PLLRDY without a bound, so the
    /// crystal and the PLL are tried here first: a dead crystal leaves the board on the 16 MHz
    /// HSI (same PLL settings, same clocks), a PLL that does not lock at its 16 MHz input, on
    /// the ground and saying so, never dark. The cycle counter, started first, times the waits.
    fn start_clocks(
        rcc: stm32f4xx_hal::pac::RCC,
        dcb: &mut cortex_m::peripheral::DCB,
        dwt: &mut cortex_m::peripheral::DWT,
    ) -> (stm32f4xx_hal::rcc::Rcc, ClockCheck) {
        // The HAL prelude only where the HAL is set up: its fugit 0.3 `.millis()` clashes with
        // the monotonic's fugit 0.6 used by the tasks.
        use stm32f4xx_hal::prelude::*;
        use stm32f4xx_hal::rcc;
        dcb.enable_trace();
        dwt.enable_cycle_counter();
        let crystal_ready = start_crystal(&rcc);
        let pll_locked = pll_locks(&rcc, crystal_ready);
        let source = if crystal_ready { rcc::Config::hse(HSE_HZ.Hz()) } else { rcc::Config::hsi() };
        let sysclk_hz = if pll_locked { SYSCLK_HZ } else { INPUT_HZ };
        let rcc = rcc.freeze(source.sysclk(sysclk_hz.Hz()).hclk(sysclk_hz.Hz()).pclk1((sysclk_hz / 2).Hz()).pclk2(sysclk_hz.Hz()));
        (rcc, ClockCheck { crystal_ready, pll_locked })
    }

    /// USART1 at 115200 8N1: the transmit side for telemetry and the link, and the receiver
    /// on PA10 (AF7), whose bytes DMA2 takes (`link_task::start_receiver`).
    fn start_uart(
        usart: USART1,
        tx_pin: stm32f4xx_hal::gpio::PA9,
        rx_pin: stm32f4xx_hal::gpio::PA10,
        rcc: &mut stm32f4xx_hal::rcc::Rcc,
        leds: &mut Leds,
    ) -> UartOut {
        use stm32f4xx_hal::prelude::*;
        use stm32f4xx_hal::serial;
        let config = serial::Config::default().baudrate(UART_BAUD.bps());
        let tx = serial::Serial::new(usart, (tx_pin, rx_pin), config, rcc)
            .map(|serial| serial.split().0)
            .unwrap_or_else(|_| halt(leds, None, "USART1 rejected 115200 8N1"));
        UartOut { tx, queue: Deque::new(), dropped_bytes: 0 }
    }

    /// SPI2 in 3-wire mode at `SPI_HZ` (CPOL 1, CPHA 1, the sensors' mode) with DMA1 for the
    /// IMU burst. The chip selects are high (deselected) before the bus is clocked.
    fn start_sensor_bus(
        spi2: stm32f4xx_hal::pac::SPI2,
        dma1: stm32f4xx_hal::pac::DMA1,
        cs: [stm32f4xx_hal::gpio::AnyPin<Output>; 3],
        sck: stm32f4xx_hal::gpio::PB13,
        sda: stm32f4xx_hal::gpio::PB15,
        rcc: &mut stm32f4xx_hal::rcc::Rcc,
    ) -> SensorBus {
        use stm32f4xx_hal::prelude::*;
        use stm32f4xx_hal::rcc::Enable;
        use stm32f4xx_hal::{gpio::Speed, spi};
        let sck = sck.into_alternate::<5>().speed(Speed::High);
        let sda = sda.into_alternate::<5>().speed(Speed::High);
        let spi2 = spi::Spi::new_bidi(
            spi2,
            (Some(sck), Some(sda)),
            spi::Mode { polarity: spi::Polarity::IdleHigh, phase: spi::Phase::CaptureOnSecondTransition },
            crate::sensor_bus::SPI_HZ.Hz(),
            rcc,
        );
        let (spi2, _sensor_pins) = spi2.release();
        stm32f4xx_hal::pac::DMA1::enable(rcc);
        SensorBus::new(spi2, cs, dma1)
    }

    /// Turns the HSE crystal on and waits for it, at most ST's `HSE_STARTUP_TIMEOUT` (100 ms;
    /// the datasheet's typical start-up is 2 ms). Runs on the reset clock, the 16 MHz HSI, timed
    /// on the cycle counter. A crystal that does not start is turned off again.
    fn start_crystal(rcc: &stm32f4xx_hal::pac::RCC) -> bool {
        const STARTUP_BOUND_CYCLES: u32 = INPUT_HZ / 10;
        rcc.cr().modify(|_, w| w.hseon().set_bit());
        let ready = crate::cycles::poll(STARTUP_BOUND_CYCLES, || rcc.cr().read().hserdy().bit_is_set().then_some(()));
        if ready.is_none() {
            rcc.cr().modify(|_, w| w.hseon().clear_bit());
        }
        ready.is_some()
    }

    /// Tries the PLL with the settings the HAL will give it for 84 MHz from a 16 MHz input
    /// (M 8, N 168, P 4, Q 7; HSE if the crystal runs, else HSI), waits for its lock at most
    /// 1 ms (the datasheet's t_LOCK: 100 µs typical, 200 µs maximum), then turns it off for the
    /// HAL to set up again. Runs on the 16 MHz input, timed on the cycle counter.
    fn pll_locks(rcc: &stm32f4xx_hal::pac::RCC, from_hse: bool) -> bool {
        const LOCK_BOUND_CYCLES: u32 = INPUT_HZ / 1000;
        rcc.pllcfgr().write(|w| {
            // SAFETY: M 8, N 168 and Q 7 are inside the fields' ranges (M 2..63, N 50..432,
            // Q 2..15) and give a 2 MHz input and a 336 MHz VCO, inside RM0368's limits.
            unsafe { w.pllm().bits(8).plln().bits(168).pllq().bits(7) };
            w.pllp().div4().pllsrc().bit(from_hse)
        });
        rcc.cr().modify(|_, w| w.pllon().set_bit());
        let locked = crate::cycles::poll(LOCK_BOUND_CYCLES, || rcc.cr().read().pllrdy().bit_is_set().then_some(())).is_some();
        rcc.cr().modify(|_, w| w.pllon().clear_bit());
        // PLLRDY falls within a few cycles of the PLL's clock once it is off.
        let _off = crate::cycles::poll(LOCK_BOUND_CYCLES, || rcc.cr().read().pllrdy().bit_is_clear().then_some(()));
        locked
    }

    /// Waits `ms` milliseconds on the cycle counter (boot only: the control tick is not running).
    fn delay_ms(ms: u32) {
        let cycles = ms.saturating_mul(SYSCLK_HZ / 1000);
        crate::cycles::wait_since(crate::cycles::now(), cycles);
    }

    /// What the boot plays on one sensor: interface writes, a settle time, writes before
    /// `WHO_AM_I`, then the configuration.
    struct BootTable {
        interface: &'static [registers::RegWrite],
        settle_ms: u32,
        after_settle: &'static [registers::RegWrite],
        config: &'static [registers::RegWrite],
    }

    /// The IMU's and the magnetometer's tables from `fcu_core::imu::registers`; the
    /// barometer's from `fcu_core::baro::registers`, the configuration its burst is read
    /// with (75 Hz, ODR/20 low-pass, BDU, auto-increment). The reference's own LPS22HB table
    /// sets it to 25 Hz unfiltered, never reads it, and waits a second for its reset.
    fn boot_table(sensor: Sensor) -> BootTable {
        match sensor {
            Sensor::Lps22hb => BootTable {
                interface: &baro_registers::INTERFACE,
                settle_ms: baro_registers::RESET_SETTLE_MS,
                after_settle: &baro_registers::AFTER_RESET,
                config: &baro_registers::CONFIG,
            },
            Sensor::Lsm6dsl | Sensor::Lis2mdl => BootTable {
                interface: sensor.interface_writes(),
                settle_ms: sensor.settle_ms(),
                after_settle: sensor.after_settle_writes(),
                config: sensor.config_writes(),
            },
        }
    }

    /// Plays each sensor's boot table ([`boot_table`]) and collects the `WHO_AM_I` answers;
    /// the core decides what they mean.
    fn init_sensors(bus: &mut SensorBus, uart: &mut UartOut) -> BootVerdict {
        // The sensors boot after power-up and drop what they hear meanwhile.
        delay_ms(registers::POWER_UP_MS);
        let mut answers = [0u8; 3];
        for (sensor, answer) in Sensor::ALL.into_iter().zip(answers.iter_mut()) {
            *answer = init_sensor(bus, sensor);
            if sensor.identifies(*answer) {
                uart.send(sensor.name().as_bytes());
                uart.send(b" initialized and enabled\n");
            }
        }
        BootVerdict::from_answers(answers)
    }

    /// One sensor's boot sequence, tried a few times; returns the last `WHO_AM_I` answer
    /// (0x00, which no sensor answers, when the bus itself failed).
    fn init_sensor(bus: &mut SensorBus, sensor: Sensor) -> u8 {
        const BUS_FAILED: u8 = 0x00;
        let play = |bus: &mut SensorBus, writes: &[registers::RegWrite]| writes.iter().try_for_each(|w| bus.write(sensor, w.addr, w.value));
        let table = boot_table(sensor);
        let mut who_am_i = BUS_FAILED;
        for attempt in 0..registers::WHO_AM_I_ATTEMPTS {
            if attempt > 0 {
                delay_ms(registers::WHO_AM_I_RETRY_MS);
            }
            if play(bus, table.interface).is_err() {
                continue;
            }
            delay_ms(table.settle_ms);
            if play(bus, table.after_settle).is_err() {
                continue;
            }
            who_am_i = bus.read_u8(sensor, sensor.who_am_i_addr()).unwrap_or(BUS_FAILED);
            if sensor.identifies(who_am_i) {
                return match play(bus, table.config) {
                    Ok(()) => who_am_i,
                    Err(_) => BUS_FAILED,
                };
            }
        }
        who_am_i
    }

    /// Radio capture: timestamps and pin levels queued for the control tick's decoder,
    /// nothing else (and a count of the pins the capture muted for an edge storm, for the
    /// status line). Kept short, as it outranks the tick: an edge that comes while it runs
    /// waits for it (the hardware has latched its time meanwhile).
    #[task(binds = TIM2, priority = 4, shared = [radio_mutes], local = [capture, edges_out])]
    fn rc_capture(mut cx: rc_capture::Context) {
        let edges_out = cx.local.edges_out;
        let mut lost = 0u32;
        let mut muted = cx.local.capture.take_edges(|edge| {
            if edges_out.enqueue(edge).is_err() {
                lost += 1;
            }
        });
        // A full queue is not reachable within the capture's edge budget; an edge lost there
        // is the same to the core as a muted pin's, and counted with them.
        muted = muted.saturating_add(lost);
        if muted > 0 {
            cx.shared.radio_mutes.lock(|n| *n = n.saturating_add(muted));
        }
    }

    /// A burst's DMA (the IMU's or the barometer's) is done but for the last byte: stop the
    /// clock during it, at the highest priority (the 3-wire end-of-read window is met from
    /// this entry).
    #[task(binds = DMA1_STREAM3, priority = 5, shared = [bus])]
    fn sensor_dma(mut cx: sensor_dma::Context) {
        cx.shared.bus.lock(SensorBus::on_dma_complete);
    }

    /// Starts a burst of `N` bytes from `sensor`'s register `addr`: the address byte goes out
    /// with the bus unlocked between short looks (the radio's capture interrupt is never held
    /// off for the byte's 3 µs).
    fn start_burst<const N: usize>(bus: &mut impl rtic::Mutex<T = SensorBus>, sensor: Sensor, addr: u8) -> Result<(), BusError> {
        bus.lock(|bus| bus.send_burst_address::<N>(sensor, addr))?;
        if crate::cycles::poll(ADDRESS_WAIT_CYCLES, || bus.lock(|bus| bus.address_sent()).then_some(())).is_none() {
            bus.lock(SensorBus::abandon_burst);
            return Err(BusError::Timeout);
        }
        bus.lock(SensorBus::receive_burst)
    }

    /// Waits for the burst the DMA receives (the radio's and the DMA's interrupts run
    /// meanwhile); a burst that does not come in time is abandoned.
    fn wait_for_burst<const N: usize>(bus: &mut impl rtic::Mutex<T = SensorBus>) -> Result<[u8; N], BusError> {
        let taken = crate::cycles::poll(BURST_WAIT_CYCLES, || {
            // The flag first: the bus's lock would hold off the very interrupt that sets it.
            crate::sensor_bus::last_byte_started().then(|| bus.lock(SensorBus::take_burst)).flatten()
        });
        match taken {
            Some(done) => done.map(crate::sensor_bus::burst_bytes::<N>),
            None => {
                bus.lock(SensorBus::abandon_burst);
                Err(BusError::Timeout)
            }
        }
    }

    /// The barometer's burst, STATUS through TEMP_OUT_H (`None` when the read failed; the
    /// core decides what that means). Read after the motor write: the IMU's burst is in, so
    /// the bus is free, and the next one starts a millisecond later.
    fn read_baro(bus: &mut impl rtic::Mutex<T = SensorBus>) -> Option<RawBaro> {
        const N: usize = baro_registers::BURST_LEN;
        start_burst::<N>(bus, Sensor::Lps22hb, baro_registers::BURST_START).ok()?;
        wait_for_burst::<N>(bus).ok().map(|bytes| baro::decode_burst(&bytes))
    }

    /// The control tick: IMU burst → `ControlTick::tick` → TIM4; the outer step when due, with
    /// the barometer's burst read for it every second time.
    #[task(
        binds = TIM1_BRK_TIM9,
        priority = 3,
        shared = [outer_result, outer_job, bus, mailbox, watchdog],
        local = [tick_timer, edges_in, decoder, inner, motors, burst_started: bool = false, outer_overruns: u32 = 0, bus_errors: u32 = 0, baro_reads: u32 = 0, baro_bus_errors: u32 = 0, baro_countdown: u8 = 0, ticks: u32 = 0, snapshot_countdown: u16 = 0, rc_widths_counts: [u16; 4] = [0; 4]]
    )]
    fn control(mut cx: control::Context) {
        let events = cx.local.tick_timer.take_events();
        let inner = cx.local.inner;
        let decoder = cx.local.decoder;
        if events.read_due {
            // A lead before the tick: the burst's bytes arrive by DMA meanwhile, and the
            // work that does not need them is done now, off the path from the tick to the
            // motors (the tick's state does not change until the tick).
            *cx.local.burst_started = start_burst::<{ lsm6dsl::BURST_LEN }>(&mut cx.shared.bus, Sensor::Lsm6dsl, lsm6dsl::OUTX_L_G).is_ok();
            if let Some(result) = cx.shared.outer_result.lock(Option::take) {
                inner.apply_outer(&result);
            }
            // A parameter change the link task accepted (the core checked it against the
            // armed state) and the ground station's commands, taken between ticks (the core
            // decides again with its own state).
            cx.shared.mailbox.lock(|mailbox| mailbox.deliver_to_tick(inner));
            while let Some(edge) = cx.local.edges_in.dequeue() {
                decoder.on_edge(edge);
            }
        }
        if !events.tick_due {
            return;
        }
        // The edges of the last 60 µs, in order after those fed at the lead.
        while let Some(edge) = cx.local.edges_in.dequeue() {
            decoder.on_edge(edge);
        }
        let pulses = decoder.take();
        for (width, latest) in pulses.width_counts.iter().zip(cx.local.rc_widths_counts.iter_mut()) {
            if let Some(w) = width {
                *latest = *w;
            }
        }

        let sample = if core::mem::take(cx.local.burst_started) { wait_for_burst(&mut cx.shared.bus) } else { Err(BusError::Timeout) };
        let out = match sample {
            Ok(burst) => inner.tick(registers::decode_lsm6dsl_burst(&burst), &pulses),
            Err(_) => {
                // The core decides what a missing sample means (a short gap is bridged, a dead
                // bus latches a fault and stops the motors).
                *cx.local.bus_errors = cx.local.bus_errors.saturating_add(1);
                inner.tick_without_sample(&pulses)
            }
        };
        cx.local.motors.write(out.compare);

        if let Some(job) = out.outer_job {
            let (countdown, reads, errors) = (&mut *cx.local.baro_countdown, &mut *cx.local.baro_reads, &mut *cx.local.baro_bus_errors);
            let baro = read_baro_for_job(&mut cx.shared.bus, countdown, reads, errors);
            if cx.shared.outer_job.lock(|slot| slot.replace((job, baro)).is_some()) {
                // The previous job was never started (the outer step still ran the one
                // before): it is lost to this one; counted and reported on the status line.
                *cx.local.outer_overruns = cx.local.outer_overruns.saturating_add(1);
            }
            // Busy, it takes this job when it is done with its own.
            let _running = outer_step::spawn();
        }

        *cx.local.ticks = cx.local.ticks.wrapping_add(1);
        *cx.local.snapshot_countdown = cx.local.snapshot_countdown.saturating_sub(1);
        if *cx.local.snapshot_countdown == 0 {
            *cx.local.snapshot_countdown = tlm::SNAPSHOT_EVERY_TICKS;
            let snapshot = Snapshot {
                status: inner.status(),
                outer_overruns: *cx.local.outer_overruns,
                bus_errors: *cx.local.bus_errors,
                tick: *cx.local.ticks,
                rc_widths_counts: *cx.local.rc_widths_counts,
            };
            // A busy telemetry task means the UART side is behind: skipping a snapshot only
            // delays the next line by 5 ms.
            let _skipped = report::spawn(snapshot);
        }

        cx.shared.watchdog.lock(|w| {
            if let Some(watchdog) = w.as_mut() {
                watchdog.feed();
            }
        });
    }

    /// The barometer's burst for an outer job, read on every `OUTER_JOBS_PER_BARO_READ`-th
    /// one (the part's 75 Hz against the jobs' 160 Hz), each read or failure counted.
    fn read_baro_for_job(
        bus: &mut impl rtic::Mutex<T = SensorBus>,
        countdown: &mut u8,
        reads: &mut u32,
        bus_errors: &mut u32,
    ) -> Option<RawBaro> {
        *countdown = countdown.saturating_sub(1);
        if *countdown != 0 {
            return None;
        }
        *countdown = OUTER_JOBS_PER_BARO_READ;
        let read = read_baro(bus);
        match read {
            Some(_) => *reads = reads.saturating_add(1),
            None => *bus_errors = bus_errors.saturating_add(1),
        }
        read
    }

    /// The outer step (estimator + angle loop) on each job's snapshot, as long as one waits.
    #[task(priority = 2, shared = [outer_result, outer_job, battery_mv, mailbox], local = [outer])]
    async fn outer_step(mut cx: outer_step::Context) {
        while let Some((job, baro)) = cx.shared.outer_job.lock(Option::take) {
            crate::link_task::config_to_outer(&mut cx.shared.mailbox, cx.local.outer);
            // The battery compensation's input (the core filters it and decides what it does).
            let battery_mv = cx.shared.battery_mv.lock(|mv| *mv);
            cx.local.outer.set_battery_mv(battery_mv);
            // The barometer's burst read for this job, or `None` (the core's health check
            // tells a missed read from a dead part).
            cx.local.outer.set_baro(baro);
            let result = cx.local.outer.run(&job);
            cx.shared.outer_result.lock(|slot| *slot = Some(result));
        }
    }

    /// Status snapshots → LED code and UART lines (status on every change of state or of the
    /// vertical report, debug line at its rate: the core's `Reporter` decides).
    #[task(priority = 1, shared = [uart, led_pattern, battery_mv, radio_mutes, latest, mavlink_on], local = [reporter])]
    async fn report(mut cx: report::Context, snapshot: Snapshot) {
        let status = &snapshot.status;
        let pattern = tlm::led_pattern(status);
        cx.shared.led_pattern.lock(|p| *p = pattern);
        cx.shared.latest.lock(|l| *l = Some(snapshot));
        if cx.shared.mavlink_on.lock(|on| *on) {
            return;
        }

        let emit = cx.local.reporter.observe(status);
        if emit.status_line {
            let battery_mv = cx.shared.battery_mv.lock(|mv| *mv);
            let radio_mutes = cx.shared.radio_mutes.lock(|n| *n);
            cx.shared.uart.lock(|uart| {
                let fields = StatusFields {
                    battery_mv,
                    outer_overruns: snapshot.outer_overruns,
                    bus_errors: snapshot.bus_errors,
                    uart_dropped_bytes: uart.dropped_bytes,
                    radio_mutes,
                    tick: snapshot.tick,
                    ..StatusFields::of(status)
                };
                let mut line = LineBuf::<{ tlm::STATUS_LINE_MAX }>::new();
                tlm::write_status_line(&mut line, &fields);
                uart.send(line.as_bytes());
            });
        }
        if emit.debug_line {
            let mut line = LineBuf::<{ tlm::DEBUG_LINE_MAX }>::new();
            tlm::write_debug_line(&mut line, &tlm::debug_fields(status));
            cx.shared.uart.lock(|uart| uart.send(line.as_bytes()));
        }
    }

    /// Starts the control tick once `init` has returned, RTIC has put every resource in place
    /// and the interrupts are enabled (see `TickStart`).
    #[task(priority = 1)]
    async fn start_ticking(_cx: start_ticking::Context, tick_start: TickStart) {
        tick_start.start();
    }

    /// The ground station's link (`crate::link_task`): MAVLink on USART1.
    #[task(priority = 1, shared = [uart, latest, battery_mv, mailbox, watchdog, mavlink_on], local = [link])]
    async fn gcs_link(cx: gcs_link::Context, boot: BootVerdict) {
        crate::link_task::run(cx.local.link, cx.shared, boot).await;
    }

    /// USART1 transmit-empty: one queued byte out per interrupt.
    #[task(binds = USART1, priority = 1, shared = [uart])]
    fn uart_tx(mut cx: uart_tx::Context) {
        cx.shared.uart.lock(UartOut::on_tx_empty);
    }

    /// LEDs from the core's pattern, battery voltage for telemetry.
    #[task(priority = 1, shared = [led_pattern, battery_mv], local = [leds, adc, battery_pin])]
    async fn housekeeping(mut cx: housekeeping::Context) {
        let mut periods: u32 = 0;
        loop {
            let now_ms = Mono::now().duration_since_epoch().as_millis();
            let pattern = cx.shared.led_pattern.lock(|p| *p);
            cx.local.leds.show(pattern.leds_at(now_ms));

            if periods % BATTERY_EVERY_PERIODS == 0 {
                let counts = cx.local.adc.convert(cx.local.battery_pin, SampleTime::Cycles_480);
                let mv = tlm::battery_mv(counts);
                cx.shared.battery_mv.lock(|b| *b = mv);
            }
            periods = periods.wrapping_add(1);
            Mono::delay(HOUSEKEEPING_PERIOD_MS.millis()).await;
        }
    }

    /// A fatal boot fault, repeated on the UART until reset (`docs/safety.md#boot`: never a silent
    /// hang).
    #[task(priority = 1, shared = [uart, mavlink_on])]
    async fn fault_report(mut cx: fault_report::Context, verdict: BootVerdict) {
        let mut line = LineBuf::<96>::new();
        let _grounded = verdict.write_fatal_line(&mut line);
        loop {
            // Bytes shown as ASCII: a `str` would need UTF-8 validation code in flash for an
            // ASCII line.
            defmt::error!("{=[u8]:a}", line.as_bytes());
            // With MAVLink on the UART, the link task sends it as a STATUSTEXT instead.
            if !cx.shared.mavlink_on.lock(|on| *on) {
                cx.shared.uart.lock(|uart| uart.send(line.as_bytes()));
            }
            Mono::delay(FAULT_REPEAT_MS.millis()).await;
        }
    }
}
