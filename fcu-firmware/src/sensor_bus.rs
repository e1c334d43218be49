//! SPI2 as the board wires it: 3-wire half-duplex (one bidirectional data line, PB15), mode 3,
//! with a software chip select per sensor. Only moves bytes; what to write where is in
//! `fcu_core::imu::registers` and `fcu_core::baro::registers`.
//!
//! The HAL configures the peripheral (`Spi::new_bidi`), but its bidirectional receive path
//! leaves BIDIOE set, so reads are done here on the registers with the receive sequence of
//! the reference manual (RM0368, "bidirectional receive-only procedure"): in 1-line receive
//! mode the master clocks continuously from the moment SPE is set, so the clock is stopped by
//! clearing SPE during the last byte. At boot the reads are polled (interrupts are off in
//! `init`); in flight the bursts' bytes (the IMU's every control tick, the barometer's at its
//! rate) go to memory by DMA1 stream 3 and its transfer-complete interrupt stops the clock, so
//! nothing polls with interrupts masked.

use core::sync::atomic::{fence, AtomicBool, AtomicU8, Ordering};
use fcu_core::imu::registers::{read_address, write_address, Sensor};
use stm32f4xx_hal::gpio::{AnyPin, Output};
use stm32f4xx_hal::pac::{Interrupt, DMA1, NVIC, SPI2};

/// Busy-wait bound for one status flag. One byte at 2.625 MHz is about 260 CPU cycles; the
/// bound is far above that and only ends a wait on a broken bus.
const FLAG_WAIT_POLLS: u32 = 2_000;

/// SPI2's clock: PCLK1 42 MHz / 16, the reference's 2.625 MHz. The sensors would take up to
/// 10 MHz (their datasheets' SPI timing, f_c(SPC) max 10 MHz, 3-wire included), and with the
/// burst's bytes moved by DMA the CPU pays nothing per byte; but the end-of-read window is one
/// byte long, 128 cycles at 5.25 MHz, and the stop's interrupt with slow flash and APB
/// accesses (fcu-pil's pessimistic profile) landed past it now and then. At 2.625 MHz it has
/// 256 cycles.
pub const SPI_HZ: u32 = 2_625_000;
/// CPU cycles per SPI clock period: 84 MHz / 2.625 MHz.
const SCK_CYCLES: u32 = 84_000_000 / SPI_HZ;
/// When to clear SPE to end a receive, counted on the cycle counter from the moment the
/// second-to-last RXNE is seen (or, for one byte, from setting SPE): a period and a half of
/// the SPI clock. The RM's window (RM0090 §28.3.8, the F401's SPI block) runs from one SCK
/// period after that RXNE rose, so the last byte has started, to the end of the last byte
/// (8 periods, 256 cycles), so no byte follows it. Seen up to a poll or an interrupt entry
/// late, plus the CR1 read-modify-write, the clear lands 48 to about 120 cycles in: clear of
/// both ends. (`asm::delay` is not used: its cycles per count depend on the flash wait
/// states.)
const STOP_AFTER_CYCLES: u32 = SCK_CYCLES + SCK_CYCLES / 2;
/// The same stop, timed from the DMA's transfer-complete interrupt entry (see
/// [`SensorBus::on_dma_complete`]): one SPI clock, the window's whole early side, since a
/// tail-chained entry comes only 6 cycles after the flag.
const DMA_STOP_AFTER_ENTRY_CYCLES: u32 = SCK_CYCLES;
/// How long a frame clocked in receive mode may still run once SPE is cleared: the clock stops
/// at its end, at most eight SPI clocks on (SPE cleared at its very start), plus the CR1
/// write's way to the peripheral. BSY cannot say it: in bidirectional receive mode it stays
/// low on silicon (RM0090 §28.3.7, the F401's SPI block).
const FRAME_END_AFTER_STOP_CYCLES: u32 = 8 * SCK_CYCLES + SCK_CYCLES / 2;
/// Bound on waiting for a disabled stream's EN to read 0: the transfer in flight ends within
/// a few bus cycles; the bound only ends a wait on a broken bus.
const STREAM_STOP_WAIT_CYCLES: u32 = 840;

#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum BusError {
    /// A status flag never came: the peripheral is not clocking (never expected), or a
    /// burst read did not finish in its tick.
    Timeout,
    /// A received byte was overwritten before it was read (SR.OVR).
    Overrun,
}

pub struct SensorBus {
    spi: SPI2,
    /// Chip selects in `Sensor::ALL` order (PA8 LSM6DSL, PB12 LIS2MDL, PC13 LPS22HB), idle high.
    cs: [AnyPin<Output>; 3],
    /// DMA1: its stream 3, channel 0, is SPI2_RX (RM0368 table 27).
    dma: DMA1,
    /// The burst in flight, until taken.
    burst: Option<Burst>,
    /// The cycle count when SPE was last cleared in receive mode: the line is the sensor's
    /// until the frame in flight then has ended ([`FRAME_END_AFTER_STOP_CYCLES`]).
    rx_stopped_at: u32,
}

/// The longest burst read: the IMU's accel + gyro block (the barometer's is 6 bytes).
pub const MAX_BURST_BYTES: usize = fcu_core::imu::registers::lsm6dsl::BURST_LEN;

/// A burst of `N` bytes fits the DMA's buffer and has a last byte apart from the DMA's (the
/// stream moves `N − 1`, and a stream of 0 items is not a transfer): checked when the
/// firmware is built, not in flight.
const fn check_burst_len<const N: usize>() {
    assert!(N >= 2 && N <= MAX_BURST_BYTES, "a burst is 2 to MAX_BURST_BYTES bytes");
}

/// The DMA stream that receives SPI2's bytes.
const RX_STREAM: usize = 3;

/// The burst's first bytes, written by the DMA (the last one is read from DR once the clock
/// has stopped). Atomics: the CPU reads what another bus master wrote, with no `unsafe`.
static BURST_DMA: [AtomicU8; MAX_BURST_BYTES - 1] = [const { AtomicU8::new(0) }; MAX_BURST_BYTES - 1];

/// Set once the transfer-complete interrupt has stopped the clock: the control tick polls
/// this without taking the bus, whose lock would mask that very interrupt and could push it
/// past the end-of-read window.
static LAST_BYTE_STARTED: AtomicBool = AtomicBool::new(false);

/// The burst of `N` bytes taken by [`SensorBus::take_burst`] (started with the same `N`): the
/// bytes the DMA wrote, then `last`.
pub fn burst_bytes<const N: usize>(last: u8) -> [u8; N] {
    const { check_burst_len::<N>() };
    // What the DMA wrote is complete before its flag rose and the last byte was seen.
    fence(Ordering::Acquire);
    let mut bytes = [last; N];
    for (b, slot) in bytes.iter_mut().zip(BURST_DMA.iter()) {
        *b = slot.load(Ordering::Relaxed);
    }
    bytes
}

/// Whether the burst in flight is down to its last byte (see [`SensorBus::take_burst`]).
pub fn last_byte_started() -> bool {
    LAST_BYTE_STARTED.load(Ordering::Acquire)
}

/// A burst read: all but its last byte go to memory by DMA, with no interrupt per byte; the
/// stream's transfer-complete interrupt stops the clock during the last byte.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// The address byte is shifting out.
    Address,
    /// The DMA is moving the first bytes.
    Streaming,
    /// The clock stops after the byte in flight, the last one.
    LastByte,
}

struct Burst {
    sensor: Sensor,
    stage: Stage,
}

impl SensorBus {
    /// Takes SPI2 already set up by `Spi::new_bidi` (mode 3, ~2.6 MHz, bidirectional,
    /// transmitting), DMA1 with its clock on, and the three chip-select outputs, which must
    /// already be high.
    pub fn new(spi: SPI2, cs: [AnyPin<Output>; 3], dma: DMA1) -> Self {
        SensorBus { spi, cs, dma, burst: None, rx_stopped_at: crate::cycles::now() }
    }

    fn cs_index(sensor: Sensor) -> usize {
        match sensor {
            Sensor::Lsm6dsl => 0,
            Sensor::Lis2mdl => 1,
            Sensor::Lps22hb => 2,
        }
    }

    fn select(&mut self, sensor: Sensor, active: bool) {
        if let Some(pin) = self.cs.get_mut(Self::cs_index(sensor)) {
            if active {
                pin.set_low();
            } else {
                pin.set_high();
            }
        }
    }

    fn wait(&self, mut done: impl FnMut(&SPI2) -> bool) -> Result<(), BusError> {
        for _ in 0..FLAG_WAIT_POLLS {
            if done(&self.spi) {
                return Ok(());
            }
        }
        Err(BusError::Timeout)
    }

    fn send(&mut self, byte: u8) -> Result<(), BusError> {
        self.wait(|spi| spi.sr().read().txe().bit_is_set())?;
        self.spi.dr().write(|w| w.dr().set(u16::from(byte)));
        Ok(())
    }

    /// Waits until the last transmitted byte has left the shift register.
    fn finish_tx(&mut self) -> Result<(), BusError> {
        self.wait(|spi| spi.sr().read().txe().bit_is_set())?;
        self.wait(|spi| spi.sr().read().bsy().bit_is_clear())
    }

    /// One register write: address then value, chip select held around both.
    pub fn write(&mut self, sensor: Sensor, addr: u8, value: u8) -> Result<(), BusError> {
        self.select(sensor, true);
        let sent = self.send(write_address(addr)).and_then(|()| self.send(value)).and_then(|()| self.finish_tx());
        self.select(sensor, false);
        sent
    }

    /// A burst read from `addr` (the sensors auto-increment) into `buf`.
    pub fn read(&mut self, sensor: Sensor, addr: u8, buf: &mut [u8]) -> Result<(), BusError> {
        self.select(sensor, true);
        let result = self.send(read_address(addr)).and_then(|()| self.finish_tx()).and_then(|()| {
            // The receive sequence is timed against the SPI clock: a pre-emption between
            // the second-to-last byte and stopping the clock would clock in extra bytes and
            // overrun. It lasts about 3 µs per byte (37 µs for the 12-byte IMU burst);
            // radio edges are timestamped by the TIM2 capture hardware meanwhile, so the
            // deferred capture interrupt loses nothing.
            cortex_m::interrupt::free(|_| self.receive(buf))
        });
        // Chip select up first, so the sensor lets go of the data line, and only then the
        // line back to MCU output (ST's order): never both driving it.
        self.select(sensor, false);
        let turned = self.back_to_tx();
        result.and(turned)
    }

    fn receive(&mut self, buf: &mut [u8]) -> Result<(), BusError> {
        // Drop anything left in the receive register so the first RXNE is our first byte.
        let _stale = self.spi.dr().read().bits();
        let _status = self.spi.sr().read().bits();

        self.spi.cr1().modify(|_, w| w.spe().clear_bit());
        self.spi.cr1().modify(|_, w| w.bidioe().clear_bit());
        let (last, head) = match buf.split_last_mut() {
            Some(parts) => parts,
            None => return Ok(()),
        };
        // Setting SPE in 1-line receive mode starts the clock: the first byte starts now.
        self.spi.cr1().modify(|_, w| w.spe().set_bit());
        let mut last_byte_started = crate::cycles::now();
        let mut result = Ok(());
        for byte in head.iter_mut() {
            result = self.wait(|spi| spi.sr().read().rxne().bit_is_set());
            if result.is_err() {
                break;
            }
            // Each RXNE is the start of the next byte: after the second-to-last, the last one.
            last_byte_started = crate::cycles::now();
            *byte = self.spi.dr().read().dr().bits() as u8;
        }
        crate::cycles::wait_since(last_byte_started, STOP_AFTER_CYCLES);
        // Clearing SPE now stops the clock at the end of the byte in flight: the last one.
        self.stop_rx_clock();
        if result.is_ok() {
            result = self.wait(|spi| spi.sr().read().rxne().bit_is_set());
            *last = self.spi.dr().read().dr().bits() as u8;
        }
        result
    }

    /// Clears SPE in receive mode: the clock stops at the end of the frame in flight.
    fn stop_rx_clock(&mut self) {
        self.spi.cr1().modify(|_, w| w.spe().clear_bit());
        self.rx_stopped_at = crate::cycles::now();
    }

    /// The line back to MCU output once the last received frame has ended: timed from the
    /// stop on the cycle counter, as BSY stays low in bidirectional receive mode. Long past
    /// when the last byte was read; a turn mid-byte would drive the line while the clock
    /// still runs.
    fn back_to_tx(&mut self) -> Result<(), BusError> {
        if self.spi.cr1().read().spe().bit_is_set() && self.spi.cr1().read().bidioe().bit_is_clear() {
            self.stop_rx_clock();
        }
        crate::cycles::wait_since(self.rx_stopped_at, FRAME_END_AFTER_STOP_CYCLES);
        self.spi.cr1().modify(|_, w| w.spe().clear_bit());
        self.spi.cr1().modify(|_, w| w.bidioe().set_bit());
        self.spi.cr1().modify(|_, w| w.spe().set_bit());
        Ok(())
    }

    /// Disables the receive stream and waits for EN to read 0: a stream stops only once the
    /// transfer in flight has finished (RM0368 §9.3.17, "Stream configuration procedure", step
    /// 1), and until then its registers ignore writes. The transfer-complete flag that the
    /// stop raises is cleared, and its interrupt unpended, so no completion path runs for a
    /// stream stopped here.
    fn stop_stream(&mut self) -> Result<(), BusError> {
        let stream = self.dma.st(RX_STREAM);
        stream.cr().modify(|_, w| w.en().clear_bit());
        let stopped = crate::cycles::poll(STREAM_STOP_WAIT_CYCLES, || stream.cr().read().en().bit_is_clear().then_some(()));
        self.clear_stream_flags();
        NVIC::unpend(Interrupt::DMA1_STREAM3);
        stopped.ok_or(BusError::Timeout)
    }

    /// Starts a burst read of `N` bytes from `addr`, in two steps so that no lock is
    /// held while the address byte shifts out (3 µs): this one selects the sensor, readies the
    /// DMA stream and writes the address; once [`SensorBus::address_sent`],
    /// [`SensorBus::receive_burst`] turns the line around and starts the clock. Then SPI2
    /// clocks the bytes in and DMA1 stream 3 moves all but the last to memory, so nothing polls
    /// the bus or takes an interrupt per byte. A burst still in flight (its waiter gave up
    /// without abandoning it) is abandoned first.
    pub fn send_burst_address<const N: usize>(&mut self, sensor: Sensor, addr: u8) -> Result<(), BusError> {
        const { check_burst_len::<N>() };
        if self.burst.is_some() {
            self.abandon_burst();
        }
        if self.spi.cr1().read().bidioe().bit_is_clear() {
            // The last burst left the line in receive: the MCU drives it again, the sensor
            // having let go when it was deselected.
            self.back_to_tx()?;
        }
        // ST's stream configuration procedure (RM0368 §9.3.17): stream off and EN read back
        // as 0, its flags cleared, addresses, count, then the configuration. EN is set once
        // SPI2's RXDMAEN is (RM0368 §20.3.9), in `receive_burst`.
        self.stop_stream()?;
        let stream = self.dma.st(RX_STREAM);
        let dr = self.spi.dr().as_ptr() as u32;
        let memory = BURST_DMA.as_ptr() as u32;
        // SAFETY: the stream reads SPI2's data register and writes BURST_DMA, a static of at
        // least NDTR bytes (`check_burst_len`) that only this module reads; nothing else is
        // given to it.
        unsafe {
            stream.par().write(|w| w.pa().bits(dr));
            stream.m0ar().write(|w| w.m0a().bits(memory));
        }
        stream.ndtr().write(|w| w.ndt().set((N - 1) as u16));
        stream.cr().write(|w| w.chsel().set(0).dir().peripheral_to_memory().minc().set_bit().tcie().set_bit().pl().high());
        self.select(sensor, true);
        if let Err(e) = self.send(read_address(addr)) {
            self.select(sensor, false);
            return Err(e);
        }
        self.burst = Some(Burst { sensor, stage: Stage::Address });
        LAST_BYTE_STARTED.store(false, Ordering::Release);
        Ok(())
    }

    /// Whether the burst's address byte has left the shift register.
    pub fn address_sent(&self) -> bool {
        let sr = self.spi.sr().read();
        sr.txe().bit_is_set() && sr.bsy().bit_is_clear()
    }

    /// Turns the line around and starts the burst's clock (after [`SensorBus::address_sent`]).
    pub fn receive_burst(&mut self) -> Result<(), BusError> {
        let Some(burst) = self.burst.as_mut().filter(|b| b.stage == Stage::Address) else {
            return Err(BusError::Timeout);
        };
        burst.stage = Stage::Streaming;
        let _stale = self.spi.dr().read().bits();
        let _status = self.spi.sr().read().bits();
        self.spi.cr1().modify(|_, w| w.spe().clear_bit());
        self.spi.cr1().modify(|_, w| w.bidioe().clear_bit());
        // RM0368 §20.3.9 (SPI communication using DMA): RXDMAEN, then the stream's EN, then SPE.
        self.spi.cr2().modify(|_, w| w.rxdmaen().set_bit());
        self.dma.st(RX_STREAM).cr().modify(|_, w| w.en().set_bit());
        // Setting SPE in 1-line receive mode starts the clock.
        self.spi.cr1().modify(|_, w| w.spe().set_bit());
        Ok(())
    }

    /// The stream's transfer-complete interrupt: all but the last byte are in memory, and the
    /// last one started with the RXNE the DMA just served, so the clock is stopped during it
    /// (the end-of-read window, see [`STOP_AFTER_CYCLES`], met from this entry at the
    /// highest priority). The last byte then waits in DR for [`SensorBus::take_burst`].
    pub fn on_dma_complete(&mut self) {
        let seen = crate::cycles::now();
        self.dma.lifcr().write(|w| w.ctcif3().clear().chtif3().clear());
        // A stream that stopped with bytes still to move was disabled, not completed (a stop
        // on the error path raises TCIF too): no completion then.
        let completed = self.dma.st(RX_STREAM).ndtr().read().ndt().bits() == 0;
        let Some(burst) = self.burst.as_mut().filter(|b| b.stage == Stage::Streaming && completed) else {
            return;
        };
        // The window opens one SCK period (32 cycles) after the last RXNE the DMA served:
        // this entry comes at least 6 cycles (tail-chained) after the transfer-complete flag,
        // which follows the DMA's read of that byte, and a whole period more makes sure. The
        // window closes 256 cycles after that RXNE: nothing more is waited for here.
        crate::cycles::wait_since(seen, DMA_STOP_AFTER_ENTRY_CYCLES);
        self.spi.cr1().modify(|_, w| w.spe().clear_bit());
        self.rx_stopped_at = crate::cycles::now();
        self.spi.cr2().modify(|_, w| w.rxdmaen().clear_bit());
        burst.stage = Stage::LastByte;
        LAST_BYTE_STARTED.store(true, Ordering::Release);
    }

    /// The burst's last byte once it is in (once), its sensor deselected; `None` while it
    /// runs. The rest is in memory: [`burst_bytes`], with no lock held.
    pub fn take_burst(&mut self) -> Option<Result<u8, BusError>> {
        let sensor = self.burst.as_ref().filter(|b| b.stage == Stage::LastByte)?.sensor;
        let sr = self.spi.sr().read();
        if sr.rxne().bit_is_clear() {
            return None;
        }
        let last = self.spi.dr().read().dr().bits() as u8;
        self.burst = None;
        self.select(sensor, false);
        Some(if sr.ovr().bit_is_set() { Err(BusError::Overrun) } else { Ok(last) })
    }

    /// Every event flag of the receive stream (LIFCR: write 1 to clear).
    fn clear_stream_flags(&self) {
        self.dma.lifcr().write(|w| w.cfeif3().clear().cdmeif3().clear().cteif3().clear().chtif3().clear().ctcif3().clear());
    }

    /// Stops a burst that did not finish: stream off (EN read back as 0), clock off, the last
    /// frame awaited, sensor deselected, bus back to transmit.
    pub fn abandon_burst(&mut self) {
        let _stopped = self.stop_stream();
        let receiving = self.spi.cr1().read().bidioe().bit_is_clear();
        if receiving {
            self.stop_rx_clock();
        }
        self.spi.cr2().modify(|_, w| w.rxdmaen().clear_bit());
        if receiving {
            // The frame in flight still clocks to its end: its RXNE (after the stale byte is
            // dropped) says it is over. Bounded: a frame stopped in its first clock never
            // comes.
            let _stale = self.spi.dr().read().bits();
            let spi = &self.spi;
            let _last = crate::cycles::poll(FRAME_END_AFTER_STOP_CYCLES, || spi.sr().read().rxne().bit_is_set().then_some(()));
        }
        if let Some(b) = self.burst.take() {
            self.select(b.sensor, false);
        }
        LAST_BYTE_STARTED.store(false, Ordering::Release);
        let _turned = self.back_to_tx();
        let _stale = self.spi.dr().read().bits();
        let _status = self.spi.sr().read().bits();
    }

    pub fn read_u8(&mut self, sensor: Sensor, addr: u8) -> Result<u8, BusError> {
        let mut b = [0u8; 1];
        self.read(sensor, addr, &mut b)?;
        let [value] = b;
        Ok(value)
    }
}
