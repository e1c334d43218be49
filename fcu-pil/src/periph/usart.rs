//! USART1 (RM0368 §19) at 0x4001_1000: transmitter and receiver, 8N1.
//!
//! Modelled: SR (TXE, TC, RXNE, ORE, IDLE, FE; TC and RXNE cleared by writing 0), DR (TDR on
//! write, RDR on read), BRR (both oversampling modes), CR1 UE, TE, RE, TXEIE, TCIE, RXNEIE,
//! IDLEIE, OVER8, CR2 STOP, CR3 DMAR (receive DMA). Not modelled (an [`Unmodelled`] error when
//! set): 9-bit words (M), parity (PCE, PS, PEIE), send break, mute mode and wake-up, LIN, the
//! synchronous clock output, the rest of CR3 (transmit DMA, flow control, IrDA, smartcard,
//! half-duplex, EIE) and GTPR.
//!
//! Reception (RM0368 §19.3.3 "Receiver"): with UE and RE set, a frame on the RX line (the board
//! decides whether PA10 carries it, see `crate::board`) lands at the end of its stop bit:
//! - RDR empty (RXNE = 0): the byte goes to RDR and RXNE sets;
//! - RXNE still set: the byte is lost and ORE sets ("the RDR content will not be lost … the
//!   shift register will be overwritten"); RDR keeps the unread byte;
//! - a frame whose baud rate is more than 3.75 % off the receiver's (RM0368 §19.3.5, 16×
//!   oversampling, 8 bits, no fraction) sets FE with RXNE; what RDR holds then is not predicted
//!   (the model stores 0, an assumption);
//! - with UE or RE clear the receiver ignores the line: the byte is counted in
//!   [`Usart::rx_ignored`].
//!
//! RXNE clears by a DR read or by writing 0 to it. ORE, IDLE and FE clear only by an SR read
//! followed by a DR read (RM0368 §19.6.1): a write to SR does not touch them. IDLE sets when the
//! line stays idle for a whole frame (10 bits at the receiver's rate) after a received byte, and
//! not again until another byte has set RXNE. The interrupt line adds RXNEIE·(RXNE + ORE) and
//! IDLEIE·IDLE (RM0368 §19.7, "USART interrupt requests"). With DMAR (RM0368 §19.3.13
//! "Continuous communication using DMA") RXNE raises a DMA request; the DMA's read of DR clears
//! RXNE.
//!
//! RE and the HAL: stm32f4xx-hal's `Serial::tx` (0.23 `serial.rs`, `Serial::_new`) writes CR1
//! with RE = 1 even for a transmit-only serial, so the receiver runs and a byte arriving on PA10
//! sets RXNE (and ORE with the next one) whether the firmware reads them or not.
//!
//! Transmission (RM0368 §19.3.2 "Transmitter"): setting TE (with UE) first sends an idle frame
//! (a frame of 1s). A DR write with the shift register empty moves the byte there at once (TXE
//! stays 1); otherwise it waits in TDR (TXE = 0) until the frame in progress ends. A frame is
//! 1 start + 8 data + 0.5/1/1.5/2 stop bits (CR2.STOP); one bit lasts 8·(2 − OVER8)·USARTDIV
//! PCLK2 cycles, i.e. BRR PCLK2 cycles with OVER8 = 0 and 8·mantissa + BRR[2:0] with OVER8 = 1
//! (RM0368 §19.3.4: baud = f_PCLK / (8·(2 − OVER8)·USARTDIV)). A frame's length is fixed when its
//! byte is written to DR (or TE is set), from BRR, CR2 and PCLK2 at that moment. TC sets when a
//! frame ends with TDR empty; it clears by a read of SR followed by a write to DR, or by writing
//! 0 to it. Finished frames go to [`Usart::take_output`] with the times their start bit began and
//! their stop bits ended: the board decides whether the TX pin carried them.
//!
//! A BRR write during a frame: RM0368 §19.3.4 says the baud counters take the new value at once
//! ("the baud rate register value should not be changed during communication"), so the frame in
//! the shift register goes out partly at one rate and partly at the other. The model reports it
//! as not intact ([`SentFrame::intact`]), keeping its end time; a byte waiting in TDR is sent at
//! the new rate.
//!
//! A DR write while TXE = 0 overwrites the byte waiting in TDR: that byte is lost, a firmware
//! defect counted in [`Usart::lost_bytes`]. A DR write with the transmitter disabled (UE or
//! TE = 0), disabling it during a frame, or a frame with USARTDIV < 1 is an [`Unmodelled`] error.
//!
//! Layout, reset values and access types from the `stm32f4` 0.16 PAC (`stm32f401/usart1/*.rs`:
//! SR resets to 0x00C0, TC/RXNE/LBD/CTS are rc_w0).

use super::{units_per_cycle, Clocks, Time, Unmodelled};

/// Base address of USART1 (RM0368 memory map).
pub const BASE: u32 = 0x4001_1000;
/// Peripheral name used in error messages.
pub const NAME: &str = "USART1";

const SR: u32 = 0x00;
pub const DR: u32 = 0x04;
const BRR: u32 = 0x08;
const CR1: u32 = 0x0C;
const CR2: u32 = 0x10;
const CR3: u32 = 0x14;
const GTPR: u32 = 0x18;

const SR_FE: u32 = 1 << 1;
const SR_ORE: u32 = 1 << 3;
const SR_IDLE: u32 = 1 << 4;
const SR_RXNE: u32 = 1 << 5;
const SR_TC: u32 = 1 << 6;
const SR_TXE: u32 = 1 << 7;
/// TC, RXNE, LBD, CTS: rc_w0 (PAC: ZERO_TO_MODIFY_FIELDS_BITMAP 0x0360).
const SR_RC_W0: u32 = 0x0360;
/// PE, FE, NF, ORE, IDLE, TXE: read-only, writes ignored.
const SR_READ_ONLY: u32 = 0x009F;

pub const CR1_RE: u32 = 1 << 2;
pub const CR1_TE: u32 = 1 << 3;
pub const CR1_IDLEIE: u32 = 1 << 4;
pub const CR1_RXNEIE: u32 = 1 << 5;
pub const CR1_TCIE: u32 = 1 << 6;
pub const CR1_TXEIE: u32 = 1 << 7;
pub const CR1_UE: u32 = 1 << 13;
const CR1_OVER8: u32 = 1 << 15;
const CR1_MODELLED: u32 = CR1_RE | CR1_TE | CR1_IDLEIE | CR1_RXNEIE | CR1_TCIE | CR1_TXEIE | CR1_UE | CR1_OVER8;
/// CR3.DMAR: DMA enable receiver.
pub const CR3_DMAR: u32 = 1 << 6;

/// How far a received frame's baud rate may be off the receiver's (RM0368 §19.3.5, 8-bit
/// frames, 16× oversampling, DIV_Fraction = 0, noise counted as an error).
pub const RX_BAUD_TOLERANCE: f64 = 0.0375;

const CR2_STOP: u32 = 0b11 << 12;

/// A frame in the shift register: its byte (None for the idle frame after TE), when it started
/// and ends, and whether a BRR write changed the rate during it.
#[derive(Clone, Copy, Debug)]
struct Frame {
    byte: Option<u8>,
    start: Time,
    end: Time,
    bit: Time,
    garbled: bool,
}

/// A frame's length and its bit time, both in [`Time`] units.
#[derive(Clone, Copy, Debug)]
struct FrameTiming {
    length: Time,
    bit: Time,
}

/// A data frame the transmitter finished.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SentFrame {
    /// Start of the start bit.
    pub start: Time,
    /// End of the stop bits.
    pub end: Time,
    pub byte: u8,
    /// One bit's duration: the baud rate the frame went out at is `TIME_HZ / bit`.
    pub bit: Time,
    /// False if BRR was written while the frame was shifted out: a receiver sees garbage.
    pub intact: bool,
}

impl Frame {
    fn new(byte: Option<u8>, start: Time, timing: FrameTiming) -> Frame {
        Frame { byte, start, end: start + timing.length, bit: timing.bit, garbled: false }
    }
}

/// The USART1 model.
#[derive(Clone, Debug)]
pub struct Usart {
    tc: bool,
    cr1: u32,
    cr2: u32,
    brr: u32,
    /// Byte waiting in TDR with its frame's timing.
    tdr: Option<(u8, FrameTiming)>,
    shift: Option<Frame>,
    /// SR was read since the last DR write (first half of the TC clearing sequence).
    sr_read: bool,
    output: Vec<SentFrame>,
    lost_bytes: u32,
    cr3: u32,
    rx: Receiver,
}

/// The receiver's state.
#[derive(Clone, Debug, Default)]
struct Receiver {
    rdr: u8,
    rxne: bool,
    ore: bool,
    idle: bool,
    fe: bool,
    /// When IDLE sets if no start bit comes first (armed by a received byte).
    idle_at: Option<Time>,
    /// SR was read while ORE, IDLE or FE was set: the next DR read clears them.
    clear_armed: bool,
    /// Bytes the receiver took (RDR or lost to ORE), lost to ORE, and ignored (UE/RE off).
    received: u32,
    overrun_lost: u32,
    ignored: u32,
}

impl Default for Usart {
    fn default() -> Self {
        Usart::new()
    }
}

impl Usart {
    /// Reset state: SR = 0x00C0 (TXE, TC), all other registers 0.
    pub fn new() -> Self {
        Usart {
            tc: true,
            cr1: 0,
            cr2: 0,
            brr: 0,
            tdr: None,
            shift: None,
            sr_read: false,
            output: Vec::new(),
            lost_bytes: 0,
            cr3: 0,
            rx: Receiver::default(),
        }
    }

    /// Registers back to reset (RCC USART1RST or a system reset); bytes already finished and not
    /// yet taken, and the lost-byte count, are kept. A frame in progress is cut off.
    pub fn reset_registers(&mut self) {
        let output = std::mem::take(&mut self.output);
        let lost = self.lost_bytes;
        *self = Usart::new();
        self.output = output;
        self.lost_bytes = lost;
    }

    /// Frames whose stop bits have ended, oldest first.
    pub fn take_output(&mut self) -> Vec<SentFrame> {
        std::mem::take(&mut self.output)
    }

    /// Bytes overwritten in TDR by a DR write while TXE = 0 (a firmware defect).
    pub fn lost_bytes(&self) -> u32 {
        self.lost_bytes
    }

    /// The configured baud rate: PCLK2 / (8·(2 − OVER8)·USARTDIV); 0 when BRR is not valid.
    pub fn baud(&self, clocks: Clocks) -> f64 {
        match self.bit_cycles() {
            Ok(cycles) => clocks.pclk2_hz as f64 / cycles as f64,
            Err(_) => 0.0,
        }
    }

    /// The USART1 interrupt line: TXE·TXEIE + TC·TCIE + (RXNE + ORE)·RXNEIE + IDLE·IDLEIE.
    pub fn irq_line(&self) -> bool {
        (self.tdr.is_none() && self.cr1 & CR1_TXEIE != 0)
            || (self.tc && self.cr1 & CR1_TCIE != 0)
            || ((self.rx.rxne || self.rx.ore) && self.cr1 & CR1_RXNEIE != 0)
            || (self.rx.idle && self.cr1 & CR1_IDLEIE != 0)
    }

    /// End of the frame in the shift register (TXE and TC may change then), or the instant the
    /// receiver flags an idle line.
    pub fn next_event(&self) -> Option<Time> {
        [self.shift.map(|f| f.end), self.rx.idle_at].into_iter().flatten().min()
    }

    /// Finishes the frames that end by `now` (frame lengths were fixed when their bytes were
    /// written, so `clocks` is not used) and flags an idle line.
    pub fn advance(&mut self, now: Time, _clocks: Clocks) {
        self.complete(now);
        self.detect_idle(now);
    }

    fn detect_idle(&mut self, now: Time) {
        if self.rx.idle_at.is_some_and(|t| t <= now) {
            self.rx.idle_at = None;
            self.rx.idle = true;
        }
    }

    fn receiver_enabled(&self) -> bool {
        self.cr1 & (CR1_UE | CR1_RE) == CR1_UE | CR1_RE
    }

    /// A frame on the RX line whose stop bit ended at `end`, sent at one bit per `line_bit`
    /// time units. Returns whether the receiver took it (it may still be lost to ORE).
    pub fn receive(&mut self, byte: u8, end: Time, line_bit: Time, clocks: Clocks) -> bool {
        self.detect_idle(end);
        if !self.receiver_enabled() {
            self.rx.ignored = self.rx.ignored.saturating_add(1);
            return false;
        }
        let own_bit = match (self.bit_cycles(), units_per_cycle(clocks.pclk2_hz)) {
            (Ok(cycles), Some(units)) => cycles * units,
            // No valid baud rate: the receiver samples nothing meaningful.
            _ => 0,
        };
        let in_tolerance = own_bit > 0 && (line_bit as f64 / own_bit as f64 - 1.0).abs() <= RX_BAUD_TOLERANCE;
        self.rx.received = self.rx.received.saturating_add(1);
        if self.rx.rxne {
            self.rx.ore = true;
            self.rx.overrun_lost = self.rx.overrun_lost.saturating_add(1);
        } else {
            self.rx.rxne = true;
            if in_tolerance {
                self.rx.rdr = byte;
            } else {
                self.rx.rdr = 0;
                self.rx.fe = true;
            }
        }
        // The line must stay idle a whole frame at the receiver's own rate.
        self.rx.idle_at = (own_bit > 0).then(|| end + 10 * own_bit);
        true
    }

    /// Bytes the receiver took, of them lost to an overrun, and bytes it ignored (UE or RE off).
    pub fn rx_counts(&self) -> (u32, u32, u32) {
        (self.rx.received, self.rx.overrun_lost, self.rx.ignored)
    }

    /// The receiver's DMA request: DMAR with RXNE.
    pub fn rx_dma_request(&self) -> bool {
        self.cr3 & CR3_DMAR != 0 && self.rx.rxne
    }

    /// The DMA's read of DR: RDR, RXNE cleared.
    pub fn dma_read(&mut self) -> u8 {
        self.rx.rxne = false;
        self.rx.rdr
    }

    fn complete(&mut self, now: Time) {
        while let Some(frame) = self.shift {
            if frame.end > now {
                break;
            }
            if let Some(byte) = frame.byte {
                self.output.push(SentFrame { start: frame.start, end: frame.end, byte, bit: frame.bit, intact: !frame.garbled });
            }
            self.shift = match self.tdr.take() {
                // TDR moves into the shift register: TXE sets, the next frame starts.
                Some((byte, timing)) => Some(Frame::new(Some(byte), frame.end, timing)),
                None => {
                    self.tc = true;
                    None
                }
            };
        }
    }

    fn sr(&self) -> u32 {
        let r = &self.rx;
        let mut sr =
            [(r.fe, SR_FE), (r.ore, SR_ORE), (r.idle, SR_IDLE), (r.rxne, SR_RXNE)]
                .into_iter()
                .fold(0, |acc, (set, bit)| if set { acc | bit } else { acc });
        if self.tdr.is_none() {
            sr |= SR_TXE;
        }
        if self.tc {
            sr |= SR_TC;
        }
        sr
    }

    fn transmitter_enabled(&self) -> bool {
        self.cr1 & (CR1_UE | CR1_TE) == CR1_UE | CR1_TE
    }

    /// PCLK2 cycles per bit.
    fn bit_cycles(&self) -> Result<u64, Unmodelled> {
        let brr = u64::from(self.brr & 0xFFFF);
        let mantissa = brr >> 4;
        if mantissa == 0 {
            return Err(Unmodelled::new("USART1.BRR", format!("BRR = {brr:#06x}: USARTDIV below 1, no baud rate")));
        }
        if self.cr1 & CR1_OVER8 == 0 {
            Ok(brr)
        } else if brr & 0x8 != 0 {
            Err(Unmodelled::new("USART1.BRR", format!("BRR = {brr:#06x} with OVER8 = 1: RM0368 requires BRR[3] to be kept cleared")))
        } else {
            Ok(8 * mantissa + (brr & 0x7))
        }
    }

    /// Length of one frame (start, 8 data bits, stop bits) and of one bit with the current
    /// settings.
    fn frame_timing(&self, clocks: Clocks) -> Result<FrameTiming, Unmodelled> {
        let Some(units) = units_per_cycle(clocks.pclk2_hz) else {
            return Err(Unmodelled::new(
                "USART1.BRR",
                format!("PCLK2 {} Hz does not divide the emulator's 336 MHz time base", clocks.pclk2_hz),
            ));
        };
        let bit = self.bit_cycles()? * units;
        // In half bits: 1 start + 8 data = 18, then STOP 00 = 1, 01 = 0.5, 10 = 2, 11 = 1.5 bits.
        let stop_halves = match (self.cr2 & CR2_STOP) >> 12 {
            0b00 => 2,
            0b01 => 1,
            0b10 => 4,
            _ => 3,
        };
        Ok(FrameTiming { length: bit * (18 + stop_halves) / 2, bit })
    }

    /// `clocks` is not needed for a read; it is taken for a uniform interface with
    /// [`Usart::write`].
    pub fn read(&mut self, offset: u32, now: Time, _clocks: Clocks) -> Result<u32, Unmodelled> {
        self.complete(now);
        self.detect_idle(now);
        Ok(match offset {
            SR => {
                self.sr_read = true;
                self.rx.clear_armed = self.rx.ore || self.rx.idle || self.rx.fe;
                self.sr()
            }
            DR => {
                // RM0368 §19.6.1: ORE, IDLE and FE clear by "a read to the USART_SR register
                // followed by a read to the USART_DR register".
                if std::mem::take(&mut self.rx.clear_armed) {
                    self.rx.ore = false;
                    self.rx.idle = false;
                    self.rx.fe = false;
                }
                self.rx.rxne = false;
                u32::from(self.rx.rdr)
            }
            BRR => self.brr,
            CR1 => self.cr1,
            CR2 => self.cr2,
            CR3 => self.cr3,
            GTPR => 0,
            _ => return Err(Unmodelled::offset(NAME, offset, false)),
        })
    }

    /// `clocks` gives PCLK2 for the length of a frame started or queued by this write.
    pub fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        self.complete(now);
        self.detect_idle(now);
        match offset {
            SR => {
                Unmodelled::check_bits("USART1.SR", value, SR_RC_W0 | SR_READ_ONLY)?;
                if value & SR_TC == 0 {
                    self.tc = false;
                }
                if value & SR_RXNE == 0 {
                    self.rx.rxne = false;
                }
            }
            DR => self.write_dr(value, now, clocks)?,
            BRR => self.write_brr(value, clocks)?,
            CR1 => self.write_cr1(value, now, clocks)?,
            CR2 => {
                Unmodelled::check_bits("USART1.CR2", value, CR2_STOP)?;
                self.cr2 = value;
            }
            CR3 => {
                Unmodelled::check_bits("USART1.CR3", value, CR3_DMAR)?;
                self.cr3 = value;
            }
            GTPR => Unmodelled::check_bits("USART1.GTPR", value, 0)?,
            _ => return Err(Unmodelled::offset(NAME, offset, true)),
        }
        Ok(())
    }

    /// DR: a byte to send, into the shift register if it is free, else the transmit buffer
    /// (overwriting one that waits there).
    fn write_dr(&mut self, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        Unmodelled::check_bits("USART1.DR", value, 0x1FF)?;
        if !self.transmitter_enabled() {
            return Err(Unmodelled::new("USART1.DR", format!("write of {value:#04x} with the transmitter disabled (CR1.UE/TE = 0)")));
        }
        // With M = 0 only DR[7:0] is sent.
        let byte = (value & 0xFF) as u8;
        let timing = self.frame_timing(clocks)?;
        if std::mem::take(&mut self.sr_read) {
            self.tc = false;
        }
        if self.shift.is_none() {
            self.shift = Some(Frame::new(Some(byte), now, timing));
        } else {
            if self.tdr.is_some() {
                self.lost_bytes = self.lost_bytes.saturating_add(1);
            }
            self.tdr = Some((byte, timing));
        }
        Ok(())
    }

    /// BRR: the baud rate of the frames to come; a frame shifting meanwhile is garbled.
    fn write_brr(&mut self, value: u32, clocks: Clocks) -> Result<(), Unmodelled> {
        Unmodelled::check_bits("USART1.BRR", value, 0xFFFF)?;
        let previous = std::mem::replace(&mut self.brr, value);
        if let Some((byte, _)) = self.tdr {
            match self.frame_timing(clocks) {
                Ok(timing) => self.tdr = Some((byte, timing)),
                Err(e) => {
                    self.brr = previous;
                    return Err(e);
                }
            }
        }
        if let Some(frame) = self.shift.as_mut() {
            frame.garbled |= value != previous;
        }
        Ok(())
    }

    /// CR1: UE and TE enable the transmitter (an idle frame first); disabling it mid-frame is
    /// not modelled.
    fn write_cr1(&mut self, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        Unmodelled::check_bits("USART1.CR1", value, CR1_MODELLED)?;
        let was_enabled = self.transmitter_enabled();
        let enabled = value & (CR1_UE | CR1_TE) == CR1_UE | CR1_TE;
        if was_enabled && !enabled && (self.shift.is_some() || self.tdr.is_some()) {
            return Err(Unmodelled::new(
                "USART1.CR1",
                format!("write of {value:#06x} disables the transmitter during a frame: not modelled"),
            ));
        }
        let previous = std::mem::replace(&mut self.cr1, value);
        if enabled && !was_enabled {
            // RM0368: "Setting the TE bit drives the USART to send an idle frame before
            // the first data frame."
            match self.frame_timing(clocks) {
                Ok(timing) => self.shift = Some(Frame::new(None, now, timing)),
                Err(e) => {
                    self.cr1 = previous;
                    return Err(e);
                }
            }
        }
        Ok(())
    }
}

impl super::Peripheral for Usart {
    fn read(&mut self, offset: u32, now: Time, clocks: Clocks) -> Result<u32, Unmodelled> {
        Usart::read(self, offset, now, clocks)
    }

    fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        Usart::write(self, offset, value, now, clocks)
    }

    fn next_event(&self) -> Option<Time> {
        Usart::next_event(self)
    }

    fn advance(&mut self, now: Time, clocks: Clocks) {
        Usart::advance(self, now, clocks)
    }

    fn irq_line(&self, _line: usize) -> bool {
        Usart::irq_line(self)
    }

    fn reset(&mut self) {
        self.reset_registers();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periph::TIME_HZ;

    fn clocks() -> Clocks {
        Clocks::PLL_84_MHZ
    }

    fn write(u: &mut Usart, offset: u32, value: u32, now: Time) {
        u.write(offset, value, now, clocks()).expect("modelled");
    }

    /// The HAL's 115200 8N1 setup at PCLK2 = 84 MHz: BRR = (84e6 + 57600) / 115200 = 729.
    const BRR_115200: u32 = 729;
    /// One bit: 729 PCLK2 cycles of 4 units.
    const BIT: Time = 729 * 4;
    const FRAME: Time = 10 * BIT;

    /// The finished frames as (end of the stop bits, byte), all intact.
    fn sent(u: &mut Usart) -> Vec<(Time, u8)> {
        u.take_output()
            .into_iter()
            .map(|f| {
                assert!(f.intact, "{f:?}");
                (f.end, f.byte)
            })
            .collect()
    }

    fn enabled(t: Time) -> Usart {
        let mut u = Usart::new();
        write(&mut u, BRR, BRR_115200, t);
        write(&mut u, CR2, 0, t);
        write(&mut u, CR3, 0, t);
        write(&mut u, CR1, CR1_UE | CR1_TE | CR1_RE, t);
        u
    }

    #[test]
    fn reset_sr_has_txe_and_tc() {
        let mut u = Usart::new();
        assert_eq!(u.read(SR, 0, clocks()), Ok(0xC0));
        for offset in [DR, BRR, CR1, CR2, CR3, GTPR] {
            assert_eq!(u.read(offset, 0, clocks()), Ok(0));
        }
    }

    #[test]
    fn baud_follows_brr_and_over8() {
        let mut u = enabled(0);
        assert!((u.baud(clocks()) - 84e6 / 729.0).abs() < 1e-6);
        assert!((u.baud(clocks()) - 115_226.3).abs() < 0.1);
        // OVER8: BRR = mantissa << 4 | fraction (3 bits): USARTDIV = 91 + 1/8 → 8·91 + 1 cycles.
        let mut v = Usart::new();
        write(&mut v, BRR, (91 << 4) | 1, 0);
        write(&mut v, CR1, CR1_OVER8, 0);
        assert!((v.baud(clocks()) - 84e6 / 729.0).abs() < 1e-6);
        assert!(v.write(BRR, (91 << 4) | 0x8, 0, clocks()).is_ok());
        assert!(v.write(CR1, CR1_OVER8 | CR1_UE | CR1_TE, 0, clocks()).is_err(), "BRR[3] set with OVER8");
        u.write(BRR, 0, 0, clocks()).unwrap();
        assert_eq!(u.baud(clocks()), 0.0);
    }

    #[test]
    fn te_sends_an_idle_frame_first() {
        let mut u = enabled(0);
        assert_eq!(u.next_event(), Some(FRAME));
        write(&mut u, DR, b'A'.into(), 10);
        assert_eq!(u.read(SR, 10, clocks()).unwrap() & SR_TXE, 0, "waits in TDR behind the idle frame");
        assert_eq!(u.read(SR, FRAME, clocks()).unwrap() & SR_TXE, SR_TXE);
        assert_eq!(sent(&mut u), vec![]);
        u.advance(2 * FRAME, clocks());
        assert_eq!(sent(&mut u), vec![(2 * FRAME, b'A')]);
    }

    #[test]
    fn bytes_go_out_back_to_back_with_txe_and_tc() {
        let t0 = 100 * FRAME;
        let mut u = enabled(0);
        u.advance(t0, clocks());
        assert_eq!(u.read(SR, t0, clocks()).unwrap() & (SR_TXE | SR_TC), SR_TXE | SR_TC);
        write(&mut u, DR, 0x31, t0);
        assert_eq!(u.read(SR, t0, clocks()).unwrap() & (SR_TXE | SR_TC), SR_TXE, "shift register was empty; SR read + DR write cleared TC");
        write(&mut u, DR, 0x32, t0);
        assert_eq!(u.read(SR, t0, clocks()).unwrap() & SR_TXE, 0);
        assert_eq!(u.next_event(), Some(t0 + FRAME));
        u.advance(t0 + FRAME, clocks());
        assert_eq!(u.read(SR, t0 + FRAME, clocks()).unwrap() & (SR_TXE | SR_TC), SR_TXE);
        u.advance(t0 + 2 * FRAME - 1, clocks());
        assert_eq!(u.read(SR, t0 + 2 * FRAME - 1, clocks()).unwrap() & SR_TC, 0);
        assert_eq!(u.read(SR, t0 + 2 * FRAME, clocks()).unwrap() & SR_TC, SR_TC);
        assert_eq!(sent(&mut u), vec![(t0 + FRAME, 0x31), (t0 + 2 * FRAME, 0x32)]);
        assert_eq!(u.next_event(), None);
        // 115200 baud: 10 bits take about 86.8 µs.
        assert!(((FRAME as f64 / TIME_HZ as f64) - 10.0 / 115_226.3).abs() < 1e-9);
    }

    #[test]
    fn tc_clears_only_by_sr_read_then_dr_write_or_by_writing_zero() {
        let t0 = 100 * FRAME;
        let mut u = enabled(0);
        u.advance(t0, clocks());
        // No SR read before the DR write: TC stays set.
        write(&mut u, DR, 1, t0);
        assert_eq!(u.sr() & SR_TC, SR_TC);
        // rc_w0: writing 1 keeps it, writing 0 clears it.
        write(&mut u, SR, SR_TC, t0);
        assert_eq!(u.sr() & SR_TC, SR_TC);
        write(&mut u, SR, 0, t0);
        assert_eq!(u.sr() & SR_TC, 0);
    }

    #[test]
    fn dr_write_while_txe_is_clear_loses_the_waiting_byte() {
        let t0 = 100 * FRAME;
        let mut u = enabled(0);
        u.advance(t0, clocks());
        write(&mut u, DR, 1, t0);
        write(&mut u, DR, 2, t0);
        write(&mut u, DR, 3, t0);
        assert_eq!(u.lost_bytes(), 1);
        u.advance(t0 + 3 * FRAME, clocks());
        assert_eq!(sent(&mut u), vec![(t0 + FRAME, 1), (t0 + 2 * FRAME, 3)]);
    }

    #[test]
    fn frames_carry_their_start_and_end() {
        let t0 = 100 * FRAME;
        let mut u = enabled(0);
        u.advance(t0, clocks());
        write(&mut u, DR, 1, t0);
        write(&mut u, DR, 2, t0 + 5);
        u.advance(t0 + 2 * FRAME, clocks());
        let frames = u.take_output();
        assert_eq!(frames.iter().map(|f| (f.start, f.end)).collect::<Vec<_>>(), vec![(t0, t0 + FRAME), (t0 + FRAME, t0 + 2 * FRAME)]);
        assert!(frames.iter().all(|f| f.bit == BIT));
    }

    #[test]
    fn a_brr_write_during_a_frame_garbles_it_and_the_next_byte_takes_the_new_rate() {
        let t0 = 100 * FRAME;
        let mut u = enabled(0);
        u.advance(t0, clocks());
        write(&mut u, DR, 1, t0);
        write(&mut u, DR, 2, t0);
        // Halve the bit time half-way through the first frame.
        write(&mut u, BRR, BRR_115200 / 2, t0 + FRAME / 2);
        u.advance(t0 + FRAME + 10 * (BRR_115200 / 2) as Time * 4, clocks());
        let frames = u.take_output();
        assert_eq!(frames.len(), 2, "{frames:?}");
        assert!(!frames[0].intact, "the frame in the shift register went out at two rates");
        assert!(frames[1].intact);
        assert_eq!(frames[1].end - frames[1].start, 10 * (BRR_115200 / 2) as Time * 4, "TDR's byte at the new rate");
        // The same value again is no change; a BRR of 0 with a byte waiting is refused.
        write(&mut u, DR, 3, frames[1].end);
        write(&mut u, DR, 4, frames[1].end);
        write(&mut u, BRR, BRR_115200 / 2, frames[1].end + 1);
        assert!(u.write(BRR, 0, frames[1].end + 2, clocks()).is_err());
        assert_eq!(u.read(BRR, frames[1].end + 2, clocks()), Ok(BRR_115200 / 2), "refused write not applied");
        u.advance(frames[1].end + 2 * FRAME, clocks());
        assert!(u.take_output().iter().all(|f| f.intact));
    }

    #[test]
    fn stop_bits_lengthen_the_frame() {
        let mut u = enabled(0);
        u.advance(FRAME, clocks());
        write(&mut u, CR2, 0b10 << 12, FRAME);
        write(&mut u, DR, 7, FRAME);
        assert_eq!(u.next_event(), Some(FRAME + 11 * BIT), "2 stop bits");
        u.advance(FRAME + 11 * BIT, clocks());
        write(&mut u, CR2, 0b11 << 12, FRAME + 11 * BIT);
        write(&mut u, DR, 8, FRAME + 11 * BIT);
        assert_eq!(u.next_event(), Some(FRAME + 11 * BIT + 21 * BIT / 2), "1.5 stop bits");
    }

    #[test]
    fn irq_line_is_txe_and_txeie_or_tc_and_tcie() {
        let mut u = enabled(0);
        assert!(!u.irq_line());
        write(&mut u, CR1, CR1_UE | CR1_TE | CR1_TXEIE, 0);
        assert!(u.irq_line());
        write(&mut u, DR, 1, 1);
        assert!(!u.irq_line(), "TDR full behind the idle frame");
        u.advance(FRAME, clocks());
        assert!(u.irq_line());
        write(&mut u, CR1, CR1_UE | CR1_TE | CR1_TCIE, FRAME);
        assert!(u.irq_line(), "TC is still set: no SR read preceded the DR write");
        write(&mut u, SR, !SR_TC & 0x3FF, FRAME);
        assert!(!u.irq_line());
    }

    #[test]
    fn unmodelled_features_are_errors() {
        let mut u = Usart::new();
        for (offset, value) in [
            (CR1, 1 << 12),
            (CR1, 1 << 10),
            (CR1, 1 << 9),
            (CR1, 1 << 8), // PEIE
            (CR1, 1),
            (CR2, 1 << 14),
            (CR2, 1 << 11),
            (CR2, 1),
            (CR3, 1 << 7),
            (GTPR, 1),
            (BRR, 1 << 16),
            (SR, 1 << 10),
        ] {
            assert!(u.write(offset, value, 0, clocks()).is_err(), "{offset:#x} {value:#x}");
        }
        assert!(u.write(DR, 0x41, 0, clocks()).is_err(), "transmitter disabled");
        assert!(u.read(0x1C, 0, clocks()).is_err());
    }

    #[test]
    fn disabling_the_transmitter_mid_frame_is_an_error() {
        let mut u = enabled(0);
        assert!(u.write(CR1, CR1_UE, 10, clocks()).is_err());
        u.advance(FRAME, clocks());
        assert!(u.write(CR1, CR1_UE, FRAME, clocks()).is_ok());
    }

    #[test]
    fn reset_keeps_finished_output_and_lost_count() {
        let mut u = enabled(0);
        write(&mut u, DR, 1, 0);
        write(&mut u, DR, 2, 0);
        u.advance(2 * FRAME, clocks());
        u.reset_registers();
        assert_eq!(u.read(SR, 2 * FRAME, clocks()), Ok(0xC0));
        assert_eq!(u.lost_bytes(), 1);
        assert_eq!(sent(&mut u), vec![(2 * FRAME, 2)]);
    }

    /// UE | RE with BRR for 115 200 baud: the receiver as the HAL leaves it.
    fn receiver() -> Usart {
        let mut u = Usart::new();
        write(&mut u, BRR, BRR_115200, 0);
        write(&mut u, CR1, CR1_UE | CR1_RE, 0);
        u
    }

    fn sr(u: &mut Usart, now: Time) -> u32 {
        u.read(SR, now, clocks()).unwrap()
    }

    fn dr(u: &mut Usart, now: Time) -> u32 {
        u.read(DR, now, clocks()).unwrap()
    }

    #[test]
    fn a_received_byte_sets_rxne_and_a_dr_read_takes_it() {
        let mut u = receiver();
        assert!(u.receive(0x5A, FRAME, BIT, clocks()));
        assert_eq!(sr(&mut u, FRAME) & (SR_RXNE | SR_ORE), SR_RXNE);
        assert_eq!(dr(&mut u, FRAME), 0x5A);
        assert_eq!(sr(&mut u, FRAME) & SR_RXNE, 0);
    }

    /// Rule (RM0368 §19.3.3): a byte that ends while RXNE is still set is lost and sets ORE;
    /// RDR keeps the unread byte.
    #[test]
    fn a_byte_arriving_while_rxne_is_set_is_lost_and_sets_ore() {
        let mut u = receiver();
        u.receive(1, FRAME, BIT, clocks());
        u.receive(2, 2 * FRAME, BIT, clocks());
        assert_eq!(sr(&mut u, 2 * FRAME) & (SR_RXNE | SR_ORE), SR_RXNE | SR_ORE);
        assert_eq!(dr(&mut u, 2 * FRAME), 1, "the first byte survives, the second is gone");
        assert_eq!(u.rx_counts(), (2, 1, 0));
    }

    /// Rule (RM0368 §19.6.1): ORE clears by an SR read followed by a DR read. A DR read alone, or
    /// writing 0 to SR, leaves it set (and the receive interrupt with RXNEIE keeps firing).
    #[test]
    fn ore_survives_a_dr_read_without_an_sr_read_and_an_sr_write() {
        let mut u = receiver();
        write(&mut u, CR1, CR1_UE | CR1_RE | CR1_RXNEIE, 0);
        u.receive(1, FRAME, BIT, clocks());
        u.receive(2, 2 * FRAME, BIT, clocks());
        write(&mut u, SR, 0, 2 * FRAME);
        dr(&mut u, 2 * FRAME);
        assert_ne!(sr(&mut u, 2 * FRAME) & SR_ORE, 0, "a DR read without an SR read first leaves ORE");
        assert!(u.irq_line(), "ORE with RXNEIE holds the interrupt line up");
        dr(&mut u, 2 * FRAME);
        assert_eq!(sr(&mut u, 2 * FRAME) & SR_ORE, 0, "SR read, then DR read: cleared");
        assert!(!u.irq_line());
    }

    /// IDLE sets a whole frame after the last byte, and not again until RXNE has set again.
    #[test]
    fn idle_sets_a_frame_after_the_last_byte_and_only_once() {
        let mut u = receiver();
        write(&mut u, CR1, CR1_UE | CR1_RE | CR1_IDLEIE, 0);
        u.receive(7, FRAME, BIT, clocks());
        assert_eq!(u.next_event(), Some(2 * FRAME));
        u.advance(2 * FRAME - 1, clocks());
        assert_eq!(sr(&mut u, 2 * FRAME - 1) & SR_IDLE, 0);
        u.advance(2 * FRAME, clocks());
        assert!(u.irq_line());
        assert_ne!(sr(&mut u, 2 * FRAME) & SR_IDLE, 0);
        dr(&mut u, 2 * FRAME);
        assert_eq!(sr(&mut u, 2 * FRAME) & SR_IDLE, 0);
        u.advance(10 * FRAME, clocks());
        assert_eq!(sr(&mut u, 10 * FRAME) & SR_IDLE, 0, "no byte since: no second IDLE");
        assert_eq!(u.next_event(), None);
    }

    /// The wrong sequence: RE (or UE) left off, the receiver ignores the line.
    #[test]
    fn with_re_off_a_byte_on_the_line_is_not_received() {
        let mut u = Usart::new();
        write(&mut u, BRR, BRR_115200, 0);
        write(&mut u, CR1, CR1_UE | CR1_TE, 0);
        assert!(!u.receive(9, FRAME, BIT, clocks()));
        assert_eq!(sr(&mut u, FRAME) & SR_RXNE, 0);
        assert_eq!(u.rx_counts(), (0, 0, 1));
    }

    /// A receiver set for another baud rate (BRR for 16 MHz, the clock not yet raised) takes a
    /// 115 200 baud byte as a framing error.
    #[test]
    fn a_byte_at_another_baud_rate_is_a_framing_error() {
        let mut u = Usart::new();
        write(&mut u, BRR, 139, 0); // 115 200 baud from 16 MHz, run at 84 MHz
        write(&mut u, CR1, CR1_UE | CR1_RE, 0);
        u.receive(0x41, FRAME, BIT, clocks());
        let s = sr(&mut u, FRAME);
        assert_eq!(s & (SR_RXNE | SR_FE), SR_RXNE | SR_FE);
        assert_ne!(dr(&mut u, FRAME), 0x41);
        assert_eq!(sr(&mut u, FRAME) & SR_FE, 0);
    }

    /// With DMAR, RXNE is a DMA request; the DMA's DR read clears it, so no overrun follows.
    #[test]
    fn dmar_makes_rxne_a_dma_request_that_the_dma_read_clears() {
        let mut u = receiver();
        write(&mut u, CR3, CR3_DMAR, 0);
        for (i, b) in [3u8, 4, 5].into_iter().enumerate() {
            u.receive(b, (i as Time + 1) * FRAME, BIT, clocks());
            assert!(u.rx_dma_request());
            assert_eq!(u.dma_read(), b);
            assert!(!u.rx_dma_request());
        }
        assert_eq!(sr(&mut u, 3 * FRAME) & SR_ORE, 0);
        assert!(u.write(CR3, 1 << 7, 0, clocks()).is_err(), "DMAT is not modelled");
    }
}
