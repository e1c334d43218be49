//! DMA1 (0x4002_6000) and DMA2 (0x4002_6400), both on AHB1 (RM0368 §9), as the board uses
//! them: peripheral to memory, byte by byte, into SRAM, for the requests of RM0368 §9.3.3
//! tables 27 and 28 (DMA1 and DMA2 request mapping) that the firmware may use:
//! - DMA1 stream 3, channel 0: SPI2_RX (the IMU burst);
//! - DMA2 stream 2, channel 4, and DMA2 stream 5, channel 4: USART1_RX (table 28 maps USART1_RX
//!   to both; either serves it).
//!
//! Register layout from the `stm32f4` PAC (`dma2`): LISR 0x00, HISR 0x04 (read-only flags),
//! LIFCR 0x08, HIFCR 0x0C (write 1 to clear), then per stream x at 0x10 + 0x18·x: SxCR, SxNDTR,
//! SxPAR, SxM0AR, SxM1AR, SxFCR (reset 0x0000_0021). The flags of streams 0/4, 1/5, 2/6, 3/7
//! sit at bits 0, 6, 16 and 22 of their register: FEIF, (reserved), DMEIF, TEIF, HTIF, TCIF.
//!
//! Behaviour (RM0368 §9.3 and §9.5):
//! - a stream's configuration (SxCR but EN, SxNDTR, SxPAR, SxM0AR, SxFCR) can be written only
//!   while EN = 0; a write while it is 1 is ignored (counted in [`Dma::ignored_writes`]);
//! - before EN is set, the stream's event flags must have been cleared (RM0368 §9.3.17 "Stream
//!   configuration procedure", step 9 and the SxCR EN description): setting EN with a flag still
//!   up is refused here (the RM does not say what the stream then does);
//! - each request from the peripheral moves one data item; SxNDTR counts down; HTIF at the
//!   half; at 0 TCIF. Normal mode: the stream then stops (EN cleared) and further requests wait
//!   in the peripheral. Circular mode (CIRC, RM0368 §9.3.9 "Circular mode"): NDTR reloads with
//!   the value programmed at EN and the memory address restarts at M0AR, the stream stays
//!   enabled, and HTIF/TCIF set again on every lap: a ring buffer the peripheral keeps filling
//!   whatever the CPU does (a flash erase stalls the CPU, not the DMA: RM0368 §3.5, the AHB bus
//!   matrix gives the DMA its own path to SRAM);
//! - EN cleared by software during a transfer stops the stream and sets TCIF (SxCR EN: "when
//!   cleared by software … the transfer complete flag is set"), but not at once: the stream
//!   finishes the transfer in flight first, and EN reads 1 until then (RM0368 §9.3.17, step 1:
//!   "writing this bit to 0 is not immediately effective since it is actually written to 0
//!   once all the current transfers have finished"; read EN back before configuring). The
//!   model takes one transfer ([`STOP_LATENCY_HCLK_CYCLES`]) for every stop, as if a request
//!   were always in flight: configuration writes meanwhile are ignored as on the part, and the
//!   TCIF comes after them, so a flag cleared right after the EN write is up again.
//!
//! Fault injection: [`Dma::set_starved`] holds a stream's requests back (a stream the arbiter
//! never grants), so the peripheral's data waits and a transfer never completes.
//!
//! Modelled: the three routes above, peripheral to memory, PSIZE = MSIZE = byte, direct mode
//! (FCR.DMDIS = 0), normal or circular mode, no double-buffer mode, single transfers, the
//! memory in SRAM with or without increment, the peripheral address fixed at the request's
//! data register. Any other stream, channel or setting is refused when EN is set (an
//! [`Unmodelled`] error names it), so a wrong set-up cannot pass as a transfer. Memory writes
//! are handed to the machine, which stores them in the guest's RAM.

use super::{Time, Unmodelled};

/// DMA1's base address (RM0368 table 1).
pub const BASE: u32 = 0x4002_6000;
/// DMA2's base address (RM0368 table 1).
pub const DMA2_BASE: u32 = 0x4002_6400;

const LISR: u32 = 0x00;
const HISR: u32 = 0x04;
const LIFCR: u32 = 0x08;
const HIFCR: u32 = 0x0C;
const STREAM0: u32 = 0x10;
const STREAM_STRIDE: u32 = 0x18;

// SxCR fields.
pub const CR_EN: u32 = 1 << 0;
pub const CR_TEIE: u32 = 1 << 2;
pub const CR_HTIE: u32 = 1 << 3;
pub const CR_TCIE: u32 = 1 << 4;
pub const CR_DMEIE: u32 = 1 << 1;
const CR_PFCTRL: u32 = 1 << 5;
const CR_DIR: u32 = 0b11 << 6;
const CR_CIRC: u32 = 1 << 8;
const CR_PINC: u32 = 1 << 9;
pub const CR_MINC: u32 = 1 << 10;
const CR_PSIZE: u32 = 0b11 << 11;
const CR_MSIZE: u32 = 0b11 << 13;
const CR_DBM: u32 = 1 << 18;
const CR_BURSTS: u32 = (0b11 << 21) | (0b11 << 23);
const CR_CHSEL: u32 = 0b111 << 25;
/// Every SxCR field (bits 27:0 less reserved bit 20).
const CR_FIELDS: u32 = 0x0FEF_FFFF;
const FCR_RESET: u32 = 0x21;
const FCR_DMDIS: u32 = 1 << 2;

// Flags of a stream, shifted to its position.
pub const FLAG_FEIF: u32 = 1 << 0;
pub const FLAG_DMEIF: u32 = 1 << 2;
pub const FLAG_TEIF: u32 = 1 << 3;
pub const FLAG_HTIF: u32 = 1 << 4;
pub const FLAG_TCIF: u32 = 1 << 5;
const FLAGS: u32 = 0b11_1101;

/// HCLK cycles from a software EN = 0 to the stream's stop: one transfer from an APB1
/// peripheral to SRAM (arbitration, the read through the AHB/APB bridge, two PCLK1 cycles at
/// half HCLK, the SRAM write).
pub const STOP_LATENCY_HCLK_CYCLES: u64 = 10;

/// The stream of SPI2_RX on DMA1.
pub const SPI2_RX_STREAM: usize = 3;
/// SPI2's data register.
pub const SPI2_DR: u32 = 0x4000_380C;
/// USART1's data register.
pub const USART1_DR: u32 = 0x4001_1004;
/// The DMA2 streams table 28 maps USART1_RX to (channel 4 on both).
pub const USART1_RX_STREAMS: [usize; 2] = [2, 5];

/// The two DMA controllers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Controller {
    Dma1,
    Dma2,
}

/// A peripheral's DMA request the board wires.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request {
    Spi2Rx,
    Usart1Rx,
}

/// The modelled routes (RM0368 tables 27 and 28): controller, stream, channel, request, the
/// peripheral's data register.
const ROUTES: [(Controller, usize, u32, Request, u32); 3] = [
    (Controller::Dma1, 3, 0, Request::Spi2Rx, SPI2_DR),
    (Controller::Dma2, 2, 4, Request::Usart1Rx, USART1_DR),
    (Controller::Dma2, 5, 4, Request::Usart1Rx, USART1_DR),
];

/// Where a stream's flags sit in LISR/HISR: (high register, bit shift).
fn flag_position(stream: usize) -> (bool, u32) {
    let shift = [0, 6, 16, 22][stream % 4];
    (stream >= 4, shift)
}

#[derive(Clone, Debug, Default)]
struct Stream {
    cr: u32,
    ndtr: u32,
    par: u32,
    m0ar: u32,
    m1ar: u32,
    fcr: u32,
    flags: u32,
    /// Items moved since EN was set (the memory offset with MINC).
    moved: u32,
    /// NDTR when EN was set (for the half-transfer flag).
    started_with: u32,
    /// When a software EN = 0 takes effect (EN reads 1 until then).
    stops_at: Option<Time>,
    /// Requests are held back (fault injection, [`Dma::set_starved`]).
    starved: bool,
    /// Transfers that completed (NDTR reached 0).
    completions: u32,
}

/// A DMA controller's model.
#[derive(Clone, Debug)]
pub struct Dma {
    controller: Controller,
    streams: [Stream; 8],
    writes: Vec<(u32, u8)>,
    ignored_writes: u32,
    /// Time units per HCLK cycle (reset: HSI 16 MHz).
    hclk_units: Time,
}

impl Default for Dma {
    fn default() -> Self {
        Dma::new()
    }
}

impl Dma {
    /// DMA1 at reset.
    pub fn new() -> Dma {
        Dma::of(Controller::Dma1)
    }

    /// DMA2 at reset.
    pub fn dma2() -> Dma {
        Dma::of(Controller::Dma2)
    }

    fn of(controller: Controller) -> Dma {
        let hclk_units = super::TIME_HZ / super::Clocks::RESET.hclk_hz;
        let mut d = Dma { controller, streams: Default::default(), writes: Vec::new(), ignored_writes: 0, hclk_units };
        for s in &mut d.streams {
            s.fcr = FCR_RESET;
        }
        d
    }

    fn name(&self) -> &'static str {
        match self.controller {
            Controller::Dma1 => "DMA1",
            Controller::Dma2 => "DMA2",
        }
    }

    /// The enabled stream serving `request` now, if any (the lowest-numbered one if the
    /// firmware enabled two for the same request).
    fn serving(&self, request: Request) -> Option<usize> {
        ROUTES.iter().find_map(|&(c, stream, channel, r, _)| {
            let s = &self.streams[stream];
            (c == self.controller && r == request && s.cr & CR_EN != 0 && !s.starved && (s.cr & CR_CHSEL) >> 25 == channel)
                .then_some(stream)
        })
    }

    /// How many more items of `request` the controller takes now without the CPU: the
    /// stream's NDTR, unbounded for a circular stream, 0 if no stream serves it.
    pub fn capacity(&self, request: Request) -> u32 {
        match self.serving(request) {
            Some(i) if self.streams[i].cr & CR_CIRC != 0 => u32::MAX,
            Some(i) => self.streams[i].ndtr,
            None => 0,
        }
    }

    /// One request served: `byte`, read from the peripheral's data register, goes to memory.
    /// Returns false (nothing moved) if no stream serves the request.
    pub fn serve(&mut self, request: Request, byte: u8) -> bool {
        let Some(i) = self.serving(request) else { return false };
        let s = &mut self.streams[i];
        if s.ndtr == 0 {
            return false;
        }
        let offset = if s.cr & CR_MINC != 0 { s.moved } else { 0 };
        self.writes.push((s.m0ar.wrapping_add(offset), byte));
        s.moved += 1;
        s.ndtr -= 1;
        if s.started_with >= 2 && s.ndtr == s.started_with / 2 {
            s.flags |= FLAG_HTIF;
        }
        if s.ndtr == 0 {
            s.flags |= FLAG_TCIF;
            s.completions += 1;
            if s.cr & CR_CIRC != 0 {
                s.ndtr = s.started_with;
                s.moved = 0;
            } else {
                s.cr &= !CR_EN;
                s.stops_at = None;
            }
        }
        true
    }

    /// Holds back (or again serves) the requests of `stream`: a stream the arbiter does not
    /// grant. Its peripheral's data waits; an enabled transfer does not complete.
    pub fn set_starved(&mut self, stream: usize, starved: bool) {
        if let Some(s) = self.streams.get_mut(stream) {
            s.starved = starved;
        }
    }

    /// Transfers of `stream` that completed (NDTR reached 0), not counting stops by software.
    pub fn completions(&self, stream: usize) -> u32 {
        self.streams.get(stream).map_or(0, |s| s.completions)
    }

    /// The software stops whose time has come by `now`: EN reads 0, TCIF up.
    fn finish_stops(&mut self, now: Time) {
        for s in &mut self.streams {
            if s.stops_at.is_some_and(|t| t <= now) {
                s.stops_at = None;
                s.cr &= !CR_EN;
                s.flags |= FLAG_TCIF;
            }
        }
    }

    /// Configuration writes ignored because their stream was enabled.
    pub fn ignored_writes(&self) -> u32 {
        self.ignored_writes
    }

    /// The memory writes of the transfers since the last call: (address, byte).
    pub fn take_memory_writes(&mut self) -> Vec<(u32, u8)> {
        std::mem::take(&mut self.writes)
    }

    /// How many more SPI2_RX requests stream 3 serves now (0 unless it is enabled for them).
    pub fn spi2_rx_capacity(&self) -> u32 {
        self.capacity(Request::Spi2Rx)
    }

    /// One SPI2_RX request served: the byte read from SPI2's DR goes to memory.
    pub fn spi2_rx(&mut self, byte: u8) {
        self.serve(Request::Spi2Rx, byte);
    }

    /// The interrupt line of stream `stream`: a flag up with its enable.
    pub fn irq_line(&self, stream: usize) -> bool {
        let s = &self.streams[stream % 8];
        (s.flags & FLAG_TCIF != 0 && s.cr & CR_TCIE != 0)
            || (s.flags & FLAG_HTIF != 0 && s.cr & CR_HTIE != 0)
            || (s.flags & FLAG_TEIF != 0 && s.cr & CR_TEIE != 0)
            || (s.flags & FLAG_DMEIF != 0 && s.cr & CR_DMEIE != 0)
    }

    fn flags_register(&self, high: bool) -> u32 {
        (0..4).fold(0, |acc, i| {
            let stream = if high { i + 4 } else { i };
            acc | (self.streams[stream].flags << flag_position(stream).1)
        })
    }

    pub fn read(&mut self, offset: u32, now: Time) -> Result<u32, Unmodelled> {
        self.finish_stops(now);
        match offset {
            LISR => Ok(self.flags_register(false)),
            HISR => Ok(self.flags_register(true)),
            LIFCR | HIFCR => Ok(0),
            _ => {
                let (stream, reg) = stream_register(offset).ok_or_else(|| Unmodelled::offset(self.name(), offset, false))?;
                let s = &self.streams[stream];
                Ok(match reg {
                    0x00 => s.cr,
                    0x04 => s.ndtr,
                    0x08 => s.par,
                    0x0C => s.m0ar,
                    0x10 => s.m1ar,
                    _ => s.fcr,
                })
            }
        }
    }

    pub fn write(&mut self, offset: u32, value: u32, now: Time) -> Result<(), Unmodelled> {
        self.finish_stops(now);
        match offset {
            LISR | HISR => Ok(()),
            LIFCR | HIFCR => {
                for i in 0..4 {
                    let stream = if offset == HIFCR { i + 4 } else { i };
                    let shift = flag_position(stream).1;
                    self.streams[stream].flags &= !((value >> shift) & FLAGS);
                }
                Ok(())
            }
            _ => {
                let (stream, reg) = stream_register(offset).ok_or_else(|| Unmodelled::offset(self.name(), offset, true))?;
                if reg == 0x00 {
                    return self.write_cr(stream, value, now);
                }
                let name = self.name();
                let s = &mut self.streams[stream];
                if s.cr & CR_EN != 0 {
                    self.ignored_writes += 1;
                    return Ok(());
                }
                match reg {
                    0x04 => s.ndtr = value & 0xFFFF,
                    0x08 => s.par = value,
                    0x0C => s.m0ar = value,
                    0x10 => s.m1ar = value,
                    _ => {
                        Unmodelled::check_bits(&format!("{name}.S{stream}FCR"), value, 0xBF)?;
                        s.fcr = value & 0xBF;
                    }
                }
                Ok(())
            }
        }
    }

    fn write_cr(&mut self, stream: usize, value: u32, now: Time) -> Result<(), Unmodelled> {
        let name = format!("{}.S{stream}CR", self.name());
        Unmodelled::check_bits(&name, value, CR_FIELDS)?;
        let controller = self.controller;
        let stop_latency = STOP_LATENCY_HCLK_CYCLES * self.hclk_units;
        let s = &mut self.streams[stream];
        if s.cr & CR_EN != 0 {
            // Enabled: only EN can change; clearing it stops the stream once the transfer in
            // flight is done (TCIF set then).
            if value & CR_EN == 0 {
                if s.stops_at.is_none() {
                    s.stops_at = Some(now + stop_latency);
                }
            } else if value != s.cr || s.stops_at.is_some() {
                self.ignored_writes += 1;
            }
            return Ok(());
        }
        if value & CR_EN == 0 {
            s.cr = value;
            return Ok(());
        }
        if s.flags != 0 {
            return Err(Unmodelled::new(
                name,
                format!("EN set with the stream's event flags {:#04x} still up (RM0368 §9.3.17: clear them first)", s.flags),
            ));
        }
        let route = ROUTES.iter().find(|&&(c, st, _, _, _)| c == controller && st == stream);
        let channel = (value & CR_CHSEL) >> 25;
        let unsupported = [
            (route.is_none(), "a stream no modelled request uses (DMA1 stream 3, DMA2 streams 2 and 5)"),
            (route.is_some_and(|r| r.2 != channel), "a channel other than the modelled request's on this stream"),
            (value & CR_DIR != 0, "a direction other than peripheral to memory"),
            (value & (CR_PSIZE | CR_MSIZE) != 0, "a data size other than a byte"),
            (value & (CR_PFCTRL | CR_DBM | CR_BURSTS | CR_PINC) != 0, "flow control, double-buffer, bursts or a peripheral increment"),
            (s.fcr & FCR_DMDIS != 0, "FIFO mode (FCR.DMDIS = 1)"),
            (route.is_some_and(|r| s.par != r.4), "a peripheral address other than the request's data register"),
            (s.ndtr == 0, "NDTR = 0"),
        ];
        if let Some((_, what)) = unsupported.iter().find(|(bad, _)| *bad) {
            return Err(Unmodelled::new(name, format!("EN set for {what}: not modelled")));
        }
        let m0ar = s.m0ar;
        let span = if value & CR_MINC != 0 { s.ndtr } else { 1 };
        let in_sram = (0x2000_0000..0x2001_0000).contains(&m0ar) && m0ar.checked_add(span).is_some_and(|end| end <= 0x2001_0000);
        if !in_sram {
            return Err(Unmodelled::new(name, format!("EN set with M0AR {m0ar:#010x} for {span} bytes outside SRAM: not modelled")));
        }
        s.cr = value;
        s.moved = 0;
        s.started_with = s.ndtr;
        Ok(())
    }
}

/// (stream, register offset within the stream) of a register offset.
fn stream_register(offset: u32) -> Option<(usize, u32)> {
    let rel = offset.checked_sub(STREAM0)?;
    let stream = (rel / STREAM_STRIDE) as usize;
    (stream < 8 && offset % 4 == 0).then_some((stream, rel % STREAM_STRIDE))
}

impl super::Peripheral for Dma {
    fn read(&mut self, offset: u32, now: Time, _clocks: super::Clocks) -> Result<u32, Unmodelled> {
        Dma::read(self, offset, now)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, _clocks: super::Clocks) -> Result<(), Unmodelled> {
        Dma::write(self, offset, value, now)
    }

    fn next_event(&self) -> Option<Time> {
        self.streams.iter().filter_map(|s| s.stops_at).min()
    }

    fn advance(&mut self, now: Time, _clocks: super::Clocks) {
        self.finish_stops(now);
    }

    fn set_clocks(&mut self, _now: Time, clocks: super::Clocks) {
        self.hclk_units = (super::TIME_HZ / clocks.hclk_hz.max(1)).max(1);
    }

    fn irq_line(&self, stream: usize) -> bool {
        Dma::irq_line(self, stream)
    }

    /// Back to reset, still the same controller (DMA1 and DMA2 have their own reset bits).
    /// What was injected and counted is the board's and stays.
    fn reset(&mut self) {
        let mut fresh = Dma::of(self.controller);
        fresh.hclk_units = self.hclk_units;
        fresh.ignored_writes = self.ignored_writes;
        for (new, old) in fresh.streams.iter_mut().zip(&self.streams) {
            new.starved = old.starved;
            new.completions = old.completions;
        }
        *self = fresh;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periph::Peripheral;

    const S3: u32 = STREAM0 + 3 * STREAM_STRIDE;
    const BUF: u32 = 0x2000_1000;

    /// ST's stream configuration procedure (RM0368 §9.3.17) for SPI2_RX into `BUF`.
    fn configure(d: &mut Dma, n: u32) {
        d.write(S3, 0, 0).unwrap();
        d.write(LIFCR, 0b11_1101 << 22, 0).unwrap();
        d.write(S3 + 0x08, SPI2_DR, 0).unwrap();
        d.write(S3 + 0x0C, BUF, 0).unwrap();
        d.write(S3 + 0x04, n, 0).unwrap();
        d.write(S3, CR_MINC | CR_TCIE | (0b10 << 16), 0).unwrap();
        d.write(S3, CR_MINC | CR_TCIE | (0b10 << 16) | CR_EN, 0).unwrap();
    }

    #[test]
    fn reset_values_and_the_flag_positions() {
        let mut d = Dma::new();
        assert_eq!(d.read(S3 + 0x14, 0), Ok(FCR_RESET));
        assert_eq!(d.read(LISR, 0), Ok(0));
        assert_eq!(flag_position(3), (false, 22));
        assert_eq!(flag_position(7), (true, 22));
        assert!(d.read(0x100, 0).is_err());
    }

    #[test]
    fn a_transfer_moves_n_bytes_then_completes_and_disables_the_stream() {
        let mut d = Dma::new();
        configure(&mut d, 3);
        assert_eq!(d.spi2_rx_capacity(), 3);
        for b in [0xA1, 0xB2, 0xC3] {
            d.spi2_rx(b);
        }
        assert_eq!(d.take_memory_writes(), vec![(BUF, 0xA1), (BUF + 1, 0xB2), (BUF + 2, 0xC3)]);
        assert_eq!(d.read(LISR, 0).unwrap() >> 22 & FLAGS, FLAG_TCIF | FLAG_HTIF);
        assert_eq!(d.read(S3, 0).unwrap() & CR_EN, 0, "EN cleared at the end");
        assert!(d.irq_line(3));
        assert_eq!(d.spi2_rx_capacity(), 0, "the next byte stays in SPI2's DR");
        d.write(LIFCR, FLAG_TCIF << 22, 0).unwrap();
        assert!(!d.irq_line(3));
    }

    /// Rule (RM0368 §9.3.17): the stream's flags must be cleared before EN is set again.
    #[test]
    fn enabling_with_the_last_transfers_flags_up_is_refused() {
        let mut d = Dma::new();
        configure(&mut d, 1);
        d.spi2_rx(1);
        assert!(d.write(S3, CR_MINC | CR_TCIE | CR_EN, 0).is_err());
    }

    /// Rule (SxCR, SxNDTR, SxMxAR: writable only while EN = 0): a write to a running stream's
    /// configuration is ignored.
    #[test]
    fn configuration_written_while_enabled_is_ignored() {
        let mut d = Dma::new();
        configure(&mut d, 4);
        d.write(S3 + 0x04, 100, 0).unwrap();
        d.write(S3 + 0x0C, 0x2000_2000, 0).unwrap();
        assert_eq!(d.read(S3 + 0x04, 0), Ok(4));
        assert_eq!(d.ignored_writes(), 2);
    }

    /// Rule (SxCR EN): cleared by software mid-transfer, the stream stops with TCIF set, once
    /// the transfer in flight is done.
    #[test]
    fn disabling_mid_transfer_stops_with_tcif() {
        let mut d = Dma::new();
        configure(&mut d, 4);
        d.spi2_rx(1);
        d.write(S3, CR_MINC | CR_TCIE, 0).unwrap();
        let stop = STOP_LATENCY_HCLK_CYCLES * d.hclk_units;
        assert_eq!(d.next_event(), Some(stop));
        d.advance(stop, super::super::Clocks::RESET);
        assert_eq!(d.spi2_rx_capacity(), 0);
        assert_eq!(d.read(LISR, stop).unwrap() >> 22 & FLAG_TCIF, FLAG_TCIF);
        assert_eq!(d.read(S3 + 0x04, stop), Ok(3), "NDTR keeps what was left");
        assert_eq!(d.completions(3), 0, "a stop is not a completion");
    }

    /// Rule (RM0368 §9.3.17, step 1): EN = 0 takes effect after the transfer in flight; until
    /// EN reads 0 the stream ignores its configuration, and the TCIF the stop raises comes
    /// after a flag clear written right behind the EN write. The wrong sequence (reconfigure
    /// at once) keeps the old addresses and leaves a flag up that raises the interrupt.
    #[test]
    fn a_stream_reconfigured_before_en_reads_0_keeps_its_old_configuration() {
        let mut d = Dma::new();
        configure(&mut d, 4);
        d.write(S3, CR_MINC | CR_TCIE, 10).unwrap();
        assert_ne!(d.read(S3, 10).unwrap() & CR_EN, 0, "EN still reads 1");
        d.write(LIFCR, 0b11_1101 << 22, 10).unwrap();
        d.write(S3 + 0x0C, 0x2000_2000, 10).unwrap();
        d.write(S3 + 0x04, 7, 10).unwrap();
        assert_eq!(d.ignored_writes(), 2, "both configuration writes ignored");
        let later = 10 + STOP_LATENCY_HCLK_CYCLES * d.hclk_units;
        assert_eq!(d.read(S3, later).unwrap() & CR_EN, 0, "EN reads 0 once the transfer is done");
        assert!(d.irq_line(3), "the stop's TCIF came after the clear");
        assert_eq!((d.read(S3 + 0x0C, later), d.read(S3 + 0x04, later)), (Ok(BUF), Ok(4)));
        // The right sequence: EN read back as 0, then the flags and the configuration.
        d.write(LIFCR, 0b11_1101 << 22, later).unwrap();
        d.write(S3 + 0x04, 7, later).unwrap();
        assert_eq!((d.read(S3 + 0x04, later), d.ignored_writes(), d.irq_line(3)), (Ok(7), 2, false));
    }

    /// A starved stream takes no request, and takes them again once granted.
    #[test]
    fn a_starved_stream_takes_no_request() {
        let mut d = Dma::new();
        configure(&mut d, 2);
        d.set_starved(3, true);
        assert_eq!(d.spi2_rx_capacity(), 0);
        d.set_starved(3, false);
        d.spi2_rx(1);
        d.spi2_rx(2);
        assert_eq!(d.completions(3), 1);
    }

    #[test]
    fn what_is_not_modelled_is_refused_at_enable() {
        for (stream_cr, value) in [
            (STREAM0, CR_EN),           // stream 0
            (S3, CR_EN | (1 << 25)),    // channel 1
            (S3, CR_EN | (0b01 << 6)),  // memory to peripheral
            (S3, CR_EN | (0b01 << 11)), // half-word peripheral
            (S3, CR_EN | CR_DBM),       // double buffer
        ] {
            let mut d = Dma::new();
            d.write(S3 + 0x08, SPI2_DR, 0).unwrap();
            d.write(S3 + 0x0C, BUF, 0).unwrap();
            d.write(S3 + 0x04, 4, 0).unwrap();
            assert!(d.write(stream_cr, value, 0).is_err(), "{value:#x}");
        }
        let mut d = Dma::new();
        d.write(S3 + 0x08, SPI2_DR, 0).unwrap();
        d.write(S3 + 0x0C, 0x0800_0000, 0).unwrap();
        d.write(S3 + 0x04, 4, 0).unwrap();
        assert!(d.write(S3, CR_EN | CR_MINC, 0).is_err(), "memory in flash");
        // DMA2: USART1_RX is channel 4 on streams 2 and 5 only, from USART1's DR.
        for (stream, channel, par) in [(2u32, 3u32, USART1_DR), (3, 4, USART1_DR), (5, 4, SPI2_DR)] {
            let mut d = Dma::dma2();
            let base = STREAM0 + stream * STREAM_STRIDE;
            d.write(base + 0x08, par, 0).unwrap();
            d.write(base + 0x0C, BUF, 0).unwrap();
            d.write(base + 0x04, 4, 0).unwrap();
            assert!(d.write(base, CR_EN | CR_MINC | (channel << 25), 0).is_err(), "stream {stream} channel {channel}");
        }
    }

    const S5: u32 = STREAM0 + 5 * STREAM_STRIDE;

    /// USART1_RX on DMA2 stream 5, channel 4, circular over `n` bytes at `BUF`.
    fn usart1_rx_circular(d: &mut Dma, n: u32) {
        d.write(S5 + 0x08, USART1_DR, 0).unwrap();
        d.write(S5 + 0x0C, BUF, 0).unwrap();
        d.write(S5 + 0x04, n, 0).unwrap();
        d.write(S5, (4 << 25) | CR_MINC | CR_CIRC | CR_HTIE | CR_TCIE | CR_EN, 0).unwrap();
    }

    /// Circular mode (RM0368 §9.3.9): NDTR reloads and the memory address wraps to M0AR; HTIF
    /// and TCIF on every lap; the stream stays enabled, so no byte waits for the CPU.
    #[test]
    fn a_circular_stream_wraps_reloads_ndtr_and_flags_every_lap() {
        let mut d = Dma::dma2();
        usart1_rx_circular(&mut d, 4);
        assert_eq!(d.capacity(Request::Usart1Rx), u32::MAX);
        for b in 0..6u8 {
            assert!(d.serve(Request::Usart1Rx, b));
        }
        let writes = d.take_memory_writes();
        assert_eq!(writes, vec![(BUF, 0), (BUF + 1, 1), (BUF + 2, 2), (BUF + 3, 3), (BUF, 4), (BUF + 1, 5)]);
        // Stream 5's flags: HISR bit 6 upward.
        assert_eq!(d.read(HISR, 0).unwrap() >> 6 & FLAGS, FLAG_TCIF | FLAG_HTIF);
        assert_eq!(d.read(S5 + 0x04, 0), Ok(2), "NDTR reloaded to 4 at the wrap, then 2 more moved");
        assert_ne!(d.read(S5, 0).unwrap() & CR_EN, 0, "still enabled");
        assert!(d.irq_line(5));
        d.write(HIFCR, (FLAG_TCIF | FLAG_HTIF) << 6, 0).unwrap();
        assert!(!d.irq_line(5));
        d.serve(Request::Usart1Rx, 6);
        assert_eq!(d.read(HISR, 0).unwrap() >> 6 & FLAGS, 0);
        d.serve(Request::Usart1Rx, 7);
        assert_eq!(d.read(HISR, 0).unwrap() >> 6 & FLAGS, FLAG_TCIF, "the end of the second lap");
    }

    /// A reset through RCC (AHB1RSTR: bit 21 for DMA1, bit 22 for DMA2) takes the controller
    /// back to its own reset state: DMA2's streams stop and it still routes USART1_RX.
    #[test]
    fn a_reset_stops_the_streams_and_keeps_the_controller() {
        use crate::periph::Peripheral;
        let mut d = Dma::dma2();
        usart1_rx_circular(&mut d, 4);
        Peripheral::reset(&mut d);
        assert_eq!(d.read(S5, 0), Ok(0), "stream 5 disabled");
        assert_eq!(d.capacity(Request::Usart1Rx), 0);
        // DMA1 has no USART1_RX route: enabling this stream would be refused.
        usart1_rx_circular(&mut d, 4);
        assert_eq!(d.capacity(Request::Usart1Rx), u32::MAX);
    }

    /// The wrong sequence: the same ring in normal mode stops at NDTR = 0 and takes nothing
    /// more until the CPU re-arms it.
    #[test]
    fn a_normal_stream_stops_at_its_end_and_takes_no_more_requests() {
        let mut d = Dma::dma2();
        d.write(S5 + 0x08, USART1_DR, 0).unwrap();
        d.write(S5 + 0x0C, BUF, 0).unwrap();
        d.write(S5 + 0x04, 2, 0).unwrap();
        d.write(S5, (4 << 25) | CR_MINC | CR_EN, 0).unwrap();
        assert!(d.serve(Request::Usart1Rx, 1));
        assert!(d.serve(Request::Usart1Rx, 2));
        assert_eq!(d.capacity(Request::Usart1Rx), 0);
        assert!(!d.serve(Request::Usart1Rx, 3), "the third byte stays in the peripheral");
        assert_eq!(d.take_memory_writes().len(), 2);
    }
}
