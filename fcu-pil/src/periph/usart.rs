//! USART1 (RM0368 §19) at 0x4001_1000, transmitter only.
//!
//! Modelled: SR (TXE, TC; TC and the other rc_w0 flags cleared by writing 0), DR (transmit data
//! register TDR; reads return the receive data register, which stays 0: nothing is ever
//! received), BRR (both oversampling modes), CR1 UE, TE, TXEIE, TCIE, OVER8, and RE (see below),
//! CR2 STOP. Not modelled (an [`Unmodelled`] error when set): 9-bit words (M), parity (PCE, PS),
//! send break, mute mode and wake-up, the receive interrupts (RXNEIE, IDLEIE, PEIE), LIN, the
//! synchronous clock output, everything in CR3 (DMA, flow control, IrDA, smartcard, half-duplex,
//! error interrupt) and GTPR.
//!
//! RE: the HAL's `Serial::tx` (stm32f4xx-hal 0.23 `serial.rs`, `Serial::_new`) always writes CR1
//! with RE = 1, even for a transmit-only serial. The model accepts RE as a receiver whose line
//! stays idle: no start bit ever arrives, so RXNE, ORE, FE, NF, PE and IDLE stay 0.
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

const SR_TC: u32 = 1 << 6;
const SR_TXE: u32 = 1 << 7;
/// TC, RXNE, LBD, CTS: rc_w0 (PAC: ZERO_TO_MODIFY_FIELDS_BITMAP 0x0360).
const SR_RC_W0: u32 = 0x0360;
/// PE, FE, NF, ORE, IDLE, TXE: read-only, writes ignored.
const SR_READ_ONLY: u32 = 0x009F;

const CR1_RE: u32 = 1 << 2;
const CR1_TE: u32 = 1 << 3;
const CR1_TCIE: u32 = 1 << 6;
const CR1_TXEIE: u32 = 1 << 7;
const CR1_UE: u32 = 1 << 13;
const CR1_OVER8: u32 = 1 << 15;
const CR1_MODELLED: u32 = CR1_RE | CR1_TE | CR1_TCIE | CR1_TXEIE | CR1_UE | CR1_OVER8;

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
}

impl Default for Usart {
    fn default() -> Self {
        Usart::new()
    }
}

impl Usart {
    /// Reset state: SR = 0x00C0 (TXE, TC), all other registers 0.
    pub fn new() -> Self {
        Usart { tc: true, cr1: 0, cr2: 0, brr: 0, tdr: None, shift: None, sr_read: false, output: Vec::new(), lost_bytes: 0 }
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

    /// The USART1 interrupt line: TXE·TXEIE + TC·TCIE (the receive sources are not modelled).
    pub fn irq_line(&self) -> bool {
        (self.tdr.is_none() && self.cr1 & CR1_TXEIE != 0) || (self.tc && self.cr1 & CR1_TCIE != 0)
    }

    /// End of the frame in the shift register (TXE and TC may change then).
    pub fn next_event(&self) -> Option<Time> {
        self.shift.map(|f| f.end)
    }

    /// Finishes the frames that end by `now` (frame lengths were fixed when their bytes were
    /// written, so `clocks` is not used).
    pub fn advance(&mut self, now: Time, _clocks: Clocks) {
        self.complete(now);
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
        let mut sr = 0;
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
        Ok(match offset {
            SR => {
                self.sr_read = true;
                self.sr()
            }
            // The receive data register: nothing is ever received, it keeps its reset value.
            DR => 0,
            BRR => self.brr,
            CR1 => self.cr1,
            CR2 => self.cr2,
            CR3 => 0,
            GTPR => 0,
            _ => return Err(Unmodelled::offset(NAME, offset, false)),
        })
    }

    /// `clocks` gives PCLK2 for the length of a frame started or queued by this write.
    pub fn write(&mut self, offset: u32, value: u32, now: Time, clocks: Clocks) -> Result<(), Unmodelled> {
        self.complete(now);
        match offset {
            SR => {
                Unmodelled::check_bits("USART1.SR", value, SR_RC_W0 | SR_READ_ONLY)?;
                if value & SR_TC == 0 {
                    self.tc = false;
                }
            }
            DR => {
                Unmodelled::check_bits("USART1.DR", value, 0x1FF)?;
                if !self.transmitter_enabled() {
                    return Err(Unmodelled::new(
                        "USART1.DR",
                        format!("write of {value:#04x} with the transmitter disabled (CR1.UE/TE = 0)"),
                    ));
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
            }
            BRR => {
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
            }
            CR1 => {
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
            }
            CR2 => {
                Unmodelled::check_bits("USART1.CR2", value, CR2_STOP)?;
                self.cr2 = value;
            }
            CR3 => Unmodelled::check_bits("USART1.CR3", value, 0)?,
            GTPR => Unmodelled::check_bits("USART1.GTPR", value, 0)?,
            _ => return Err(Unmodelled::offset(NAME, offset, true)),
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
            (CR1, 1 << 5),
            (CR1, 1 << 4),
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
}
